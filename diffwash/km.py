r"""Kubelka-Munk pigment layers in JAX.

The two-flux model of Kubelka and Munk as Curtis et al. (1997, sec. 5) use it for
watercolour glazes. A layer of pigment with absorption `K`, scattering `S` (per
unit thickness) and thickness `x` reflects `R` and transmits `T` of the light
that falls on it:

$$ R = \frac{\sinh(b S x)}{c}, \qquad T = \frac{b}{c}, \qquad
   c = a \sinh(b S x) + b \cosh(b S x), \quad a = 1 + K/S, \quad b = \sqrt{a^2 - 1}. $$

That textbook form overflows for thick layers (`cosh`), divides by zero at `S = 0`,
and its square root has an infinite derivative at `K = 0`. Here it is rewritten
in terms of $\beta = bS = \sqrt{K(K + 2S)}$, which only ever enters through
the entire functions $\cosh(\beta x)$ and $\sinh(\beta x)/\beta$ of $\beta^2$:

$$ R = \frac{S\, \mathrm{sh}}{(S + K)\, \mathrm{sh} + \mathrm{ch}}, \qquad
   T = \frac{e^{-\beta x}}{(S + K)\, \mathrm{sh} + \mathrm{ch}}, $$

with $\mathrm{ch} = (1 + e^{-2\beta x})/2$ and
$\mathrm{sh} = (1 - e^{-2\beta x})/(2\beta)$ (both scaled by $e^{-\beta x}$, so
nothing overflows), evaluated by their power series in $(\beta x)^2$ where
$\beta x < 1$. The denominator is at least 1/2, so `R` and `T` are finite with
finite derivatives of every order for all `K, S, x >= 0`, with the exact limits
`S = 0` (a pure absorber: `R = 0`, `T = exp(-K x)`), `K = 0` (`R = Sx / (1 + Sx)`),
`x = 0` (`R = 0`, `T = 1`) and `x -> inf` (`R = R_inf`, `T = 0`).

All functions broadcast their arguments, work in float32 and float64, and are
safe under `jax.jit`, `jax.vmap`, `jax.grad` and `jax.jvp`.

**References:**

- P. Kubelka and F. Munk, "Ein Beitrag zur Optik der Farbanstriche",
  Zeitschrift für technische Physik 12 (1931).
- C. J. Curtis, S. E. Anderson, J. E. Seims, K. W. Fleischer and D. H. Salesin,
  "Computer-Generated Watercolor", SIGGRAPH 1997, sec. 5.
- G. Smedresman, "Hardware Accelerated Pigment-Based Rendering System".
"""

from __future__ import annotations

import math

import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from ._xp import JAX, namespace, shader_function

__all__ = [
    "layer",
    "composite",
    "composite_stack",
    "over",
    "infinite_reflectance",
    "invert_black_white",
    "SERIES_TERMS",
]

#: Terms of the power series of cosh(sqrt(z)) and sinh(sqrt(z))/sqrt(z) in z = (beta x)^2 that `layer`
#: uses for z < 1 (to z^9: the truncation error is below 1e-18); the shaders use the same series.
SERIES_TERMS = 10
_CH_COEFFS = tuple(1.0 / math.factorial(2 * n) for n in range(SERIES_TERMS))
_SH_COEFFS = tuple(1.0 / math.factorial(2 * n + 1) for n in range(SERIES_TERMS))


def _horner(coeffs: tuple[float, ...], z):
    acc = coeffs[-1] * z + coeffs[-2]
    for c in reversed(coeffs[:-2]):
        acc = acc * z + c
    return acc


def _as_float(*xs: ArrayLike) -> list[Array]:
    return JAX.asfloat(*xs)


