r"""Visibility: which triangle each pixel sees, by a z-buffered scatter rasterizer in JAX.

This is the renderer's only non-differentiable step (nvdiffrast's `rasterize`):
it yields integer triangle ids, which the differentiable steps (barycentrics,
interpolation, shading, antialiasing) consume. While geometry and camera stay
fixed, a `Visibility` can be reused for any number of renders, e.g. while
fitting materials.

**How it works.** Two jitted programs, with one small synchronisation between
them. The *setup* transforms the vertices to clip space and finds each
triangle's screen bounding box in pixel centres, dropping degenerate,
off-screen, out-of-range and (where asked) back-facing triangles. Each box is
scanned in *jobs* of `_WINDOW` (8) pixel centres, row-major: the host fixes the
boxes of the rare triangles that cross the near plane (numpy), lists the jobs
(`np.repeat`), pads their count to one of 8 sizes per octave (`pad_size`: few
distinct shapes, few compilations), and runs the *z-buffer* program. It
evaluates every job's pixel centres at once with homogeneous (2DH) edge functions (Olano and Greer
1997), so that triangles crossing the near plane need no clipping — a fragment
is kept where it lies inside all three edges and its eye depth `w` lies in
`[near, far]` — then scatters the minimum depth per pixel
(`zbuf.at[pixel].min(w)`) and, second, the smallest triangle id among the
fragments at that depth. The work is linear in the summed bounding-box area of
the visible triangles: no loop over pixels times triangles.

Each edge function is evaluated from its two vertices in increasing index
order with the origin at the pixel centre, so that two triangles sharing an
edge compute exactly opposite values there: a pixel centre on a shared edge is
never missed by both (no cracks).

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
def _setup(vertices, faces, view_projection, near, far, cull, *, width, height):
    """Per triangle: the box to scan, as (x0, y0, columns, pixel centres), and whether it crosses the near plane.

    A triangle that is degenerate, off screen, beyond the clip range or culled
    (`cull` and back-facing) scans nothing (0 pixel centres). Triangles crossing
    the near plane are left to `_setup_crossing` (they scan nothing here).
    """
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
    # Signed area on screen; y points down, so counter-clockwise (front) is negative.
    area2 = (fx[:, 1] - fx[:, 0]) * (fy[:, 2] - fy[:, 0]) - (fx[:, 2] - fx[:, 0]) * (fy[:, 1] - fy[:, 0])
    facing_ok = jnp.where(cull, area2 < 0, area2 != 0)
    visible = all_in & jnp.any(fw <= far, axis=1) & (x0 <= x1) & (y0 <= y1) & facing_ok
    nx = jnp.where(visible, x1 - x0 + 1, 1).astype(jnp.int32)
    centres = jnp.where(visible, nx * (y1 - y0 + 1).astype(jnp.int32), 0)
    centres = jnp.where(crossing, 0, centres)
    info = jnp.stack([x0.astype(jnp.int32), y0.astype(jnp.int32), nx, centres], axis=1)
    return info, crossing


def _setup_crossing(clip: np.ndarray, width: int, height: int, near: float, far: float, cull: bool) -> np.ndarray:
    """`_setup`'s rows for triangles crossing the near plane (few; numpy, float64).

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
    # Facing from the homogeneous determinant (valid whatever the signs of w).
    det = np.einsum("ni,ni->n", hv[:, 0], np.cross(hv[:, 1], hv[:, 2]))
    facing_ok = det < 0 if cull else det != 0
    visible = np.any(w <= far, axis=1) & (x0 <= x1) & (y0 <= y1) & facing_ok
    nx = np.where(visible, x1 - x0 + 1, 1)
    centres = np.where(visible, nx * (y1 - y0 + 1), 0)
    return np.stack([np.where(visible, x0, 0), np.where(visible, y0, 0), nx, centres], axis=1).astype(np.int32)


# ---------------------------------------------------------------------------
# The fragment kernel: both z-buffer passes in one program.


