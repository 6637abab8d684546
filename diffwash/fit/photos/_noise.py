r"""How well a photo measures a patch: the noise of a patch mean, from the patch's own pixels.

A swatch fit compares the model with the mean colour of each patch, so what it
needs to know is how far that mean may be from the truth. Three things set it,
and each is estimated from the photo itself:

1. **Pixel noise** (sensor noise, paper grain, an uneven glaze). Its spread is a
   robust standard deviation of the patch's pixel values (the interquartile
   range, or one half of the distribution where the other is clipped). Pixels
   are not independent -- the lens blurs, the glaze varies smoothly, JPEG works
   in 8x8 blocks -- so the standard error of the mean is
   $\sigma \sqrt{\tau / n}$ with $\tau$ the integrated autocorrelation of the
   patch's pixel field (the number of pixels per independent sample;
   Priestley 1981, sec. 5.3), not $\sigma / \sqrt{n}$.
2. **Code-value quantisation** of a uniform area. Where the pixel noise is
   smaller than a code value, every pixel of a uniform patch rounds the same
   way, so the error does not average out over the patch: rounding adds a
   variance of $1/12$ code value squared, less where the pixel noise dithers
   it (by $e^{-2\pi^2 s^2}$ for a noise of $s$ code values). A JPEG rounds in
   YCbCr (so dithered), then quantises each 8x8 block's mean (its DC
   coefficient) with the step $q$ of the file's tables and rounds to RGB,
   after the noise is smoothed: $q^2/12$ per YCbCr plane through the
   YCbCr-to-RGB matrix, and $1/12$ per channel, whatever the noise. For a
   *reference* area whose error every patch shares (the paper box that sets
   the gains, the black band) the bound is taken instead: a JPEG shifts a
   uniform area by up to about $1 + q/2$ code values per channel (on
   generated cards, noisy paper from a quality-90 JPEG comes back 0.7-0.9
   code values greener whatever the seed), uniform over that range, variance
   $(1 + q/2)^2/3$. All is converted to linear reflectance with the slope of
   the sRGB curve at the area's level.
3. **The noise floor.** A camera clips negative sensor values at black, so in
   a channel whose true signal is comparable to the noise, the mean of what was
   recorded overstates it (for a normal $x \sim N(\mu, \sigma^2)$ clipped at 0,
   $E[\max(x, 0)] = \mu\,\Phi(\mu/\sigma) + \sigma\,\phi(\mu/\sigma) > \mu$), and
   JPEG then smears the clipped values so that they can no longer be counted.
   Inverting that expectation needs the sensor's noise $\sigma$, which the photo
   only shows after demosaicing, noise reduction and JPEG have removed some of
   it: the spread seen, $\sigma_{seen}$, gives the largest value the truth can
   have, $\mu_{hi} = \mu(\sigma_{seen})$, and a noise up to `FLOOR_NOISE_FACTOR`
   times larger the smallest, $\mu_{lo}$. The patch's value is then the middle
   of $[\mu_{lo}, \mu_{hi}]$ with the variance of a uniform distribution over
   it, $(\mu_{hi} - \mu_{lo})^2 / 12$; well above the floor the two agree and
   nothing changes. A channel whose interval spans more than a factor of 2 is
   *at the noise floor*: the photo bounds it, but does not measure it.

**References:**

- M. B. Priestley, "Spectral Analysis and Time Series", Academic Press 1981
  (integrated autocorrelation; effective sample size).
- ITU-T T.81 | ISO/IEC 10918-1, "JPEG" (1992), annex A (DCT, quantisation) and
  JFIF 1.02 (YCbCr conversion).
- J. Tobin, "Estimation of relationships for limited dependent variables",
  Econometrica 26 (1958) (the mean of a normal variable censored at zero).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass

import numpy as np

from ..._lazy import lazy

Image = lazy("PIL.Image")
scipy_special = lazy("scipy.special")

#: JFIF's YCbCr to RGB matrix (rows R, G, B; columns Y, Cb, Cr), ITU-T T.871, and its inverse.
YCC_TO_RGB = np.array([[1.0, 0.0, 1.402], [1.0, -0.344136, -0.714136], [1.0, 1.772, 0.0]])
RGB_TO_YCC = np.linalg.inv(YCC_TO_RGB)

__all__ = ["JpegSteps", "jpeg_steps", "PixelNoise", "pixel_noise", "integrated_autocorrelation", "camera_noise_floor",
           "censored_mean", "trimmed_mean", "FLOOR_NOISE_FACTOR"]  # fmt: skip

#: The relative uncertainty of the camera's noise at black as `camera_noise_floor` measures it (JPEG's smoothing
#: lowers what the black band shows, the signal's shot noise there raises it).
FLOOR_NOISE_SPREAD = 0.3

#: Without a black band: how much larger than the spread seen in a patch the sensor's own noise may have been
#: (JPEG chroma subsampling and quantisation, and a phone's noise reduction, remove noise before the
#: pixels are read; on the generated cards the spread seen is 0.6-0.8 of the sensor's).
FLOOR_NOISE_FACTOR = 2.0



@dataclass(frozen=True)
class JpegSteps:
    """The quantisation steps of a JPEG's block means, in 8-bit code values.

    **Fields:** `luma`, `chroma`: the DC quantisation step of the luma and the
    chroma planes divided by 8 (a block's DC coefficient is 8 times its mean).
    """

    luma: float
    chroma: float


def jpeg_steps(path: str | os.PathLike | None) -> JpegSteps | None:
    """The DC quantisation steps of a JPEG file (None for other files or no file)."""
    if path is None:
        return None
    try:
        with Image.open(path) as im:
            if im.format != "JPEG":
                return None
            tables = getattr(im, "quantization", None) or {}
    except OSError:
        return None
    if not tables:
        return None
    luma = float(tables[0][0]) / 8
    chroma = float(tables.get(1, tables[0])[0]) / 8
    return JpegSteps(luma=luma, chroma=chroma)


def integrated_autocorrelation(field: np.ndarray, max_lag: int = 8) -> float:
    r"""Pixels per independent sample of a 2D field: $\tau = \sum_{|dx|, |dy| \le L} \rho(dx, dy)$.

    The autocorrelation $\rho$ is estimated with FFTs (zero-padded, each lag
    normalised by its number of pixel pairs) from the field minus its mean;
    the sum is over a square window of lags up to `max_lag` (smaller for small
    fields), with Bartlett weights to damp its noisy edges. At least 1.
    """
    f = np.asarray(field, np.float64)
    h, w = f.shape
    L = int(max(1, min(max_lag, h // 3, w // 3)))
    x = f - f.mean()
    var = float(np.mean(x * x))
    if var <= 0 or h < 3 or w < 3:
        return 1.0
    H, W = 2 * h, 2 * w
    F = np.fft.rfft2(x, (H, W))
    acov = np.fft.irfft2(F * np.conj(F), (H, W))
    ones = np.fft.rfft2(np.ones_like(x), (H, W))
    pairs = np.fft.irfft2(ones * np.conj(ones), (H, W))
    lags = np.r_[0 : L + 1, -L:0]
    sub = np.ix_(lags % H, lags % W)
    rho = acov[sub] / np.maximum(pairs[sub], 1.0) / var
    taper = np.outer(1 - np.abs(lags) / (L + 1), 1 - np.abs(lags) / (L + 1))
    return float(max(np.sum(rho * taper), 1.0))


def censored_mean(m: np.ndarray, sigma: np.ndarray) -> np.ndarray:
    r"""The mean $\mu$ of a normal variable whose values clipped at 0 average `m`.

    Solves $\mu\,\Phi(\mu/\sigma) + \sigma\,\phi(\mu/\sigma) = m$ (increasing in
    $\mu$) by bisection, elementwise; $\mu = m$ where $\sigma = 0$. May be
    negative (the truth is then at or below zero).
    """
    m = np.asarray(m, np.float64)
    s = np.maximum(np.asarray(sigma, np.float64), 0.0)
    m, s = np.broadcast_arrays(m, s)
    safe = np.where(s > 0, s, 1.0)

    def expect(mu):
        z = mu / safe
        return mu * scipy_special.ndtr(z) + safe * np.exp(-0.5 * z * z) / math.sqrt(2 * math.pi)

    lo = m - 6 * safe
    hi = m.copy()  # expect(mu) >= mu, so mu <= m
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        big = expect(mid) > m
        hi = np.where(big, mid, hi)
        lo = np.where(big, lo, mid)
    return np.where(s > 0, 0.5 * (lo + hi), m)


def _robust_sd(v: np.ndarray, clipped_lo: float, clipped_hi: float) -> float:
    """A standard deviation from quantiles, from the unclipped side where one side is clipped."""
    q16, q25, q50, q75, q84 = np.quantile(v, [0.1587, 0.25, 0.5, 0.75, 0.8413])
    if clipped_lo > 0.02 and clipped_hi <= 0.02:
        return float(q84 - q50)
    if clipped_hi > 0.02 and clipped_lo <= 0.02:
        return float(q50 - q16)
    return float((q75 - q25) / 1.349)


def camera_noise_floor(linear: np.ndarray, display: np.ndarray, bits: int) -> float:
    """The camera's noise at black, in linear camera signal, from a dark uniform box of the photo (the black band).

    The largest robust standard deviation over the channels (a JPEG smooths
    chroma, which lowers some channels' spread); from the unclipped side where
    the box reaches black. `linear`, `display`: the box's pixels, (h, w, 3).
    """
    flat = linear.reshape(-1, 3)
    raw = display.reshape(-1, 3)
    top = (1 << bits) - 1
    lo = np.mean(raw <= 0.5 / top, axis=0)
    hi = np.mean(raw >= 1 - 0.5 / top, axis=0)
    return float(max(_robust_sd(flat[:, c], lo[c], hi[c]) for c in range(3)))


def _srgb_slope(display: np.ndarray) -> np.ndarray:
    """d(linear)/d(display) of the sRGB transfer function at display values in [0, 1]."""
    d = np.asarray(display, np.float64)
    return np.where(d > 0.04045, 2.4 / 1.055 * ((np.maximum(d, 0.04045) + 0.055) / 1.055) ** 1.4, 1 / 12.92)


@dataclass(frozen=True)
class PixelNoise:
    """How well a box's pixels measure its mean (all in the units of the values given).

    **Fields:**

    - `value`: the estimate of the mean (3,): the trimmed mean, or the middle of
      `interval` in a channel near the noise floor.
    - `cov`: the covariance of `value` (3, 3): pixel noise, code-value
      quantisation and the noise floor's interval.
    - `spread`: the robust standard deviation of the pixels (3,).
    - `pixels_per_sample`: the integrated autocorrelation (3,) (`n / tau` independent samples).
    - `interval`: the range (2, 3) the mean lies in by the noise-floor analysis
      (both ends equal to the mean well above the floor).
    - `floor`: per channel, whether the channel is at the noise floor (its
      interval spans more than a factor of 2).
    """

    value: np.ndarray
    cov: np.ndarray
    spread: np.ndarray
    pixels_per_sample: np.ndarray
    interval: np.ndarray
    floor: np.ndarray


def _row_norms(a: np.ndarray) -> np.ndarray:
    """The Euclidean norm of each row of `a`, scaled by its largest entry first (no overflow for finite `a`)."""
    a = np.abs(np.asarray(a, np.float64))
    top = np.max(a, axis=-1)
    safe = np.where(top > 0, top, 1.0)
    return top * np.sqrt(np.sum(np.square(a / safe[..., None]), axis=-1))


def _coherent(s: np.ndarray) -> np.ndarray:
    """The variance, in code values squared, of rounding a value with normal noise of `s` code values (module
    docstring): 1/12 without noise, $e^{-2\\pi^2 s^2}/12$ with it; 0 to double precision beyond 10 code values."""
    return np.exp(-2 * (np.pi * np.minimum(np.abs(s), 10.0)) ** 2) / 12


def trimmed_mean(v: np.ndarray, trim: float = 0.2) -> np.ndarray:
    """Mean of the middle (1 - 2 trim) of the values along axis 0, per column."""
    v = np.sort(v, axis=0)
    n = v.shape[0]
    k = int(np.floor(trim * n))
    return v[k : n - k].mean(axis=0) if n - 2 * k > 0 else np.median(v, axis=0)


def pixel_noise(values: np.ndarray, display: np.ndarray, scale: np.ndarray, bits: int, clipped_lo: np.ndarray,
                clipped_hi: np.ndarray, jpeg: JpegSteps | None = None, reference: bool = False,
                floor_noise: float | None = None) -> PixelNoise:  # fmt: skip
    r"""The mean of a box of pixels and its covariance (module docstring).

    **Arguments:**

    - `values`: the box's calibrated values, (h, w, 3) (linear reflectance).
    - `display`: the same pixels as read, display-encoded in [0, 1], (h, w, 3).
    - `scale`: values per unit of linear camera signal, (3,) (1 / (gain x light)
      over the box).
    - `bits`: the file's bits per channel (8 or 16).
    - `clipped_lo`, `clipped_hi`: fraction of the pixels at the bottom / top code, (3,).
    - `jpeg`: the file's `JpegSteps`, or None.
    - `reference`: the box is a reference (the paper that calibrates the gains,
      the black band under patches), whose error every patch shares: a JPEG's
      shift is then taken at its bound, uniform over $\pm(1 + q/2)$ code values
      per channel (the fit's misfit cannot reveal a shared error).
    - `floor_noise`: the camera's noise at black, in linear camera signal
      (`camera_noise_floor`), if known: the noise-floor analysis then uses it,
      within a factor `1 -/+ FLOOR_NOISE_SPREAD`, instead of the patch's own spread.

    **Returns:** a `PixelNoise`.
    """
    h, w, _ = values.shape
    n = h * w
    flat = values.reshape(-1, 3)
    trimmed = trimmed_mean(flat)
    spread = np.array([_robust_sd(flat[:, c], clipped_lo[c], clipped_hi[c]) for c in range(3)])
    tau = np.empty(3)
    for c in range(3):
        x = np.clip(values[..., c], np.median(flat[:, c]) - 3 * spread[c], np.median(flat[:, c]) + 3 * spread[c])
        tau[c] = integrated_autocorrelation(x)
    # The trimmed mean of a normal sample has about 1.1 times the variance of its mean.
    var_pixels = 1.1 * spread**2 * tau / n

    # The noise floor: the clipped values' mean un-clipped with the camera's noise (module docstring).
    full = flat.mean(axis=0)
    if floor_noise is not None:
        sigma = floor_noise * scale  # the camera's noise at black, in the values' units
        near = (clipped_lo > 0.005) | (trimmed < 4 * sigma)
        hi_sigma, lo_sigma = (1 - FLOOR_NOISE_SPREAD) * sigma, (1 + FLOOR_NOISE_SPREAD) * sigma
    else:
        near = (clipped_lo > 0.005) | (trimmed < 3 * spread)
        hi_sigma, lo_sigma = spread, FLOOR_NOISE_FACTOR * spread
    m = np.where(near, full, trimmed)
    hi = np.where(near, censored_mean(m, hi_sigma), trimmed)
    lo = np.where(near, np.clip(censored_mean(m, lo_sigma), 0, None), trimmed)
    lo = np.minimum(lo, hi)
    value = np.where(near, 0.5 * (lo + hi), trimmed)
    var_floor = (hi - lo) ** 2 / 12
    floor = near & (lo < 0.5 * hi)

    # Code-value quantisation of a uniform patch, in display code values, then in the values' units. Rounding to
    # whole code values averages out where the pixel noise dithers it (the mean rounding error of a value with
    # normal noise sd s, in code values, falls as exp(-2 pi^2 s^2)). A JPEG's do not (module docstring).
    d_mean = display.reshape(-1, 3).mean(axis=0)
    top = 255 if jpeg is not None else (1 << bits) - 1
    J = _srgb_slope(d_mean) / top * scale  # values per code value
    # The pixels' spread in code values, at most 1e6 (beyond 10 the rounding averages out): finite whatever `scale`.
    sd_codes = spread / np.maximum(np.abs(J), np.maximum(spread, 1e-300) * 1e-6)
    if jpeg is not None:
        steps = np.array([jpeg.luma, jpeg.chroma, jpeg.chroma])
        sd_ycc = _row_norms(RGB_TO_YCC * sd_codes)  # sqrt((RGB_TO_YCC**2) @ sd_codes**2), without overflow
        codes = YCC_TO_RGB @ np.diag(steps**2 / 12 + _coherent(sd_ycc)) @ YCC_TO_RGB.T + np.eye(3) / 12
        if reference:
            codes = np.eye(3) * (1 + steps.max() / 2) ** 2 / 3
    else:
        codes = np.diag(_coherent(sd_codes))
    cov = np.diag(J) @ codes @ np.diag(J) + np.diag(var_pixels + var_floor)
    return PixelNoise(value=value, cov=cov, spread=spread, pixels_per_sample=tau,
                      interval=np.stack([lo, hi]), floor=floor)  # fmt: skip
