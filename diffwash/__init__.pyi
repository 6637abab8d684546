"""The public API of `diffwash`, for type checkers and for `lazy_loader.attach_stub` (`__init__.py`).

Each name here is imported from its module on first use.
"""

from . import colorimetry as colorimetry
from . import demo as demo
from . import fit as fit
from . import io as io
from . import km as km
from . import lut as lut
from . import ops as ops
from . import pigments as pigments
from . import preview as preview
from . import shading as shading
from . import shaders as shaders
from . import swatchcard as swatchcard
from . import swatches as swatches
from ._cache import enable_compilation_cache as enable_compilation_cache
from ._camera import Camera as Camera
from ._errors import DiffwashError as DiffwashError
from ._errors import FailureError as FailureError
from ._export import export as export
from ._glsl import functions_source as functions_source
from ._glsl import shader_sources as shader_sources
from ._glsl import uniform_values as uniform_values
from ._mixture import Mixture as Mixture
from ._choices import SHADING_MODES as SHADING_MODES
from ._choices import EXPORT_TARGETS as EXPORT_TARGETS
from ._choices import BLENDER_LEAVES_OUT as BLENDER_LEAVES_OUT
from ._choices import LUT_FORMATS as LUT_FORMATS
from ._render import Visibility as Visibility
from ._render import clear_visibility_cache as clear_visibility_cache
from ._render import rasterize as rasterize
from ._render import render as render
from ._render import render_rgba as render_rgba
from ._render import render_strips as render_strips
from ._render import render_thicknesses as render_thicknesses
from ._render import render_views as render_views
from ._render import visibility as visibility
from ._scene import Mesh as Mesh
from ._scene import Scene as Scene
from ._scene import load_mesh as load_mesh
from ._scene import load_scene as load_scene
from ._scene import referenced_files as referenced_files
from ._scene import save_scene as save_scene
from ._version import __version__ as __version__
from ._widget import widget as widget
from .pigments import Pigment as Pigment
from .shading import Params as Params
from . import library as library
from . import measurements as measurements
from . import mixing as mixing
from . import spectral as spectral
