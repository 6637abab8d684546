r"""The watercolour look as a pipeline of array operators, in the order the renderer applies them.

**1. Surface terms** (per shaded point, where the renderer computes the
model's wash and unlit thickness; the geometry pass of a shader):
`surface_terms` thickens the unlit glaze in the object's own shadow
(`_shadow`) and turns it into hatching for a pen-and-wash style
(`_hatching`).

**2. The G-buffer**: per pixel `(wash, unlit, mix, stroke)`, `(H, W, 4)`:
the thicknesses, the pigment mix and the brush-stroke value (`_strokes`, a
per-vertex attribute interpolated like the normals), all zero where nothing
is drawn (row 0 at the top, as every diffwash image). Coverage is not needed
here (bare paper is thickness 0); the renderer keeps its own alpha.

**3. Image terms** (`image_terms`, full-screen passes of a shader): edge
darkening (`_edges`, the only neighbourhood operator: a separable blur at
reduced resolution) of the smooth thicknesses, then per pixel the brush
strokes, the paper's granulation, staining and density for each glaze's
pigment mixture, and the turbulence and dispersion of the pigment
(`_paper`), all as factors on the thickness. Strokes come after the edge
darkening so that the edges are the wash's, not every stroke's.

**4. Glaze**: the Kubelka-Munk glazes of the (mixed) pigments over the
paper (`_mix.glaze_mix`, or its 3D LUT `_mix.lookup_mix_lut`; with no mix map,
`diffwash.shading.glaze` or the 2D LUT).

**5. Paper shading**: the paper's relief over the colour (`_paper`).

Every continuous parameter is a leaf of `Look` (differentiable with
`jax.grad`, fittable with optimistix); zero strengths and widths give back
the plain model exactly (`OFF`; a zero edge width alone keeps the blur grid's
own narrow edge).

**Written once.** Each effect's per-pixel arithmetic (`surface_terms`,
`pixel_terms` and the functions they call) is written against the array
namespace of `diffwash._xp`: the renderer runs it on JAX arrays, and
`diffwash._look_glsl` traces the very same functions into the look's shaders,
as `diffwash._glsl` does for the model. Each `Look` leaf is declared once,
with its scene key, default, bound and documentation (`leaf_specs`): the scene
reader (`diffwash._watercolour`), the shaders' uniforms (`look_<leaf>`) and
`look_uniforms` all read that declaration.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any, NamedTuple

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from .._xp import Expr, namespace, shader_function
from ._edges import EDGE_RADIUS, edge_darken, edge_downsample, gaussian_weights_np, local_mean
from ._hatching import hatch_ink
from ._paper import PigmentLook, paper_shading, pigment_factor, unevenness_factor
from ._shadow import DEFAULT_BIAS
from ._strokes import stroke_factor

__all__ = [
    "Look",
    "LeafSpec",
    "leaf_specs",
    "DEFAULT_LOOK",
    "OFF",
    "Pigments",
    "surface_terms",
    "pixel_terms",
    "image_terms",
    "compose",
    "look_uniforms",
]


class LeafSpec(NamedTuple):
    """How a `Look` leaf appears in a scene file and a shader: one declaration per leaf (`leaf_specs`).

    **Fields:** `leaf` (the `Look` field), `effect` and `key` (the scene's
    `watercolour.<effect>.<key>`), `default` (the `Look`'s default: 0 for an
    effect that is off unless asked for), `on` (the value when the scene turns
    the effect on without giving the key), `at_most` (an upper bound, or
    None), `fit` (whether fit-image may fit it: False for a step, whose
    gradient is 0; such a leaf keeps its default when its effect is off),
    `doc` (what it is, as the shaders' uniform declarations say it). The
    shaders' uniform is `look_<leaf>`.
    """

    leaf: str
    effect: str
    key: str
    default: float
    on: float
    at_most: float | None
    fit: bool
    doc: str


def _leaf(effect: str, key: str, default: float, doc: str, *, on: float | None = None, at_most: float | None = None, fit: bool = True) -> Any:
    """A `Look` field declared with its scene key, default, bound and documentation (read by `leaf_specs`)."""
    meta = {"effect": effect, "key": key, "on": default if on is None else on, "at_most": at_most, "fit": fit, "doc": doc}
    return eqx.field(default=default, metadata={"look": meta})


class Look(eqx.Module):
    """The look's continuous parameters, as a pytree (every field differentiable).

    **Fields** (each declared with its scene key, `leaf_specs`):

    - `edge_darkening`: pigment gathered at a glaze's edge, $k_e$ (0: off).
    - `edge_width`: the edge's width, the blur's sigma in pixels (at 0 the
      blur grid's own width remains, about `edge_downsample(H)` pixels).
    - `granulation`: the paper's effect on granular pigments, $k_g$ in [0, 1].
    - `density`: how much a pigment's density scales its thickness, $k_\\rho$.
    - `turbulence`, `dispersion`: amplitudes of the low- and high-frequency
      unevenness.
    - `paper_shading`: the strength of the paper's relief shading.
    - `strokes`: the amplitude of the brush-stroke layer.
    - `shadow`: how far the unlit glaze thickens in the object's own shadow
      (0: off, 1: as thick as on the side facing away from the light).
    - `shadow_bias`: the shadow map's depth bias (a step: zero gradient).
    - `hatching`: how far the unlit glaze becomes hatching (0: a wash, 1: pen
      strokes only).
    """

    edge_darkening: Any = _leaf("edges", "darkening", 3.0, "k_e: pigment gathered at a glaze's edge")
    edge_width: Any = _leaf("edges", "width", 3.0, "the edge's width: the blur's sigma in pixels")
    granulation: Any = _leaf("paper", "granulation", 0.6, "k_g: 0 even, 1 Curtis et al.'s equilibrium", at_most=1.0)
    density: Any = _leaf("paper", "density", 0.25, "k_rho: how much a pigment's density scales its thickness",
                         at_most=10.0)
    turbulence: Any = _leaf("unevenness", "turbulence", 0.18, "amplitude of the low-frequency turbulent flow")
    dispersion: Any = _leaf("unevenness", "dispersion", 0.08, "amplitude of the high-frequency pigment dispersion")
    paper_shading: Any = _leaf("paper", "shading", 0.08, "strength of the paper's relief shading")
    strokes: Any = _leaf("strokes", "amplitude", 0.12, "amplitude of the stroke layer")
    shadow: Any = _leaf("shadow", "strength", 0.7, "how far the unlit glaze thickens in the object's own shadow", at_most=1.0)
    shadow_bias: Any = _leaf("shadow", "bias", DEFAULT_BIAS, "the shadow map's depth bias", fit=False)
    hatching: Any = _leaf("hatching", "amount", 0.0, "how far the unlit glaze becomes hatching", on=0.5, at_most=1.0)


def leaf_specs() -> dict[str, LeafSpec]:
    """Every `Look` leaf's declaration (`LeafSpec`), in the `Look`'s field order."""
    return {f.name: LeafSpec(f.name, **{k: f.metadata["look"][k] for k in ("effect", "key")}, default=f.default,
                             **{k: f.metadata["look"][k] for k in ("on", "at_most", "fit", "doc")})
            for f in dataclasses.fields(Look)}  # fmt: skip


#: The look's defaults: what `"watercolour": {}` turns on (docs/watercolour.md gives the reasons).
DEFAULT_LOOK: dict[str, float] = {name: spec.default for name, spec in leaf_specs().items()}

#: Every effect off: `compose` then gives the plain model's image.
OFF = Look(**{k: 0.0 for k in DEFAULT_LOOK})


class Pigments(NamedTuple):
    """The `PigmentLook`s of the four pigments a mixed pair of glazes uses (the `_b` ones at mix = 1).

    Without a mix map, pass the same pigment twice (`Pigments.single(wash, unlit)`).
    """

    wash: PigmentLook
    wash_b: PigmentLook
    unlit: PigmentLook
    unlit_b: PigmentLook

    @classmethod
    def single(cls, wash: PigmentLook, unlit: PigmentLook) -> "Pigments":
        return cls(wash, wash, unlit, unlit)


def surface_terms(
    wash: Float[ArrayLike, "*b"],
    unlit: Float[ArrayLike, "*b"],
    look: Look,
    *,
    unlit_max: Float[ArrayLike, ""],
    shadow: Float[ArrayLike, "*b"] | None = None,
    hatch: Float[ArrayLike, "*b T"] | Callable[[Array], Array] | None = None,
) -> tuple[Float[Array, "*b"], Float[Array, "*b"]]:
    r"""Shadow and hatching on the model's thicknesses at shaded points.

    $$ u_1 = u + k_\text{shadow}\, s\, (u_\max - u), \qquad
       u' = u_1 + k_\text{hatching} (u_\max\, \mathrm{ink}(u_1 / u_\max) - u_1), $$

    with `s` the shadow factor (`_shadow.shadow`) and `ink(tau)` the tonal
    art map's ink at tone `tau` (`hatch`: the map's samples of every tone at
    the point, `_hatching.hatch_samples`; or a function `tau -> ink`, e.g.
    `_hatching.hatch_ink_at`, which reads only the two tones it needs). Each
    term is skipped when its input is None; the wash is unchanged. Written
    against `diffwash._xp`: the look's geometry shader is this function, traced.

    **Arguments:**

    - `wash`, `unlit`: the model's thicknesses (`diffwash.shading.thicknesses`).
    - `look`: the `Look`.
    - `unlit_max`: the model's largest unlit thickness (`params.k_unlit`).
    - `shadow`, `hatch`: see above.
    """
    xp = namespace(wash, unlit, shadow, unlit_max)
    w, u = xp.asfloat(wash, unlit)
    if shadow is not None:
        u = u + look.shadow * shadow * (unlit_max - u)
    if hatch is not None:
        ok = unlit_max > 0
        tau = xp.where(ok, u / xp.where(ok, unlit_max, 1.0), 0.0)
        ink = hatch(tau) if callable(hatch) else hatch_ink(hatch, tau)
        u = u + look.hatching * (unlit_max * ink - u)
    return w, u


def _lerp(a: Array, b: Array, t: Array) -> Array:
    return a + t * (b - a)


def _pigment_factor(h: Array, a: PigmentLook, b: PigmentLook, m: Array, look: Look) -> Array:
    fa = pigment_factor(h, a, look.granulation, look.density)
    if b is a or (not isinstance(b, Expr) and b == a):  # no mix map: one pigment (a static check, no work for the second)
        return fa
    return _lerp(fa, pigment_factor(h, b, look.granulation, look.density), m)


@shader_function(
    "look_pixel_terms",
    [("wash", "float"), ("unlit", "float"), ("mean_wash", "float"), ("mean_unlit", "float"), ("mix_proportion", "float"),
     ("stroke", "float"), ("paper", "float"), ("turbulence_wash", "float"), ("dispersion_wash", "float"),
     ("turbulence_unlit", "float"), ("dispersion_unlit", "float")],
    [("wash_out", "float"), ("unlit_out", "float")],
)  # fmt: skip
def pixel_terms(
    wash, unlit, mean_wash, mean_unlit, mix_proportion, stroke, paper, turbulence_wash, dispersion_wash, turbulence_unlit, dispersion_unlit,
    look: Look, pigments: Pigments,
) -> tuple[Float[Array, "*p"], Float[Array, "*p"]]:  # fmt: skip
    r"""The image terms at pixels whose glazes' local mean is known: what the final pass does per pixel.

    $$ t' = \mathrm{edge}(t, \bar t)\ \exp(k_\text{strokes} b)\ \mathrm{lerp}(F_a(h), F_b(h), m)\ \exp(k_t n_t + k_d n_d) $$

    per glaze (`image_terms` explains the terms). Every argument but `look` and
    `pigments` is a per-pixel value (any matching shapes): the G-buffer's
    thicknesses, their local mean (`_edges.local_mean`), mix and stroke value,
    and the screen tile's paper height and the four noises.

    **Returns:**

    `(wash, unlit)` to glaze.
    """
    t_w = edge_darken(wash, mean_wash, look.edge_darkening)
    t_u = edge_darken(unlit, mean_unlit, look.edge_darkening)
    b = stroke_factor(stroke, look.strokes)
    w = t_w * b * _pigment_factor(paper, pigments.wash, pigments.wash_b, mix_proportion, look) * unevenness_factor(turbulence_wash, dispersion_wash, look.turbulence, look.dispersion)
    u = t_u * b * _pigment_factor(paper, pigments.unlit, pigments.unlit_b, mix_proportion, look) * unevenness_factor(turbulence_unlit, dispersion_unlit, look.turbulence, look.dispersion)
    return w, u


def image_terms(
    gbuffer: Float[ArrayLike, "*p 4"],
    screen: Float[ArrayLike, "*p 6"],
    look: Look,
    pigments: Pigments,
    *,
    mean: Float[ArrayLike, "*p 2"] | None = None,
) -> Float[Array, "*p 2"]:
    r"""Edge darkening, then strokes, granulation, staining, density and unevenness, on the G-buffer's thicknesses.

    The local mean over the image (the edge blur), then `pixel_terms` at each pixel.

    $$ t' = \mathrm{edge}(t)\ \exp(k_\text{strokes} b)\ \mathrm{lerp}(F_a(h), F_b(h), m)\ \exp(k_t n_t + k_d n_d) $$

    per glaze, `F` the pigment factors (`_paper.pigment_factor`) of the
    glaze's two pigments, `m` the mix, `b` the stroke value, `h` the paper.

    **Arguments:**

    - `gbuffer`: `(wash, unlit, mix, stroke)` per pixel: an `(H, W, 4)` image,
      or any list of pixels when `mean` is given.
    - `screen`: the screen textures at the same pixels (`_textures.tile`).
    - `look`: the `Look`.
    - `pigments`: the four pigments' `PigmentLook`.
    - `mean`: the glazes' local mean at those pixels (`_edges.local_mean` of
      the G-buffer's `(H, W, 2)` thicknesses, with `edge_downsample(H)`); by
      default computed here from the `(H, W, 4)` image. With it, any set of
      pixels can be processed: the edge blur is the only operator that needs
      the whole image.

    **Returns:**

    `(*p, 2)`: the wash and unlit thickness to glaze.
    """
    g = jnp.asarray(gbuffer)
    s = jnp.asarray(screen)
    if mean is None:
        mean = local_mean(g[..., :2], look.edge_width, edge_downsample(g.shape[0]))
    mean = jnp.asarray(mean)
    w, u = pixel_terms(g[..., 0], g[..., 1], mean[..., 0], mean[..., 1], g[..., 2], g[..., 3], s[..., 0], s[..., 2], s[..., 3], s[..., 4], s[..., 5], look, pigments)
    return jnp.stack([w, u], axis=-1)


def compose(
    gbuffer: Float[ArrayLike, "H W 4"],
    screen: Float[ArrayLike, "H W 6"],
    look: Look,
    pigments: Pigments,
    glaze: Any,
) -> Float[Array, "H W 3"]:
    """Steps 3 to 5: image terms, the glaze, the paper's shading: linear RGB.

    `glaze(wash, unlit, mix) -> (..., 3)`: e.g. `lambda w, u, m: glaze_mix(params,
    wash_b, unlit_b, w, u, m)`, or a LUT lookup.
    """
    g = jnp.asarray(gbuffer)
    t = image_terms(g, screen, look, pigments)
    rgb = glaze(t[..., 0], t[..., 1], g[..., 2])
    return paper_shading(rgb, jnp.asarray(screen)[..., 1], look.paper_shading)


def look_uniforms(look: Look, pigments: Pigments, *, height: int, radius: int = EDGE_RADIUS) -> dict[str, Any]:
    """The uniforms of the look's shaders (`diffwash._look_glsl`) for a `Look`.

    The same numbers the JAX operators use: each leaf as `look_<leaf>`, the
    pigments' `vec4`s, and `look_edge_weights` (`gaussian_weights_np(width /
    f, radius)`, offsets 0..radius, `f = edge_downsample(height)` for an
    image `height` pixels tall).
    """
    factor = edge_downsample(height)
    f = lambda x: float(np.asarray(x))  # noqa: E731
    out: dict[str, Any] = {f"look_{name}": f(getattr(look, name)) for name in leaf_specs()}
    out.update({
        "look_wash_pigment": pigments.wash.uniform(),
        "look_wash_pigment_b": pigments.wash_b.uniform(),
        "look_unlit_pigment": pigments.unlit.uniform(),
        "look_unlit_pigment_b": pigments.unlit_b.uniform(),
    })  # fmt: skip
    weights = gaussian_weights_np(f(look.edge_width) / factor, radius)
    out["look_edge_weights"] = [float(v) for v in weights[radius:]]
    return out
