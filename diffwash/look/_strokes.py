r"""Brush strokes that follow the shape: line-integral convolution of solid noise along curvature directions.

The seed's future work asks for "a pre-computed brush-stroke texture layer",
computed once per mesh rather than per frame, that hints at the geometry. Lum
and Ma (2001) build each glaze's texture by line-integral convolution (LIC,
Cabral and Leedom 1993) of Perlin noise along the surface's principal
directions of curvature. Here, once per mesh:

1. `principal_directions`: at each vertex the shape operator is fitted by
   least squares to the change of the normal along the vertex's edges
   (`dn = S e` in the tangent plane; after Rusinkiewicz 2004's per-face
   fit, done per vertex), smoothed over the 1-ring, and its eigenvectors give
   the directions of largest and smallest curvature.
2. `stroke_field`: from each vertex a streamline is traced both ways along the
   chosen direction field on the surface (steps in the tangent plane of the
   nearest vertex), and solid value noise (`solid_noise`, cells of the
   stroke's width) is averaged along it with a Hann window: noise stretched
   along the strokes, as a brush leaves it. The result is standardised (zero
   mean, unit deviation).

The stroke value is a per-vertex attribute: the renderer interpolates it like
the normals (perspective-correct barycentrics, exactly the same in JAX and in
a vertex shader's `out float`), and it multiplies both glazes' thickness by
`exp(k_strokes * s)` (`stroke_factor`). Being attached to the vertices, the
strokes stay on the surface as it turns. See docs/watercolour.md for the
measured trade-off against a texture atlas or a triplanar projection.

**References:**

- E. B. Lum and K.-L. Ma, "Non-Photorealistic Rendering using Watercolor
  Inspired Textures and Illumination", Pacific Graphics 2001 (LIC of Perlin
  noise along principal directions for each layer's texture).
- B. Cabral and L. C. Leedom, "Imaging vector fields using line integral
  convolution", SIGGRAPH 1993.
- S. Rusinkiewicz, "Estimating curvatures and their derivatives on triangle
  meshes", 3DPVT 2004.
"""

from __future__ import annotations

import numpy as np
from jaxtyping import Array, ArrayLike, Float

from .._lazy import lazy
from .._xp import namespace, shader_function

spatial = lazy("scipy.spatial")
trimesh = lazy("trimesh")

__all__ = [
    "principal_directions",
    "solid_noise",
    "stroke_field",
    "stroke_factor",
    "mean_edge_length",
    "subdivide",
]

_HASH_SIZE = 1 << 20


