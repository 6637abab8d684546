"""Fitting: pigments from swatch photos and measurement tables, shading parameters from target images.

Three fits, each a thin layer of data handling over optimistix least squares:

- `fit_swatches(photo, layout)`: one pigment's K and S (per coat) from photos of its swatch card
  (`diffwash.swatchcard` makes synthetic ones); `diffwash fit-swatch PHOTO --layout LAYOUT.json`. Each
  patch is weighed by its own noise and the calibration's uncertainty is carried along, so the result
  has calibrated intervals (`SwatchFit.intervals`, `SwatchFit.predict_interval`) and says which channels
  the photo only bounds (the camera's noise floor, clipping).
- `fit_swatch_mixtures(photos, layouts)`: several pigments from cards whose layouts name each patch's
  paint, alone or mixed (`"pigment": "P1+P4", "coats": "1+2"`), fitted jointly by `fit_mixtures` into a
  mixable library; `diffwash fit-swatch` takes this path when the layouts hold more than one pigment
  (`swatch_pigments`).
- `fit_table(csv)`: every pigment of a table of measured colours in one call (`jax.vmap`, or a loop);
  `diffwash fit-swatch --table MEASUREMENTS.csv`.
- `fit_image(targets, scenes, fit=...)`: named scene parameters (K, S, gain, bias, thickness
  constants, shininess, light, paper, the watercolour look's `watercolour.<effect>.<key>`) from
  target images; `diffwash fit-image`.

Each result has a one-page report figure: `save_swatch_report`, `save_table_report`, `save_mixture_report`,
`save_image_report`
(what the CLI's `--report` writes).

Formats, models, gauges and what each fit can identify: docs/fitting.md.

Each family is a subpackage with its own public face, and every name above is also here:
`diffwash.fit.photos` (swatch-card photos), `diffwash.fit.tables` (measurement tables, mixtures,
`suggest`) and `diffwash.fit.images` (target images). What the families share stays in this package's
private modules: `_kmfit` (the single-pigment Kubelka-Munk fit, `FitModel`, `PLAIN`), `_bandlsq` (the band
Levenberg-Marquardt) and `_report` (the report figures). A family imports another's public face only.
"""

import lazy_loader as _lazy

# The names of `__init__.pyi`, each imported from its module when first used.
__getattr__, __dir__, __all__ = _lazy.attach_stub(__name__, __file__)