@shader_function("km_layer", [("K", "vec3"), ("S", "vec3"), ("x", "float")], [("R", "vec3"), ("T", "vec3")])
def layer(
    K: Float[ArrayLike, "*#b"], S: Float[ArrayLike, "*#b"], x: Float[ArrayLike, "*#b"]
) -> tuple[Float[Array, "*b"], Float[Array, "*b"]]:
    r"""Reflectance and transmittance of one pigment layer.

    **Arguments:**

    - `K`: absorption coefficient per unit thickness, `>= 0`.
    - `S`: scattering coefficient per unit thickness, `>= 0`.
    - `x`: thickness, `>= 0` (negative values are treated as 0).

    The three broadcast together (e.g. `K` and `S` of shape `(3,)` for RGB and `x`
    of shape `(H, W, 1)`).

    **Returns:**

    `(R, T)`, each in `[0, 1]` with `R + T <= 1`, of the broadcast shape.
    """
    xp = namespace(K, S, x)
    K, S, x = xp.asfloat(K, S, x)
    if xp is JAX:
        K, S, x = jnp.broadcast_arrays(K, S, x)
    x = xp.where(x < 0, 0, x)  # not maximum: its gradient at 0 is 1/2
    # (beta x)^2 = K (K + 2 S) x^2 <= ((K + S) x)^2: computed only where that cannot overflow float32 (elsewhere
    # beta x is large: the exponential branch), so that neither it nor its gradient is ever infinite.
    ok = (K + S) * x < 1e15
    Kq, Sq, xq = xp.where(ok, K, 0), xp.where(ok, S, 0), xp.where(ok, x, 0)
    z = xp.where(ok, (Kq * xq) * ((Kq + 2 * Sq) * xq), 2)  # each factor < 2e15
    small = z < 1
    # Series branch (beta x < 1): unscaled cosh and sinh/beta; exact at beta = 0.
    z_s = xp.where(small, z, 0)
    ch_s = _horner(_CH_COEFFS, z_s)
    sh_s = xq * _horner(_SH_COEFFS, z_s)
    denom_s = (S + K) * sh_s + ch_s  # >= 1
    # Exponential branch (beta x >= 1), in k = K / (K + S), s = S / (K + S), b = beta / (K + S) (in [0, 1]) and
    # r = b / (1 - exp(-2 beta x)), scaled by exp(-beta x): no overflow at any optical depth float32 holds, and R
    # tends to the masstone s / (1 + b) as x grows (to 1 for a pure scatterer, b = 0, where r = 1 / (2 (K + S) x)).
    ks = xp.where(small, 1, K + S)
    k, s = K / ks, S / ks
    kk = xp.where(small, 1, k * (k + 2 * s))
    b = xp.where(kk > 0, xp.sqrt(xp.where(kk > 0, kk, 1)), 0)
    bx = xp.where(small, 1, b * ks * x)
    e1 = xp.exp(-bx)
    om = -xp.expm1(-2 * bx)  # 1 - exp(-2 beta x)
    r = xp.where(b > 0, b / xp.where(om > 0, om, 1), 1 / xp.where(small, 2, 2 * ks * x))
    denom_l = 1 + r * (1 + e1 * e1)  # >= 1
    R = xp.where(small, S * sh_s / denom_s, s / denom_l)
    T = xp.where(small, 1 / denom_s, 2 * r * e1 / denom_l)
    return R, T


def _safe_div(num, den):
    """num / den where den > 0, else 0, with finite gradients (the double-where)."""
    xp = namespace(num, den)
    ok = den > 0
    return xp.where(ok, num / xp.where(ok, den, 1), 0)


@shader_function(
    "km_composite", [("R1", "vec3"), ("T1", "vec3"), ("R2", "vec3"), ("T2", "vec3")], [("R", "vec3"), ("T", "vec3")]
)
def composite(
    R1: Float[ArrayLike, "*#b"],
    T1: Float[ArrayLike, "*#b"],
    R2: Float[ArrayLike, "*#b"],
    T2: Float[ArrayLike, "*#b"],
) -> tuple[Float[Array, "*b"], Float[Array, "*b"]]:
    r"""Reflectance and transmittance of layer 1 lying on top of layer 2.

    $$ R = R_1 + \frac{T_1^2 R_2}{1 - R_1 R_2}, \qquad T = \frac{T_1 T_2}{1 - R_1 R_2} $$

    (Kubelka's compositing of the inter-reflections, Curtis et al. 1997, eq. 5).
    Light enters from layer 1's side. Layer 2 may be any stack; layer 1 is taken
    to reflect alike from both sides, which is exact for a single homogeneous
    layer. So build a stack from the bottom up,
    `composite(*top, *composite(*middle, *bottom))`; to put a stack on top of
    something, or to compose stacks in any order (associatively), use
    `composite_stack`, which also carries each stack's reflectance from below.
    The degenerate `R1 = R2 = 1` (two perfect mirrors, so `T1 = 0` for a
    physical layer) gives `R = R1`, `T = 0`.

    **Returns:**

    `(R, T)` of the stack.
    """
    xp = namespace(R1, T1, R2, T2)
    R1, T1, R2, T2 = xp.asfloat(R1, T1, R2, T2)
    d = 1 - R1 * R2
    return R1 + _safe_div(T1 * T1 * R2, d), _safe_div(T1 * T2, d)


def composite_stack(
    top: tuple[Float[ArrayLike, "*#b"], Float[ArrayLike, "*#b"], Float[ArrayLike, "*#b"]],
    bottom: tuple[Float[ArrayLike, "*#b"], Float[ArrayLike, "*#b"], Float[ArrayLike, "*#b"]],
) -> tuple[Float[Array, "*b"], Float[Array, "*b"], Float[Array, "*b"]]:
    r"""Stack `top` on `bottom`, each given as `(R, R_below, T)`.

    A stack of different layers reflects differently from above (`R`) and from
    below (`R_below`); it transmits the same both ways (`T`, by reciprocity). A
    single layer is `(R, R, T)`. With both reflectances tracked, stacking is
    associative: `composite_stack(composite_stack(a, b), c) ==
    composite_stack(a, composite_stack(b, c))`.

    $$ R = R_1 + \frac{T_1^2 R_2}{1 - R_1' R_2}, \quad
       R' = R_2' + \frac{T_2^2 R_1'}{1 - R_1' R_2}, \quad
       T = \frac{T_1 T_2}{1 - R_1' R_2}, $$

    with primes for reflectance from below.

    **Returns:**

    `(R, R_below, T)` of the stack.
    """
    R1, R1b, T1 = _as_float(*top)
    R2, R2b, T2 = _as_float(*bottom)
    d = 1 - R1b * R2
    return R1 + _safe_div(T1 * T1 * R2, d), R2b + _safe_div(T2 * T2 * R1b, d), _safe_div(T1 * T2, d)


