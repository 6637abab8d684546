"""A scene's `"watercolour"` object: the look's settings, validated, and the look drawn by the JAX renderer.

```
"watercolour": {
  "paper":      {"image": "paper.png", "seed": 0, "relief": 2.0,
                 "granulation": 0.6, "density": 0.25, "shading": 0.08},
  "edges":      {"darkening": 3.0, "width": 3.0},
  "unevenness": {"turbulence": 0.18, "dispersion": 0.08},
  "strokes":    {"amplitude": 0.12, "direction": "max", "length": 0.25, "seed": 0},
  "shadow":     {"strength": 0.7, "bias": 0.004},
  "hatching":   {"amount": 0.5, "scale": 190},
  "mix":        {"wash": {"pigment": "Cadmium Yellow"}, "unlit": {"pigment": "Hookers Green"},
                 "map": [0.0, 0.1, ...] | "mix.npy" | {"axis": [0, 1, 0], "softness": 0.25}}
}
```

Absent: the plain model. `{}`: every effect at its default but hatching and
the mix (which need to be asked for). An effect set to `false` is off; an
object takes defaults for the keys it leaves out. docs/scene-format.md and
docs/watercolour.md describe each key.

**References:** Curtis et al. 1997 (granulation, staining, edge darkening);
Bousseau et al. 2006 (unevenness, paper); Lum and Ma 2001 (strokes along
principal curvature); Praun et al. 2001 (tonal art maps); Montesdeoca et al.
2017, MNPR (edge darkening from a blurred density).
"""

from __future__ import annotations

import functools
import os
from pathlib import Path
from typing import Any, Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array

from . import look as wl
from .look._xla import apart
from . import shading
from ._errors import DiffwashError
from ._interpolate import barycentrics, interpolate
from ._io import check_input_file
from ._scene_schema import EFFECT_MODELS, ON_BY_DEFAULT
from ._rasterize import rasterize as rasterize_op

__all__ = ["Watercolour", "parse_watercolour", "watercolour_to_dict", "watercolour_files", "WATERCOLOUR_KEYS",
           "LOOK_PARAMETERS", "look_parameter_check"]

#: Scene keys of the `Look` leaves: leaf -> (effect, key).
_LEAF_KEYS: dict[str, tuple[str, str]] = {leaf: (spec.effect, spec.key) for leaf, spec in wl.leaf_specs().items()}
#: The keys of each effect's object, with their defaults (None: no default), as `_scene_schema` declares them: its
#: options, then its leaves' (their values when turned on, from `look.leaf_specs`).
WATERCOLOUR_KEYS: dict[str, dict[str, Any]] = {
    effect: {k: None if f.is_required() else f.default for k, f in model.model_fields.items()}
    for effect, model in EFFECT_MODELS.items()
}  # fmt: skip
#: Effects on unless the scene says otherwise: those whose leaves are on in `Look`'s defaults (hatching and
#: the mix are asked for).
_ON_BY_DEFAULT = ON_BY_DEFAULT
#: Upper bounds of the keys that have one.
_AT_MOST = {f"{spec.effect}.{spec.key}": spec.at_most for spec in wl.leaf_specs().values() if spec.at_most is not None}


class Watercolour(eqx.Module):
    """A scene's watercolour look: its continuous parameters and what it precomputes.

    **Fields:**

    - `look`: the `diffwash.look.Look` (every leaf differentiable: replace it
      with `eqx.tree_at(lambda s: s.watercolour.look, scene, look)`).
    - `screen`: the screen-space tile `(Th, Tw, 6)` (`look.screen_textures`).
    - `strokes`: the brush-stroke layer per vertex `(V,)`, or None.
    - `mix`: the pigment mix per vertex `(V,)` in [0, 1] (differentiable), or None.
    - `wash_b`, `unlit_b`: the pigments at mix 1, or None.
    - `tam`: the tonal art map's levels, or None (no hatching); `tam_packed`:
      the same as one table (`look.pack_tam`), as the renderer reads it.
    - `pigments`: the `look.Pigments` (granularity, staining, density on this paper).
    - `shadow`: whether the unlit glaze thickens in the object's own shadow.
    - `hatch_scale`: texels of the map's finest level per object unit.
    - `effects`: the effects the scene turns on (`WATERCOLOUR_KEYS` names).
    """

    look: wl.Look
    screen: Any
    strokes: Any = None
    mix: Any = None
    wash_b: Any = None
    unlit_b: Any = None
    tam: Any = None
    pigments: Any = eqx.field(static=True, default=None)
    shadow: bool = eqx.field(static=True, default=True)
    hatch_scale: float = eqx.field(static=True, default=190.0)
    effects: tuple[str, ...] = eqx.field(static=True, default=tuple(WATERCOLOUR_KEYS))
    tam_packed: Any = None


