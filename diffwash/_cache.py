"""Small caches keyed by array identity or content, without a device-to-host copy.

JAX arrays are immutable, so one that is the same object has the same values:
it is keyed by identity (the cache holds a reference, so the identity is not
reused while the entry lives). NumPy arrays and Python numbers are mutable or
host values: they are keyed by their bytes (no device transfer is involved).
Within one call that looks up several caches with the same arrays (a render:
its visibility, then the look's light pass), `same_arrays()` hashes each array
once.
"""

from __future__ import annotations

import collections
import contextlib
import gc
import os
import threading
import zlib
from collections.abc import Callable, Hashable, Iterator
from typing import Any

import jax
import numpy as np

__all__ = ["leaf_key", "tree_key", "same_arrays", "LRU", "enable_compilation_cache", "relieve_compiled_programs"]

#: The share of the system's memory maps a process may hold before `relieve_compiled_programs` drops JAX's
#: compiled programs.
MAP_SHARE = 0.5


def relieve_compiled_programs(share: float = MAP_SHARE) -> bool:
    """Drop JAX's in-memory compiled programs when this process holds more than `share` of the memory maps
    the system allows (Linux's `vm.max_map_count`, 65530 by default). Returns whether it did.

    XLA's CPU backend maps each compiled program's code and data in small regions of their own, which live as
    long as the program stays cached: a mixture fit with its posterior holds hundreds. A process that fits
    many tables (a notebook, a benchmark, a test worker) reaches the limit, and the next compilation cannot
    map its code: the process dies inside XLA's compiler. The fits call this before they compile. Dropped
    programs are compiled again when next used (from the persistent cache, `enable_compilation_cache`, where
    it is on).
    """
    try:
        with open("/proc/self/maps", "rb") as f:
            held = sum(chunk.count(b"\n") for chunk in iter(lambda: f.read(1 << 20), b""))
        with open("/proc/sys/vm/max_map_count") as f:
            limit = int(f.read())
    except (OSError, ValueError):
        return False
    if held <= share * limit:
        return False
    jax.clear_caches()
    gc.collect()
    return True


_local = threading.local()


def enable_compilation_cache() -> None:
    """Keep JAX's compiled programs on disk so that later runs start fast (what every `diffwash` command does).

    The folder is `$DIFFWASH_CACHE_DIR` or `~/.cache/diffwash/jax`; `DIFFWASH_CACHE_DIR=off` turns the
    cache off. A folder that cannot be made leaves JAX as it is.
    """
    folder = os.environ.get("DIFFWASH_CACHE_DIR", os.path.join(os.path.expanduser("~"), ".cache", "diffwash", "jax"))
    if folder.lower() in ("", "off", "0", "none"):
        return
    try:
        os.makedirs(folder, exist_ok=True)
    except OSError:
        return
    jax.config.update("jax_compilation_cache_dir", folder)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)


@contextlib.contextmanager
def same_arrays() -> Iterator[None]:
    """Within the block, a NumPy array's key is computed once per array object (the caller promises not to change
    the arrays meanwhile): the block holds each array it keyed, so no identity is reused in it."""
    outer = getattr(_local, "memo", None)
    _local.memo = {} if outer is None else outer
    try:
        yield
    finally:
        _local.memo = outer


def leaf_key(x: Any) -> Hashable:
    """A hashable key for one array leaf: its identity if a JAX array, else its shape, dtype and bytes."""
    if isinstance(x, jax.Array):
        return ("jax", id(x))
    memo = getattr(_local, "memo", None)
    if memo is not None and isinstance(x, np.ndarray) and id(x) in memo:
        return memo[id(x)][1]
    a = np.ascontiguousarray(np.asarray(x))
    key = ("np", a.shape, a.dtype.str, zlib.crc32(a.view(np.uint8).reshape(-1)))
    if memo is not None and isinstance(x, np.ndarray):
        memo[id(x)] = (x, key)
    return key


def tree_key(*trees: Any) -> tuple[tuple[Hashable, ...], list[Any]]:
    """`(key, leaves)` of pytrees: the key of every leaf, and the leaves themselves (to hold them alive)."""
    leaves = jax.tree_util.tree_leaves(trees)
    return tuple(leaf_key(x) for x in leaves), leaves


class LRU:
    """A small least-recently-used cache of values computed from pytrees of arrays."""

    def __init__(self, size: int):
        self.size = size
        self._items: collections.OrderedDict[Hashable, tuple[Any, list[Any]]] = collections.OrderedDict()

    def get(self, key_trees: tuple, compute: Callable[[], Any], *, extra: Hashable = ()) -> Any:
        """The value for `key_trees` (and the hashable `extra`), computed by `compute()` if absent."""
        key, leaves = tree_key(*key_trees)
        key = (key, extra)
        hit = self._items.get(key)
        if hit is None:
            hit = (compute(), leaves)
        self._items[key] = hit
        self._items.move_to_end(key)
        while len(self._items) > self.size:
            self._items.popitem(last=False)
        return hit[0]

    def put(self, key_trees: tuple, value: Any, *, extra: Hashable = ()) -> None:
        key, leaves = tree_key(*key_trees)
        self._items[(key, extra)] = (value, leaves)
        self._items.move_to_end((key, extra))
        while len(self._items) > self.size:
            self._items.popitem(last=False)

    def clear(self) -> None:
        self._items.clear()

    def __len__(self) -> int:
        return len(self._items)

    def values(self) -> list[Any]:
        """The cached values, least recently used first."""
        return [v for v, _ in self._items.values()]
