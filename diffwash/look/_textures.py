r"""Screen-space textures of the look: the paper's height and shading, and the unevenness noises.

Watercolour is pigment on a sheet of paper, so these textures live on the
image, not on the object: one tile of `(Th, Tw)` texels is repeated over the
image, texel `(r mod Th, c mod Tw)` at pixel row `r` (from the top), column
`c`. A texel is a pixel (no filtering): the JAX operators and a GLSL pass with
`texelFetch` read exactly the same numbers.

Six channels (`CHANNELS`):

- `paper`: the paper's height in [0, 1] (1 on the peaks), procedural
  (`procedural_paper`: cold-press "tooth", fibres and grain) or from a
  greyscale image (`paper_from_image`);
- `shade`: the paper's own shading under a grazing light, zero mean
  (`paper_shade`), for the subtle relief a scanned sheet shows;
- `turbulence_wash`, `turbulence_unlit`: low-frequency noise (wavelength about
  100 px), zero mean and unit standard deviation: Bousseau et al.'s
  "turbulent flow", one per glaze (they were painted at different times);
- `dispersion_wash`, `dispersion_unlit`: high-frequency noise (about 2 px),
  zero mean, unit standard deviation: Bousseau et al.'s "pigment dispersion".

All noises are periodic by construction (filtered white noise on a torus, in
the Fourier domain), so the tile repeats without seams.

**References:**

- C. J. Curtis, S. E. Anderson, J. E. Seims, K. W. Fleischer and D. H. Salesin,
  "Computer-Generated Watercolor", SIGGRAPH 1997, sec. 4.1 (paper texture as a
  height field).
- A. Bousseau, M. Kaplan, J. Thollot and F. X. Sillion, "Interactive watercolor
  rendering with temporal coherence and abstraction", NPAR 2006, sec. 3
  (paper, turbulent flow and pigment dispersion textures).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Any

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._errors import DiffwashError
from .._io import max_image_pixels, read_image
from .._lazy import lazy

spatial = lazy("scipy.spatial")

__all__ = [
    "CHANNELS",
    "ScreenTextures",
    "band_noise",
    "procedural_paper",
    "paper_from_image",
    "paper_shade",
    "screen_textures",
    "tile",
    "PAPER_LIGHT",
]

#: The channels of `ScreenTextures.channels`, in order.
CHANNELS = ("paper", "shade", "turbulence_wash", "dispersion_wash", "turbulence_unlit", "dispersion_unlit")
#: Direction towards the light that shades the paper's relief: from the upper left, 35 degrees above
#: the sheet (x to the right, y up the image, z out of the sheet).
PAPER_LIGHT = (-0.5792, 0.5792, 0.5736)
#: Smallest tile side accepted for a paper image, in texels.
MIN_TILE = 8
#: Most texels accepted in a paper image (2048 x 2048), checked from its header: it is one tile, repeated over the
#: picture, and its textures are made at its size (an 8192^2 image took 7.5 GB and over 600 s for a 64^2 render).
MAX_TILE_PIXELS = 2048 * 2048


def _frequencies(shape: tuple[int, int]) -> np.ndarray:
    """Radial frequency (cycles per texel) of each coefficient of an `rfft2` of `shape`."""
    fy = np.fft.fftfreq(shape[0])[:, None]
    fx = np.fft.rfftfreq(shape[1])[None, :]
    return np.hypot(fx, fy)


def _standardise(x: np.ndarray) -> np.ndarray:
    x = x - x.mean()
    s = x.std()
    return x / s if s > 0 else x


def band_noise(shape: tuple[int, int], wavelength: float, octaves: float, rng: np.random.Generator) -> np.ndarray:
    r"""Periodic band-limited Gaussian noise: zero mean, unit standard deviation.

    White noise filtered in the Fourier domain by a Gaussian in log-frequency
    centred on `1 / wavelength`, `octaves` wide (its standard deviation, in
    octaves). Periodic in both directions with the tile's size.

    **Arguments:**

    - `shape`: `(rows, columns)` of the tile.
    - `wavelength`: the dominant wavelength, in texels.
    - `octaves`: the bandwidth, in octaves.
    - `rng`: a NumPy random generator.

    **Returns:**

    A float64 array of `shape`.
    """
    f = _frequencies(shape)
    f0 = 1.0 / wavelength
    with np.errstate(divide="ignore"):
        lg = np.where(f > 0, np.log2(np.where(f > 0, f, 1.0) / f0), -np.inf)
    gain = np.exp(-0.5 * (lg / octaves) ** 2)
    spectrum = np.fft.rfft2(rng.standard_normal(shape)) * gain
    return _standardise(np.fft.irfft2(spectrum, s=shape))


def _gaussian_blur(x: np.ndarray, sigma: float) -> np.ndarray:
    """Periodic Gaussian blur of a tile (Fourier domain)."""
    f2 = _frequencies(x.shape) ** 2
    return np.fft.irfft2(np.fft.rfft2(x) * np.exp(-2 * np.pi**2 * sigma**2 * f2), s=x.shape)


def _tooth(shape: tuple[int, int], cell: float, rng: np.random.Generator) -> np.ndarray:
    """Cold-press "tooth": rounded bumps of random size around random points, on a torus."""
    rows, cols = shape
    # A jittered grid: bumps about `cell` apart, evenly spread like the felt marks of cold-pressed paper.
    nr, nc = max(2, int(round(rows / cell))), max(2, int(round(cols / cell)))
    gr, gc = np.meshgrid(np.arange(nr), np.arange(nc), indexing="ij")
    jitter = rng.uniform(-0.45, 0.45, (nr * nc, 2))
    points = (np.stack([gr.ravel(), gc.ravel()], axis=1) + 0.5 + jitter) * np.array([rows / nr, cols / nc])
    n = len(points)
    radius = cell * rng.uniform(0.55, 1.0, n)
    height = rng.uniform(0.6, 1.0, n)
    tree = spatial.cKDTree(points, boxsize=np.array([rows, cols], float))
    r, c = np.meshgrid(np.arange(rows) + 0.5, np.arange(cols) + 0.5, indexing="ij")
    dist, idx = tree.query(np.stack([r.ravel(), c.ravel()], axis=1) % np.array([rows, cols]), k=3)
    domes = height[idx] * np.clip(1 - (dist / radius[idx]) ** 2, 0, None) ** 0.75
    return domes.max(axis=1).reshape(shape)


def _fibres(shape: tuple[int, int], length: float, rng: np.random.Generator) -> np.ndarray:
    """Thin curved fibres (random walks), splatted bilinearly on a torus and blurred a little."""
    rows, cols = shape
    n = max(1, int(rows * cols / (length * length) * 1.5))
    steps = int(length * 2)
    pos = rng.uniform(0, 1, (n, 2)) * np.array([rows, cols])
    angle = rng.uniform(0, 2 * np.pi, n)
    turn = rng.normal(0, 0.06, (steps, n))
    acc = np.zeros(shape)
    weight = rng.uniform(0.3, 1.0, n)
    for k in range(steps):
        angle = angle + turn[k]
        pos = pos + 0.5 * np.stack([np.sin(angle), np.cos(angle)], axis=1)
        r0 = np.floor(pos[:, 0] - 0.5)
        c0 = np.floor(pos[:, 1] - 0.5)
        fr, fc = pos[:, 0] - 0.5 - r0, pos[:, 1] - 0.5 - c0
        for dr, wr in ((0, 1 - fr), (1, fr)):
            for dc, wc in ((0, 1 - fc), (1, fc)):
                np.add.at(acc, ((r0 + dr).astype(int) % rows, (c0 + dc).astype(int) % cols), weight * wr * wc)
    return _gaussian_blur(acc, 0.6)


def _unit_range(x: np.ndarray, lo_pct: float = 0.5, hi_pct: float = 99.5) -> np.ndarray:
    """Map the `lo_pct` and `hi_pct` percentiles to 0 and 1, clipped (a flat input gives 0.5)."""
    lo, hi = np.percentile(x, [lo_pct, hi_pct])
    if not hi > lo:
        return np.full_like(x, 0.5)
    return np.clip((x - lo) / (hi - lo), 0, 1)


def procedural_paper(
    shape: tuple[int, int] = (512, 512),
    seed: int = 0,
    *,
    tooth: float = 9.0,
    fibre_length: float = 24.0,
    weights: tuple[float, float, float, float] = (0.6, 0.25, 0.1, 0.05),
) -> np.ndarray:
    """A tileable height field that reads as cold-press watercolour paper.

    The sum of four standardised components, each periodic on the tile:

    1. the *tooth*: rounded bumps `tooth` texels apart around random points
       (a cellular pattern, on a torus), the grain of cold-pressed paper;
    2. band-limited noise of wavelength `tooth / 1.5` that makes the bumps
       irregular;
    3. *fibres*: thin curved random walks about `fibre_length` texels long;
    4. fine grain: white noise blurred by 0.7 texel.

    mapped to [0, 1] (the 0.5 and 99.5 percentiles to 0 and 1, clipped).

    **Arguments:**

    - `shape`: `(rows, columns)` of the tile, each >= `MIN_TILE`.
    - `seed`: the random seed (same seed, same paper).
    - `tooth`: the distance between bumps, in texels (= pixels).
    - `fibre_length`: the fibres' length, in texels.
    - `weights`: the four components' weights.

    **Returns:**

    `(rows, columns)` float64 heights in [0, 1], 1 on the peaks.
    """
    shape = (int(shape[0]), int(shape[1]))
    if min(shape) < MIN_TILE:
        raise DiffwashError(f"must be at least {MIN_TILE} texels on each side, got {shape}", field="paper.size")
    rng = np.random.default_rng(seed)
    parts = [
        _standardise(_tooth(shape, tooth, rng)),
        band_noise(shape, tooth / 1.5, 0.5, rng),
        _standardise(_fibres(shape, fibre_length, rng)),
        _standardise(_gaussian_blur(rng.standard_normal(shape), 0.7)),
    ]
    h = sum(w * p for w, p in zip(weights, parts))
    return _unit_range(_gaussian_blur(h, 0.5))


def paper_from_image(path: str | os.PathLike, *, field: str = "paper") -> np.ndarray:
    """A paper height field from a greyscale image file (white = peaks).

    The image's display values (the mean of its channels) are mapped to [0, 1]
    by their 0.5 and 99.5 percentiles; the image is tiled as it is (use a
    seamless texture). A missing, unreadable or too small file (under
    `MIN_TILE` pixels a side) is a one-line `DiffwashError` naming the file.

    **Returns:**

    `(rows, columns)` float64 heights in [0, 1].
    """
    try:
        rgb, _ = read_image(path, colour=False, opaque=False, max_pixels=min(MAX_TILE_PIXELS, max_image_pixels()),
                            advice="a paper image is one tile repeated over the picture: crop or scale it to "
                                   "2048x2048 pixels or fewer")  # fmt: skip
    except DiffwashError as e:
        raise DiffwashError(e.problem, file=path, field=field) from None
    if min(rgb.shape[:2]) < MIN_TILE:
        raise DiffwashError(
            f"a paper image must be at least {MIN_TILE}x{MIN_TILE} pixels, got {rgb.shape[1]}x{rgb.shape[0]}",
            file=path,
            field=field,
        )
    return _unit_range(rgb.mean(axis=2))


def paper_shade(height: np.ndarray, relief: float = 2.0, light: tuple[float, float, float] = PAPER_LIGHT) -> np.ndarray:
    r"""The paper's relief shading: Lambert's law on the height field, relative to flat paper, zero mean.

    With the normal `n = normalize(-relief dh/dx, -relief dh/dy, 1)` (periodic
    central differences; x to the right, y up the image) and the light `l`,
    the shade is `n . l / l_z - 1`, minus its mean over the tile: 0 on flat
    paper, positive on slopes facing the light.

    **Arguments:**

    - `height`: the paper's height in [0, 1], `(rows, columns)`.
    - `relief`: height units per texel of slope: how deep the paper is.
    - `light`: unit direction towards the light.
    """
    dx = (np.roll(height, -1, axis=1) - np.roll(height, 1, axis=1)) / 2
    dy = -(np.roll(height, -1, axis=0) - np.roll(height, 1, axis=0)) / 2  # rows go down; y goes up
    n = np.stack([-relief * dx, -relief * dy, np.ones_like(height)], axis=-1)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    lv = np.asarray(light, np.float64)
    lv = lv / np.linalg.norm(lv)
    s = n @ lv / lv[2] - 1
    return s - s.mean()


@dataclass(frozen=True, eq=False)
class ScreenTextures:
    """The look's screen-space tile: `channels` `(Th, Tw, 6)` float32, in the order of `CHANNELS`.

    `paper_mean` is the mean paper height over the tile. Build one with
    `screen_textures`; `tile` repeats it over an image.
    """

    channels: np.ndarray

    @property
    def shape(self) -> tuple[int, int]:
        """`(Th, Tw)`: the tile's rows and columns."""
        return int(self.channels.shape[0]), int(self.channels.shape[1])

    @property
    def paper(self) -> np.ndarray:
        """The paper's height, `(Th, Tw)` float32."""
        return self.channels[..., 0]

    def rgba(self) -> tuple[np.ndarray, np.ndarray]:
        """The two RGBA float32 textures a shader reads: channels 0-3 and 4-5 (then two zeros)."""
        c = self.channels
        second = np.concatenate([c[..., 4:6], np.zeros(c.shape[:2] + (2,), np.float32)], axis=-1)
        return np.ascontiguousarray(c[..., :4]), np.ascontiguousarray(second)