def _fail(msg: str, file: Any, field: str) -> DiffwashError:
    return DiffwashError(msg, file=file, field=field)


def _paper(settings: Any, file: Any, base: Path) -> wl.ScreenTextures:
    if settings is None:
        return wl.screen_textures()
    seed, relief, image = settings.seed, settings.relief, settings.image
    if image is None:
        return wl.screen_textures(seed=seed, relief=relief)
    field = "watercolour.paper.image"
    path = base / image
    if not os.path.lexists(path):
        raise _fail(f"no such image file: {path}", file, field)
    check_input_file(path, file=file, field=field)
    try:
        height = wl.paper_from_image(path, field=field)
    except DiffwashError as e:
        raise _fail(f"{path}: {e.problem}", file, field) from None
    return wl.screen_textures(height, seed=seed, relief=relief)


def _mix_map(spec: Any, vertices: np.ndarray, file: Any, base: Path) -> np.ndarray:
    """The mix per vertex (`spec` checked by `SceneFile`: a list, a file name or an axis), one per vertex in [0, 1]."""
    field = "watercolour.mix.map"
    if not isinstance(spec, (str, list)):
        return wl.mix_along_axis(vertices, list(spec.axis), softness=float(spec.softness))
    if isinstance(spec, str):
        path = base / spec
        check_input_file(path, file=file, field=field)
        try:
            spec = np.load(path, allow_pickle=False)
        except (OSError, ValueError) as e:
            raise _fail(f"{path}: not a NumPy .npy array ({e})", file, field) from None
    return wl.check_mix_map(spec, len(vertices), file=file, field=field)


def parse_watercolour(
    spec: Any, *, file: Any, base: Path, mesh: Any, params: shading.Params, pigment: Callable[[Any, str], Any]
) -> Watercolour | None:
    """The `Watercolour` of a scene's `"watercolour"` object (None: absent or `false`).

    **Arguments:**

    - `spec`: the object as `SceneFile` checked it (`_scene_schema.WatercolourObject`: keys, types and ranges),
      or None; `file`: the scene file (for errors); `base`: the
      folder relative paths start from.
    - `mesh`: the scene's `Mesh`; `params`: its `Params`.
    - `pigment(spec, key)`: the scene's pigment reader (names, files, K and S).

    **Returns:**

    A `Watercolour`, or None. Bad values raise a one-line `DiffwashError`
    naming the file and the key (`watercolour.edges.width`, ...).
    """
    if spec is None or spec is False:
        return None
    # Each effect's settings (the declaration reads `true` as its defaults), or None when it is off.
    eff = {name: None if v is False else v for name, v in spec}
    # An effect that is off contributes 0, but for a step (the shadow's bias), which keeps its default.
    values = {leaf: 0.0 if spec.fit else spec.default for leaf, spec in wl.leaf_specs().items()}
    for leaf, (effect, key) in _LEAF_KEYS.items():
        if eff[effect] is not None:
            values[leaf] = float(getattr(eff[effect], key))
    screen = _paper(eff["paper"], file, base)
    vertices = np.asarray(mesh.vertices, np.float64)
    strokes = None
    if eff["strokes"] is not None:
        s = eff["strokes"]
        length = float(s.length)
        size = float(np.linalg.norm(np.ptp(vertices, axis=0)))  # the mesh's bounding-box diagonal
        if length > 10 * size:
            raise _fail(f"must be at most 10 times the mesh's size ({size:.4g}, its bounding box's diagonal: "
                        f"a stroke longer than the object traces nothing), got {length:g}", file,
                        "watercolour.strokes.length")  # fmt: skip
        strokes = wl.stroke_field(vertices, np.asarray(mesh.faces), np.asarray(mesh.normals), direction=s.direction,
                                  length=length, seed=s.seed)  # fmt: skip
    tam, scale = None, WATERCOLOUR_KEYS["hatching"]["scale"]
    if eff["hatching"] is not None:
        scale = float(eff["hatching"].scale)
        tam = [np.asarray(level, np.float32) for level in wl.tonal_art_map()]
    mix = wash_b = unlit_b = None
    if eff["mix"] is not None:
        m = eff["mix"]
        wash_b = params.wash if m.wash is None else pigment(_json(m.wash), "watercolour.mix.wash")
        unlit_b = params.unlit if m.unlit is None else pigment(_json(m.unlit), "watercolour.mix.unlit")
        mix = _mix_map(m.map, vertices, file, base)
    looks = [wl.pigment_look(q, screen.paper) for q in (params.wash, wash_b or params.wash, params.unlit, unlit_b or params.unlit)]
    return Watercolour(
        look=wl.Look(**{k: np.float64(v) for k, v in values.items()}),
        screen=np.asarray(screen.channels, np.float32),
        strokes=strokes,
        mix=mix,
        wash_b=wash_b,
        unlit_b=unlit_b,
        tam=tam,
        pigments=wl.Pigments(*looks),
        shadow=eff["shadow"] is not None,
        hatch_scale=float(scale),
        effects=tuple(k for k, v in eff.items() if v is not None),
        tam_packed=None if tam is None else wl.pack_tam(tam),
    )


