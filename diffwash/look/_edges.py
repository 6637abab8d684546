r"""Edge darkening: pigment gathers where a wash ends.

As a wash dries, water evaporates fastest at its edge and the flow it draws
carries pigment there (Curtis et al. 1997, sec. 2 and 4.3; Deegan's coffee
ring). In image space this is the excess of a glaze's thickness over its
local average (Bousseau et al. 2006's and Montesdeoca et al.'s edge darkening
is the same difference of a value and its blur, applied to colour there):

$$ e = \max(t - \bar t, 0), \qquad t' = t + k_e\, e, $$

with $\bar t$ the thickness blurred by a Gaussian of standard deviation
$\sigma$ (the `edge_width`, in pixels) and $k_e$ the `edge_darkening`
strength. Inside a wash of even thickness $t_0$, $e$ rises to $t_0/2$ at its
boundary (a silhouette, the rim of a reserved highlight, the edge of the unlit
glaze where `gain` makes it sharp) and falls to 0 about $2\sigma$ inside;
outside the wash $t = 0$ stays 0.

**Real-time form.** So that a GLSL pass can do exactly what the JAX version
does, and cheaply, the blur is fixed-radius, separable and evaluated at a
reduced resolution:

1. `downsample`: the mean of each `f x f` block of pixels (the image padded by
   repeating its last row and column), `f = edge_downsample(height)` (2 at
   512^2, 4 at 1024^2: the grid is about 256 pixels tall);
2. `blur`: a separable Gaussian of $\sigma / f$ low-resolution pixels with
   `2 EDGE_RADIUS + 1` taps per axis, clamped to the edge, weights normalised
   (`gaussian_weights`; $\sigma = 0$ gives the identity);
3. `upsample`: bilinear interpolation at the full-resolution pixel centres
   (low-resolution coordinate `(x + 0.5) / f - 0.5`, clamped to the edge), as
   a GPU's linear filtering does.

Each step is defined at pixel centres, so that the look's shaders
(`diffwash._look_glsl.glsl_edge_passes`) give the same numbers with `texelFetch`,
and `texture` for the final bilinear sample, whose weights are multiples of
`1 / (2 f)`, exact on any GPU. The darkening itself (`edge_darken`) is written
once, for JAX and for the shaders alike.

**References:**

- C. J. Curtis, S. E. Anderson, J. E. Seims, K. W. Fleischer and D. H. Salesin,
  "Computer-Generated Watercolor", SIGGRAPH 1997, sec. 4.3 (edge darkening).
- A. Bousseau, M. Kaplan, J. Thollot and F. X. Sillion, "Interactive watercolor
  rendering with temporal coherence and abstraction", NPAR 2006, sec. 3.3.
- S. E. Montesdeoca, H. S. Seah, H.-M. Rall and D. Benvenuti, "Art-directed
  watercolor stylization of 3D animations in real-time", Computers & Graphics
  66 (2017), sec. 5 (edge darkening as a blurred difference).
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from .._xp import namespace, shader_function

__all__ = [
    "EDGE_RADIUS",
    "EDGE_DOWNSAMPLE",
    "EDGE_GRID",
    "edge_downsample",
    "gaussian_weights",
    "gaussian_weights_np",
    "downsample",
    "blur",
    "upsample",
    "local_mean",
    "edge_darken",
    "edge_darkening",
]

#: Taps on each side of the centre in the separable blur (2 * EDGE_RADIUS + 1 per axis): enough for a
#: sigma of 1.6 low-resolution pixels at 2.5 sigma, i.e. edge widths up to 3 (256^2 image) to 13
#: (2048^2) pixels; wider edges are cut off.
EDGE_RADIUS = 4
#: The blur runs on a grid this many times coarser than the image, in each direction, for a 512^2
#: image (`edge_downsample` gives it for any size).
EDGE_DOWNSAMPLE = 2
#: The blur's grid is about this many pixels tall, whatever the image's size (so its cost is too).
EDGE_GRID = 256


def edge_downsample(height: int) -> int:
    """The blur's reduction for an image `height` pixels tall: the power of two nearest `height / 256`, at least 1.

    512 -> 2, 1024 -> 4, 2048 -> 8, 256 or less -> 1: the blur always runs on a grid about
    `EDGE_GRID` pixels tall, so it costs the same at any resolution (on llvmpipe a half-resolution
    blur at 1024^2 alone took two thirds of the plain model's frame time).
    """
    return 1 << max(0, round(math.log2(max(height, 1) / EDGE_GRID)))


def gaussian_weights(sigma: Float[ArrayLike, ""], radius: int = EDGE_RADIUS) -> Float[Array, " n"]:
    r"""Normalised Gaussian weights at the integer offsets `-radius .. radius`.

    $w_i \propto \exp(-i^2 / (2\sigma^2))$, summing to 1; differentiable in
    `sigma`. `sigma <= 0` gives the identity `(0, ..., 1, ..., 0)` with a zero
    gradient (the double-where: the exponent never sees `sigma = 0`).
    """
    sigma = jnp.asarray(sigma)
    i = jnp.arange(-radius, radius + 1, dtype=jnp.result_type(sigma, float))
    ok = sigma > 0
    s = jnp.where(ok, sigma, 1.0)
    w = jnp.exp(-0.5 * (i / s) ** 2)
    w = w / jnp.sum(w)
    return jnp.where(ok, w, (i == 0).astype(w.dtype))


def gaussian_weights_np(sigma: float, radius: int = EDGE_RADIUS) -> np.ndarray:
    """`gaussian_weights` in NumPy float64: what a host program uploads as the shader's weights."""
    i = np.arange(-radius, radius + 1, dtype=np.float64)
    if not sigma > 0:
        return (i == 0).astype(np.float64)
    w = np.exp(-0.5 * (i / float(sigma)) ** 2)
    return w / w.sum()


def _low_size(n: int, factor: int) -> int:
    return -(-n // factor)


def downsample(x: Float[ArrayLike, "H W *C"], factor: int = EDGE_DOWNSAMPLE) -> Float[Array, "h w *C"]:
    """The mean of each `factor x factor` block, the image padded by repeating its last row and column.

    **Returns:** `(ceil(H / factor), ceil(W / factor), *C)`.
    """
    x = jnp.asarray(x)
    if factor == 1:
        return x
    H, W = x.shape[:2]
    h, w = _low_size(H, factor), _low_size(W, factor)
    pad = [(0, h * factor - H), (0, w * factor - W)] + [(0, 0)] * (x.ndim - 2)
    x = jnp.pad(x, pad, mode="edge")
    # A sum of strided slices (elementwise work for XLA; a reshape-and-mean lays the data out badly).
    total = sum(x[a::factor, b::factor] for a in range(factor) for b in range(factor))
    return total * (1.0 / (factor * factor))


def _blur_axis(x: Array, weights: Array, axis: int) -> Array:
    radius = (weights.shape[0] - 1) // 2
    n = x.shape[axis]
    pad = [(0, 0)] * x.ndim
    pad[axis] = (radius, radius)
    p = jnp.pad(x, pad, mode="edge")
    out = None
    for k in range(2 * radius + 1):
        term = weights[k] * _slice(p, k, n, axis)
        out = term if out is None else out + term
    return out


def _slice(x: Array, start: int, size: int, axis: int) -> Array:
    """`x` sliced to `[start, start + size)` along `axis` (a static slice)."""
    index = [slice(None)] * x.ndim
    index[axis] = slice(start, start + size)
    return x[tuple(index)]


def blur(x: Float[ArrayLike, "h w *C"], sigma: Float[ArrayLike, ""], radius: int = EDGE_RADIUS) -> Float[Array, "h w *C"]:
    """Separable Gaussian blur (`gaussian_weights(sigma, radius)`), rows then columns, clamped to the edge."""
    x = jnp.asarray(x)
    w = gaussian_weights(sigma, radius).astype(x.dtype)
    return _blur_axis(_blur_axis(x, w, 1), w, 0)


def _upsample_axis(x: Array, n_out: int, factor: int, axis: int) -> Array:
    """Bilinear upsampling along one axis at the pixel centres, clamped to the edge (static slices, no gather).

    Output `f i + k` sits at low-resolution coordinate `i + t_k`, `t_k = (k + 1/2)/f - 1/2`, so it is
    `(1 - a_k) x[i + o_k] + a_k x[i + o_k + 1]` with `o_k = floor(t_k)`, `a_k = t_k - o_k`: `factor`
    shifted slices of the edge-padded input, interleaved.
    """
    n = x.shape[axis]
    pad = [(0, 0)] * x.ndim
    pad[axis] = (1, 1)
    p = jnp.pad(x, pad, mode="edge")
    phases = []
    for k in range(factor):
        t = (k + 0.5) / factor - 0.5
        o = math.floor(t)
        a = t - o
        lo, hi = _slice(p, o + 1, n, axis), _slice(p, o + 2, n, axis)
        phases.append(lo if a == 0 else (1 - a) * lo + a * hi)
    y = jnp.stack(phases, axis=axis + 1)
    shape = list(x.shape)
    shape[axis] = n * factor
    return _slice(y.reshape(shape), 0, n_out, axis)


def upsample(x: Float[ArrayLike, "h w *C"], height: int, width: int, factor: int = EDGE_DOWNSAMPLE) -> Float[Array, "H W *C"]:
    """Bilinear interpolation of a low-resolution image at the pixel centres of a `height x width` one.

    Low-resolution coordinate `(x + 0.5) / factor - 0.5` per axis, indices
    clamped to the edge: what a GPU's linear filtering with clamp-to-edge
    returns at those points.
    """
    x = jnp.asarray(x)
    if factor == 1:
        return x[:height, :width]
    return _upsample_axis(_upsample_axis(x, height, factor, 0), width, factor, 1)


def local_mean(
    x: Float[ArrayLike, "H W *C"], sigma: Float[ArrayLike, ""], factor: int = EDGE_DOWNSAMPLE, radius: int = EDGE_RADIUS
) -> Float[Array, "H W *C"]:
    """`upsample(blur(downsample(x), sigma / factor))`: the Gaussian-weighted neighbourhood mean at each pixel."""
    x = jnp.asarray(x)
    H, W = x.shape[:2]
    # The barriers keep XLA from fusing the blur into the upsampling's consumers, which would
    # recompute its taps for every output pixel (several times slower on a CPU).
    low = jax.lax.optimization_barrier(blur(downsample(x, factor), jnp.asarray(sigma) / factor, radius))
    return jax.lax.optimization_barrier(upsample(low, H, W, factor))


@shader_function("look_edge_darken", [("t", "float"), ("mean", "float")], "float")
def edge_darken(t: Float[ArrayLike, "*b C"], mean: Float[ArrayLike, "*b C"], strength: Float[ArrayLike, ""]) -> Float[Array, "*b C"]:
    r"""The darkening at one pixel, given its local mean: $t + k_e \max(t - \bar t, 0)$ (`strength` $= k_e$)."""
    xp = namespace(t, mean, strength)
    t, mean = xp.asfloat(t, mean)
    d = t - mean
    return t + strength * xp.where(d > 0, d, 0.0)


def edge_darkening(
    thickness: Float[ArrayLike, "H W *C"],
    strength: Float[ArrayLike, ""],
    width: Float[ArrayLike, ""],
    *,
    factor: int = EDGE_DOWNSAMPLE,
    radius: int = EDGE_RADIUS,
    mean: Float[ArrayLike, "H W *C"] | None = None,
) -> Float[Array, "H W *C"]:
    r"""Pigment gathered where a glaze ends: $t + k_e \max(t - \bar t, 0)$.

    **Arguments:**

    - `thickness`: glaze thickness maps (e.g. `(H, W, 2)` wash and unlit), 0
      where nothing is painted.
    - `strength`: $k_e$ (0: off); differentiable.
    - `width`: the blur's $\sigma$ in pixels; differentiable. At 0 the
      reduced grid's own resampling remains (an edge about `factor` pixels
      wide; none at `factor = 1`): `strength = 0` is what turns it off.
    - `factor`, `radius`: the blur's reduction and taps (static).
    - `mean`: $\bar t$ if already computed (`local_mean`).

    **Returns:**

    The darkened thickness, same shape.
    """
    t = jnp.asarray(thickness)
    m = local_mean(t, width, factor, radius) if mean is None else jnp.asarray(mean)
    return edge_darken(t, m, strength)


