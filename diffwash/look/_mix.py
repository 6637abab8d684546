r"""More than one shade per surface: a pigment mix that varies across the surface, and its 3D LUT.

The seed's LUT is a function of the two thicknesses only, so "objects can
have only one shade of color over their entire surface". Here each glaze is a
mixture of two pigments in a proportion `m` in [0, 1] that varies over the
surface (a per-vertex *mix map*, interpolated like the normals; a texture map
works the same way). By Duncan's mixing law a mixture's absorption and
scattering are the concentration-weighted means of its pigments':

$$ K(m) = (1 - m) K_a + m K_b, \qquad S(m) = (1 - m) S_a + m S_b, $$

for the wash (`wash` -> `wash_b`) and the unlit glaze (`unlit` -> `unlit_b`)
alike; `glaze_mix` is `diffwash.shading.glaze` of the mixtures.

**The real-time form** is a 3D LUT over (wash, unlit, mix): `bake_mix_lut`
evaluates any `glaze(params, wash, unlit, mix)` on the grid (a pure function,
as `diffwash.lut.bake` is for the 2D table), `lookup_mix_lut` is the
trilinear lookup a `sampler3D` does with the same texel-centre convention as
the 2D LUT (docs/realtime.md; the shaders' `sampler3D` returns the same), and `mix_lut_error` measures what a size
costs against the exact glaze. docs/watercolour.md has the table; at
64 x 64 x 16 the error is below an 8-bit level. A mix between two *colours*
(two 2D LUTs blended) is not the same (`blended_pair_error`): mixing pigments
is not mixing their colours.

**References:**

- D. R. Duncan, "The colour of pigment mixtures", Proc. Phys. Soc. 52 (1940).
- C. J. Curtis et al., "Computer-Generated Watercolor", SIGGRAPH 1997, sec. 5.
- G. Smedresman, "Hardware Accelerated Pigment-Based Rendering System"
  ("objects can have only one shade of color over their entire surface").
"""

from __future__ import annotations

from collections.abc import Callable
import dataclasses
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from .. import shading
from .._errors import DiffwashError
from ..colorimetry import to_display as srgb_encode
from ..pigments import Pigment

__all__ = [
    "mix_coefficients",
    "glaze_mix",
    "bake_mix_lut",
    "lookup_mix_lut",
    "mix_lut_error",
    "blended_pair_error",
    "check_mix_map",
    "mix_along_axis",
]


def mix_coefficients(a: Any, b: Any, mix: Float[ArrayLike, "*b"]) -> tuple[Float[Array, "*b 3"], Float[Array, "*b 3"]]:
    """`K` and `S` of the mixture `(1 - mix) a + mix b` of two pigments (Duncan's law)."""
    m = jnp.asarray(mix)[..., None]
    K = (1 - m) * jnp.asarray(a.K) + m * jnp.asarray(b.K)
    S = (1 - m) * jnp.asarray(a.S) + m * jnp.asarray(b.S)
    return K, S


def glaze_mix(
    params: Any,
    wash_b: Any,
    unlit_b: Any,
    wash: Float[ArrayLike, "*b"],
    unlit: Float[ArrayLike, "*b"],
    mix: Float[ArrayLike, "*b"],
) -> Float[Array, "*b 3"]:
    """Linear RGB of the unlit glaze on the wash glaze on the paper, each glaze a mixture.

    **Arguments:**

    - `params`: the shading `Params` (`params.wash`, `params.unlit`: the
      pigments at `mix = 0`; `params.paper`).
    - `wash_b`, `unlit_b`: the pigments at `mix = 1`.
    - `wash`, `unlit`: thicknesses; `mix`: the proportion of the `_b`
      pigments, in [0, 1].

    **Returns:**

    `(*b, 3)`; at `mix = 0` exactly `diffwash.shading.glaze(params, wash, unlit)`.
    Differentiable in everything (pigments, paper, thicknesses, mix).
    """
    Kw, Sw = mix_coefficients(params.wash, wash_b, mix)
    Ku, Su = mix_coefficients(params.unlit, unlit_b, mix)
    mixed = dataclasses.replace(params, wash=Pigment(K=Kw, S=Sw), unlit=Pigment(K=Ku, S=Su), paper=jnp.asarray(params.paper))
    return shading.glaze(mixed, wash, unlit)  # the model's own glaze, of the mixtures