def _edges(faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Both directions of each undirected edge: `(i, j)` arrays."""
    f = np.asarray(faces, np.int64)
    e = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    e = np.unique(np.sort(e, axis=1), axis=0)
    return np.concatenate([e[:, 0], e[:, 1]]), np.concatenate([e[:, 1], e[:, 0]])


def mean_edge_length(vertices: np.ndarray, faces: np.ndarray) -> float:
    """The mean length of the mesh's edges."""
    i, j = _edges(faces)
    return float(np.linalg.norm(np.asarray(vertices)[i] - np.asarray(vertices)[j], axis=1).mean())


def _frames(normals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A tangent basis `(t1, t2)` per unit normal."""
    axis = np.eye(3)[np.argmin(np.abs(normals), axis=1)]
    t1 = np.cross(normals, axis)
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    return t1, np.cross(normals, t1)


def principal_directions(
    vertices: np.ndarray, faces: np.ndarray, normals: np.ndarray, *, smoothing: int = 2
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    r"""Principal curvatures and directions at each vertex.

    The shape operator $S$ (symmetric 2x2 in a tangent basis of the vertex)
    is the least-squares solution of $\Pi(n_j - n_i) = S\, \Pi(p_j - p_i)$ over
    the vertex's edges ($\Pi$ the projection on the tangent plane). The
    operators are then averaged `smoothing` times over each vertex's 1-ring as
    3x3 world-space tensors (which removes the noise of small meshes' normals
    and keeps the field coherent), and re-projected.

    **Returns:**

    `(d_max, d_min, k_max, k_min)`: unit directions `(V, 3)` of the largest and
    smallest curvature (as lines: their sign is arbitrary) and the curvatures
    `(V,)` (positive where the surface bends away from its normal).
    """
    p = np.asarray(vertices, np.float64)
    n = np.asarray(normals, np.float64)
    n = n / np.linalg.norm(n, axis=1, keepdims=True)
    i, j = _edges(faces)
    t1, t2 = _frames(n)
    e, dn = p[j] - p[i], n[j] - n[i]
    x, y = np.einsum("ij,ij->i", e, t1[i]), np.einsum("ij,ij->i", e, t2[i])
    d1, d2 = np.einsum("ij,ij->i", dn, t1[i]), np.einsum("ij,ij->i", dn, t2[i])
    # Normal equations of rows [x, y, 0] -> d1 and [0, x, y] -> d2 for the unknowns (a, b, c).
    ata = np.zeros((len(p), 3, 3))
    atb = np.zeros((len(p), 3))
    for r, c, v in ((0, 0, x * x), (0, 1, x * y), (1, 1, x * x + y * y), (1, 2, x * y), (2, 2, y * y)):
        np.add.at(ata[:, r, c], i, v)
        if r != c:
            np.add.at(ata[:, c, r], i, v)
    for r, v in ((0, x * d1), (1, y * d1 + x * d2), (2, y * d2)):
        np.add.at(atb[:, r], i, v)
    scale = np.trace(ata, axis1=1, axis2=2)[:, None, None]
    abc = np.linalg.solve(ata + 1e-9 * scale * np.eye(3) + 1e-30 * np.eye(3), atb[..., None])[..., 0]
    a, b, c = abc.T
    # As a world-space tensor, for smoothing over the 1-ring.
    T = a[:, None, None] * t1[:, :, None] * t1[:, None, :] + c[:, None, None] * t2[:, :, None] * t2[:, None, :]
    T += b[:, None, None] * (t1[:, :, None] * t2[:, None, :] + t2[:, :, None] * t1[:, None, :])
    degree = np.bincount(i, minlength=len(p)).astype(np.float64)
    for _ in range(smoothing):
        acc = T.copy()
        np.add.at(acc, i, T[j])
        T = acc / (degree + 1)[:, None, None]
    a = np.einsum("vi,vij,vj->v", t1, T, t1)
    b = np.einsum("vi,vij,vj->v", t1, T, t2)
    c = np.einsum("vi,vij,vj->v", t2, T, t2)
    theta = 0.5 * np.arctan2(2 * b, a - c)
    d_max = np.cos(theta)[:, None] * t1 + np.sin(theta)[:, None] * t2
    d_min = np.cross(n, d_max)
    mid, rad = (a + c) / 2, np.hypot((a - c) / 2, b)
    return d_max, d_min, mid + rad, mid - rad


def solid_noise(points: np.ndarray, cell: float, seed: int = 0) -> np.ndarray:
    """Value noise in 3D: random values on a lattice of spacing `cell`, blended with a quintic fade.

    Zero mean, values in [-1, 1]; the same `seed` gives the same noise at the
    same points (a hashed lattice, unbounded in space).
    """
    table = np.random.default_rng(seed).uniform(-1, 1, _HASH_SIZE)
    q = np.asarray(points, np.float64) / cell
    base = np.floor(q).astype(np.int64)
    f = q - base
    fade = f * f * f * (f * (f * 6 - 15) + 10)
    out = np.zeros(len(q))
    for dx in (0, 1):
        for dy in (0, 1):
            for dz in (0, 1):
                ix, iy, iz = base[:, 0] + dx, base[:, 1] + dy, base[:, 2] + dz
                h = (ix * 73856093) ^ (iy * 19349663) ^ (iz * 83492791)
                w = (fade[:, 0] if dx else 1 - fade[:, 0]) * (fade[:, 1] if dy else 1 - fade[:, 1]) * (fade[:, 2] if dz else 1 - fade[:, 2])
                out += w * table[h % _HASH_SIZE]
    return out


def stroke_field(
    vertices: np.ndarray,
    faces: np.ndarray,
    normals: np.ndarray,
    *,
    direction: str = "min",
    length: float = 0.25,
    width: float | None = None,
    steps: int = 12,
    seed: int = 0,
) -> np.ndarray:
    """The brush-stroke layer: a per-vertex value, LIC of solid noise along a principal direction.

    **Arguments:**

    - `vertices`, `faces`, `normals`: the mesh (object space).
    - `direction`: `"min"` (strokes along the direction of least curvature,
      e.g. along a tube, as a brush paints it) or `"max"` (across it, like
      cross-contour hatching).
    - `length`: the strokes' length, in object units.
    - `width`: the noise's cell, i.e. the strokes' width, in object units;
      by default twice the mean edge length (a vertex attribute cannot hold
      finer detail).
    - `steps`: streamline steps each way.
    - `seed`: the noise's seed.

    **Returns:**

    `(V,)` float32, zero mean, unit standard deviation.
    """
    if direction not in ("min", "max"):
        raise ValueError(f"direction must be 'min' or 'max', got {direction!r}")
    p = np.asarray(vertices, np.float64)
    n = np.asarray(normals, np.float64)
    n = n / np.linalg.norm(n, axis=1, keepdims=True)
    d_max, d_min, _, _ = principal_directions(p, faces, n)
    field = d_min if direction == "min" else d_max
    if width is None:
        width = 2.0 * mean_edge_length(p, faces)
    tree = spatial.cKDTree(p)
    h = length / (2 * steps)
    window = np.cos(np.pi * np.arange(1, steps + 1) / (steps + 1)) * 0.5 + 0.5  # Hann, centre weight 1
    acc = solid_noise(p, width, seed)
    total = 1.0 + 2 * window.sum()
    for sign in (1.0, -1.0):
        q, d = p.copy(), sign * field
        for k in range(steps):
            q = q + h * d
            _, idx = tree.query(q)
            nd = field[idx]
            nd = nd * np.where(np.einsum("ij,ij->i", nd, d) < 0, -1.0, 1.0)[:, None]
            q = q - np.einsum("ij,ij->i", q - p[idx], n[idx])[:, None] * n[idx]
            d = nd
            acc += window[k] * solid_noise(q, width, seed)
    s = acc / total
    s = s - s.mean()
    sd = s.std()
    return (s / sd if sd > 0 else s).astype(np.float32)


def subdivide(
    vertices: np.ndarray, faces: np.ndarray, normals: np.ndarray, *, max_edge: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Split every triangle into four until the mean edge is at most `max_edge`, without changing the shape.

    Midpoint subdivision keeps the surface exactly (new vertices lie on the old
    triangles) and interpolates the normals linearly, unnormalised, so per-pixel
    shading (which interpolates normals and renormalises them) is unchanged;
    only the vertex attributes it carries, like the stroke layer, gain detail.
    For a coarse mesh (`knot-1k.ply`) this is what makes the stroke layer
    readable.

    **Returns:**

    `(vertices, faces, normals)` of the finer mesh.
    """
    v, f, n = np.asarray(vertices, np.float64), np.asarray(faces, np.int64), np.asarray(normals, np.float64)
    while mean_edge_length(v, f) > max_edge:
        v, f, attrs = trimesh.remesh.subdivide(v, f, vertex_attributes={"normals": n})
        n = attrs["normals"]
    return v, f, n


@shader_function("look_stroke_factor", [("stroke", "float")], "float")
def stroke_factor(stroke: Float[ArrayLike, "*b"], amplitude: Float[ArrayLike, ""]) -> Float[Array, "*b"]:
    """The thickness factor of the stroke layer: `exp(amplitude * stroke)` (0: off); differentiable."""
    xp = namespace(stroke, amplitude)
    (stroke,) = xp.asfloat(stroke)
    return xp.exp(amplitude * stroke)
