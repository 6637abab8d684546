r"""A camera model fitted to patches of known colour: a tone curve, then a colour matrix.

A phone or camera makes its picture as: sensor signal -> white balance -> a
colour matrix -> a tone curve (the same for every channel) -> encoding
(JPEG). Reading a photo back to reflectance inverts that: a monotone curve
`g` takes each channel's encoded value to a linear signal, the light falloff
(`diffwash.fit.photos._photo`) is divided out, and a colour correction `M` takes the
three signals to linear sRGB reflectance:

$$ \rho = M\big(g(e) / \ell(x, y)\big) . $$

`g` is a Bernstein polynomial of degree 5 with non-decreasing coefficients
(so monotone and smooth) and a free value at 0 (a lifted black or flare),
normalised to 1 at 1; or the sRGB curve (IEC 61966-2-1), or a typical
camera's curve (`camera_curve`), or the identity for raw photos. `M` is one of colour-science's colour-correction forms:
a 3x3 matrix (Cheung 2004, 3 terms), a matrix with an offset (4 terms),
Finlayson 2015's root-polynomial of degree 2, or a Vandermonde polynomial of
degree 2. `g` and a 3x3 `M` are fitted together by alternating least squares
(relative errors: each reference channel weighted by `1 / (value + 0.02)`),
then `g` is kept and the chosen `M` refitted. Each candidate (curve x
correction) that the references support is scored by leave-one-out over the
references (each reference predicted by the model fitted to the others,
CIEDE2000 to its known colour); the best is used, fitted to all references,
and its leave-one-out mean CIEDE2000 is the calibration's accuracy.

The references support a candidate when they determine it. A colour matrix
needs colours that span the three dimensions of colour space: the
references' known linear colours, and the photo's values of them through the
candidate's curve, must each have a condition number (each channel scaled to
unit RMS) of at most `MAX_SPAN_CONDITION`. Neutral greys alone only fix a
tone curve, and leave-one-out cannot see it (a grey predicted from the other
greys is right whatever the matrix does to a colour); nor can it see
duplicates (a reference left out is predicted by its twin). Each
leave-one-out fold must also determine the candidate's terms (a condition
number of at most `MAX_TERMS_CONDITION`), or it cannot be scored. References
that support no candidate are refused, naming `references`.

**References:**

- V. Cheung, S. Westland, D. Connah, C. Ripamonti, "A comparative study of the
  characterisation of colour cameras by means of neural networks and
  polynomial transforms", Coloration Technology 120 (2004).
- G. D. Finlayson, M. Mackiewicz, A. Hurlbert, "Color Correction Using
  Root-Polynomial Regression", IEEE TIP 24 (2015).
- colour-science, `colour.characterisation.colour_correction`.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from math import comb
from typing import Any

import colour
import numpy as np
from PIL import Image
from colour.characterisation import polynomial_expansion_Finlayson2015, polynomial_expansion_Vandermonde
from scipy.optimize import nnls

from ... import colorimetry
from ..._errors import DiffwashError

__all__ = ["CameraModel", "fit_camera", "CORRECTIONS", "needed_references", "lab_to_linear", "spectrum_lab",
           "camera_curve", "default_curve", "TONE_CURVES"]  # fmt: skip

#: Colour corrections: name -> (colour-science's expansion, fewest references for a leave-one-out score).
CORRECTIONS = ("Cheung 2004 (3 terms)", "Cheung 2004 (4 terms)", "Finlayson 2015 (root-polynomial, degree 2)",
               "Vandermonde (degree 2)")  # fmt: skip
_CURVE_NAMES = {"srgb": "sRGB curve", "camera": "typical camera curve", "linear": "linear (raw)",
                "fitted": "fitted tone curve"}  # fmt: skip
#: The typical camera curve's exponent `a` and knee `c` (`camera_curve`).
CAMERA_CURVE = (1.60, 0.167)
#: Its mean CIEDE2000 on ColorChecker patches photographed through 14 cameras' measured tone curves, each left
#: out of the fit of `CAMERA_CURVE` (the sRGB curve: 6.5); carried into each patch's noise as a colour floor.
CAMERA_CURVE_ACCURACY = 2.0
_DEGREE = 5
_SOFT = 0.02  # the floor of the relative weights (a channel's value below it weighs as at it)
#: The largest condition number of the references' linear colours (n, 3), each channel scaled to unit RMS, known and
#: as the photo shows them, for a colour matrix: a chart's or a few paints' colours give 4-15 (the ColorChecker's 24
#: patches 4.4; 4 of them, one in six, 11), greys tinted by up to 10 in a* and b* about 30, by up to 5 about 100, the
#: ColorChecker's 6 greys 700, and greys or a repeated colour alone have no third dimension at all.
MAX_SPAN_CONDITION = 50.0
#: The largest condition number of a candidate's terms (each scaled to unit RMS) in a leave-one-out fold: above it
#: the fold does not determine the candidate's matrix and its prediction of the reference left out means nothing.
MAX_TERMS_CONDITION = 1e6
#: Below this chroma (C*ab) every reference is called near-neutral when they span too few colours.
_NEUTRAL_CHROMA = 10.0


def _expand(rgb: np.ndarray, correction: str) -> np.ndarray:
    """The terms a colour correction is linear in, (n, terms)."""
    x = np.asarray(rgb, np.float64)
    if correction == CORRECTIONS[0]:
        return x
    if correction == CORRECTIONS[1]:
        return np.concatenate([x, np.ones(x.shape[:-1] + (1,))], axis=-1)
    if correction == CORRECTIONS[2]:
        return polynomial_expansion_Finlayson2015(np.maximum(x, 0), 2, True)
    return polynomial_expansion_Vandermonde(x, 2)


_TERMS = {CORRECTIONS[0]: 3, CORRECTIONS[1]: 4, CORRECTIONS[2]: 6, CORRECTIONS[3]: 10}


def _bernstein(e: np.ndarray) -> np.ndarray:
    """Bernstein basis of degree `_DEGREE` at `e` in [0, 1], (..., degree + 1)."""
    e = np.clip(np.asarray(e, np.float64), 0, 1)[..., None]
    k = np.arange(_DEGREE + 1)
    return np.array([comb(_DEGREE, int(i)) for i in k]) * e**k * (1 - e) ** (_DEGREE - k)


@dataclass(frozen=True)
class ToneCurve:
    """An encoded value's linear signal: `kind` "srgb", "linear" or "fitted" (Bernstein `coefficients`)."""

    kind: str
    coefficients: np.ndarray | None = None

    def __call__(self, e: np.ndarray) -> np.ndarray:
        if self.kind == "srgb":
            return colorimetry.from_display(np.asarray(e, np.float64))
        if self.kind == "linear":
            return np.asarray(e, np.float64)
        if self.kind == "camera":
            return camera_curve(e)
        return _bernstein(e) @ self.coefficients

    def slope(self, e: np.ndarray) -> np.ndarray:
        """d(signal)/d(encoded) at `e` (a central difference)."""
        e = np.asarray(e, np.float64)
        h = 1e-3
        return (self(np.minimum(e + h, 1)) - self(np.maximum(e - h, 0))) / (np.minimum(e + h, 1) - np.maximum(e - h, 0))


