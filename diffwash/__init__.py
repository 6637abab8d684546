"""diffwash: a differentiable watercolour renderer.

Data flows one way: scene file -> `Scene` (mesh, camera, light, pigments,
constants) -> visibility (`ops.rasterize`) -> barycentrics and attributes
(`ops.interpolate`) -> wash and unlit thicknesses (`shading`) -> Kubelka-Munk
glazes (`km`) -> colour -> image (`ops.antialias`). Fitting wraps that
pipeline; baking evaluates its tail on a grid of thicknesses; exporting writes
the tail as a shader, generated from the same functions.

The public API is what `__init__.pyi` names; each name loads its module when first used.
"""

import os as _os

import lazy_loader as _lazy

from ._version import __version__ as __version__

# XLA's CPU runtime can deadlock (jaxlib 0.10): a batched LAPACK kernel (the triangular solves under a vmapped
# `jnp.linalg.solve`) running on one worker of the intra-op (Eigen) thread pool hands its batch to that same pool
# and waits; when every worker is such a kernel (both, on 2 cores), nobody runs the batch and the process hangs
# with every thread idle. It hung a fit of a generated 80-row table twice, beside another JAX process
# (benchmarks/README.md, "XLA's CPU deadlock"). Without that pool the kernels run their batches in place: the same
# fits and renders, no slower here. Set before JAX starts its CPU backend; an `XLA_FLAGS` that says otherwise is
# left as it is.
if "xla_cpu_multi_thread_eigen" not in _os.environ.get("XLA_FLAGS", ""):
    _os.environ["XLA_FLAGS"] = (_os.environ.get("XLA_FLAGS", "") + " --xla_cpu_multi_thread_eigen=false").strip()

# The names of `__init__.pyi`, each imported from its module when first used (scientific-python SPEC 1),
# so `import diffwash` and `diffwash --help` load neither JAX nor colour-science.
__getattr__, __dir__, __all__ = _lazy.attach_stub(__name__, __file__)
