"""The jaxlib releases whose CPU backend can hang for ever, and a warning when one is installed.

jaxlib 0.10 runs the batch of a batched LAPACK kernel (Cholesky, triangular solves, LU, eigh) on XLA's
intra-op thread pool, from inside a task of that same pool, and waits for it (`jax::ParallelBatchMap`).
When as many such kernels run at once as the pool has workers (two, on a 2-core machine), every worker waits
for a batch that no free worker is left to run, and the process hangs with every thread idle. diffwash's
table fits solve many small systems per band under `vmap`: a fit of a generated 80-row table hung in 2 of 4
runs on 2 cores, and a program of eight batched triangular solves hangs every time
(`tests/test_structure.py::test_concurrent_batched_solves_finish`). `--xla_cpu_multi_thread_eigen=false`
does not help: that pool is not the one the kernels use. jaxlib 0.9 runs each batch in place, and the
published reports (PyAutoLabs/PyAutoFit#1530 for FFT; PyAutoHeart's diagnostics for Cholesky) say 0.11.2
builds the parallel path out. `pyproject.toml` excludes the releases between; an environment that has one
anyway (installed with `--no-deps`, or pinned by another package) gets one warning at `import diffwash`.
"""

from __future__ import annotations

import importlib.util
import os
import re
import warnings

__all__ = ["DEADLOCKING", "deadlocks", "installed_version", "warn_if_deadlocking"]

#: The jaxlib releases `[first, end)` whose CPU LAPACK kernels fan their batch out onto the pool they run on.
DEADLOCKING = ((0, 10, 0), (0, 11, 2))


def deadlocks(version: str) -> bool:
    """Whether a jaxlib version string (`"0.10.2"`, `"0.10.1.dev20260301"`) is one of `DEADLOCKING`."""
    parts = [int(x) for x in re.findall(r"\d+", version)[:3]]
    release = tuple(parts + [0] * (3 - len(parts)))
    return DEADLOCKING[0] <= release < DEADLOCKING[1]


def installed_version() -> str | None:
    """The installed jaxlib's version, without importing it: read from its `version.py` (every jaxlib release has
    one; about 1 ms, where importing `importlib.metadata` to ask would make `import diffwash` six times slower).
    None where jaxlib is not installed or that file does not say."""
    spec = importlib.util.find_spec("jaxlib")
    if spec is None or spec.origin is None:
        return None
    try:
        with open(os.path.join(os.path.dirname(spec.origin), "version.py"), encoding="utf-8") as f:
            found = re.search(r'^_version\s*=\s*"([^"]+)"', f.read(), re.M)
    except OSError:
        found = None
    return found.group(1) if found else None


def warn_if_deadlocking() -> None:
    """One `RuntimeWarning` when the installed jaxlib is one of `DEADLOCKING` (JAX is not imported)."""
    version = installed_version()
    if version is not None and deadlocks(version):
        warnings.warn(f"jaxlib {version} can hang for ever on the CPU when batched linear solves run at once "
                      "(diffwash's table fits do); install diffwash's supported jaxlib: "
                      "pip install 'jax<0.10' 'jaxlib<0.10'", RuntimeWarning, stacklevel=3)
