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
   repeating its last row and column), `f = EDGE_DOWNSAMPLE`;
2. `blur`: a separable Gaussian of $\sigma / f$ low-resolution pixels with
   `2 EDGE_RADIUS + 1` taps per axis, clamped to the edge, weights normalised
   (`gaussian_weights`; $\sigma = 0$ gives the identity);
3. `upsample`: bilinear interpolation at the full-resolution pixel centres
   (low-resolution coordinate `(x + 0.5) / f - 0.5`, clamped to the edge), as
   a GPU's linear filtering does.

Each step is defined at pixel centres: `glsl_edge_passes` gives the three
passes (`texelFetch`, and `texture` for the final bilinear sample, whose
weights are multiples of `1 / (2 f)`, exact on any GPU).

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

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from ._gl import float_literal

__all__ = [
    "EDGE_RADIUS",
    "EDGE_DOWNSAMPLE",
    "gaussian_weights",
    "gaussian_weights_np",
    "downsample",
    "blur",
    "upsample",
    "local_mean",
    "edge_darkening",
    "glsl_edge_passes",
    "glsl_edge_darkening",
]

#: Taps on each side of the centre in the separable blur (2 * EDGE_RADIUS + 1 per axis).
EDGE_RADIUS = 6
#: The blur runs on a grid this many times coarser than the image, in each direction.
EDGE_DOWNSAMPLE = 2


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
    x = x.reshape(h, factor, w, factor, *x.shape[2:])
    return x.mean(axis=(1, 3))


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


