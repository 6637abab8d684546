"""The public API of `diffwash.fit`, for type checkers and for `lazy_loader.attach_stub` (`__init__.py`).

Each family's names come from its subpackage's public face (`photos`, `tables`, `images`); the model
and the reports, which the families share, from their own modules.
"""

from . import images as images
from . import photos as photos
from . import tables as tables
from ._kmfit import PLAIN as PLAIN
from ._kmfit import FitModel as FitModel
from ._report import save_image_report as save_image_report
from ._report import save_mixture_report as save_mixture_report
from ._report import save_swatch_report as save_swatch_report
from ._report import save_table_report as save_table_report
from .photos import Layout as Layout
from .photos import parse_layout as parse_layout
from .photos import read_layout as read_layout
from .photos import swatch_pigments as swatch_pigments
from .photos import SWATCH_MODEL as SWATCH_MODEL
from .photos import PatchResult as PatchResult
from .photos import SwatchFit as SwatchFit
from .photos import fit_swatches as fit_swatches
from .photos import CARD_MODEL as CARD_MODEL
from .photos import CARD_PRIOR as CARD_PRIOR
from .photos import SwatchMixtureFit as SwatchMixtureFit
from .photos import fit_swatch_mixtures as fit_swatch_mixtures
from .tables import MeasurementTable as MeasurementTable
from .tables import TableFit as TableFit
from .tables import fit_table as fit_table
from .tables import read_ntu_wpsm as read_ntu_wpsm
from .tables import read_table as read_table
from .tables import MixModel as MixModel
from .tables import MixtureFit as MixtureFit
from .tables import fit_mixtures as fit_mixtures
from .tables import pair_folds as pair_folds
from .tables import score_library as score_library
from .tables import uncertainty_lines as uncertainty_lines
from .tables import Pick as Pick
from .tables import Suggestions as Suggestions
from .tables import suggest as suggest
from .tables import write_suggestions as write_suggestions
from .images import FITTABLE as FITTABLE
from .images import IMAGE_LOSSES as IMAGE_LOSSES
from .images import SOLVERS as SOLVERS
from .images import ImageFit as ImageFit
from .images import fit_image as fit_image
from .images import load_cameras as load_cameras
from .images import parse_fit_list as parse_fit_list