def _json(v: Any) -> Any:
    """A checked value back as the JSON it was (the keys it gave)."""
    return v.model_dump(exclude_unset=True) if hasattr(v, "model_dump") else v


#: The look's continuous parameters by their scene keys (`watercolour.<effect>.<key>` -> `Look` leaf): what
#: fit-image can fit. The shadow's depth bias is left out (a step: its gradient is 0).
LOOK_PARAMETERS: dict[str, str] = {f"watercolour.{s.effect}.{s.key}": leaf for leaf, s in wl.leaf_specs().items() if s.fit}
#: The look parameters that are fractions in [0, 1] (the others are >= 0).
LOOK_FRACTIONS = frozenset(f"watercolour.{k}" for k, top in _AT_MOST.items() if top == 1)


def look_parameter_check(name: str, wc: Watercolour | None, file: Any) -> None:
    """Refuse to fit the look parameter `name` (a `LOOK_PARAMETERS` key) on a scene whose look lacks it.

    One line naming the scene `file` and the key: no `"watercolour"` object, or the effect is off.
    """
    effect = name.split(".")[1]
    if wc is None:
        raise _fail('the scene has no "watercolour" object, so it has no look parameters to fit', file, name)
    if effect not in wc.effects:
        raise _fail(f'the scene\'s {effect} effect is off; turn it on (e.g. "{effect}": {{}}) to fit it', file, name)


def watercolour_to_dict(spec: Any, wc: Watercolour) -> dict:
    """The scene file's `"watercolour"` object `spec` with the values of `wc.look` (a fitted look, written back).

    Effects that are off stay off; paths, seeds and choices are kept as written.
    """
    out = {k: (dict(v) if isinstance(v, dict) else v) for k, v in (spec or {}).items()}
    for leaf, (effect, key) in _LEAF_KEYS.items():
        on = out.get(effect, {} if effect in _ON_BY_DEFAULT else False)
        if on is False:
            continue
        on = {} if on is True else on
        on[key] = float(np.asarray(getattr(wc.look, leaf)))
        out[effect] = on
    return out


def watercolour_files(spec: Any, base: Path) -> list[Path]:
    """The files a `"watercolour"` object names (its paper image, its mix map), best effort."""
    if not isinstance(spec, dict):
        return []
    paper, mix = spec.get("paper"), spec.get("mix")
    names = [paper.get("image") if isinstance(paper, dict) else None, mix.get("map") if isinstance(mix, dict) else None]
    return [base / n for n in names if isinstance(n, str) and n and (base / n).is_file()]


# --- the look in the renderer ------------------------------------------------------------------------


