"""The public API of `diffwash.fit.photos`, for type checkers and for `lazy_loader.attach_stub` (`__init__.py`)."""

from ._photo import Layout as Layout
from ._photo import parse_layout as parse_layout
from ._photo import read_layout as read_layout
from ._photo import swatch_pigments as swatch_pigments
from ._swatch import SWATCH_MODEL as SWATCH_MODEL
from ._swatch import PatchResult as PatchResult
from ._swatch import SwatchFit as SwatchFit
from ._swatch import fit_swatches as fit_swatches
from ._swatchmix import CARD_MODEL as CARD_MODEL
from ._swatchmix import CARD_PRIOR as CARD_PRIOR
from ._swatchmix import SwatchMixtureFit as SwatchMixtureFit
from ._swatchmix import fit_swatch_mixtures as fit_swatch_mixtures
