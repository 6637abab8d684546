"""Target images: scene parameters fitted so that the rendering matches them.

The image family of `diffwash.fit` (docs/fitting.md, "Target images"):

- `fit_image(targets, scenes, fit=...)`: named scene parameters (`FITTABLE`: K, S, gain, bias, thickness
  constants, shininess, light, paper, a library mixture's proportions and amount, the watercolour look's
  `watercolour.<effect>.<key>`) from one or more target images, with an optimistix solver (`SOLVERS`)
  on linear RGB or CIELAB residuals (`IMAGE_LOSSES`); an `ImageFit`.
- `parse_fit_list` (the `--fit` list), `load_cameras` (one scene per camera of a cameras file).

Inside: `_image`. It steps the optimistix solver through the solvers' public `init`/`step`/`terminate`
methods rather than `optimistix.least_squares`; docs/fitting.md says why.
"""

import lazy_loader as _lazy

# The names of `__init__.pyi`, each imported from its module when first used.
__getattr__, __dir__, __all__ = _lazy.attach_stub(__name__, __file__)
