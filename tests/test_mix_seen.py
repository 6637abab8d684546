"""The CIEDE2000 refinement of spectral mixture fits (diffwash.fit.tables._seen): its structured Jacobian is the
true one, it lowers the colour error it is built for, and the command line can switch it off."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import ROOT, write_spectral_table

import diffwash._cache
from diffwash import colorimetry, measurements, spectral
from diffwash.cli import main
from diffwash.fit import MixModel, fit_mixtures
from diffwash.fit.tables import _seen

NTU = ROOT / "data" / "ntu-wpsm" / "ntu-spectral-train.csv"


def _toy(dtype=jnp.float64):
    """Rows whose band b reflectance depends on band b's parameters and the shared ones only."""
    rng = np.random.default_rng(0)
    N, B, Q = 9, 7, 2
    X = jnp.asarray(rng.uniform(0.2, 1.0, (N, Q)), dtype)
    grid = tuple(float(w) for w in np.linspace(400, 700, B))
    obs = spectral.observation(grid)

    def reflect(band, shared):  # (B, Q), (G,) -> (N, B) in (0, 1)
        z = X @ band.T + shared[0] * X[:, :1] ** 2 + shared[1]
        return jax.nn.sigmoid(z)

    band0 = jnp.asarray(rng.normal(0, 1, (B, Q)), dtype)
    shared0 = jnp.asarray([0.3, -0.2], dtype)
    return reflect, obs, band0, shared0


