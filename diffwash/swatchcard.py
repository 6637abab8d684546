r"""Synthetic photos of swatch cards: what `diffwash fit-swatch` reads, with known answers.

A swatch card is a sheet of watercolour paper with, optionally, a band of black
ink across its lower half, and patches of one pigment glazed 1, 2, 3... coats
thick, each once over the paper and once over the black band. The photo of it
is made as a camera would make it:

1. the card's linear reflectance: paper with grain, black ink, and the pigment
   composited with Kubelka-Munk (`diffwash.km`) over whatever lies under it;
   the glaze is a little uneven and darker at its edges, as washes dry;
2. lit unevenly: a linear gradient of the light across the card and lens
   vignetting (cos^4 falloff);
3. exposed: an exposure error and a white-balance error (per-channel gains);
4. sensor noise (signal-dependent shot noise and read noise), optical blur;
5. clipped to the sensor's range, sRGB-encoded, and written as PNG (8 or 16
   bit) or JPEG (with its chroma subsampling and blocking), optionally stored
   rotated with an EXIF orientation tag.

The layout JSON written beside it gives the boxes `fit-swatch` needs (pixel
coordinates of the photo *as displayed*), and the generator returns the truth:
the pigment, the paper and the ink.

`make_mixture_card` paints a card of a mixable library's pigments instead
(`diffwash.library`, e.g. `data/libraries/ntu-four.json`), each patch one
pigment or a mixture (`("P1+P4", "1+2")`: coats of each in one layer): the
layer's optical depths per band come from the library's mixing law (step 1 is
done per band, over the library's paper and over a smooth spectrum of the ink,
and seen in linear sRGB through the library's observation); steps 2-5 are the
same. Its layout names each patch's `pigment` and `coats`.

**References:**

- C. J. Curtis et al., "Computer-Generated Watercolor", SIGGRAPH 1997 (glazes
  over black and white, edge darkening).
- S. F. Ray, "Applied Photographic Optics", 3rd ed., Focal Press 2002, ch. 25
  (cos^4 illumination falloff).
- S. W. Hasinoff, "Photon, Poisson noise", in Computer Vision: A Reference
  Guide, Springer 2014 (shot and read noise).
"""

from __future__ import annotations

import json
import os
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import equinox as eqx
import numpy as np

from . import colorimetry, km, mixing, spectral
from ._io import FLOAT32_MAX, atomic_paths, image_format_for, refuse_overwriting_inputs, write_png
from ._lazy import lazy
from .library import Library
from .measurements import format_stack, split_layers
from .pigments import Pigment
from .shading import DEFAULT_PAPER

Image = lazy("PIL.Image")
ndimage = lazy("scipy.ndimage")

__all__ = ["CameraEffects", "SwatchCard", "make_swatch_card", "make_mixture_card", "save_swatch_card", "DEFAULT_INK",
           "IDEAL"]  # fmt: skip

#: Linear reflectance of the black ink band (an ivory-black-like ink, slightly bluish).
DEFAULT_INK = (0.035, 0.035, 0.04)


@dataclass(frozen=True)
class CameraEffects:
    """What the camera and the lighting do to the card (all defaults: a typical phone photo).

    **Fields:**

    - `exposure`: overall gain (1 puts white paper near the top of the range).
    - `white_balance`: per-channel gains (red, green, blue) of a mis-set white balance.
    - `vignetting`: relative light lost in the corners by cos^4 falloff (0: none).
    - `gradient`: relative change of the light from the left to the right edge.
    - `grain`: standard deviation of the paper's relative reflectance texture.
    - `unevenness`: standard deviation of the glaze's relative thickness.
    - `edge_darkening`: extra relative thickness at the glaze's edges.
    - `shot_noise`: noise standard deviation at signal 1 (scales as sqrt(signal)).
    - `read_noise`: signal-independent noise standard deviation.
    - `blur`: standard deviation of the optical blur, pixels.
    - `jpeg_quality`: JPEG quality when writing a .jpg.
    """

    exposure: float = 0.9
    white_balance: tuple[float, float, float] = (1.06, 1.0, 0.92)
    vignetting: float = 0.25
    gradient: float = 0.12
    grain: float = 0.015
    unevenness: float = 0.03
    edge_darkening: float = 0.25
    shot_noise: float = 0.01
    read_noise: float = 0.002
    blur: float = 1.0
    jpeg_quality: int = 90


