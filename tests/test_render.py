"""`render` and `render_rgba`: the model per pixel and per vertex, coverage, paper, visibility reuse."""

from __future__ import annotations

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
import pytest

import diffwash
from diffwash import shading
from diffwash.ops import barycentrics, clip_positions
from diffwash._render import _cache, clear_visibility_cache
from diffwash._scene import Mesh, Scene

from conftest import DATA
from test_render_gradients import H, W, small_scene


def test_render_is_render_rgba_without_alpha():
    scene = small_scene()
    rgb = diffwash.render(scene)
    rgba = diffwash.render_rgba(scene)
    assert rgb.shape == (H, W, 3) and rgba.shape == (H, W, 4)
    np.testing.assert_array_equal(np.asarray(rgb), np.asarray(rgba[..., :3]))
    vis = diffwash.rasterize(scene)
    np.testing.assert_array_equal(np.asarray(rgba[..., 3]), np.asarray(vis.tri_id >= 0).astype(float))


def test_uncovered_pixels_show_the_paper():
    scene = small_scene()
    paper = jnp.array([0.3, 0.5, 0.7])
    img = np.asarray(diffwash.render(scene, dataclasses.replace(scene.params, paper=paper)))
    empty = ~np.asarray(diffwash.rasterize(scene).coverage)
    assert empty.sum() > 100
    np.testing.assert_allclose(img[empty], np.broadcast_to(paper, (empty.sum(), 3)))


def _reference_pixels(scene, params):
    """The model evaluated independently of the renderer's shading code path, at every covered pixel.

    Barycentrics come from the renderer (tested against OpenGL elsewhere); the
    interpolation and the model are redone here with numpy and `shading`.
    """
    vis = diffwash.rasterize(scene)
    px = np.asarray(vis.pixels)
    real = px < scene.width * scene.height
    tri = np.asarray(vis.pixel_tri)[real]
    clip = clip_positions(jnp.asarray(scene.mesh.vertices), scene.camera.view_projection(scene.width / scene.height))
    bary, front = barycentrics(clip, jnp.asarray(scene.mesh.faces), jnp.asarray(tri), jnp.asarray(px[real]),
                               scene.width, scene.height)  # fmt: skip
    bary = np.asarray(bary)
    f = np.asarray(scene.mesh.faces)[tri]
    v, n = np.asarray(scene.mesh.vertices), np.asarray(scene.mesh.normals)
    eye = np.asarray(scene.camera.eye)
    light = np.asarray(params.light) / np.linalg.norm(params.light)
    if scene.shading == "per-pixel":
        N = np.einsum("pi,pik->pk", bary, n[f])
        N /= np.linalg.norm(N, axis=1, keepdims=True)
        P = np.einsum("pi,pik->pk", bary, v[f])
        V = (eye - P) / np.linalg.norm(eye - P, axis=1, keepdims=True)
        wash, unlit = shading.thicknesses(N, light, V, params)
    else:
        Vv = (eye - v) / np.linalg.norm(eye - v, axis=1, keepdims=True)
        wv, uv = (np.asarray(x) for x in shading.thicknesses(n, light, Vv, params))
        wash, unlit = np.einsum("pi,pi->p", bary, wv[f]), np.einsum("pi,pi->p", bary, uv[f])
    return px[real], np.asarray(shading.glaze(params, wash, unlit))


