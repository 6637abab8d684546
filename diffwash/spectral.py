r"""Spectral colour: reflectance on a band grid seen as CIE XYZ, linear sRGB and CIELAB.

A pigment's reflectance lives on a grid of *bands*: wavelengths in nm (the NTU
watercolour data: 380-780 nm in 10 nm steps), or the three linear sRGB channels
of the seed's pigments. An `Observation` turns reflectance on its grid into
colour by one matrix product, so that Kubelka-Munk per band and the colour it
makes stay differentiable and cheap:

$$ \mathrm{XYZ} = R\, M_{XYZ}, \qquad \mathrm{RGB}_{lin} = R\, M_{RGB}, \qquad
   M_{RGB} = M_{XYZ}\, (A\, C)^\top, $$

with $R$ of shape `(..., B)`, $M_{XYZ}$ of shape `(B, 3)`, $C$ the chromatic
adaptation (CAT02) from the white the observation sees (a perfect reflector) to
sRGB's D65 white, and $A$ the IEC 61966-2-1 XYZ to linear sRGB matrix. CIELAB
is taken relative to the observation's own white.

For a spectral grid, $M_{XYZ}$ is computed once with colour-science, for any
illuminant and observer it knows by name (D65 and the CIE 1931 2-degree
observer by default):

- `"ASTM E308"` (colour-science's default for `sd_to_XYZ`, used where the grid
  allows it: regular steps of 1, 5, 10 or 20 nm, the 10 and 20 nm grids starting
  and ending on a multiple of 10): the matrix is colour-science's own
  `sd_to_XYZ(..., method="ASTM E308")` applied to each band's unit vector
  (the method is linear in the reflectance, so the matrix reproduces it to
  rounding error: ASTM E2022 weighting factors for 10 and 20 nm data, the
  practice range 360-780 nm with the reflectance extended by its end values).
- `"Integration"` (any strictly increasing grid): the colour-matching functions
  and the illuminant are interpolated to the band centres (colour-science's own
  interpolators) and summed with band widths $\Delta\lambda_j$ (half the distance
  between the neighbours, the full step at the ends):
  $M_{XYZ,jc} = \bar c(\lambda_j) S(\lambda_j) \Delta\lambda_j / \sum_i \bar y(\lambda_i) S(\lambda_i) \Delta\lambda_i$.
  On a regular grid this is colour-science's `sd_to_XYZ_integration(..., shape=grid)`.

XYZ is on the scale where the perfect reflector has `Y = 1`.

The three-channel grid (`observation()` with no wavelengths, `RGB`) is the
same API with the identity as $M_{RGB}$: the bands *are* linear sRGB, seen
through `diffwash.colorimetry`'s matrices and white, so one code path serves
both kinds of pigment.

**References:**

- CIE 15:2004, "Colorimetry", 3rd edition.
- ASTM E308-15, "Standard Practice for Computing the Colors of Objects by Using
  the CIE System"; ASTM E2022-16 (weighting factors).
- IEC 61966-2-1:1999 (sRGB).
- T. Mansencal et al., colour-science (colour 0.4), https://colour.readthedocs.io.
"""

from __future__ import annotations

import functools
import math
import warnings
from collections.abc import Sequence
from typing import Any

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from . import colorimetry
from ._errors import DiffwashError
from ._lazy import lazy

colour = lazy("colour")  # colour-science: its observers and illuminants, when a band grid is first observed

__all__ = [
    "Observation",
    "observation",
    "RGB",
    "DEFAULT_ILLUMINANT",
    "DEFAULT_OBSERVER",
    "METHODS",
    "check_grid",
    "resample",
]

#: The band names of the three-channel grid (linear sRGB channels).
RGB = ("r", "g", "b")
#: Illuminant used when none is named (colour-science's name).
DEFAULT_ILLUMINANT = "D65"
#: Colour-matching functions used when none are named (colour-science's name).
DEFAULT_OBSERVER = "CIE 1931 2 Degree Standard Observer"
#: Methods from reflectance to XYZ, as colour-science names them.
METHODS = ("ASTM E308", "Integration")
#: Chromatic adaptation used to reach sRGB's white (colour-science's default for `XYZ_to_sRGB`).
ADAPTATION = "CAT02"


