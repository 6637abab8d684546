r"""Analytic silhouette antialiasing, differentiable in vertex positions and camera.

After Laine et al. (2020, sec. 3.4; nvdiffrast's `antialias`). Point-sampled
visibility has no gradient with respect to where a silhouette lies; this op
gives it one. For each pair of horizontally or vertically adjacent pixels that
see different triangles (or a triangle and the background):

1. the *occluder* is the pixel whose surface is nearer (never the background);
2. the segment between the two pixel centres is followed from the occluder's
   triangle across its neighbours (up to `_WALK` triangles: with small
   triangles the first edge crossed is often an interior one, where nvdiffrast
   stops) until it crosses a *silhouette* edge — a boundary edge, or one whose
   neighbouring triangle faces the other way — at the fraction `t` of the way
   (from the homogeneous edge function, exactly linear on screen);
3. if that edge runs more across the pair's direction than along it (so that
   each edge is handled in one direction only), the pixel on whose side the
   crossing lies is blended with its neighbour: with `alpha = 1/2 - t` and
   colours `c_a` (occluder) and `c_b`, `c_a += alpha (c_b - c_a)` if
   `alpha > 0`, else `c_b += alpha (c_b - c_a)`.

That is the 1D coverage of the pixel by the occluder along the pair's
direction, and `t` is a smooth function of the clip-space vertices.

Steps 1-3 (which pairs, which edge) are decided once per visibility
(`silhouettes`: non-differentiable, on the device, jittable); `antialias`
recomputes `t` and the blend differentiably.

**References:**

- S. Laine, J. Hellsten, T. Karras, Y. Seol, J. Lehtinen and T. Aila, "Modular
  Primitives for High-Performance Differentiable Rendering", ACM TOG 39(6), 2020.
"""

from __future__ import annotations

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float, Int

from ._cache import LRU
from ._interpolate import corners, edge_functions, pixel_ndc
from ._rasterize import compact, is_concrete

__all__ = ["Silhouettes", "edge_topology", "silhouettes", "antialias"]

_EPS = 1.0 / 16  # tolerance on the crossing fraction (as nvdiffrast's)
_WALK = 6  # triangles a pair's segment may cross before it reaches a silhouette edge
_topology_cache = LRU(4)


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


def edge_topology(faces: Int[ArrayLike, "F 3"]) -> tuple[Int[Array, "F 3"], Int[Array, "F 3"]]:
    """For each triangle edge: the triangle across it and that triangle's far vertex.

    Edge `i` of triangle `t` joins `faces[t, (i + 1) % 3]` and
    `faces[t, (i + 2) % 3]`. Both answers are -1 for a boundary edge or one
    shared by more than two triangles. A property of the mesh: host work, once
    per mesh (cached by the faces' identity or content).

    **Returns:**

    `(neighbour, opposite)`, each (F, 3) int32, on the device.
    """
    return _topology_cache.get((faces,), lambda: _edge_topology(np.asarray(faces, np.int64)))


def _edge_topology(faces: np.ndarray) -> tuple[Array, Array]:
    n_tri = len(faces)
    a = faces[:, [1, 2, 0]].reshape(-1)
    b = faces[:, [2, 0, 1]].reshape(-1)
    keys = np.minimum(a, b) * (int(faces.max(initial=0)) + 1) + np.maximum(a, b)
    order = np.argsort(keys, kind="stable")
    ks = keys[order]
    m = len(ks)
    first_of_pair = np.zeros(m, bool)
    first_of_pair[:-1] = ks[:-1] == ks[1:]
    first_of_pair[1:] &= ks[1:] != ks[:-1]  # not the second of a run
    first_of_pair[: m - 2] &= ks[2:] != ks[: m - 2]  # not followed by a third
    i = np.flatnonzero(first_of_pair)
    e1, e2 = order[i], order[i + 1]  # flat edge ids (triangle * 3 + edge)
    neighbour = np.full(3 * n_tri, -1, np.int64)
    neighbour[e1], neighbour[e2] = e2 // 3, e1 // 3
    opposite = np.full(3 * n_tri, -1, np.int64)
    flat_faces = faces.reshape(-1)
    opposite[e1], opposite[e2] = flat_faces[e2], flat_faces[e1]  # edge i's far vertex is faces[t, i]
    return (
        jax.device_put(neighbour.reshape(n_tri, 3).astype(np.int32)),
        jax.device_put(opposite.reshape(n_tri, 3).astype(np.int32)),
    )


