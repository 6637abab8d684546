"""Photos calibrated from patches of known colour, on simulated phone photos (issue 20, item 2).

A card on a dark grey board holds the 24 patches of a ColorChecker Classic (their reflectance spectra,
colour-science's `SDS_COLOURCHECKERS["BabelColor Average"]`), 8 paint patches (smooth spectra) and a white
patch (the layout's paper, its reflectance given). It is "photographed" as a phone would, not through
diffwash's own swatch-card generator: linear reflectance -> a 3x3 sensor crosstalk matrix -> a white-balance
error -> exposure and vignetting -> shot and read noise -> a non-sRGB tone curve (an S-curve with lifted
blacks) -> JPEG (quality 90). Several cameras (tone curve, matrix, white balance) are run.

(a) paper and black boxes only: the mean CIEDE2000 of every patch read by `fit-swatch`'s measurement
    (`diffwash.fit.photos._swatch._measure`) against its truth, and of plain scaling of the sRGB-linearised
    photo to the paper box, channel by channel;
(b) 8 of the checker's patches as `references` in the layout: the mean CIEDE2000 of the other 16.

The four built-in phones' tone curves are invented (an S-curve on top of the sRGB curve) and their files name
no camera, so (a) reads them through the sRGB curve; the column "(a) camera curve" reads them through
`diffwash.fit.photos._camera.camera_curve` instead, the cost of that assumption when it is wrong.

`--curves FILE` adds cameras whose tone curves were measured: a JSON object `{"name": [[x, y], ...]}` of
base curves (raw signal x -> linear display value y, then the sRGB encoding, as darktable's base-curve
presets: each maker's curve measured from raw and JPEG pairs; darktable's source, src/iop/basecurve.c, is
GPL and not shipped here). Those photos carry an EXIF camera make, so (a) reads them as `fit-swatch` does
by default, through the typical camera curve; each curve is photographed with the paper at 55% and 90% of
the sensor's clipping.

Run: PYTHONPATH=. python benchmarks/bench_photo.py [--curves FILE]  (about two minutes on 2 cores).
"""

from __future__ import annotations

import json
import sys
import tempfile
import time
from pathlib import Path

import colour
import numpy as np
from PIL import Image

from diffwash import colorimetry
from diffwash.fit.photos._camera import lab_to_linear, spectrum_lab
from diffwash.fit.photos._swatch import _measure

PATCH, GAP, COLS = 64, 24, 8
BOARD = 0.12  # the board's reflectance (dark grey, not black)
TEXTURE = 0.03  # the board's relative texture (standard deviation)

#: Cameras: (name, tone curve parameters (contrast, lift, gamma), crosstalk matrix, white-balance error).
CAMERAS = [
    ("phone A: S-curve, lifted blacks", (0.25, 0.05, 1.0),
     [[0.82, 0.15, 0.03], [0.10, 0.80, 0.10], [0.02, 0.18, 0.80]], (1.08, 1.0, 0.90)),
    ("phone B: strong S-curve, warm", (0.45, 0.03, 0.9),
     [[0.75, 0.20, 0.05], [0.12, 0.76, 0.12], [0.05, 0.20, 0.75]], (1.15, 1.0, 0.82)),
    ("phone C: flat curve, high lift, cool", (0.10, 0.09, 1.15),
     [[0.88, 0.10, 0.02], [0.06, 0.88, 0.06], [0.01, 0.10, 0.89]], (0.92, 1.0, 1.12)),
    ("phone D: gamma 2.0, mild S", (0.20, 0.02, 0.85),
     [[0.78, 0.18, 0.04], [0.15, 0.72, 0.13], [0.03, 0.25, 0.72]], (1.0, 1.0, 1.0)),
]


def tone_curve(x: np.ndarray, contrast: float, lift: float, gamma: float) -> np.ndarray:
    """A phone's tone curve: sRGB encoding, a gamma tweak, an S-curve of `contrast`, blacks lifted by `lift`."""
    e = colorimetry.to_display(np.clip(x, 0, 1)) ** gamma
    s = np.clip(e + contrast * (e - 0.5) * (1 - np.abs(2 * e - 1)), 0, 1)  # steeper mid-tones, flatter ends
    return lift + (1 - lift) * s


