r"""Visibility: which triangle each pixel sees, by a z-buffered scatter rasterizer in JAX.

This is the renderer's only non-differentiable step (nvdiffrast's `rasterize`):
it yields integer triangle ids, which the differentiable steps (barycentrics,
interpolation, shading, antialiasing) consume. While geometry and camera stay
fixed, a `Visibility` can be reused for any number of renders, e.g. while
fitting materials.

**How it works.** Triangles are transformed to clip space and set up once
(screen bounding box, facing). On the host, the bounding boxes are sorted into
buckets by the number of pixel centres they span: a triangle whose box spans
`n` centres becomes a *job* evaluating a window of `K >= n` pixels (`K` a power
of two, at most 1024; larger boxes are cut into 32 x 32 tiles). For each bucket
one small jitted kernel evaluates all its windows at once with homogeneous
(2DH) edge functions (Olano and Greer 1997), so that triangles crossing the
near plane need no clipping: a fragment is kept where it lies inside all three
edges and its eye depth `w` lies in `[near, far]`. A first scatter takes the
minimum depth per pixel (`zbuf.at[pixel].min(w)`), a second the smallest
triangle id among the fragments at that depth. Job counts are padded to powers
of two so that few kernels are ever compiled. The work is linear in the summed
bounding-box area of the visible triangles: no loop over pixels times
triangles.

**Conventions.** Pixel `(row, col)` has its centre at `(col + 0.5, row + 0.5)`
pixels from the top-left corner; row 0 is the top. Clip space follows OpenGL
(`Camera.view_projection`); a triangle is front-facing when its vertices appear
counter-clockwise on screen. Pixels exactly on an edge shared by two triangles
belong to the nearer one, or to the lower id at equal depth.

**References:**

- M. Olano and T. Greer, "Triangle Scan Conversion using 2D Homogeneous
  Coordinates", Graphics Hardware 1997.
- S. Laine, J. Hellsten, T. Karras, Y. Seol, J. Lehtinen and T. Aila, "Modular
  Primitives for High-Performance Differentiable Rendering", ACM TOG 39(6), 2020
  (nvdiffrast).
"""

from __future__ import annotations

import functools
import math
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Int

__all__ = ["Visibility", "rasterize", "rasterize_arrays", "view_projection", "clip_positions", "pad_size"]

_WINDOW = 8  # pixel centres evaluated per job
_MIN_JOBS = 64  # smallest padded job count
_NO_TRI = np.iinfo(np.int32).max


class Visibility(eqx.Module):
    """What each pixel sees: the rasterizer's output.

    Non-differentiable and reusable while the geometry, the camera and the
    image size stay fixed.

    **Fields:**

    - `tri_id`: (H, W) int32, the triangle seen at each pixel centre (an index
      into `mesh.faces`), -1 where no triangle covers it.
    - `depth`: (H, W) float32, eye-space depth of the visible surface (distance
      along the view axis), `inf` where uncovered.
    - `pixels`: (P,) int32, row-major indices of the covered pixels, padded to a
      bucket size with `H * W` (an index past the image).
    - `pixel_tri`: (P,) int32, the triangle at each of `pixels` (padding repeats
      a real covered pixel's triangle, so padded entries shade something valid).
    - `silhouettes`: the antialiasing work items (`diffwash._antialias.Silhouettes`),
      or None when not prepared.
    - `width`, `height`: image size in pixels.
    """

    tri_id: Int[Array, "H W"]
    depth: Float[Array, "H W"]
    pixels: Int[Array, " P"]
    pixel_tri: Int[Array, " P"]
    silhouettes: Any = None
    width: int = eqx.field(static=True, default=0)
    height: int = eqx.field(static=True, default=0)

    @property
    def coverage(self) -> Array:
        """(H, W) bool: which pixel centres some triangle covers."""
        return self.tri_id >= 0


