"""The forms the renderer uses for speed give the numbers of the forms the shaders mirror: the hatching's two-tone
reads (`hatch_ink_at`) against every tone sampled and blended (`hatch_ink(hatch_samples(...))`), values and
derivatives (float64); the shadow map from per-face depth planes against the barycentric interpolation it
replaces; and `apart` (a boundary for XLA's fusion) is the identity, differentiable, and jit- and vmap-safe."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from diffwash._meshes import torus_knot
from diffwash.look import _hatching, _shadow
from diffwash.ops import rasterize
from diffwash.look._xla import apart


@pytest.fixture(scope="module")
def tam():
    return _hatching.tonal_art_map(size=32, levels=3, seed=1)


def _points(n=300, seed=0):
    rng = np.random.default_rng(seed)
    P = rng.uniform(-1.5, 1.5, (n, 3))
    N = rng.normal(size=(n, 3))
    N /= np.linalg.norm(N, axis=1, keepdims=True)
    pixel = rng.uniform(0.0005, 0.05, n)  # footprints across every level
    tau = np.concatenate([rng.uniform(0, 1, n - 4), [0.0, 1.0, 0.5, 1e-3]])
    return jnp.asarray(P), jnp.asarray(N), jnp.asarray(pixel), jnp.asarray(tau)


@pytest.mark.parametrize("packed", [False, True])
def test_two_tone_reads_are_every_tone_blended(tam, packed):
    P, N, pixel, tau = _points()
    scale = 40.0
    want = _hatching.hatch_ink(_hatching.hatch_samples(tam, P, N, pixel, scale), tau)
    source = _hatching.pack_tam(tam) if packed else [jnp.asarray(level) for level in tam]
    got = jax.jit(lambda P, N, pixel, tau: _hatching.hatch_ink_at(source, P, N, pixel, scale, tau))(P, N, pixel, tau)
    np.testing.assert_allclose(np.asarray(got), np.asarray(want), rtol=1e-12, atol=1e-14)


def test_two_tone_reads_have_the_same_derivatives(tam):
    P, N, pixel, tau = _points(n=60, seed=3)
    tau = jnp.clip(tau, 0.01, 0.99) + 0.003  # away from the tones' kinks
    scale = 40.0
    weights = jnp.asarray(np.random.default_rng(4).normal(size=tau.shape))

    def f(P, N, pixel, tau):
        return jnp.vdot(weights, _hatching.hatch_ink_at(tam, P, N, pixel, scale, tau))

    def ref(P, N, pixel, tau):
        return jnp.vdot(weights, _hatching.hatch_ink(_hatching.hatch_samples(tam, P, N, pixel, scale), tau))

    got, want = jax.grad(f, argnums=(0, 1, 2, 3))(P, N, pixel, tau), jax.grad(ref, argnums=(0, 1, 2, 3))(P, N, pixel, tau)
    for g, w in zip(got, want):
        assert np.all(np.isfinite(np.asarray(g)))
        np.testing.assert_allclose(np.asarray(g), np.asarray(w), rtol=1e-10, atol=1e-10)
    # and against central differences in tau (float64)
    d = jnp.asarray(np.random.default_rng(5).normal(size=tau.shape))
    h = 1e-7
    fd = (f(P, N, pixel, tau + h * d) - f(P, N, pixel, tau - h * d)) / (2 * h)
    assert float(jnp.vdot(got[3], d)) == pytest.approx(float(fd), rel=1e-5)


def test_a_map_of_other_sides_is_refused():
    with pytest.raises(ValueError, match="powers of two"):
        _hatching.pack_tam([np.zeros((24, 24, 8)), np.zeros((12, 12, 8))])


def _barycentric_depth(vertices, faces, vp, tri):
    """The shadow map as it was computed before the plane form: each texel interpolates its face's corners."""
    rows, cols = tri.shape
    ndc = np.asarray(_shadow._project(jnp.asarray(vertices), jnp.asarray(vp)))
    p = ndc[np.asarray(faces)[np.maximum(tri, 0)]]
    x = (np.arange(cols) + 0.5) / cols * 2 - 1
    y = 1 - (np.arange(rows) + 0.5) / rows * 2
    px, py = x[None, :], y[:, None]
    a, b, c = p[..., 0, :], p[..., 1, :], p[..., 2, :]
    area = (b[..., 0] - a[..., 0]) * (c[..., 1] - a[..., 1]) - (c[..., 0] - a[..., 0]) * (b[..., 1] - a[..., 1])
    wb = (px - a[..., 0]) * (c[..., 1] - a[..., 1]) - (c[..., 0] - a[..., 0]) * (py - a[..., 1])
    wc = (b[..., 0] - a[..., 0]) * (py - a[..., 1]) - (px - a[..., 0]) * (b[..., 1] - a[..., 1])
    ok = (tri >= 0) & (area != 0)
    safe = np.where(ok, area, 1.0)
    z = a[..., 2] + (wb / safe) * (b[..., 2] - a[..., 2]) + (wc / safe) * (c[..., 2] - a[..., 2])
    return np.where(ok, np.clip((z + 1) / 2, 0.0, 1.0), 1.0)


