r"""Several pigments, alone and mixed, from photos of their swatch cards: one joint fit, one library.

A card's layout may name each patch's paint (`"pigment": "P1+P4", "coats": "1+2"`;
a glaze stack `"pigment": "P1/P4", "coats": "1/2"`: `diffwash.fit.photos._photo`). Cards that
together hold more than one pigment are
measured exactly as a single pigment's (`diffwash.fit.photos._swatch`: the same
calibration from the paper, the same robust patch means, clipped channels as
bounds), and every patch becomes a row of an RGB measurement table
(`diffwash.measurements.Measurements`): its pigments, the coats of each, its
ground and its linear colour. The grounds are the paper, at its layout
reflectance (what the calibration makes it read), and the black band where a
card has one, at its measured colour. The table is fitted by
`diffwash.fit.fit_mixtures`: every pigment as a smooth spectral K and S seen
through sRGB, mixed by Duncan's law with a fitted amount law per pigment, all
patches at once. The result is a `diffwash.library.Library` whose amounts are
coats (its amount law's reference is one coat), which `diffwash predict` reads.

A single-pigment card's fit (`fit_swatches`) weighs each patch by its own
noise and gives intervals; the joint fit minimises CIEDE2000 over the patches,
every patch alike, and keeps the RGB table fit's posterior
(`diffwash.fit.tables._mixfit._rgb_posterior`): its library predicts with 90%
regions (`de2000_90`), their model errors measured on the cards' own patches
(mixtures of pairs the cards never mixed: by leave-pairs-out refits).
"""

from __future__ import annotations

import os
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ... import mixing
from ..._errors import DiffwashError
from ...library import Library
from ...measurements import Measurements
from ..tables import MixModel, MixtureFit, fit_mixtures
from ._photo import GROUNDS, Calibration, _name_key, patch_paints
from ._swatch import PatchResult, _bounds, _default_name, _measure_all, _Photo, lab_sd
from .._kmfit import delta_e_displayed

__all__ = ["SwatchMixtureFit", "fit_swatch_mixtures", "CARD_MODEL", "CARD_PRIOR"]


@dataclass(frozen=True)
class SwatchMixtureFit:
    """Pigments fitted jointly to swatch photos of them alone and mixed (`fit_swatch_mixtures`).

    **Fields:**

    - `library`: the fitted `diffwash.library.Library` (amounts in coats; grounds `paper` and, where a
      card has the band, `black`), its `fit` holding the record below.
    - `mixture`: the `MixtureFit` of `measurements` (its `library` is `library`).
    - `measurements`: the patches as an RGB `diffwash.measurements.Measurements` (linear colours, one row
      per patch in the layouts' order, photo by photo).
    - `patches`: a `PatchResult` per patch: observed and fitted colour, CIEDE2000.
    - `paper`, `black`: the grounds' linear reflectance (the layouts' paper; the measured black band, or None).
    - `calibrations`: each photo's `Calibration`.
    - `converged`, `iterations`: how the solver ended.
    """

    library: Library
    mixture: MixtureFit
    measurements: Measurements
    patches: list[PatchResult]
    paper: np.ndarray
    black: np.ndarray | None
    calibrations: list[Calibration]
    converged: bool
    iterations: int

    @property
    def names(self) -> tuple[str, ...]:
        """The pigments, in the order first met."""
        return self.library.names

    @property
    def mean_delta_e(self) -> float:
        """Mean CIEDE2000 over the patches."""
        return float(np.mean([p.delta_e for p in self.patches]))

    def save(self, path: str | os.PathLike) -> None:
        """Write the library (with the fit's record under `"fit"`) as JSON, atomically."""
        self.library.save(path)


def _table(measured: list[_Photo], paints: list, paper: np.ndarray, black: np.ndarray | None) -> Measurements:
    """Every patch of every photo as a row of an RGB measurement table (linear colours)."""
    pigments, amounts, ground, values, lo, hi, layers = [], [], [], [], [], [], []
    for ph, rows in zip(measured, paints):
        for p, st, (names, coats) in zip(ph.layout.patches, ph.patches, rows):
            bound_lo, bound_hi, _ = _bounds(st)
            layers.append(p.layers or (len(names),))
            pigments.append(names)
            amounts.append(coats)
            ground.append(p.ground)
            values.append(st.rgb)
            lo.append(bound_lo)
            hi.append(bound_hi)
    grounds = {"paper": paper, **({"black": black} if black is not None else {})}
    return Measurements(pigments=tuple(pigments), amounts=tuple(amounts), ground=np.asarray(ground),
                        values=np.asarray(values, np.float64), lo=np.asarray(lo, bool), hi=np.asarray(hi, bool),
                        grounds=grounds, path=measured[0].layout.path,
                        layers=tuple(layers) if any(len(k) > 1 for k in layers) else None)  # fmt: skip