class Observation(eqx.Module):
    """How reflectance on a grid of bands is seen: linear maps to XYZ and linear sRGB.

    A pytree whose leaves are the matrices (so it can be passed through
    `jax.jit`); the grid and the names are static. Build one with `observation`.

    **Fields:**

    - `to_xyz`: reflectance to CIE XYZ (perfect reflector `Y = 1`), shape (B, 3).
    - `to_rgb`: reflectance to linear sRGB (adapted to sRGB's D65 white), shape (B, 3).
    - `white`: XYZ of the perfect reflector, the CIELAB reference white, shape (3,).
    - `wavelengths`: the band centres in nm, or None for the three sRGB channels.
    - `illuminant`, `observer`, `method`: colour-science's names (`"sRGB"` for
      all three on the channel grid).
    """

    to_xyz: Float[Array, "b 3"]
    to_rgb: Float[Array, "b 3"]
    white: Float[Array, "3"]
    wavelengths: tuple[float, ...] | None = eqx.field(static=True, default=None)
    illuminant: str = eqx.field(static=True, default=DEFAULT_ILLUMINANT)
    observer: str = eqx.field(static=True, default=DEFAULT_OBSERVER)
    method: str = eqx.field(static=True, default="ASTM E308")

    @property
    def spectral(self) -> bool:
        """True for a wavelength grid, False for the three sRGB channels."""
        return self.wavelengths is not None

    @property
    def bands(self) -> tuple[str, ...]:
        """Column names of the bands: wavelengths as text (`"380"`), or `r, g, b`."""
        if self.wavelengths is None:
            return RGB
        return tuple(_band_name(w) for w in self.wavelengths)

    def xyz(self, R: Float[ArrayLike, "*n b"]) -> Float[Array, "*n 3"]:
        """CIE XYZ (perfect reflector `Y = 1`) of reflectance `R` on this grid."""
        R = _float(R)
        return R @ jnp.asarray(self.to_xyz, R.dtype)

    def linear_srgb(self, R: Float[ArrayLike, "*n b"]) -> Float[Array, "*n 3"]:
        """Linear sRGB of reflectance `R` on this grid (unclipped)."""
        R = _float(R)
        return R @ jnp.asarray(self.to_rgb, R.dtype)

    def srgb(self, R: Float[ArrayLike, "*n b"]) -> Float[Array, "*n 3"]:
        """Display sRGB (0-1, unclipped) of reflectance `R` on this grid."""
        return colorimetry.srgb_encode(self.linear_srgb(R))

    def lab(self, R: Float[ArrayLike, "*n b"]) -> Float[Array, "*n 3"]:
        """CIELAB of reflectance `R`, relative to the observation's white."""
        xyz = self.xyz(R)
        return colorimetry.xyz_to_lab(xyz, jnp.asarray(self.white, xyz.dtype))

    def describe(self) -> dict[str, Any]:
        """The observation as JSON-ready names (what `observation` needs to rebuild it)."""
        if self.wavelengths is None:
            return {"bands": "sRGB"}
        return {"wavelengths": list(self.wavelengths), "illuminant": self.illuminant,
                "observer": self.observer, "method": self.method}  # fmt: skip


def _float(x: ArrayLike) -> Array:
    return jnp.asarray(x, jnp.result_type(x, float))


def _band_name(w: float) -> str:
    return str(int(w)) if float(w).is_integer() else repr(float(w))


def check_grid(wavelengths: Sequence[float], *, file: Any = None, field: str | None = None) -> tuple[float, ...]:
    """Validate a band grid: at least two finite, positive, strictly increasing wavelengths (nm).

    **Returns:** the grid as a tuple of floats. A bad grid raises a `DiffwashError`.
    """
    try:
        wl = tuple(float(w) for w in wavelengths)
    except (TypeError, ValueError):
        raise DiffwashError(f"wavelengths must be numbers, got {list(wavelengths)!r}", file=file, field=field) from None
    if len(wl) < 2:
        raise DiffwashError(f"a band grid needs at least two wavelengths, got {len(wl)}", file=file, field=field)
    bad = [w for w in wl if not (math.isfinite(w) and w > 0)]
    if bad:
        raise DiffwashError(f"wavelengths must be finite and > 0 nm, got {bad[0]!r}", file=file, field=field)
    steps = np.diff(wl)
    if np.any(steps <= 0):
        i = int(np.argmax(steps <= 0))
        raise DiffwashError(f"wavelengths must increase strictly ({wl[i]:g} then {wl[i + 1]:g})", file=file,
                            field=field)  # fmt: skip
    return wl


