r"""A pigment from photos of a swatch card.

The photo is linearised and calibrated from its paper (`diffwash.fit.photos._photo`);
each patch's robust mean colour is a row (coats, ground, colour) for the shared
Kubelka-Munk fit (`diffwash.fit._kmfit`): `log K` and `log S` per channel,
refined with optimistix's Levenberg-Marquardt on CIE 1994 residuals, from
Curtis's black/white inversion when the card has patches over both grounds.
The thickness of a patch is its number of coats, so the fitted K and S are
per coat, the renderer's unit.

Identifiability (what the card can tell):

- patches over paper and over black: K and S are both determined (Curtis et
  al. 1997, sec. 5.1: over black a glaze shows what it scatters, over a light
  ground what it absorbs);
- over one ground, several coat counts: K is determined by how the colour
  darkens with coats, S only by how that departs from a pure absorber (over
  paper) or approaches opacity (over black) -- weakly for transparent pigments;
- over one ground, one coat count: one number per channel for two unknowns;
  K and S are not separately identifiable (the weak prior picks one of the
  solutions; predictions at other thicknesses are guesses).

The fit reports this, with the standard deviations of the fitted logs.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from ... import colorimetry
from ..._cache import relieve_compiled_programs
from ..._errors import DiffwashError
from ..._io import read_image
from ..._regions import Posterior
from ...library import Library, library_from_pigments
from ...shading import DEFAULT_PAPER
from ...pigments import Pigment
from .._kmfit import FitModel, Rows, fit_rows, log_sd, pad_rows, paired_start, predict_jit, single_ground_start
from .._kmfit import delta_e_displayed, starts_for
from ._noise import camera_noise_floor, jpeg_steps
from ._noisefit import Observations, Uncertainty, fit_noise, uncertainty
from ._noisefit import _prediction_and_jacobian
from ._camera import RAW_SUFFIXES, default_curve, find_checker, read_raw
from ._photo import Calibration, Layout, PatchStats, calibrate, calibrate_references, inner_box, linearise
from ._photo import parse_layout, patch_stats
from ._photo import read_layout, swatch_pigments

__all__ = ["SWATCH_MODEL", "PatchResult", "SwatchFit", "fit_swatches"]

#: The model for swatch photos: thickness = coats (the renderer's unit), no
#: surface term (as the renderer), residuals in standard deviations of each
#: patch's own noise with the calibration fitted jointly (`loss="noise"`,
#: `diffwash.fit.photos._noisefit`), and a weak prior (a tenth of a standard deviation
#: per unit of log) that only settles what the photo leaves free. The
#: diagnostics are CIEDE2000; `FitModel(thickness="linear", loss="cie94")` is
#: the unweighted perceptual fit.
SWATCH_MODEL = FitModel(thickness="linear", surface="none", loss="noise", prior=0.1)
_CHANNELS = ("red", "green", "blue")


@dataclass(frozen=True)
class PatchResult:
    """One patch: where, what, what was seen and what the fitted pigment predicts.

    `observed` and `fitted` are linear reflectance (3,); `delta_e` is CIEDE2000
    between them; `weight` is the patch's weight in the fit (lower when partly
    clipped); `bound` says per channel whether the observation was only a bound;
    `se` is the standard error of `observed` (3,) (its noise); `floor` says per
    channel whether it is at the camera's noise floor. A patch of a mixture card
    (`fit_swatch_mixtures`) names its `pigments` and the coats of each (`amounts`);
    `coats` is then their sum.
    """

    photo: int
    box: list[int]
    coats: float
    ground: str
    observed: np.ndarray
    fitted: np.ndarray
    delta_e: float
    weight: float
    bound: list[bool]
    spread: np.ndarray
    se: np.ndarray | None = None
    floor: list[bool] | None = None
    pigments: tuple[str, ...] = ()
    amounts: tuple[float, ...] = ()

    def to_dict(self) -> dict[str, Any]:
        paint = {"pigment": "+".join(self.pigments), "amount": "+".join(f"{a:g}" for a in self.amounts)}
        out = {"photo": self.photo, "box": self.box, **(paint if self.pigments else {}), "coats": self.coats,
               "ground": self.ground,
               "observed": [round(float(v), 6) for v in self.observed],
               "fitted": [round(float(v), 6) for v in self.fitted], "delta_e_2000": round(float(self.delta_e), 4),
               "weight": round(float(self.weight), 4), "clipped": self.bound}  # fmt: skip
        if self.se is not None:
            out["standard_error"] = [float(f"{v:.4g}") for v in self.se]
            out["noise_floor"] = self.floor
        return out


#: The mean length of a 3-vector of standard normal components: a mean colour error over this is a standard
#: deviation per CIELAB axis.
MEAN_OF_CHI3 = 1.596
#: The standard deviation given to a log K or log S that the photo only bounds or does not determine, in a
#: library's posterior (`SwatchFit.posterior`): a factor of e either way.
UNDETERMINED_SD = 1.0


def lab_sd(rgb: Any, cov: Any) -> float:
    """The standard deviation per CIELAB axis (RMS over the three) of a linear sRGB colour `rgb` of covariance
    `cov` (3, 3), to first order."""
    rgb = np.clip(np.asarray(rgb, np.float64), 1e-4, None)
    h = 1e-4 * np.maximum(rgb, 1e-3)
    lab = lambda x: np.asarray(colorimetry.linear_srgb_to_lab(x), np.float64)  # noqa: E731
    J = np.stack([(lab(rgb + h[c] * e) - lab(rgb - h[c] * e)) / (2 * h[c]) for c, e in enumerate(np.eye(3))], 1)
    v = float(np.trace(J @ np.asarray(cov, np.float64) @ J.T)) / 3
    return float(np.sqrt(v)) if np.isfinite(v) and v > 0 else 0.0


@dataclass(frozen=True)
class SwatchFit:
    """A pigment fitted to swatch photos, with its diagnostics.

    **Fields:**

    - `pigment`: the fitted `Pigment` (K, S per coat).
    - `patches`: a `PatchResult` per patch.
    - `paper`: the paper's linear reflectance (from the layout), (3,).
    - `black`: the black ground's calibrated linear reflectance (measured), or None.
    - `calibrations`: each photo's `Calibration`.
    - `iterations`, `converged`: how Levenberg-Marquardt went.
    - `log_sd`: standard deviations of the fitted `log_K`, `log_S`.
    - `identifiability`: what the card can and cannot tell, in words.
    - `uncertainty`: the noise-aware fit's `Uncertainty` (covariance of the logs
      with the calibration's uncertainty, degrees of freedom, parameters the
      photo does not determine), or None for an unweighted fit. `intervals` and
      `predict_interval` use it.
    """

    pigment: Pigment
    patches: list[PatchResult]
    paper: np.ndarray
    black: np.ndarray | None
    calibrations: list[Calibration]
    iterations: int
    converged: bool
    log_sd: dict[str, np.ndarray]
    identifiability: str
    model: FitModel = SWATCH_MODEL
    uncertainty: Uncertainty | None = None

    @property
    def log_value(self) -> np.ndarray:
        """`(log K_r, log K_g, log K_b, log S_r, log S_g, log S_b)`."""
        return np.log(np.maximum(np.concatenate([self.pigment.K, self.pigment.S]), 1e-300))

    def _need_uncertainty(self) -> Uncertainty:
        if self.uncertainty is None:
            raise DiffwashError(f"an unweighted fit (loss {self.model.loss!r}) has no intervals: fit with the "
                                f"default model (loss 'noise')")  # fmt: skip
        return self.uncertainty

    def intervals(self, level: float = 0.9) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """Intervals of K and S per channel holding the truth with probability `level` (default 90%).

        **Returns:** `{"K": (lower, upper), "S": (lower, upper)}`, arrays (3,).
        Where the photo only bounds a parameter (`uncertainty.reason`), the
        interval is one-sided: a lower end of 0 or an upper end of infinity.
        """
        lo, hi = self._need_uncertainty().intervals(self.log_value, level)
        lo, hi = np.exp(lo), np.exp(hi)
        return {"K": (lo[:3], hi[:3]), "S": (lo[3:], hi[3:])}

    def interval_lines(self, level: float = 0.9) -> list[str]:
        """K and S per channel with their intervals, in words (what `diffwash fit-swatch` prints).

        A parameter the photo does not determine is given as the bound the data do
        give, with the reason, e.g. `S blue < 0.0174 (at the camera's noise floor...)`.
        """
        if self.uncertainty is None:
            return []
        unc = self.uncertainty
        iv = self.intervals(level)
        pct = f"{100 * level:g}%"
        why = {"noise floor": "at the camera's noise floor: the photo bounds it but does not measure it",
               "clipped": "clipped by the camera: the photo bounds it but does not measure it",
               "weak": "poorly determined by this card"}  # fmt: skip
        lines = []
        for k, key in enumerate(("K", "S")):
            parts = []
            for c, ch in enumerate(_CHANNELS):
                j = 3 * k + c
                v, lo, hi = getattr(self.pigment, key)[c], iv[key][0][c], iv[key][1][c]
                if unc.reason[j] and lo <= 0 and np.isfinite(hi):
                    parts.append(f"{ch} < {hi:.3g} ({why[unc.reason[j]]})")
                elif unc.reason[j] and not np.isfinite(hi) and lo > 0:
                    parts.append(f"{ch} > {lo:.3g} ({why[unc.reason[j]]})")
                elif unc.reason[j] and not (lo > 0 or np.isfinite(hi)):
                    parts.append(f"{ch} not determined ({why[unc.reason[j]]})")
                else:
                    flag = f" ({why[unc.reason[j]]})" if unc.reason[j] else ""
                    parts.append(f"{ch} {v:.4g} [{lo:.4g}, {hi:.4g}]{flag}")
            lines.append(f"{key} per coat ({pct} intervals): " + "; ".join(parts))
        lines.append(f"chi-square {unc.chi2:.1f} for {unc.dof} degrees of freedom; patch-to-patch dispersion beyond "
                     f"the pixels' noise {100 * unc.dispersion:.1f}%")  # fmt: skip
        return lines

    def _ground(self, ground: Any) -> np.ndarray:
        if isinstance(ground, str):
            if ground == "black":
                if self.black is None:
                    raise DiffwashError("the card had no black band: its reflectance is unknown")
                return self.black
            if ground == "paper":
                return self.paper
            raise DiffwashError(f"unknown ground {ground!r} (must be 'paper' or 'black')")
        return np.asarray(ground, np.float64)

    def predict_interval(self, coats: Any, ground: Any = "paper", level: float = 0.9) -> tuple[np.ndarray, np.ndarray]:
        """Intervals of the linear reflectance at `coats` over `ground` (as `predict`), per channel.

        Propagates the covariance of the logs (calibration included) through
        Kubelka-Munk (to first order, in log reflectance), with Student's t;
        a reflectance is at most 1. **Returns:** `(lower, upper)`, each (len(coats), 3).
        """
        unc = self._need_uncertainty()
        coats = np.atleast_1d(np.asarray(coats, np.float64))
        g = np.broadcast_to(self._ground(ground), coats.shape + (3,))
        theta = {"log_K": self.log_value[:3], "log_S": self.log_value[3:]}
        pred, J = _prediction_and_jacobian(self.model, theta, coats, g)
        cov = np.where(np.isfinite(unc.log_cov), unc.log_cov, 1e6)
        var = np.einsum("ncj,jk,nck->nc", J, cov, J)
        sd_log = np.sqrt(np.maximum(var, 0)) / np.maximum(pred, 1e-12)
        t = unc.quantile(level)
        return pred * np.exp(-t * sd_log), np.minimum(pred * np.exp(t * sd_log), 1.0)

    @property
    def mean_delta_e(self) -> float:
        """Mean CIEDE2000 over the patches."""
        return float(np.mean([p.delta_e for p in self.patches]))

    def predict(self, coats: Any, ground: Any = "paper") -> np.ndarray:
        """Linear reflectance at `coats` over `"paper"`, `"black"` or a reflectance (3,).

        **Returns:** (len(coats), 3).
        """
        coats = np.atleast_1d(np.asarray(coats, np.float64))
        g = self._ground(ground)
        theta = {"log_K": np.log(np.maximum(self.pigment.K, 1e-300)),
                 "log_S": np.log(np.maximum(self.pigment.S, 1e-300))}  # fmt: skip
        return np.asarray(predict_jit(self.model, theta, coats, np.broadcast_to(g, coats.shape + (3,))), np.float64)

    def to_dict(self) -> dict[str, Any]:
        """The diagnostics, JSON-ready."""
        return {
            "source": "diffwash fit-swatch",
            "model": self.model.describe(),
            "paper": self.paper.tolist(),
            "black": None if self.black is None else self.black.tolist(),
            "mean_delta_e_2000": round(self.mean_delta_e, 4),
            "max_delta_e_2000": round(max(p.delta_e for p in self.patches), 4),
            "iterations": int(self.iterations),
            "converged": bool(self.converged),
            "log_sd": {k: [float(x) if np.isfinite(x) else None for x in v] for k, v in self.log_sd.items()},
            "identifiability": self.identifiability,
            **({"uncertainty": self.uncertainty.to_dict()} if self.uncertainty is not None else {}),
            "calibration": [c.to_dict() for c in self.calibrations],
            "patches": [p.to_dict() for p in self.patches],
        }

    @property
    def library(self) -> Library:
        """The pigment as a `diffwash.library.Library` per sRGB channel (amounts in coats, its grounds the card's
        paper and black), with the diagnostics as its fit record and, for the noise-aware fit, its posterior
        (`posterior`), so that `diffwash predict` writes 90% regions."""
        k2 = self.model.k2 if self.model.surface == "saunderson" else 0.0
        lib = library_from_pigments([self.pigment], grounds={"paper": self.paper, "black": self.black}, k2=k2,
                                    fit=self.to_dict())  # fmt: skip
        return replace(lib, posterior=self.posterior())

    def posterior(self) -> Posterior | None:
        """The fit's posterior as a library's (`diffwash._regions.Posterior`), or None for an unweighted fit.

        The covariance of the six logs (calibration included), with a log that the photo only bounds or does
        not determine given a standard deviation of `UNDETERMINED_SD` and no correlation; the amount law's
        exponent is fixed (1). The model error of a single paint (CIELAB units per axis) is the calibration's
        own error: the camera model's leave-one-out error, or the assumed tone curve's typical error (mean
        CIEDE2000, as a standard deviation per axis: / 1.6), 0 for a photo read through the sRGB curve. The
        patches' noise and the fit's dispersion beyond it are in the posterior already (`Uncertainty`); the
        calibration's error is shared by every patch, so no number of patches averages it away.
        """
        if self.uncertainty is None:
            return None
        unc = self.uncertainty
        cov = np.where(np.isfinite(unc.log_cov), unc.log_cov, 0.0)
        loose = np.array([bool(r) for r in unc.reason]) | ~np.isfinite(np.diag(unc.log_cov))
        loose |= np.diag(cov) > UNDETERMINED_SD**2
        cov[loose, :] = cov[:, loose] = 0.0
        cov[loose, loose] = UNDETERMINED_SD**2
        w, V = np.linalg.eigh(0.5 * (cov + cov.T))
        F = np.vstack([V * np.sqrt(np.maximum(w, 0.0)), np.zeros((1, 6))])  # + log gamma, fixed
        calibration = max([c.accuracy for c in self.calibrations] or [0.0]) / MEAN_OF_CHI3
        lab = lambda x: np.asarray(colorimetry.linear_srgb_to_lab(np.clip(x, 1e-6, None)), np.float64)  # noqa: E731
        resid = np.array([lab(q.fitted) - lab(q.observed) for q in self.patches])
        residual = float(np.sqrt(np.mean(np.square(resid)))) if len(resid) else 0.0
        single = float(calibration)
        record = {"single_from": "the calibration's own error (the patches' noise and the fit's dispersion are in "
                  "the posterior)",
                  "calibration_per_axis": round(float(calibration), 4),
                  "residual_per_axis": round(residual, 4)}  # fmt: skip
        return Posterior(F, np.zeros(7), {"single": single}, (), record)

    def save(self, path: str | os.PathLike) -> None:
        """Write the library file (one pigment, per sRGB channel; also a pigment file) with the diagnostics
        under `"fit"`: what `diffwash predict`, scenes and `fit-image` read."""
        self.library.save(path)


def _identifiability(patches: list[tuple[float, str]], sd: dict[str, np.ndarray]) -> str:
    grounds = {g for _, g in patches}
    coats = {g: sorted({c for c, gg in patches if gg == g}) for g in grounds}
    if grounds == {"paper", "black"}:
        text = ("Patches over paper and over black: K and S are both identifiable (Curtis et al. 1997, sec. 5.1: "
                "over black a glaze shows what it scatters, over paper what it absorbs).")  # fmt: skip
    else:
        (g,) = grounds
        n = len(coats[g])
        if n >= 2:
            how = ("departs from a pure absorber's as coats add up" if g == "paper"
                   else "approaches its opaque colour as coats add up")  # fmt: skip
            text = (f"Patches over {g} only, {n} coat counts: K is set by how the colour changes with coats, S only "
                    f"by how that change {how} -- weakly so for a transparent pigment. A patch over black would "
                    f"pin S down.")  # fmt: skip
        else:
            text = (f"Patches over {g} only, at one thickness: each channel gives one number for two unknowns, so K "
                    f"and S are NOT separately identifiable; the fit reproduces the patch with the (K, S) nearest "
                    f"the prior, and its colours at other thicknesses are guesses. Add coat counts, or patches over "
                    f"black.")  # fmt: skip
    weak = []
    for key, label in (("log_K", "K"), ("log_S", "S")):
        for c, v in zip(_CHANNELS, sd.get(key, [])):
            if not np.isfinite(v) or v > np.log(2):
                weak.append(f"{label} {c}")
    if weak:
        text += (" Poorly determined here (changing it by a factor of 2 changes the fit by less than about one "
                 "unit of colour difference): " + ", ".join(weak) + ".")  # fmt: skip
    return text


def _default_name(photo: Any) -> str:
    """The pigment's name when neither the caller nor a layout gives one: the photo's file name."""
    return Path(photo).stem if isinstance(photo, (str, os.PathLike)) else "pigment"


def _load_photo(photo: Any) -> tuple[np.ndarray, int, str | None]:
    if isinstance(photo, (str, os.PathLike)):
        if Path(photo).suffix.lower() in RAW_SUFFIXES:
            return read_raw(photo), 16, os.fspath(photo)
        display, bits = read_image(photo)
        return display, bits, os.fspath(photo)
    a = np.asarray(photo, np.float64)
    if a.ndim != 3 or a.shape[2] != 3:
        raise DiffwashError(f"a photo must be an (H, W, 3) array, got shape {a.shape}")
    return a, 8, None


@dataclass
class _Photo:
    """One photo measured: its layout, calibration, black band and patches."""

    layout: Layout
    calibration: Calibration
    paper: PatchStats
    black: PatchStats | None
    patches: list[PatchStats]


def _measure_all(photo: Any, layout: Any, checker: bool = False, tone_curve: str = "auto"
                 ) -> tuple[list[Any], list[Any], list[_Photo]]:  # fmt: skip
    """The photos and layouts (one or a list of each, as many layouts as photos) and each photo measured."""
    photos = list(photo) if isinstance(photo, (list, tuple)) else [photo]
    layouts = list(layout) if isinstance(layout, (list, tuple)) else [layout]
    if len(photos) != len(layouts):
        raise DiffwashError(f"got {len(photos)} photos but {len(layouts)} layouts")
    return photos, layouts, [_measure(ph, lay, checker, tone_curve) for ph, lay in zip(photos, layouts)]


def _raw_path(photo: Any) -> bool:
    return isinstance(photo, (str, os.PathLike)) and Path(photo).suffix.lower() in RAW_SUFFIXES


def _measure(photo: Any, layout: Any, checker: bool = False, tone_curve: str = "auto") -> _Photo:
    """Read, validate, calibrate and measure one photo (its patches, paper and black boxes).

    With references in the layout (or `checker`: a ColorChecker found in the photo) the photo is read through
    a camera model fitted to them (`diffwash.fit.photos._camera`); a raw photo is linear already. Without,
    through `tone_curve` (`diffwash.fit.photos._camera.default_curve`: "auto", "camera" or "srgb").
    """
    display, bits, photo_path = _load_photo(photo)
    raw = _raw_path(photo)
    if not np.all(np.isfinite(display)):
        raise DiffwashError("the photo has NaN or infinite values", file=photo_path)
    H, W, _ = display.shape
    if isinstance(layout, Layout):
        L = parse_layout(layout.to_dict(), file=layout.path, size=(W, H))
    elif isinstance(layout, (str, os.PathLike)):
        L = read_layout(layout, size=(W, H))
    else:
        L = parse_layout(layout, size=(W, H))
    curve, note = (None, "") if raw else default_curve(photo_path, tone_curve)
    linear = display if raw else linearise(display, curve)
    cal = replace(calibrate(linear, display, bits, L, file=L.path or photo_path), raw=raw, curve=curve)
    extra = find_checker(display, file=photo_path) if checker else None
    if L.references or extra is not None:
        cal = calibrate_references(display, bits, L, cal, raw=raw, file=L.path or photo_path, extra=extra)
    elif not raw:
        cal = replace(cal, notes=cal.notes + [note])
    if L.paper_default and cal.camera is None:
        cal = replace(cal, notes=cal.notes + [
            f"the paper box's colour was not given: taken as diffwash's paper {tuple(DEFAULT_PAPER)} (a cream "
            f"watercolour paper); give the layout's paper.reflectance or paper.lab if it is another white"])  # fmt: skip
    steps = jpeg_steps(photo_path)
    paper = patch_stats(linear, display, bits, cal, L.paper, steps, reference=True)
    if cal.camera is not None and L.paper_default:  # the paper as the references measure it
        L = replace(L, paper_reflectance=np.clip(paper.rgb, 1e-3, 1.0))
    black, floor = None, None
    if L.black is not None:
        black = patch_stats(linear, display, bits, cal, L.black, steps, reference=True)
        if np.any(black.clipped_hi > 0.5):
            raise DiffwashError("the black box is clipped white in the photo: is it on the black band?",
                                file=L.path, field="black.box")  # fmt: skip
        b = inner_box(L.black)
        floor = camera_noise_floor(linear[b.y0 : b.y1, b.x0 : b.x1], display[b.y0 : b.y1, b.x0 : b.x1], bits)
        # A black box that is not at the camera's black (a dark board, not black ink) shows its own texture,
        # not the sensor's noise: the noise floor is then read from each patch's own pixels.
        if not np.any(black.clipped_lo > 0.005) and np.all(black.rgb * cal.gain > 12 * floor):
            floor = None
    patches = [patch_stats(linear, display, bits, cal, p.box, steps, floor_noise=floor) for p in L.patches]
    return _Photo(layout=L, calibration=cal, paper=paper, black=black, patches=patches)


def _bounds(st: PatchStats) -> tuple[np.ndarray, np.ndarray, float]:
    """A patch's clipped channels (bounds, not values) and its weight (lower when partly clipped)."""
    bound_lo, bound_hi = st.clipped_lo > 0.5, st.clipped_hi > 0.5
    partly = np.where(bound_lo | bound_hi, 0.0, np.maximum(st.clipped_lo, st.clipped_hi))
    return bound_lo, bound_hi, float(max(1.0 - 2 * partly.max(), 0.1))


