r"""A pigment from photos of a swatch card.

The photo is linearised and calibrated from its paper (`diffwash.fit._photo`);
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
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .._errors import DiffwashError
from .._io import read_image
from ..pigments import Pigment
from ..pigments import save as save_pigments
from ._kmfit import FitModel, Rows, fit_rows, log_sd, pad_rows, paired_start, predict_jit, single_ground_start
from ._kmfit import starts_for
from ._photo import Calibration, Layout, PatchStats, calibrate, linearise, parse_layout, patch_stats, read_layout
from ._table import delta_e_displayed

__all__ = ["SWATCH_MODEL", "PatchResult", "SwatchFit", "fit_swatches"]

#: The model for swatch photos: thickness = coats (the renderer's unit), no
#: surface term (as the renderer), CIE 1994 residuals, a weak prior. CIE94
#: weights chroma and hue differences by chroma as CIEDE2000 does; on the real
#: NTU measurements a fit in it predicts within 0.05 CIEDE2000 of a fit in
#: CIEDE2000 itself, and it compiles in half the time (the command's cold start).
#: The diagnostics are CIEDE2000 either way; `FitModel(loss="de2000", ...)` fits in it.
SWATCH_MODEL = FitModel(thickness="linear", surface="none", loss="cie94")
_CHANNELS = ("red", "green", "blue")


@dataclass(frozen=True)
class PatchResult:
    """One patch: where, what, what was seen and what the fitted pigment predicts.

    `observed` and `fitted` are linear reflectance (3,); `delta_e` is CIEDE2000
    between them; `weight` is the patch's weight in the fit (lower when partly
    clipped); `bound` says per channel whether the observation was only a bound.
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

    def to_dict(self) -> dict[str, Any]:
        return {"photo": self.photo, "box": self.box, "coats": self.coats, "ground": self.ground,
                "observed": [round(float(v), 6) for v in self.observed],
                "fitted": [round(float(v), 6) for v in self.fitted], "delta_e_2000": round(float(self.delta_e), 4),
                "weight": round(float(self.weight), 4), "clipped": self.bound}  # fmt: skip


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

    @property
    def mean_delta_e(self) -> float:
        """Mean CIEDE2000 over the patches."""
        return float(np.mean([p.delta_e for p in self.patches]))

    def predict(self, coats: Any, ground: Any = "paper") -> np.ndarray:
        """Linear reflectance at `coats` over `"paper"`, `"black"` or a reflectance (3,).

        **Returns:** (len(coats), 3).
        """
        coats = np.atleast_1d(np.asarray(coats, np.float64))
        if isinstance(ground, str):
            if ground == "black":
                if self.black is None:
                    raise DiffwashError("the card had no black band: its reflectance is unknown")
                g = self.black
            elif ground == "paper":
                g = self.paper
            else:
                raise DiffwashError(f"unknown ground {ground!r} (must be 'paper' or 'black')")
        else:
            g = np.asarray(ground, np.float64)
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
            "calibration": [c.to_dict() for c in self.calibrations],
            "patches": [p.to_dict() for p in self.patches],
        }

    def save(self, path: str | os.PathLike) -> None:
        """Write the pigment file (library schema) with the diagnostics under `"fit"`."""
        save_pigments(path, self.pigment, fit=self.to_dict())


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


def _load_photo(photo: Any) -> tuple[np.ndarray, int, str | None]:
    if isinstance(photo, (str, os.PathLike)):
        display, bits = read_image(photo)
        return display, bits, os.fspath(photo)
    a = np.asarray(photo, np.float64)
    if a.ndim != 3 or a.shape[2] != 3:
        raise DiffwashError(f"a photo must be an (H, W, 3) array, got shape {a.shape}")
    return a, 8, None


