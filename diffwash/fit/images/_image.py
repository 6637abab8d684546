r"""Shading parameters from target images: render, compare, and solve with optimistix.

`fit_image` fits named parameters of a scene (pigment K and S, gain, bias, the
thickness constants, shininess, the light, the paper, the proportions and
amount of a library mixture...) so that the scene's
rendering matches one or more target images, with an optimistix least-squares
solver (Levenberg-Marquardt by default).

**What is compared.** The pixels the object covers in the rendering (the
coverage mask of `diffwash.rasterize`; the geometry and camera are not
fitted, so the visibility is computed once per view and reused). The loss is
in linear RGB (`loss="linear"`, the renderer's own output against the target
linearised from sRGB) or in CIELAB (`loss="lab"`, closer to what the eye sees).

**Reparametrisation.** The solver works on unconstrained numbers:

- `log` for positive parameters (`k_wash`, `k_unlit`, `k_specular`,
  `shininess`, pigment `K` and `S`);
- `logit` for parameters in (0, 1) (`gain`, `bias`, `wash_reduction`,
  `paper`); starting values are nudged into [0.01, 0.99] (a logit at 0 or 1
  is infinite);
- the light by two angles (azimuth and elevation): the model only sees its
  direction, so its length is not a parameter;
- a glaze's library mixture (`wash.mix`, `unlit.mix`: its proportions) by
  the isometric log-ratio of the proportions (`_simplex_basis`): P - 1 numbers
  for P pigments, mapped to proportions by a softmax, so they stay >= 0 and
  sum to 1 (the model sees only their ratios; the sum is the gauge it
  fixes). Starting proportions below `MIN_PROPORTION` are raised to it (a
  log-ratio at 0 is infinite); `log` for its amount (`wash.amount`,
  `unlit.amount`). Either is refused, in one line naming it, on a glaze that
  is not a library mixture;
- the watercolour look's parameters (`watercolour.edges.darkening`, ...,
  named by their scene keys): `logit` for the fractions (`paper.granulation`,
  `shadow.strength`, `hatching.amount`), `log` for the others.

**The look.** A scene with a `"watercolour"` object is fitted as
`diffwash.render` draws it: the whole look (`diffwash._watercolour.look_image`,
whose edge blur needs the whole image) at each step, compared at the covered
pixels. Its continuous parameters can be fitted like the model's; asking for
one on a scene without a watercolour object, or with that effect off, is a
one-line error naming the scene file and the key.

**Gauges.** Some parameters trade off exactly; fitting both sides of such a
trade would leave a direction with no information, so one side is held fixed
(a *gauge*) and the fit says so:

- a glaze's thickness scale against its pigment's K and S: the layer sees only
  `K t` and `S t`, so scaling K and S by `c` and the thickness by `1/c`
  changes nothing. When a pigment's `K` and `S` are both fitted together with
  its thickness constant (`k_wash` for the wash, `k_unlit` for the unlit glaze),
  the thickness constant is held at its starting value: K and S are then per
  unit of that thickness.
- `k_specular` against `k_wash`: the wash thickness uses only their product;
  with both named, `k_specular` is held fixed.
- a library mixture's amount against its glaze's thickness scale: the amount
  scales K and S through the pigments' amount laws (all alike but for their
  exponents and the pair terms), nearly as the thickness does; with
  `wash.amount` and `k_wash` both named, `k_wash` is held (and `k_unlit` with
  `unlit.amount`).
"""

from __future__ import annotations

import difflib
import functools
import math
import os
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import equinox as eqx
import jax
import jax.flatten_util
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from ... import colorimetry
from ..._cache import relieve_compiled_programs
from ..._choices import IMAGE_LOSSES, SOLVERS
from ..._errors import DiffwashError
from ..._io import read_image, read_json
from ..._mixture import check_fittable
from ... import look as wl
from ... import shading
from ..._render import Surface, Visibility, _kernel_statics, _look_kernel, rasterize, surface, surface_thicknesses
from ..._scene import Scene, load_scene, parse_scene, save_scene
from ..._watercolour import LOOK_FRACTIONS, LOOK_PARAMETERS, look_parameter_check, shadow_triangles
from ...pigments import Pigment
from ...shading import Params

__all__ = ["FITTABLE", "SOLVERS", "IMAGE_LOSSES", "ImageFit", "fit_image", "parse_fit_list", "load_cameras"]