def patches() -> tuple[list[str], np.ndarray]:
    """The card's patches: names and CIELAB truth (D65); the checker's first, then paints."""
    sds = colour.SDS_COLOURCHECKERS["BabelColor Average"]
    names, labs = [], []
    for name, sd in sds.items():
        names.append(name)
        labs.append(spectrum_lab(sd.wavelengths, sd.values))
    wl = np.arange(380.0, 781.0, 10.0)
    rng = np.random.default_rng(7)
    for k in range(8):
        c, w = rng.uniform(420, 680, 2), rng.uniform(30, 80, 2)
        sp = 0.04 + sum(rng.uniform(0.1, 0.6) * np.exp(-0.5 * ((wl - c[j]) / w[j]) ** 2) for j in range(2))
        names.append(f"paint {k + 1}")
        labs.append(spectrum_lab(wl, np.clip(sp, 0, 0.95)))
    return names, np.array(labs)


def card(labs: np.ndarray) -> tuple[np.ndarray, dict, list]:
    """The card's linear reflectance image and its layout (paper, black, every patch), and the boxes."""
    n = len(labs) + 1  # + the white patch
    rows = -(-n // COLS)
    H, W = GAP + rows * (PATCH + GAP) + 80, GAP + COLS * (PATCH + GAP)
    rng = np.random.default_rng(1)
    img = BOARD * (1 + TEXTURE * rng.standard_normal((H, W, 1))) * np.ones((1, 1, 3))
    boxes = []
    lin = np.clip(lab_to_linear(labs), 0, 1)
    white = np.array([0.86, 0.86, 0.85])
    for i, rgb in enumerate([white, *lin]):
        y, x = GAP + (i // COLS) * (PATCH + GAP), GAP + (i % COLS) * (PATCH + GAP)
        img[y : y + PATCH, x : x + PATCH] = rgb * (1 + 0.01 * rng.standard_normal((PATCH, PATCH, 1)))
        boxes.append([x, y, x + PATCH, y + PATCH])
    black = [GAP, H - 70, W - GAP, H - 20]
    layout = {"paper": {"box": boxes[0], "reflectance": white.tolist()}, "black": {"box": black},
              "patches": [{"box": b, "coats": 1, "ground": "paper"} for b in boxes[1:]]}  # fmt: skip
    return img, layout, boxes[1:]


def measured_curve(points: list, exposure: float):
    """A measured base curve (monotone cubic through its points, then the sRGB encoding) at `exposure`."""
    from scipy.interpolate import PchipInterpolator

    xs, ys = np.array([[0.0, 0.0], *points, [1.0, 1.0]], np.float64).T
    order = np.unique(xs, return_index=True)[1]
    B = PchipInterpolator(xs[order], ys[order])
    return lambda x: colorimetry.to_display(np.clip(B(np.clip(exposure * x, 0, 1)), 0, 1))


def photograph(img: np.ndarray, camera: tuple, path: Path, seed: int) -> None:
    """Render `img` (linear reflectance) as a phone would and write a JPEG (module docstring). A camera whose
    curve is measured (a callable) writes an EXIF camera make, as a phone's file does."""
    _, curve, C, wb = camera
    rng = np.random.default_rng(seed)
    H, W, _ = img.shape
    sensor = np.clip(img @ np.asarray(C).T, 0, None) * np.asarray(wb)
    yy, xx = np.mgrid[0:H, 0:W]
    r2 = ((xx - W / 2) ** 2 + (yy - H / 2) ** 2) / (0.5 * np.hypot(W, H)) ** 2
    light = 0.95 / (1 + 0.35 * r2) ** 2 * (1 + 0.08 * (xx / W - 0.5))
    sensor = sensor * light[..., None]
    sensor = sensor + np.sqrt(0.0004 * sensor + 1e-6) * rng.standard_normal(sensor.shape)
    enc = curve(sensor) if callable(curve) else tone_curve(sensor, *curve)
    exif = Image.Exif()
    if callable(curve):
        exif[0x010F] = "bench_photo measured curve"  # Make
    Image.fromarray(np.round(255 * np.clip(enc, 0, 1)).astype(np.uint8)).save(path, quality=90, exif=exif)


def de(rgb: np.ndarray, lab: np.ndarray) -> np.ndarray:
    return np.asarray(colorimetry.delta_e_2000(colorimetry.linear_srgb_to_lab(np.clip(rgb, 0, None)), lab))


def plain_scaling(photo: Path, layout: dict) -> np.ndarray:
    """The baseline: the sRGB-linearised photo scaled to the paper box's reflectance, channel by channel."""
    lin = colorimetry.from_display(np.asarray(Image.open(photo), np.float64) / 255)
    mean = lambda b: np.median(lin[b[1] + 8 : b[3] - 8, b[0] + 8 : b[2] - 8].reshape(-1, 3), axis=0)  # noqa: E731
    gain = mean(layout["paper"]["box"]) / np.asarray(layout["paper"]["reflectance"])
    return np.array([mean(p["box"]) / gain for p in layout["patches"]])


#: Boards: (name, reflectance, relative texture). The issue's photo had "the bare board -- not black, a dark-ish
#: board -- as black".
BOARDS = [("dark smooth board", 0.12, 0.03), ("mid-grey textured board", 0.25, 0.15)]


def run(cameras: list | None = None) -> list[dict]:
    global BOARD, TEXTURE
    out = []
    for board in BOARDS:
        _, BOARD, TEXTURE = board
        out += run_board(board[0], CAMERAS if cameras is None else cameras)
    return out


def curve_cameras(path: str) -> list[tuple]:
    """Cameras of measured tone curves (`--curves`), with phone A's crosstalk and white-balance error."""
    curves = json.loads(Path(path).read_text())
    _, _, C, wb = CAMERAS[0]
    # The card's white patch reaches 0.86 * 0.95 (light) * 1.08 (red's white balance) = 0.88 of clipping at 1.
    return [(f"{name} (paper at {level:.0%})", measured_curve(points, level / 0.88), C, wb)
            for name, points in curves.items() for level in (0.55, 0.9)]  # fmt: skip


def run_board(board: str, cameras: list) -> list[dict]:
    names, labs = patches()
    img, layout, boxes = card(labs)
    checker = np.arange(24)
    refs = checker[::3]  # 8 references: every third checker patch
    held = np.setdiff1d(checker, refs)
    out = []
    with tempfile.TemporaryDirectory() as tmp:
        for k, cam in enumerate(cameras):
            photo = Path(tmp) / f"card{k}.jpg"
            photograph(img, cam, photo, seed=k)
            t0 = time.perf_counter()
            a = np.array([s.rgb for s in _measure(photo, layout).patches])
            a_cam = np.array([s.rgb for s in _measure(photo, layout, tone_curve="camera").patches])
            base = plain_scaling(photo, layout)
            lay_b = dict(layout, references=[{"box": boxes[i], "lab": labs[i].tolist()} for i in refs])
            m = _measure(photo, lay_b)
            b = np.array([s.rgb for s in m.patches])
            row = {"board": board, "camera": cam[0], "a_every_patch": float(np.mean(de(a, labs))),
                   "a_camera_curve": float(np.mean(de(a_cam, labs))),
                   "a_plain_scaling": float(np.mean(de(base, labs))),
                   "b_other_16": float(np.mean(de(b[held], labs[held]))),
                   "b_paints": float(np.mean(de(b[24:], labs[24:]))),
                   "b_model": m.calibration.camera.name, "b_accuracy": m.calibration.camera.accuracy,
                   "seconds": time.perf_counter() - t0}  # fmt: skip
            out.append(row)
            print(json.dumps(row), flush=True)
    return out


if __name__ == "__main__":
    import argparse

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--curves", metavar="FILE", help="also cameras of measured tone curves (module docstring)")
    args = ap.parse_args()
    rows = run(CAMERAS + (curve_cameras(args.curves) if args.curves else []))
    for key in ("a_every_patch", "a_camera_curve", "a_plain_scaling", "b_other_16", "b_paints"):
        print(f"{key}: mean over cameras {np.mean([r[key] for r in rows]):.2f}", file=sys.stderr)
