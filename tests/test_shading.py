"""The shading model: Schlick's bias, Perlin's gain, thicknesses and glazes."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from diffwash import km, pigments
from diffwash.shading import Params, bias, gain, glaze, glaze_layers, thicknesses

unit = st.floats(0, 1)
open_unit = st.floats(0.01, 0.99)


@given(t=unit, b=open_unit)
def test_bias_laws(t, b):
    assert float(bias(t, 0.5)) == pytest.approx(t, abs=1e-15)
    assert float(bias(0.5, b)) == pytest.approx(b, rel=1e-12)  # Schlick: bias(1/2) = b
    assert float(bias(0.0, b)) == 0 and float(bias(1.0, b)) == pytest.approx(1.0, abs=1e-15)
    assert 0 <= float(bias(t, b)) <= 1 + 1e-15


@given(t=unit, g=open_unit)
def test_gain_laws(t, g):
    assert float(gain(t, 0.5)) == pytest.approx(t, abs=1e-15)
    assert float(gain(0.5, g)) == pytest.approx(0.5, abs=1e-15)
    assert float(gain(1 - t, g)) == pytest.approx(1 - float(gain(t, g)), abs=1e-12)  # odd about (1/2, 1/2)
    assert float(gain(0.25, g)) == pytest.approx((1 - g) / 2, rel=1e-12)


@given(t1=unit, t2=unit, p=open_unit)
def test_bias_and_gain_are_monotone(t1, t2, p):
    lo, hi = min(t1, t2), max(t1, t2)
    assert float(bias(lo, p)) <= float(bias(hi, p)) + 1e-15
    assert float(gain(lo, p)) <= float(gain(hi, p)) + 1e-15


def test_gain_and_bias_gradients_are_finite_everywhere():
    t = jnp.linspace(0, 1, 101)
    for p in (1e-6, 0.01, 0.5, 0.99, 1 - 1e-6, 0.0, 1.0):
        for f in (bias, gain):
            gt = jax.vmap(jax.grad(f, argnums=0), in_axes=(0, None))(t, p)
            gp = jax.vmap(jax.grad(f, argnums=1), in_axes=(0, None))(t, p)
            assert np.all(np.isfinite(gt)) and np.all(np.isfinite(gp)), (f.__name__, p)


def reference_thicknesses(N, L, V, c):
    """The issue's formulas, written out plainly in numpy."""

    def np_bias(t, b):
        return t / ((1 / b - 2) * (1 - t) + 1)

    def np_gain(t, g):
        return np.where(t < 0.5, np_bias(2 * t, 1 - g) / 2, 1 - np_bias(2 - 2 * t, 1 - g) / 2)

    H = (L + V) / np.linalg.norm(L + V, axis=-1, keepdims=True)
    w = (1 - np.clip(np.sum(H * N, -1), 0, 1) ** c["shininess"]) * c["k_specular"] * c["k_wash"]
    t = np.clip(1 - np.sum(L * N, -1), 0, 1)
    u = np_gain(np_bias(t, c["bias"]), c["gain"])
    return w * (1 - c["wash_reduction"] * u), c["k_unlit"] * u


def random_units(rng, n):
    v = rng.normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def make_params(**c):
    return Params(wash=pigments.load("Quinacridone Rose"), unlit=pigments.load("French Ultramarine"), **c)


CONSTANTS = dict(k_wash=1.3, k_specular=0.8, shininess=7.0, k_unlit=1.7, gain=0.35, bias=0.62, wash_reduction=0.4)