#: Fittable parameters: name -> (kind, size). Kinds: log (> 0), logit (in (0, 1)), sphere (a direction),
#: simplex (proportions summing to 1; size 0: one fewer than the glaze's mixture has pigments).
FITTABLE: dict[str, tuple[str, int]] = {
    "gain": ("logit", 1),
    "bias": ("logit", 1),
    "wash_reduction": ("logit", 1),
    "k_wash": ("log", 1),
    "k_unlit": ("log", 1),
    "k_specular": ("log", 1),
    "shininess": ("log", 1),
    "wash.K": ("log", 3),
    "wash.S": ("log", 3),
    "unlit.K": ("log", 3),
    "unlit.S": ("log", 3),
    "paper": ("logit", 3),
    "light": ("sphere", 2),
    # A glaze that is a mixture of library pigments: its proportions and amount.
    "wash.mix": ("simplex", 0),
    "wash.amount": ("log", 1),
    "unlit.mix": ("simplex", 0),
    "unlit.amount": ("log", 1),
    # The watercolour look's continuous parameters (a scene's "watercolour" object, that effect on).
    **{n: ("logit" if n in LOOK_FRACTIONS else "log", 1) for n in LOOK_PARAMETERS},
}
#: Starting proportions of a fitted mixture are raised to this (then renormalised): a log-ratio at 0 is infinite.
MIN_PROPORTION = 1e-3


def parse_fit_list(text: str | Sequence[str], *, field: str = "--fit") -> tuple[str, ...]:
    """Validate a list of parameter names (comma-separated text or a sequence)."""
    names = [n.strip() for n in text.split(",")] if isinstance(text, str) else [str(n).strip() for n in text]
    names = [n for n in names if n]
    if not names:
        raise DiffwashError(f"names no parameter; choose from {', '.join(FITTABLE)}", field=field)
    for n in names:
        if n not in FITTABLE:
            close = difflib.get_close_matches(n, list(FITTABLE), n=1)
            hint = f"; did you mean {close[0]!r}?" if close else f" (fittable: {', '.join(FITTABLE)})"
            raise DiffwashError(f"unknown parameter {n!r}{hint}", field=field)
    dupes = sorted({n for n in names if names.count(n) > 1})
    if dupes:
        raise DiffwashError(f"names {', '.join(dupes)} twice", field=field)
    return tuple(names)


def _gauges(names: tuple[str, ...]) -> tuple[tuple[str, ...], list[str]]:
    """Drop the parameters a gauge holds fixed; say why."""
    notes = []
    held = set()
    for glaze, k in (("wash", "k_wash"), ("unlit", "k_unlit")):
        if f"{glaze}.K" in names and f"{glaze}.S" in names and k in names:
            held.add(k)
            notes.append(f"gauge: {k} is held at its starting value, since {glaze}.K and {glaze}.S are fitted too "
                         f"(the {glaze} layer sees only K*thickness and S*thickness); the fitted K and S are per "
                         f"unit of that thickness")  # fmt: skip
    for glaze, k in (("wash", "k_wash"), ("unlit", "k_unlit")):
        if f"{glaze}.amount" in names and k in names and k not in held:
            held.add(k)
            notes.append(f"gauge: {k} is held at its starting value, since {glaze}.amount is fitted too (the amount "
                         f"scales the {glaze}'s K and S through the pigments' amount laws, nearly as the thickness "
                         f"does)")  # fmt: skip
    if "k_specular" in names and "k_wash" in names and "k_wash" not in held:
        held.add("k_specular")
        notes.append("gauge: k_specular is held at its starting value, since k_wash is fitted too "
                     "(the wash thickness uses only their product)")  # fmt: skip
    if "k_specular" in names and "k_wash" in held:
        held.add("k_specular")
        notes.append("gauge: k_specular is held too (it scales the wash thickness like k_wash)")
    return tuple(n for n in names if n not in held), notes


def _get(params: Params, name: str, look: wl.Look | None = None) -> np.ndarray:
    if name in LOOK_PARAMETERS:
        return np.asarray(getattr(look, LOOK_PARAMETERS[name]), np.float64)
    if "." in name:
        glaze, which = name.split(".")
        paint = getattr(params, glaze)
        if which == "mix":  # the proportions as shares (the model normalises them)
            p = np.asarray(paint.proportions, np.float64)
            return p / p.sum() if p.sum() > 0 else p
        return np.asarray(getattr(paint, which), np.float64)
    return np.asarray(getattr(params, name), np.float64)


@functools.cache
def _simplex_basis(n: int) -> np.ndarray:
    r"""An orthonormal basis, shape (n, n - 1), of the vectors whose entries sum to 0 (Helmert's).

    The isometric log-ratio coordinates of proportions $p$ are $y = V^T \log p$, and
    $p = \mathrm{softmax}(V y)$: $V V^T$ removes the mean of $\log p$, which the softmax ignores, so
    every $y$ is one point of the simplex and every point with $p > 0$ one $y$ (no gauge left).
    """
    V = np.zeros((n, n - 1))
    for k in range(1, n):
        V[:k, k - 1] = 1 / math.sqrt(k * (k + 1))
        V[k, k - 1] = -k / math.sqrt(k * (k + 1))
    return V


