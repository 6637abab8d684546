r"""Analytic silhouette antialiasing, differentiable in vertex positions and camera.

After Laine et al. (2020, sec. 3.4; nvdiffrast's `antialias`). Point-sampled
visibility has no gradient with respect to where a silhouette lies; this op
gives it one. For each pair of horizontally or vertically adjacent pixels that
see different triangles (or a triangle and the background):

1. the *occluder* is the pixel whose surface is nearer (never the background);
2. the segment between the two pixel centres leaves the occluder's triangle
   through one edge, at the fraction `t` of the way (from the homogeneous edge
   function, exactly linear on screen);
3. if that edge is a *silhouette* edge (a boundary edge, or one whose
   neighbouring triangle faces the other way) and runs more across the pair's
   direction than along it (so that each edge is handled in one direction
   only), the pixel on whose side the crossing lies is blended with its
   neighbour: with `alpha = 1/2 - t` and colours `c_a` (occluder) and `c_b`,
   `c_a += alpha (c_b - c_a)` if `alpha > 0`, else `c_b += alpha (c_b - c_a)`.

That is the 1D coverage of the pixel by the occluder along the pair's
direction, and `t` is a smooth function of the clip-space vertices.

Steps 1-3 (which pairs, which edge) are decided once per visibility
(`prepare`, non-differentiable, cached with the visibility); `antialias`
recomputes `t` and the blend differentiably.

**References:**

- S. Laine, J. Hellsten, T. Karras, Y. Seol, J. Lehtinen and T. Aila, "Modular
  Primitives for High-Performance Differentiable Rendering", ACM TOG 39(6), 2020.
"""

from __future__ import annotations

import collections
import functools
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Int

from ._barycentric import edge_functions, pixel_ndc
from ._raster import Visibility, clip_positions, pad_size, rasterize_arrays, view_projection

__all__ = ["Silhouettes", "opposite_vertices", "prepare", "antialias", "traced_visibility"]

_EPS = 1.0 / 16  # tolerance on the crossing fraction (as nvdiffrast's)
_topology_cache: collections.OrderedDict[tuple, np.ndarray] = collections.OrderedDict()


class Silhouettes(eqx.Module):
    """Antialiasing work items: pixel pairs split by a silhouette edge.

    **Fields** (each (N,) int32, padded with `a = H * W`):

    - `a`: the occluder's pixel (row-major index).
    - `b`: its neighbour (right, left, below or above).
    - `tri`: the occluder's triangle.
    - `edge`: which of its edges (the one opposite vertex `edge`) the pair straddles.
    """

    a: Int[Array, " N"]
    b: Int[Array, " N"]
    tri: Int[Array, " N"]
    edge: Int[Array, " N"]


def opposite_vertices(faces: Any) -> np.ndarray:
    """For each triangle edge, the far vertex of the triangle across it.

    Edge `i` of triangle `t` joins `faces[t, (i + 1) % 3]` and
    `faces[t, (i + 2) % 3]`. The answer is -1 for a boundary edge or one shared
    by more than two triangles. Cached per `faces` content.

    **Returns:**

    (F, 3) int32.
    """
    from ._render import _array_key

    faces = np.asarray(faces, np.int64)
    key = _array_key(faces)
    hit = _topology_cache.get(key)
    if hit is not None:
        return hit
    n_tri = len(faces)
    a = faces[:, [1, 2, 0]].reshape(-1)
    b = faces[:, [2, 0, 1]].reshape(-1)
    keys = np.minimum(a, b) * (int(faces.max(initial=0)) + 1) + np.maximum(a, b)
    order = np.argsort(keys, kind="stable")
    ks = keys[order]
    m = len(ks)
    same_next = np.zeros(m, bool)
    same_next[:-1] = ks[:-1] == ks[1:]
    first_of_pair = same_next.copy()
    first_of_pair[1:] &= ks[1:] != ks[:-1]  # not the second of a run
    first_of_pair[: m - 2] &= ks[2:] != ks[: m - 2]  # not followed by a third
    i = np.flatnonzero(first_of_pair)
    e1, e2 = order[i], order[i + 1]  # flat edge ids (triangle * 3 + edge)
    opposite = np.full(3 * n_tri, -1, np.int64)
    flat_faces = faces.reshape(-1)
    opposite[e1] = flat_faces[e2]  # the vertex opposite edge e2 in its triangle is faces[t2, i2]
    opposite[e2] = flat_faces[e1]
    out = opposite.reshape(n_tri, 3).astype(np.int32)
    _topology_cache[key] = out
    while len(_topology_cache) > 4:
        _topology_cache.popitem(last=False)
    return out


