"""Swatch-card photos: one pigment, or several alone and mixed, from photos of painted cards.

The photo family of `diffwash.fit` (docs/fitting.md, "Swatch photos"):

- `fit_swatches(photo, layout)`: one pigment's K and S from photos of its swatch card, each patch
  weighed by its own noise, with calibrated intervals (`SwatchFit`, its `PatchResult`s);
  `SWATCH_MODEL` is the fit's default `diffwash.fit.FitModel`.
- `fit_swatch_mixtures(photos, layouts)`: several pigments from cards whose layouts name each patch's
  paint, alone or mixed, measured as above and fitted jointly by `diffwash.fit.tables.fit_mixtures`
  (`SwatchMixtureFit`; `CARD_MODEL`, its default model, and `CARD_PRIOR`, the cards' population prior).
- Layouts: `read_layout`, `parse_layout` (a `Layout`), and `swatch_pigments`, the pigments a layout names.

Inside: `_photo` (layouts, linearisation, calibration from the paper or references, patch statistics),
`_camera` (camera models fitted to a colour checker, raw files), `_noise` (each patch's measurement noise),
`_noisefit` (the noise-weighted fit and its intervals), `_swatch` and `_swatchmix` (the two fits). The
Kubelka-Munk fit they share with measurement tables is `diffwash.fit._kmfit`.
"""

import lazy_loader as _lazy

# The names of `__init__.pyi`, each imported from its module when first used.
__getattr__, __dir__, __all__ = _lazy.attach_stub(__name__, __file__)