def _observations(photos: list[_Photo], paper: np.ndarray, black: np.ndarray | None) -> Observations:
    """Every patch of every photo as rows with their noise, and the calibration's uncertainty."""
    rows = []
    for k, ph in enumerate(photos):
        for p, st in zip(ph.layout.patches, ph.patches):
            lo, hi, weight = _bounds(st)
            ground = ph.layout.paper_reflectance if p.ground == "paper" else black
            rows.append((p.coats, ground, st.rgb, st.cov, lo, hi, weight, k, p.ground == "black",
                         ph.calibration.uncertainty_at(p.box), st.floor))  # fmt: skip
    cols = list(zip(*rows))
    # A photo's gain is its paper box's mean over the paper's reflectance: the box's noise is the gain's.
    gain_sd = np.array([np.sqrt(np.diag(ph.paper.cov)) / np.maximum(ph.paper.rgb, 1e-12) for ph in photos])
    black_sd = None
    if black is not None:
        sds = [np.sqrt(np.diag(ph.black.cov)) / np.maximum(ph.black.rgb, 1e-12) for ph in photos if ph.black]
        black_sd = np.sqrt(np.sum(np.square(sds), axis=0)) / len(sds)
    return Observations(amount=np.array(cols[0], np.float64), ground=np.array(cols[1], np.float64),
                        rgb=np.array(cols[2]), cov=np.array(cols[3]), lo=np.array(cols[4]), hi=np.array(cols[5]),
                        weight=np.array(cols[6]), photo=np.array(cols[7]), on_black=np.array(cols[8]),
                        relative=np.array(cols[9], np.float64), floor=np.array(cols[10]),
                        gain_sd=np.maximum(gain_sd, 1e-5),
                        black_sd=None if black_sd is None else np.maximum(black_sd, 1e-5))  # fmt: skip