@shader_function("km_over", [("R", "vec3"), ("T", "vec3"), ("R_ground", "vec3")], "vec3")
def over(
    R: Float[ArrayLike, "*#b"], T: Float[ArrayLike, "*#b"], R_ground: Float[ArrayLike, "*#b"]
) -> Float[Array, "*b"]:
    r"""Reflectance of a layer stack `(R, T)` lying over an opaque ground.

    $$ R_\text{total} = R + \frac{T^2 R_g}{1 - R R_g}, $$

    i.e. `composite` with a ground that transmits nothing (the paper, in the seed).
    """
    xp = namespace(R, T, R_ground)
    R, T, R_ground = xp.asfloat(R, T, R_ground)
    return R + _safe_div(T * T * R_ground, 1 - R * R_ground)


def infinite_reflectance(K: Float[ArrayLike, "*#b"], S: Float[ArrayLike, "*#b"]) -> Float[Array, "*b"]:
    r"""Reflectance of an infinitely thick layer (the layer's colour when opaque).

    $$ R_\infty = 1 + \frac{K}{S} - \sqrt{\frac{K^2}{S^2} + 2\frac{K}{S}}
               = \frac{S}{S + K + \sqrt{K (K + 2S)}}, $$

    the second (stable) form being the one evaluated. `S = 0` gives 0 (also at
    `K = 0`, the limit of `layer(0, 0, x)` as `x` grows). The true derivative with
    respect to `K` is infinite at `K = 0`; there the gradient is large but finite.
    """
    K, S = _as_float(K, S)
    tiny = jnp.finfo(K.dtype).tiny
    # in k = K / (K + S), s = S / (K + S): K (K + 2S) would overflow float32 for K past about 1e19
    ks = K + S
    ok = ks > 0
    d = jnp.where(ok, ks, 1)
    k, s = K / d, S / d
    beta = jnp.sqrt(jnp.maximum(k * (k + 2 * s), tiny))
    return jnp.where(ok, s / (1 + beta), 0)


def invert_black_white(
    R_white: Float[ArrayLike, "*#b"], R_black: Float[ArrayLike, "*#b"]
) -> tuple[Float[Array, "*b"], Float[Array, "*b"]]:
    r"""`K` and `S` of a unit-thickness layer from its reflectance over white and black.

    Curtis et al. (1997, sec. 5.1): with the layer seen over a white ground
    (`R = 1`) as `R_white` and over a black ground (`R = 0`) as `R_black`,

    $$ a = \tfrac12\left(R_w + \frac{R_b - R_w + 1}{R_b}\right),\quad b = \sqrt{a^2 - 1},\quad
       S = \frac1b \coth^{-1}\frac{b^2 - (a - R_w)(a - 1)}{b (1 - R_w)},\quad K = S(a - 1). $$

    A physical pair has `0 < R_black < R_white < 1`. Inputs outside that range
    are clamped into it, so the answer (and its gradient) is always finite:
    `R_black` to `[eps, 1 - 2 eps]` and `R_white` to `[R_black + eps, 1 - eps]`,
    with `eps = 1e-15` (float64) or `1e-7` (float32). Clamped inputs give a
    layer that is very thin, very dark or very opaque, as the data suggest.

    Evaluated in forms without cancellation: with $r_b$, $r_w$ the inputs,
    $a - 1 = (1 - r_b)(1 - r_w) / (2 r_b)$ and the argument of $\coth^{-1}$,
    $y$, has $y - 1 \propto (1 - r_w)(r_w - r_b)$, so `K` and `S` keep their
    precision down to nearly opaque layers (`R_white` close to `R_black`)
    until the inputs' own rounding dominates.

    **Returns:**

    `(K, S)`, each `>= 0`, per unit thickness.
    """
    R_white, R_black = _as_float(R_white, R_black)
    eps = 1e-15 if R_white.dtype == jnp.float64 else 1e-7
    Rb = jnp.clip(R_black, eps, 1 - 2 * eps)
    Rw = jnp.clip(R_white, Rb + eps, 1 - eps)
    am1 = (1 - Rb) * (1 - Rw) / (2 * Rb)  # a - 1
    b = jnp.sqrt(am1 * (am1 + 2))
    # y = sqrt(am1 / (am1 + 2)) (1 + Rw) / (1 - Rw);  arccoth(y) = log((y + 1) / (y - 1)) / 2
    q = (1 - Rb) * (1 - Rw) + 4 * Rb
    c = jnp.sqrt((1 - Rb) * (1 - Rw) / q)
    num = (1 + Rw) * c + (1 - Rw)  # (y + 1)(1 - Rw)
    den = 4 * (1 - Rw) * (Rw - Rb) / (q * num)  # (y - 1)(1 - Rw), without cancellation
    S = 0.5 * jnp.log(num / den) / b
    K = S * am1
    return K, S