def _jobs(centres: np.ndarray, n_jobs: int) -> tuple[np.ndarray, np.ndarray]:
    """Cut each triangle's box into jobs of `_WINDOW` pixel centres (row-major over the box), on the host.

    **Arguments:** `centres`: (T,) pixel centres of each triangle's box (0: none);
    `n_jobs`: the padded job count (at least the real one).

    **Returns:** `(triangle, first)` per job, (n_jobs,) int32 each; padding jobs
    have `first` past any box (they do nothing).
    """
    count = -(-centres // _WINDOW)
    total = int(count.sum())
    tri = np.zeros(n_jobs, np.int32)
    tri[:total] = np.repeat(np.arange(len(centres), dtype=np.int32), count)
    first = np.full(n_jobs, np.iinfo(np.int32).max // 2, np.int32)
    start = np.cumsum(count) - count
    first[:total] = (np.arange(total, dtype=np.int32) - np.repeat(start.astype(np.int32), count)) * _WINDOW
    return tri, first


def _fragments(hv, faces, info, tri, first, near, far, width, height):
    """Evaluate each job's window: (pixel index or H*W, depth w, triangle) per fragment.

    The job's vertices are taken in increasing index order. Every edge function is then computed from its two vertices in the same
    order (lower index first) and with the origin at the pixel itself, so the
    two triangles sharing an edge get exactly opposite values: a pixel centre
    on a shared edge is never missed by both (no cracks). Orientation is not
    needed here (culling is decided in `_setup`).
    """
    x0, y0, nx, area = (info[tri, i] for i in range(4))
    f = faces[tri]
    lo = jnp.minimum(jnp.minimum(f[:, 0], f[:, 1]), f[:, 2])
    hi = jnp.maximum(jnp.maximum(f[:, 0], f[:, 1]), f[:, 2])
    mid = f[:, 0] + f[:, 1] + f[:, 2] - lo - hi
    v = [hv[i] for i in (lo, mid, hi)]  # (X, Y, w) of the vertices, in increasing index order
    X, Y, w = ([vi[:, c][:, None] for vi in v] for c in range(3))
    # det[v0, v1, v2] with the origin at the box's first pixel centre (precision).
    ox = x0.astype(hv.dtype)[:, None] + 0.5
    oy = y0.astype(hv.dtype)[:, None] + 0.5
    Xo = [Xi - ox * wi for Xi, wi in zip(X, w)]
    Yo = [Yi - oy * wi for Yi, wi in zip(Y, w)]
    det = (
        w[0] * (Xo[1] * Yo[2] - Xo[2] * Yo[1])
        + w[1] * (Xo[2] * Yo[0] - Xo[0] * Yo[2])
        + w[2] * (Xo[0] * Yo[1] - Xo[1] * Yo[0])
    )
    sgn = jnp.where(det > 0, 1.0, jnp.where(det < 0, -1.0, 0.0)).astype(hv.dtype)
    local = first[:, None] + jnp.arange(_WINDOW, dtype=jnp.int32)[None, :]
    du = jax.lax.rem(local, nx[:, None])
    dv = jax.lax.div(local, nx[:, None])
    px = x0[:, None] + du
    py = y0[:, None] + dv
    fx = px.astype(hv.dtype) + 0.5
    fy = py.astype(hv.dtype) + 0.5
    Xs = [Xi - fx * wi for Xi, wi in zip(X, w)]  # origin at the pixel centre
    Ys = [Yi - fy * wi for Yi, wi in zip(Y, w)]

    def edge(a, b):  # homogeneous edge function of the edge from vertex a to b (a < b by index)
        return Xs[a] * Ys[b] - Xs[b] * Ys[a]

    e0 = sgn * edge(1, 2)
    e1 = -sgn * edge(0, 2)  # the edge from v2 to v0, computed as -(v0 to v2)
    e2 = sgn * edge(0, 1)
    esum = e0 + e1 + e2
    depth = jnp.abs(det) / jnp.where(esum > 0, esum, 1)
    ok = (e0 >= 0) & (e1 >= 0) & (e2 >= 0) & (esum > 0) & (depth >= near) & (depth <= far) & (local < area[:, None])
    pix = jnp.where(ok, py * width + px, width * height)
    return pix.reshape(-1), depth.reshape(-1), jnp.broadcast_to(tri[:, None], pix.shape).reshape(-1)


@functools.partial(jax.jit, static_argnames=("width", "height"))
def _zbuffer(vertices, faces, view_projection, info, job_tri, first, near, far, *, width, height):
    hv = _pixel_homogeneous(clip_positions(vertices, view_projection), width, height)
    pix, depth, tri = _fragments(hv, faces, info, job_tri, first, near, far, width, height)
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
    info, crossing = _setup(vertices, faces, vp, near, far, np.bool_(cull_backfaces), width=width, height=height)
    crossing = np.asarray(crossing)
    centres = np.asarray(info)[:, 3]
    if crossing.any():
        idx = np.flatnonzero(crossing)
        vp64 = np.asarray(view_projection, np.float64)
        clip = vertices_np.astype(np.float64)[faces_np[idx]] @ vp64[:, :3].T + vp64[:, 3]
        rows = _setup_crossing(clip, width, height, float(near), float(far), cull_backfaces)
        info = np.array(info)
        info[idx] = rows
        centres = info[:, 3]
        info = jax.device_put(info)
    n_jobs = int(np.sum(-(-centres // _WINDOW)))
    job_tri, first = _jobs(centres, pad_size(n_jobs, _MIN_JOBS))
    tri_id, zbuf = _zbuffer(vertices, faces, vp, info, jax.device_put(job_tri), jax.device_put(first), near, far,
                            width=width, height=height)  # fmt: skip
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


def host_context() -> Any:
    """A context in which JAX computations run now, even while an outer function is being traced.

    The host work (rasterizing a concrete scene inside a jitted loss that
    closes over it, say) must not be staged into the outer trace. JAX's
    `eval_context` does exactly that; `ensure_compile_time_eval` (the public
    fallback) also constant-folds while tracing the kernels, which compiles
    many small programs.
    """
    try:
        from jax._src.core import eval_context

        return eval_context()
    except ImportError:  # pragma: no cover - older or newer JAX
        return jax.ensure_compile_time_eval()


def rasterize(scene: Any, *, antialias: bool = False) -> Visibility:
    """Which triangle each pixel of `scene`'s image sees (a host function).

    **Arguments:**

    - `scene`: a `Scene` with concrete geometry and camera (its mesh, camera,
      size and back-face mode are used). It may be called while tracing a
      function that closes over the scene (e.g. inside a jitted loss): the
      work is done there and then, on the concrete values.
    - `antialias`: also prepare the silhouette work items that
      `render(..., antialias=True)` needs.

    **Returns:**

    A `Visibility`, reusable while geometry, camera and size stay fixed.
    """
    with host_context():
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
