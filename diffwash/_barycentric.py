r"""Perspective-correct barycentrics of pixel centres, recomputed differentiably.

Given which triangle each pixel sees (`Visibility`), the barycentric
coordinates of the pixel centre in that triangle are a smooth function of the
triangle's clip-space vertices, so gradients flow to vertex positions and to
the camera (as in nvdiffrast, where `rasterize` outputs are differentiable in
the same way).

With the clip coordinates `v_i = (x_i, y_i, w_i)` of the three vertices (z is
not needed) and the pixel centre `p = (x, y, 1)` in normalised device
coordinates, the homogeneous edge functions are `e_i = det[p, v_j, v_k]` for
`(i, j, k)` cyclic, and

$$ b_i = e_i / (e_0 + e_1 + e_2) $$

are the perspective-correct barycentrics (Olano and Greer 1997): `sum_i b_i v_i`
is the point of the triangle's plane that projects to `p`. They are evaluated
with the origin moved to the pixel (`v_i' = v_i - w_i p`), which keeps float32
precise for small triangles far from the screen centre. The sign of
`det[v_0, v_1, v_2] = sum_i e_i w_i` tells the facing: positive for a
counter-clockwise (front-facing) triangle.

**References:**

- M. Olano and T. Greer, "Triangle Scan Conversion using 2D Homogeneous
  Coordinates", Graphics Hardware 1997.
"""

from __future__ import annotations

import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int

__all__ = ["pixel_ndc", "edge_functions", "barycentrics"]


def pixel_ndc(pixels: Int[Array, " P"], width: int, height: int, dtype=jnp.float32) -> tuple[Array, Array]:
    """Normalised device coordinates of the centres of row-major pixel indices (row 0 at the top)."""
    col = pixels % width
    row = pixels // width
    x = (2 * col.astype(dtype) + 1) / width - 1
    y = 1 - (2 * row.astype(dtype) + 1) / height
    return x, y


def edge_functions(v: Float[Array, "P 3 4"], x: Float[Array, " P"], y: Float[Array, " P"]) -> Float[Array, "P 3"]:
    """Homogeneous edge functions `e_i = det[p, v_j, v_k]` of triangles `v` (clip space) at `p = (x, y, 1)`.

    Edge `i` is the one opposite vertex `i`. Evaluated with the origin moved to
    `p` for precision.
    """
    w = v[..., 3]
    xs = v[..., 0] - x[:, None] * w
    ys = v[..., 1] - y[:, None] * w
    j = jnp.array([1, 2, 0])
    k = jnp.array([2, 0, 1])
    return xs[:, j] * ys[:, k] - xs[:, k] * ys[:, j]


def barycentrics(
    clip: Float[Array, "V 4"],
    faces: Int[Array, "F 3"],
    tri: Int[Array, " P"],
    pixels: Int[Array, " P"],
    width: int,
    height: int,
) -> tuple[Float[Array, "P 3"], Bool[Array, " P"]]:
    """Perspective-correct barycentrics of pixel centres in the triangles they see.

    **Arguments:**

    - `clip`: clip-space vertex positions (OpenGL convention).
    - `faces`: the mesh's triangles (vertex indices).
    - `tri`: the triangle seen at each pixel.
    - `pixels`: row-major pixel indices; entries `>= width * height` are padding
      and get `(1/3, 1/3, 1/3)`.
    - `width`, `height`: image size.

    **Returns:**

    `(bary, front)`: (P, 3) barycentrics, differentiable with respect to `clip`,
    and whether each triangle faces the camera.
    """
    valid = pixels < width * height
    x, y = pixel_ndc(jnp.where(valid, pixels, 0), width, height, clip.dtype)
    v = clip[faces[tri]]  # (P, 3, 4)
    w = v[..., 3]
    e = edge_functions(v, x, y)
    total = jnp.sum(e, axis=1, keepdims=True)
    det = jnp.sum(e * w, axis=1)
    ok = valid[:, None] & (total != 0)
    bary = jnp.where(ok, e / jnp.where(ok, total, 1), 1 / 3)
    return bary, det > 0