def pad_size(n: int, minimum: int = _MIN_JOBS) -> int:
    """`n` rounded up to a size with at most 8 steps per octave (few distinct shapes)."""
    n = max(int(n), minimum)
    step = 1 << max(0, n.bit_length() - 4)
    return -(-n // step) * step


# ---------------------------------------------------------------------------
# Triangle setup: clip space, screen bounding boxes, facing.


@functools.partial(jax.jit, static_argnames=("aspect",))
def view_projection(camera: Any, aspect: float) -> Float[Array, "4 4"]:
    """`camera.view_projection(aspect)`, compiled (no eager op-by-op dispatch on the host path)."""
    return camera.view_projection(aspect)


def clip_positions(vertices: Float[Array, "V 3"], view_projection: Float[Array, "4 4"]) -> Float[Array, "V 4"]:
    """Homogeneous clip-space positions `[v, 1] @ VP^T`."""
    vp = jnp.asarray(view_projection)
    return vertices @ vp[:, :3].T + vp[:, 3]


def _pixel_homogeneous(clip: Array, width: int, height: int) -> Array:
    """(x, y, w) clip coordinates to homogeneous pixel coordinates (X, Y, w).

    A point at pixel position (px, py) (y down) is `(X / w, Y / w)`.
    """
    x, y, w = clip[..., 0], clip[..., 1], clip[..., 3]
    return jnp.stack([(x + w) * (0.5 * width), (w - y) * (0.5 * height), w], axis=-1)


def _pixel_centre_range(lo: Any, hi: Any, size: int, xp: Any = jnp) -> tuple[Any, Any]:
    """Indices of the first and last pixel centres (i + 0.5) within [lo, hi], clamped to [0, size)."""
    margin = 1e-3  # the edge functions decide; the box only needs to include
    first = xp.clip(xp.ceil(lo - 0.5 - margin), 0, size)
    last = xp.clip(xp.floor(hi - 0.5 + margin), -1, size - 1)
    return first, last


@functools.partial(jax.jit, static_argnames=("width", "height"))
def _setup(vertices, faces, view_projection, near, far, *, width, height):
    """Per-triangle pixel-centre box (x0, x1, y0, y1), facing (+1 front, -1 back, 0 degenerate or
    unknown) and whether the triangle crosses the near plane (then box and facing are left to
    `_setup_crossing`)."""
    hv = _pixel_homogeneous(clip_positions(vertices, view_projection), width, height)
    w = hv[:, 2]
    big = 4.0 * (width + height) + 64.0
    safe_w = jnp.where(w >= near, w, 1)
    px = jnp.clip(hv[:, 0] / safe_w, -big, big)
    py = jnp.clip(hv[:, 1] / safe_w, -big, big)
    fx, fy, fw = px[faces], py[faces], w[faces]  # (T, 3) each
    front_of_near = fw >= near
    all_in = jnp.all(front_of_near, axis=1)
    crossing = jnp.any(front_of_near, axis=1) & ~all_in
    x0, x1 = _pixel_centre_range(jnp.min(fx, axis=1), jnp.max(fx, axis=1), width)
    y0, y1 = _pixel_centre_range(jnp.min(fy, axis=1), jnp.max(fy, axis=1), height)
    visible = all_in & jnp.any(fw <= far, axis=1) & (x0 <= x1) & (y0 <= y1)
    box = jnp.stack([x0, x1, y0, y1], axis=1).astype(jnp.int32)
    box = jnp.where(visible[:, None], box, jnp.array([0, -1, 0, -1], jnp.int32))
    # Signed area on screen; y points down, so counter-clockwise (front) is negative.
    area = (fx[:, 1] - fx[:, 0]) * (fy[:, 2] - fy[:, 0]) - (fx[:, 2] - fx[:, 0]) * (fy[:, 1] - fy[:, 0])
    facing = jnp.where(area < 0, 1, jnp.where(area > 0, -1, 0)).astype(jnp.int8)
    return box, jnp.where(visible, facing, 0).astype(jnp.int8), crossing


def _setup_crossing(clip: np.ndarray, width: int, height: int, near: float, far: float) -> tuple[np.ndarray, np.ndarray]:
    """Box and facing of triangles crossing the near plane (few; numpy, float64).

    The box is that of the part in front of the near plane: the vertices with
    `w >= near` and the points where the edges cross `w = near`.

    **Arguments:** `clip`: (n, 3, 4) clip coordinates of the triangles' vertices.
    """
    x, y, w = clip[..., 0], clip[..., 1], clip[..., 3]
    hv = np.stack([(x + w) * (0.5 * width), (w - y) * (0.5 * height), w], axis=-1)
    a, b = hv, np.roll(hv, -1, axis=1)
    wa, wb = a[..., 2], b[..., 2]
    crosses = (wa - near) * (wb - near) < 0
    s = np.where(crosses, (near - wa) / np.where(crosses, wb - wa, 1), 0)
    pts = np.concatenate([hv, a + s[..., None] * (b - a)], axis=1)  # (n, 6, 3)
    ok = np.concatenate([w >= near, crosses], axis=1)
    pw = np.where(ok, pts[..., 2], 1)
    px = np.where(ok, pts[..., 0] / pw, np.nan)
    py = np.where(ok, pts[..., 1] / pw, np.nan)
    x0, x1 = _pixel_centre_range(np.nanmin(px, axis=1), np.nanmax(px, axis=1), width, np)
    y0, y1 = _pixel_centre_range(np.nanmin(py, axis=1), np.nanmax(py, axis=1), height, np)
    visible = np.any(w <= far, axis=1) & (x0 <= x1) & (y0 <= y1)
    box = np.stack([x0, x1, y0, y1], axis=1).astype(np.int32)
    box[~visible] = [0, -1, 0, -1]
    # Facing from the homogeneous determinant (valid whatever the signs of w).
    det = np.einsum("ni,ni->n", hv[:, 0], np.cross(hv[:, 1], hv[:, 2]))
    facing = np.where(visible, -np.sign(det), 0).astype(np.int8)
    return box, facing


def _make_jobs(box: np.ndarray, keep: np.ndarray) -> np.ndarray:
    """Cut the kept triangles' bounding boxes into jobs of `_WINDOW` pixels.

    A box of `nx` by `ny` pixel centres is scanned in row-major order, `_WINDOW`
    centres per job.

    **Returns:**

    An (n, 6) int32 array of rows (triangle, x0, y0, nx, nx * ny, first), `n`
    padded with empty jobs.
    """
    tri = np.flatnonzero(keep).astype(np.int32)
    b = box[tri]
    nx = b[:, 1] - b[:, 0] + 1
    area = nx * (b[:, 3] - b[:, 2] + 1)
    count = -(-area // _WINDOW)
    owner = np.repeat(np.arange(len(tri), dtype=np.int32), count)
    first = (np.arange(len(owner), dtype=np.int32) - np.repeat(np.cumsum(count, dtype=np.int32) - count, count)) * _WINDOW
    n = pad_size(len(owner), _MIN_JOBS)
    jobs = np.zeros((n, 6), np.int32)
    jobs[:, 3] = 1  # padding: a 1-wide box of no pixels
    jobs[: len(owner)] = np.stack([tri[owner], b[owner, 0], b[owner, 2], nx[owner], area[owner], first], axis=1)
    return jobs


# ---------------------------------------------------------------------------
# The fragment kernel: both z-buffer passes in one program.


def _fragments(hv, faces, jobs, near, far, width, height):
    """Evaluate each job's window: (pixel index or H*W, depth w, triangle) per fragment."""
    tri, x0, y0, nx, area, first = (jobs[:, i] for i in range(6))
    f = faces[tri]
    v = [hv[f[:, i]] for i in range(3)]  # 3 x (n, 3): (X, Y, w) per vertex
    # Shift the origin to the box's first pixel centre, for precision.
    ox = (x0.astype(hv.dtype) + 0.5)
    oy = (y0.astype(hv.dtype) + 0.5)
    w = [vi[:, 2] for vi in v]
    X = [vi[:, 0] - ox * wi for vi, wi in zip(v, w)]
    Y = [vi[:, 1] - oy * wi for vi, wi in zip(v, w)]
    # Edge i's homogeneous line: c_i = v_j x v_k; e_i(p) = c_i . (px, py, 1).
    A, B, C = [], [], []
    for i, j, k in ((0, 1, 2), (1, 2, 0), (2, 0, 1)):
        A.append(Y[j] * w[k] - w[j] * Y[k])
        B.append(w[j] * X[k] - X[j] * w[k])
        C.append(X[j] * Y[k] - Y[j] * X[k])
    det = C[0] * w[0] + C[1] * w[1] + C[2] * w[2]  # det[v0, v1, v2]
    sgn = jnp.where(det > 0, 1.0, jnp.where(det < 0, -1.0, 0.0)).astype(hv.dtype)
    local = first[:, None] + jnp.arange(_WINDOW, dtype=jnp.int32)[None, :]
    du = jax.lax.rem(local, nx[:, None])
    dv = jax.lax.div(local, nx[:, None])
    fu = du.astype(hv.dtype)
    fv = dv.astype(hv.dtype)
    e = [(A[i] * sgn)[:, None] * fu + (B[i] * sgn)[:, None] * fv + (C[i] * sgn)[:, None] for i in range(3)]
    esum = e[0] + e[1] + e[2]
    depth = jnp.abs(det)[:, None] / jnp.where(esum > 0, esum, 1)
    px = x0[:, None] + du
    py = y0[:, None] + dv
    ok = (e[0] >= 0) & (e[1] >= 0) & (e[2] >= 0) & (esum > 0) & (depth >= near) & (depth <= far) & (local < area[:, None])
    pix = jnp.where(ok, py * width + px, width * height)
    return pix.reshape(-1), depth.reshape(-1), jnp.broadcast_to(tri[:, None], pix.shape).reshape(-1)


@functools.partial(jax.jit, static_argnames=("width", "height"))
def _zbuffer(vertices, faces, view_projection, jobs, near, far, *, width, height):
    hv = _pixel_homogeneous(clip_positions(vertices, view_projection), width, height)
    pix, depth, tri = _fragments(hv, faces, jobs, near, far, width, height)
    n = width * height
    zbuf = jnp.full(n, jnp.inf, hv.dtype).at[pix].min(depth, mode="drop")
    front = depth <= zbuf.at[pix].get(mode="fill", fill_value=-jnp.inf)
    ids = jnp.full(n, _NO_TRI, jnp.int32).at[pix].min(jnp.where(front, tri, _NO_TRI), mode="drop")
    return jnp.where(ids == _NO_TRI, -1, ids), zbuf


def rasterize_arrays(
    vertices: Any,
    faces: Any,
    view_projection: Any,
    near: float,
    far: float,
    width: int,
    height: int,
    cull_backfaces: bool,
) -> tuple[np.ndarray, np.ndarray]:
    """Z-buffered triangle ids and depths for concrete arrays (host function).

    **Returns:**

    `(tri_id, depth)`: (H, W) int32 (-1 uncovered) and (H, W) float32 (`inf`
    uncovered) numpy arrays.
    """
    vertices_np = np.asarray(vertices)
    faces_np = np.asarray(faces)
    vertices = jax.device_put(vertices_np.astype(np.float32, copy=False))
    faces = jax.device_put(faces_np.astype(np.int32, copy=False))
    vp = jax.device_put(np.asarray(view_projection, np.float32))
    near = np.float32(near)
    far = np.float32(far)
    box, facing, crossing = _setup(vertices, faces, vp, near, far, width=width, height=height)
    box, facing, crossing = np.array(box), np.array(facing), np.asarray(crossing)
    if crossing.any():
        idx = np.flatnonzero(crossing)
        vp64 = np.asarray(view_projection, np.float64)
        clip = vertices_np.astype(np.float64)[faces_np[idx]] @ vp64[:, :3].T + vp64[:, 3]
        box[idx], facing[idx] = _setup_crossing(clip, width, height, float(near), float(far))
    keep = (box[:, 1] >= box[:, 0]) & (box[:, 3] >= box[:, 2]) & (facing != 0)
    if cull_backfaces:
        keep &= facing > 0
    jobs = _make_jobs(box, keep)
    tri_id, zbuf = _zbuffer(vertices, faces, vp, jax.device_put(jobs), near, far, width=width, height=height)
    return np.asarray(tri_id).reshape(height, width), np.asarray(zbuf).reshape(height, width)


def _covered(tri_id: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    flat = tri_id.reshape(-1)
    pixels = np.flatnonzero(flat >= 0).astype(np.int32)
    n = pad_size(len(pixels), 64)
    out_pix = np.full(n, flat.size, np.int32)
    out_pix[: len(pixels)] = pixels
    out_tri = np.full(n, flat[pixels[0]] if len(pixels) else 0, np.int32)
    out_tri[: len(pixels)] = flat[pixels]
    return out_pix, out_tri


def rasterize(scene: Any, *, antialias: bool = False) -> Visibility:
    """Which triangle each pixel of `scene`'s image sees (host function, concrete scene).

    **Arguments:**

    - `scene`: a `Scene` (its mesh, camera, size and back-face mode are used).
    - `antialias`: also prepare the silhouette work items that
      `render(..., antialias=True)` needs.

    **Returns:**

    A `Visibility`, reusable while geometry and camera stay fixed.
    """
    vp = np.asarray(view_projection(scene.camera, scene.width / scene.height), np.float64)
    tri_id, depth = rasterize_arrays(
        scene.mesh.vertices,
        scene.mesh.faces,
        vp,
        float(scene.camera.near),
        float(scene.camera.far),
        scene.width,
        scene.height,
        scene.cull_backfaces,
    )
    pixels, pixel_tri = _covered(tri_id)
    vis = Visibility(
        tri_id=jax.device_put(tri_id),
        depth=jax.device_put(depth),
        pixels=jax.device_put(pixels),
        pixel_tri=jax.device_put(pixel_tri),
        width=scene.width,
        height=scene.height,
    )
    if antialias:
        from ._antialias import prepare

        vis = prepare(scene, vis)
    return vis
