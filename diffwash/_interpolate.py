"""Per-vertex attributes interpolated at pixels (nvdiffrast's `interpolate`)."""

from __future__ import annotations

import jax.numpy as jnp
from jaxtyping import Array, Float, Int

__all__ = ["interpolate"]


def interpolate(
    attr: Float[Array, "V *C"],
    faces: Int[Array, "F 3"],
    tri: Int[Array, " P"],
    bary: Float[Array, "P 3"],
) -> Float[Array, "P *C"]:
    """`sum_i bary_i attr[faces[tri, i]]`: the attribute at each pixel.

    With perspective-correct `bary` (`diffwash._barycentric.barycentrics`) this
    is perspective-correct interpolation. Differentiable with respect to `attr`
    and `bary`.
    """
    f = faces[tri]  # (P, 3)
    a = jnp.asarray(attr)[f]  # (P, 3, *C)
    b = bary.reshape(bary.shape + (1,) * (a.ndim - 2))
    return jnp.sum(a * b, axis=1)