def _regular_interval(wl: tuple[float, ...]) -> float | None:
    steps = np.diff(wl)
    if np.allclose(steps, steps[0], rtol=0, atol=1e-9) and float(steps[0]).is_integer():
        return float(steps[0])
    return None


def _astm_applies(wl: tuple[float, ...]) -> bool:
    step = _regular_interval(wl)
    if step not in (1.0, 5.0, 10.0, 20.0) or not all(float(w).is_integer() for w in wl):
        return False
    return step in (1.0, 5.0) or (wl[0] % 10 == 0 and wl[-1] % 10 == 0)


def _spectral_data(illuminant: str, observer: str) -> tuple[Any, Any]:
    """colour-science's CMFs and illuminant by name (a one-line error for an unknown name)."""
    if observer not in colour.MSDS_CMFS:
        known = ", ".join(k for k in colour.MSDS_CMFS if "Standard Observer" in k)
        raise DiffwashError(f"unknown observer {observer!r} (colour-science knows e.g. {known})", field="observer")
    if illuminant not in colour.SDS_ILLUMINANTS:
        raise DiffwashError(f"unknown illuminant {illuminant!r} (colour-science knows e.g. D65, D50, A, E, FL2)",
                            field="illuminant")  # fmt: skip
    return colour.MSDS_CMFS[observer], colour.SDS_ILLUMINANTS[illuminant]


def _xyz_matrix_astm(wl: tuple[float, ...], cmfs: Any, illuminant: Any) -> np.ndarray:
    basis = colour.MultiSpectralDistributions(np.eye(len(wl)), np.asarray(wl))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # colour-science's notes on aligning shapes
        M = colour.msds_to_XYZ(basis, cmfs, illuminant, method="ASTM E308")
    return np.asarray(M, np.float64).reshape(len(wl), 3) / 100


def _xyz_matrix_integration(wl: tuple[float, ...], cmfs: Any, illuminant: Any) -> np.ndarray:
    w = np.asarray(wl)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        cbar = np.asarray(cmfs[w], np.float64).reshape(len(w), 3)
        S = np.asarray(illuminant[w], np.float64).reshape(len(w))
    d = np.empty_like(w)
    d[1:-1] = (w[2:] - w[:-2]) / 2
    d[0], d[-1] = w[1] - w[0], w[-1] - w[-2]
    M = cbar * (S * d)[:, None]
    return M / np.sum(M[:, 1])


@functools.lru_cache(maxsize=32)
def _spectral_matrices(wl: tuple[float, ...], illuminant: str, observer: str, method: str) -> tuple[np.ndarray, ...]:
    cmfs, sd_illuminant = _spectral_data(illuminant, observer)
    if method == "ASTM E308":
        to_xyz = _xyz_matrix_astm(wl, cmfs, sd_illuminant)
    else:
        to_xyz = _xyz_matrix_integration(wl, cmfs, sd_illuminant)
    white = to_xyz.sum(axis=0)
    cat = colour.adaptation.matrix_chromatic_adaptation_VonKries(
        colour.xy_to_XYZ(colour.XYZ_to_xy(white)), colour.xy_to_XYZ(colorimetry.WHITE_D65_XY), transform=ADAPTATION
    )
    to_rgb = to_xyz @ (colorimetry.XYZ_TO_SRGB @ cat).T
    for m in (to_xyz, to_rgb, white):
        m.setflags(write=False)
    return to_xyz, to_rgb, white