def screen_textures(
    paper: Any = None,
    *,
    shape: tuple[int, int] = (512, 512),
    seed: int = 0,
    relief: float = 2.0,
    turbulence_wavelength: float = 96.0,
    dispersion_wavelength: float = 2.0,
) -> ScreenTextures:
    """The look's screen-space tile: paper height and shade, turbulence and dispersion noises.

    **Arguments:**

    - `paper`: a height field `(Th, Tw)` in [0, 1], a path to a greyscale
      image (`paper_from_image`), or None for `procedural_paper(shape, seed)`.
    - `shape`: the tile's `(rows, columns)` when the paper is procedural.
    - `seed`: the random seed of the procedural paper and of the noises.
    - `relief`: the paper's depth for its shading (`paper_shade`).
    - `turbulence_wavelength`, `dispersion_wavelength`: the noises' dominant
      wavelengths, in pixels.

    **Returns:**

    A `ScreenTextures`.
    """
    if paper is None:
        height = procedural_paper(shape, seed)
    elif isinstance(paper, (str, os.PathLike)):
        height = paper_from_image(paper)
    else:
        height = np.asarray(paper, np.float64)
        if height.ndim != 2 or min(height.shape) < 8 or not np.all(np.isfinite(height)):
            raise DiffwashError(f"a paper height field must be a finite 2D array of at least 8x8, got shape {height.shape}", field="paper")
    rng = np.random.default_rng(np.random.SeedSequence([seed, 1]))
    tile_shape = height.shape
    noise = [
        band_noise(tile_shape, turbulence_wavelength, 1.0, rng),
        band_noise(tile_shape, dispersion_wavelength, 0.6, rng),
        band_noise(tile_shape, turbulence_wavelength, 1.0, rng),
        band_noise(tile_shape, dispersion_wavelength, 0.6, rng),
    ]
    channels = np.stack([height, paper_shade(height, relief), *noise], axis=-1).astype(np.float32)
    return ScreenTextures(channels=channels)


def tile(textures: ScreenTextures | np.ndarray, height: int, width: int) -> Float[Array, "H W C"]:
    """The tile repeated over an image of `height` x `width` pixels: texel `(r mod Th, c mod Tw)` at pixel `(r, c)`.

    **Returns:**

    `(height, width, C)` as a JAX array (float32).
    """
    c = textures.channels if isinstance(textures, ScreenTextures) else np.asarray(textures)
    rows = np.arange(height) % c.shape[0]
    cols = np.arange(width) % c.shape[1]
    return jnp.asarray(c[rows][:, cols])