#: A perfect camera and paper: no falloff, no noise, no blur, no texture.
IDEAL = CameraEffects(exposure=1.0, white_balance=(1.0, 1.0, 1.0), vignetting=0.0, gradient=0.0, grain=0.0,
                      unevenness=0.0, edge_darkening=0.0, shot_noise=0.0, read_noise=0.0, blur=0.0)  # fmt: skip


@dataclass
class SwatchCard:
    """A generated swatch-card photo, its layout and the truth behind it.

    **Fields:**

    - `photo`: the photo as displayed, display sRGB in [0, 1], (H, W, 3).
    - `layout`: the layout (dict, the `fit-swatch` layout format).
    - `pigment`, `paper`, `ink`: the truth (pigment, or None for a card of a library's pigments; linear
      reflectance of paper and ink).
    - `effects`: the `CameraEffects` used.
    - `library`, `amount_per_coat`, `patch_colours`: a mixture card's truth (`make_mixture_card`; None
      otherwise): the library, its amount of one coat, and the linear reflectance (sRGB) of each of the
      layout's patches, an even layer over the bare ground as a perfect camera would see it, (N, 3).
    """

    photo: np.ndarray
    layout: dict[str, Any]
    pigment: Pigment | None
    paper: np.ndarray
    ink: np.ndarray | None
    effects: CameraEffects = field(default_factory=CameraEffects)
    patch_colours: np.ndarray | None = None
    library: Library | None = None
    amount_per_coat: float | None = None


def _smooth_noise(rng: np.random.Generator, shape: tuple[int, int], sigma: float) -> np.ndarray:
    """Zero-mean, unit-variance noise smoothed over about `sigma` pixels."""
    n = ndimage.gaussian_filter(rng.standard_normal(shape), sigma, mode="wrap")
    return n / max(float(n.std()), 1e-12)


@dataclass(frozen=True)
class _Plan:
    """Where things go on a card of `columns` patch columns: its size, the paper box, the black band, the patches.

    `cells` are `(column, ground, box)` for each patch, in the layout's order (column by column, paper first).
    """

    H: int
    W: int
    margin: int
    paper_box: list[int]
    band: tuple[int, int] | None  # rows y0:y1 of the black band (it spans columns margin // 6 : W - margin // 6)
    black_box: list[int] | None
    cells: list[tuple[int, str, list[int]]]