def _logit(p: np.ndarray) -> np.ndarray:
    p = np.clip(p, 0.01, 0.99)
    return np.log(p / (1 - p))


def _encode(params: Params, names: tuple[str, ...], look: wl.Look | None = None) -> dict[str, np.ndarray]:
    """Parameters (and look parameters) to the solver's unconstrained variables."""
    y = {}
    for n in names:
        kind, size = FITTABLE[n]
        v = _get(params, n, look).reshape(-1)
        if kind == "log":
            y[n] = np.log(np.maximum(v, 1e-6))
        elif kind == "logit":
            y[n] = _logit(v)
        elif kind == "simplex":
            p = np.maximum(v, MIN_PROPORTION * max(float(v.sum()), 1e-300))
            y[n] = _simplex_basis(v.size).T @ np.log(p / p.sum())
        else:  # sphere: azimuth about +y from +z towards +x, elevation towards +y
            d = v / max(float(np.linalg.norm(v)), 1e-300)
            y[n] = np.array([math.atan2(d[0], d[2]), math.asin(float(np.clip(d[1], -1, 1)))])
        y[n] = y[n].reshape(()) if size == 1 else y[n]
    return y


def _decode_look(y: dict[str, Any], base: wl.Look | None) -> wl.Look | None:
    """The solver's look variables back to a `Look` (the others from `base`)."""
    names = [n for n in y if n in LOOK_PARAMETERS]
    if not names:
        return base
    values = [jax.nn.sigmoid(y[n]) if FITTABLE[n][0] == "logit" else jnp.exp(y[n]) for n in names]
    return eqx.tree_at(lambda lk: [getattr(lk, LOOK_PARAMETERS[n]) for n in names], base, values)


def _decode(y: dict[str, Any], base: Params, light_length: float) -> Params:
    """The solver's variables back to a `Params` (the others from `base`; look variables are ignored)."""
    values = {}
    for n, v in y.items():
        if n in LOOK_PARAMETERS:
            continue
        kind, _ = FITTABLE[n]
        if kind == "log":
            values[n] = jnp.exp(v)
        elif kind == "logit":
            values[n] = jax.nn.sigmoid(v)
        elif kind == "simplex":
            values[n] = jax.nn.softmax(jnp.asarray(_simplex_basis(v.shape[0] + 1), v.dtype) @ v)
        else:
            az, el = v[0], v[1]
            values[n] = light_length * jnp.stack([jnp.cos(el) * jnp.sin(az), jnp.sin(el), jnp.cos(el) * jnp.cos(az)])
    p = base
    for glaze in ("wash", "unlit"):  # a library mixture's proportions and amount
        m = getattr(p, glaze)
        if f"{glaze}.mix" in values:
            m = eqx.tree_at(lambda q: q.proportions, m, values.pop(f"{glaze}.mix"))
        if f"{glaze}.amount" in values:
            m = eqx.tree_at(lambda q: q.amount, m, values.pop(f"{glaze}.amount"))
        p = eqx.tree_at(lambda q, g=glaze: getattr(q, g), p, m) if m is not getattr(p, glaze) else p
    for glaze in ("wash", "unlit"):
        if f"{glaze}.K" not in values and f"{glaze}.S" not in values:
            continue  # kept as it is (a library mixture stays one)
        pig = getattr(p, glaze)
        K = values.pop(f"{glaze}.K", pig.K)
        S = values.pop(f"{glaze}.S", pig.S)
        p = eqx.tree_at(lambda q, g=glaze: getattr(q, g), p, Pigment(K=K, S=S, name=pig.name, density=pig.density,
                                                                     staining=pig.staining,
                                                                     granularity=pig.granularity))  # fmt: skip
    for n, v in values.items():
        p = eqx.tree_at(lambda q, n=n: getattr(q, n), p, v)
    return p


