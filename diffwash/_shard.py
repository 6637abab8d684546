"""Batches over devices: a leading batch axis split across all local devices with `jax.sharding`.

A one-axis device mesh named `"batch"`; the batch is padded to a multiple of the device count by
repeating its last element (the padding's results are dropped by the caller with `unpad`). With one
device nothing moves and nothing is padded, so the same code serves a laptop, a multi-GPU host and,
after `jax.distributed.initialize`, several hosts (docs/scaling.md).
"""

from __future__ import annotations

from typing import TypeVar

import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

T = TypeVar("T")

__all__ = ["batch_devices", "shard_leading", "unpad"]


def batch_devices() -> list:
    """The devices a batch is spread over: all of them (every host's, under `jax.distributed`)."""
    return list(jax.devices())


def shard_leading(tree: T, size: int) -> tuple[T, int]:
    """Pad every array leaf's leading axis (of length `size`) to a multiple of the device count and
    place it split over the devices; returns the tree and the padded size.

    With one device the tree is returned as it is.
    """
    devices = batch_devices()
    n = len(devices)
    if n == 1:
        return tree, size
    padded = -(-size // n) * n

    def pad(a):
        a = jnp.asarray(a)
        if padded > size:
            a = jnp.concatenate([a, jnp.repeat(a[-1:], padded - size, axis=0)], axis=0)
        return a

    mesh = Mesh(np.asarray(devices), ("batch",))
    sharding = NamedSharding(mesh, PartitionSpec("batch"))
    return jax.device_put(jax.tree.map(pad, tree), sharding), padded


def unpad(tree: T, size: int) -> T:
    """Drop the padding `shard_leading` added (the leading axis cut back to `size`)."""
    return jax.tree.map(lambda a: a[:size], tree)
