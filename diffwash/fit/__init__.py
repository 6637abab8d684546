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
"""

from ._image import FITTABLE as FITTABLE
from ._image import LOSSES as IMAGE_LOSSES
from ._image import SOLVERS as SOLVERS
from ._image import ImageFit as ImageFit
from ._image import fit_image as fit_image
from ._image import load_cameras as load_cameras
from ._image import parse_fit_list as parse_fit_list
from ._kmfit import PLAIN as PLAIN
from ._kmfit import FitModel as FitModel
from ._photo import Layout as Layout
from ._photo import parse_layout as parse_layout
from ._photo import read_layout as read_layout
from ._photo import swatch_pigments as swatch_pigments
from ._report import save_image_report as save_image_report
from ._report import save_mixture_report as save_mixture_report
from ._report import save_swatch_report as save_swatch_report
from ._report import save_table_report as save_table_report
from ._swatch import SWATCH_MODEL as SWATCH_MODEL
from ._swatch import PatchResult as PatchResult
from ._swatch import SwatchFit as SwatchFit
from ._swatch import fit_swatches as fit_swatches
from ._swatchmix import CARD_PRIOR as CARD_PRIOR
from ._swatchmix import SwatchMixtureFit as SwatchMixtureFit
from ._swatchmix import fit_swatch_mixtures as fit_swatch_mixtures
from ._table import MeasurementTable as MeasurementTable
from ._table import TableFit as TableFit
from ._table import fit_table as fit_table
from ._table import read_ntu_wpsm as read_ntu_wpsm
from ._table import read_table as read_table
from ._mixfit import MixModel as MixModel
from ._mixfit import MixtureFit as MixtureFit
from ._mixfit import fit_mixtures as fit_mixtures
from ._mixfit import pair_folds as pair_folds
from ._mixfit import score as score_library