def _plan(columns: int, black: bool, patch: int) -> _Plan:
    gap = patch // 2
    margin = patch
    W = 2 * margin + columns * patch + (columns - 1) * gap
    rows = 2 if black else 1
    H = 2 * margin + rows * patch + (rows - 1) * 2 * gap + patch // 2  # room for a paper box above
    top = margin + patch // 2
    paper_box = [margin, margin // 3, W - margin, top - patch // 6]
    band, black_box, ground_rows = None, None, [("paper", top)]
    if black:
        y0 = top + patch + gap
        y1 = y0 + patch + 2 * gap
        band = (y0, y1)
        black_box = [margin // 6 + 4, y0 + 4, margin - 6, y1 - 4]
        ground_rows = [("paper", top), ("black", y0 + gap)]
    cells = []
    for j in range(columns):
        x0 = margin + j * (patch + gap)
        for name, y0 in ground_rows:
            cells.append((j, name, [x0, y0, x0 + patch, y0 + patch]))
    return _Plan(H=H, W=W, margin=margin, paper_box=paper_box, band=band, black_box=black_box, cells=cells)


def _edge_profile(patch: int, edge_darkening: float) -> np.ndarray:
    """A glaze's relative thickness over its patch: 1 inside, up to `1 + edge_darkening` at its edges."""
    yy, xx = np.mgrid[0:patch, 0:patch]
    edge = np.minimum.reduce([yy, xx, patch - 1 - yy, patch - 1 - xx]).astype(float)
    return 1 + edge_darkening * np.exp(-edge / 2.0)


def _rng(seed: Any) -> np.random.Generator:
    """The random generator of `seed`, a whole number >= 0 (a ValueError naming the seed otherwise)."""
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed must be a whole number >= 0, got {seed!r}")
    return np.random.default_rng(int(seed))


def make_swatch_card(
    pigment: Pigment,
    *,
    coats: Sequence[float] = (1, 2, 3, 4),
    black: bool = True,
    paper: Sequence[float] = DEFAULT_PAPER,
    ink: Sequence[float] = DEFAULT_INK,
    effects: CameraEffects = CameraEffects(),
    patch: int = 48,
    seed: int = 0,
) -> SwatchCard:
    """Make a photo of a swatch card of `pigment`.

    **Arguments:**

    - `pigment`: the pigment painted (its K and S are per coat).
    - `coats`: the coat counts (thicknesses) of the patches, one column each.
    - `black`: whether the card has the black ink band (and patches over it).
    - `paper`, `ink`: linear reflectance of the paper and of the black ink.
    - `effects`: the `CameraEffects`.
    - `patch`: patch side in pixels (the photo is about `(len(coats) + 1) *
      1.5 * patch` wide).
    - `seed`: the random seed (grain, unevenness, noise).

    **Returns:**

    A `SwatchCard`.
    """
    rng = _rng(seed)
    paper = np.asarray(paper, np.float64)
    ink_rgb = np.asarray(ink, np.float64)
    plan = _plan(len(coats), black, patch)
    H, W = plan.H, plan.W

    # The card's reflectance: paper with grain, the black band, then the glazes.
    ground = np.broadcast_to(paper, (H, W, 3)).copy()
    if effects.grain > 0:
        grain = 1 + effects.grain * _smooth_noise(rng, (H, W), 1.2)
        ground *= grain[..., None]
    layout: dict[str, Any] = {"paper": {"box": plan.paper_box, "reflectance": paper.tolist()}}
    if plan.band is not None:
        y0, y1 = plan.band
        ground[y0:y1, plan.margin // 6 : W - plan.margin // 6] = ink_rgb
        layout["black"] = {"box": plan.black_box}
    thickness = np.zeros((H, W))
    profile = _edge_profile(patch, effects.edge_darkening)
    patches = []
    for j, name, box in plan.cells:
        x0, y0 = box[0], box[1]
        thickness[y0 : y0 + patch, x0 : x0 + patch] = float(coats[j]) * profile
        patches.append({"box": box, "coats": coats[j], "ground": name})
    layout["patches"] = patches
    if effects.unevenness > 0:
        thickness *= 1 + effects.unevenness * _smooth_noise(rng, (H, W), 4.0)
    card = np.empty((H, W, 3), np.float64)
    rows = max(1, (1 << 18) // W)  # the glaze composited in bands of rows: its temporaries are the band's size
    for y in range(0, H, rows):
        R, T = km.layer(np.asarray(pigment.K), np.asarray(pigment.S), np.maximum(thickness[y : y + rows], 0)[..., None])
        card[y : y + rows] = np.asarray(km.over(R, T, ground[y : y + rows]), np.float64)
    return SwatchCard(photo=_photograph(card, effects, rng), layout=layout, pigment=pigment, paper=paper,
                      ink=ink_rgb if black else None, effects=effects)  # fmt: skip


def _photograph(card: np.ndarray, effects: CameraEffects, rng: np.random.Generator) -> np.ndarray:
    """The photo (display sRGB in [0, 1]) a camera takes of a card of linear reflectance `card`, (H, W, 3).

    Made in bands of rows (each with the rows the blur reaches beyond it), so that a card of hundreds of patches
    takes tens of MB beside its photo, not ten copies of it; the noise is drawn row after row, as one draw of the
    whole photo would (the same photo, band by band or whole)."""
    H, W, _ = card.shape
    reach = int(4.0 * effects.blur + 0.5) if effects.blur > 0 else 0  # ndimage.gaussian_filter's radius
    rows = max(4 * reach + 1, (1 << 18) // W)
    noisy = effects.shot_noise > 0 or effects.read_noise > 0
    noise = _RowNoise(rng, W)
    out = np.empty((H, W, 3), np.float64)
    for y0 in range(0, H, rows):
        y1 = min(y0 + rows, H)
        a, b = max(y0 - reach, 0), min(y1 + reach, H)
        signal = card[a:b] * _light(a, b, H, W, effects)[..., None] * effects.exposure
        signal *= np.asarray(effects.white_balance)
        if noisy:
            sd = np.sqrt(effects.shot_noise**2 * np.maximum(signal, 0) + effects.read_noise**2)
            signal = signal + sd * noise.rows(a, b)
        if effects.blur > 0:
            signal = ndimage.gaussian_filter(signal, (effects.blur, effects.blur, 0), mode="nearest")
        signal = signal[y0 - a : y1 - a]
        out[y0:y1] = np.clip(np.asarray(colorimetry.srgb_encode(np.clip(signal, 0, 1)), np.float64), 0, 1)
    return out


def _light(a: int, b: int, H: int, W: int, effects: CameraEffects) -> np.ndarray:
    """The relative light on rows `a:b` of an `H` x `W` card: cos^4 falloff, the field angle chosen so that the
    corners lose `vignetting`, and a linear gradient from left to right."""
    yy, xx = np.mgrid[a:b, 0:W].astype(np.float64)
    cx, cy = (W - 1) / 2, (H - 1) / 2
    r2 = ((xx - cx) ** 2 + (yy - cy) ** 2) / (cx**2 + cy**2)
    tan2 = r2 * ((1 - effects.vignetting) ** -0.5 - 1)
    return 1 / (1 + tan2) ** 2 * (1 + effects.gradient * (xx / max(W - 1, 1) - 0.5))


class _RowNoise:
    """Standard normal noise for rows of a `W`-pixel-wide RGB image, drawn in row order and kept while needed."""

    def __init__(self, rng: np.random.Generator, W: int):
        self.rng, self.W, self.first, self.kept = rng, W, 0, np.empty((0, W, 3))

    def rows(self, a: int, b: int) -> np.ndarray:
        """Rows `a:b`; `a` never goes back before an earlier call's."""
        drawn = self.first + len(self.kept)
        if b > drawn:
            self.kept = np.concatenate([self.kept, self.rng.standard_normal((b - drawn, self.W, 3))])
        self.kept, self.first = self.kept[a - self.first :], a
        return self.kept[: b - a]


def _mixture_patch(spec: Any, i: int) -> tuple[tuple[str, ...], tuple[float, ...], tuple[int, ...]]:
    """`(pigment, coats)` of a mixture card's patch as names, coats of each and pigments per layer (`"P1+P4",
    "1+2"` or tuples; `"P1/P4", "1/2"` for a glaze stack, bottom layer first)."""
    pigment, coats = spec
    if isinstance(pigment, str) and "/" in pigment:
        if not isinstance(coats, str) or coats.count("/") != pigment.count("/"):
            raise ValueError(f"patches[{i}]: a stack needs '/'-joined coats, a group per layer, got {spec!r}")
        layers = [_mixture_patch((p, c), i) for p, c in zip(pigment.split("/"), coats.split("/"))]
        return (tuple(n for x in layers for n in x[0]), tuple(a for x in layers for a in x[1]),
                tuple(len(x[0]) for x in layers))  # fmt: skip
    names = tuple(" ".join(n.split()) for n in (pigment.split("+") if isinstance(pigment, str) else pigment))
    if isinstance(coats, str):
        amounts = tuple(float(c) for c in coats.split("+"))
    else:
        amounts = tuple(float(c) for c in np.atleast_1d(np.asarray(coats, np.float64)))
    if not names or any(not n for n in names) or len(amounts) != len(names):
        raise ValueError(f"patches[{i}]: needs as many coats as pigments, got {spec!r}")
    if not all(np.isfinite(a) and a >= 0 for a in amounts) or sum(amounts) <= 0:
        raise ValueError(f"patches[{i}]: coats must be finite, >= 0 and > 0 in all, got {spec!r}")
    return names, amounts, (len(names),)


def _smooth_spectrum(linear_rgb: np.ndarray, obs: spectral.Observation) -> np.ndarray:
    """A smooth, positive spectrum on `obs`'s bands whose linear sRGB is `linear_rgb` (three broad bumps)."""
    if obs.wavelengths is None:
        return np.asarray(linear_rgb, np.float64)
    wl = np.asarray(obs.wavelengths, np.float64)
    bumps = np.exp(-0.5 * ((wl[:, None] - np.array([450.0, 550.0, 620.0])) / 60) ** 2)
    M = np.asarray(obs.to_rgb, np.float64).T @ bumps
    return np.maximum(bumps @ np.linalg.solve(M, np.asarray(linear_rgb, np.float64)), 1e-4)


#: Pixels of a mixture card painted at once (`_paint_card`): a card of hundreds of patches is millions of pixels
#: of tens of bands, gigabytes painted whole; in blocks of this many, one compiled program paints any card in
#: tens of MB.
_PAINT_BLOCK = 1 << 16


@eqx.filter_jit
def _paint(palette: mixing.Palette, A: Any, column: Any, thickness: Any, ground: Any, k2: float,
           obs: spectral.Observation) -> Any:  # fmt: skip
    """The linear sRGB of a block of a mixture card's pixels, (n, 3), in one compiled program.

    Each pixel's paint is its column's (`column`, (n,), an index into the rows of amounts `A`, (N, L, P) layer by
    layer, bottom first; row 0 holds nothing) with every layer's optical depths scaled by `thickness`, (n,), over
    its ground spectrum `ground`, (n, B) (`mixing.stack_reflectance`: Saunderson's term at the top only).
    """
    t = thickness[..., None]
    g = mixing.saunderson_in(ground, k2)
    if A.shape[1] == 1:  # one layer: as before stacks
        Kx, Sx = palette.optical_depths(A[:, 0])
        R, T = km.layer(Kx[column] * t, Sx[column] * t, 1.0)
        g = km.over(R, T, g)
    else:
        Kx, Sx = palette.optical_depths(A)  # (N, L, B)
        for i in range(A.shape[1]):
            R, T = km.layer(Kx[column, i] * t, Sx[column, i] * t, 1.0)
            g = km.over(R, T, g)
    return obs.linear_srgb(mixing.saunderson_out(g, k2))


@eqx.filter_jit
def _even_colours(palette: mixing.Palette, cell_amounts: Any, under: Any, k2: float, obs: spectral.Observation) -> Any:
    """The linear sRGB of the patches painted evenly, (N, 3)."""
    return obs.linear_srgb(palette.stack_reflectance(cell_amounts, under, k2))


def _paint_card(palette: mixing.Palette, A: Any, column: np.ndarray, thickness: np.ndarray, grounds: np.ndarray,
                which: np.ndarray, grain: np.ndarray, k2: float, obs: spectral.Observation) -> np.ndarray:  # fmt: skip
    """A mixture card's linear sRGB, (H, W, 3) float64, painted `_PAINT_BLOCK` pixels at a time (`_paint`).

    A pixel's ground spectrum is `grounds[which]` (paper, ink) times its `grain`, all (H, W)."""
    H, W = column.shape
    out = np.empty((H * W, 3), np.float64)
    column, thickness, which, grain = (a.reshape(-1) for a in (column, thickness, which, grain))
    for start in range(0, H * W, _PAINT_BLOCK):
        sl = slice(start, min(start + _PAINT_BLOCK, H * W))
        n = sl.stop - sl.start
        pad = lambda a: np.pad(a, (0, _PAINT_BLOCK - n))  # noqa: E731 (one block shape: one compilation)
        ground = grounds[pad(which[sl])] * pad(grain[sl])[:, None]
        out[sl] = np.asarray(_paint(palette, A, pad(column[sl]), pad(thickness[sl]), ground, k2, obs))[:n]
    return out.reshape(H, W, 3)


def make_mixture_card(
    library: Library,
    patches: Sequence[tuple[Any, Any]],
    *,
    amount_per_coat: float | None = None,
    paper: str = "paper",
    black: bool = True,
    ink: Sequence[float] = DEFAULT_INK,
    effects: CameraEffects = CameraEffects(),
    patch: int = 48,
    seed: int = 0,
) -> SwatchCard:
    """Make a photo of a swatch card whose patches are a library's pigments, alone or mixed.

    The truth is a mixable `diffwash.library.Library` (e.g. `data/libraries/ntu-four.json`, spectral):
    each patch's layer, brushed from its pigments' amounts, has the optical depths `Kx`, `Sx` per band
    of `diffwash.mixing` (its pair terms included), scaled pixel by pixel by the glaze's relative
    thickness (uneven, darker at the edges, as `make_swatch_card`); its reflectance and transmittance
    per band are composited with Kubelka-Munk (and the library's surface term) over the paper (the
    library's ground `paper`, with grain) or over the black ink (a smooth spectrum of linear sRGB
    `ink`), and seen in linear sRGB through the library's observation. The camera is
    `make_swatch_card`'s.

    **Arguments:**

    - `library`: the library whose pigments are painted.
    - `patches`: one column each: `(pigment, coats)`, e.g. `("P1", 2)` or `("P1+P4", "1+2")` (or tuples
      `(("P1", "P4"), (1, 2))`): the coats of each pigment in one layer; `("P1/P4", "1/2")` is a glaze
      stack, two coats of P4 over one of dry P1 (layers bottom first, each painted with the patch's
      uneven thickness, `diffwash.mixing.stack_reflectance`).
    - `amount_per_coat`: the library's amount of one coat (default: its amount law's reference, where the
      thickness is 1).
    - `paper`: the library's ground the card is painted on.
    - `black`, `ink`, `effects`, `patch`, `seed`: as `make_swatch_card`.

    **Returns:**

    A `SwatchCard` whose layout names every patch's pigments and coats, with `pigment` None and
    `library` the truth.
    """
    specs = [_mixture_patch(spec, i) for i, spec in enumerate(patches)]
    if not specs:
        raise ValueError("a card needs at least one patch")
    per_coat = float(library.palette.law.reference if amount_per_coat is None else amount_per_coat)
    if not (np.isfinite(per_coat) and per_coat > 0):
        raise ValueError(f"amount_per_coat must be > 0, got {amount_per_coat!r}")
    most = per_coat * max(sum(spec[1]) for spec in specs)
    if not most <= FLOAT32_MAX:
        raise ValueError(f"amount_per_coat {per_coat:g} makes a patch of {most:g}, out of float32 range (magnitude at "
                         f"most {FLOAT32_MAX:.4g}), which diffwash computes in")  # fmt: skip
    rng = _rng(seed)
    obs = library.observation
    paper_spec = library.ground_matrix([paper])[0]
    ink_rgb = np.asarray(ink, np.float64)
    ink_spec = _smooth_spectrum(ink_rgb, obs)
    plan = _plan(len(specs), black, patch)
    H, W = plan.H, plan.W

    A = library.layer_amounts([n for n, _, _ in specs], [tuple(per_coat * a for a in amts) for _, amts, _ in specs],
                              [k for _, _, k in specs])  # fmt: skip
    # The ground's spectrum at each pixel: paper with grain, or the ink of the black band (which: 0 paper, 1 ink).
    grain = 1 + effects.grain * _smooth_noise(rng, (H, W), 1.2) if effects.grain > 0 else np.ones((H, W))
    which = np.zeros((H, W), np.intp)
    paper_rgb = paper_spec @ np.asarray(obs.to_rgb, np.float64)
    layout: dict[str, Any] = {"paper": {"box": plan.paper_box, "reflectance": paper_rgb.tolist()}}
    if plan.band is not None:
        y0, y1 = plan.band
        which[y0:y1, plan.margin // 6 : W - plan.margin // 6] = 1
        grain[y0:y1, plan.margin // 6 : W - plan.margin // 6] = 1.0  # the ink has no grain
        layout["black"] = {"box": plan.black_box}
    column = np.zeros((H, W), int)  # column 0 is no paint
    thickness = np.zeros((H, W))
    profile = _edge_profile(patch, effects.edge_darkening)
    cells = []
    for j, name, box in plan.cells:
        x0, y0 = box[0], box[1]
        column[y0 : y0 + patch, x0 : x0 + patch] = j + 1
        thickness[y0 : y0 + patch, x0 : x0 + patch] = profile
        names, amounts, sizes = specs[j]
        pigment, coats = format_stack(split_layers(names, amounts, sizes))
        cells.append({"box": box, "pigment": pigment, "coats": amounts[0] if len(amounts) == 1 else coats,
                      "ground": name})  # fmt: skip
    layout["patches"] = cells
    if effects.unevenness > 0:
        thickness *= 1 + effects.unevenness * _smooth_noise(rng, (H, W), 4.0)
    under = np.stack([paper_spec if g == "paper" else ink_spec for _, g, _ in plan.cells])
    card = _paint_card(library.palette, np.concatenate([np.zeros((1, *A.shape[1:])), A]), column,
                       np.maximum(thickness, 0), np.stack([paper_spec, ink_spec]), which, grain, float(library.k2),
                       obs)  # fmt: skip
    colours = np.asarray(_even_colours(library.palette, A[[j for j, _, _ in plan.cells]], under, float(library.k2),
                                       obs), np.float64)  # fmt: skip
    return SwatchCard(photo=_photograph(card, effects, rng), layout=layout, pigment=None, paper=paper_rgb,
                      ink=ink_rgb if black else None, effects=effects, patch_colours=colours, library=library,
                      amount_per_coat=per_coat)  # fmt: skip


#: EXIF orientation -> how to store pixels so that the photo displays upright.
_STORE = {
    1: lambda a: a,
    3: lambda a: a[::-1, ::-1],
    6: lambda a: np.swapaxes(a, 0, 1)[::-1],  # displayed = stored rotated 90 degrees clockwise
    8: lambda a: np.swapaxes(a, 0, 1)[:, ::-1],
}


def save_swatch_card(
    card: SwatchCard,
    photo_path: str | os.PathLike,
    layout_path: str | os.PathLike | None = None,
    *,
    bits: int = 8,
    orientation: int = 1,
) -> None:
    """Write the card's photo (PNG 8/16 bit, or JPEG by the suffix) and its layout JSON.

    **Arguments:**

    - `card`: the `SwatchCard`.
    - `photo_path`: `.png`, `.jpg` or `.jpeg`.
    - `layout_path`: where the layout goes (default: the photo's name with `.json`).
    - `bits`: 8 or 16 (PNG only).
    - `orientation`: EXIF orientation tag (1, 3, 6 or 8): the pixels are stored
      turned so that a viewer that honours the tag shows the card upright (the
      layout's boxes are in displayed coordinates).
    """
    photo_path = Path(photo_path)
    if orientation not in _STORE:
        raise ValueError(f"orientation must be one of {sorted(_STORE)}, got {orientation}")
    fmt = image_format_for(photo_path, bits=bits)
    if fmt == "png" and orientation != 1 and bits != 8:
        raise ValueError("an EXIF-oriented PNG is written 8-bit")
    layout_path = Path(layout_path) if layout_path is not None else photo_path.with_suffix(".json")
    refuse_overwriting_inputs({"photo": photo_path, "layout": layout_path}, [])
    stored = np.ascontiguousarray(_STORE[orientation](card.photo))
    if card.library is not None:  # the truth: the library (without its fit record) and the amount of a coat
        truth = {k: v for k, v in card.library.to_dict().items() if k != "fit"}
        meta = {"generator": "diffwash.swatchcard", "library": truth, "amount_per_coat": card.amount_per_coat}
    else:
        meta = {"generator": "diffwash.swatchcard", "pigment": card.pigment.to_dict()}
    meta["effects"] = asdict(card.effects)
    layout_text = json.dumps({**card.layout, "meta": meta}, indent=2, allow_nan=False) + "\n"
    # Both files or neither: each goes to a temporary name, and both are renamed once both are complete.
    with atomic_paths(photo_path, layout_path) as (photo_tmp, layout_tmp):
        if fmt == "png" and orientation == 1:
            write_png(photo_tmp, stored, bits=bits)
        else:
            im = Image.fromarray(np.round(stored * 255).astype(np.uint8))
            exif = Image.Exif()
            exif[0x0112] = orientation
            extra = {"quality": card.effects.jpeg_quality} if fmt == "jpeg" else {}
            im.save(photo_tmp, format=fmt.upper(), exif=exif, **extra)
        layout_tmp.write_text(layout_text, encoding="utf-8")