def _pairs(tri_id: np.ndarray, depth: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Adjacent pixel pairs seeing different triangles: (occluder pixel, other pixel, vertical?)."""
    h, w = tri_id.shape
    idx = np.arange(h * w, dtype=np.int32).reshape(h, w)
    horizontal = idx[:, :-1][tri_id[:, :-1] != tri_id[:, 1:]]
    vertical = idx[:-1, :][tri_id[:-1, :] != tri_id[1:, :]]
    p = np.concatenate([horizontal, vertical])
    q = np.concatenate([horizontal + 1, vertical + w])
    down = np.concatenate([np.zeros(len(horizontal), bool), np.ones(len(vertical), bool)])
    d = depth.reshape(-1)
    p_front = d[p] <= d[q]
    return np.where(p_front, p, q), np.where(p_front, q, p), down


@functools.partial(jax.jit, static_argnames=("width", "height"))
def _analyse(vertices, faces, view_projection, opposite, tri_id, a, b, down, *, width, height):
    """For candidate pairs: whether a silhouette edge of the occluder splits them, and which edge."""
    n = width * height
    valid = a < n
    a = jnp.where(valid, a, 0)
    b = jnp.where(valid, b, 0)
    clip = clip_positions(vertices, view_projection)
    tri = jnp.maximum(tri_id[a], 0)
    v = clip[faces[tri]]  # (N, 3, 4)
    xa, ya = pixel_ndc(a, width, height, clip.dtype)
    xb, yb = pixel_ndc(b, width, height, clip.dtype)
    ea = edge_functions(v, xa, ya)
    eb = edge_functions(v, xb, yb)
    det = jnp.sum(ea * v[..., 3], axis=1)
    s = jnp.sign(det)[:, None]
    leaves = s * eb < 0
    den = ea - eb
    t = jnp.where(leaves, ea / jnp.where(leaves, den, 1), jnp.inf)
    k = jnp.argmin(t, axis=1)
    tk = jnp.min(t, axis=1)
    rows = jnp.arange(len(k))
    # Silhouette: no neighbour across edge k, or its far vertex lies on the same
    # side of the edge as our own vertex k (the neighbour faces the other way).
    o = opposite[tri, k]
    vo = clip[jnp.maximum(o, 0)]
    vj = v[rows, (k + 1) % 3]
    vk = v[rows, (k + 2) % 3]
    xyw = jnp.array([0, 1, 3])
    c = jnp.cross(vj[:, xyw], vk[:, xyw])  # edge k's homogeneous line (NDC)
    side = jnp.sum(c * vo[:, xyw], axis=1)
    silhouette = (o < 0) | (side * s[:, 0] > 0)
    # Handle each edge in one direction: across horizontal pairs if it is steep.
    steep = jnp.abs(c[:, 0]) / width >= jnp.abs(c[:, 1]) / height
    across = jnp.where(down, ~steep, steep)
    keep = valid & (tri_id[a] >= 0) & (s[:, 0] != 0) & jnp.isfinite(tk) & (tk > -_EPS) & (tk < 1 + _EPS)
    return keep & silhouette & across, k.astype(jnp.int32), tri.astype(jnp.int32)


def _silhouettes(vertices, faces, vp, tri_id: np.ndarray, depth: np.ndarray, width: int, height: int, size: int | None):
    """Work items from concrete arrays (host). `size`: pad to this many (else a bucket size)."""
    a, b, down = _pairs(tri_id, depth)
    m = pad_size(len(a), 64)
    n = width * height

    def pad(x: np.ndarray, fill: Any, size: int) -> np.ndarray:
        return np.concatenate([x, np.full(size - len(x), fill, x.dtype)])

    keep, k, tri = _analyse(
        jax.device_put(np.asarray(vertices)),
        jax.device_put(np.asarray(faces).astype(np.int32, copy=False)),
        jax.device_put(np.asarray(vp)),
        jax.device_put(opposite_vertices(faces)),
        jax.device_put(tri_id.reshape(-1)),
        jax.device_put(pad(a, n, m)),
        jax.device_put(pad(b, n, m)),
        jax.device_put(pad(down, False, m)),
        width=width,
        height=height,
    )
    sel = np.flatnonzero(np.asarray(keep))
    m = pad_size(len(sel), 64) if size is None else size
    return {
        "a": pad(a[sel], n, m),
        "b": pad(b[sel], n, m),
        "tri": pad(np.asarray(tri)[sel], 0, m),
        "edge": pad(np.asarray(k)[sel], 0, m),
    }


def prepare(scene: Any, vis: Visibility) -> Visibility:
    """`vis` with its antialiasing work items (host function; needs a concrete scene)."""
    from ._render import _geometry, _is_concrete

    if not _is_concrete(_geometry(scene)):
        raise ValueError(
            "antialiasing needs a visibility prepared for it while the geometry is traced: "
            "pass visibility=diffwash.rasterize(scene, antialias=True)"
        )
    vp = np.asarray(view_projection(scene.camera, scene.width / scene.height))
    items = _silhouettes(
        scene.mesh.vertices,
        scene.mesh.faces,
        vp,
        np.asarray(vis.tri_id),
        np.asarray(vis.depth),
        scene.width,
        scene.height,
        None,
    )
    return eqx.tree_at(
        lambda v: v.silhouettes,
        vis,
        Silhouettes(**{k: jax.device_put(x) for k, x in items.items()}),
        is_leaf=lambda x: x is None,
    )


def antialias(
    image: Float[Array, "n C"],
    clip: Float[Array, "V 4"],
    faces: Int[Array, "F 3"],
    silhouettes: Silhouettes,
    width: int,
    height: int,
) -> Float[Array, "n C"]:
    """Blend pixels across silhouette edges by the edges' analytic positions.

    **Arguments:**

    - `image`: (H * W, C) row-major pixel values (colour and, usually, coverage).
    - `clip`: clip-space vertex positions (differentiable).
    - `faces`: the mesh's triangles.
    - `silhouettes`: the work items of the visibility (`prepare`).
    - `width`, `height`: image size.

    **Returns:**

    The antialiased (H * W, C) image, differentiable with respect to `image`
    and `clip`.
    """
    n = width * height
    s = silhouettes
    valid = s.a < n
    a = jnp.where(valid, s.a, 0)
    b = jnp.where(valid, s.b, 0)
    v = clip[faces[s.tri]]
    xa, ya = pixel_ndc(a, width, height, clip.dtype)
    xb, yb = pixel_ndc(b, width, height, clip.dtype)
    rows = jnp.arange(len(a))
    ea = edge_functions(v, xa, ya)[rows, s.edge]
    eb = edge_functions(v, xb, yb)[rows, s.edge]
    den = ea - eb
    ok = valid & (den != 0)
    t = jnp.clip(jnp.where(ok, ea / jnp.where(ok, den, 1), 0.5), 0, 1)
    alpha = 0.5 - t
    ca = image[a]
    cb = image[b]
    delta = alpha[:, None] * (cb - ca)
    target = jnp.where(valid, jnp.where(alpha > 0, a, b), n)
    return image.at[target].add(delta, mode="drop")


def traced_visibility(scene: Any, antialias: bool) -> Visibility:
    """The visibility of a scene whose geometry or camera is traced, by a host callback.

    Arrays have their largest possible sizes (every pixel; two pairs per
    pixel), as the callback's output shapes must be known when tracing.
    """
    w, h = scene.width, scene.height
    n = w * h
    sg = jax.lax.stop_gradient
    vertices = sg(jnp.asarray(scene.mesh.vertices))
    faces = jnp.asarray(scene.mesh.faces, jnp.int32)
    vp = sg(scene.camera.view_projection(w / h))
    near = sg(jnp.asarray(scene.camera.near))
    far = sg(jnp.asarray(scene.camera.far))
    cull = scene.cull_backfaces

    def host(vertices, faces, vp, near, far):
        vertices, faces, vp = np.asarray(vertices), np.asarray(faces), np.asarray(vp)
        tri_id, depth = rasterize_arrays(vertices, faces, vp, float(near), float(far), w, h, cull)
        out = [tri_id.astype(np.int32), depth.astype(np.float32)]
        if antialias:
            items = _silhouettes(vertices, faces, vp, tri_id, depth, w, h, 2 * n)
            out += [items[k].astype(np.int32) for k in ("a", "b", "tri", "edge")]
        return tuple(out)

    shapes = [jax.ShapeDtypeStruct((h, w), jnp.int32), jax.ShapeDtypeStruct((h, w), jnp.float32)]
    if antialias:
        shapes += [jax.ShapeDtypeStruct((2 * n,), jnp.int32)] * 4
    out = jax.pure_callback(host, tuple(shapes), vertices, faces, vp, near, far)
    tri_id = out[0]
    flat = tri_id.reshape(-1)
    covered = flat >= 0
    sil = Silhouettes(*out[2:]) if antialias else None
    return Visibility(
        tri_id=tri_id,
        depth=out[1],
        pixels=jnp.where(covered, jnp.arange(n, dtype=jnp.int32), n),
        pixel_tri=jnp.maximum(flat, 0),
        silhouettes=sil,
        width=w,
        height=h,
    )
