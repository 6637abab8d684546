"""Gradients of every continuous look parameter against central finite differences (float64), and no NaN or inf
at the edges (zero strengths, zero width, bare paper)."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from diffwash import shading
from diffwash.look import _edges, _hatching, _look, _mix, _paper, _shadow, _textures
from diffwash.pigments import Pigment

H, W = 18, 16
ROSE = Pigment(K=np.array([0.22, 1.47, 0.57]), S=np.array([0.05, 0.003, 0.03]), density=0.02, staining=5.5, granularity=0.81)
ULTRAMARINE = Pigment(K=np.array([0.86, 0.86, 0.06]), S=np.array([0.005, 0.005, 0.09]), density=0.01, staining=3.1, granularity=0.91)
UMBER = Pigment(K=np.array([0.74, 1.54, 2.1]), S=np.array([0.09, 0.09, 0.004]), density=0.09, staining=9.3, granularity=0.9)
GREEN = Pigment(K=np.array([1.55, 0.47, 0.63]), S=np.array([0.01, 0.05, 0.035]), density=0.02, staining=1.0, granularity=0.12)
PARAMS = shading.Params(wash=ROSE, unlit=ULTRAMARINE)
FIELDS = ["edge_darkening", "edge_width", "granulation", "density", "turbulence", "dispersion", "paper_shading", "strokes"]
SURFACE_FIELDS = ["shadow", "hatching"]


def central_difference(f, x, direction, h):
    return (f(x + h * direction) - f(x - h * direction)) / (2 * h)


def assert_close_rel(ad, fd, rel=1e-4):
    ad, fd = float(ad), float(fd)
    assert abs(ad - fd) <= rel * max(abs(fd), 1e-3), (ad, fd, abs(ad - fd) / max(abs(fd), 1e-12))


def _gbuffer(seed=0):
    rng = np.random.default_rng(seed)
    g = np.zeros((H, W, 4))
    yy, xx = np.mgrid[0:H, 0:W]
    inside = (yy - 8.5) ** 2 / 49 + (xx - 7.5) ** 2 / 36 < 1
    smooth = lambda: 0.6 + 0.3 * np.sin(0.4 * yy + rng.uniform(0, 6)) * np.cos(0.3 * xx + rng.uniform(0, 6))  # noqa: E731
    g[..., 0] = np.where(inside, smooth(), 0)
    g[..., 1] = np.where(inside, smooth() * 0.8, 0)
    g[..., 2] = np.where(inside, 0.5 + 0.4 * np.sin(0.5 * xx), 0)
    g[..., 3] = np.where(inside, np.sin(0.7 * xx + 0.2 * yy), 0)  # the stroke layer
    return jnp.asarray(g)


@pytest.fixture(scope="module")
def setup():
    screen = _textures.screen_textures(shape=(16, 16), seed=4)
    tiled = jnp.asarray(_textures.tile(screen, H, W), jnp.float64)
    pigs = _look.Pigments(*(_paper.pigment_look(p, screen.paper) for p in (ROSE, UMBER, ULTRAMARINE, GREEN)))
    weights = jnp.asarray(np.random.default_rng(9).uniform(0.5, 1.5, (H, W, 3)))

    def glaze(w, u, m):
        return _mix.glaze_mix(PARAMS, UMBER, GREEN, w, u, m)

    def loss(look, g):
        return jnp.sum(_look.compose(g, tiled, look, pigs, glaze) * weights)

    # One compiled value-and-gradient for every test of the module (same shapes).
    return jax.jit(loss), jax.jit(jax.value_and_grad(loss, argnums=(0, 1))), glaze, tiled, pigs


def _look64(**kw):
    return jax.tree_util.tree_map(lambda x: jnp.asarray(x, jnp.float64), _look.Look(**kw))


def test_image_parameters_gradients(setup):
    loss, vg, *_ = setup
    look = _look64()
    g = _gbuffer()
    _, (grad, _) = vg(look, g)
    for name in FIELDS:
        x0 = getattr(look, name)
        ad = getattr(grad, name)
        assert bool(jnp.isfinite(ad)), name
        fd = central_difference(lambda x: loss(eqx.tree_at(lambda q: getattr(q, name), look, x), g), x0, 1.0, 1e-6)
        assert_close_rel(ad, fd)
        assert abs(float(ad)) > 0, name  # every parameter shows in the image


def test_mix_map_gradient(setup):
    """The per-pixel mix (an interpolated per-vertex map) is differentiable, through the glaze and the paper terms."""
    loss, vg, *_ = setup
    look = _look64()
    g = _gbuffer()
    ad = vg(look, g)[1][1][..., 2]
    d = jnp.asarray(np.random.default_rng(2).normal(size=(H, W))) * g[..., 3]
    fd = central_difference(lambda m: loss(look, g.at[..., 2].set(m)), g[..., 2], d, 1e-6)
    assert_close_rel(jnp.sum(ad * d), fd)
    assert float(jnp.max(jnp.abs(ad))) > 0


def test_surface_parameters_gradients():
    rng = np.random.default_rng(3)
    n = 200
    wash, unlit = jnp.asarray(rng.uniform(0, 1, n)), jnp.asarray(rng.uniform(0, 1.2, n))
    sh = jnp.asarray(rng.uniform(0, 1, n))
    tam = _hatching.tonal_art_map(size=16, levels=2, seed=1)
    hatch = jnp.asarray(tam[0].reshape(-1, 8)[:n], jnp.float64)
    wts = jnp.asarray(rng.uniform(0.5, 1.5, (2, n)))

    def loss(look):
        w, u = _look.surface_terms(wash, unlit, look, unlit_max=1.2, shadow=sh, hatch=hatch)
        return jnp.sum(wts[0] * w + wts[1] * u)

    look = _look64(hatching=0.5)
    grad = jax.jit(jax.grad(loss))(look)
    loss = jax.jit(loss)
    for name in SURFACE_FIELDS:
        x0 = getattr(look, name)
        fd = central_difference(lambda x: loss(eqx.tree_at(lambda q: getattr(q, name), look, x)), x0, 1.0, 1e-6)
        assert_close_rel(getattr(grad, name), fd)
        assert abs(float(getattr(grad, name))) > 0, name


def test_everything_off_is_the_plain_model(setup):
    """With every strength and width at 0 the look is the identity: `compose` gives the glaze of the G-buffer."""
    _, _, glaze, tiled, pigs = setup
    g = _gbuffer()
    off = _look64(**{k: 0.0 for k in _look.DEFAULT_LOOK})
    got = jax.jit(lambda lk, gb: _look.compose(gb, tiled, lk, pigs, glaze))(off, g)
    np.testing.assert_allclose(got, jax.jit(glaze)(g[..., 0], g[..., 1], g[..., 2]), rtol=1e-12, atol=1e-14)
    w, u = _look.surface_terms(g[..., 0], g[..., 1], off, unlit_max=1.0, shadow=g[..., 2], hatch=jnp.ones((H, W, 8)))
    np.testing.assert_allclose(w, g[..., 0])
    np.testing.assert_allclose(u, g[..., 1])


@pytest.mark.parametrize("case", ["all-zero", "zero-width", "bare-paper", "zero-unlit-max"])
def test_finite_values_and_gradients_at_the_edges(setup, case):
    _, vg, *_ = setup
    look = _look64()
    g = _gbuffer()
    if case == "all-zero":
        look = _look64(**{k: 0.0 for k in _look.DEFAULT_LOOK})
    elif case == "zero-width":
        look = _look64(edge_width=0.0)
    elif case == "bare-paper":
        g = jnp.zeros_like(g)
    value, grad = vg(look, g)
    assert bool(jnp.isfinite(value))
    for leaf in jax.tree_util.tree_leaves(grad):
        assert bool(jnp.all(jnp.isfinite(leaf))), case
    if case == "zero-unlit-max":
        f = lambda lk: jnp.sum(jnp.stack(_look.surface_terms(g[..., 0], g[..., 1] * 0, lk, unlit_max=0.0, shadow=g[..., 2],  # noqa: E731
                                                             hatch=jnp.ones((H, W, 8)))))  # fmt: skip
        for leaf in jax.tree_util.tree_leaves(jax.grad(f)(look)):
            assert bool(jnp.isfinite(leaf))


def test_gaussian_weights_at_zero_width():
    w, dw = jax.jit(lambda s, t: jax.jvp(lambda s: _edges.gaussian_weights(s, 3), (s,), (t,)))(jnp.asarray(0.0, jnp.float64), jnp.asarray(1.0, jnp.float64))
    np.testing.assert_array_equal(w, [0, 0, 0, 1, 0, 0, 0])
    assert bool(jnp.all(jnp.isfinite(dw)))
    s = jnp.asarray(0.7, jnp.float64)
    ad = jax.jit(jax.jacfwd(lambda s: _edges.gaussian_weights(s, 3)))(s)
    fd = central_difference(lambda s: _edges.gaussian_weights(s, 3), s, 1.0, 1e-6)
    np.testing.assert_allclose(ad, fd, rtol=1e-6, atol=1e-9)


def test_glaze_mix_gradients():
    """The mixed glaze is differentiable in both pigments of each pair and in the mix."""
    rng = np.random.default_rng(5)
    w, u, m = (jnp.asarray(rng.uniform(0, 1, 50)) for _ in range(3))

    def loss(a, b, mix):
        return jnp.sum(_mix.glaze_mix(shading.Params(wash=a, unlit=ULTRAMARINE), b, GREEN, w, u, mix))

    a = jax.tree_util.tree_map(jnp.asarray, Pigment(K=ROSE.K, S=ROSE.S))
    b = jax.tree_util.tree_map(jnp.asarray, Pigment(K=UMBER.K, S=UMBER.S))
    ga, gb, gm = jax.jit(jax.grad(loss, argnums=(0, 1, 2)))(a, b, m)
    loss = jax.jit(loss)
    d = jnp.asarray(rng.normal(size=3))
    fd = central_difference(lambda K: loss(eqx.tree_at(lambda p: p.K, a, K), b, m), a.K, d, 1e-6)
    assert_close_rel(jnp.sum(ga.K * d), fd)
    fd = central_difference(lambda S: loss(a, eqx.tree_at(lambda p: p.S, b, S), m), b.S, d, 1e-6)
    assert_close_rel(jnp.sum(gb.S * d), fd)
    dm = jnp.asarray(rng.normal(size=50))
    assert_close_rel(jnp.sum(gm * dm), central_difference(lambda x: loss(a, b, x), m, dm, 1e-6))


def test_shadow_gradients_in_positions_and_light():
    """The shadow factor moves with the point and the light (through the tent weights)."""
    rng = np.random.default_rng(6)
    depth = jnp.asarray(rng.uniform(0.3, 0.7, (12, 12)))
    vertices = jnp.asarray(rng.uniform(-1, 1, (30, 3)))
    P = jnp.asarray(rng.uniform(-0.8, 0.8, (40, 3)))
    wts = jnp.asarray(rng.uniform(0.5, 1.5, 40))

    def loss(P, light):
        return jnp.sum(wts * _shadow.shadow(depth, _shadow.light_view_projection(vertices, light), P, 0.0))

    light = jnp.asarray([0.3, 1.0, 0.4])
    gP, gl = jax.jit(jax.grad(loss, argnums=(0, 1)))(P, light)
    loss = jax.jit(loss)
    dP = jnp.asarray(rng.normal(size=P.shape))
    assert_close_rel(jnp.sum(gP * dP), central_difference(lambda x: loss(x, light), P, dP, 1e-7))
    dl = jnp.asarray(rng.normal(size=3))
    assert_close_rel(jnp.sum(gl * dl), central_difference(lambda x: loss(P, x), light, dl, 1e-7))
    assert float(jnp.max(jnp.abs(gP))) > 0


@pytest.mark.parametrize("factor", [2, 4])
def test_edge_gradients_at_reduced_resolution(factor):
    """Strength and width through the reduced-resolution blur (as at 512^2 and 1024^2)."""
    rng = np.random.default_rng(7)
    t = np.zeros((34, 30, 2))
    t[5:28, 4:25] = rng.uniform(0.3, 1.0, (23, 21, 2))
    t = jnp.asarray(t)
    wts = jnp.asarray(rng.uniform(0.5, 1.5, t.shape))
    loss = jax.jit(lambda k, s: jnp.sum(wts * _edges.edge_darkening(t, k, s, factor=factor)))
    gk, gs = jax.jit(jax.grad(loss, argnums=(0, 1)))(jnp.asarray(1.5), jnp.asarray(3.0))
    assert_close_rel(gk, central_difference(lambda k: loss(k, 3.0), 1.5, 1.0, 1e-6))
    assert_close_rel(gs, central_difference(lambda s: loss(1.5, s), 3.0, 1.0, 1e-6))
    assert abs(float(gs)) > 0