@dataclass(frozen=True)
class ImageFit:
    """The result of `fit_image`.

    **Fields:**

    - `scene`: the (first) scene, with its fitted look if look parameters were
      fitted, and `params` its fitted shading parameters.
    - `fitted`, `start`: the fitted parameters' values after and before, by name.
    - `held`: parameters a gauge held fixed, and `notes` saying why.
    - `history`: the loss (root mean square residual) after each step.
    - `iterations`, `converged`, `message`: how the solver ended.
    - `rms`: root mean square residual per view, in the loss's units
      (linear reflectance, or CIELAB units).
    - `loss`, `solver`: what was minimised and how; `seconds`: the time it took.
    - `start_params`: the parameters the fit started from.
    """

    scene: Scene
    params: Params
    fitted: dict[str, Any]
    start: dict[str, Any]
    held: tuple[str, ...]
    notes: list[str]
    history: list[float]
    iterations: int
    converged: bool
    message: str
    rms: list[float]
    loss: str
    solver: str
    seconds: float = 0.0
    start_params: Params | None = None

    def to_dict(self) -> dict[str, Any]:
        """Diagnostics, JSON-ready."""
        lst = lambda v: np.asarray(v, np.float64).round(8).tolist()  # noqa: E731
        return {"fitted": {k: lst(v) for k, v in self.fitted.items()},
                "start": {k: lst(v) for k, v in self.start.items()},
                "held_by_gauge": list(self.held), "notes": self.notes, "loss": self.loss, "solver": self.solver,
                "iterations": self.iterations, "converged": self.converged, "message": self.message,
                "rms_per_view": [float(r) for r in self.rms]}  # fmt: skip

    def save(self, path: str | os.PathLike) -> None:
        """Write the scene with the fitted parameters (`diffwash.save_scene`): `bake` and `export` take it."""
        save_scene(path, self.scene, self.params)


def load_cameras(path: str | os.PathLike, scene: Scene) -> list[Scene]:
    """One scene per camera of a camera list file: `[{"eye": [...], "target": [...], ...}, ...]`.

    Each camera object has the keys of a scene file's `camera`.
    """
    data = read_json(path)
    if isinstance(data, dict) and "cameras" in data:
        data = data["cameras"]
    if not isinstance(data, list) or not data:
        raise DiffwashError('must be a non-empty list of cameras (or {"cameras": [...]})', file=path)
    if scene.path is None:
        raise DiffwashError("a camera list needs a scene loaded from a file", file=path)
    src = read_json(scene.path)
    out = []
    for i, cam in enumerate(data):
        if not isinstance(cam, dict):
            raise DiffwashError(f"must be a camera object, got {type(cam).__name__}", file=path, field=f"[{i}]")
        try:
            out.append(parse_scene({**src, "camera": cam}, file=scene.path, shading=scene.shading,
                                   size=(scene.width, scene.height)))  # fmt: skip
        except DiffwashError as e:
            raise DiffwashError(e.problem, file=path, field=f"[{i}]" + (f".{e.field}" if e.field else "")) from None
    return out


def _read_target(target: Any, scene: Scene, index: int) -> np.ndarray:
    """A target as linear RGB (H, W, 3), checked against the scene's size."""
    if isinstance(target, (str, os.PathLike)):
        display, _ = read_image(target)
        where = os.fspath(target)
        linear = colorimetry.from_display(display)
    else:
        linear = np.asarray(target, np.float64)
        where = None
        if linear.ndim != 3 or linear.shape[2] not in (3, 4):
            raise DiffwashError(f"target {index} must be an (H, W, 3) linear image, got shape {linear.shape}")
        linear = linear[..., :3]
    h, w = linear.shape[:2]
    if (w, h) != (scene.width, scene.height):
        raise DiffwashError(f"is {w}x{h} pixels but the scene renders {scene.width}x{scene.height}; "
                            f"render the scene at the target's size or resize the target", file=where)  # fmt: skip
    if not np.all(np.isfinite(linear)):
        raise DiffwashError("has NaN or infinite values", file=where)
    return linear


def _make_solver(name: str, rtol: float, atol: float):
    if name == "lm":
        return optx.LevenbergMarquardt(rtol=rtol, atol=atol)
    if name == "gauss-newton":
        return optx.GaussNewton(rtol=rtol, atol=atol)
    if name == "dogleg":
        return optx.Dogleg(rtol=rtol, atol=atol)
    if name == "bfgs":
        return optx.BFGS(rtol=rtol, atol=atol)
    raise DiffwashError(f"unknown solver {name!r} (choose from {', '.join(SOLVERS)})", field="--solver")


class _View(eqx.Module):
    """One view's fixed part: the target and the renderer's `Surface` at the covered pixels.

    The geometry is not fitted, so the renderer's geometry steps (barycentrics,
    interpolation) run once per view. Padding entries of the covered-pixel list
    have `valid = False`.
    """

    target: Any
    valid: Any
    surface: Surface


def _prepare_view(scene: Scene, vis: Visibility, target: np.ndarray, dtype) -> _View:
    f = lambda a: jnp.asarray(np.asarray(a, dtype))  # noqa: E731
    mesh = scene.mesh
    return _geometry(f(mesh.vertices), f(mesh.normals), jnp.asarray(np.asarray(mesh.faces, np.int32)),
                     jax.tree.map(f, scene.camera), vis, np.bool_(not scene.cull_backfaces),
                     f(np.asarray(target).reshape(-1, 3)), width=scene.width, height=scene.height,
                     mode=scene.shading)  # fmt: skip