def camera_curve(e: Any) -> np.ndarray:
    r"""The linear signal of encoded values `e` through a typical camera's tone curve.

    A camera's JPEG engine brightens the mid-tones and rolls the highlights off before it encodes with the
    sRGB curve, so reading its photo through the sRGB curve alone reads mid-tones too light relative to
    white paper. The curve here undoes a Naka-Rushton tone curve $y = (1 + c)\,x^a / (x^a + c)$ of the raw
    signal $x$ (1 at the sensor's clipping) under the sRGB encoding:

    $$ x = \big(c\,y / (1 + c - y)\big)^{1/a}, \qquad y = \mathrm{sRGB}^{-1}(e), $$

    with $a = 1.60$, $c = 0.167$ (`CAMERA_CURVE`), fitted to the in-camera tone curves of 14 cameras measured
    from raw and JPEG pairs (darktable's base-curve presets for 13 makers, and the Nikon D7000 model of
    Kim et al., "A New In-Camera Imaging Model for Color Computer Vision and Its Application", IEEE TPAMI 34
    (2012)). On ColorChecker patches photographed through each of those curves, left out of the fit, scaling
    to white paper read through this curve misses by 2.0 mean CIEDE2000, and through the sRGB curve by 6.5
    (benchmarks/README.md, "bench_photo.py").
    """
    a, c = CAMERA_CURVE
    y = np.clip(colorimetry.from_display(np.asarray(e, np.float64)), 0.0, 1.0)
    return (c * y / (1.0 + c - y)) ** (1.0 / a)


