"""diffwash: a differentiable watercolour renderer.

Data flows one way: scene file -> `Scene` (mesh, camera, light, pigments,
constants) -> visibility (`ops.rasterize`) -> barycentrics and attributes
(`ops.interpolate`) -> wash and unlit thicknesses (`shading`) -> Kubelka-Munk
glazes (`km`) -> colour -> image (`ops.antialias`). Fitting wraps that
pipeline; baking evaluates its tail on a grid of thicknesses; exporting writes
the tail as a shader, generated from the same functions.

The public API is what `__init__.pyi` names; each name loads its module when first used.
"""

import lazy_loader as _lazy

from ._jaxlib import warn_if_deadlocking as _warn_if_deadlocking
from ._version import __version__ as __version__

# jaxlib 0.10 can hang for ever on the CPU (diffwash/_jaxlib.py): pyproject.toml excludes it, and an
# environment that has it anyway is warned once.
_warn_if_deadlocking()

# The names of `__init__.pyi`, each imported from its module when first used (scientific-python SPEC 1),
# so `import diffwash` and `diffwash --help` load neither JAX nor colour-science.
__getattr__, __dir__, __all__ = _lazy.attach_stub(__name__, __file__)