def fit_swatches(
    photo: Any,
    layout: Any,
    *,
    name: str | None = None,
    model: FitModel = SWATCH_MODEL,
    max_steps: int = 1000,
    checker: bool = False,
    tone_curve: str = "auto",
) -> SwatchFit:
    """Fit one pigment's K and S (per coat) to photos of its swatch card.

    **Arguments:**

    - `photo`: a photo (path of a PNG, 8 or 16 bit, or JPEG; or an (H, W, 3)
      array of display sRGB in [0, 1]), or a list of them (one pigment on
      several cards).
    - `layout`: its layout (path, parsed JSON, or `Layout`; format in
      `diffwash.fit.photos._photo`), or a list matching `photo`.
    - `name`: the pigment's name (default: the layout's `name`, else the photo's
      file name); patches that name their `pigment` are of that pigment.
    - `model`: the `FitModel` (default `SWATCH_MODEL`: residuals weighted by
      each patch's noise, the calibration fitted jointly; a perceptual loss,
      e.g. `FitModel(thickness="linear", loss="cie94")`, fits unweighted and
      reports no intervals).
    - `max_steps`: Levenberg-Marquardt steps at most (per run).
    - `checker`: find an X-Rite ColorChecker Classic in each photo and calibrate the camera from its 24
      patches (with the layout's `references`, if any).
    - `tone_curve`: how a photo without references is read: "auto" (a typical camera's tone curve when the
      file's EXIF names a camera, else the sRGB curve), "camera" or "srgb"
      (`diffwash.fit.photos._camera.camera_curve`).

    **Returns:**

    A `SwatchFit`: the pigment and its diagnostics (per-patch CIEDE2000,
    iterations, convergence, identifiability, intervals, channels at the
    noise floor). Bad input (boxes outside the photo or empty, an unknown
    ground, a saturated or missing paper box, NaN) raises `DiffwashError`
    naming the file and the field; so do layouts that hold more than one
    pigment, alone or mixed (`swatch_pigments`): those are fitted jointly by
    `fit_swatch_mixtures`.
    """
    relieve_compiled_programs()  # before this fit compiles: a long-lived process may run out of memory maps
    photos, layouts, measured = _measure_all(photo, layout, checker, tone_curve)
    names = swatch_pigments([m.layout for m in measured], name=name, default=_default_name(photos[0]))
    if len(names) > 1:
        raise DiffwashError(f"the layouts hold {len(names)} pigments ({', '.join(names)}), alone or mixed: fit them "
                            f"jointly into a library with fit_swatch_mixtures (diffwash fit-swatch does)",
                            file=measured[0].layout.path)  # fmt: skip
    name = names[0]
    paper = np.mean([m.layout.paper_reflectance for m in measured], axis=0)
    blacks = [m.black.rgb for m in measured if m.black is not None]
    black = np.mean(blacks, axis=0) if blacks else None
    obs = _observations(measured, paper, black)
    if not np.all(np.isfinite(obs.rgb)):
        raise DiffwashError("a patch's colour is not finite", file=layouts[0] if isinstance(layouts[0], str) else None)
    gnames = np.where(obs.on_black, "black", "paper")
    start = paired_start(obs.amount, gnames, obs.rgb, paper, black)
    K0, S0 = start if start is not None else single_ground_start(obs.amount, obs.ground, obs.rgb)
    starts = starts_for(model, K0, S0)
    info = [(k, p, st) for k, m in enumerate(measured) for p, st in zip(m.layout.patches, m.patches)]
    if model.loss != "noise":
        return _fit_unweighted(model, obs, starts, max_steps, name, paper, black, measured, info)
    res = fit_noise(model, obs, [{k: v[i] for k, v in starts.items()} for i in range(len(starts["log_K"]))],
                    max_steps=max_steps)  # fmt: skip
    theta = res.theta
    if black is not None:
        black = black * np.exp(theta["log_black"])
    shown = res.fitted * np.exp(theta["log_gain"][obs.photo])  # what the photo shows of the fit
    sd = np.sqrt(np.diag(res.cov))
    log_sd_ = {"log_K": sd[:3], "log_S": sd[3:]}
    pigment = Pigment(K=np.exp(theta["log_K"]), S=np.exp(theta["log_S"]), name=name)
    patches = _patch_results(info, obs, shown)
    text = _identifiability([(p.coats, p.ground) for _, p, _ in info], log_sd_)
    unc = uncertainty(res, obs)
    return SwatchFit(pigment=pigment, patches=patches, paper=paper, black=black,
                     calibrations=[m.calibration for m in measured], iterations=res.steps, converged=res.converged,
                     log_sd=log_sd_, identifiability=text, model=model, uncertainty=unc)  # fmt: skip