def camera_named(path: Any) -> str | None:
    """The camera a photo file's EXIF names ("Make Model"), or None (no EXIF, or not a file)."""
    if not isinstance(path, (str, os.PathLike)):
        return None
    try:
        with Image.open(path) as im:
            exif = im.getexif()
    except (OSError, ValueError, SyntaxError, Image.DecompressionBombError):
        return None  # not an image PIL reads: read_image says why, with the file's name
    words = [str(exif.get(tag, "")).strip("\x00 ") for tag in (0x010F, 0x0110)]  # Make, Model
    name = " ".join(w for w in words if w)
    return name or None


#: How a photo with no references is read: "auto" (the typical camera curve when the file's EXIF names a
#: camera, else the sRGB curve), "camera" or "srgb".
TONE_CURVES = ("auto", "camera", "srgb")


def default_curve(path: Any, choice: str = "auto") -> tuple[ToneCurve, str]:
    """The tone curve a photo without references is read through, and why (a note for the user)."""
    if choice not in TONE_CURVES:
        raise DiffwashError(f"unknown tone curve {choice!r}: one of {', '.join(TONE_CURVES)}", field="--tone-curve")
    named = camera_named(path) if choice == "auto" else None
    if choice == "camera" or named:
        why = f"the file's EXIF names a camera, {named}" if named else "as asked"
        return ToneCurve("camera"), (f"read through a typical camera's tone curve ({why}); --tone-curve srgb "
                                     f"if the photo was saved as plain sRGB")  # fmt: skip
    why = "no camera named in the file" if choice == "auto" else "as asked"
    return ToneCurve("srgb"), (f"read through the sRGB curve ({why}); --tone-curve camera for a phone or camera "
                               f"photo whose metadata was removed")  # fmt: skip


def needed_references() -> int:
    """The fewest references a camera model needs: a 3x3 matrix on a fixed curve (sRGB, or linear for a raw
    photo), scored by leave-one-out."""
    return _needs("srgb", CORRECTIONS[0])


def _needs(curve: str, correction: str) -> int:
    """References a candidate needs: its terms (and the fitted curve's shape) plus two for leave-one-out."""
    return _TERMS[correction] + (3 if curve == "fitted" else 1)


def lab_to_linear(lab: Any) -> np.ndarray:
    """CIELAB (D65, CIE 1931 2-degree) to linear sRGB."""
    return np.asarray(colorimetry.xyz_to_linear_srgb(colorimetry.lab_to_xyz(np.asarray(lab, np.float64))), np.float64)


def spectrum_lab(wl: Any, sp: Any) -> np.ndarray:
    """CIELAB of a reflectance spectrum `sp` at wavelengths `wl` (nm) under D65, CIE 1931 2-degree observer."""
    shape = colour.SpectralShape(360, 830, 5)
    cmfs = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"].copy().align(shape)
    d65 = colour.SDS_ILLUMINANTS["D65"].copy().align(shape)
    refl = np.interp(np.arange(360.0, 831.0, 5.0), np.asarray(wl, np.float64), np.asarray(sp, np.float64))
    w = cmfs.values * d65.values[:, None]
    return np.asarray(colorimetry.xyz_to_lab(refl @ w / w[:, 1].sum()), np.float64)


def _lab(rgb: np.ndarray) -> np.ndarray:
    return np.asarray(colorimetry.linear_srgb_to_lab(np.asarray(rgb, np.float64)), np.float64)


