"""When a fit is converged: at a minimum (the loss stopped falling, or a Gauss-Newton step would gain almost
nothing), never merely because it ran out of steps; a fit stopped far from a minimum says how far."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
import pytest
from test_mix_seen import _toy, _Traces

from diffwash.fit import _bandlsq
from diffwash.fit.tables import _pairs, _seen


def test_newton_decrement_is_the_share_of_the_loss_a_gauss_newton_step_removes():
    with jax.enable_x64(True):
        rng = np.random.default_rng(1)
        J, b = jnp.asarray(rng.normal(size=(12, 4))), jnp.asarray(rng.normal(size=12))
        x = jnp.zeros(4)
        r = J @ x - b
        f = jnp.sum(r * r)
        best = jnp.linalg.lstsq(J, b)[0]
        gained = (f - jnp.sum((J @ best - b) ** 2)) / f  # a linear problem: one Gauss-Newton step is exact
        assert float(_bandlsq.newton_decrement(J.T @ J, J.T @ r, f)) == pytest.approx(float(gained), rel=1e-4)
        # invariant to the parameters' scale: measured in the fit's own scale
        D = jnp.diag(jnp.asarray([1e-3, 1.0, 1e3, 7.0]))
        Js = J @ D
        assert float(_bandlsq.newton_decrement(Js.T @ Js, Js.T @ r, f)) == pytest.approx(float(gained), rel=1e-4)


def _refine(max_steps, rtol):
    reflect, obs, band0, shared0 = _toy()
    target = obs.lab(reflect(band0 + 0.4, shared0))
    prior = lambda s: 1e-3 * s  # noqa: E731
    return _seen.refine_in_de2000(reflect, obs.lab, target, (band0, shared0), ridge=1e-2, shared_prior=prior,
                                  max_steps=max_steps, rtol=rtol)  # fmt: skip


def test_a_fit_that_stalls_at_its_minimum_is_converged_though_out_of_steps():
    with jax.enable_x64(True):
        # rtol = 0: the decrease test never fires; the fit runs out of steps at its minimum
        _, conv, steps = _refine(max_steps=60, rtol=0.0)
        assert conv and conv.converged and conv.decrement <= _bandlsq.GN_TOL
        assert "at a minimum" in conv.describe() and "not" not in conv.describe()


def test_a_fit_stopped_far_from_its_minimum_says_how_far():
    with jax.enable_x64(True):
        _, conv, steps = _refine(max_steps=1, rtol=0.0)
        assert not conv and steps == 1 and conv.decrement > _bandlsq.GN_TOL
        text = conv.describe()
        assert "not at a minimum after 1 steps" in text and "Gauss-Newton step would lower its loss by" in text
        assert conv.to_dict()["gauss_newton_decrement"] == pytest.approx(conv.decrement)


def test_pair_terms_out_of_steps_at_their_minimum_are_converged():
    """The pair terms run a fixed number of steps: a pair still creeping at its minimum is converged."""
    with jax.enable_x64(True):
        def residuals(theta):  # a valley whose floor LM creeps along: at the minimum in few steps, never "still"
            return jnp.asarray([10 * (theta[1] - theta[0] ** 2), 1 - theta[0], 0.3])

        jacobians = jax.vmap(lambda th: (residuals(th), jax.jacfwd(residuals)(th)))  # one problem of a batch
        th, done, dec = _pairs._lm(jacobians, np.asarray([[1.0 + 1e-9, 1.0]]), 3)
        assert bool(done[0]) and float(dec[0]) <= _bandlsq.GN_TOL
        th, done, dec = _pairs._lm(jacobians, np.asarray([[-1.2, 1.0]]), 2)
        assert not bool(done[0]) and float(dec[0]) > _bandlsq.GN_TOL


def test_the_row_space_step_is_the_dense_step():
    """Tables with fewer colour residuals than band parameters take the Woodbury/Schur step: the same step."""
    with jax.enable_x64(True):
        reflect, obs, band0, shared0 = _toy()
        target = obs.lab(reflect(band0 + 0.3, shared0 * 2))[:3]  # 3 rows: 9 residuals < 14 band parameters
        few = lambda band, shared: reflect(band, shared)[:3]  # noqa: E731
        pb = _seen._Problem(few, obs.lab, target, band0, 0.5, lambda s: 0.1 * (s - 1.0))
        y = (band0 + 0.1, shared0 - 0.05)
        H, g = _seen._normal_equations(pb, y)
        for mu in (1e-6, 1e-2, 10.0):
            step, grad = _seen._row_step(_seen._jacobians(pb, y), 0.5, mu)
            np.testing.assert_allclose(step, _seen._dense_step(H, g, mu), rtol=1e-7, atol=1e-10)
            np.testing.assert_allclose(grad, g, rtol=1e-10, atol=1e-12)


class _Arrow(eqx.Module):
    """A small band-separable problem (3 bands of 2 parameters, one shared) that takes many steps to solve."""

    y: jax.Array

    def __call__(self, p, args):
        band, shared = p
        x = jnp.exp(band)
        rows = (x[:, :1] * jnp.linspace(0.0, 1.0, 5) + x[:, 1:] ** 2) * shared[0] - self.y
        return rows, 0.1 * (shared - 1.0)


def test_a_capped_solve_is_a_solve_of_that_many_steps_and_runs_the_bounds_compiled_program():
    """`BandLevenbergMarquardt(cap=k)` under `max_steps=n` stops where `max_steps=k` would, with the same result,
    and compiles nothing that `max_steps=n` did not: a fit's cross-validation folds reuse the fit's program."""
    with jax.enable_x64(True):
        fn = _Arrow(jnp.asarray(np.random.default_rng(0).uniform(1.0, 3.0, (3, 5))))
        y0 = (jnp.full((3, 2), -2.0), jnp.asarray([0.3]))
        solve = lambda n, cap=None: optx.least_squares(  # noqa: E731
            fn, _bandlsq.BandLevenbergMarquardt(rtol=1e-12, atol=1e-12, cap=cap), y0, max_steps=n, throw=False)
        short = solve(3)
        full = solve(60)
        assert int(full.stats["num_steps"]) > 3  # the cap below cuts a longer solve short
        # A program compiled, or read from the persistent cache (another test may have compiled it).
        events = "/jax/core/compile/backend_compile_duration", "/jax/compilation_cache/cache_retrieval_time_sec"
        with _Traces(*events) as compiles:
            capped = solve(60, cap=3)
        assert compiles.n == 0
        assert int(capped.stats["num_steps"]) == int(short.stats["num_steps"]) == 3
        assert capped.result == short.result == optx.RESULTS.nonlinear_max_steps_reached
        for a, b in zip(capped.value, short.value):
            np.testing.assert_allclose(a, b, rtol=1e-12)
        # A cap the solve does not reach changes nothing.
        np.testing.assert_array_equal(solve(60, cap=60).value[0], full.value[0])
        assert solve(60, cap=60).result == full.result
