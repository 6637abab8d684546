"""The public API of `diffwash.fit.tables`, for type checkers and for `lazy_loader.attach_stub` (`__init__.py`)."""

from ._table import MeasurementTable as MeasurementTable
from ._table import TableFit as TableFit
from ._table import fit_table as fit_table
from ._table import read_ntu_wpsm as read_ntu_wpsm
from ._table import read_table as read_table
from ._mixfit import MixModel as MixModel
from ._mixfit import MixtureFit as MixtureFit
from ._mixfit import fit_mixtures as fit_mixtures
from ._mixfit import pair_folds as pair_folds
from ._mixfit import score_library as score_library
from ._posterior import uncertainty_lines as uncertainty_lines
from ._suggest import Pick as Pick
from ._suggest import Suggestions as Suggestions
from ._suggest import suggest as suggest
from ._suggest import write_suggestions as write_suggestions