@pytest.mark.parametrize("shading_mode", ["per-pixel", "per-vertex"])
def test_pixels_follow_the_model(shading_mode):
    scene = small_scene(shading_mode)
    pix, ref = _reference_pixels(scene, scene.params)
    img = np.asarray(diffwash.render(scene)).reshape(-1, 3)
    np.testing.assert_allclose(img[pix], ref, rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("shading_mode", ["per-pixel", "per-vertex"])
def test_thickness_maps_are_what_render_glazes(shading_mode):
    scene = small_scene(shading_mode)
    maps = np.asarray(diffwash.render_thicknesses(scene))
    assert maps.shape == (H, W, 2)
    cov = np.asarray(diffwash.rasterize(scene).coverage)
    np.testing.assert_array_equal(maps[~cov], 0)
    assert np.all(maps[cov, 0] <= float(scene.params.wash_max) + 1e-12) and np.all(maps[cov, 1] >= 0)
    glazed = np.asarray(shading.glaze(scene.params, maps[..., 0], maps[..., 1]))
    np.testing.assert_allclose(glazed[cov], np.asarray(diffwash.render(scene))[cov], rtol=1e-12, atol=1e-14)
    # Differentiable like render: d(unlit)/d(k_unlit) is the unlit fraction u.
    g = jax.grad(lambda k: diffwash.render_thicknesses(scene, dataclasses.replace(scene.params, k_unlit=k))[..., 1].sum())
    np.testing.assert_allclose(g(2.0), maps[..., 1].sum() / float(scene.params.k_unlit), rtol=1e-10)


def test_per_vertex_approaches_per_pixel_on_a_fine_mesh():
    """Per-vertex interpolates thicknesses; on a finely tessellated smooth mesh both agree closely."""
    fine = diffwash.load_scene(DATA / "scenes" / "sphere.json", size=(64, 64))
    pp = np.asarray(diffwash.render(fine))
    pv = np.asarray(diffwash.render(dataclasses.replace(fine, shading="per-vertex")))
    cov = np.asarray(diffwash.rasterize(fine).coverage)
    err = np.abs(pp - pv)[cov]
    assert err.mean() < 0.005 and err.max() < 0.2  # the largest gap is in the highlight
    assert err.max() > 0  # but they are different modes


def test_shading_mode_changes_the_image_where_highlights_are_sharp():
    scene = small_scene("per-pixel")
    a = np.asarray(diffwash.render(scene))
    b = np.asarray(diffwash.render(dataclasses.replace(scene, shading="per-vertex")))
    assert np.abs(a - b).max() > 0.02


def test_visibility_is_cached_and_reused():
    clear_visibility_cache()
    scene = small_scene()
    diffwash.render(scene)
    assert len(_cache) == 1
    vis = next(iter(_cache.values()))
    diffwash.render(scene, dataclasses.replace(scene.params, k_unlit=2.0))  # new params: same visibility
    assert len(_cache) == 1 and next(iter(_cache.values())) is vis
    explicit = diffwash.rasterize(scene)
    np.testing.assert_array_equal(np.asarray(explicit.tri_id), np.asarray(vis.tri_id))
    np.testing.assert_array_equal(np.asarray(diffwash.render(scene, visibility=explicit)),
                                  np.asarray(diffwash.render(scene)))  # fmt: skip


def test_cache_follows_geometry_and_camera():
    clear_visibility_cache()
    scene = small_scene()
    before = np.asarray(diffwash.render(scene))
    moved = dataclasses.replace(scene, camera=dataclasses.replace(scene.camera, eye=np.array([0.5, 0.6, 3.0])))
    after = np.asarray(diffwash.render(moved))
    assert len(_cache) == 2 and np.abs(before - after).max() > 0.1
    # Editing the vertex array in place is noticed (the key hashes the contents).
    vertices = np.array(scene.mesh.vertices)
    edited = eqx.tree_at(lambda s: s.mesh.vertices, scene, vertices)
    a = np.asarray(diffwash.rasterize(edited).tri_id)
    np.asarray(diffwash.render(edited))
    vertices += [0.3, 0.0, 0.0]
    b = np.asarray(diffwash.render_rgba(edited)[..., 3])
    np.testing.assert_array_equal(b > 0.5, np.asarray(diffwash.rasterize(edited).tri_id) >= 0)
    assert ((b > 0.5) != (a >= 0)).sum() > 20


def test_cache_is_bounded():
    clear_visibility_cache()
    scene = small_scene()
    for i in range(10):
        cam = dataclasses.replace(scene.camera, eye=np.array([0.4 + 0.01 * i, 0.6, 3.0]))
        diffwash.render(dataclasses.replace(scene, camera=cam))
    assert len(_cache) <= 4


def test_visibility_of_another_size_is_refused():
    scene = small_scene()
    other = diffwash.rasterize(dataclasses.replace(scene, width=W + 1))
    with pytest.raises(ValueError, match="visibility is for a"):
        diffwash.render(scene, visibility=other)


def test_render_inside_jit_closing_over_the_scene():
    """The usual fitting setup: params traced, scene a constant; visibility is computed at trace time."""
    clear_visibility_cache()
    scene = small_scene()
    f = jax.jit(lambda p: diffwash.render(scene, p))
    np.testing.assert_allclose(np.asarray(f(scene.params)), np.asarray(diffwash.render(scene)), atol=1e-12)


def test_optimistix_fits_parameters_through_render():
    """optimistix recovers k_unlit and gain from an image rendered with them."""
    scene = small_scene()
    truth = dataclasses.replace(scene.params, k_unlit=jnp.float64(1.7), gain=jnp.float64(0.35))
    target = diffwash.render(scene, truth)

    def residuals(x, _):
        p = dataclasses.replace(scene.params, k_unlit=x[0], gain=x[1])
        return (diffwash.render(scene, p) - target).reshape(-1)

    sol = optx.least_squares(residuals, optx.LevenbergMarquardt(rtol=1e-10, atol=1e-10), jnp.array([1.0, 0.5]),
                             max_steps=100)  # fmt: skip
    np.testing.assert_allclose(np.asarray(sol.value), [1.7, 0.35], rtol=1e-6)


def test_float32_by_default():
    """Outside the tests' float64 mode the renderer works in float32 (checked in a subprocess)."""
    import subprocess
    import sys

    code = (
        "import diffwash, jax.numpy as jnp;"
        f"s = diffwash.load_scene({str(DATA / 'scenes' / 'sphere.json')!r}, size=(24, 16));"
        "img = diffwash.render(s); assert img.dtype == jnp.float32, img.dtype;"
        "assert bool(jnp.isfinite(img).all()); print('ok')"
    )
    import os

    env = {**os.environ, "PYTHONPATH": str(DATA.parent), "JAX_ENABLE_X64": "0"}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=300)
    assert out.returncode == 0 and "ok" in out.stdout, out.stderr