@functools.partial(jax.jit, static_argnames=("cull",))
def _candidates(tri_id, depth, neighbour, *, cull):
    """All adjacent pixel pairs: (occluder, other, vertical?) and whether they may straddle a silhouette.

    Candidates see different triangles. With back faces culled, every visible
    triangle faces the camera, so a pair of pixels in two triangles that share
    an edge straddles no silhouette (the segment crosses the shared edge):
    those pairs, most of them with small triangles, are no candidates.
    """
    h, w = tri_id.shape
    idx = jnp.arange(h * w, dtype=jnp.int32).reshape(h, w)
    p = jnp.concatenate([idx[:, :-1].reshape(-1), idx[:-1, :].reshape(-1)])
    q = jnp.concatenate([idx[:, 1:].reshape(-1), idx[1:, :].reshape(-1)])
    down = jnp.concatenate([jnp.zeros(h * (w - 1), bool), jnp.ones((h - 1) * w, bool)])
    flat, d = tri_id.reshape(-1), depth.reshape(-1)
    tp, tq = flat[p], flat[q]
    mask = tp != tq
    if cull:
        nb = neighbour[jnp.maximum(tp, 0)]
        adjacent = (tp >= 0) & (tq >= 0) & ((nb[:, 0] == tq) | (nb[:, 1] == tq) | (nb[:, 2] == tq))
        mask = mask & ~adjacent
    p_front = d[p] <= d[q]
    return jnp.where(p_front, p, q), jnp.where(p_front, q, p), down, mask


@functools.partial(jax.jit, static_argnames=("width", "height"))
def _analyse(clip, faces, neighbour, opposite, tri_id, a, b, down, *, width, height):
    """For candidate pairs: whether a silhouette edge splits them, which triangle and edge.

    The segment from the occluder's pixel centre `a` to `b` is followed across
    up to `_WALK` triangles of the same surface (small triangles: the first
    edge crossed is often an interior one) until it crosses a silhouette edge
    or ends.
    """
    n = width * height
    valid = a < n
    a = jnp.where(valid, a, 0)
    b = jnp.where(valid, b, 0)
    xa, ya = pixel_ndc(a, width, height, clip.dtype)
    xb, yb = pixel_ndc(b, width, height, clip.dtype)
    rows = jnp.arange(a.shape[0])
    xyw = jnp.array([0, 1, 3])
    tri = jnp.maximum(tri_id[a], 0)
    t_in = jnp.zeros(a.shape, clip.dtype)
    done = ~valid | (tri_id[a] < 0)
    found = jnp.zeros(a.shape, bool)
    out_tri, out_k = tri, jnp.zeros(a.shape, jnp.int32)
    for _ in range(_WALK):
        v = corners(clip, faces, tri)
        ea = jnp.stack(edge_functions(v, xa, ya), axis=1)
        eb = jnp.stack(edge_functions(v, xb, yb), axis=1)
        w = jnp.stack([c[:, 3] for c in v], axis=1)
        s = jnp.sign(jnp.sum(ea * w, axis=1))[:, None]  # facing; (sum_i e_i w_i = det, at any point)
        sa, sb = s * ea, s * eb
        leaves = (sb < 0) & (sb < sa)  # the segment goes out through this edge
        t = jnp.where(leaves, ea / jnp.where(leaves, ea - eb, 1), jnp.inf)
        t = jnp.where(t >= t_in[:, None] - 1e-6, t, jnp.inf)
        k = jnp.argmin(t, axis=1).astype(jnp.int32)
        tk = t[rows, k]
        # Silhouette: no neighbour across edge k, or the neighbour's far vertex
        # lies on our side of the edge (the neighbour faces the other way).
        o = opposite[tri, k]
        V = jnp.stack(v, axis=1)
        c = jnp.cross(V[rows, (k + 1) % 3][:, xyw], V[rows, (k + 2) % 3][:, xyw])  # edge k's line
        side = jnp.sum(c * clip[jnp.maximum(o, 0)][:, xyw], axis=1)
        silhouette = (o < 0) | (side * s[:, 0] > 0)
        # Each edge is handled in one direction: across horizontal pairs if steep.
        steep = jnp.abs(c[:, 0]) / width >= jnp.abs(c[:, 1]) / height
        exits = jnp.isfinite(tk) & (tk > -_EPS) & (tk < 1 + _EPS) & (s[:, 0] != 0)
        hit = ~done & exits & silhouette
        found = found | (hit & jnp.where(down, ~steep, steep))
        out_tri = jnp.where(hit, tri, out_tri)
        out_k = jnp.where(hit, k, out_k)
        nxt = neighbour[tri, k]
        done = done | hit | ~exits | (nxt < 0)
        tri = jnp.where(done, tri, jnp.maximum(nxt, 0))
        t_in = jnp.where(done, t_in, tk)
    return found, out_k, out_tri.astype(jnp.int32)