def test_thicknesses_match_the_formulas():
    rng = np.random.default_rng(0)
    N, L, V = random_units(rng, 500), random_units(rng, 500), random_units(rng, 500)
    p = make_params(**CONSTANTS)
    w, u = thicknesses(N, L, V, p)
    w_ref, u_ref = reference_thicknesses(N, L, V, CONSTANTS)
    np.testing.assert_allclose(w, w_ref, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(u, u_ref, rtol=1e-12, atol=1e-14)
    assert np.all(np.asarray(w) >= 0) and np.all(np.asarray(w) <= p.wash_max + 1e-12)
    assert np.all(np.asarray(u) >= 0) and np.all(np.asarray(u) <= p.unlit_max + 1e-12)


def test_glaze_is_unlit_on_wash_on_paper():
    p = make_params()
    w, u = 0.7, 0.4
    Rw, Tw = km.layer(p.wash.K, p.wash.S, w)
    Ru, Tu = km.layer(p.unlit.K, p.unlit.S, u)
    R, T = km.composite(Ru, Tu, Rw, Tw)
    np.testing.assert_allclose(glaze(p, w, u), km.over(R, T, p.paper), rtol=1e-14)
    np.testing.assert_allclose(glaze_layers(p, w, u), (R, T), rtol=1e-14)
    # No pigment: bare paper.
    np.testing.assert_allclose(glaze(p, 0.0, 0.0), p.paper, rtol=1e-15)


def _shade(params, N, L, V):
    w, u = thicknesses(N, L, V, params)
    return glaze(params, w, u)


def test_gradients_wrt_every_parameter_match_finite_differences():
    rng = np.random.default_rng(1)
    N, L, V = random_units(rng, 40), random_units(rng, 40), random_units(rng, 40)
    p = jax.tree_util.tree_map(jnp.asarray, make_params(**CONSTANTS))
    weights = jnp.asarray(rng.normal(size=(40, 3)))

    def loss(params):
        return jnp.sum(weights * _shade(params, N, L, V))

    grads = jax.grad(loss)(p)
    leaves, treedef = jax.tree_util.tree_flatten(p)
    gleaves = jax.tree_util.tree_leaves(grads)
    h = 1e-6
    for i, (leaf, g) in enumerate(zip(leaves, gleaves)):
        leaf = np.atleast_1d(np.asarray(leaf, float))
        for j in range(leaf.size):
            def at(delta):
                new = leaf.copy()
                new[j] += delta
                ls = list(leaves)
                ls[i] = new.reshape(np.shape(leaves[i]))
                return float(loss(jax.tree_util.tree_unflatten(treedef, ls)))

            fd = (at(h) - at(-h)) / (2 * h)
            np.testing.assert_allclose(np.atleast_1d(np.asarray(g))[j], fd, rtol=1e-4, atol=1e-7)


@pytest.mark.parametrize(
    "N, L, V",
    [
        ([0, 0, 1], [1, 0, 0], [0, 0, 1]),  # grazing light, N.L = 0
        ([0, 0, 1], [1, 0, 0], [-1, 0, 0]),  # light opposite the eye: L + V = 0
        ([0, 0, 1], [0, 0, -1], [0, 1, 0]),  # N.H = 0 exactly
        ([0, 0, 1], [0, 0, 1], [0, 0, 1]),  # mirror highlight, N.H = 1
    ],
)
def test_values_and_gradients_are_finite_at_grazing_angles(N, L, V):
    p = jax.tree_util.tree_map(jnp.asarray, make_params(shininess=0.0, gain=0.5, bias=0.5))
    args = [jnp.asarray(v, float) for v in (N, L, V)]
    assert np.all(np.isfinite(_shade(p, *args)))
    g = jax.grad(lambda q, n, l, v: jnp.sum(_shade(q, n, l, v)), argnums=(0, 1, 2, 3))(p, *args)
    assert all(np.all(np.isfinite(leaf)) for leaf in jax.tree_util.tree_leaves(g))


def test_extreme_constants_stay_finite():
    p = make_params(shininess=1e4, k_wash=1e3, k_unlit=1e3, gain=1e-9, bias=1 - 1e-9, wash_reduction=1.0)
    rng = np.random.default_rng(2)
    out = _shade(p, random_units(rng, 50), random_units(rng, 50), random_units(rng, 50))
    assert np.all(np.isfinite(out)) and np.all((np.asarray(out) >= 0) & (np.asarray(out) <= 1))
