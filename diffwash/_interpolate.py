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
    attr = jnp.asarray(attr)
    f = faces[tri]
    out = 0
    for i in range(3):  # one gather per corner: far faster on CPU than a (P, 3, *C) gather
        b = bary[:, i].reshape((-1,) + (1,) * (attr.ndim - 1))
        out = out + attr[f[:, i]] * b
    return out