def test_back_faces_are_shaded_with_the_normal_towards_the_eye():
    """A single quad seen from behind (drawn, as the mesh is open) looks like the same quad seen from the front."""
    v = np.array([[-1.0, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]])
    faces = np.array([[0, 1, 2], [0, 2, 3]], np.int32)
    n = np.tile([0.0, 0.0, 1.0], (4, 1))
    params = dataclasses.replace(small_scene().params, light=np.array([0.0, 0.0, 1.0]))

    def look(eye, normals, faces):
        cam = diffwash.Camera(eye=np.asarray(eye, float), target=np.zeros(3), up=np.array([0.0, 1.0, 0.0]),
                              fov_y=np.float64(40.0), near=np.float64(1.0), far=np.float64(6.0))  # fmt: skip
        mesh = Mesh(vertices=v, faces=faces, normals=normals, closed=False)
        scene = Scene(mesh=mesh, camera=cam, params=params, width=16, height=16)
        return np.asarray(diffwash.render(scene))

    front = look([0, 0, 3.0], n, faces)
    # From behind with the light behind too: mirror image of the front view.
    params = dataclasses.replace(params, light=np.array([0.0, 0.0, -1.0]))
    back = look([0, 0, -3.0], n, faces)
    np.testing.assert_allclose(back[:, ::-1], front, atol=1e-12)


def test_vmap_over_params():
    scene = small_scene()
    ks = jnp.array([0.5, 1.0, 2.0])
    images = jax.vmap(lambda k: diffwash.render(scene, dataclasses.replace(scene.params, k_unlit=k)))(ks)
    assert images.shape == (3, H, W, 3)
    one = diffwash.render(scene, dataclasses.replace(scene.params, k_unlit=jnp.float64(2.0)))
    np.testing.assert_allclose(np.asarray(images[2]), np.asarray(one), atol=1e-12)


def test_python_numbers_in_params_reuse_the_compiled_kernel():
    """`replace(params, gain=0.3)` (a weakly typed Python float, or an int) does not compile another kernel."""
    from diffwash._render import _render_kernel, _thickness_kernel

    scene = small_scene()
    diffwash.render(scene)
    diffwash.render_thicknesses(scene)
    compiled = _render_kernel._cache_size(), _thickness_kernel._cache_size()
    for change in ({"gain": 0.3}, {"shininess": 40}, {"bias": 0.45, "k_unlit": 2}):
        p = dataclasses.replace(scene.params, **change)
        want = diffwash.render(scene, dataclasses.replace(p, **{k: np.float64(v) for k, v in change.items()}))
        np.testing.assert_array_equal(np.asarray(diffwash.render(scene, p)), np.asarray(want))
        diffwash.render_thicknesses(scene, p)
    assert (_render_kernel._cache_size(), _thickness_kernel._cache_size()) == compiled


def test_antialiasing_reuses_the_cached_visibility():
    clear_visibility_cache()
    scene = small_scene()
    diffwash.render(scene)
    vis = next(iter(_cache.values()))
    assert vis.silhouettes is None
    diffwash.render(scene, antialias=True)
    assert len(_cache) == 1
    with_aa = next(iter(_cache.values()))
    assert with_aa.silhouettes is not None and with_aa.tri_id is vis.tri_id  # prepared, not rasterized again