def _per_coat(fit: MixtureFit, scale: float) -> MixtureFit:
    """The fit of amounts `scale` times the coats, as a library whose amounts are coats (reference: one coat).

    `AmountLaw` gives thickness `(a / a0)^gamma`: amounts `scale * c` with reference `a0` are coats `c` with
    reference `a0 / scale` (1 when `scale = a0`), so every prediction is the same.
    """
    p = fit.library.palette
    law = mixing.AmountLaw(gamma=p.law.gamma, reference=p.law.reference / scale)
    palette = mixing.Palette(K=p.K, S=p.S, law=law, weights=p.weights, names=p.names, wavelengths=p.wavelengths,
                             pairs=p.pairs)  # fmt: skip
    return replace(fit, library=replace(fit.library, palette=palette))


#: The factor on the RGB tables' priors (`MixModel.prior`) for a card: a card measures each paint over paper and
#: over black, which tells K from S (Curtis et al. 1997), in a few dozen patches, which the tables' priors (chosen
#: for pairs never seen mixed, on a table of 13 paints and 1,700 rows) would outweigh. Measured on
#: tests/test_swatch_mixtures.py's card (float64): mean CIEDE2000 to the card 0.54 (max 2.3) with this factor,
#: 1.71 (max 6.2) with 1; the mixture held out of the card 0.9 and 1.8 (over paper, over black) against 3.5.
CARD_PRIOR = 0.1
#: A card's fit keeps Duncan's law for its mixtures (`MixModel.pairs` off): a card holds a patch or two per pair, and
#: pair terms (fitted and measured on tables of 12-20 rows per pair) have not been measured on cards.
CARD_MODEL = MixModel(prior=CARD_PRIOR, pairs=False)


def measurement_error(measured: list[_Photo]) -> float:
    """How far a patch's reading may be from its true colour: the median over the patches of their noise and
    calibration floor (`diffwash.fit.photos._photo.patch_stats`'s covariance), in CIELAB units per axis."""
    return float(np.median([lab_sd(st.rgb, st.cov) for m in measured for st in m.patches] or [0.0]))


def _with_measurement_error(lib: Library, measured: list[_Photo]) -> Library:
    """The library with its model errors widened by the photos' measurement error (in quadrature).

    The fit reproduces its patches as the photo read them. A card of one patch per paint reproduces them
    exactly, and its model error comes out near 0, whatever the reading's own error (a camera curve assumed, a
    camera model's leave-one-out error, noise). A prediction is of the true colour, so both count."""
    post = lib.posterior
    m = measurement_error(measured)
    if post is None or m <= 0:
        return lib
    me = {k: float(np.hypot(v, m)) for k, v in post.model_error.items()}
    record = {**(post.record or {}), "measurement": {"per_axis": round(m, 4), "from": "the median patch's noise "
              "and calibration floor, added in quadrature to each kind's model error"}}  # fmt: skip
    fit = {**lib.fit, "uncertainty": record} if lib.fit and "uncertainty" in lib.fit else lib.fit
    return replace(lib, posterior=replace(post, model_error=me, record=record), fit=fit)


