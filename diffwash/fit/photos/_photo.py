r"""Reading a swatch-card photo: the layout, the camera's calibration, patch statistics.

The layout file (JSON) says where things are, in pixels of the photo as
displayed (EXIF orientation applied; x to the right, y down; a box is
`[x0, y0, x1, y1]` with `x0 < x1`, `y0 < y1`, covering pixels `x0 <= x < x1`):

```
{"paper":   {"box": [x0, y0, x1, y1], "reflectance": [0.92, 0.90, 0.84]},
 "black":   {"box": [x0, y0, x1, y1]},
 "patches": [{"box": [x0, y0, x1, y1], "coats": 1, "ground": "paper"},
             {"box": [...], "coats": 2, "ground": "black"},
             {"box": [...], "pigment": "P1+P4", "coats": "1+2", "ground": "paper"}],
 "name": "Cadmium Red"}
```

`paper` is required; its `reflectance` (linear RGB) is optional and defaults to
diffwash's paper `DEFAULT_PAPER` = (0.92, 0.90, 0.84). `black` (a box of the
bare black band) is required when a patch lies on black. `coats` is the
patch's thickness in coats (> 0, may be fractional). `name` is optional (the
pigment's name). A `meta` object is ignored.

A patch may name its paint: `pigment` is a pigment's name, or several joined
by `+` for a mixture brushed as one layer (as in measurement tables,
`diffwash.measurements`), and `coats` then gives the coats of each, a number
for one pigment or as many `+`-joined numbers (>= 0, in all > 0) as there are
pigments. Layers joined by `/` are a glaze stack, bottom first (`"pigment":
"P1/P4", "coats": "1/2"`: two coats of P4 over one of dry P1), each layer's
coats as above. A patch without `pigment` is of the card's pigment (the layout's
`name`). Layouts that together name more than one pigment, or hold a mixture,
are fitted jointly into a library (`diffwash.fit.fit_swatch_mixtures`).

Calibration. The photo is linearised (the sRGB transfer function, or a typical
camera's tone curve when the file names a camera: `diffwash.fit.photos._camera.
default_curve`), then the camera is taken to have recorded
`gain_c * light(x, y) * reflectance`: `light` (vignetting, uneven lighting) is
a smooth surface fitted to the bare paper visible around the boxes (or, where
none shows, to the bare board around them: the black box's surface; a
low-order polynomial in x and y of log brightness, fitted robustly),
normalised to 1 over the paper box;
`gain_c` (exposure and white balance) makes the paper box read its
`reflectance`.

Patch statistics are trimmed means (the middle 60% of each channel's values)
over the box shrunk away from its edges (watercolour darkens at its edges, and
blur and JPEG smear across them); a channel clipped by the camera in most of a
patch is a bound, not a value, and partly clipped patches weigh less.

**References:**

- S. F. Ray, "Applied Photographic Optics", Focal Press 2002 (illumination
  falloff).
- J. W. Tukey, trimmed means; P. J. Huber, "Robust Statistics", Wiley 1981.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from scipy.ndimage import binary_erosion

from ... import colorimetry
from ..._errors import DiffwashError
from ..._io import check_float32, read_json
from ..._schema import LayoutFile, name_key, validate
from ...shading import DEFAULT_PAPER
from ._camera import CAMERA_CURVE_ACCURACY, CameraModel, ToneCurve, fit_camera, lab_to_linear, needed_references
from ._camera import spectrum_lab
from ._noise import JpegSteps, _srgb_slope, pixel_noise, trimmed_mean

__all__ = ["Box", "Patch", "Layout", "parse_layout", "read_layout", "patch_paints", "swatch_pigments", "Calibration",
           "calibrate", "PatchStats", "patch_stats", "inner_box", "linearise", "Reference", "calibrate_references",
           "reference_readings", "camera_floor", "check_readings"]  # fmt: skip

GROUNDS = ("paper", "black")


@dataclass(frozen=True)
class Box:
    """A pixel box `[x0, y0, x1, y1)` of the displayed photo."""

    x0: int
    y0: int
    x1: int
    y1: int

    @property
    def width(self) -> int:
        return self.x1 - self.x0

    @property
    def height(self) -> int:
        return self.y1 - self.y0

    def tolist(self) -> list[int]:
        return [self.x0, self.y0, self.x1, self.y1]

    def grow(self, d: int) -> "Box":
        return Box(self.x0 - d, self.y0 - d, self.x1 + d, self.y1 + d)


@dataclass(frozen=True)
class Patch:
    """A patch: its box, thickness in coats, the ground under it and, if the layout names it, its paint.

    `pigments` are the names the layout gives (empty: the card's pigment) and `amounts` the coats of each
    (parallel to `pigments`); `coats` is the paint's thickness in coats in all (their sum). `layers`: for a
    glaze stack (`"pigment": "A/B"`), the number of pigments in each layer, bottom first; empty for one layer.
    """

    box: Box
    coats: float
    ground: str
    pigments: tuple[str, ...] = ()
    amounts: tuple[float, ...] = ()
    layers: tuple[int, ...] = ()

    def to_dict(self) -> dict[str, Any]:
        """The patch as layout-file JSON."""
        if not self.pigments:
            return {"box": self.box.tolist(), "coats": self.coats, "ground": self.ground}
        if len(self.amounts) == 1:
            pigment, coats = self.pigments[0], self.amounts[0]
        else:
            ends = np.cumsum((0, *(self.layers or (len(self.pigments),)))).tolist()
            cut = list(zip(ends[:-1], ends[1:]))
            pigment = "/".join("+".join(self.pigments[a:b]) for a, b in cut)
            coats = "/".join("+".join(f"{x:g}" for x in self.amounts[a:b]) for a, b in cut)
        return {"box": self.box.tolist(), "pigment": pigment, "coats": coats, "ground": self.ground}


@dataclass(frozen=True)
class Reference:
    """A patch of known colour: its box and its CIELAB (D65, CIE 1931 2-degree), (3,)."""

    box: Box
    lab: np.ndarray

    def to_dict(self) -> dict[str, Any]:
        return {"box": self.box.tolist(), "lab": [float(v) for v in self.lab]}


@dataclass(frozen=True)
class Layout:
    """Where the paper, the black band, the patches and the references of known colour are in the photo.

    `paper_default`: the layout gave no paper reflectance (`DEFAULT_PAPER` is assumed; a photo calibrated from
    references measures it instead).
    """

    paper: Box
    paper_reflectance: np.ndarray
    black: Box | None
    patches: tuple[Patch, ...]
    name: str | None = None
    path: str | None = None
    references: tuple[Reference, ...] = ()
    paper_default: bool = False

    def to_dict(self) -> dict[str, Any]:
        """The layout as layout-file JSON."""
        paper: dict[str, Any] = {"box": self.paper.tolist()}
        if not self.paper_default:
            paper["reflectance"] = self.paper_reflectance.tolist()
        out: dict[str, Any] = {"paper": paper}
        if self.black is not None:
            out["black"] = {"box": self.black.tolist()}
        out["patches"] = [p.to_dict() for p in self.patches]
        if self.references:
            out["references"] = [r.to_dict() for r in self.references]
        if self.name:
            out["name"] = self.name
        return out


def _fail(msg: str, file: Any, fld: str | None) -> DiffwashError:
    return DiffwashError(msg, file=file, field=fld)


def _box(value: list, file: Any, fld: str, size: tuple[int, int] | None) -> Box:
    """A box (whole, non-empty: `LayoutFile`) inside the photo of `size`."""
    x0, y0, x1, y1 = (int(v) for v in value)
    if size is not None:
        w, h = size
        if x0 < 0 or y0 < 0 or x1 > w or y1 > h:
            raise _fail(f"{[x0, y0, x1, y1]!r} lies outside the {w}x{h} photo (as displayed, after EXIF orientation)",
                        file, fld)  # fmt: skip
    return Box(x0, y0, x1, y1)


def parse_layout(data: Any, *, file: str | os.PathLike | None = None, size: tuple[int, int] | None = None) -> Layout:
    """Validate a layout (parsed JSON) against a photo of `size = (width, height)`.

    Keys, types and ranges are `diffwash._schema.LayoutFile`'s, checked first; here what needs the photo's size
    or more than one key. Errors name the file and the field, e.g. `card.json: patches[2].box: ... lies outside`.
    """
    model = validate(LayoutFile, data, file, what="layout")
    paper_box = _box(model.paper.box, file, "paper.box", size)
    refl = model.paper.reflectance if model.paper.reflectance is not None else list(DEFAULT_PAPER)
    if model.paper.lab is not None:
        rgb = lab_to_linear(np.asarray(model.paper.lab, np.float64))
        if np.any(rgb <= 0) or np.any(rgb > 1):
            raise _fail(f"is outside the sRGB gamut (linear {np.round(rgb, 3).tolist()}): give the paper's "
                        f"reflectance instead", file, "paper.lab")  # fmt: skip
        refl = rgb.tolist()
    black = None if model.black is None else _box(model.black.box, file, "black.box", size)
    patches = []
    for i, p in enumerate(model.patches):
        where = f"patches[{i}]"
        box = _box(p.box, file, f"{where}.box", size)
        names, layers = _pigment_layers(p.pigment, file, f"{where}.pigment") if p.pigment is not None else ((), ())
        amounts = _stack_coats(p.coats, layers or (1,), file, f"{where}.coats", p.pigment)
        if p.ground == "black" and black is None:
            raise _fail("lies on black, but the layout has no 'black' box of bare black to measure it", file,
                        f"{where}.ground")  # fmt: skip
        patches.append(Patch(box=box, coats=float(sum(amounts)), ground=p.ground, pigments=names,
                             amounts=amounts if names else (), layers=layers if len(layers) > 1 else ()))  # fmt: skip
    refs = tuple(Reference(box=_box(r.box, file, f"references[{i}].box", size), lab=_reference_lab(r))
                 for i, r in enumerate(model.references))  # fmt: skip
    return Layout(paper=paper_box, paper_reflectance=np.asarray(refl, np.float64), black=black,
                  patches=tuple(patches), name=model.name.strip() if model.name else None,
                  path=None if file is None else os.fspath(file), references=refs,
                  paper_default=model.paper.reflectance is None and model.paper.lab is None)  # fmt: skip


def _reference_lab(r: Any) -> np.ndarray:
    """A reference's CIELAB (D65) from its `lab`, linear-sRGB `reflectance` or `spectrum` (checked: `LayoutFile`)."""
    if r.lab is not None:
        return np.asarray(r.lab, np.float64)
    if r.reflectance is not None:
        return np.asarray(colorimetry.linear_srgb_to_lab(np.asarray(r.reflectance, np.float64)), np.float64)
    return spectrum_lab(np.asarray(r.wavelengths, np.float64), np.asarray(r.spectrum, np.float64))


#: Pigment names match ignoring case and runs of spaces, as the libraries look them up.
_name_key = name_key


def _pigment_names(value: Any, file: Any, fld: str) -> tuple[str, ...]:
    """A patch's `pigment`: a name, or names joined by `+`; none empty, none a ground's name."""
    if not isinstance(value, str) or not value.strip():
        raise _fail(f"must be a pigment's name, or names joined by '+' for a mixture, got {value!r}", file, fld)
    names = tuple(" ".join(n.split()) for n in value.split("+"))
    if any(not n for n in names):
        raise _fail(f"empty pigment name in {value.strip()!r}", file, fld)
    grounds = [n for n in names if _name_key(n) in GROUNDS]
    if grounds:
        raise _fail(f"{grounds[0]!r} names a ground, not a pigment", file, fld)
    return names


def _pigment_layers(value: Any, file: Any, fld: str) -> tuple[tuple[str, ...], tuple[int, ...]]:
    """A patch's `pigment` as a glaze stack: layers joined by `/` (bottom first), each `_pigment_names`.

    **Returns:** every layer's names in order, and the number in each layer."""
    if not isinstance(value, str) or "/" not in value:
        names = _pigment_names(value, file, fld)
        return names, (len(names),)
    parts = value.split("/")
    if any(not t.strip() for t in parts):
        raise _fail(f"empty layer in {value.strip()!r} (layers are joined by '/', bottom first)", file, fld)
    layers = [_pigment_names(t, file, fld) for t in parts]
    return tuple(n for layer in layers for n in layer), tuple(len(layer) for layer in layers)


def _stack_coats(value: Any, layers: tuple[int, ...], file: Any, fld: str, pigment: Any) -> tuple[float, ...]:
    """A patch's `coats` for layers of `layers` pigments: `/`-joined per layer, each as `_coats` (each layer
    needs paint, `> 0` in all)."""
    if len(layers) == 1 and not (isinstance(value, str) and "/" in value):
        return _coats(value, layers[0], file, fld, pigment)
    parts = value.split("/") if isinstance(value, str) else [value]
    if any(isinstance(t, str) and not t.strip() for t in parts):
        raise _fail(f"empty layer in {str(value).strip()!r} (coats are '/'-joined per layer, bottom first)", file,
                    fld)  # fmt: skip
    if len(parts) != len(layers):
        what = f"{len(layers)} layer{'s' if len(layers) != 1 else ''} of pigments ({pigment.strip()})" if pigment \
            else "the card's one pigment"  # fmt: skip
        raise _fail(f"{len(parts)} layer{'s' if len(parts) != 1 else ''} of coats for {what}: give one "
                    "'/'-separated group of coats per layer", file, fld)  # fmt: skip
    starts = np.cumsum((0, *layers)).tolist()
    names = str(pigment).replace("/", "+").split("+")
    return tuple(c for t, k, a in zip(parts, layers, starts)
                 for c in _coats(t, k, file, fld, "+".join(names[a : a + k])))  # fmt: skip


def _coats(value: Any, n: int, file: Any, fld: str, pigment: Any) -> tuple[float, ...]:
    """A patch's `coats`: a number (one pigment) or `n` numbers joined by `+` (>= 0 each, > 0 in all)."""
    if isinstance(value, str):
        texts = [t.strip() for t in value.split("+")]
        amounts = []
        for t in texts:
            try:
                v = float(t)
            except ValueError:
                raise _fail(f"not a number: {t!r} (coats are a number, or '+'-joined numbers for a mixture)", file,
                            fld) from None  # fmt: skip
            if not np.isfinite(v):
                raise _fail(f"must be finite numbers of coats, got {value!r}", file, fld)
            amounts.append(v)
    else:  # a finite number (`LayoutFile`)
        amounts = [float(value)]
    if len(amounts) != n:
        what = f"{n} pigments ({pigment.strip()})" if n > 1 else (f"1 pigment ({pigment.strip()})" if pigment
                                                                  else "the card's one pigment")  # fmt: skip
        k = len(amounts)
        raise _fail(f"{k} number{'s' if k != 1 else ''} of coats for {what}: give one per pigment", file, fld)
    for v in amounts:
        check_float32(v, file=file, field=fld)
    if n == 1 and amounts[0] <= 0:
        raise _fail(f"must be a number of coats > 0, got {value!r}", file, fld)
    if any(v < 0 for v in amounts):
        raise _fail(f"the coats of each pigment must be >= 0, got {value!r}", file, fld)
    if sum(amounts) <= 0:
        raise _fail(f"a patch needs paint: the coats add up to 0 ({value!r})", file, fld)
    return tuple(amounts)


def patch_paints(layouts: list[Layout], *, name: str | None = None, default: str = "pigment"
                 ) -> list[list[tuple[tuple[str, ...], tuple[float, ...]]]]:  # fmt: skip
    """Each patch's pigments and the coats of each, per layout: `[[(names, coats), ...], ...]`.

    A patch that names no pigment is of its card's pigment: `name` if given, else its layout's `name`,
    else the first layout's `name`, else `default` (as `fit_swatches` names the pigment). Names that
    match ignoring case and runs of spaces are one pigment, spelled as first met.
    """
    fallback = name or next((L.name for L in layouts if L.name), None) or default
    spelling: dict[str, str] = {}
    out = []
    for L in layouts:
        card = name or L.name or fallback
        rows = []
        for p in L.patches:
            names, amounts = (p.pigments, p.amounts) if p.pigments else ((card,), (p.coats,))
            rows.append((tuple(spelling.setdefault(_name_key(n), n) for n in names), amounts))
        out.append(rows)
    return out


def swatch_pigments(layout: Any, *, name: str | None = None, default: str = "pigment") -> list[str]:
    """The distinct pigments that swatch-card layouts hold, in the order first met (`patch_paints`).

    **Arguments:** `layout`, a `Layout`, a layout file's path, its parsed JSON, or a list of them; `name` and
    `default`, the pigment of patches that name none (as `fit_swatches`'s `name`, and its fallback).

    **Returns:** the names. More than one means the cards are fitted jointly into a library
    (`fit_swatch_mixtures`); one, a single pigment (`fit_swatches`).
    """
    items = layout if isinstance(layout, (list, tuple)) else [layout]
    layouts = [L if isinstance(L, Layout) else read_layout(L) if isinstance(L, (str, os.PathLike)) else parse_layout(L)
               for L in items]  # fmt: skip
    return list(dict.fromkeys(n for rows in patch_paints(layouts, name=name, default=default)
                              for names, _ in rows for n in names))  # fmt: skip


def read_layout(path: str | os.PathLike, size: tuple[int, int] | None = None) -> Layout:
    """Read and validate a layout file (format: module docstring)."""
    return parse_layout(read_json(path), file=path, size=size)


def inner_box(box: Box, fraction: float = 0.15, least: int = 2) -> Box:
    """The box shrunk on each side by `fraction` of its size (at least `least` pixels, never empty)."""
    dx = min(max(int(round(fraction * box.width)), least), (box.width - 1) // 2)
    dy = min(max(int(round(fraction * box.height)), least), (box.height - 1) // 2)
    return Box(box.x0 + dx, box.y0 + dy, box.x1 - dx, box.y1 - dy)


@dataclass(frozen=True)
class Calibration:
    """The camera's response as calibrated from the paper.

    **Fields:**

    - `gain`: per-channel gain (exposure times white balance), shape (3,).
    - `coefficients`: the light-falloff polynomial's coefficients (log brightness).
    - `degree`: its degree (0: no falloff correction).
    - `pixels`: bare-paper pixels it was fitted to.
    - `light_range`: the smallest and largest relative light over the photo.
    - `size`: the photo's (width, height).
    - `curve`: the tone curve the photo was read through without references (None: the sRGB curve, or a raw
      photo's identity); its typical error is `curve_accuracy`.
    """

    gain: np.ndarray
    coefficients: np.ndarray
    degree: int
    pixels: int
    light_range: tuple[float, float]
    size: tuple[int, int]
    norm: float = 1.0
    notes: list[str] = field(default_factory=list)
    lack_of_fit: float = 0.0
    camera: CameraModel | None = None
    raw: bool = False
    curve: ToneCurve | None = None

    @property
    def curve_accuracy(self) -> float:
        """The assumed tone curve's typical error (mean CIEDE2000): `CAMERA_CURVE_ACCURACY` for the camera
        curve, 0 for the sRGB curve."""
        return CAMERA_CURVE_ACCURACY if self.curve is not None and self.curve.kind == "camera" else 0.0

    @property
    def accuracy(self) -> float:
        """The calibration's own error (mean CIEDE2000), which every patch shares: the camera model's
        leave-one-out error, or the assumed tone curve's."""
        return self.camera.accuracy if self.camera is not None else self.curve_accuracy

    def light(self, ys: np.ndarray, xs: np.ndarray) -> np.ndarray:
        """Relative light at pixel centres (ys, xs) (1 on average over the paper box)."""
        w, h = self.size
        return np.exp(_poly(xs, ys, w, h, self.degree) @ self.coefficients) / self.norm

    def uncertainty_at(self, box: Box) -> float:
        """The light model's own relative uncertainty over `box` (its lack of fit to the bare paper)."""
        return float(self.lack_of_fit)

    def to_dict(self) -> dict[str, Any]:
        out = {"gain": self.gain.tolist(), "falloff_degree": self.degree, "falloff_pixels": self.pixels,
               "light_range": list(self.light_range), "notes": list(self.notes)}  # fmt: skip
        if self.camera is not None:
            out["camera"] = self.camera.to_dict()
        return out


def _poly(xs: np.ndarray, ys: np.ndarray, w: int, h: int, degree: int) -> np.ndarray:
    """Monomials x^i y^j (i + j <= degree) in coordinates scaled to [-1, 1]."""
    u = (2 * (np.asarray(xs, np.float64) + 0.5) / w - 1)[..., None]
    v = (2 * (np.asarray(ys, np.float64) + 0.5) / h - 1)[..., None]
    cols = [u**i * v**j for i in range(degree + 1) for j in range(degree + 1 - i)]
    return np.concatenate(cols, axis=-1)


def _clip_levels(bits: int) -> tuple[float, float]:
    top = (1 << bits) - 1
    return 0.5 / top, 1 - 0.5 / top


def calibrate(linear: np.ndarray, display: np.ndarray, bits: int, layout: Layout, *, file: Any = None,
              degree: int = 2) -> Calibration:  # fmt: skip
    """Calibrate exposure, white balance and light falloff from the bare paper.

    **Arguments:**

    - `linear`: the photo linearised, (H, W, 3).
    - `display`: the photo as read (display-encoded), to find clipped pixels.
    - `bits`: the file's bits per channel.
    - `layout`: the validated `Layout`.
    - `degree`: the falloff polynomial's degree (lowered when too little paper
      is visible).

    **Returns:**

    The `Calibration`. A paper box that is over- or under-exposed raises a
    `DiffwashError` (the exposure cannot be known from clipped values).
    """
    H, W, _ = linear.shape
    lo_level, hi_level = _clip_levels(bits)
    pb = inner_box(layout.paper, 0.05, 1)
    raw = display[pb.y0 : pb.y1, pb.x0 : pb.x1].reshape(-1, 3)
    clipped = np.mean((raw >= hi_level) | (raw <= lo_level), axis=0)
    if np.any(clipped > 0.01):
        c = int(np.argmax(clipped))
        bright = np.mean(raw[:, c] >= hi_level) >= np.mean(raw[:, c] <= lo_level)
        kind = "over-exposed (saturated)" if bright else "black"
        raise _fail(f"the paper box is {kind}: {100 * clipped[c]:.0f}% of its pixels are clipped in "
                    f"{'red green blue'.split()[c]}, so exposure and white balance cannot be calibrated from it",
                    file, "paper.box")  # fmt: skip
    paper_lin = linear[pb.y0 : pb.y1, pb.x0 : pb.x1].reshape(-1, 3)
    ref = np.median(paper_lin, axis=0)
    if np.any(ref <= 0):
        raise _fail("the paper box is black in the photo: nothing to calibrate from", file, "paper.box")

    notes = []
    step = max(1, int(np.sqrt(H * W / 40000)))  # at most ~40k samples of the light surface
    ys, xs, y = _paper_samples(linear, display, layout, pb, ref, lo_level, hi_level)
    degree, coef, use, lack, low, high = _surface(ys, xs, y, W, H, degree, pb, step)
    if degree < 2:
        notes.append(f"little bare paper visible around the boxes: light falloff modelled to degree {degree}")
    if degree > 0 and not _plausible(lack, low, high):
        # What looked like bare paper does not follow a plausible smooth light: it is not all paper (a board, a
        # mount, a table around the card). Scaling to the paper box alone is the safer reading.
        notes.append(f"the bare paper around the boxes does not follow a smooth light falloff (it misses by "
                     f"{100 * lack:.0f}%, light {low:.2f}-{high:.2f} of the paper box's; is it all paper?): light "
                     f"falloff not corrected")  # fmt: skip
        degree, coef, use, lack, low, high = _surface(ys, xs, y, W, H, 0, pb, step)
    if degree == 0 and layout.black is not None:
        # Cards painted on a board: the bare board around the boxes (the black box's surface) shows the light.
        bb = inner_box(layout.black, 0.05, 1)
        bref = np.median(linear[bb.y0 : bb.y1, bb.x0 : bb.x1].reshape(-1, 3), axis=0)
        if np.all(bref > 0):
            bys, bxs, by = _paper_samples(linear, display, layout, bb, bref, lo_level, hi_level, own=layout.black)
            board = _surface(bys, bxs, by, W, H, 2, pb, step)
            if board[0] > 0 and _plausible(*board[3:]):
                degree, coef, use, lack, low, high = board
                notes = [f"light falloff read from the bare board around the boxes (the black box's surface), "
                         f"degree {degree}"]  # fmt: skip
    cal = Calibration(gain=np.ones(3), coefficients=coef, degree=degree, pixels=int(use.sum()), light_range=(1.0, 1.0),
                      size=(W, H), norm=1.0, notes=notes)  # fmt: skip
    pys, pxs = np.mgrid[pb.y0 : pb.y1, pb.x0 : pb.x1]
    norm = float(np.mean(cal.light(pys.ravel(), pxs.ravel())))
    gys, gxs = np.mgrid[0:H:step, 0:W:step]
    light = np.exp(_poly(gxs.ravel(), gys.ravel(), W, H, degree) @ coef) / norm
    flat = paper_lin / np.exp(_poly(pxs.ravel(), pys.ravel(), W, H, degree) @ coef)[:, None] * norm
    gain = trimmed_mean(flat) / layout.paper_reflectance
    return Calibration(gain=gain, coefficients=coef, degree=degree, pixels=int(use.sum()),
                       light_range=(float(light.min()), float(light.max())), size=(W, H), norm=norm,
                       notes=notes, lack_of_fit=lack)  # fmt: skip


#: The light falloff's plausible range over the photo, relative to the paper box (outside it, what was taken for
#: bare paper is something else).
LIGHT_RANGE = (0.5, 1.6)


def _plausible(lack: float, low: float, high: float) -> bool:
    """A light surface that follows its samples (`MAX_LACK_OF_FIT`) and stays in a plausible range (`LIGHT_RANGE`)."""
    return lack <= MAX_LACK_OF_FIT and LIGHT_RANGE[0] <= low and high <= LIGHT_RANGE[1]


def _surface(ys: np.ndarray, xs: np.ndarray, y: np.ndarray, W: int, H: int, degree: int, pb: Box, step: int
             ) -> tuple[int, np.ndarray, np.ndarray, float, float, float]:  # fmt: skip
    """The light surface through samples (ys, xs) of log brightness `y`, of `degree` at most (lowered until the
    samples span enough of the photo to support it): its degree, coefficients, the samples kept, its lack of
    fit and the smallest and largest light over the photo relative to the paper box."""
    span = (np.ptp(xs) / W if len(xs) else 0.0, np.ptp(ys) / H if len(ys) else 0.0)
    while degree > 0:
        n_terms = (degree + 1) * (degree + 2) // 2
        if len(xs) >= 20 * n_terms and min(span) > 0.5:
            break
        degree -= 1
    size = _cell_size(H, W)
    cell = (ys // size) * (W // size + 1) + xs // size  # the samples in patch-sized cells
    A = _poly(xs, ys, W, H, degree)
    coef, use = _trimmed_lstsq(A, y)
    lack = _lack_of_fit(y - A @ coef, use, cell)
    low, high = _light_span(A, coef, W, H, degree, pb, step)
    return degree, coef, use, lack, low, high


def _light_span(A: np.ndarray, coef: np.ndarray, W: int, H: int, degree: int, pb: Box, step: int
                ) -> tuple[float, float]:  # fmt: skip
    """The smallest and largest light over the photo relative to the paper box's mean."""
    pys, pxs = np.mgrid[pb.y0 : pb.y1, pb.x0 : pb.x1]
    norm = float(np.mean(np.exp(_poly(pxs.ravel(), pys.ravel(), W, H, degree) @ coef)))
    gys, gxs = np.mgrid[0:H:step, 0:W:step]
    light = np.exp(_poly(gxs.ravel(), gys.ravel(), W, H, degree) @ coef) / norm
    return float(light.min()), float(light.max())


#: The most the light-falloff surface may miss the bare paper by, at the scale of a patch (relative), before the
#: surface is dropped for plain scaling to the paper box: on generated cards it misses by under 1%; a dark,
#: textured board taken for paper by 10% (benchmarks/bench_photo.py).
MAX_LACK_OF_FIT = 0.04


def _paper_samples(linear: np.ndarray, display: np.ndarray, layout: Layout, pb: Box, ref: np.ndarray, lo_level: float,
                   hi_level: float, own: Box | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:  # fmt: skip
    """Bare paper visible anywhere, as block medians: block centres (ys, xs) and log brightness relative to `ref`.

    Blocks outside every box (grown by a margin) or inside the paper box, unclipped, coloured like the paper box
    and within a factor 0.4-1.6 of its brightness. Medians over blocks of a few pixels, not single pixels: the
    bright tail of a darker textured surface (a board around the card) would pass as paper pixel by pixel.
    `own`: the bare board's samples instead, around the black box `own` (`pb` its inner box, `ref` its colour).
    """
    H, W, _ = linear.shape
    mask = np.ones((H, W), bool)
    boxes = [p.box for p in layout.patches] + ([layout.black] if layout.black is not None and own is None else [])
    boxes += [r.box for r in layout.references] + ([layout.paper] if own is not None else [])
    for b in boxes:
        g = b.grow(max(3, int(0.15 * min(b.width, b.height))))
        mask[max(g.y0, 0) : max(g.y1, 0), max(g.x0, 0) : max(g.x1, 0)] = False
    mask[pb.y0 : pb.y1, pb.x0 : pb.x1] = True
    bs = max(4, int(np.sqrt(H * W / 40000)))  # at most ~40k blocks
    hb, wb = H // bs, W // bs
    blocks = lambda a: a[: hb * bs, : wb * bs].reshape(hb, bs, wb, bs, -1)  # noqa: E731
    # Medians a band of blocks at a time: np.median copies what it sorts, a whole photo at once.
    band = max(1, (1 << 18) // max(1, bs * bs * wb))
    med = np.concatenate([np.median(blocks(linear)[i : i + band], axis=(1, 3)).reshape(-1, 3)
                          for i in range(0, hb, band)] or [np.empty((0, 3))]).reshape(-1, 3)  # fmt: skip
    d = blocks(display)
    unclipped = ((d.max(axis=(1, 3)) < hi_level) & (d.min(axis=(1, 3)) > lo_level)).all(axis=-1).ravel()
    inside = blocks(mask[..., None]).all(axis=(1, 3, 4)).ravel()
    ys, xs = np.divmod(np.arange(hb * wb), wb)
    ys, xs = ys * bs + bs // 2, xs * bs + bs // 2
    ratio = med / ref
    ok = (inside & unclipped & np.all((ratio > 0.4) & (ratio < 1.6), axis=1)
          & (ratio.max(axis=1) / np.maximum(ratio.min(axis=1), 1e-6) < 1.2))  # fmt: skip
    # Paper is a surface: keep blocks whose neighbours pass too (isolated blocks are the tail of something else).
    ok = binary_erosion(ok.reshape(hb, wb), np.ones((3, 3), bool), border_value=1).ravel()
    return ys[ok], xs[ok], np.log(np.mean(ratio[ok], axis=1))


def _cell_size(H: int, W: int) -> int:
    """Side of the cells the light model's lack of fit is measured in (about a patch)."""
    return max(16, min(H, W) // 8)


def _trimmed_lstsq(A: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Least squares that drops outliers (stains, shadows, stray marks): the coefficients and the samples kept."""
    use = np.ones(len(y), bool)
    coef = np.zeros(A.shape[1])
    for _ in range(4):
        if use.sum() < A.shape[1]:
            break
        Au = A[use]  # normal equations: a handful of columns, well conditioned on [-1, 1] coordinates
        coef = np.linalg.solve(Au.T @ Au + 1e-12 * np.eye(A.shape[1]), Au.T @ y[use])
        r = y - A @ coef
        mad = 1.4826 * np.median(np.abs(r[use] - np.median(r[use]))) + 1e-6
        use = np.abs(r) < 3 * mad
    return coef, use


def _cell_means(r: np.ndarray, cell: np.ndarray, least: int = 10) -> tuple[np.ndarray, np.ndarray]:
    """Mean residual and its noise variance per cell with at least `least` samples."""
    _, inverse, counts = np.unique(cell, return_inverse=True, return_counts=True)
    sums = np.bincount(inverse, r)
    sq = np.bincount(inverse, r * r)
    ok = counts >= least
    mean = sums[ok] / counts[ok]
    var = np.maximum(sq[ok] / counts[ok] - mean**2, 0) / counts[ok]
    return mean, var


def _lack_of_fit(r: np.ndarray, use: np.ndarray, cell: np.ndarray) -> float:
    """The light model's error at the scale of a patch: the spread of its cell-mean residuals beyond their noise."""
    mean, var = _cell_means(r[use], cell[use])
    if len(mean) < 3:
        return 0.0
    return float(np.sqrt(max(np.mean(mean**2) - np.mean(var), 0.0)))


@dataclass(frozen=True)
class PatchStats:
    """Robust statistics of one box of the calibrated photo.

    **Fields:** `rgb` (the mean linear reflectance, (3,): a trimmed mean, or
    near the noise floor the middle of `interval`), `cov` (its covariance,
    (3, 3): pixel noise, code-value quantisation, the noise floor; see
    `diffwash.fit.photos._noise`), `spread` (robust standard deviation of the pixels,
    (3,)), `clipped_lo`, `clipped_hi` (fraction of the pixels clipped at the
    bottom / top, per channel), `pixels` (pixels used), `pixels_per_sample`
    (integrated autocorrelation, (3,)), `interval` ((2, 3): the range the mean
    lies in by the noise-floor analysis), `floor` ((3,): the channel is at the
    camera's noise floor).
    """

    rgb: np.ndarray
    spread: np.ndarray
    clipped_lo: np.ndarray
    clipped_hi: np.ndarray
    pixels: int
    cov: np.ndarray | None = None
    pixels_per_sample: np.ndarray | None = None
    interval: np.ndarray | None = None
    floor: np.ndarray | None = None

    @property
    def se(self) -> np.ndarray:
        """Standard error of `rgb`, per channel."""
        return np.sqrt(np.diag(self.cov)) if self.cov is not None else np.full(3, np.nan)


def patch_stats(linear: np.ndarray, display: np.ndarray, bits: int, cal: Calibration, box: Box,
                jpeg: JpegSteps | None = None, reference: bool = False,
                floor_noise: float | None = None) -> PatchStats:  # fmt: skip
    """Statistics of the calibrated reflectance inside `box`, away from its edges, with the noise of their mean.

    `jpeg`: the file's quantisation steps (`diffwash.fit.photos._noise.jpeg_steps`), if it is a JPEG;
    `reference`: the box is a reference every patch depends on; `floor_noise`: the camera's noise
    at black (`diffwash.fit.photos._noise.camera_noise_floor`), if known (see `diffwash.fit.photos._noise.pixel_noise`).
    """
    ib = inner_box(box)
    ys, xs = np.mgrid[ib.y0 : ib.y1, ib.x0 : ib.x1]
    light = cal.light(ys.ravel(), xs.ravel()).reshape(ys.shape)
    raw = display[ib.y0 : ib.y1, ib.x0 : ib.x1]
    d_mean = raw.reshape(-1, 3).mean(axis=0)
    if cal.camera is not None:  # the camera model fitted to references: tone curve, light, colour correction
        values = cal.camera.correct(cal.camera.signal(raw) / light[..., None])
        scale = cal.camera.gain() / float(np.mean(light)) * cal.camera.curve.slope(d_mean) / _srgb_slope(d_mean)
    else:
        values = linear[ib.y0 : ib.y1, ib.x0 : ib.x1] / light[..., None] / cal.gain
        slope = cal.curve.slope(d_mean) / _srgb_slope(d_mean) if cal.curve is not None else 1.0
        scale = slope / (float(np.mean(light)) * cal.gain) / (_srgb_slope(d_mean) if cal.raw else 1.0)
    lo_level, hi_level = _clip_levels(bits)
    clipped_lo = np.mean(raw <= lo_level, axis=(0, 1))
    clipped_hi = np.mean(raw >= hi_level, axis=(0, 1))
    noise = pixel_noise(values, raw, scale, bits, clipped_lo, clipped_hi, jpeg, reference, floor_noise)
    cov = noise.cov
    if cal.accuracy > 0:  # the camera model's leave-one-out error, or the assumed tone curve's, as a colour floor
        cov = cov + np.diag(np.square(camera_floor(noise.value, cal.accuracy)))
    return PatchStats(rgb=noise.value, spread=noise.spread, clipped_lo=clipped_lo, clipped_hi=clipped_hi,
                      pixels=int(ys.size), cov=cov, pixels_per_sample=noise.pixels_per_sample,
                      interval=noise.interval, floor=noise.floor)  # fmt: skip


def camera_floor(rgb: np.ndarray, accuracy: float) -> np.ndarray:
    r"""The standard deviation per channel (linear) of a colour error of `accuracy` CIEDE2000 units.

    Near a lightness $L^*$ one unit of $L^*$ is a relative change of about $3 / (L^* + 16)$ in each linear
    channel ($L^* = 116 Y^{1/3} - 16$).
    """
    rgb = np.maximum(np.asarray(rgb, np.float64), 1e-4)
    L = float(colorimetry.linear_srgb_to_lab(np.clip(rgb, 0, 1))[0])
    return 3 * accuracy / (L + 16) * rgb


def linearise(display: np.ndarray, curve: ToneCurve | None = None) -> np.ndarray:
    """Display sRGB in [0, 1] to linear (the IEC 61966-2-1 transfer function, or `curve`), in numpy.

    A photo is decoded in blocks of rows: the transfer function works through several float64 temporaries of
    its input's size, which for a photo of hundreds of patches (tens of millions of values) was a gigabyte."""
    display = np.asarray(display, np.float64)
    decode = colorimetry.from_display if curve is None else curve
    if display.ndim < 2:
        return decode(display)
    out = np.empty(display.shape, np.float64)
    step = max(1, (1 << 18) // max(1, int(np.prod(display.shape[1:]))))
    for y in range(0, display.shape[0], step):
        out[y : y + step] = decode(display[y : y + step])
    return out


def reference_readings(display: np.ndarray, cal: Calibration, boxes: list[Box]) -> tuple[np.ndarray, np.ndarray]:
    """Each box's trimmed-mean encoded value (n, 3) and the mean relative light over it (n,)."""
    enc, light = [], []
    for box in boxes:
        ib = inner_box(box)
        enc.append(trimmed_mean(display[ib.y0 : ib.y1, ib.x0 : ib.x1].reshape(-1, 3)))
        ys, xs = np.mgrid[ib.y0 : ib.y1, ib.x0 : ib.x1]
        light.append(float(np.mean(cal.light(ys.ravel(), xs.ravel()))))
    return np.asarray(enc, np.float64).reshape(-1, 3), np.asarray(light, np.float64)


def calibrate_references(display: np.ndarray, bits: int, layout: Layout, cal: Calibration, *, raw: bool = False,
                         file: Any = None, extra: tuple | None = None) -> Calibration:  # fmt: skip
    """The calibration with a camera model fitted to the layout's references (and `extra` ones).

    `cal` is the paper's calibration (its light falloff); `extra` is `(encoded (m, 3), centres (m, 2) as
    (x, y) pixels, lab (m, 3))` of references found in the photo (a ColorChecker). The curve and the light
    are fitted twice: the light falloff again from the paper read through the first model's curve.
    Fewer references than `needed_references()`, references that determine no camera model
    (`diffwash.fit.photos._camera.fit_camera`), and a model that reads the layout's boxes as no paper could be
    (`check_readings`) raise a `DiffwashError` naming `references`.
    """
    n = len(layout.references) + (0 if extra is None else len(extra[0]))
    need = needed_references()
    if n < need:
        raise _fail(f"{n} reference{'s' if n != 1 else ''} of known colour, but the camera model needs at least "
                    f"{need} (a 3x3 colour matrix scored by leave-one-out)", file, "references")  # fmt: skip
    model = None
    for k in range(2):
        enc, light = reference_readings(display, cal, [r.box for r in layout.references])
        lab = np.array([r.lab for r in layout.references]).reshape(-1, 3)
        if extra is not None:
            e2, centres, lab2 = extra
            l2 = cal.light(np.asarray(centres)[:, 1], np.asarray(centres)[:, 0])
            enc, light, lab = np.concatenate([enc, e2]), np.concatenate([light, l2]), np.concatenate([lab, lab2])
        model = fit_camera(enc, light, lab, raw=raw, file=file)
        check_readings(model, display, cal, layout, file)
        if k == 0:  # the light falloff again, from the paper read through the fitted curve
            base = calibrate(model.signal(display), display, bits, layout, file=file, degree=cal.degree)
            cal = replace(base, notes=cal.notes)
    assert model is not None
    return replace(cal, camera=model, raw=raw, gain=1 / model.gain())


#: The least reflectance a camera model may read the paper box as, in every channel (white or cream paper reads
#: 0.6-0.95; a model that reads it darker than this is wrong, not the paper).
LEAST_PAPER = 0.05
#: The lowest luminance a camera model may read any box as (linear; a dark patch or the black band reads about 0.01,
#: less its noise): below it the model reads negative light.
LEAST_LUMINANCE = -0.05
_LUMINANCE = np.array([0.2126, 0.7152, 0.0722])  # linear sRGB to Y (IEC 61966-2-1)


def _shown(v: np.ndarray) -> str:
    return "(" + ", ".join(f"{x:.3g}" for x in v) + ")"


def _reading_problem(named: list[str], rgb: np.ndarray, gain: np.ndarray) -> str | None:
    """What is wrong with a camera model's readings `rgb` (n, 3) of the boxes `named` (the paper box first) and
    its `gain` near neutral, in words, or None."""
    for name, v in zip(named, rgb):
        if not np.all(np.isfinite(v)):
            return f"reads {name} as {_shown(v)}, not a number"
    if not np.all(np.isfinite(gain) & (gain > 0)):
        return f"reads more light as less (its gain per channel near neutral is {_shown(gain)})"
    if np.min(rgb[0]) < LEAST_PAPER:
        return f"reads {named[0]} as {_shown(rgb[0])} in linear sRGB, darker than any paper (below {LEAST_PAPER})"
    for name, v in zip(named, rgb):
        if float(v @ _LUMINANCE) < LEAST_LUMINANCE:
            return f"reads {name} as {_shown(v)} in linear sRGB, darker than black"
    return None


def check_readings(model: CameraModel, display: np.ndarray, cal: Calibration, layout: Layout, file: Any) -> None:
    """Refuse a camera model that reads the paper box, the black box or a patch as not a number, more light as
    less (its gain near neutral), the paper box as dark or any box as darker than black: a `DiffwashError` naming
    `references`. Such a calibration is never used."""
    named = [("the paper box", layout.paper)] + ([("the black box", layout.black)] if layout.black else [])
    named += [(f"patches[{i}]", p.box) for i, p in enumerate(layout.patches)]
    enc, light = reference_readings(display, cal, [box for _, box in named])
    rgb = model.correct(model.signal(enc) / light[:, None])
    problem = _reading_problem([name for name, _ in named], rgb, model.gain())
    if problem is not None:
        raise _fail(f"the camera model fitted to the {model.references} references {problem}: check the "
                    f"references' boxes and colours", file, "references")  # fmt: skip
