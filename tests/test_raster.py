"""Visibility: the scatter rasterizer against brute-force ray casting, and its conventions."""

from __future__ import annotations

import dataclasses
import functools

import hypothesis
import hypothesis.strategies as st
import numpy as np
import pytest

import diffwash
from diffwash import ops
from diffwash._rasterize import WINDOW, _jobs, pad_size
from diffwash._scene import Mesh, Scene

N_TRI = 10  # fixed triangle count: the kernels compile once for all examples
W, H = 28, 20


def _scene(vertices, faces, *, eye=(0.0, 0.0, 0.0), target=(0.0, 0.0, -1.0), fov=60.0, near=0.5, far=20.0,
           width=W, height=H, backfaces="both") -> Scene:  # fmt: skip
    base = _base_scene()
    normals = np.tile([0.0, 0.0, 1.0], (len(vertices), 1))
    mesh = Mesh(vertices=np.asarray(vertices, float), faces=np.asarray(faces, np.int32), normals=normals, closed=False)
    cam = diffwash.Camera(
        eye=np.asarray(eye, float), target=np.asarray(target, float), up=np.array([0.0, 1.0, 0.0]),
        fov_y=np.float64(fov), near=np.float64(near), far=np.float64(far),
    )  # fmt: skip
    return Scene(mesh=mesh, camera=cam, params=base.params, width=width, height=height, backfaces=backfaces)


from conftest import DATA  # noqa: E402

_SPHERE = DATA / "scenes" / "sphere.json"


@functools.cache
def _base_scene() -> Scene:
    return diffwash.load_scene(_SPHERE)


def ray_cast(scene: Scene) -> tuple[np.ndarray, np.ndarray]:
    """Reference visibility by casting a ray through every pixel centre (float64, O(pixels x triangles)).

    **Returns:** `(tri_id, ambiguous)`: the nearest hit with eye depth in [near, far]
    (respecting culling), and pixels whose answer is numerically fragile (the
    centre within 1e-6 of an edge, or two hits at nearly the same depth).
    """
    cam = scene.camera
    eye = np.asarray(cam.eye, float)
    f = np.asarray(cam.target, float) - eye
    f /= np.linalg.norm(f)
    s = np.cross(f, cam.up)
    s /= np.linalg.norm(s)
    u = np.cross(s, f)
    w, h = scene.width, scene.height
    tan = np.tan(np.radians(float(cam.fov_y)) / 2)
    x = ((np.arange(w) + 0.5) / w * 2 - 1) * tan * w / h
    y = (1 - (np.arange(h) + 0.5) / h * 2) * tan
    X, Y = np.meshgrid(x, y)
    d = X[..., None] * s + Y[..., None] * u + f  # eye depth along the ray = parameter t
    v = np.asarray(scene.mesh.vertices, float)[np.asarray(scene.mesh.faces)]  # (T, 3, 3)
    e1, e2 = v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]
    normal = np.cross(e1, e2)
    # Moeller-Trumbore for all (pixel, triangle) pairs.
    p = np.cross(d[:, :, None, :], e2)  # (H, W, T, 3)
    det = np.einsum("hwtk,tk->hwt", p, e1)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1 / det
        tvec = eye - v[:, 0]
        bu = np.einsum("hwtk,tk->hwt", p, tvec) * inv
        q = np.cross(tvec, e1)
        bv = np.einsum("hwk,tk->hwt", d, q) * inv
        t = np.einsum("tk,tk->t", e2, q) * inv
    bw = 1 - bu - bv
    hit = (bu >= 0) & (bv >= 0) & (bw >= 0) & (t >= float(cam.near)) & (t <= float(cam.far)) & (det != 0)
    front = np.einsum("tk,tk->t", normal, eye - v[:, 0]) > 0
    if scene.cull_backfaces:
        hit &= front
    depth = np.where(hit, t, np.inf)
    tri_id = np.where(np.isfinite(depth.min(-1)), np.argmin(depth, axis=-1), -1)
    near_edge = (np.minimum(np.minimum(np.abs(bu), np.abs(bv)), np.abs(bw)) < 1e-6) & np.isfinite(t) & (t > 0)
    sorted_d = np.sort(depth, axis=-1)
    with np.errstate(invalid="ignore"):
        tie = np.isfinite(sorted_d[..., 1]) & (sorted_d[..., 1] - sorted_d[..., 0] < 1e-6 * sorted_d[..., 0])
    at_limits = np.any(hit & ((np.abs(t - float(cam.near)) < 1e-6) | (np.abs(t - float(cam.far)) < 1e-6)), -1)
    return tri_id, near_edge.any(-1) | tie | at_limits


