"""Gradients of rendered images against central finite differences (float64), and NaN-safety at the edges."""

from __future__ import annotations

import dataclasses
import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import diffwash
from diffwash._scene import Mesh, Scene

from conftest import knot_scene

W, H = 40, 32
PARAMS = ["wash.K", "wash.S", "unlit.K", "unlit.S", "paper", "light", "k_wash", "k_specular", "shininess",
          "k_unlit", "gain", "bias", "wash_reduction"]  # fmt: skip


@functools.cache
def small_scene(shading: str = "per-pixel", backfaces: str = "auto") -> Scene:
    return knot_scene("knot-1k.ply", W, H, shading, backfaces=backfaces)


def _weights(shape, seed=0):
    return jnp.asarray(np.random.default_rng(seed).uniform(0.5, 1.5, shape))


def _get(p, path):
    for part in path.split("."):
        p = getattr(p, part)
    return p


def _set(p, path, value):
    return eqx.tree_at(lambda q: _get(q, path), p, value)


def _as_arrays(params):
    return jax.tree_util.tree_map(lambda x: jnp.asarray(x, jnp.float64), params)


def central_difference(f, x, direction, h):
    return (f(x + h * direction) - f(x - h * direction)) / (2 * h)


def assert_close_rel(ad, fd, rel=1e-4):
    ad, fd = float(ad), float(fd)
    assert abs(ad - fd) <= rel * max(abs(fd), 1e-3), (ad, fd, abs(ad - fd) / max(abs(fd), 1e-12))


@pytest.mark.parametrize("shading", ["per-pixel", "per-vertex"])
def test_shading_parameter_gradients_match_finite_differences(shading):
    scene = small_scene(shading)
    params = _as_arrays(scene.params)
    weights = _weights((H, W, 3))

    @jax.jit
    def loss(p):
        return jnp.sum(diffwash.render(scene, p) * weights)

    grad = jax.jit(jax.grad(loss))(params)
    rng = np.random.default_rng(1)
    for path in PARAMS:
        x0 = jnp.asarray(_get(params, path))
        g = jnp.asarray(_get(grad, path))
        assert jnp.all(jnp.isfinite(g))
        d = jnp.asarray(rng.normal(size=x0.shape))
        fd = central_difference(lambda x: loss(_set(params, path, x)), x0, d, 1e-6 * max(1.0, float(jnp.max(jnp.abs(x0)))))
        assert_close_rel(jnp.sum(g * d), fd)
        assert float(jnp.max(jnp.abs(g))) > 0, path  # every parameter shows in the image


def test_every_leaf_of_params_has_a_gradient():
    """jax.grad works through the `Params` pytree as it is (names and all); jacfwd and jvp agree with it."""
    scene = small_scene()
    params = _as_arrays(scene.params)
    grad = jax.jit(jax.grad(lambda p: jnp.sum(diffwash.render(scene, p))))(params)
    assert isinstance(grad, diffwash.Params) and grad.wash.name == params.wash.name

    def image(k):
        return diffwash.render(scene, _set(params, "k_unlit", k))

    jac = jax.jit(jax.jacfwd(image))(params.k_unlit)
    assert jac.shape == (H, W, 3)
    _, jvp = jax.jit(lambda k: jax.jvp(lambda x: jnp.sum(image(x)), (k,), (jnp.ones_like(k),)))(params.k_unlit)
    np.testing.assert_allclose(float(jnp.sum(jac)), float(jvp), rtol=1e-10)
    np.testing.assert_allclose(float(grad.k_unlit), float(jvp), rtol=1e-10)


def _geometry_loss(scene, vis, weights):
    def loss(vertices, eye, fov_y):
        s = eqx.tree_at(lambda q: (q.mesh.vertices, q.camera.eye, q.camera.fov_y), scene, (vertices, eye, fov_y))
        return jnp.sum(diffwash.render_rgba(s, visibility=vis, antialias=True) * weights)

    return jax.jit(loss), jax.jit(jax.grad(loss, argnums=(0, 1, 2)))


@functools.cache
def _geometry_setup(shading):
    scene = small_scene(shading)
    vis = diffwash.rasterize(scene, antialias=True)
    return (scene, vis, *_geometry_loss(scene, vis, _weights((H, W, 4))))


def _geometry_args(scene):
    return jnp.asarray(scene.mesh.vertices), jnp.asarray(scene.camera.eye), jnp.asarray(scene.camera.fov_y)