@functools.partial(jax.jit, static_argnames=("width", "height", "mode"))
def _geometry(vertices, normals, faces, camera, vis, both, target, *, width, height, mode) -> _View:
    pixels = vis.pixels
    valid = pixels < width * height
    surf, _ = surface(vertices, faces, normals, camera, vis, both, width=width, height=height, mode=mode)
    return _View(target=target[jnp.where(valid, pixels, 0)], valid=valid, surface=surf)


class _LookView(eqx.Module):
    """One view of a scene with a watercolour look: the target at the covered pixels and what
    `diffwash._render._look_kernel` needs besides the parameters (the geometry, the visibility, the
    scene's `Watercolour` and the shadow map's triangles, all fixed during the fit)."""

    target: Any
    valid: Any
    vertices: Any
    faces: Any
    normals: Any
    camera: Any
    vis: Visibility
    both: Any
    wc: Any
    light_tri: Any
    width: int = eqx.field(static=True)
    height: int = eqx.field(static=True)
    mode: str = eqx.field(static=True)


def _prepare_look_view(scene: Scene, vis: Visibility, target: np.ndarray, light: Any, dtype) -> _LookView:
    cast = lambda a: jnp.asarray(a, dtype) if np.asarray(a).dtype.kind == "f" else a  # noqa: E731
    mesh, wc = scene.mesh, scene.watercolour
    light_tri = shadow_triangles(mesh.vertices, mesh.faces, light) if wc.shadow else None
    pixels = vis.pixels
    valid = pixels < scene.width * scene.height
    target = jnp.asarray(np.asarray(target, dtype).reshape(-1, 3))[jnp.where(valid, pixels, 0)]
    return _LookView(target=target, valid=valid, vertices=cast(mesh.vertices), faces=jnp.asarray(np.asarray(mesh.faces, np.int32)),
                     normals=cast(mesh.normals), camera=jax.tree.map(cast, scene.camera), vis=vis,
                     both=np.bool_(not scene.cull_backfaces), wc=jax.tree.map(cast, wc), light_tri=light_tri,
                     **_kernel_statics(scene))  # fmt: skip


def _shade_look(view: _LookView, params: Params, look: wl.Look) -> Any:
    """Linear RGB at the view's covered pixels: `diffwash.render`'s watercolour look with `params` and `look`."""
    wc = eqx.tree_at(lambda w: w.look, view.wc, look)
    rgba = _look_kernel(view.vertices, view.faces, view.normals, view.camera, params, view.vis, view.both, wc,
                        view.light_tri, width=view.width, height=view.height, mode=view.mode, antialias=False)  # fmt: skip
    return rgba[..., :3].reshape(-1, 3)[jnp.where(view.valid, view.vis.pixels, 0)]


#: The inputs of `_glaze_terms`, in order.
_GLAZE_INPUTS = ("wash", "unlit", "wash.K", "wash.S", "unlit.K", "unlit.S", "paper")


def _varying(free: Sequence[str]) -> tuple[bool, ...]:
    """Which of `_GLAZE_INPUTS` depend on the fitted parameters `free` (the `varying` of `_glaze`).

    The thicknesses vary with the shading constants and the light; a glaze's K and S when fitted, or with
    its library mixture's proportions or amount; the paper when fitted.
    """
    thick = {"gain", "bias", "wash_reduction", "k_wash", "k_unlit", "k_specular", "shininess", "light"}
    moves = {f"{g}.{w}": {f"{g}.{w}", f"{g}.mix", f"{g}.amount"} for g in ("wash", "unlit") for w in ("K", "S")}
    return (bool(thick & set(free)),) * 2 + tuple(bool(moves.get(n, {n}) & set(free)) for n in _GLAZE_INPUTS[2:])


def _glaze(inputs: tuple[Any, ...], varying: tuple[bool, ...]) -> Any:
    r"""`shading.glaze`, arranged so that its derivative is cheap to push many tangents through.

    The colour at a pixel depends on the two thicknesses there and, channel by channel, on the
    pigments' K, S and the paper. So its Jacobian is a handful of per-pixel partial derivatives:
    they are computed once per evaluation with `jax.jvp` of `shading.glaze` itself (one pass per
    input that varies, a tangent of ones: channels do not mix), and the colour is written as

    $$ c = c_0 + \sum_i \partial_i c_0\,(x_i - \bar x_i) $$

    with $c_0$, $\partial_i c_0$ and $\bar x_i = x_i$ held constant (`stop_gradient`): the value is
    exactly the glaze and so is the first derivative, while each of the fit's tangents costs a
    multiply-add instead of a pass through Kubelka-Munk. (Second derivatives are not those of the
    glaze; the least-squares solvers use first derivatives only.)

    **Arguments:** `inputs` as `_GLAZE_INPUTS`; `varying` (static) says which of them depend on
    the fitted parameters.
    """
    sg = jax.lax.stop_gradient
    fixed = tuple(sg(jnp.asarray(a)) for a in inputs)
    out = _glaze_terms(*fixed)
    live = [i for i, v in enumerate(varying) if v]
    if not live:
        return out
    for i in live:
        # One jvp per varying input (separate passes: batching them with vmap is slower on the CPU).
        f = lambda x, i=i: _glaze_terms(*fixed[:i], x, *fixed[i + 1 :])  # noqa: E731
        partial = jax.jvp(f, (fixed[i],), (jnp.ones_like(fixed[i]),))[1]  # (P, 3)
        d = jnp.asarray(inputs[i]) - fixed[i]  # 0, with the input's derivative
        out = out + partial * (d[:, None] if i < 2 else d[None, :])
    return out