@st.composite
def triangle_soups(draw):
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    centres = rng.uniform([-2.5, -2, -8], [2.5, 2, 0.5], size=(N_TRI, 1, 3))  # some behind the eye
    size = draw(st.sampled_from([0.3, 1.0, 3.0]))
    v = (centres + rng.normal(scale=size, size=(N_TRI, 3, 3))).reshape(-1, 3)
    faces = np.arange(3 * N_TRI).reshape(N_TRI, 3)
    return v, faces, draw(st.sampled_from(["both", "cull"])), draw(st.sampled_from([0.1, 0.5, 2.0]))


@hypothesis.settings(max_examples=60)
@hypothesis.given(triangle_soups())
def test_visibility_matches_ray_casting(soup):
    v, faces, backfaces, near = soup
    scene = _scene(v, faces, backfaces=backfaces, near=near)
    ours = np.asarray(diffwash.rasterize(scene).tri_id)
    ref, ambiguous = ray_cast(scene)
    bad = (ours != ref) & ~ambiguous
    assert not bad.any(), (np.argwhere(bad)[:5], ours[bad][:5], ref[bad][:5])


def test_pixel_centres_and_rows():
    """Row 0 is the top, pixel centres at i + 0.5: a triangle covers exactly the centres inside it."""
    # With the camera at the origin looking down -z, fov 90 and an aspect of 1, a
    # point (x, y, -1) lands on pixel coordinates ((x + 1) W / 2, (1 - y) H / 2).
    w = h = 16
    tri = np.array([[-1.0, 1.0, -1.0], [-1.0, 0.0, -1.0], [0.0, 1.0, -1.0]])  # top-left corner, CCW seen from the eye
    scene = _scene(tri, [[0, 1, 2]], fov=90.0, width=w, height=h, backfaces="cull")
    ids = np.asarray(diffwash.rasterize(scene).tri_id)
    px, py = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
    inside = (px + py <= 8) & (px >= 0) & (py >= 0)  # the half-square above the diagonal x + y = 8
    assert ids[0, 0] == 0 and ids[h - 1, 0] == -1  # top row, not the bottom
    np.testing.assert_array_equal(ids >= 0, inside)
    # Clockwise seen from the eye: culled when culling, drawn when not.
    flipped = tri[[0, 2, 1]]
    assert (np.asarray(diffwash.rasterize(_scene(flipped, [[0, 1, 2]], fov=90.0, width=w, height=h,
                                                 backfaces="cull")).tri_id) == -1).all()  # fmt: skip
    assert (np.asarray(diffwash.rasterize(_scene(flipped, [[0, 1, 2]], fov=90.0, width=w, height=h,
                                                 backfaces="both")).tri_id) >= 0).sum() == inside.sum()  # fmt: skip


def test_nearer_triangle_wins_and_ties_go_to_the_lower_id():
    quad = np.array([[-3.0, -3.0, 0.0], [3.0, -3.0, 0.0], [0.0, 3.0, 0.0]])
    far = quad + [0, 0, -4]
    near = quad + [0, 0, -3]
    for order, expect in (((far, near), 1), ((near, far), 0)):
        scene = _scene(np.concatenate(order), [[0, 1, 2], [3, 4, 5]], fov=90.0)
        ids = np.asarray(diffwash.rasterize(scene).tri_id)
        assert (ids[ids >= 0] == expect).all() and (ids >= 0).sum() > 50
    same = _scene(np.concatenate([far, far]), [[0, 1, 2], [3, 4, 5]], fov=90.0)
    ids = np.asarray(diffwash.rasterize(same).tri_id)
    assert set(np.unique(ids)) == {-1, 0}


