r"""`rasterize`: which triangle each pixel sees, by a z-buffered scatter rasterizer in JAX.

The renderer's one non-differentiable op (nvdiffrast's `rasterize`): clip-space
positions and triangles in, per-pixel triangle ids and depths out. It runs on
the device under `jax.jit`, without a host round trip, so a fit that moves the
geometry or the camera stays on the device; `jax.vmap` batches it over views.
The differentiable steps (`diffwash._interpolate`: barycentrics and
interpolation; shading; `diffwash._antialias`) consume its integer ids.

**How it works.** *Setup*, per triangle: the screen bounding box (in pixel
centres) of the part of the triangle in front of the near plane — its vertices
there and the points where its edges cross it — and its facing, from the
homogeneous determinant (valid whatever the signs of `w`); degenerate,
off-screen, beyond-the-far-plane and (where asked) back-facing triangles scan
nothing. *Jobs*: each box is scanned in runs of `WINDOW` (8) pixel centres,
row-major; `jnp.repeat` with a static total lists the jobs of all triangles
(`capacity` of them at most: the fragment budget). *Fragments*: every job's
pixel centres are tested at once with homogeneous (2DH) edge functions (Olano
and Greer 1997), so triangles crossing the near plane need no clipping: a
fragment is kept where it lies inside all three edges and between the near and
far planes (`-w <= z <= w`). *Depth test*: a scatter-min of the eye depth `w`
per pixel (`zbuf.at[pixel].min(w)`), then a scatter-min of the triangle id
among the fragments at that depth. The work is linear in the summed box area
of the triangles: no pixels x triangles loop.

Each edge function is evaluated from its two vertices in increasing index
order with the origin at the pixel centre, so that two triangles sharing an
edge compute exactly opposite values there: a pixel centre on a shared edge is
never missed by both (no cracks).

**Conventions.** Pixel `(row, col)` has its centre at `(col + 0.5, row + 0.5)`
pixels from the top-left corner; row 0 is the top. Clip space follows OpenGL;
a triangle is front-facing when its vertices appear counter-clockwise on
screen. Pixels exactly on an edge shared by two triangles belong to the nearer
one, or to the lower id at equal depth.

**References:**

- M. Olano and T. Greer, "Triangle Scan Conversion using 2D Homogeneous
  Coordinates", Graphics Hardware 1997.
- S. Laine, J. Hellsten, T. Karras, Y. Seol, J. Lehtinen and T. Aila, "Modular
  Primitives for High-Performance Differentiable Rendering", ACM TOG 39(6), 2020
  (nvdiffrast).
"""

from __future__ import annotations

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float, Int

__all__ = [
    "Raster",
    "rasterize",
    "covered",
    "compact",
    "clip_positions",
    "pad_size",
    "default_capacity",
    "required_capacity",
    "is_concrete",
    "WINDOW",
]

#: Pixel centres one job tests (a run of a triangle's bounding box, row-major).
WINDOW = 8
_NO_TRI = np.iinfo(np.int32).max


class Raster(eqx.Module):
    """What `rasterize` returns: the triangle and depth seen at each pixel centre.

    **Fields:**

    - `tri_id`: (H, W) int32, the triangle seen at each pixel centre (an index
      into the faces), -1 where none covers it.
    - `depth`: (H, W), eye-space depth `w` of the visible surface, `inf` where
      uncovered.
    - `complete`: a bool scalar, False when the triangles' boxes needed more
      jobs than the fragment `capacity` allowed (some fragments were then not
      tested: rasterize again with a larger capacity).
    """

    tri_id: Int[Array, "H W"]
    depth: Float[Array, "H W"]
    complete: Bool[Array, ""]