def _glaze_terms(wash, unlit, Kw, Sw, Ku, Su, paper):
    return shading.glaze(Params(wash=Pigment(K=Kw, S=Sw), unlit=Pigment(K=Ku, S=Su), paper=paper), wash, unlit)


def _shade(view: _View, params: Params, varying: tuple[bool, ...] = (True,) * 7) -> Any:
    """Linear RGB at the view's covered pixels: `diffwash.render`'s shading of the stored surface."""
    wash, unlit = surface_thicknesses(view.surface, params)
    inputs = (wash, unlit, params.wash.K, params.wash.S, params.unlit.K, params.unlit.S, params.paper)
    return shading.linear_srgb(params, _glaze(inputs, varying))  # spectral glazes: per band, then seen


class _Problem(eqx.Module):
    """Everything the residual function needs, as a pytree (one compile per shapes)."""

    views: tuple[_View | _LookView, ...]
    base: Params
    light_length: Any
    loss: str = eqx.field(static=True)
    varying: tuple[bool, ...] = eqx.field(static=True, default=(True,) * 7)
    look: Any = None


def _residuals(y: dict[str, Any], problem: _Problem) -> Any:
    params = _decode(y, problem.base, problem.light_length)
    look = _decode_look(y, problem.look)
    parts = []
    for view in problem.views:
        if isinstance(view, _LookView):
            img = _shade_look(view, params, look)
        else:
            img = _shade(view, params, problem.varying)
        if problem.loss == "lab":
            d = colorimetry.linear_srgb_to_lab(img) - colorimetry.linear_srgb_to_lab(view.target)
        else:
            d = img - view.target
        parts.append(jnp.where(view.valid[:, None], d, 0).ravel())
    return jnp.concatenate(parts)