def _de(pred: np.ndarray, lab: np.ndarray) -> np.ndarray:
    """CIEDE2000 between predicted linear sRGB (may lie outside the gamut) and known Lab."""
    return np.asarray(colorimetry.delta_e_2000(_lab(pred), lab), np.float64)


def _weights(target: np.ndarray) -> np.ndarray:
    return 1.0 / (np.abs(target) + _SOFT)


def _solve_matrix(F: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Per output channel, weighted least squares of `target[:, c]` on the terms `F`, (terms, 3)."""
    out = np.empty((F.shape[1], 3))
    for c in range(3):
        w = _weights(target[:, c])[:, None]
        A = F * w
        out[:, c] = np.linalg.lstsq(A.T @ A + 1e-9 * np.eye(F.shape[1]), A.T @ (target[:, c] * w[:, 0]), rcond=None)[0]
    return out


def _fit_curve(e: np.ndarray, light: np.ndarray, target: np.ndarray, iterations: int = 30
               ) -> tuple[ToneCurve, np.ndarray]:  # fmt: skip
    """A shared monotone curve and a 3x3 matrix by alternating least squares (module docstring)."""
    # Start at the sRGB curve: Bernstein coefficients that reproduce it at the nodes.
    nodes = np.linspace(0, 1, 41)
    c0 = np.linalg.lstsq(_bernstein(nodes), colorimetry.from_display(nodes), rcond=None)[0]
    curve = ToneCurve("fitted", np.maximum.accumulate(c0))
    M = _solve_matrix(curve(e) / light[:, None], target)
    # The curve in increments: c_k = c_0 + sum_{j <= k} d_j (d_j >= 0), c_0 = a - b (both >= 0).
    B = _bernstein(e.reshape(-1))  # (3n, K+1)
    cum = np.cumsum(B[:, ::-1], axis=1)[:, ::-1][:, 1:]  # sum_{k >= j} B_k, for j = 1..K
    design = np.concatenate([np.ones((B.shape[0], 1)), -np.ones((B.shape[0], 1)), cum], axis=1)
    for _ in range(iterations):
        try:
            Minv = np.linalg.inv(M)
        except np.linalg.LinAlgError:
            break
        want = (target @ Minv) * light[:, None]  # what the curve should give per channel
        w = _weights(want.reshape(-1))
        try:
            x, _ = nnls(design * w[:, None], want.reshape(-1) * w, maxiter=50 * design.shape[1])
        except RuntimeError:  # no solution within the iterations (degenerate references): keep the last curve
            break
        coef = x[0] - x[1] + np.concatenate([[0.0], np.cumsum(x[2:])])
        top = coef[-1]
        if not np.isfinite(top) or top <= 1e-9:
            break
        curve = ToneCurve("fitted", coef / top)
        M = _solve_matrix(curve(e) / light[:, None], target)
    return curve, M


@dataclass(frozen=True)
class CameraModel:
    """A fitted camera model: `curve` (encoded -> linear signal), `correction` and its `matrix` (terms, 3).

    **Fields:** `accuracy` (the leave-one-out mean CIEDE2000 over the references), `references` (how many),
    `scores` (each supported candidate's leave-one-out mean CIEDE2000), `residuals` (each reference's leave-one-out
    CIEDE2000 with the chosen model).
    """

    curve: ToneCurve
    correction: str
    matrix: np.ndarray
    accuracy: float
    references: int
    scores: dict[str, float] = field(default_factory=dict)
    residuals: np.ndarray | None = None

    def signal(self, encoded: np.ndarray) -> np.ndarray:
        """Linear camera signal of encoded values (the tone curve undone), same shape."""
        return self.curve(encoded)

    def correct(self, signal: np.ndarray) -> np.ndarray:
        """Linear sRGB reflectance of light-corrected signals (..., 3)."""
        s = np.asarray(signal, np.float64)
        return (_expand(s.reshape(-1, 3), self.correction) @ self.matrix).reshape(s.shape)

    @property
    def name(self) -> str:
        """The curve and the correction, in words (as `scores` names them)."""
        return f"{_CURVE_NAMES[self.curve.kind]} + {self.correction}"

    def gain(self) -> np.ndarray:
        """The model's gain per channel near neutral (reflectance per unit of signal), (3,)."""
        s = np.full((1, 3), 0.5)
        d = np.eye(3) * 1e-3
        return np.array([(self.correct(s + d[c])[0, c] - self.correct(s - d[c])[0, c]) / 2e-3 for c in range(3)])

    def to_dict(self) -> dict[str, Any]:
        return {"model": self.name, "references": self.references,
                "leave_one_out_mean_delta_e_2000": round(float(self.accuracy), 4),
                "candidates": {k: round(float(v), 4) for k, v in self.scores.items()},
                "tone_curve": None if self.curve.coefficients is None else
                [round(float(c), 6) for c in self.curve.coefficients],
                "matrix": np.round(self.matrix, 6).tolist()}  # fmt: skip


def _curve(kind: str, e: np.ndarray, light: np.ndarray, target: np.ndarray) -> ToneCurve:
    return _fit_curve(e, light, target)[0] if kind == "fitted" else ToneCurve(kind)


def _curve_kinds(raw: bool) -> tuple[str, ...]:
    return ("linear",) if raw else ("srgb", "camera", "fitted")


def _candidates(n: int, raw: bool) -> list[tuple[str, str]]:
    return [(c, m) for c in _curve_kinds(raw) for m in CORRECTIONS if n >= _needs(c, m)]


def _condition(X: np.ndarray) -> float:
    """The condition number of `X` (n, k) with each column scaled to unit RMS; inf where it is rank deficient."""
    X = np.asarray(X, np.float64)
    if X.shape[0] < X.shape[1] or not np.all(np.isfinite(X)):
        return float("inf")
    top = np.max(np.abs(X), axis=0)
    if np.any(top <= 0):
        return float("inf")
    Y = X / top  # in [-1, 1] first: the RMS cannot overflow
    s = np.linalg.svd(Y / np.sqrt(np.mean(Y * Y, axis=0)), compute_uv=False)
    return float(s[0] / s[-1]) if s[-1] > 0 else float("inf")


def _distinct(lab: np.ndarray, tol: float = 1.0) -> int:
    """How many of the colours `lab` (n, 3) differ by more than `tol` (CIE 1976) from every earlier one."""
    kept: list[np.ndarray] = []
    for c in lab:
        if all(np.linalg.norm(c - k) > tol for k in kept):
            kept.append(c)
    return len(kept)


def _too_few_colours(lab: np.ndarray) -> str:
    """Why references of known colour `lab` (n, 3) do not span colour space, in words."""
    n, k = len(lab), _distinct(lab)
    if np.max(np.hypot(lab[:, 1], lab[:, 2])) < _NEUTRAL_CHROMA:
        why = "they are all near-neutral"
    elif k < 3:
        why = f"they are only {k} distinct colour{'s' if k != 1 else ''}"
    else:
        why = "their colours lie close to one plane of colour space"
    return (f"the {n} references span too few colours for a colour matrix ({why}): add coloured references, or "
            f"leave them out to calibrate from the paper")  # fmt: skip


def _unsupported(msg: str, file: Any) -> DiffwashError:
    return DiffwashError(msg, file=file, field="references")


def _shown_curves(kinds: set[str], e: np.ndarray, light: np.ndarray, target: np.ndarray) -> dict[str, ToneCurve]:
    """Each curve kind fitted to all references, where the photo's values of them through it span colour space."""
    curves = {kind: _curve(kind, e, light, target) for kind in sorted(kinds)}
    return {k: c for k, c in curves.items() if _condition(c(e) / light[:, None]) <= MAX_SPAN_CONDITION}


def _leave_one_out(kind: str, corr: str, e: np.ndarray, light: np.ndarray, target: np.ndarray,
                   curves: dict[tuple[str, int], ToneCurve]) -> np.ndarray | None:  # fmt: skip
    """Each reference predicted by the candidate fitted to the others, (n, 3); None where a fold does not
    determine the candidate's terms (`MAX_TERMS_CONDITION`). `curves` caches each fold's curve."""
    n = len(e)
    pred = np.empty((n, 3))
    for i in range(n):
        keep = np.arange(n) != i
        if (kind, i) not in curves:
            curves[kind, i] = _curve(kind, e[keep], light[keep], target[keep])
        curve = curves[kind, i]
        F = _expand(curve(e[keep]) / light[keep, None], corr)
        if _condition(F) > MAX_TERMS_CONDITION:
            return None
        pred[i] = _expand(curve(e[i : i + 1]) / light[i], corr) @ _solve_matrix(F, target[keep])
    return pred


def fit_camera(encoded: Any, light: Any, lab: Any, *, raw: bool = False, file: Any = None) -> CameraModel:
    """Fit the camera model to references (module docstring), choosing it by leave-one-out.

    **Arguments:** `encoded` (n, 3): each reference's mean encoded value in [0, 1] (linear for a raw photo);
    `light` (n,): the relative light at each; `lab` (n, 3): their known CIELAB (D65); `raw`: the values are
    linear already (the curve is the identity); `file`: the layout, named by errors.

    **Returns:** the `CameraModel`. Needs at least `needed_references()` references (the caller checks).
    References that support no candidate (module docstring) raise a `DiffwashError` naming `references`.
    """
    e = np.asarray(encoded, np.float64)
    light = np.asarray(light, np.float64)
    lab = np.asarray(lab, np.float64)
    target = lab_to_linear(lab)
    n = len(e)
    if _condition(target) > MAX_SPAN_CONDITION:
        raise _unsupported(_too_few_colours(lab), file)
    candidates = _candidates(n, raw)
    full = _shown_curves({kind for kind, _ in candidates}, e, light, target)
    if not full:
        raise _unsupported(f"the photo shows the {n} references as too few colours for a colour matrix (as it "
                           f"reads them, their colours lie close to one plane of colour space): check that their "
                           f"boxes are on the patches of known colour, or add more strongly coloured references",
                           file)  # fmt: skip
    scores, loo = {}, {}
    curves: dict[tuple[str, int], ToneCurve] = {}  # the curve of each fold, shared by the corrections
    for kind, corr in candidates:
        pred = _leave_one_out(kind, corr, e, light, target, curves) if kind in full else None
        de = None if pred is None else _de(pred, lab)
        if de is None or not np.all(np.isfinite(de)):
            continue  # the references do not support it: it cannot be scored
        scores[f"{_CURVE_NAMES[kind]} + {corr}"] = float(np.mean(de))
        loo[(kind, corr)] = (float(np.mean(de)), de)
    if not loo:
        raise _unsupported(f"with any one of the {n} references left out, the others do not determine a colour "
                           f"matrix, so its accuracy cannot be scored: add references of other colours",
                           file)  # fmt: skip
    (kind, corr), (best, de) = min(loo.items(), key=lambda kv: kv[1][0])
    curve = full[kind]
    M = _solve_matrix(_expand(curve(e) / light[:, None], corr), target)
    return CameraModel(curve=curve, correction=corr, matrix=M, accuracy=best, references=n, scores=scores,
                       residuals=de)  # fmt: skip


#: File suffixes read as raw photos (through rawpy / LibRaw).
RAW_SUFFIXES = (".dng", ".cr2", ".cr3", ".crw", ".nef", ".nrw", ".arw", ".srf", ".sr2", ".orf", ".rw2", ".raf",
                ".pef", ".srw", ".x3f", ".3fr", ".iiq", ".rwl", ".mrw", ".kdc", ".dcr", ".erf", ".mos")  # fmt: skip
_EXTRA = "pip install 'diffwash[photo]'"


def read_raw(path: Any) -> np.ndarray:
    """A raw photo (DNG, CR2, NEF, ARW, ...) as linear camera values in [0, 1], (H, W, 3), as displayed.

    Demosaiced by LibRaw (rawpy) with no gamma, no automatic brightening, the camera's white balance where
    the file has one, in the camera's colour matrix to linear sRGB primaries; the camera model or the paper's
    calibration does the rest. Orientation as the file says.
    """
    try:
        import rawpy
    except ImportError:
        raise DiffwashError(f"reading raw photos needs rawpy: {_EXTRA}", file=path) from None
    try:
        with rawpy.imread(str(path)) as r:
            rgb = r.postprocess(gamma=(1, 1), no_auto_bright=True, output_bps=16, use_camera_wb=True,
                                output_color=rawpy.ColorSpace.sRGB, user_flip=None)  # fmt: skip
    except (rawpy.LibRawError, OSError, ValueError) as e:
        raise DiffwashError(f"cannot read as a raw photo: {e}", file=path) from None
    return np.asarray(rgb, np.float64) / 65535.0


def checker_references() -> np.ndarray:
    """CIELAB (D65) of the 24 patches of an X-Rite ColorChecker Classic (colour-science's "ColorChecker24 -
    After November 2014", D50, adapted to D65 with Bradford's transform), in the chart's order, (24, 3)."""
    cc = colour.CCS_COLOURCHECKERS["ColorChecker24 - After November 2014"]
    XYZ = colour.xyY_to_XYZ(np.array(list(cc.data.values())))
    d65 = colour.CCS_ILLUMINANTS["CIE 1931 2 Degree Standard Observer"]["D65"]
    XYZ = colour.chromatic_adaptation(XYZ, colour.xy_to_XYZ(cc.illuminant), colour.xy_to_XYZ(d65),
                                      method="Von Kries", transform="Bradford")  # fmt: skip
    return np.asarray(colorimetry.xyz_to_lab(XYZ), np.float64)


def find_checker(display: np.ndarray, file: Any = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Find an X-Rite ColorChecker Classic in a photo (colour-checker-detection's segmentation).

    **Returns:** `(encoded (24, 3), centres (24, 2) as (x, y) pixels, lab (24, 3))`: each patch's mean
    encoded value, where it is and its known colour. A photo with no checker found raises `DiffwashError`.
    """
    try:
        import colour_checker_detection as ccd
    except ImportError:
        raise DiffwashError(f"--checker needs colour-checker-detection: {_EXTRA}", file=file) from None
    img = np.asarray(display, np.float32)
    found = ccd.detect_colour_checkers_segmentation(img, additional_data=True)
    if not found:
        raise DiffwashError("no X-Rite ColorChecker Classic found in the photo (24 patches, 4 x 6, fully in view)",
                            file=file, field="--checker")  # fmt: skip
    data = found[0]
    colours = np.asarray(data.swatch_colours, np.float64)
    centres = _checker_centres(data, np.asarray(display, np.float64))
    return colours, centres, checker_references()


def _checker_centres(data: Any, display: np.ndarray) -> np.ndarray:
    """The 24 patches' centres (x, y) in the photo's pixels, from the checker's quadrilateral.

    The detector works on the photo resized to its working width (1440 pixels) and may have read the chart
    turned or mirrored; the patches lie on a 6 x 4 grid inside the quadrilateral (interpolated bilinearly
    between its corners), and of the 8 ways to lay the grid on it the one whose pixels match the detected
    colours best is taken. The centres set only where the light falloff is read, which varies slowly.
    """
    H, W = display.shape[:2]
    q = np.asarray(data.quadrilateral, np.float64).reshape(4, 2) * (W / 1440.0)
    colours = np.asarray(data.swatch_colours, np.float64)
    u = (np.arange(6) + 0.5) / 6
    v = (np.arange(4) + 0.5) / 4
    vv, uu = np.meshgrid(v, u, indexing="ij")
    uu, vv = uu.ravel()[:, None], vv.ravel()[:, None]
    best, out = np.inf, None
    for k in range(4):
        for order in (np.roll(np.arange(4), -k), np.roll(np.arange(4)[::-1], -k)):
            c0, c1, c2, c3 = q[order]
            c = (1 - uu) * (1 - vv) * c0 + uu * (1 - vv) * c1 + uu * vv * c2 + (1 - uu) * vv * c3
            c = np.clip(c, 0, [W - 1, H - 1])
            seen = display[c[:, 1].astype(int), c[:, 0].astype(int)]
            err = float(np.sum((seen - colours) ** 2))
            if err < best:
                best, out = err, c
    return out
