r"""Differentiable colorimetry in JAX: sRGB, CIE XYZ, CIELAB and CIEDE2000.

Everything here is what colour-science computes (and the tests hold it to
colour-science within 1e-6), written in `jax.numpy` so that losses in CIELAB or
CIEDE2000 can be differentiated. Colour work that needs no gradient (image
files, textures, plots, reports) goes through colour-science itself:
`to_display` and `from_display`. The sRGB curve of the exported shaders is
generated from `srgb_encode` and `srgb_decode` (`diffwash._xp`).

Conventions: linear sRGB and XYZ on the scale where the white (D65) has `Y = 1`;
CIELAB on its usual scale (`L*` in [0, 100]); the reference white of CIELAB is
the sRGB white, CIE 1931 2-degree D65 (x, y = 0.3127, 0.3290).

Every function broadcasts over leading axes (the last axis holds the three
components) and has finite gradients everywhere, including black, the
achromatic axis and identical colour pairs ("double where" forms).

**References:**

- IEC 61966-2-1:1999, "Multimedia systems and equipment - Colour measurement
  and management - Part 2-1: Default RGB colour space - sRGB".
- CIE 15:2004, "Colorimetry", 3rd edition (CIELAB).
- G. Sharma, W. Wu and E. N. Dalal, "The CIEDE2000 color-difference formula:
  Implementation notes, supplementary test data, and mathematical
  observations", Color Research & Application 30 (2005).
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from ._lazy import lazy
from ._xp import namespace, shader_function

colour = lazy("colour")  # colour-science (seconds to import), when a file's colours are first encoded

__all__ = [
    "srgb_encode",
    "srgb_decode",
    "to_display",
    "from_display",
    "linear_srgb_to_xyz",
    "xyz_to_linear_srgb",
    "xyz_to_lab",
    "lab_to_xyz",
    "linear_srgb_to_lab",
    "srgb_to_lab",
    "delta_e_2000",
    "delta_e_2000_residuals",
    "delta_e_1994_residuals",
    "SRGB_TO_XYZ",
    "XYZ_TO_SRGB",
    "WHITE_D65",
]


def _xy_to_XYZ(xy: tuple[float, float]) -> np.ndarray:
    x, y = xy
    return np.array([x / y, 1.0, (1 - x - y) / y])


#: CIE 1931 2-degree chromaticity of D65, the white of sRGB and of our CIELAB.
WHITE_D65_XY = (0.3127, 0.3290)
#: XYZ of the D65 white with Y = 1 (the CIELAB reference white).
WHITE_D65 = _xy_to_XYZ(WHITE_D65_XY)
#: Linear sRGB to CIE XYZ, the matrix IEC 61966-2-1 publishes (4 decimals), as
#: colour-science uses it.
SRGB_TO_XYZ = np.array([[0.4124, 0.3576, 0.1805], [0.2126, 0.7152, 0.0722], [0.0193, 0.1192, 0.9505]])
#: CIE XYZ to linear sRGB, the inverse matrix IEC 61966-2-1 publishes (not the
#: exact inverse of `SRGB_TO_XYZ`: round trips agree to about 1e-4).
XYZ_TO_SRGB = np.array([[3.2406, -1.5372, -0.4986], [-0.9689, 1.8758, 0.0415], [0.0557, -0.2040, 1.0570]])

#: Where the sRGB transfer function leaves its linear segment: linear value, and encoded value.
SRGB_LINEAR_BREAK = 0.0031308
SRGB_ENCODED_BREAK = 0.04045

_LAB_EPSILON = 216 / 24389  # (6/29)^3
_LAB_KAPPA = 24389 / 27


def _float(x: ArrayLike) -> Array:
    return jnp.asarray(x, jnp.result_type(x, float))


def _matmul3(M: np.ndarray, v: Array) -> Array:
    return jnp.einsum("ij,...j->...i", jnp.asarray(M, v.dtype), v)


def _safe_pow(x: Array, p: float) -> Array:
    """x**p for x > 0, else 0; gradient finite (0) where x <= 0."""
    xp = namespace(x)
    ok = x > 0
    return xp.where(ok, xp.power(xp.where(ok, x, 1), p), 0)


def _safe_sqrt(x: Array) -> Array:
    ok = x > 0
    return jnp.where(ok, jnp.sqrt(jnp.where(ok, x, 1)), 0)


@shader_function("srgb_encode", [("rgb", "vec3")], "vec3")
def srgb_encode(rgb: Float[ArrayLike, "*b 3"]) -> Float[Array, "*b 3"]:
    r"""Linear sRGB to non-linear (display) sRGB, the IEC 61966-2-1 transfer function.

    $$ V = 12.92\,L \ (L \le 0.0031308), \qquad V = 1.055\,L^{1/2.4} - 0.055 \ (\text{else}). $$

    Not clipped: values outside [0, 1] follow the two branches (negative values
    stay on the linear segment).
    """
    xp = namespace(rgb)
    (L,) = xp.asfloat(rgb)
    hi = L > SRGB_LINEAR_BREAK
    return xp.where(hi, 1.055 * _safe_pow(L, 1 / 2.4) - 0.055, 12.92 * L)


@shader_function("srgb_decode", [("rgb", "vec3")], "vec3")
def srgb_decode(rgb: Float[ArrayLike, "*b 3"]) -> Float[Array, "*b 3"]:
    """Non-linear (display) sRGB to linear sRGB, the inverse of `srgb_encode`."""
    xp = namespace(rgb)
    (V,) = xp.asfloat(rgb)
    hi = V > SRGB_ENCODED_BREAK
    return xp.where(hi, _safe_pow((V + 0.055) / 1.055, 2.4), V / 12.92)


def to_display(linear: Float[ArrayLike, "*b"]) -> np.ndarray:
    """Linear sRGB to display sRGB in [0, 1], clipped to [0, 1] first (NumPy float64; no gradient).

    For image files, textures and figures: colour-science's IEC 61966-2-1
    inverse EOTF (`colour.models.eotf_inverse_sRGB`). NaN becomes 0.
    """
    x = np.clip(np.nan_to_num(np.asarray(linear, np.float64), nan=0.0), 0, 1)
    return np.asarray(colour.models.eotf_inverse_sRGB(x), np.float64)


def from_display(encoded: Float[ArrayLike, "*b"]) -> np.ndarray:
    """Display sRGB in [0, 1] (clipped to it first) to linear sRGB (NumPy float64; no gradient).

    colour-science's IEC 61966-2-1 EOTF (`colour.models.eotf_sRGB`).
    """
    v = np.clip(np.asarray(encoded, np.float64), 0, 1)
    return np.asarray(colour.models.eotf_sRGB(v), np.float64)


def linear_srgb_to_xyz(rgb: Float[ArrayLike, "*b 3"]) -> Float[Array, "*b 3"]:
    """Linear sRGB to CIE XYZ (D65 white has `Y = 1`)."""
    return _matmul3(SRGB_TO_XYZ, _float(rgb))


def xyz_to_linear_srgb(xyz: Float[ArrayLike, "*b 3"]) -> Float[Array, "*b 3"]:
    """CIE XYZ to linear sRGB (unclipped)."""
    return _matmul3(XYZ_TO_SRGB, _float(xyz))


def _lab_f(t: Array) -> Array:
    hi = t > _LAB_EPSILON
    return jnp.where(hi, _safe_pow(t, 1 / 3), (_LAB_KAPPA * t + 16) / 116)


def _lab_f_inv(f: Array) -> Array:
    hi = f > 6 / 29
    return jnp.where(hi, f**3, (116 * f - 16) / _LAB_KAPPA)


def xyz_to_lab(xyz: Float[ArrayLike, "*b 3"], white: Float[ArrayLike, "3"] = WHITE_D65) -> Float[Array, "*b 3"]:
    r"""CIE XYZ to CIELAB (CIE 15:2004), relative to `white` (default D65, `Y = 1`)."""
    xyz = _float(xyz)
    f = _lab_f(xyz / jnp.asarray(white, xyz.dtype))
    fx, fy, fz = f[..., 0], f[..., 1], f[..., 2]
    return jnp.stack([116 * fy - 16, 500 * (fx - fy), 200 * (fy - fz)], axis=-1)


def lab_to_xyz(lab: Float[ArrayLike, "*b 3"], white: Float[ArrayLike, "3"] = WHITE_D65) -> Float[Array, "*b 3"]:
    """CIELAB to CIE XYZ, the inverse of `xyz_to_lab`."""
    lab = _float(lab)
    fy = (lab[..., 0] + 16) / 116
    f = jnp.stack([fy + lab[..., 1] / 500, fy, fy - lab[..., 2] / 200], axis=-1)
    return _lab_f_inv(f) * jnp.asarray(white, lab.dtype)


def linear_srgb_to_lab(rgb: Float[ArrayLike, "*b 3"]) -> Float[Array, "*b 3"]:
    """Linear sRGB to CIELAB (D65)."""
    return xyz_to_lab(linear_srgb_to_xyz(rgb))


def srgb_to_lab(rgb: Float[ArrayLike, "*b 3"]) -> Float[Array, "*b 3"]:
    """Display sRGB in [0, 1] to CIELAB (D65)."""
    return linear_srgb_to_lab(srgb_decode(rgb))


def _hue_deg(b: Array, a: Array) -> Array:
    """Hue angle atan2(b, a) in degrees in [0, 360); 0 (with zero gradient) at a = b = 0."""
    zero = (a == 0) & (b == 0)
    h = jnp.degrees(jnp.arctan2(jnp.where(zero, 0, b), jnp.where(zero, 1, a)))
    return jnp.where(zero, 0, jnp.mod(h, 360))


@functools.partial(jax.jit, static_argnames="textiles")  # one program per shape: op by op, each of its ~100
# operations compiled apart for every new number of rows (13 s of a small mixture fit's posterior, cold)
def delta_e_2000(
    lab1: Float[ArrayLike, "*#b 3"], lab2: Float[ArrayLike, "*#b 3"], *, textiles: bool = False
) -> Float[Array, "*b"]:
    r"""The CIEDE2000 colour difference between two CIELAB colours.

    As Sharma et al. (2005) give it (and colour-science's `delta_E_CIE2000`),
    with `k_L = 2` when `textiles` else 1, and `k_C = k_H = 1`. The hue branches
    follow Sharma's conventions; where the colours are identical the difference
    is 0 with a zero (finite) gradient.
    """
    tL, tC, tH, R_T = _ciede2000_terms(lab1, lab2, textiles)
    return _safe_sqrt(tL * tL + tC * tC + tH * tH + R_T * tC * tH)


def delta_e_2000_residuals(
    lab1: Float[ArrayLike, "*#b 3"], lab2: Float[ArrayLike, "*#b 3"], *, textiles: bool = False
) -> Float[Array, "*b 3"]:
    r"""Three smooth residuals whose sum of squares is the squared CIEDE2000 difference.

    With Sharma et al.'s weighted differences $t_L = \Delta L'/(k_L S_L)$,
    $t_C = \Delta C'/S_C$, $t_H = \Delta H'/S_H$ and the rotation term $R_T$,
    $\Delta E_{00}^2 = t_L^2 + t_C^2 + t_H^2 + R_T t_C t_H$; completing the
    square gives

    $$ r = \bigl(t_L,\; t_C + \tfrac12 R_T t_H,\; \sqrt{1 - R_T^2/4}\; t_H\bigr),
       \qquad |r|^2 = \Delta E_{00}^2 $$

    ($|R_T| < 2$). Unlike $\Delta E_{00}$ itself, whose square root has a kink
    at zero, these are smooth: the residuals a Gauss-Newton or
    Levenberg-Marquardt fit in CIEDE2000 wants.
    """
    tL, tC, tH, R_T = _ciede2000_terms(lab1, lab2, textiles)
    return jnp.stack([tL, tC + 0.5 * R_T * tH, _safe_sqrt(1 - 0.25 * R_T * R_T) * tH], axis=-1)


def delta_e_1994_residuals(
    lab_ref: Float[ArrayLike, "*#b 3"], lab: Float[ArrayLike, "*#b 3"], *, textiles: bool = False
) -> Float[Array, "*b 3"]:
    r"""CIE 1994 colour-difference terms of `lab` from the reference `lab_ref`, as three residuals.

    $$ r = \Bigl(\frac{\Delta L^*}{k_L},\ \frac{\Delta C^*}{1 + K_1 C^*_{ref}},\
           \frac{\Delta H^*}{1 + K_2 C^*_{ref}}\Bigr), \qquad |r| = \Delta E^*_{94} $$

    with $K_1 = 0.045$, $K_2 = 0.015$, $k_L = 1$ (graphic arts) or $K_1 = 0.048$,
    $K_2 = 0.014$, $k_L = 2$ (`textiles`), as CIE 116-1995 and colour-science's
    `delta_E_CIE1994` (whose `Lab_1` is the reference). $\Delta H^*$ carries its
    sign and is computed without the square root's kink: with $z = (a^*, b^*)$,
    $\Delta H^* = (z_{ref} \times z)\sqrt{2 / (C^*_{ref} C^* + z_{ref} \cdot z)}$
    while the hues are less than 90 degrees apart, else
    $\pm\sqrt{2 (C^*_{ref} C^* - z_{ref}\cdot z)}$. The weights depend on the
    reference only, so these residuals are cheap to differentiate: a fit in them
    compiles about twice as fast as one in CIEDE2000, which they approximate.
    """
    ref, lab = _float(lab_ref), _float(lab)
    L1, a1, b1 = ref[..., 0], ref[..., 1], ref[..., 2]
    L2, a2, b2 = lab[..., 0], lab[..., 1], lab[..., 2]
    K1, K2, k_L = (0.048, 0.014, 2.0) if textiles else (0.045, 0.015, 1.0)
    C1 = _safe_sqrt(a1 * a1 + b1 * b1)
    C2 = _safe_sqrt(a2 * a2 + b2 * b2)
    dot = a1 * a2 + b1 * b2
    cross = a1 * b2 - a2 * b1
    near = dot > 0
    sign = jnp.where(cross < 0, -1.0, 1.0)
    dH = jnp.where(
        near,
        cross * _safe_sqrt(2 / jnp.where(near, C1 * C2 + dot, 1)),
        sign * _safe_sqrt(2 * jnp.where(near, 0, C1 * C2 - dot)),
    )
    return jnp.stack([(L2 - L1) / k_L, (C2 - C1) / (1 + K1 * C1), dH / (1 + K2 * C1)], axis=-1)


def _ciede2000_terms(lab1: ArrayLike, lab2: ArrayLike, textiles: bool) -> tuple[Array, Array, Array, Array]:
    """Sharma et al.'s weighted differences t_L, t_C, t_H and the rotation term R_T."""
    lab1, lab2 = _float(lab1), _float(lab2)
    L1, a1, b1 = lab1[..., 0], lab1[..., 1], lab1[..., 2]
    L2, a2, b2 = lab2[..., 0], lab2[..., 1], lab2[..., 2]
    C1 = _safe_sqrt(a1 * a1 + b1 * b1)
    C2 = _safe_sqrt(a2 * a2 + b2 * b2)
    Cbar7 = ((C1 + C2) / 2) ** 7
    G = 0.5 * (1 - _safe_sqrt(Cbar7 / (Cbar7 + 25.0**7)))
    a1p, a2p = (1 + G) * a1, (1 + G) * a2
    C1p = _safe_sqrt(a1p * a1p + b1 * b1)
    C2p = _safe_sqrt(a2p * a2p + b2 * b2)
    h1p, h2p = _hue_deg(b1, a1p), _hue_deg(b2, a2p)

    dL = L2 - L1
    dC = C2p - C1p
    Cprod = C1p * C2p
    dh = h2p - h1p
    dh = jnp.where(dh > 180, dh - 360, jnp.where(dh < -180, dh + 360, dh))
    dh = jnp.where(Cprod == 0, 0, dh)
    dH = 2 * _safe_sqrt(Cprod) * jnp.sin(jnp.radians(dh / 2))

    Lbar = (L1 + L2) / 2
    Cbarp = (C1p + C2p) / 2
    hsum = h1p + h2p
    far = jnp.abs(h1p - h2p) > 180
    hbar = jnp.where(far, jnp.where(hsum < 360, (hsum + 360) / 2, (hsum - 360) / 2), hsum / 2)
    hbar = jnp.where(Cprod == 0, hsum, hbar)

    T = (
        1
        - 0.17 * jnp.cos(jnp.radians(hbar - 30))
        + 0.24 * jnp.cos(jnp.radians(2 * hbar))
        + 0.32 * jnp.cos(jnp.radians(3 * hbar + 6))
        - 0.20 * jnp.cos(jnp.radians(4 * hbar - 63))
    )
    dtheta = 30 * jnp.exp(-(((hbar - 275) / 25) ** 2))
    Cbarp7 = Cbarp**7
    R_C = 2 * _safe_sqrt(Cbarp7 / (Cbarp7 + 25.0**7))
    Lb2 = (Lbar - 50) ** 2
    S_L = 1 + 0.015 * Lb2 / jnp.sqrt(20 + Lb2)
    S_C = 1 + 0.045 * Cbarp
    S_H = 1 + 0.015 * Cbarp * T
    R_T = -jnp.sin(jnp.radians(2 * dtheta)) * R_C

    k_L = 2.0 if textiles else 1.0
    return dL / (k_L * S_L), dC / S_C, dH / S_H, R_T