def fit_image(
    targets: Any,
    scenes: Any,
    fit: str | Sequence[str] = ("gain", "bias", "k_wash", "k_unlit", "shininess"),
    *,
    start: Params | None = None,
    loss: str = "linear",
    solver: str = "lm",
    max_steps: int = 100,
    rtol: float | None = None,
    atol: float | None = None,
    gtol: float | None = None,
    progress: bool | Callable[[int, float], None] = False,
) -> ImageFit:
    """Fit scene parameters to target images.

    **Arguments:**

    - `targets`: a target image (path of a PNG/JPEG, sRGB; or an (H, W, 3)
      array of linear RGB), or a list of them, one per view.
    - `scenes`: a `Scene` or scene path, or a list matching `targets` (one per
      view: their geometry and cameras; the shading parameters are shared and
      taken from the first).
    - `fit`: the parameter names (see `FITTABLE`), a list or comma-separated text;
      look parameters (`watercolour.edges.darkening`, ...) need the scenes' look
      to have that effect on; a mixture's (`wash.mix`, `wash.amount`, ...) need
      that glaze to be a mixture of library pigments.
    - `start`: starting parameters (default: the first scene's).
    - `loss`: `"linear"` (linear RGB) or `"lab"` (CIELAB).
    - `solver`: `"lm"` (Levenberg-Marquardt), `"gauss-newton"`, `"dogleg"` or `"bfgs"`.
    - `max_steps`: solver steps at most.
    - `rtol`, `atol`: the solver's step tolerances (default 1e-6, or 1e-4 in float32).
    - `gtol`: the stationarity tolerance (default as `rtol`): the fit has converged
      when no parameter direction has a cosine above `gtol` with the residuals.
    - `progress`: print the loss at each step (True), or call `progress(step, loss)`.

    **Returns:**

    An `ImageFit` (its `save` writes the fitted scene). Not converging (the
    solver's step test and the stationarity test both unmet after `max_steps`)
    is reported in the result (`converged`, `message`), not raised.
    """
    relieve_compiled_programs()  # before this fit compiles: a long-lived process may run out of memory maps
    t_start = time.perf_counter()
    names = parse_fit_list(fit)
    if loss not in IMAGE_LOSSES:
        raise DiffwashError(f"unknown loss {loss!r} (choose from {', '.join(IMAGE_LOSSES)})", field="--loss")
    if solver not in SOLVERS:
        raise DiffwashError(f"unknown solver {solver!r} (choose from {', '.join(SOLVERS)})", field="--solver")
    target_list = list(targets) if isinstance(targets, (list, tuple)) else [targets]
    scene_list = list(scenes) if isinstance(scenes, (list, tuple)) else [scenes]
    scene_list = [load_scene(s) if isinstance(s, (str, os.PathLike)) else s for s in scene_list]
    if len(scene_list) == 1 and len(target_list) > 1:
        scene_list = scene_list * len(target_list)
    if len(scene_list) != len(target_list):
        raise DiffwashError(f"got {len(target_list)} targets but {len(scene_list)} scenes: give one scene per target "
                            f"(or one for all)", field="--scene")  # fmt: skip
    for n in (n for n in names if n in LOOK_PARAMETERS):
        for s in scene_list:
            look_parameter_check(n, s.watercolour, s.path)
    free, notes = _gauges(names)
    held = tuple(n for n in names if n not in free)
    base = start if start is not None else scene_list[0].params
    check_fittable(base, names)
    wc0 = scene_list[0].watercolour
    base_look = None if wc0 is None else wc0.look
    dtype = jnp.zeros(()).dtype
    views = _views(target_list, scene_list, base, dtype)
    light_length = float(np.linalg.norm(np.asarray(base.light, np.float64)))
    cast = lambda a: jnp.asarray(a, dtype) if np.asarray(a).dtype.kind == "f" else a  # noqa: E731
    problem = _Problem(views=tuple(views), base=jax.tree.map(cast, base), light_length=jnp.asarray(light_length, dtype),
                       loss=loss, varying=_varying(free), look=jax.tree.map(cast, base_look))  # fmt: skip
    y0 = {k: jnp.asarray(v, dtype) for k, v in _encode(base, free, base_look).items()}
    tol = 1e-6 if dtype == jnp.float64 else 1e-4
    opt = _make_solver(solver, rtol if rtol is not None else tol, atol if atol is not None else tol)
    y, history, steps, result, r = _iterate(opt, y0, problem, max_steps, progress, gtol if gtol is not None else tol)
    converged = not isinstance(result, str) and bool(result == optx.RESULTS.successful)
    message = "converged" if converged else (result if isinstance(result, str) else optx.RESULTS[result])
    params = _decode_jit(y, base, light_length)
    r = np.asarray(_residual_jit(y, problem) if r is None else r, np.float64)
    rms, off = [], 0
    for view in views:
        n = view.target.size
        used = 3 * int(np.sum(np.asarray(view.valid)))
        rms.append(float(np.sqrt(np.sum(r[off : off + n] ** 2) / used)))
        off += n
    to_np = lambda a: np.asarray(a, np.float64) if isinstance(a, jax.Array) else a  # noqa: E731
    look = jax.tree.map(to_np, _decode_look(y, base_look))
    fitted = {n: np.asarray(_get(params, n, look)) for n in names}
    started = {n: np.asarray(_get(base, n, base_look)) for n in names}
    params = jax.tree.map(to_np, params)
    fits_look = any(n in LOOK_PARAMETERS for n in free)
    scene = eqx.tree_at(lambda sc: sc.watercolour.look, scene_list[0], look) if fits_look else scene_list[0]
    return ImageFit(scene=scene, params=params,
                    fitted=fitted, start=started, held=held, notes=notes, history=history, iterations=steps,
                    converged=bool(converged), message=str(message), rms=rms, loss=loss, solver=solver,
                    seconds=time.perf_counter() - t_start, start_params=base)  # fmt: skip


def _views(target_list: list, scene_list: list[Scene], base: Params, dtype) -> list[_View | _LookView]:
    """Each view's fixed part: the plain model's `_View`, or a `_LookView` for a scene with a watercolour look."""
    views = []
    for i, (t, s) in enumerate(zip(target_list, scene_list)):
        linear = _read_target(t, s, i)
        vis = rasterize(s)
        if not np.any(np.asarray(vis.tri_id) >= 0):
            raise DiffwashError(f"the object covers no pixel of view {i}: nothing to compare", file=s.path)
        if s.watercolour is not None:
            views.append(_prepare_look_view(s, vis, linear, np.asarray(base.light, np.float64), dtype))
        else:
            views.append(_prepare_view(s, vis, linear, dtype))
    return views


_residual_jit = jax.jit(_residuals)
_decode_jit = eqx.filter_jit(_decode)