def fit_swatch_mixtures(
    photo: Any,
    layout: Any,
    *,
    name: str | None = None,
    model: MixModel = CARD_MODEL,
    max_steps: int = 400,
    rtol: float | None = None,
    checker: bool = False,
    posterior: bool = True,
    tone_curve: str = "auto",
) -> SwatchMixtureFit:
    """Fit every pigment of swatch cards that hold several, alone and mixed, jointly (module docstring).

    **Arguments:**

    - `photo`: a photo (path of a PNG, 8 or 16 bit, or JPEG; or an (H, W, 3) array of display sRGB in
      [0, 1]), or a list of them.
    - `layout`: its layout (path, parsed JSON, or `Layout`), or a list matching `photo`. Its patches name
      their paint (`"pigment": "P1+P4", "coats": "1+2"`); a patch that names none is of the card's pigment
      (`name`, else the layout's `name`, else the photo's file name).
    - `name`: the pigment of patches that name none.
    - `model`: the `MixModel` (default `CARD_MODEL`: Duncan's law with a fitted amount law per pigment, priors
      `CARD_PRIOR` times the RGB tables', no pair terms).
    - `max_steps`: Levenberg-Marquardt steps at most.
    - `rtol`: the solver's tolerance (default: `fit_mixtures`'s for an RGB table).
    - `checker`: calibrate each photo from an X-Rite ColorChecker Classic found in it (as `fit_swatches`).
    - `posterior`: keep the fit's posterior and model errors, so that the library's predictions carry 90%
      regions (`de2000_90`; `fit_mixtures`'s `posterior`). Off, the fit skips the posterior's folds (on a
      card of 22 patches, 0.1 s instead of 0.6 s once compiled).
    - `tone_curve`: how a photo without references is read ("auto", "camera" or "srgb"; as `fit_swatches`).

    **Returns:**

    A `SwatchMixtureFit`: the library (amounts in coats) and each patch's observed and fitted colour. Bad
    input raises `DiffwashError` naming the file and the field, as `fit_swatches`.
    """
    photos, _, measured = _measure_all(photo, layout, checker, tone_curve)
    paints = patch_paints([m.layout for m in measured], name=name, default=_default_name(photos[0]))
    for m, rows in zip(measured, paints):
        for i, (names, _) in enumerate(rows):
            if any(_name_key(n) in GROUNDS for n in names):
                raise DiffwashError("the card's pigment is named like a ground (paper, black): name it in the "
                                    "layout's 'name' or the patch's 'pigment'", file=m.layout.path,
                                    field=f"patches[{i}]")  # fmt: skip
    paper = np.mean([m.layout.paper_reflectance for m in measured], axis=0)
    blacks = [m.black.rgb for m in measured if m.black is not None]
    black = np.mean(blacks, axis=0) if blacks else None
    table = _table(measured, paints, paper, black)
    if not np.all(np.isfinite(table.values)):
        raise DiffwashError("a patch's colour is not finite", file=table.path)
    # fit_mixtures' amount law has its reference at mixing.REFERENCE_AMOUNT: fitted at one coat = that amount
    # (K and S start and are regularised per coat), then stated in coats.
    scale = mixing.REFERENCE_AMOUNT
    scaled = replace(table, amounts=tuple(tuple(scale * a for a in row) for row in table.amounts))
    fit = _per_coat(fit_mixtures(scaled, model=model, max_steps=max_steps, rtol=rtol, posterior=posterior), scale)
    fit = replace(fit, library=_with_measurement_error(fit.library, measured))
    fitted = np.asarray(fit.library.predict(table).linear_srgb, np.float64)
    rgb, lo, hi = table.values, table.lo, table.hi
    # As the camera would have recorded the fit: a clipped channel shows its bound when the fit lies beyond it.
    des = delta_e_displayed(np.where(lo, np.maximum(fitted, rgb), np.where(hi, np.minimum(fitted, rgb), fitted)), rgb)
    patches, i = [], 0
    for k, (m, rows) in enumerate(zip(measured, paints)):
        for p, st, (names, coats) in zip(m.layout.patches, m.patches, rows):
            patches.append(PatchResult(photo=k, box=p.box.tolist(), coats=float(sum(coats)), ground=p.ground,
                                       observed=rgb[i], fitted=fitted[i], delta_e=float(des[i]), weight=1.0,
                                       bound=[bool(a or b) for a, b in zip(lo[i], hi[i])], spread=st.spread,
                                       se=np.sqrt(np.diag(st.cov)), floor=[bool(f) for f in st.floor],
                                       pigments=names, amounts=coats))  # fmt: skip
            i += 1
    record = {**{k: v for k, v in (fit.library.fit or {}).items() if k not in ("table", "rows")},
              "source": "diffwash fit-swatch",
              "photos": [os.fspath(ph) if isinstance(ph, (str, os.PathLike)) else None for ph in photos],
              "layouts": [m.layout.path for m in measured],
              "paper": paper.tolist(), "black": None if black is None else black.tolist(),
              "mean_delta_e_2000": round(float(np.mean(des)), 4), "max_delta_e_2000": round(float(np.max(des)), 4),
              "calibration": [m.calibration.to_dict() for m in measured],
              "patches": [q.to_dict() for q in patches]}  # fmt: skip
    lib = replace(fit.library, fit=record)
    fit = replace(fit, library=lib)
    return SwatchMixtureFit(library=lib, mixture=fit, measurements=table, patches=patches, paper=paper, black=black,
                            calibrations=[m.calibration for m in measured], converged=fit.converged,
                            iterations=fit.iterations)  # fmt: skip