def _patch_results(info: list, obs: Observations, fitted: np.ndarray) -> list[PatchResult]:
    rgb, lo, hi = obs.rgb, obs.lo, obs.hi
    # As the camera would have recorded the fit: a clipped channel shows its bound when the fit lies beyond it.
    des = delta_e_displayed(np.where(lo, np.maximum(fitted, rgb), np.where(hi, np.minimum(fitted, rgb), fitted)), rgb)
    return [
        PatchResult(photo=k, box=p.box.tolist(), coats=p.coats, ground=p.ground, observed=rgb[i], fitted=fitted[i],
                    delta_e=float(des[i]), weight=float(obs.weight[i]),
                    bound=[bool(a or b) for a, b in zip(lo[i], hi[i])], spread=st.spread,
                    se=np.sqrt(np.diag(obs.cov[i])), floor=[bool(f) for f in obs.floor[i]])  # fmt: skip
        for i, (k, p, st) in enumerate(info)
    ]


def _fit_unweighted(model: FitModel, obs: Observations, starts: dict, max_steps: int, name: str, paper: np.ndarray,
                    black: np.ndarray | None, measured: list[_Photo], info: list) -> SwatchFit:  # fmt: skip
    """The perceptual fit (CIE94, CIEDE2000, CIELAB or sRGB residuals), every patch alike: no intervals."""
    starts = {k: v[None] for k, v in starts.items()}
    n, M = len(obs.amount), pad_rows(len(obs.amount))
    pad = lambda a, fill: np.concatenate([a, np.full((M - n,) + a.shape[1:], fill, a.dtype)])[None]  # noqa: E731
    batch = Rows(amount=pad(obs.amount, 0.0), ground=pad(obs.ground, 0.5), rgb=pad(obs.rgb, 0.5),
                 lo=pad(obs.lo, False), hi=pad(obs.hi, False), weight=pad(obs.weight, 0.0))  # fmt: skip
    res = fit_rows(model, batch, starts, max_steps=max_steps)
    theta = {k: np.asarray(v[0], np.float64) for k, v in res.theta.items()}
    sizes = {k: int(np.prod(theta[k].shape)) for k in res.param_names}
    sd = log_sd(np.asarray(res.jacobian[0], np.float64), sizes, float(res.loss[0]))
    pigment = Pigment(K=np.exp(theta["log_K"]), S=np.exp(theta["log_S"]), name=name)
    patches = _patch_results(info, obs, np.asarray(res.fitted[0], np.float64)[:n])
    text = _identifiability([(p.coats, p.ground) for _, p, _ in info], sd)
    return SwatchFit(pigment=pigment, patches=patches, paper=paper, black=black,
                     calibrations=[m.calibration for m in measured], iterations=int(res.steps[0]),
                     converged=bool(res.converged[0]), log_sd=sd, identifiability=text, model=model)  # fmt: skip