def _is_least_squares(solver: Any) -> bool:
    return isinstance(solver, optx.AbstractLeastSquaresSolver)


@eqx.filter_jit
def _init(solver, y, problem):
    fn = _objective(solver)
    f_struct, aux_struct = jax.eval_shape(lambda: fn(y, problem))
    return solver.init(fn, y, problem, {}, f_struct, aux_struct, frozenset())


@eqx.filter_jit
def _step(solver, y, problem, state):
    fn = _objective(solver)
    y, state, _ = solver.step(fn, y, problem, {}, state, frozenset())
    done, result = solver.terminate(fn, y, problem, {}, state, frozenset())
    # The stationarity test costs a Jacobian: only after a rejected step (an accepted one has the solver's test).
    rejected = getattr(state, "num_steps_since_acceptance", jnp.array(1)) > 0
    loss = _state_loss(state)
    stationarity = jax.lax.cond(rejected, lambda: _stationarity(state).astype(loss.dtype),
                                lambda: jnp.asarray(jnp.inf, loss.dtype))  # fmt: skip
    return y, state, done, result, loss, stationarity


def _stationarity(state: Any) -> Any:
    r"""How far the last accepted point is from a stationary point, scale-free (0 at an optimum).

    Least squares: the largest cosine between the residual vector and a column of its Jacobian,
    $\max_j |J_j^T r| / (\|J_j\| \|r\|)$ (MINPACK's `gtol` test, Moré et al. 1980): at a minimum
    the residuals are orthogonal to every direction the parameters can move them in. 0 when the
    residuals vanish. Minimisers: the largest gradient component relative to the loss.
    """
    info = state.f_info
    if hasattr(info, "residual"):
        r = info.residual
        J = info.jac.as_matrix()
        g = J.T @ r
        scale = jnp.linalg.norm(J, axis=0) * jnp.linalg.norm(r)
        cos = jnp.abs(g) / jnp.where(scale > 0, scale, 1.0)
        return jnp.where(jnp.linalg.norm(r) > 0, jnp.max(cos), 0.0)
    g = jax.flatten_util.ravel_pytree(info.grad)[0]
    return jnp.max(jnp.abs(g)) / jnp.maximum(jnp.abs(info.f), 1e-30)


def _objective(solver):
    if _is_least_squares(solver):
        return lambda y, problem: (_residuals(y, problem), None)

    def scalar(y, problem):
        r = _residuals(y, problem)
        return 0.5 * jnp.sum(r * r), None

    return scalar


def _state_loss(state: Any) -> Any:
    info = state.f_info
    if hasattr(info, "residual"):
        r = info.residual
        return jnp.sqrt(jnp.mean(r * r))
    return jnp.asarray(info.f)


def _iterate(solver, y0, problem, max_steps: int, progress, gtol: float) -> tuple[Any, list[float], int, Any, Any]:
    """Step the solver by hand, through its public `init`, `step` and `terminate`, so that each step's loss
    can be shown and the stationarity test can end the fit: `optimistix.least_squares` and `minimise` offer
    neither (docs/fitting.md, "Why the fit steps the solver itself").

    Converged when the solver's own test passes (optimistix's Cauchy test: a small step in both the
    parameters and the residuals, relative `rtol` plus absolute `atol`), or, after a rejected step, when
    the last accepted point is stationary to within `gtol` (`_stationarity`: where float rounding keeps
    the solver rejecting ever smaller steps at the minimum). Otherwise, after `max_steps`, not converged.
    """
    state = _init(solver, y0, problem)
    y = y0
    history: list[float] = []
    report = progress if callable(progress) else (_print_progress if progress else None)
    result: Any = f"did not converge in {max_steps} steps"
    steps = 0
    minimiser = not _is_least_squares(solver)
    n_all = sum(int(v.target.size) for v in problem.views)
    n_used = sum(3 * int(np.sum(np.asarray(v.valid))) for v in problem.views)  # without the padding
    for steps in range(1, max_steps + 1):
        y, state, done, solver_result, loss, stationarity = _step(solver, y, problem, state)
        value = float(loss)
        if minimiser:  # 0.5 sum r^2 -> root mean square
            value = math.sqrt(max(2 * value / n_used, 0.0))
        else:
            value = value * math.sqrt(n_all / n_used)
        history.append(value)
        if report is not None:
            report(steps, value)
        if bool(done):
            result = solver_result
            break
        if float(stationarity) <= gtol:
            result = optx.RESULTS.successful
            break
    # The residuals at the solution, from the solver's own state (least-squares solvers keep them).
    residual = getattr(state.f_info, "residual", None) if not minimiser else None
    return y, history, steps, result, residual


def _print_progress(step: int, loss: float) -> None:
    print(f"  step {step:3d}  loss (rms) {loss:.6g}", flush=True)