def test_large_and_small_triangles_share_one_kernel():
    """A triangle covering the whole image (thousands of pixels) and tiny ones in one pass."""
    big = np.array([[-50.0, -50.0, -2.0], [50.0, -50.0, -2.0], [0.0, 50.0, -2.0]])
    small = np.array([[0.0, 0.0, -1.5], [0.01, 0.0, -1.5], [0.0, 0.01, -1.5]])
    scene = _scene(np.concatenate([big, small]), [[0, 1, 2], [3, 4, 5]], width=200, height=150)
    ids = np.asarray(diffwash.rasterize(scene).tri_id)
    ref, amb = ray_cast(scene)
    assert (ids == 0).sum() > 29000
    np.testing.assert_array_equal(ids[~amb], ref[~amb])


def test_nothing_visible():
    tri = np.array([[0.0, 0.0, 5.0], [1.0, 0.0, 5.0], [0.0, 1.0, 5.0]])  # behind the camera
    scene = _scene(tri, [[0, 1, 2]])
    vis = diffwash.rasterize(scene)
    assert (np.asarray(vis.tri_id) == -1).all()
    assert np.isinf(np.asarray(vis.depth)).all()
    image = np.asarray(diffwash.render(scene))
    np.testing.assert_allclose(image, np.broadcast_to(scene.params.paper, image.shape))


def test_depth_is_the_eye_depth():
    tri = np.array([[-30.0, -30.0, -3.0], [30.0, -30.0, -3.0], [0.0, 30.0, -3.0]])
    vis = diffwash.rasterize(_scene(tri, [[0, 1, 2]]))
    np.testing.assert_allclose(np.asarray(vis.depth), 3.0, rtol=1e-6)


@hypothesis.given(st.integers(0, 10**7))
def test_pad_size(n):
    p = pad_size(n)
    assert p >= max(n, 64)
    assert p <= max(64, n) * 1.125 + 1 or p <= 2 * max(n, 64)
    assert pad_size(p) == p  # padded sizes are fixed points: few distinct shapes