def _tile(screen: Array, height: int, width: int, dtype) -> Array:
    """The tile repeated over the image (copies, not a gather)."""
    reps = (-(-height // screen.shape[0]), -(-width // screen.shape[1])) + (1,) * (screen.ndim - 2)
    return jnp.tile(jnp.asarray(screen, dtype), reps)[:height, :width]


def _attributes(surf: Any, clip, vertices, faces, normals, params, vis, wc: Watercolour, light_tri, light_depth, shadow, dtype,
                *, width, height) -> dict[str, Array]:  # fmt: skip
    """The per-vertex attributes the look reads, at the covered pixels, in one interpolation (one gather per corner
    for them all, where each alone took as long): `P`, `N` (world position and unit normal, turned towards the eye
    on drawn back faces; for the hatching), `shadow` (`vertex_shadow`), `mix`, `stroke`; those the look has."""
    columns: dict[str, Array] = {}
    if wc.tam is not None:
        columns["P"] = jnp.asarray(vertices)
        if surf.N is None:
            columns["N"] = jnp.asarray(normals)
    if wc.shadow:
        if shadow is None:
            shadow = vertex_shadow(vertices, faces, normals, params.light, wc.look.shadow_bias, light_tri, light_depth)
        columns["shadow"] = jnp.asarray(shadow)[:, None]
    for name, values in (("mix", wc.mix), ("stroke", wc.strokes)):
        if values is not None:
            columns[name] = jnp.asarray(values, dtype)[:, None]
    if not columns:
        return {}
    table = jnp.concatenate(list(columns.values()), axis=1)
    # Apart: XLA would fuse the table's making (the shadow lookups) into the gathers, once per pixel and corner.
    at = apart(interpolate, table, faces, vis.pixel_tri, _bary(surf, clip, faces, vis, width, height))
    out, start = {}, 0
    for name, c in columns.items():
        out[name] = at[:, start : start + c.shape[1]].astype(c.dtype)
        start += c.shape[1]
    for name in ("shadow", "mix", "stroke"):
        if name in out:
            out[name] = out[name][:, 0]
    if "P" in out:
        if surf.N is not None:
            out["N"] = surf.N
        else:
            N = shading.safe_normalize(out["N"])
            out["N"] = jnp.where(surf.flip[:, None], -N, N)
    return out


def look_image(
    surf: Any, clip: Array, wash: Array, unlit: Array, vertices, faces, normals, camera, params, vis, wc: Watercolour,
    light_tri: Array | None, light_depth: Array | None = None, shadow: Array | None = None, *, width: int, height: int,
) -> Array:  # fmt: skip
    r"""The look on the model's thicknesses at the covered pixels: `(H * W, 3)` linear RGB, the whole image.

    Surface terms (shadow, hatching) at the pixels (the shadow looked up per vertex and interpolated,
    `vertex_shadow`), the G-buffer, image terms
    (edges, strokes, paper, unevenness), the glaze (mixed pigments where the
    scene has a mix map) and the paper's shading, as `diffwash.look.compose`
    and docs/watercolour.md describe. Differentiable in every leaf of
    `wc.look`, `wc.mix`, the pigments, the constants and the geometry.
    `light_tri`: the shadow map's triangles (`ops.rasterize` of
    `look.light_clip`), or None without shadows; `light_depth`: the shadow map
    (`shadow_depth`) when the light and the mesh are fixed, else None (computed here); `shadow`: the
    shadow factor at the vertices (`fixed_vertex_shadow`) when the bias and normals are fixed too, else None.
    """
    look = wc.look
    dtype = wash.dtype
    attrs = _attributes(surf, clip, vertices, faces, normals, params, vis, wc, light_tri, light_depth, shadow, dtype,
                        width=width, height=height)  # fmt: skip
    sh, hatch = attrs.get("shadow"), None
    if wc.tam is not None:
        P, N = attrs["P"], attrs["N"]
        eye = jnp.asarray(camera.eye, dtype)
        fwd = shading.safe_normalize(jnp.asarray(camera.target, dtype) - eye)
        d = P - eye
        pixel = (d[:, 0] * fwd[0] + d[:, 1] * fwd[1] + d[:, 2] * fwd[2]) * (2 * jnp.tan(jnp.deg2rad(camera.fov_y) / 2) / height)
        tam = wc.tam if wc.tam_packed is None else wc.tam_packed
        hatch = functools.partial(wl.hatch_ink_at, tam, P, N, pixel, wc.hatch_scale)  # reads only the 2 tones used
    w, u = wl.surface_terms(wash, unlit, look, unlit_max=params.k_unlit, shadow=sh, hatch=hatch)
    # Barriers between the stages: XLA would otherwise fuse a stage's gathers into each of its consumers
    # and compute them again there (the hatching several times per pixel).
    w, u = jax.lax.optimization_barrier((w, u))
    zero = jnp.zeros_like(w)
    m, b = attrs.get("mix", zero), attrs.get("stroke", zero)
    # The edge blur is the one operator over the whole image; the rest runs on the covered pixels only
    # (bare paper is thickness 0: its glaze is the paper), as image_terms(..., mean=) allows.
    n, pixels = width * height, vis.pixels
    t = jnp.zeros((n, 2), dtype).at[pixels].set(jnp.stack([w, u], 1), mode="drop", unique_indices=True)
    mean = wl.local_mean(t.reshape(height, width, 2), look.edge_width, wl.edge_downsample(height))
    mean = mean.reshape(n, 2).at[pixels].get(mode="fill", fill_value=0)
    screen = jax.lax.optimization_barrier(jnp.asarray(wc.screen, dtype))
    rows, cols = screen.shape[:2]
    p = jnp.minimum(pixels, n - 1)
    at = screen[(p // width) % rows, (p % width) % cols]  # the screen tile at the covered pixels
    terms = lambda g, at, mean, look: wl.image_terms(g, at, look, wc.pigments, mean=mean)  # noqa: E731
    thick = apart(terms, jnp.stack([w, u, m, b], 1), at, mean, look)
    # The glaze apart: XLA splits Kubelka-Munk into several loops and would recompute the image terms in each.
    if wc.mix is None:
        rgb = apart(lambda params, t: shading.glaze(params, t[:, 0], t[:, 1]), params, thick)
    else:
        rgb = apart(lambda params, wb, ub, t, m: wl.glaze_mix(params, wb, ub, t[:, 0], t[:, 1], m), params, wc.wash_b, wc.unlit_b, thick, m)
    image = jnp.broadcast_to(jnp.asarray(params.paper, dtype), (n, 3)).at[pixels].set(rgb, mode="drop", unique_indices=True)
    shade = _tile(screen[..., 1:2], height, width, dtype)[..., 0]
    return wl.paper_shading(image.reshape(height, width, 3), shade, look.paper_shading).reshape(n, 3)


def vertex_shadow(vertices, faces, normals, light, bias, light_tri: Array, light_depth: Array | None = None) -> Array:
    """The self-shadow factor at each vertex, `(V,)`: `look.shadow` at the vertices (offset along their normals).

    The renderer interpolates it over the triangles, as the exported shaders' vertex stage does
    (`geometry_sources(shadow="vertex")`): the map's 9 reads per vertex, not per covered pixel.
    `light_depth`: the shadow map of a fixed light and mesh, else None (computed from `light_tri`).
    """
    v = jnp.asarray(vertices)
    vp = wl.light_view_projection(v, light)
    # A barrier: fused into the lookups' gathers, the map would be recomputed at every tap.
    depth = light_depth if light_depth is not None else wl.light_depth(v, faces, vp, light_tri)
    depth = jax.lax.optimization_barrier(jnp.asarray(depth, v.dtype))
    offset = 1.5 * 2 / (jnp.linalg.norm(vp[0, :3]) * light_tri.shape[0])  # look.normal_offset, traced
    n = shading.safe_normalize(jnp.asarray(normals, v.dtype))
    return wl.shadow(depth, vp, v, bias, normals=n, normal_offset=offset)


@jax.jit
def fixed_vertex_shadow(vertices: Any, faces: Any, light: Any, normals: Any, bias: Any, light_tri: Array, light_depth: Array) -> Array:
    """`vertex_shadow` of a fixed light, mesh and bias, computed once outside the look's kernel (as `shadow_depth`)."""
    return vertex_shadow(vertices, faces, normals, light, bias, light_tri, light_depth)


def _bary(surf, clip, faces, vis, width, height):
    if surf.bary is not None:
        return surf.bary
    return barycentrics(clip, faces, vis.pixel_tri, vis.pixels, width, height)[0]


@jax.jit
def shadow_depth(vertices: Any, faces: Any, light: Any, light_tri: Array) -> Array:
    """The shadow map of a fixed light and mesh (`look.light_depth`), computed once outside the look's kernel."""
    v = jnp.asarray(vertices)
    return wl.light_depth(v, faces, wl.light_view_projection(v, jnp.asarray(light, v.dtype)), light_tri)


def shadow_triangles(vertices: Any, faces: Any, light: Any, size: int = wl.SHADOW_MAP_SIZE) -> Array:
    """The triangle the light sees at each shadow-map texel, `(size, size)` (the depth pass; not differentiable)."""
    v = jnp.asarray(vertices, jnp.float32)
    vp = wl.light_view_projection(v, jnp.asarray(light, jnp.float32))
    return rasterize_op(wl.light_clip(v, vp), faces, (size, size)).tri_id