def pad_size(n: int, minimum: int = 64) -> int:
    """`n` rounded up to a size with at most 8 steps per octave (few distinct shapes, few compilations)."""
    n = max(int(n), minimum)
    step = 1 << max(0, n.bit_length() - 4)
    return -(-n // step) * step


def default_capacity(n_faces: int, width: int, height: int) -> int:
    """The job budget when the geometry is traced: one job per triangle plus one per `WINDOW` pixels, twice.

    Enough for closed meshes whose triangles are small on screen and whose
    surfaces overlap a few times; pass `capacity` for other scenes (and check
    `Raster.complete`).
    """
    return pad_size(2 * (n_faces + -(-width * height // WINDOW)))


def is_concrete(*trees) -> bool:
    """Whether no leaf of `trees` is being traced (so its values can be read now)."""
    return not any(isinstance(x, jax.core.Tracer) for x in jax.tree_util.tree_leaves(trees))


def clip_positions(vertices: Float[ArrayLike, "V 3"], view_projection: Float[ArrayLike, "4 4"]) -> Float[Array, "V 4"]:
    """Homogeneous clip-space positions `[v, 1] @ VP^T` (differentiable)."""
    vp = jnp.asarray(view_projection)
    return jnp.asarray(vertices) @ vp[:, :3].T + vp[:, 3]


def _pixel_homogeneous(clip: Array, width: int, height: int) -> Array:
    """(x, y, w) clip coordinates to homogeneous pixel coordinates (X, Y, w); a point is at `(X / w, Y / w)`."""
    x, y, w = clip[..., 0], clip[..., 1], clip[..., 3]
    return jnp.stack([(x + w) * (0.5 * width), (w - y) * (0.5 * height), w], axis=-1)


def _pixel_centre_range(lo: Array, hi: Array, size: int) -> tuple[Array, Array]:
    """Indices of the first and last pixel centres (i + 0.5) within [lo, hi], clamped to [0, size)."""
    margin = 1e-3  # the edge functions decide; the box only needs to include
    first = jnp.clip(jnp.ceil(lo - 0.5 - margin), 0, size)
    last = jnp.clip(jnp.floor(hi - 0.5 + margin), -1, size - 1)
    return first, last


def _boxes(clip: Array, faces: Array, cull: Array, width: int, height: int) -> Array:
    """Per triangle `(x0, y0, columns, pixel centres)` of the box to scan (0 centres: nothing to scan).

    The box bounds the part of the triangle in front of the near plane
    (`z + w >= 0`): its vertices there and the points where its edges cross
    the plane.
    """
    c = [clip[faces[:, i]] for i in range(3)]  # one gather per corner, (T, 4) each
    hv = [_pixel_homogeneous(ci, width, height) for ci in c]
    d = [ci[:, 2] + ci[:, 3] for ci in c]  # >= 0 in front of the near plane
    points, valid = [], []
    for i in range(3):
        j = (i + 1) % 3
        points.append(hv[i])
        valid.append((d[i] >= 0) & (c[i][:, 3] > 0))
        crosses = d[i] * d[j] < 0
        s = jnp.where(crosses, d[i] / jnp.where(crosses, d[i] - d[j], 1), 0)
        points.append(hv[i] + s[:, None] * (hv[j] - hv[i]))
        valid.append(crosses)
    big = 4.0 * (width + height) + 64.0
    pts = jnp.stack(points, axis=1)  # (T, 6, 3)
    ok = jnp.stack(valid, axis=1) & (pts[..., 2] > 0)
    w = jnp.where(ok, pts[..., 2], 1)
    px = jnp.clip(pts[..., 0] / w, -big, big)
    py = jnp.clip(pts[..., 1] / w, -big, big)
    x0, x1 = _pixel_centre_range(jnp.min(jnp.where(ok, px, jnp.inf), 1), jnp.max(jnp.where(ok, px, -jnp.inf), 1), width)
    y0, y1 = _pixel_centre_range(jnp.min(jnp.where(ok, py, jnp.inf), 1), jnp.max(jnp.where(ok, py, -jnp.inf), 1), height)
    # Facing from the homogeneous determinant (negative: counter-clockwise on screen, y down).
    det = jnp.sum(hv[0] * jnp.cross(hv[1], hv[2]), axis=1)
    facing_ok = jnp.where(cull, det < 0, det != 0)
    before_far = (c[0][:, 2] <= c[0][:, 3]) | (c[1][:, 2] <= c[1][:, 3]) | (c[2][:, 2] <= c[2][:, 3])
    visible = jnp.any(ok, axis=1) & before_far & (x0 <= x1) & (y0 <= y1) & facing_ok
    nx = jnp.where(visible, x1 - x0 + 1, 1).astype(jnp.int32)
    centres = jnp.where(visible, nx * (y1 - y0 + 1).astype(jnp.int32), 0)
    x0 = jnp.where(visible, x0, 0).astype(jnp.int32)
    y0 = jnp.where(visible, y0, 0).astype(jnp.int32)
    return jnp.stack([x0, y0, nx, centres], axis=1)


def _jobs(boxes: Array, capacity: int) -> tuple[Array, Array, Array]:
    """Each job's triangle and first pixel centre (in its box), and whether all jobs fit in `capacity`."""
    count = -(-boxes[:, 3] // WINDOW)
    total = jnp.sum(count)
    n_tri = boxes.shape[0]
    tri = jnp.repeat(jnp.arange(n_tri, dtype=jnp.int32), count, total_repeat_length=capacity)
    start = jnp.cumsum(count) - count
    job = jnp.arange(capacity, dtype=jnp.int32)
    first = (job - start[tri]) * WINDOW
    first = jnp.where(job < total, first, np.iinfo(np.int32).max // 2)  # jobs past the list test nothing
    return tri, first, total <= capacity


def _fragments(clip, faces, boxes, tri, first, width, height):
    """Evaluate each job's window: (pixel index or H*W, depth w, triangle) per fragment.

    The job's vertices are taken in increasing index order. Every edge function
    is then computed from its two vertices in the same order (lower index
    first) and with the origin at the pixel itself, so the two triangles
    sharing an edge get exactly opposite values: a pixel centre on a shared
    edge is never missed by both (no cracks). Orientation is not needed here
    (culling is decided in the setup).
    """
    box = boxes[tri]  # one gather per job of (x0, y0, columns, pixel centres)
    x0, y0, nx, area = (box[:, i] for i in range(4))
    f = faces[tri]
    lo = jnp.minimum(jnp.minimum(f[:, 0], f[:, 1]), f[:, 2])
    hi = jnp.maximum(jnp.maximum(f[:, 0], f[:, 1]), f[:, 2])
    mid = f[:, 0] + f[:, 1] + f[:, 2] - lo - hi
    hvz = jnp.concatenate([_pixel_homogeneous(clip, width, height), clip[:, 2:3]], axis=1)  # (X, Y, w, z)
    v = [hvz[i] for i in (lo, mid, hi)]  # the vertices in increasing index order, one gather each
    X, Y, w, Z = ([vi[:, k][:, None] for vi in v] for k in range(4))
    # det[v0, v1, v2] with the origin at the box's first pixel centre (precision).
    ox = x0.astype(hvz.dtype)[:, None] + 0.5
    oy = y0.astype(hvz.dtype)[:, None] + 0.5
    Xo = [Xi - ox * wi for Xi, wi in zip(X, w)]
    Yo = [Yi - oy * wi for Yi, wi in zip(Y, w)]
    det = (
        w[0] * (Xo[1] * Yo[2] - Xo[2] * Yo[1])
        + w[1] * (Xo[2] * Yo[0] - Xo[0] * Yo[2])
        + w[2] * (Xo[0] * Yo[1] - Xo[1] * Yo[0])
    )
    sgn = jnp.sign(det).astype(hvz.dtype)
    local = first[:, None] + jnp.arange(WINDOW, dtype=jnp.int32)[None, :]
    px = x0[:, None] + jax.lax.rem(local, nx[:, None])
    py = y0[:, None] + jax.lax.div(local, nx[:, None])
    fx = px.astype(hvz.dtype) + 0.5
    fy = py.astype(hvz.dtype) + 0.5
    Xs = [Xi - fx * wi for Xi, wi in zip(X, w)]  # origin at the pixel centre
    Ys = [Yi - fy * wi for Yi, wi in zip(Y, w)]

    def edge(a, b):  # homogeneous edge function of the edge from vertex a to b (a < b by index)
        return Xs[a] * Ys[b] - Xs[b] * Ys[a]

    e = [sgn * edge(1, 2), -sgn * edge(0, 2), sgn * edge(0, 1)]  # edge 1 runs v2 -> v0: -(v0 -> v2)
    esum = e[0] + e[1] + e[2]
    inv = 1 / jnp.where(esum > 0, esum, 1)
    depth = jnp.abs(det) * inv  # w at the pixel: sum_i e_i w_i / sum_i e_i
    z = (e[0] * Z[0] + e[1] * Z[1] + e[2] * Z[2]) * inv
    inside = (e[0] >= 0) & (e[1] >= 0) & (e[2] >= 0) & (esum > 0)
    ok = inside & (z >= -depth) & (z <= depth) & (local < area[:, None])
    pix = jnp.where(ok, py * width + px, width * height)
    return pix.reshape(-1), depth.reshape(-1), jnp.broadcast_to(tri[:, None], pix.shape).reshape(-1)


@functools.partial(jax.jit, static_argnames=("width", "height", "capacity"))
def _rasterize(clip, faces, cull, *, width, height, capacity):
    boxes = _boxes(clip, faces, cull, width, height)
    tri, first, complete = _jobs(boxes, capacity)
    pix, depth, frag_tri = _fragments(clip, faces, boxes, tri, first, width, height)
    n = width * height
    zbuf = jnp.full(n, jnp.inf, clip.dtype).at[pix].min(depth, mode="drop")
    front = depth <= zbuf.at[pix].get(mode="fill", fill_value=-jnp.inf)
    ids = jnp.full(n, _NO_TRI, jnp.int32).at[pix].min(jnp.where(front, frag_tri, _NO_TRI), mode="drop")
    ids = jnp.where(ids == _NO_TRI, -1, ids)
    return Raster(tri_id=ids.reshape(height, width), depth=zbuf.reshape(height, width), complete=complete)


@functools.partial(jax.jit, static_argnames=("width", "height"))
def _job_count(clip, faces, cull, *, width, height):
    return jnp.sum(-(-_boxes(clip, faces, cull, width, height)[:, 3] // WINDOW))


def required_capacity(
    clip: Float[ArrayLike, "V 4"],
    faces: Int[ArrayLike, "F 3"],
    resolution: tuple[int, int],
    *,
    cull_backfaces: bool | Bool[ArrayLike, ""] = False,
) -> int:
    """The fragment budget `rasterize` needs for these (concrete) inputs, rounded up to a bucket.

    Reads one number from the device. Pass it (with some margin, for moving
    geometry) as `capacity` to rasterize under `jax.jit` without a host round
    trip.
    """
    height, width = (int(r) for r in resolution)
    clip = jnp.asarray(clip, jnp.float32)
    count = _job_count(clip, jnp.asarray(faces, jnp.int32), jnp.asarray(cull_backfaces, bool), width=width, height=height)
    return pad_size(int(count))


def rasterize(
    clip: Float[ArrayLike, "V 4"],
    faces: Int[ArrayLike, "F 3"],
    resolution: tuple[int, int],
    *,
    cull_backfaces: bool | Bool[ArrayLike, ""] = False,
    capacity: int | None = None,
) -> Raster:
    """Which triangle each pixel centre sees, and at what depth (not differentiable).

    **Arguments:**

    - `clip`: clip-space vertex positions (OpenGL convention), e.g.
      `clip_positions(vertices, camera.view_projection(aspect))`.
    - `faces`: triangles, vertex indices, counter-clockwise when front-facing.
    - `resolution`: `(height, width)` in pixels.
    - `cull_backfaces`: hide back-facing triangles (may be a traced bool).
    - `capacity`: the most jobs (runs of `WINDOW` pixel centres of the
      triangles' bounding boxes) to test: a static size. By default it is the
      exact count (read from the device once) when the inputs are concrete, and
      `default_capacity` when they are traced. `Raster.complete` says whether
      it sufficed.

    **Returns:**

    A `Raster` (depths in float32: visibility is decided in float32, as on a
    GPU). Works under `jax.jit` and `jax.vmap`; gradients do not flow through
    it (the barycentrics do: `diffwash._interpolate.barycentrics`).
    """
    height, width = (int(r) for r in resolution)
    # Visibility is decided in float32 whatever the precision of the rest (as a GPU rasterizer does).
    clip = jax.lax.stop_gradient(jnp.asarray(clip, jnp.float32))
    faces = jnp.asarray(faces, jnp.int32)
    cull = jnp.asarray(cull_backfaces, bool)
    if capacity is None:
        if is_concrete(clip, faces, cull) and clip.ndim == 2:
            capacity = required_capacity(clip, faces, resolution, cull_backfaces=cull)
        else:
            capacity = default_capacity(faces.shape[0], width, height)
    return _rasterize(clip, faces, cull, width=width, height=height, capacity=int(capacity))


def compact(mask: Bool[Array, " n"], size: int | None = None) -> Int[Array, " m"]:
    """Indices where `mask` holds, in order, padded with `n` to a static length.

    `size` None: the count rounded up to a bucket (`pad_size`) when `mask` is
    concrete, else `n`. On the CPU, for a concrete mask, the host does it
    (NumPy's `flatnonzero` is many times faster than XLA's stream compaction
    there, and reading the mask copies nothing).
    """
    n = mask.shape[0]
    if size is None and is_concrete(mask):
        if jax.default_backend() == "cpu":
            idx = np.flatnonzero(np.asarray(mask)).astype(np.int32)
            out = np.full(pad_size(len(idx)), n, np.int32)
            out[: len(idx)] = idx
            return jax.device_put(out)
        size = pad_size(int(jnp.sum(mask)))
    return _nonzero(mask, size=n if size is None else size)


@functools.partial(jax.jit, static_argnames=("size",))
def _nonzero(mask, *, size):
    return jnp.nonzero(mask, size=size, fill_value=mask.shape[0])[0].astype(jnp.int32)


def covered(tri_id: Int[Array, "H W"], size: int | None = None) -> tuple[Int[Array, " P"], Int[Array, " P"]]:
    """The covered pixels (row-major indices) and their triangles, compacted to a static length.

    **Arguments:**

    - `tri_id`: a `Raster`'s triangle ids.
    - `size`: the length `P` of the list: by default the covered count rounded
      up to a bucket (`pad_size`) when `tri_id` is concrete, else every pixel.

    **Returns:**

    `(pixels, pixel_tri)`, (P,) int32 each. Padding entries have the pixel
    index `H * W` (past the image) and repeat a covered pixel's triangle, so
    they shade something valid and are dropped when scattered into the image.
    """
    flat = jnp.asarray(tri_id).reshape(-1)
    return _pixel_tri(flat, compact(flat >= 0, size))


@jax.jit
def _pixel_tri(flat, pixels):
    n = flat.shape[0]
    first = jnp.maximum(flat[jnp.minimum(pixels[0], n - 1)], 0)
    return pixels, jnp.where(pixels < n, flat[jnp.minimum(pixels, n - 1)], first).astype(jnp.int32)