def test_depth_planes_are_the_barycentric_interpolation():
    v, f, _ = torus_knot(60, 12)
    v, f = np.asarray(v, np.float64), np.asarray(f)
    vp = np.asarray(_shadow.light_view_projection(v, [1.0, 1.2, 0.8]))
    tri = np.asarray(rasterize(_shadow.light_clip(jnp.asarray(v), jnp.asarray(vp)), f, (64, 64)).tri_id)
    got = np.asarray(_shadow.light_depth(v, f, vp, tri))
    assert np.sum(tri >= 0) > 500
    np.testing.assert_allclose(got, _barycentric_depth(v, f, vp, tri), atol=1e-12)
    g = jax.grad(lambda v: jnp.sum(_shadow.light_depth(v, f, vp, tri)))(jnp.asarray(v))
    assert np.all(np.isfinite(np.asarray(g)))


def test_apart_is_the_identity_differentiable_and_batchable():
    x = jnp.linspace(-1.0, 2.0, 7)
    f = lambda x: apart(lambda a, b: jnp.sin(a) * b, x, 2 * x)  # noqa: E731
    np.testing.assert_allclose(np.asarray(jax.jit(f)(x)), np.sin(np.asarray(x)) * 2 * np.asarray(x), rtol=1e-15)
    g = jax.grad(lambda x: jnp.sum(f(x)))(x)
    np.testing.assert_allclose(np.asarray(g), 2 * (np.cos(x) * x + np.sin(x)), rtol=1e-12)
    np.testing.assert_allclose(np.asarray(jax.vmap(f)(jnp.stack([x, x]))), np.stack([f(x), f(x)]), rtol=1e-15)
    nan = jnp.asarray([jnp.nan, 1.0])
    assert np.isnan(np.asarray(apart(lambda a: a + 1, nan))[0])  # the other branch computes the same


def test_magnified_everywhere_reads_one_level_with_the_same_numbers_and_derivatives(tam):
    # Every footprint below a texel: the level of detail is clamped at 0 everywhere, so hatch_ink_at reads
    # level 0 alone (half the reads). Values and derivatives are those of every tone and level blended.
    P, N, _, tau = _points(n=80, seed=6)
    tau = jnp.clip(tau, 0.01, 0.99) + 0.003
    scale = 40.0
    pixel = jnp.asarray(np.random.default_rng(7).uniform(0.001, 0.02, tau.shape))  # x = pixel * scale < 1
    assert float(jnp.max(_hatching.hatch_lod(pixel, scale, len(tam)))) == 0.0
    weights = jnp.asarray(np.random.default_rng(8).normal(size=tau.shape))

    def f(P, N, pixel, tau):
        return jnp.vdot(weights, _hatching.hatch_ink_at(tam, P, N, pixel, scale, tau))

    def ref(P, N, pixel, tau):
        return jnp.vdot(weights, _hatching.hatch_ink(_hatching.hatch_samples(tam, P, N, pixel, scale), tau))

    assert float(f(P, N, pixel, tau)) == pytest.approx(float(ref(P, N, pixel, tau)), rel=1e-12)
    got, want = jax.grad(f, argnums=(0, 1, 2, 3))(P, N, pixel, tau), jax.grad(ref, argnums=(0, 1, 2, 3))(P, N, pixel, tau)
    for g, w in zip(got, want):
        np.testing.assert_allclose(np.asarray(g), np.asarray(w), rtol=1e-10, atol=1e-10)
    # One point minified: both levels are read again, and still agree.
    pixel2 = pixel.at[0].set(0.2)
    assert float(f(P, N, pixel2, tau)) == pytest.approx(float(ref(P, N, pixel2, tau)), rel=1e-12)
    # The choice is a conditional whose one-level branch has half the texel reads of the general one, and
    # none of its per-point reads of the level's side and offset (level 0's are constants there).
    jaxpr = jax.make_jaxpr(lambda P: _hatching.hatch_ink_at(tam, P, N, pixel, scale, tau))(P).jaxpr
    conds = [e for e in jaxpr.eqns if e.primitive.name == "cond"]
    reads = sorted(_count(b.jaxpr, "gather") for b in conds[-1].params["branches"])
    texels = 3 * 4 * 2  # projections, bilinear taps, tones; each branch's `apart` holds the reads twice
    assert reads == [2 * texels, 2 * (2 * texels + 3 * 2 * 2)]


def _count(jaxpr, name):
    """How many `name` equations `jaxpr` holds, those of its inner jaxprs (conditionals, jit) included."""
    n = 0
    for e in jaxpr.eqns:
        n += e.primitive.name == name
        for v in e.params.values():
            for j in v if isinstance(v, (tuple, list)) else [v]:
                if hasattr(j, "jaxpr") and hasattr(j.jaxpr, "eqns"):
                    n += _count(j.jaxpr, name)
                elif hasattr(j, "eqns"):
                    n += _count(j, name)
    return n