@pytest.mark.parametrize("shading", ["per-pixel", "per-vertex"])
def test_vertex_and_camera_gradients_match_finite_differences(shading):
    """With antialiasing and a fixed visibility, the image is smooth in vertices and camera."""
    scene, vis, loss, grad = _geometry_setup(shading)
    assert int(jnp.sum(vis.silhouettes.a < W * H)) > 20  # silhouette work items exist
    v0, e0, f0 = _geometry_args(scene)
    gv, ge, gf = grad(v0, e0, f0)
    rng = np.random.default_rng(2)
    dv = jnp.asarray(rng.normal(size=v0.shape))
    assert_close_rel(jnp.sum(gv * dv), central_difference(lambda v: loss(v, e0, f0), v0, dv, 1e-6))
    de = jnp.asarray(rng.normal(size=3))
    assert_close_rel(jnp.sum(ge * de), central_difference(lambda e: loss(v0, e, f0), e0, de, 1e-6))
    assert_close_rel(gf, central_difference(lambda f: loss(v0, e0, f), f0, 1.0, 1e-6))


def test_traced_geometry_without_a_visibility():
    """Under jit/grad with traced vertices and camera, visibility comes from a host callback: same values and
    gradients as with the visibility given."""
    scene, vis, loss, grad = _geometry_setup("per-pixel")
    traced_loss, traced_grad = _geometry_loss(scene, None, _weights((H, W, 4)))
    args = _geometry_args(scene)
    np.testing.assert_allclose(float(traced_loss(*args)), float(loss(*args)), rtol=1e-12)
    for a, b in zip(traced_grad(*args), grad(*args)):
        np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-9, atol=1e-10)


def _quad_scene(angle_deg=20.0, width=48, height=32):
    a = np.radians(angle_deg)
    rot = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
    v = 0.5 * np.array([[-1.0, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]]) @ rot.T
    mesh = Mesh(vertices=v, faces=np.array([[0, 1, 2], [0, 2, 3]], np.int32), normals=np.tile([0, 0, 1.0], (4, 1)))
    cam = diffwash.Camera(eye=np.array([0.1, 0.2, 3.0]), target=np.zeros(3), up=np.array([0.0, 1.0, 0.0]),
                          fov_y=np.float64(30.0), near=np.float64(1.0), far=np.float64(5.0))  # fmt: skip
    scene = Scene(mesh=mesh, camera=cam, params=small_scene().params, width=width, height=height, backfaces="both")
    return scene, diffwash.rasterize(scene, antialias=True)


def _projected_area(scene, vertices):
    w, h = scene.width, scene.height
    vp = np.asarray(scene.camera.view_projection(w / h))
    c = np.c_[vertices, np.ones(len(vertices))] @ vp.T
    x = (c[:, 0] / c[:, 3] + 1) * w / 2
    y = (1 - c[:, 1] / c[:, 3]) * h / 2
    return 0.5 * abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


@functools.cache
def _quad_alpha():
    """Compiled (antialiased alpha sum, its derivatives in scale and sideways shift), for any quad scene."""

    @jax.jit
    @functools.partial(jax.value_and_grad, argnums=(1, 2))
    def alpha_sum(scene, scale, shift, vis):
        v = scene.mesh.vertices * scale + jnp.stack([shift, 0.0, 0.0])
        s = eqx.tree_at(lambda q: q.mesh.vertices, scene, v)
        return jnp.sum(diffwash.render_rgba(s, visibility=vis, antialias=True)[..., 3])

    return alpha_sum


@pytest.mark.parametrize("angle", [0.0, 20.0])
def test_antialiased_coverage_and_its_gradient_follow_the_true_area(angle):
    """Summed antialiased alpha ~ the quad's exact projected area; its derivative in scale ~ the area's."""
    scene, vis = _quad_scene(angle)
    v = np.asarray(scene.mesh.vertices)
    area = _projected_area(scene, v)
    point = float(jnp.sum(vis.tri_id >= 0))
    aa, (d_scale, d_shift) = _quad_alpha()(scene, jnp.float64(1), jnp.float64(0), vis)
    assert abs(float(aa) - area) < 0.2 * max(abs(point - area), 1.0) + 1.0
    # Per pixel, closer to 8x8 supersampled coverage than point sampling is.
    big = dataclasses.replace(scene, width=scene.width * 8, height=scene.height * 8)
    cover = (np.asarray(diffwash.rasterize(big).tri_id) >= 0).reshape(scene.height, 8, scene.width, 8).mean((1, 3))
    alpha = np.asarray(diffwash.render_rgba(scene, visibility=vis, antialias=True)[..., 3])
    point_err = np.abs((np.asarray(vis.tri_id) >= 0) - cover).sum()
    assert np.abs(alpha - cover).sum() < 0.3 * point_err
    h = 1e-4
    d_area = (_projected_area(scene, v * (1 + h)) - _projected_area(scene, v * (1 - h))) / (2 * h)
    np.testing.assert_allclose(float(d_scale), d_area, rtol=0.02)
    # Sliding sideways (parallel to the image plane) keeps the area: a small gradient next to the scale's.
    assert abs(float(d_shift)) < 0.05 * abs(d_area)