def _grid(size: tuple[int, int, int], wash_max: float, unlit_max: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    n, m, p = size
    return np.arange(n) / (n - 1) * wash_max, np.arange(m) / (m - 1) * unlit_max, np.arange(p) / (p - 1)


def bake_mix_lut(
    glaze: Callable[..., Any],
    params: Any,
    size: tuple[int, int, int] = (64, 64, 16),
    *,
    wash_max: float,
    unlit_max: float,
) -> np.ndarray:
    """Evaluate `glaze(params, wash, unlit, mix)` on the 3D grid: the table a `sampler3D` holds.

    **Arguments:**

    - `glaze`: any `(params, wash, unlit, mix) -> (*b, C)` (e.g. `glaze_mix`
      with the `_b` pigments bound, or a spectral model's).
    - `params`: passed through.
    - `size`: `(N, M, P)` samples of wash, unlit and mix, each >= 2.
    - `wash_max`, `unlit_max`: the thickness of the last column and row.

    **Returns:**

    `(P, M, N, C)` float32: slice `k` holds mix `k / (P - 1)`, row `j` unlit
    `j / (M - 1) * unlit_max`, column `i` wash `i / (N - 1) * wash_max` (the
    2D LUT's convention, one slice per mix value).
    """
    size = tuple(int(s) for s in size)
    if len(size) != 3 or min(size) < 2:
        raise DiffwashError(f"must be three sizes (wash, unlit, mix), each >= 2, got {size}", field="size")
    w, u, m = _grid(size, float(wash_max), float(unlit_max))
    M, U, W = np.meshgrid(m, u, w, indexing="ij")
    evaluate = jax.jit(glaze)
    dtype = jnp.zeros(()).dtype
    out = evaluate(params, W.astype(dtype), U.astype(dtype), M.astype(dtype))
    out = np.asarray(out, np.float32)
    if not np.all(np.isfinite(out)):
        raise DiffwashError("the glaze is not finite on the grid (NaN or inf)", field="pigments")
    return out


def _axis(t: Array, n: int) -> tuple[Array, Array, Array]:
    x = jnp.clip(t, 0.0, 1.0) * (n - 1)
    i0 = jnp.minimum(jnp.floor(x), n - 2)
    f = x - i0
    i0 = i0.astype(jnp.int32)
    return i0, i0 + 1, f


def _unit(x: Array, top: float) -> Array:
    if top <= 0:
        return jnp.zeros_like(x)
    return x / top


def lookup_mix_lut(
    table: Float[ArrayLike, "P M N C"],
    wash: Float[ArrayLike, "*b"],
    unlit: Float[ArrayLike, "*b"],
    mix: Float[ArrayLike, "*b"],
    *,
    wash_max: float,
    unlit_max: float,
) -> Float[Array, "*b C"]:
    """Trilinear lookup at texel centres, clamped to the table: what the look's shaders' `sampler3D` returns.

    Differentiable in `wash`, `unlit`, `mix` (piecewise linear) and in `table`.
    """
    table = jnp.asarray(table)
    P, M, N = table.shape[:3]
    wash, unlit, mix = jnp.broadcast_arrays(jnp.asarray(wash), jnp.asarray(unlit), jnp.asarray(mix))
    x0, x1, fx = _axis(_unit(wash, wash_max), N)
    y0, y1, fy = _axis(_unit(unlit, unlit_max), M)
    z0, z1, fz = _axis(mix, P)
    fx, fy, fz = fx[..., None], fy[..., None], fz[..., None]

    def plane(z):
        top = table[z, y0, x0] * (1 - fx) + table[z, y0, x1] * fx
        bottom = table[z, y1, x0] * (1 - fx) + table[z, y1, x1] * fx
        return top * (1 - fy) + bottom * fy

    return plane(z0) * (1 - fz) + plane(z1) * fz


def mix_lut_error(
    glaze: Callable[..., Any],
    params: Any,
    size: tuple[int, int, int],
    *,
    wash_max: float,
    unlit_max: float,
    samples: int = 20000,
    seed: int = 0,
) -> dict[str, float]:
    """How far the baked 3D LUT is from the glaze it tabulates, at random points of its range.

    **Returns:**

    `{"max", "rms"}`: the largest and the root-mean-square difference of the
    display sRGB values, in 8-bit levels (1 = one level of 255), and
    `"bytes"`: the table's size as RGBA8 texels.
    """
    table = bake_mix_lut(glaze, params, size, wash_max=wash_max, unlit_max=unlit_max)
    rng = np.random.default_rng(seed)
    w = rng.uniform(0, wash_max, samples)
    u = rng.uniform(0, unlit_max, samples)
    m = rng.uniform(0, 1, samples)
    exact = np.asarray(jax.jit(glaze)(params, w, u, m), np.float64)
    got = np.asarray(lookup_mix_lut(table, w, u, m, wash_max=wash_max, unlit_max=unlit_max), np.float64)
    d = np.abs(srgb_encode(got) - srgb_encode(exact)) * 255
    return {"max": float(d.max()), "rms": float(np.sqrt(np.mean(d**2))), "bytes": float(np.prod(size) * 4)}


def blended_pair_error(
    glaze: Callable[..., Any], params: Any, *, wash_max: float, unlit_max: float, samples: int = 20000, seed: int = 0
) -> dict[str, float]:
    """The error of mixing *colours* instead of pigments: `(1 - m) glaze(.., 0) + m glaze(.., 1)` against `glaze(.., m)`.

    What two exact 2D LUTs blended in a shader would give (no table error at
    all). Same units as `mix_lut_error`.
    """
    rng = np.random.default_rng(seed)
    w = rng.uniform(0, wash_max, samples)
    u = rng.uniform(0, unlit_max, samples)
    m = rng.uniform(0, 1, samples)
    f = jax.jit(glaze)
    exact = np.asarray(f(params, w, u, m), np.float64)
    ends = [np.asarray(f(params, w, u, np.full_like(m, e)), np.float64) for e in (0.0, 1.0)]
    got = (1 - m)[:, None] * ends[0] + m[:, None] * ends[1]
    d = np.abs(srgb_encode(got) - srgb_encode(exact)) * 255
    return {"max": float(d.max()), "rms": float(np.sqrt(np.mean(d**2)))}


def check_mix_map(mix: Any, n_vertices: int, *, file: Any = None, field: str = "watercolour.mix") -> np.ndarray:
    """A per-vertex mix map as float32 `(V,)` in [0, 1], or a one-line `DiffwashError` naming the file and key.

    Refused: a shape that does not match the mesh's vertex count, non-finite
    values, values outside [0, 1].
    """
    a = np.asarray(mix, np.float64)
    if a.ndim != 1 or a.shape[0] != n_vertices:
        raise DiffwashError(f"a mix map needs one value per vertex ({n_vertices}), got shape {a.shape}", file=file, field=field)
    if not np.all(np.isfinite(a)):
        raise DiffwashError("a mix map must be finite (found NaN or inf)", file=file, field=field)
    if a.min() < 0 or a.max() > 1:
        raise DiffwashError(f"a mix map must lie in [0, 1], got [{a.min():.4g}, {a.max():.4g}]", file=file, field=field)
    return a.astype(np.float32)


def mix_along_axis(vertices: np.ndarray, axis: Any, *, softness: float = 0.25) -> np.ndarray:
    """A procedural mix map: a smooth ramp from 0 to 1 along `axis` across the mesh (smoothstep of the projection).

    `softness` is the ramp's width as a fraction of the mesh's extent along the axis.
    """
    v = np.asarray(vertices, np.float64)
    a = np.asarray(axis, np.float64)
    a = a / np.linalg.norm(a)
    t = v @ a
    lo, hi = t.min(), t.max()
    mid, half = (lo + hi) / 2, max(softness, 1e-6) * (hi - lo) / 2
    x = np.clip((t - mid) / (2 * half) + 0.5, 0, 1)
    return (x * x * (3 - 2 * x)).astype(np.float32)
