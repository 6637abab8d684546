"""Kubelka-Munk core: accuracy against mpmath, exact limits, laws, gradients."""

import itertools

import jax
import jax.numpy as jnp
import mpmath as mp
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import km_reference
from diffwash import km, pigments

mp.mp.dps = 50


# ----------------------------------------------------------------------------
# An independent high-precision reference.


def ref_beta(K, S, x):
    """The same layer through beta = sqrt(K(K+2S)) (complex when K(K+2S) < 0).

    Analytic in K, S and x around every point of the domain, edges included, so
    mpmath can differentiate it numerically at K = 0, S = 0 and x = 0.
    """
    beta = mp.sqrt(K * (K + 2 * S))
    sh = mp.sinh(beta * x) / beta if beta != 0 else x
    ch = mp.cosh(beta * x)
    d = (S + K) * sh + ch
    return mp.re(S * sh / d), mp.re(1 / d)


# ----------------------------------------------------------------------------
# Accuracy.


def _sample_points(n, seed):
    rng = np.random.default_rng(seed)
    K = rng.uniform(0, 10, n)
    S = rng.uniform(0, 10, n)
    # Thicknesses across scales: thin, unit, thick.
    x = np.concatenate([rng.uniform(0, 1e-3, n // 4), rng.uniform(0, 2, n // 4), rng.uniform(0, 1000, n - n // 2)])
    rng.shuffle(x)
    edges = [0.0, 1e-8, 1e-3, 0.5, 1.0, 10.0]
    grid = np.array(list(itertools.product(edges, edges, [0.0, 1e-6, 0.1, 1.0, 100.0, 1000.0])))
    return np.concatenate([K, grid[:, 0]]), np.concatenate([S, grid[:, 1]]), np.concatenate([x, grid[:, 2]])


@pytest.mark.parametrize("dtype, tol", [(np.float64, 1e-9), (np.float32, 2e-6)])
def test_layer_matches_high_precision_reference(dtype, tol):
    K, S, x = (a.astype(dtype) for a in _sample_points(800, seed=1))
    R, T = jax.jit(km.layer)(K, S, x)
    assert R.dtype == dtype and T.dtype == dtype
    ref = np.array([[float(v) for v in km_reference.layer(float(k), float(s), float(t))] for k, s, t in zip(K, S, x)])
    err = max(np.max(np.abs(np.asarray(R, np.float64) - ref[:, 0])), np.max(np.abs(np.asarray(T, np.float64) - ref[:, 1])))
    assert err <= tol, err


def test_layer_exact_limits():
    K = jnp.array([0.7, 2.0, 0.0])
    # S = 0: a pure absorber.
    R, T = km.layer(K, 0.0, 1.5)
    np.testing.assert_allclose(R, 0.0, atol=0)
    np.testing.assert_allclose(T, np.exp(-1.5 * np.asarray(K)), rtol=1e-15)
    # K = 0: a pure scatterer.
    R, T = km.layer(0.0, 2.0, 3.0)
    np.testing.assert_allclose([R, T], [6 / 7, 1 / 7], rtol=1e-15)
    # x = 0: the identity layer.
    R, T = km.layer(3.0, 4.0, 0.0)
    assert float(R) == 0.0 and float(T) == 1.0
    # K = S = 0: a clear layer.
    R, T = km.layer(0.0, 0.0, 5.0)
    assert float(R) == 0.0 and float(T) == 1.0


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_very_thick_layer_is_infinite_reflectance(dtype):
    K = np.array([0.22, 1.47, 0.57, 3.0, 1e-3], dtype)
    S = np.array([0.05, 0.003, 0.03, 0.0, 2.0], dtype)
    R, T = km.layer(K, S, dtype(1e6))
    assert np.all(np.isfinite(R)) and np.all(np.isfinite(T))
    np.testing.assert_array_equal(T, 0)
    np.testing.assert_allclose(R, km.infinite_reflectance(K, S), rtol=1e-6 if dtype == np.float32 else 1e-12)
    # And the textbook R_inf = 1 + K/S - sqrt((K/S)^2 + 2K/S) where S > 0.
    k = K[S > 0].astype(np.float64) / S[S > 0]
    np.testing.assert_allclose(
        np.asarray(km.infinite_reflectance(K, S))[S > 0], 1 + k - np.sqrt(k * k + 2 * k), rtol=5e-6 if dtype == np.float32 else 1e-9
    )


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("x", [1e15, 1e30, 3e38])
def test_a_layer_at_any_optical_depth_float32_holds_is_its_masstone(dtype, x):
    """(beta x)^2 overflows float32 past beta x ~ 1e19: the layer must still be its masstone, not black or NaN,
    with finite gradients (issue 23: an amount of 1e30 predicted black)."""
    K = np.array([1e28, 2.0, 0.5, 1e-3, 0.0, 1e12, 0.0], dtype)
    S = np.array([3e27, 1.0, 0.0, 2.0, 1.0, 1e-6, 0.0], dtype)
    R, T = km.layer(K, S, dtype(x))
    assert np.all(np.isfinite(R)) and np.all(np.isfinite(T))
    expected = np.array(km.infinite_reflectance(K, S), np.float64)
    expected[-1] = 0.0  # no paint at all: R = 0, T = 1 at any thickness
    np.testing.assert_allclose(R, expected, rtol=1e-5, atol=1e-30)
    assert np.all(T[:-1] <= 1.5 / x)  # opaque (a pure scatterer: T = 1 / (1 + S x))
    for arg in range(3):
        g = jax.grad(lambda *a: jnp.sum(km.layer(*a)[0] + km.layer(*a)[1]), argnums=arg)(K, S, dtype(x))
        assert np.all(np.isfinite(g)), (arg, g)
    # At x = 0 the largest coefficients are still no paint.
    R0, T0 = km.layer(K, S, dtype(0))
    np.testing.assert_array_equal(R0, 0)
    np.testing.assert_array_equal(T0, 1)


def test_infinite_reflectance_edges():
    assert float(km.infinite_reflectance(0.0, 1.0)) == 1.0
    assert float(km.infinite_reflectance(1.0, 0.0)) == 0.0
    assert float(km.infinite_reflectance(0.0, 0.0)) == 0.0
    g = jax.grad(lambda K, S: km.infinite_reflectance(K, S), argnums=(0, 1))
    for point in [(0.0, 0.0), (0.0, 1.0), (1.0, 0.0)]:
        assert all(np.isfinite(v) for v in g(*point))


# ----------------------------------------------------------------------------
# Gradients.

EDGE_POINTS = [
    (0.0, 0.0, 0.0),
    (0.0, 0.0, 1.0),
    (0.0, 1.0, 1.0),
    (1.0, 0.0, 1.0),
    (1.0, 1.0, 0.0),
    (0.0, 2.0, 0.0),
    (0.5, 0.3, 1.0),
    (0.0, 0.0, 1e6),
    (1.0, 1.0, 1e6),
    (1e-30, 1.0, 1e6),
    (10.0, 10.0, 1000.0),
]


@pytest.mark.parametrize("point", EDGE_POINTS)
def test_gradients_finite_forward_and_reverse(point):
    def f(v):
        return jnp.stack(km.layer(v[0], v[1], v[2]))

    v = jnp.array(point)
    rev = jax.jacrev(f)(v)
    fwd = jax.jacfwd(f)(v)
    assert np.all(np.isfinite(rev)) and np.all(np.isfinite(fwd))
    np.testing.assert_allclose(rev, fwd, rtol=1e-9, atol=1e-300)
    hess = jax.hessian(lambda v: f(v).sum())(v)
    assert np.all(np.isfinite(hess))


@pytest.mark.parametrize("point", [p for p in EDGE_POINTS if p[2] < 1e5])
def test_gradients_match_mpmath_derivatives_at_edges(point):
    """The derivative at K = 0, S = 0 and x = 0 equals the analytic one (mpmath)."""
    jac = np.asarray(jax.jacrev(lambda v: jnp.stack(km.layer(*v)))(jnp.array(point)))
    for out in range(2):
        for arg in range(3):

            def g(t, out=out, arg=arg):
                p = [mp.mpf(c) for c in point]
                p[arg] = p[arg] + t
                return ref_beta(*p)[out]

            d = float(mp.diff(g, 0))
            np.testing.assert_allclose(jac[out, arg], d, rtol=1e-8, atol=1e-10, err_msg=f"d{'RT'[out]}/d{'KSx'[arg]}")


def central_difference(f, x, h):
    return (f(x + h) - f(x - h)) / (2 * h)


_layer_jac = jax.jit(jax.jacfwd(lambda v: jnp.stack(km.layer(*v))))
_layer_jit = jax.jit(lambda v: jnp.stack(km.layer(*v)))


@given(
    K=st.floats(0.01, 5),
    S=st.floats(0.01, 5),
    x=st.floats(0.01, 10),
)
def test_gradients_match_finite_differences(K, S, x):
    v = np.array([K, S, x])
    jac = np.asarray(_layer_jac(v))
    for arg in range(3):
        e = np.zeros(3)
        e[arg] = 1.0
        fd = central_difference(lambda t: np.asarray(_layer_jit(v + t * e)), 0.0, 1e-6)
        np.testing.assert_allclose(jac[:, arg], fd, rtol=1e-5, atol=1e-8)


# ----------------------------------------------------------------------------
# Laws (property tests).

coef = st.floats(0, 10, allow_subnormal=False)
thick = st.floats(0, 1000, allow_subnormal=False)


@given(K=coef, S=coef, x=thick)
def test_R_T_are_fractions_of_the_light(K, S, x):
    R, T = km.layer(K, S, x)
    assert 0 <= R <= 1 and 0 <= T <= 1
    assert R + T <= 1 + 1e-15


@given(K=coef, S=coef, x1=thick, x2=thick)
def test_thicker_layers_reflect_more_and_transmit_less(K, S, x1, x2):
    lo, hi = min(x1, x2), max(x1, x2)
    R1, T1 = km.layer(K, S, lo)
    R2, T2 = km.layer(K, S, hi)
    assert R2 >= R1 - 1e-15
    assert T2 <= T1 + 1e-15


@given(K=coef, S=coef, x1=st.floats(0, 10), x2=st.floats(0, 10))
def test_two_coats_of_a_pigment_are_one_thicker_coat(K, S, x1, x2):
    """Compositing layers of the same pigment adds their thicknesses."""
    R, T = km.composite(*km.layer(K, S, x1), *km.layer(K, S, x2))
    R12, T12 = km.layer(K, S, x1 + x2)
    np.testing.assert_allclose([R, T], [R12, T12], rtol=1e-9, atol=1e-12)


layer_st = st.tuples(coef, coef, st.floats(0, 10)).map(lambda a: km.layer(*a))


stack_st = layer_st.map(lambda rt: (rt[0], rt[0], rt[1]))


@given(a=stack_st, b=stack_st, c=stack_st, d=stack_st)
def test_composite_is_associative(a, b, c, d):
    """Stacking is associative once stacks carry their reflectance from below."""
    cs = km.composite_stack
    left = cs(cs(cs(a, b), c), d)
    right = cs(a, cs(b, cs(c, d)))
    middle = cs(cs(a, b), cs(c, d))
    np.testing.assert_allclose(left, right, rtol=1e-10, atol=1e-13)
    np.testing.assert_allclose(middle, right, rtol=1e-10, atol=1e-13)


@given(a=layer_st, b=layer_st, c=layer_st)
def test_composite_builds_stacks_from_the_bottom_up(a, b, c):
    """composite() with a single layer on top is composite_stack's (R, T)."""
    R, T = km.composite(*a, *km.composite(*b, *c))
    full = km.composite_stack((a[0], a[0], a[1]), km.composite_stack((b[0], b[0], b[1]), (c[0], c[0], c[1])))
    np.testing.assert_allclose([R, T], [full[0], full[2]], rtol=1e-12, atol=1e-15)


def test_composite_stack_of_one_pigment_is_symmetric():
    R, Rb, T = km.composite_stack((*[km.layer(1.0, 2.0, 0.3)[0]] * 2, km.layer(1.0, 2.0, 0.3)[1]),
                                  (*[km.layer(1.0, 2.0, 0.6)[0]] * 2, km.layer(1.0, 2.0, 0.6)[1]))
    np.testing.assert_allclose([R, Rb, T], [*[km.layer(1.0, 2.0, 0.9)[0]] * 2, km.layer(1.0, 2.0, 0.9)[1]], rtol=1e-12)


@given(a=layer_st, K=coef, S=coef)
def test_zero_thickness_is_the_identity_layer(a, K, S):
    ident = km.layer(K, S, 0.0)
    np.testing.assert_allclose(km.composite(*ident, *a), a, rtol=1e-14, atol=1e-15)
    np.testing.assert_allclose(km.composite(*a, *ident), a, rtol=1e-14, atol=1e-15)


@given(a=layer_st, g=st.floats(0, 1))
def test_over_is_composite_with_an_opaque_ground(a, g):
    np.testing.assert_allclose(km.over(*a, g), km.composite(*a, g, 0.0)[0], rtol=1e-14)
    assert 0 <= km.over(*a, g) <= 1


@given(K=st.floats(1e-9, 10), S=st.floats(1e-9, 10), x_thin=st.floats(0, 1e-6))
def test_thin_layers_converge_to_identity(K, S, x_thin):
    """R <= S x and 1 - T <= (K + S) x: the layer tends to the identity as x -> 0."""
    R, T = km.layer(K, S, x_thin)
    assert R <= S * x_thin * (1 + 1e-9)
    assert 1 - T <= (K + S) * x_thin * (1 + 1e-9) + 4e-16  # a few ulps of 1


def test_degenerate_composite_is_finite():
    R, T = km.composite(1.0, 0.0, 1.0, 0.0)
    assert float(R) == 1.0 and float(T) == 0.0
    g = jax.grad(lambda r: km.composite(r, 0.0, 1.0, 0.0)[0])(1.0)
    assert np.isfinite(g)


# ----------------------------------------------------------------------------
# Inversion.


def test_inversion_round_trips_the_seed_pigments():
    for p in pigments.library().values():
        R, T = km.layer(p.K, p.S, 1.0)
        R_white = km.over(R, T, 1.0)
        K, S = km.invert_black_white(R_white, R)
        np.testing.assert_allclose(K, p.K, rtol=1e-9, err_msg=p.name)
        np.testing.assert_allclose(S, p.S, rtol=1e-9, err_msg=p.name)


@given(K=st.floats(0.01, 5), S=st.floats(0.01, 5))
def test_inversion_round_trips(K, S):
    R, T = km.layer(K, S, 1.0)
    K2, S2 = km.invert_black_white(km.over(R, T, 1.0), R)
    np.testing.assert_allclose([K2, S2], [K, S], rtol=1e-7)


@given(Rw=st.floats(-1, 2, allow_nan=False), Rb=st.floats(-1, 2, allow_nan=False))
def test_inversion_is_finite_outside_its_domain(Rw, Rb):
    K, S = km.invert_black_white(Rw, Rb)
    assert np.isfinite(K) and np.isfinite(S) and K >= 0 and S >= 0
    g = jax.grad(lambda a, b: sum(km.invert_black_white(a, b)), argnums=(0, 1))(Rw, Rb)
    assert all(np.isfinite(v) for v in g)


def test_inversion_float32_is_finite():
    Rw = np.array([0.9, 0.5, 0.999999, 0.2, 0.0], np.float32)
    Rb = np.array([0.1, 0.49, 0.5, 0.3, 0.0], np.float32)
    K, S = km.invert_black_white(Rw, Rb)
    assert K.dtype == np.float32
    assert np.all(np.isfinite(K)) and np.all(np.isfinite(S))


# ----------------------------------------------------------------------------
# Shapes and transformations.


def test_broadcasting_jit_and_vmap():
    p = pigments.load("Cadmium Yellow")
    x = jnp.linspace(0, 4, 20).reshape(4, 5, 1)
    R, T = km.layer(p.K, p.S, x)
    assert R.shape == T.shape == (4, 5, 3)
    Rj, Tj = jax.jit(km.layer)(p.K, p.S, x)
    np.testing.assert_allclose(R, Rj, rtol=1e-14)
    Rv, Tv = jax.vmap(km.layer, in_axes=(None, None, 0))(p.K, p.S, x)
    np.testing.assert_allclose(R, Rv, rtol=1e-14)


def test_float32_stays_float32_and_weak_types_follow():
    R, T = km.layer(np.float32(1.0), np.float32(0.5), 2.0)
    assert R.dtype == np.float32
    R, T = km.layer(1.0, 0.5, 2.0)
    assert R.dtype == np.float64  # x64 enabled in the tests


def test_negative_thickness_is_treated_as_zero():
    R, T = km.layer(1.0, 1.0, -3.0)
    assert float(R) == 0.0 and float(T) == 1.0
