"""Heavy dependencies imported when first used: `colour = lazy("colour")` at the top of a module.

`diffwash` loads its own submodules on first use with `lazy_loader.attach_stub` (scientific-python
SPEC 1). Third-party modules get this smaller proxy rather than `lazy_loader.load`, whose
`importlib.util.LazyLoader` registers the module in `sys.modules` before it is loaded: colour-science
replaces its own `sys.modules` entry while importing, which that loader refuses ("substituted in
sys.modules during a lazy load"), and libraries that ask `"jax" in sys.modules` (array-api-compat,
inside SciPy) would then import JAX. The proxy imports the module the ordinary way at its first
attribute access and forwards every read and write after that; until then the module is not in
`sys.modules`.
"""

from __future__ import annotations

import importlib
from types import ModuleType
from typing import Any

__all__ = ["lazy"]


class _LazyModule:
    """A stand-in for the module `name`, imported at the first attribute access."""

    __slots__ = ("_lazy_name", "_lazy_module")

    def __init__(self, name: str) -> None:
        self._lazy_name = name
        self._lazy_module: ModuleType | None = None

    def _load(self) -> ModuleType:
        if self._lazy_module is None:
            self._lazy_module = importlib.import_module(self._lazy_name)
        return self._lazy_module

    def __getattr__(self, attr: str) -> Any:  # only for names the proxy itself lacks
        return getattr(self._load(), attr)

    def __setattr__(self, attr: str, value: Any) -> None:  # `Image.MAX_IMAGE_PIXELS = None` sets the module's
        if attr in _LazyModule.__slots__:
            object.__setattr__(self, attr, value)
        else:
            setattr(self._load(), attr, value)

    def __delattr__(self, attr: str) -> None:
        delattr(self._load(), attr)

    def __dir__(self) -> list[str]:
        return dir(self._load())

    def __repr__(self) -> str:
        state = "loaded" if self._lazy_module is not None else "not yet imported"
        return f"<lazy module {self._lazy_name!r} ({state})>"


def lazy(name: str) -> Any:
    """The module `name`, imported when an attribute of it is first read (typed `Any`: a stand-in)."""
    return _LazyModule(name)
