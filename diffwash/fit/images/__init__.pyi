"""The public API of `diffwash.fit.images`, for type checkers and for `lazy_loader.attach_stub` (`__init__.py`)."""

from ._image import FITTABLE as FITTABLE
from ._image import IMAGE_LOSSES as IMAGE_LOSSES
from ._image import SOLVERS as SOLVERS
from ._image import ImageFit as ImageFit
from ._image import fit_image as fit_image
from ._image import load_cameras as load_cameras
from ._image import parse_fit_list as parse_fit_list