def _bilinear_taps(n_out: int, n_low: int, factor: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per output index: the two low-resolution indices and the weight of the second (GL's clamp to edge)."""
    t = (np.arange(n_out) + 0.5) / factor - 0.5
    i0 = np.floor(t)
    frac = t - i0
    i1 = i0 + 1
    return np.clip(i0, 0, n_low - 1).astype(np.int32), np.clip(i1, 0, n_low - 1).astype(np.int32), frac


def upsample(x: Float[ArrayLike, "h w *C"], height: int, width: int, factor: int = EDGE_DOWNSAMPLE) -> Float[Array, "H W *C"]:
    """Bilinear interpolation of a low-resolution image at the pixel centres of a `height x width` one.

    Low-resolution coordinate `(x + 0.5) / factor - 0.5` per axis, indices
    clamped to the edge: what a GPU's linear filtering with clamp-to-edge
    returns at those points.
    """
    x = jnp.asarray(x)
    if factor == 1:
        return x[:height, :width]
    r0, r1, fr = _bilinear_taps(height, x.shape[0], factor)
    c0, c1, fc = _bilinear_taps(width, x.shape[1], factor)
    extra = (1,) * (x.ndim - 2)
    fr = jnp.asarray(fr, x.dtype).reshape((-1, 1) + extra)
    fc = jnp.asarray(fc, x.dtype).reshape((1, -1) + extra)
    rows = x[r0] * (1 - fr) + x[r1] * fr
    return rows[:, c0] * (1 - fc) + rows[:, c1] * fc


def local_mean(
    x: Float[ArrayLike, "H W *C"], sigma: Float[ArrayLike, ""], factor: int = EDGE_DOWNSAMPLE, radius: int = EDGE_RADIUS
) -> Float[Array, "H W *C"]:
    """`upsample(blur(downsample(x), sigma / factor))`: the Gaussian-weighted neighbourhood mean at each pixel."""
    x = jnp.asarray(x)
    H, W = x.shape[:2]
    return upsample(blur(downsample(x, factor), jnp.asarray(sigma) / factor, radius), H, W, factor)


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
    - `width`: the blur's $\sigma$ in pixels (0: off); differentiable.
    - `factor`, `radius`: the blur's reduction and taps (static).
    - `mean`: $\bar t$ if already computed (`local_mean`).

    **Returns:**

    The darkened thickness, same shape.
    """
    t = jnp.asarray(thickness)
    m = local_mean(t, width, factor, radius) if mean is None else jnp.asarray(mean)
    d = t - m
    return t + strength * jnp.where(d > 0, d, 0.0)


# --- GLSL -----------------------------------------------------------------------------------------


def glsl_edge_passes(factor: int = EDGE_DOWNSAMPLE, radius: int = EDGE_RADIUS) -> dict[str, str]:
    """Fragment shader bodies of the three low-resolution passes (no `#version` line).

    - `"downsample"`: `look_source` (full resolution, `.rg` = wash, unlit)
      -> the mean of each `factor x factor` block;
    - `"blur_rows"`, `"blur_columns"`: `look_source` -> blurred along x, then y,
      with `uniform float look_edge_weights[radius + 1]` (weights of offsets
      0..radius, from `gaussian_weights_np(width / factor)`).

    Each writes `vec4(wash, unlit, 0, 0)` to `look_out` and is drawn as a
    full-screen triangle at the low resolution.
    """
    f = int(factor)
    down = f"""\
uniform sampler2D look_source;   // full resolution: .r wash, .g unlit
layout(location = 0) out vec4 look_out;

void main() {{
    ivec2 base = ivec2(gl_FragCoord.xy) * {f};
    ivec2 last = textureSize(look_source, 0) - 1;
    vec2 acc = vec2(0.0);
    for (int dy = 0; dy < {f}; ++dy)
        for (int dx = 0; dx < {f}; ++dx)
            acc += texelFetch(look_source, min(base + ivec2(dx, dy), last), 0).rg;
    look_out = vec4(acc * {float_literal(1.0 / (f * f))}, 0.0, 0.0);
}}
"""

    def blur_pass(axis: str) -> str:
        step = "ivec2(k, 0)" if axis == "x" else "ivec2(0, k)"
        return f"""\
uniform sampler2D look_source;   // low resolution: .r wash, .g unlit
uniform float look_edge_weights[{radius + 1}];   // Gaussian weights of offsets 0..{radius}
layout(location = 0) out vec4 look_out;

void main() {{
    ivec2 p = ivec2(gl_FragCoord.xy);
    ivec2 last = textureSize(look_source, 0) - 1;
    vec2 acc = vec2(0.0);
    for (int i = 0; i <= {2 * radius}; ++i) {{
        int k = i - {radius};
        acc += look_edge_weights[abs(k)] * texelFetch(look_source, clamp(p + {step}, ivec2(0), last), 0).rg;
    }}
    look_out = vec4(acc, 0.0, 0.0);
}}
"""

    return {"downsample": down, "blur_rows": blur_pass("x"), "blur_columns": blur_pass("y")}


def glsl_edge_darkening(factor: int = EDGE_DOWNSAMPLE) -> str:
    """GLSL of the final step: the bilinear local mean at a full-resolution pixel, and the darkening.

    `look_edge_mean(pixel)` samples `uniform sampler2D look_edge_blurred` (the
    low-resolution blurred glazes, linear filtering, clamp to edge) at the
    pixel's centre; `look_edge_darken(t, mean)` is `t + look_edge_darkening *
    max(t - mean, 0)`.
    """
    return f"""\
// ---- Edge darkening (diffwash/look/_edges.py) ---------------------------------------------------
uniform sampler2D look_edge_blurred;   // low resolution (1/{int(factor)}): blurred wash and unlit, linear filtering
uniform float look_edge_darkening;     // k_e

// Gaussian neighbourhood mean of (wash, unlit) at the full-resolution pixel `pixel` (column, row of
// the blurred texture's own orientation): a bilinear sample at low-resolution coordinate (x + 0.5) / f - 0.5.
vec2 look_edge_mean(ivec2 pixel) {{
    vec2 size = vec2(textureSize(look_edge_blurred, 0));
    vec2 uv = (vec2(pixel) + 0.5) / ({float_literal(float(factor))} * size);
    return texture(look_edge_blurred, uv).rg;
}}

vec2 look_edge_darken(vec2 t, vec2 mean) {{
    vec2 d = t - mean;
    return t + look_edge_darkening * max(d, vec2(0.0));
}}
"""