def test_the_structured_normal_equations_are_the_dense_ones():
    with jax.enable_x64(True):
        reflect, obs, band0, shared0 = _toy()
        target = obs.lab(reflect(band0 + 0.3, shared0 * 2))
        prior = lambda s: 0.1 * (s - 1.0)  # noqa: E731
        pb = _seen._Problem(reflect, obs.lab, target, band0, 0.5, prior)
        loss, normal = (lambda y: _seen._linearised(pb, y, False)[1]), (lambda y: _seen._normal_equations(pb, y))
        y = (band0 + 0.1, shared0 - 0.05)

        def flat_residuals(theta):
            band = theta[: band0.size].reshape(band0.shape)
            shared = theta[band0.size :]
            r = colorimetry.delta_e_2000_residuals(target, obs.lab(reflect(band, shared)))
            return jnp.concatenate([r.ravel(), 0.5 * (band - band0).ravel(), prior(shared)])

        theta = jnp.concatenate([y[0].ravel(), y[1]])
        J = jax.jacfwd(flat_residuals)(theta)
        H, g = normal(y)
        np.testing.assert_allclose(H, J.T @ J, rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(g, J.T @ flat_residuals(theta), rtol=1e-9, atol=1e-9)
        assert float(loss(y)) == pytest.approx(float(jnp.sum(flat_residuals(theta) ** 2)), rel=1e-12)


def test_refinement_recovers_a_colour_target_from_a_wrong_start():
    with jax.enable_x64(True):
        reflect, obs, band0, shared0 = _toy()
        target = obs.lab(reflect(band0 + 0.4, shared0))
        prior = lambda s: 1e-3 * s  # noqa: E731
        (band, shared), ok, steps = _seen.refine_in_de2000(reflect, obs.lab, target, (band0, shared0), ridge=1e-4,
                                                           shared_prior=prior, max_steps=200, rtol=1e-10)  # fmt: skip
        de = colorimetry.delta_e_2000(target, obs.lab(reflect(band, shared)))
        de0 = colorimetry.delta_e_2000(target, obs.lab(reflect(band0, shared0)))
        assert ok and steps > 1
        assert float(jnp.max(de)) < 0.05 < float(jnp.mean(de0))


def test_the_normal_equations_in_a_basis_are_the_dense_ones_of_its_coefficients():
    """With a basis Phi, band = band0 + Phi C: the matrix and gradient are J^T J and J^T r over (C, shared)."""
    with jax.enable_x64(True):
        reflect, obs, band0, shared0 = _toy()
        target = obs.lab(reflect(band0 + 0.3, shared0 * 2))
        prior = lambda s: 0.1 * (s - 1.0)  # noqa: E731
        phi = jnp.asarray(_seen.smooth_basis(obs.wavelengths, 100.0))
        B, K = phi.shape
        Q = band0.shape[1]
        pb = _seen._Problem(reflect, obs.lab, target, band0, 0.5, prior, None, phi)
        C = jnp.asarray(np.random.default_rng(1).normal(0, 0.1, (K, Q)))
        shared = shared0 - 0.05

        def flat_residuals(theta):
            band = band0 + phi @ theta[: K * Q].reshape(K, Q)
            r = colorimetry.delta_e_2000_residuals(target, obs.lab(reflect(band, theta[K * Q :])))
            return jnp.concatenate([r.ravel(), 0.5 * (band - band0).ravel(), prior(theta[K * Q :])])

        theta = jnp.concatenate([C.ravel(), shared])
        J = jax.jacfwd(flat_residuals)(theta)
        H, g = _seen._normal_equations(pb, (band0 + phi @ C, shared))
        assert H.shape == (K * Q + 2, K * Q + 2)
        np.testing.assert_allclose(H, J.T @ J, rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(g, J.T @ flat_residuals(theta), rtol=1e-9, atol=1e-9)


def test_the_identity_basis_is_the_refinement_with_every_band_free():
    with jax.enable_x64(True):
        reflect, obs, band0, shared0 = _toy()
        target = obs.lab(reflect(band0 + 0.4, shared0))
        prior = lambda s: 1e-3 * s  # noqa: E731
        run = lambda basis: _seen.refine_in_de2000(reflect, obs.lab, target, (band0, shared0), ridge=0.3,  # noqa: E731
                                                   shared_prior=prior, max_steps=50, rtol=1e-12, basis=basis)
        (b_free, s_free), _, n_free = run(None)
        (b_eye, s_eye), _, n_eye = run(jnp.eye(band0.shape[0]))
        assert n_free == n_eye
        np.testing.assert_allclose(b_eye, b_free, rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(s_eye, s_free, rtol=1e-9, atol=1e-9)


def test_smooth_basis_spans_the_band_range_in_bumps_of_its_spacing():
    wl = np.arange(380.0, 781.0, 10.0)
    phi = _seen.smooth_basis(wl, 50.0)
    assert phi.shape == (41, 9)  # 400 nm in bumps 50 nm apart: one at each end
    assert np.allclose(phi[0, 0], 1) and np.allclose(phi[-1, -1], 1)
    assert _seen.smooth_basis(wl, 0) is None and _seen.smooth_basis(wl, None) is None
    assert _seen.smooth_basis(np.arange(400.0, 701.0, 5.0), 50.0).shape == (61, 7)  # in nm, not in bands


@pytest.fixture(scope="module")
def two_paints():
    """Two real paints of the NTU table and their mixtures (a quick but real fit)."""
    m = measurements.read_measurements(NTU)
    return m.select([set(p) <= {"P1", "P4"} for p in m.pigments])


def test_the_refinement_lowers_the_colour_error_of_a_real_fit(two_paints):
    plain = fit_mixtures(two_paints, model=MixModel(loss="spectral", pairs=False), posterior=False)
    seen = fit_mixtures(two_paints, model=MixModel(pairs=False), posterior=False)
    assert seen.library.fit["model"]["loss"] == "de2000"
    assert seen.library.palette.pairs is None and "pair_terms" not in seen.library.to_dict()  # pairs=False
    assert np.all(np.isfinite(seen.delta_e))
    # Measured on this subset: 0.94 -> 0.89 mean CIEDE2000 with the default ridge of 3 and the smooth basis (0.86,
    # max 3.7 -> 2.8, with every band free: test_the_default_refinement_moves_the_spectra_only_smoothly).
    assert seen.summary()["mean_de2000"] < 0.97 * plain.summary()["mean_de2000"]
    assert seen.summary()["max_de2000"] < plain.summary()["max_de2000"]


def test_fit_swatch_refine_none_is_the_log_reflectance_fit(two_paints, tmp_path, capsys):
    table = write_spectral_table(tmp_path / "two.csv", two_paints)
    assert main(["fit-swatch", "--table", str(table), "--refine", "none", "-o", str(tmp_path / "lib.json")]) == 0
    assert "loss=spectral" in capsys.readouterr().out


def test_refine_is_refused_where_it_does_not_apply(tmp_path, capsys):
    rgb = ROOT / "data" / "ntu-wpsm" / "ntu-rgb-train.csv"
    assert main(["fit-swatch", "--table", str(rgb), "--refine", "none", "-o", str(tmp_path / "x.json")]) == 2
    err = capsys.readouterr().err
    assert "--refine" in err and not (tmp_path / "x.json").exists()


class _Traces:
    """Counts JAX's traces (`jaxpr_trace_duration` events: every jit that is traced, found in a cache or not), or
    others of its duration events (`backend_compile_duration`: every program XLA compiles;
    `cache_retrieval_time_sec`: every program read from the persistent cache the test processes share)."""

    def __init__(self, *events: str):
        self.events = set(events or ["/jax/core/compile/jaxpr_trace_duration"])
        self.n = 0

    def __call__(self, event, duration, **kwargs):
        if event in self.events:
            self.n += 1

    def __enter__(self):
        jax.monitoring.register_event_duration_secs_listener(self)
        return self

    def __exit__(self, *exc):
        jax.monitoring.unregister_event_duration_listener(self)


def test_a_second_fit_of_the_same_shapes_traces_nothing(two_paints):
    """The solvers' functions hold their data (Modules), so a later fit of the same shapes and model reuses the
    compiled programs: a spectral fit with its refinement and pair terms, and an RGB fit. (With closures over
    the data every fit traced and compiled again: 6.8 s of a 7 s repeat of this spectral fit.)"""
    rgb = measurements.read_measurements(ROOT / "data" / "ntu-wpsm" / "ntu-rgb-train.csv")
    rgb = rgb.select([set(p) <= {"P1", "P4"} for p in rgb.pigments])
    for table in (two_paints, rgb):
        # A worker that ran many tests may hold enough of XLA's memory maps that the repeat's own relief
        # (`relieve_compiled_programs`) drops the programs: start with them dropped, as a fresh process would.
        diffwash._cache.relieve_compiled_programs(share=0.0)
        first = fit_mixtures(table)
        with _Traces() as traces:
            again = fit_mixtures(table)
        assert traces.n == 0, f"{traces.n} traces in a repeated {'spectral' if table.spectral else 'RGB'} fit"
        np.testing.assert_array_equal(again.delta_e, first.delta_e)
        assert first.library.palette.pairs is not None  # the pair terms' fit ran (an RGB table's too)


def test_the_default_refinement_moves_the_spectra_only_smoothly(two_paints):
    """The refinement's change of each log K and log S spectrum lies in the smooth basis (bumps 50 nm apart), so
    the fitted spectra are no rougher than the log-reflectance fit's; with every band free (`refine_spacing=0`,
    the default before) it bought colour with single bands, and the spectra came out rougher."""
    plain = fit_mixtures(two_paints, model=MixModel(loss="spectral", pairs=False), posterior=False)
    smooth = fit_mixtures(two_paints, model=MixModel(pairs=False), posterior=False)
    free = fit_mixtures(two_paints, model=MixModel(pairs=False, refine_spacing=0), posterior=False)
    assert smooth.library.fit["model"]["refine_spacing"] == 50.0

    def log_ks(fit):
        pal = fit.library.palette
        return np.log(np.concatenate([np.asarray(pal.K), np.asarray(pal.S)]))  # (2P, B)

    phi = _seen.smooth_basis(two_paints.observation().wavelengths, 50.0)
    change = (log_ks(smooth) - log_ks(plain)).T  # (B, 2P)
    in_span = phi @ np.linalg.lstsq(phi, change, rcond=None)[0]
    np.testing.assert_allclose(in_span, change, atol=2e-3 * np.abs(change).max() + 1e-6)
    # How rough each refinement's change is: mean |second difference| over mean |change|. Measured: 0.24 in the
    # basis (bumps five bands apart), 0.88 with every band free, for changes of the same size (0.049, 0.050).
    rough = lambda c: float(np.mean(np.abs(np.diff(c, 2, axis=0))) / np.mean(np.abs(c)))  # noqa: E731
    assert rough(change) < 0.4 < 0.7 < rough((log_ks(free) - log_ks(plain)).T)
    assert free.summary()["mean_de2000"] < smooth.summary()["mean_de2000"] < plain.summary()["mean_de2000"]