def _compact(mask: Array, size: int | None, arrays: tuple[Array, ...], fill: tuple) -> list[Array]:
    """The entries of `arrays` where `mask` holds, first, padded with `fill` to a static `size`.

    `size` None: the count rounded up to a bucket (read from the device).
    """
    idx = compact(mask, size)
    ok = idx < mask.shape[0]
    safe = jnp.minimum(idx, mask.shape[0] - 1)
    return [jnp.where(ok, x[safe], f) for x, f in zip(arrays, fill)]


def silhouettes(
    clip: Float[ArrayLike, "V 4"],
    faces: Int[ArrayLike, "F 3"],
    tri_id: Int[Array, "H W"],
    depth: Float[Array, "H W"],
    *,
    cull_backfaces: bool,
    topology: tuple[Array, Array] | None = None,
    size: int | None = None,
) -> "Silhouettes":
    """The antialiasing work items of a raster: the pixel pairs a silhouette edge splits (not differentiable).

    **Arguments:**

    - `clip`: clip-space vertex positions.
    - `faces`: the mesh's triangles.
    - `tri_id`, `depth`: their `Raster`'s (`diffwash._rasterize.rasterize`).
    - `cull_backfaces`: whether back faces were culled (a Python bool).
    - `topology`: `edge_topology(faces)`; computed here by default (host
      work, once per mesh): pass it when `faces` is traced.
    - `size`: the static number of work items. By default the count rounded
      up to a bucket when the inputs are concrete (read from the device), and
      two per pixel (every possible pair) when they are traced.

    **Returns:**

    The `Silhouettes`, padded with `a = H * W`. Runs on the device, under
    `jax.jit` and `jax.vmap` too (with `topology` given).
    """
    h, w = tri_id.shape
    n = h * w
    neighbour, opposite = edge_topology(faces) if topology is None else topology
    clip = jax.lax.stop_gradient(jnp.asarray(clip))
    faces = jnp.asarray(faces, jnp.int32)
    a, b, down, mask = _candidates(tri_id, depth, neighbour, cull=bool(cull_backfaces))
    exact = size is None and is_concrete(clip, tri_id)
    a, b, down = _compact(mask, None if exact else 2 * n, (a, b, down), (n, n, False))
    keep, k, tri = _analyse(clip, faces, neighbour, opposite, tri_id.reshape(-1), a, b, down, width=w, height=h)
    a, b, tri, k = _compact(keep, None if exact else (size or 2 * n), (a, b, tri, k), (n, n, 0, 0))
    return Silhouettes(a=a.astype(jnp.int32), b=b.astype(jnp.int32), tri=tri.astype(jnp.int32), edge=k.astype(jnp.int32))


def antialias(
    image: Float[Array, "n C"],
    clip: Float[Array, "V 4"],
    faces: Int[ArrayLike, "F 3"],
    silhouettes: Silhouettes,
    width: int,
    height: int,
) -> Float[Array, "n C"]:
    """Blend pixels across silhouette edges by the edges' analytic positions.

    **Arguments:**

    - `image`: (H * W, C) row-major pixel values (colour and, usually, coverage).
    - `clip`: clip-space vertex positions (differentiable).
    - `faces`: the mesh's triangles.
    - `silhouettes`: the work items (`silhouettes`).
    - `width`, `height`: image size.

    **Returns:**

    The antialiased (H * W, C) image, differentiable with respect to `image`
    and `clip`.
    """
    n = width * height
    s = silhouettes
    faces = jnp.asarray(faces, jnp.int32)
    valid = s.a < n
    a = jnp.where(valid, s.a, 0)
    b = jnp.where(valid, s.b, 0)
    v = corners(clip, faces, s.tri)
    xa, ya = pixel_ndc(a, width, height, clip.dtype)
    xb, yb = pixel_ndc(b, width, height, clip.dtype)
    ea_all = edge_functions(v, xa, ya)
    eb_all = edge_functions(v, xb, yb)
    ea = jnp.where(s.edge == 0, ea_all[0], jnp.where(s.edge == 1, ea_all[1], ea_all[2]))
    eb = jnp.where(s.edge == 0, eb_all[0], jnp.where(s.edge == 1, eb_all[1], eb_all[2]))
    den = ea - eb
    ok = valid & (den != 0)
    t = jnp.clip(jnp.where(ok, ea / jnp.where(ok, den, 1), 0.5), 0, 1)
    alpha = 0.5 - t
    ca = image[a]
    cb = image[b]
    delta = alpha[:, None] * (cb - ca)
    target = jnp.where(valid, jnp.where(alpha > 0, a, b), n)
    return image.at[target].add(delta, mode="drop")
