"""diffwash.mixing: Duncan's laws with amount laws and mixing weights, as properties."""

import jax
import jax.numpy as jnp
import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from jax.test_util import check_grads

from diffwash import km, mixing

B = 5
floats = st.floats
amount = st.one_of(st.just(0.0), floats(1e-6, 0.2))
#: Each example runs Kubelka-Munk eagerly: a few dozen cover the laws and keep the file fast.
few = settings(max_examples=30)
positive = floats(0.05, 20.0)


def _pigments(seed, P=3):
    rng = np.random.default_rng(seed)
    K = rng.uniform(0.01, 8.0, (P, B))
    S = rng.uniform(0.0, 3.0, (P, B))
    law = mixing.AmountLaw(gamma=jnp.asarray(rng.uniform(0.2, 1.5, P)))
    w = rng.uniform(0.3, 3.0, P)
    ground = rng.uniform(0.2, 0.95, B)
    return K, S, law, w, ground


@few
@given(st.integers(0, 10_000), amount, amount)
def test_a_pigment_mixed_with_itself_is_itself_at_the_summed_amount(seed, a, b):
    K, S, law, w, ground = _pigments(seed, P=1)
    # The same pigment twice (two rows of the palette), any weights: the law sees the total.
    K2, S2 = np.concatenate([K, K]), np.concatenate([S, S])
    law2 = mixing.AmountLaw(gamma=jnp.concatenate([law.gamma, law.gamma]))
    twice = mixing.reflectance(K2, S2, np.array([a, b]), ground, law2, weights=np.array([w[0], w[0]]))
    once = mixing.reflectance(K, S, np.array([a + b]), ground, law)
    np.testing.assert_allclose(twice, once, rtol=1e-12, atol=1e-14)


@few
@given(st.integers(0, 10_000), st.lists(amount, min_size=3, max_size=3), st.permutations([0, 1, 2]))
def test_a_mixture_does_not_depend_on_the_order_of_its_pigments(seed, amounts, order):
    K, S, law, w, ground = _pigments(seed)
    a = np.asarray(amounts)
    o = np.asarray(order)
    ref = mixing.reflectance(K, S, a, ground, law, w)
    perm = mixing.reflectance(K[o], S[o], a[o], ground, mixing.AmountLaw(gamma=law.gamma[o]), w[o])
    np.testing.assert_allclose(perm, ref, rtol=1e-12, atol=1e-14)


@few
@given(st.lists(amount, min_size=4, max_size=4), st.lists(positive, min_size=4, max_size=4))
def test_concentrations_sum_to_one_or_are_all_zero(amounts, weights):
    c = np.asarray(mixing.concentrations(np.asarray(amounts), np.asarray(weights)))
    assert np.all(c >= 0)
    if sum(amounts) > 0:
        np.testing.assert_allclose(c.sum(), 1.0, rtol=1e-12)
    else:
        assert np.all(c == 0)


@few
@given(st.integers(0, 10_000), amount)
def test_duncan_is_the_weighted_sum_with_unit_weights(seed, a):
    K, S, law, _, _ = _pigments(seed, P=2)
    a2 = np.array([a, 2 * a])
    Kx, Sx = mixing.optical_depths(K, S, a2, law)
    t = np.asarray(law(3 * a))
    np.testing.assert_allclose(Kx, (t[0] * K[0] + 2 * t[1] * K[1]) / 3, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(Sx, (t[0] * S[0] + 2 * t[1] * S[1]) / 3, rtol=1e-12, atol=1e-12)


def test_single_pigment_is_km_layer_at_the_laws_thickness():
    K, S, law, w, ground = _pigments(1, P=1)
    a = 0.07
    t = float(law(a)[0])
    R, T = km.layer(K[0], S[0], t)
    np.testing.assert_allclose(mixing.reflectance(K, S, np.array([a]), ground, law, w), km.over(R, T, ground),
                               rtol=1e-12)  # fmt: skip
    np.testing.assert_allclose(law(mixing.REFERENCE_AMOUNT), 1.0)


def test_an_empty_layer_is_the_ground_with_finite_gradients():
    K, S, law, w, ground = _pigments(2)
    zero = np.zeros(3)
    np.testing.assert_allclose(mixing.reflectance(K, S, zero, ground, law, w), ground, rtol=1e-14)
    g = jax.grad(lambda a, gam: jnp.sum(mixing.reflectance(K, S, a, ground, mixing.AmountLaw(gam), w)),
                 argnums=(0, 1))(jnp.asarray(zero), law.gamma)  # fmt: skip
    assert all(bool(jnp.all(jnp.isfinite(x))) for x in g)


def test_gradients_match_finite_differences():
    K, S, law, w, ground = _pigments(3)

    def f(K, S, a, gamma, w):
        return mixing.reflectance(K, S, a, ground, mixing.AmountLaw(gamma), w, k2=0.6)

    args = tuple(map(jnp.asarray, (K, S, np.array([0.03, 0.0, 0.05]), law.gamma, w)))
    check_grads(f, args, order=1, modes=["fwd", "rev"], atol=1e-6, rtol=1e-5)


def test_saunderson_round_trip_and_limits():
    R = np.linspace(0, 1, 11)
    np.testing.assert_allclose(mixing.saunderson_out(mixing.saunderson_in(R, 0.6), 0.6), R, atol=1e-14)
    np.testing.assert_allclose(mixing.saunderson_out(np.array([0.0, 1.0]), 0.6), [0.0, 1.0])


def test_palette_is_a_pytree_and_batches_over_layers():
    K, S, law, w, ground = _pigments(4)
    pal = mixing.Palette(K=jnp.asarray(K), S=jnp.asarray(S), law=law, weights=jnp.asarray(w), names=("a", "b", "c"))
    amounts = np.array([[0.01, 0.02, 0.0], [0.0, 0.0, 0.04]])
    out = jax.jit(lambda p, a: p.reflectance(a, ground))(pal, amounts)
    assert out.shape == (2, B)
    np.testing.assert_allclose(out[1], mixing.reflectance(K[2:], S[2:], amounts[1, 2:], ground,
                                                          mixing.AmountLaw(law.gamma[2:])), rtol=1e-12)  # fmt: skip
