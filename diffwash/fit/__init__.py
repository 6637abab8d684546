"""Fitting: pigments from swatch photos and measurement tables, shading from target images."""

from ._kmfit import PLAIN as PLAIN
from ._kmfit import FitModel as FitModel
from ._table import MeasurementTable as MeasurementTable
from ._table import TableFit as TableFit
from ._table import fit_table as fit_table
from ._table import read_ntu_wpsm as read_ntu_wpsm
from ._table import read_table as read_table
from ._swatch import SWATCH_MODEL as SWATCH_MODEL
from ._swatch import SwatchFit as SwatchFit
from ._swatch import PatchResult as PatchResult
from ._swatch import fit_swatches as fit_swatches
from ._photo import Layout as Layout
from ._photo import read_layout as read_layout
from ._photo import parse_layout as parse_layout
from ._image import FITTABLE as FITTABLE
from ._image import ImageFit as ImageFit
from ._image import fit_image as fit_image