def fit_swatches(
    photo: Any,
    layout: Any,
    *,
    name: str | None = None,
    model: FitModel = SWATCH_MODEL,
    max_steps: int = 1000,
) -> SwatchFit:
    """Fit one pigment's K and S (per coat) to photos of its swatch card.

    **Arguments:**

    - `photo`: a photo (path of a PNG, 8 or 16 bit, or JPEG; or an (H, W, 3)
      array of display sRGB in [0, 1]), or a list of them (one pigment on
      several cards).
    - `layout`: its layout (path, parsed JSON, or `Layout`; format in
      `diffwash.fit._photo`), or a list matching `photo`.
    - `name`: the pigment's name (default: the layout's `name`, else the photo's
      file name).
    - `model`: the `FitModel` (default `SWATCH_MODEL`).
    - `max_steps`: Levenberg-Marquardt steps at most.

    **Returns:**

    A `SwatchFit`: the pigment and its diagnostics (per-patch CIEDE2000,
    iterations, convergence, identifiability). Bad input (boxes outside the
    photo or empty, an unknown ground, a saturated or missing paper box, NaN)
    raises `DiffwashError` naming the file and the field.
    """
    photos = list(photo) if isinstance(photo, (list, tuple)) else [photo]
    layouts = list(layout) if isinstance(layout, (list, tuple)) else [layout]
    if len(photos) != len(layouts):
        raise DiffwashError(f"got {len(photos)} photos but {len(layouts)} layouts")
    rows, info, cals, papers, blacks = [], [], [], [], []
    for k, (ph, lay) in enumerate(zip(photos, layouts)):
        display, bits, photo_path = _load_photo(ph)
        if not np.all(np.isfinite(display)):
            raise DiffwashError("the photo has NaN or infinite values", file=photo_path)
        H, W, _ = display.shape
        if isinstance(lay, Layout):
            L = parse_layout(lay.to_dict(), file=lay.path, size=(W, H))
        elif isinstance(lay, (str, os.PathLike)):
            L = read_layout(lay, size=(W, H))
        else:
            L = parse_layout(lay, size=(W, H))
        if name is None and L.name:
            name = L.name
        linear = linearise(display)
        cal = calibrate(linear, display, bits, L, file=L.path or photo_path)
        cals.append(cal)
        papers.append(L.paper_reflectance)
        black = None
        if L.black is not None:
            bs = patch_stats(linear, display, bits, cal, L.black)
            black = bs.rgb
            if np.any(bs.clipped_hi > 0.5):
                raise DiffwashError("the black box is clipped white in the photo: is it on the black band?",
                                    file=L.path, field="black.box")  # fmt: skip
            blacks.append(black)
        for j, p in enumerate(L.patches):
            st: PatchStats = patch_stats(linear, display, bits, cal, p.box)
            bound_lo, bound_hi = st.clipped_lo > 0.5, st.clipped_hi > 0.5
            partly = np.where(bound_lo | bound_hi, 0.0, np.maximum(st.clipped_lo, st.clipped_hi))
            weight = float(max(1.0 - 2 * partly.max(), 0.1))
            ground = L.paper_reflectance if p.ground == "paper" else black
            rows.append((p.coats, ground, st.rgb, bound_lo, bound_hi, weight))
            info.append((k, p, st))
    if name is None:
        name = Path(photos[0]).stem if isinstance(photos[0], (str, os.PathLike)) else "pigment"
    paper = np.mean(papers, axis=0)
    black = np.mean(blacks, axis=0) if blacks else None
    amount = np.array([r[0] for r in rows])
    grounds = np.array([r[1] for r in rows])
    rgb = np.array([r[2] for r in rows])
    lo = np.array([r[3] for r in rows])
    hi = np.array([r[4] for r in rows])
    weight = np.array([r[5] for r in rows])
    if not np.all(np.isfinite(rgb)):
        raise DiffwashError("a patch's colour is not finite", file=layouts[0] if isinstance(layouts[0], str) else None)

    # Start: Curtis's inversion from each coat count seen over both grounds, else a rough guess.
    gnames = np.array([p.ground for _, p, _ in info])
    start = paired_start(amount, gnames, rgb, paper, black)
    K0, S0 = start if start is not None else single_ground_start(amount, grounds, rgb)
    starts = {k: v[None] for k, v in starts_for(model, K0, S0).items()}
    n, M = len(amount), pad_rows(len(amount))
    pad = lambda a, fill: np.concatenate([a, np.full((M - n,) + a.shape[1:], fill, a.dtype)])[None]  # noqa: E731
    batch = Rows(amount=pad(amount, 0.0), ground=pad(grounds, 0.5), rgb=pad(rgb, 0.5), lo=pad(lo, False),
                 hi=pad(hi, False), weight=pad(weight, 0.0))  # fmt: skip
    res = fit_rows(model, batch, starts, max_steps=max_steps)
    theta = {k: np.asarray(v[0], np.float64) for k, v in res.theta.items()}
    sizes = {k: int(np.prod(theta[k].shape)) for k in res.param_names}
    sd = log_sd(np.asarray(res.jacobian[0], np.float64), sizes, float(res.loss[0]))
    pigment = Pigment(K=np.exp(theta["log_K"]), S=np.exp(theta["log_S"]), name=name)
    fitted = np.asarray(res.fitted[0], np.float64)[:n]
    # As the camera would have recorded the fit: a clipped channel shows its bound when the fit lies beyond it.
    des = delta_e_displayed(np.where(lo, np.maximum(fitted, rgb), np.where(hi, np.minimum(fitted, rgb), fitted)), rgb)
    patches = [
        PatchResult(photo=k, box=p.box.tolist(), coats=p.coats, ground=p.ground, observed=rgb[i], fitted=fitted[i],
                    delta_e=float(des[i]), weight=float(weight[i]), bound=[bool(a or b) for a, b in zip(lo[i], hi[i])],
                    spread=st.spread)  # fmt: skip
        for i, (k, p, st) in enumerate(info)
    ]
    text = _identifiability([(p.coats, p.ground) for _, p, _ in info], sd)
    return SwatchFit(pigment=pigment, patches=patches, paper=paper, black=black, calibrations=cals,
                     iterations=int(res.steps[0]), converged=bool(res.converged[0]), log_sd=sd,
                     identifiability=text, model=model)  # fmt: skip