def observation(
    wavelengths: Sequence[float] | None = None,
    *,
    illuminant: str = DEFAULT_ILLUMINANT,
    observer: str = DEFAULT_OBSERVER,
    method: str | None = None,
) -> Observation:
    r"""The `Observation` of reflectance on a band grid.

    **Arguments:**

    - `wavelengths`: the band centres in nm, strictly increasing; None for the
      three linear sRGB channels (then the other arguments are ignored).
    - `illuminant`: the light, by colour-science's name (`colour.SDS_ILLUMINANTS`:
      `"D65"`, `"D50"`, `"A"`, `"FL2"`, ...).
    - `observer`: the colour-matching functions, by colour-science's name
      (`colour.MSDS_CMFS`: `"CIE 1931 2 Degree Standard Observer"`,
      `"CIE 1964 10 Degree Standard Observer"`, ...).
    - `method`: `"ASTM E308"` or `"Integration"` (see the module docstring);
      None picks ASTM E308 where the grid allows it, else Integration.

    **Returns:**

    The `Observation` (its matrices computed once per grid, illuminant, observer
    and method, and cached). Unknown names or a bad grid raise a `DiffwashError`.
    """
    if wavelengths is None:
        return _rgb_observation()
    wl = check_grid(wavelengths)
    if method is None:
        method = "ASTM E308" if _astm_applies(wl) else "Integration"
    if method not in METHODS:
        raise DiffwashError(f"unknown method {method!r} (one of {', '.join(METHODS)})", field="method")
    if method == "ASTM E308" and not _astm_applies(wl):
        raise DiffwashError("ASTM E308 needs a regular grid of 1, 5, 10 or 20 nm (10 and 20 nm ones starting and "
                            "ending on a multiple of 10); use method='Integration'", field="method")  # fmt: skip
    _check_visible(wl, str(observer))
    to_xyz, to_rgb, white = _spectral_matrices(wl, str(illuminant), str(observer), method)
    return Observation(to_xyz=to_xyz, to_rgb=to_rgb, white=white, wavelengths=wl, illuminant=str(illuminant),
                       observer=str(observer), method=method)  # fmt: skip


#: A grid must span this much of the visible range (nm): nearly all of what an observer sees under daylight.
VISIBLE = (420.0, 680.0)


def _check_visible(wl: tuple[float, ...], observer: str) -> None:
    """Refuse a grid the observer cannot see: bands outside its colour-matching functions, or not spanning VISIBLE."""
    cmfs, _ = _spectral_data(DEFAULT_ILLUMINANT, observer)
    lo, hi = float(cmfs.wavelengths[0]), float(cmfs.wavelengths[-1])
    if wl[0] < lo or wl[-1] > hi or wl[0] > VISIBLE[0] or wl[-1] < VISIBLE[1]:
        raise DiffwashError(f"a band grid of {wl[0]:g}-{wl[-1]:g} nm cannot be seen as colour: it must lie within the "
                            f"observer's {lo:g}-{hi:g} nm and span {VISIBLE[0]:g}-{VISIBLE[1]:g} nm",
                            field="wavelengths")  # fmt: skip


@functools.lru_cache(maxsize=1)
def _rgb_observation() -> Observation:
    return Observation(
        to_xyz=colorimetry.SRGB_TO_XYZ.T.copy(), to_rgb=np.eye(3), white=colorimetry.WHITE_D65.copy(),
        wavelengths=None, illuminant="sRGB", observer="sRGB", method="sRGB",
    )  # fmt: skip


def resample(
    values: Float[ArrayLike, "*n b"], wavelengths: Sequence[float], to: Sequence[float], *, file: Any = None
) -> Float[Array, "*n c"]:
    """Values on one band grid (K, S or reflectance) linearly interpolated onto another.

    **Arguments:**

    - `values`: values on the grid `wavelengths`, last axis the bands.
    - `wavelengths`: their grid (nm).
    - `to`: the grid wanted; it must lie within `wavelengths`' range (no
      extrapolation: a pigment measured on 400-700 nm knows nothing of 750 nm).

    **Returns:** the values on `to`. A grid outside the range raises a `DiffwashError`.
    """
    src, dst = np.asarray(check_grid(wavelengths)), np.asarray(check_grid(to))
    tol = 1e-9 * max(1.0, float(src[-1]))
    if dst[0] < src[0] - tol or dst[-1] > src[-1] + tol:
        raise DiffwashError(f"the grid {dst[0]:g}-{dst[-1]:g} nm leaves the {src[0]:g}-{src[-1]:g} nm the values "
                            "are known on", file=file, field="wavelengths")  # fmt: skip
    # Linear interpolation as a (B, C) matrix, so it is a plain (differentiable) product.
    j = np.clip(np.searchsorted(src, dst, side="right") - 1, 0, len(src) - 2)
    f = np.clip((dst - src[j]) / (src[j + 1] - src[j]), 0, 1)
    W = np.zeros((len(src), len(dst)))
    W[j, np.arange(len(dst))] = 1 - f
    W[j + 1, np.arange(len(dst))] += f
    v = _float(values)
    return v @ jnp.asarray(W, v.dtype)
