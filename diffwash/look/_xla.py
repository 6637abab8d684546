"""What XLA's CPU compiler needs told: where to stop fusing.

XLA fuses an elementwise producer into every consumer and computes it again
there. For the look's texture reads that is ruinous: each of the hatching's
48 reads (or the shadow's 9, or the glaze's passes) would recompute the whole
chain of per-point work before it (the thickness model, the tone, the level
of detail), and the render ran several times slower than the sum of its
parts. `jax.lax.optimization_barrier` does not stop it on the CPU (the
barrier is expanded before fusion), so `apart` compiles the reads inside a
conditional, whose operands XLA must hold in memory.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, TypeVar

import jax
import jax.numpy as jnp

__all__ = ["apart"]

T = TypeVar("T")


def apart(fn: Callable[..., T], *args: Any) -> T:
    """`fn(*args)`, compiled apart from what computes `args`: `args` are computed once and read from memory.

    A `lax.cond` whose two branches both call `fn`; its predicate depends on
    the data (an element compared with itself), so XLA can neither fold it
    away nor, the branches not being trivial, turn it into a select of both.
    Differentiable like `fn`. Under `vmap` the conditional becomes a select
    and the boundary goes (the values are the same).
    """
    leaves = jax.tree.leaves(args)
    if not leaves:
        return fn(*args)
    first = jnp.ravel(leaves[0])[:1]
    pred = jnp.all(first == first)
    return jax.lax.cond(pred, lambda a: fn(*a), lambda a: fn(*a), args)