# ---------------------------------------------------------------------------
# No NaN or inf, in values or gradients, at the model's edges.


def _edge_cases(params):
    # Same pigment names (static metadata): one compiled gradient serves every case.
    zero_s = dataclasses.replace(params.wash, K=jnp.array([0.3, 1.2, 0.0]), S=jnp.array([0.0, 0.0, 0.0]))
    zero_k = dataclasses.replace(params.unlit, K=jnp.array([0.0, 0.0, 0.0]), S=jnp.array([0.5, 0.0, 0.2]))
    return {
        "zero thickness": dataclasses.replace(params, k_wash=jnp.float64(0), k_unlit=jnp.float64(0)),
        "S = 0 and K = 0": dataclasses.replace(params, wash=zero_s, unlit=zero_k),
        "shininess 0": dataclasses.replace(params, shininess=jnp.float64(0)),
        "gain and bias at their limits": dataclasses.replace(params, gain=jnp.float64(1.0), bias=jnp.float64(0.0)),
        "huge thickness": dataclasses.replace(params, k_wash=jnp.float64(1e4), k_unlit=jnp.float64(1e4)),
        "light towards the eye": dataclasses.replace(params, light=jnp.array([0.4, 0.6, 3.0])),
        "light from behind": dataclasses.replace(params, light=-jnp.array([0.4, 0.6, 3.0])),
        "black paper": dataclasses.replace(params, paper=jnp.zeros(3)),
    }


@pytest.mark.parametrize("case", list(_edge_cases(small_scene().params)))
@pytest.mark.parametrize("shading", ["per-pixel", "per-vertex"])
def test_finite_values_and_gradients_at_the_edges(case, shading):
    scene, vis, image, grads = _edge_setup(shading)
    params = _as_arrays(_edge_cases(scene.params)[case])
    img = image(params)
    assert bool(jnp.all(jnp.isfinite(img)))
    assert float(jnp.min(img)) >= -1e-12 and float(jnp.max(img)) <= 1 + 1e-12
    for g in jax.tree_util.tree_leaves(grads(params, jnp.asarray(scene.mesh.vertices))):
        assert bool(jnp.all(jnp.isfinite(g))), case


def _loss(scene, vis, params, vertices):
    s = eqx.tree_at(lambda q: q.mesh.vertices, scene, vertices)
    return jnp.sum(diffwash.render_rgba(s, params, visibility=vis, antialias=True) ** 2)


@functools.cache
def _edge_setup(shading):
    """An open-mesh scene (back faces drawn), its visibility, the compiled image and gradient (params, vertices).

    In front of the knot: a triangle whose normals are perpendicular to the view and opposite at two
    corners (so they cancel where interpolated), and a degenerate triangle.
    """
    knot = small_scene(shading, "both")
    extra_v = np.array([[-0.3, -0.3, 0.6], [0.3, -0.3, 0.6], [0.0, 0.3, 0.6], [0.1, 0.1, 0.65], [0.1, 0.1, 0.65]])
    extra_n = np.array([[1.0, 0, 0], [-1.0, 0, 0], [0, 1.0, 0], [0, 0, 1.0], [0, 0, 1.0]])
    n = len(knot.mesh.vertices)
    mesh = Mesh(
        vertices=np.concatenate([knot.mesh.vertices, extra_v]),
        faces=np.concatenate([knot.mesh.faces, [[n, n + 1, n + 2], [n + 3, n + 4, n + 3]]]).astype(np.int32),
        normals=np.concatenate([knot.mesh.normals, extra_n]),
    )
    scene = dataclasses.replace(knot, mesh=mesh)
    vis = diffwash.rasterize(scene, antialias=True)
    assert int(jnp.sum(vis.tri_id == len(knot.mesh.faces))) > 10  # the grazing triangle shows
    image = jax.jit(lambda p: diffwash.render_rgba(scene, p, visibility=vis, antialias=True))
    return scene, vis, image, jax.jit(jax.grad(functools.partial(_loss, scene, vis), argnums=(0, 1)))
