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

import numpy as np
from PIL import Image
from scipy.ndimage import gaussian_filter

from . import colorimetry, km
from ._io import atomic_paths, image_format_for, refuse_overwriting_inputs, write_png
from .pigments import Pigment
from .shading import DEFAULT_PAPER

__all__ = ["CameraEffects", "SwatchCard", "make_swatch_card", "save_swatch_card", "DEFAULT_INK", "IDEAL"]

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
    - `pigment`, `paper`, `ink`: the truth (pigment; linear reflectance of paper and ink).
    - `effects`: the `CameraEffects` used.
    """

    photo: np.ndarray
    layout: dict[str, Any]
    pigment: Pigment
    paper: np.ndarray
    ink: np.ndarray | None
    effects: CameraEffects = field(default_factory=CameraEffects)


def _smooth_noise(rng: np.random.Generator, shape: tuple[int, int], sigma: float) -> np.ndarray:
    """Zero-mean, unit-variance noise smoothed over about `sigma` pixels."""
    n = gaussian_filter(rng.standard_normal(shape), sigma, mode="wrap")
    return n / max(float(n.std()), 1e-12)


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
    rng = np.random.default_rng(seed)
    paper = np.asarray(paper, np.float64)
    ink_rgb = np.asarray(ink, np.float64)
    n = len(coats)
    gap = patch // 2
    margin = patch
    W = 2 * margin + n * patch + (n - 1) * gap
    rows = 2 if black else 1
    H = 2 * margin + rows * patch + (rows - 1) * 2 * gap + patch // 2  # room for a paper box above
    top = margin + patch // 2

    # The card's reflectance: paper with grain, the black band, then the glazes.
    ground = np.broadcast_to(paper, (H, W, 3)).copy()
    if effects.grain > 0:
        grain = 1 + effects.grain * _smooth_noise(rng, (H, W), 1.2)
        ground *= grain[..., None]
    layout: dict[str, Any] = {"paper": {"box": [margin, margin // 3, W - margin, top - patch // 6],
                                        "reflectance": paper.tolist()}}  # fmt: skip
    if black:
        y0 = top + patch + gap
        y1 = y0 + patch + 2 * gap
        ground[y0:y1, margin // 6 : W - margin // 6] = ink_rgb
        layout["black"] = {"box": [margin // 6 + 4, y0 + 4, margin - 6, y1 - 4]}
        ground_rows = [("paper", top), ("black", y0 + gap)]
    else:
        ground_rows = [("paper", top)]
    thickness = np.zeros((H, W))
    patches = []
    for j, c in enumerate(coats):
        x0 = margin + j * (patch + gap)
        for name, y0 in ground_rows:
            box = [x0, y0, x0 + patch, y0 + patch]
            yy, xx = np.mgrid[0:patch, 0:patch]
            edge = np.minimum.reduce([yy, xx, patch - 1 - yy, patch - 1 - xx]).astype(float)
            t = float(c) * (1 + effects.edge_darkening * np.exp(-edge / 2.0))
            thickness[y0 : y0 + patch, x0 : x0 + patch] = t
            patches.append({"box": box, "coats": c, "ground": name})
    layout["patches"] = patches
    if effects.unevenness > 0:
        thickness *= 1 + effects.unevenness * _smooth_noise(rng, (H, W), 4.0)
    R, T = km.layer(np.asarray(pigment.K), np.asarray(pigment.S), np.maximum(thickness, 0)[..., None])
    card = np.asarray(km.over(R, T, ground), np.float64)

    # The light and the camera.
    yy, xx = np.mgrid[0:H, 0:W].astype(np.float64)
    cx, cy = (W - 1) / 2, (H - 1) / 2
    r2 = ((xx - cx) ** 2 + (yy - cy) ** 2) / (cx**2 + cy**2)
    # cos^4 falloff with the field angle chosen so that the corners lose `vignetting`.
    tan2 = r2 * ((1 - effects.vignetting) ** -0.5 - 1)
    light = 1 / (1 + tan2) ** 2 * (1 + effects.gradient * (xx / max(W - 1, 1) - 0.5))
    signal = card * light[..., None] * effects.exposure * np.asarray(effects.white_balance)
    if effects.shot_noise > 0 or effects.read_noise > 0:
        sd = np.sqrt(effects.shot_noise**2 * np.maximum(signal, 0) + effects.read_noise**2)
        signal = signal + sd * rng.standard_normal(signal.shape)
    if effects.blur > 0:
        signal = gaussian_filter(signal, (effects.blur, effects.blur, 0), mode="nearest")
    photo = np.clip(np.asarray(colorimetry.srgb_encode(np.clip(signal, 0, 1)), np.float64), 0, 1)
    return SwatchCard(photo=photo, layout=layout, pigment=pigment, paper=paper, ink=ink_rgb if black else None,
                      effects=effects)  # fmt: skip


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
    meta = {"generator": "diffwash.swatchcard", "pigment": card.pigment.to_dict(), "effects": asdict(card.effects)}
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