def test_jobs_cover_each_box_exactly_once():
    rng = np.random.default_rng(3)
    nx = rng.integers(1, 40, 40)
    centres = np.where(rng.random(40) < 0.8, nx * rng.integers(1, 40, 40), 0)
    boxes = np.stack([rng.integers(0, 50, 40), rng.integers(0, 50, 40), nx, centres], 1).astype(np.int32)
    n_jobs = int(np.sum(-(-centres // WINDOW)))
    tri, first, complete = (np.asarray(x) for x in _jobs(boxes, pad_size(n_jobs)))
    assert complete
    seen: dict[int, list] = {}
    for t, f in zip(tri, first):
        for k in range(f, min(f + WINDOW, boxes[t, 3])):
            seen.setdefault(int(t), []).append(k)
    assert set(seen) == set(np.flatnonzero(centres).tolist())
    for t, ks in seen.items():
        assert sorted(ks) == list(range(boxes[t, 3]))  # every pixel centre of the box once
    # Too small a budget is reported, not silently passed over.
    assert not bool(_jobs(boxes, n_jobs - 1)[2])


def _sphere_op_inputs(width=40, height=30):
    scene = diffwash.load_scene(_SPHERE, size=(width, height))
    clip = ops.clip_positions(scene.mesh.vertices, scene.camera.view_projection(width / height))
    return scene, clip


def test_array_op_matches_scene_rasterize_and_covered_lists_the_covered_pixels():
    scene, clip = _sphere_op_inputs()
    vis = diffwash.rasterize(scene)
    raster = ops.rasterize(clip, scene.mesh.faces, (30, 40), cull_backfaces=True)
    ids = np.asarray(raster.tri_id)
    assert bool(raster.complete)
    np.testing.assert_array_equal(ids, np.asarray(vis.tri_id))
    # The compacted pixel list is exactly the covered pixels, padded past the image.
    pixels = np.asarray(vis.pixels)
    real = pixels[pixels < 40 * 30]
    np.testing.assert_array_equal(real, np.flatnonzero(ids.reshape(-1) >= 0))
    np.testing.assert_array_equal(np.asarray(vis.pixel_tri)[: len(real)], ids.reshape(-1)[real])
    assert len(pixels) == pad_size(len(real))
    # The device's stream compaction (traced, or a given size) lists the same pixels.
    p2, t2 = ops.covered(raster.tri_id, size=len(pixels))
    np.testing.assert_array_equal(np.asarray(p2), pixels)
    np.testing.assert_array_equal(np.asarray(t2), np.asarray(vis.pixel_tri))


def test_rasterize_under_jit_and_vmap_matches_concrete_calls():
    """Traced geometry: no host round trip, same answer; a batch of views through vmap."""
    import jax
    import jax.numpy as jnp

    scene, _ = _sphere_op_inputs()
    faces = jnp.asarray(scene.mesh.faces)

    def raster(vertices, eye):
        cam = dataclasses.replace(scene.camera, eye=eye)
        clip = ops.clip_positions(vertices, cam.view_projection(40 / 30))
        return ops.rasterize(clip, faces, (30, 40), cull_backfaces=True).tri_id

    eyes = jnp.asarray([[0.0, 0.0, 3.5], [0.6, 0.3, 3.5], [-0.9, 0.5, 3.3]])  # within the near and far planes
    v = jnp.asarray(scene.mesh.vertices)
    batched = np.asarray(jax.jit(jax.vmap(raster, in_axes=(None, 0)))(v, eyes))
    for i, eye in enumerate(eyes):
        one = np.asarray(raster(v, eye))
        np.testing.assert_array_equal(batched[i], one)
        np.testing.assert_array_equal(np.asarray(jax.jit(raster)(v, eye)), one)
    assert (batched >= 0).sum(axis=(1, 2)).min() > 100


def test_a_small_fragment_budget_says_so():
    scene, clip = _sphere_op_inputs()
    raster = ops.rasterize(clip, scene.mesh.faces, (30, 40), cull_backfaces=True, capacity=64)
    assert not bool(raster.complete)


@pytest.mark.parametrize("backfaces", ["auto", "cull", "both"])
def test_backface_modes(backfaces):
    scene = dataclasses.replace(diffwash.load_scene(_SPHERE, size=(24, 24)), backfaces=backfaces)
    assert scene.cull_backfaces == (backfaces in ("auto", "cull"))  # the sphere is closed
    ref, amb = ray_cast(scene)
    ids = np.asarray(diffwash.rasterize(scene).tri_id)
    np.testing.assert_array_equal(ids[~amb], ref[~amb])


@hypothesis.settings(max_examples=40)
@hypothesis.given(st.integers(0, 2**32 - 1), st.sampled_from(["cull", "both"]))
def test_no_cracks_where_pixel_centres_lie_on_shared_edges(seed, backfaces):
    """A Delaunay mesh with many vertices on pixel centres (so edges pass through centres): watertight."""
    import scipy.spatial

    w = h = 32
    rng = np.random.default_rng(seed)
    i = rng.choice(np.arange(6, 26), size=(40, 2))
    centres = np.c_[2 * (i[:, 0] + 0.5) / w - 1, 1 - 2 * (i[:, 1] + 0.5) / h]
    corners = [[-0.8, -0.8], [0.8, -0.8], [0.8, 0.8], [-0.8, 0.8]]
    pts = np.concatenate([centres, rng.uniform(-0.8, 0.8, (30, 2)), corners])
    tri = scipy.spatial.Delaunay(pts).simplices
    p = pts[tri]
    ccw = (p[:, 1, 0] - p[:, 0, 0]) * (p[:, 2, 1] - p[:, 0, 1]) - (p[:, 2, 0] - p[:, 0, 0]) * (p[:, 1, 1] - p[:, 0, 1]) > 0
    tri = np.where(ccw[:, None], tri, tri[:, ::-1])
    tri = np.roll(tri, int(rng.integers(0, 3)), axis=1)
    faces = np.zeros((200, 3), np.int64)  # padded with degenerate triangles: one compiled kernel
    faces[: len(tri)] = tri
    scale = rng.uniform(0.5, 3)  # the same picture at any distance (fov 90: x / -z lands on NDC x)
    v = np.c_[pts * scale, -np.ones(len(pts)) * scale]
    scene = _scene(v, faces, fov=90.0, width=w, height=h, backfaces=backfaces)
    ids = np.asarray(diffwash.rasterize(scene).tri_id)
    px, py = np.meshgrid((np.arange(w) + 0.5) / w * 2 - 1, 1 - (np.arange(h) + 0.5) / h * 2)
    inside = (np.abs(px) < 0.8 - 1e-9) & (np.abs(py) < 0.8 - 1e-9)
    assert not (inside & (ids < 0)).any()
