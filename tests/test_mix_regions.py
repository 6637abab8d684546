"""90% regions of a library's predictions (`de2000_90`): the Monte Carlo radius, the kinds of row, the library
file's uncertainty record, and libraries without one."""

import json

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from diffwash import _regions, library, mixing, spectral
from diffwash._errors import DiffwashError
from diffwash.cli import main
from diffwash.fit.tables import _posterior

GRID = (400.0, 500.0, 600.0, 700.0)


def _library(posterior=None):
    K = jnp.asarray([[2.0, 1.0, 0.5, 0.3], [0.3, 0.5, 1.5, 2.5]])
    S = jnp.asarray([[0.5, 0.6, 0.7, 0.8], [1.0, 1.0, 1.0, 1.0]])
    pal = mixing.Palette(K=K, S=S, law=mixing.AmountLaw(gamma=jnp.asarray([0.8, 0.9])), weights=jnp.ones(2),
                         names=("A", "B"), wavelengths=GRID)  # fmt: skip
    return library.Library(pal, {"paper": np.full(4, 0.85)}, spectral.observation(GRID), posterior=posterior)


def _posterior_of(n, scale, error):
    return _regions.Posterior(np.sqrt(scale) * np.eye(n)[:, :3], np.full(n, scale), error, (("A", "B"),))


def test_the_radius_of_an_isotropic_model_error_grows_with_it_and_is_zero_without_it():
    lab = np.array([[50.0, 10.0, -20.0], [80.0, 0.0, 0.0]])
    spread = np.zeros((400, 2, 3))
    assert np.all(_regions.radius90(lab, spread, np.zeros(2)) == 0)
    r1, r2 = _regions.radius90(lab, spread, np.ones(2)), _regions.radius90(lab, spread, np.full(2, 2.0))
    assert np.all(r1 > 0) and np.all(r2 > 1.8 * r1)
    # CIEDE2000 is smaller than dE*ab for chromatic offsets (the 90% radius of dE*ab: 2.50), near it for greys.
    assert r1[0] < 2.4 and 2.2 < r1[1] < 3.0


@settings(max_examples=10, deadline=None)
@given(st.floats(0.1, 5.0))
def test_the_calibrated_model_error_makes_the_regions_hold_ninety_percent_of_the_rows(s):
    rng = np.random.default_rng(1)
    lab_pred = np.column_stack([rng.uniform(30, 80, 300), rng.uniform(-30, 30, 300), rng.uniform(-30, 30, 300)])
    lab_true = lab_pred + s * rng.standard_normal((300, 3))
    spread = np.zeros((400, 300, 3))
    got = _posterior.calibrate_scale(lab_true, lab_pred, spread)
    held = np.mean(np.asarray(_dE(lab_true, lab_pred)) <= _regions.radius90(lab_pred, spread, np.full(300, got)))
    assert 0.88 <= held <= 0.93 and 0.6 * s < got < 1.5 * s


def _dE(a, b):
    from diffwash import colorimetry

    return colorimetry.delta_e_2000(jnp.asarray(a), jnp.asarray(b))


def test_a_model_error_measured_on_few_rows_holds_more_of_them():
    """Split conformal prediction's finite-sample level: a model error fitted to hold 90% of 10 rows holds the next
    row with probability about 90% only if it holds all 10 (ceil(11 x 0.9) = 10)."""
    assert _posterior.conformal_level(10) == 1.0 and _posterior.conformal_level(9) == 1.0
    assert _posterior.conformal_level(19) == pytest.approx(18 / 19) and _posterior.conformal_level(1700) < 0.901
    rng = np.random.default_rng(0)
    lab = rng.uniform(20, 80, (10, 3))
    de = np.array([1.0] * 9 + [8.0])  # one row of the ten far off
    spread = np.zeros((64, 10, 3))
    held = lambda s: np.mean(de <= _regions.radius90(lab, spread, np.full(10, s)))  # noqa: E731
    loose = _posterior.calibrate_scale(lab, lab, spread, de=de)
    tight = _posterior.calibrate_scale(lab, lab, spread, de=de, share=_posterior.conformal_level(10))
    assert held(loose) == 0.9 and held(tight) == 1.0 and tight > 3 * loose


def test_rows_are_single_seen_unseen_or_unmixed():
    seen = (("A", "B"), ("B", "C"))
    got = _regions.kinds([("A",), ("A", "A"), ("B", "A"), ("A", "C"), ("a", "b"), ("A", "D"), ("D", "E")], seen)
    assert got == ["single", "single", "seen", "unseen", "seen", "unmixed", "unmixed"]
    # A table without mixtures: every mixture holds a paint never measured mixed.
    assert _regions.kinds([("A", "B")], ()) == ["unmixed"]


def test_a_pigment_fitted_at_its_scattering_edge_gets_a_bounded_region_from_its_own_rows():
    """Issue 24: a paint fitted to S near 0 has a Laplace variance of log S its own rows refute further out (drawn
    at S ~ 1 it turns opaque): unbounded, every region of it was ~60 CIEDE2000. Bounded by its own single rows,
    its draws stay where those rows hold, and a well determined paint keeps its posterior."""
    P, B = 2, 4
    lib = _library()
    pal = eqx.tree_at(lambda p: p.S, lib.palette, jnp.asarray([[0.5, 0.6, 0.7, 0.8], [1e-4] * 4]))
    n = 2 * P * B + P
    diag = np.full(n, 1e-4)
    diag[P * B + B : 2 * P * B] = 75.0**2  # B's log S: left free by the linearisation at S = 1e-4
    F = np.zeros((n, 1))
    amounts = (0.005, 0.01, 0.015, 0.02, 0.03, 0.04, 0.06, 0.08, 0.12, 0.16)
    k = len(amounts)
    A = np.zeros((2 * k, 1, 2))
    A[:k, 0, 0], A[k:, 0, 1] = amounts, amounts
    G = np.full((2 * k, 4), 0.85)
    obs = lib.observation
    lab_pred = np.asarray(obs.lab(pal.stack_reflectance(jnp.asarray(A), jnp.asarray(G), 0.0)))
    lab_true = lab_pred + np.random.default_rng(0).normal(0, 0.5, lab_pred.shape)  # rows fitted to about 0.5
    owner = _posterior.owners(P, B)

    def draw(a):
        return _regions.lab_draws(_regions.Posterior(*_posterior.scaled(F, diag, a, owner), {}), pal, A, G, 0.0, obs.lab)

    wide = _regions.radius90(lab_pred, draw(np.ones(P)), np.zeros(2 * k))
    a = _posterior.shrink_per_pigment(draw, np.repeat([0, 1], k), P, lab_true, lab_pred)
    bounded = _regions.radius90(lab_pred, draw(a), np.zeros(2 * k))
    assert a[0] == 1.0 and 0 < a[1] < 0.01  # only the paint whose rows refute its draws
    assert np.median(wide[k:]) > 20 and np.all(np.isfinite(bounded)) and np.median(bounded[k:]) < 5
    assert bounded[k:].max() < wide[k:].min()
    np.testing.assert_allclose(bounded[:k], wide[:k])
    # Its mixture with A gets a finite region, from the (bounded) draws and its kind's model error.
    post = _regions.Posterior(*_posterior.scaled(F, diag, a, owner), {"unseen": 2.0, "unmixed": 5.0}, ())
    r = _regions.de2000_90(post, pal, A[:1] + A[k : k + 1], G[:1], 0.0, obs.lab, lab_pred[:1])
    assert np.isfinite(r[0]) and 3 < r[0] < 15


def test_predictions_carry_regions_that_widen_with_the_posterior_and_vanish_for_kinds_without_an_error():
    n = 2 * 2 * 4 + 2
    narrow = _library(_posterior_of(n, 1e-4, {"single": 0.5, "seen": 1.0}))
    wide = _library(_posterior_of(n, 0.05, {"single": 0.5, "seen": 1.0}))
    rows = (["A", "A+B", "B+C"], ["0.03", "0.01+0.02", "0.01+0.01"])
    with pytest.raises(DiffwashError):  # C is not in the library
        narrow.predict(*rows)
    p1, p2 = (lib.predict(["A", "A+B", "B"], ["0.03", "0.01+0.02", "0.02"]) for lib in (narrow, wide))
    assert np.all(np.isfinite(p1.de2000_90)) and np.all(p2.de2000_90 > p1.de2000_90)
    no_unseen = _library(_posterior_of(n, 1e-4, {"single": 0.5}))
    p = no_unseen.predict(["A", "A+B"], ["0.03", "0.01+0.02"])
    assert np.isfinite(p.de2000_90[0]) and np.isnan(p.de2000_90[1])  # no region without a model error
    # A row's kind is what it lays down: A+B at 0.03+0, A/B at 0.03/0 and A+A at 0.01+0.02 are A at 0.03.
    same = narrow.predict(["A", "A+B", "A/B", "A+A"], ["0.03", "0.03+0", "0.03/0", "0.01+0.02"])
    np.testing.assert_allclose(same.de2000_90, same.de2000_90[0], rtol=1e-9)
    assert narrow.predict(["A+B"], ["0+0"]).de2000_90[0] > 0  # the bare ground: a single paint's region
    csv_text = library.prediction_csv(library._as_queries(["A", "A+B"], ["0.03", "0.01+0.02"], None), p)
    assert csv_text.splitlines()[0].split(",")[9] == "de2000_90" and csv_text.splitlines()[2].split(",")[9] == ""


def test_a_library_without_an_uncertainty_record_still_loads_and_predicts(tmp_path):
    lib = _library()
    lib.save(tmp_path / "old.json")
    assert "uncertainty" not in json.loads((tmp_path / "old.json").read_text())
    again = library.load_library(tmp_path / "old.json")
    pred = again.predict(["A+B"], ["0.01+0.02"])
    assert again.posterior is None and pred.de2000_90 is None
    (tmp_path / "q.csv").write_text("pigment,amount,ground\nA,0.02,paper\n")
    assert main(["predict", str(tmp_path / "old.json"), "--table", str(tmp_path / "q.csv"), "-o", str(tmp_path / "p.csv")]) == 0
    assert "de2000_90" not in (tmp_path / "p.csv").read_text().splitlines()[0]


def test_a_library_with_a_posterior_round_trips(tmp_path):
    n = 2 * 2 * 4 + 2
    lib = _library(_posterior_of(n, 1e-3, {"single": 0.5, "seen": 1.0, "unseen": 2.0}))
    lib.save(tmp_path / "lib.json")
    again = library.load_library(tmp_path / "lib.json")
    np.testing.assert_allclose(again.posterior.factor, lib.posterior.factor, atol=1e-8)
    assert again.posterior.model_error == lib.posterior.model_error and again.posterior.seen == (("A", "B"),)
    a, b = lib.predict(["A+B"], ["0.01+0.02"]), again.predict(["A+B"], ["0.01+0.02"])
    np.testing.assert_allclose(a.de2000_90, b.de2000_90, rtol=1e-6)


@pytest.mark.parametrize(
    "change, where",
    [
        (lambda u: u.update(factor=[[1.0]]), "uncertainty.factor"),
        (lambda u: u.update(diagonal=[-1.0] * 18), "uncertainty.factor"),
        (lambda u: u.update(model_error={"unseen": -1}), "uncertainty.model_error"),
        (lambda u: u.update(model_error={"someday": 1}), "uncertainty.model_error"),
        (lambda u: u.update(seen=[["A", 3]]), "uncertainty.seen"),
    ],
)
def test_a_bad_uncertainty_record_is_one_line_naming_the_field(tmp_path, change, where, capsys):
    n = 2 * 2 * 4 + 2
    d = _library(_posterior_of(n, 1e-3, {"single": 0.5})).to_dict()
    change(d["uncertainty"])
    (tmp_path / "bad.json").write_text(json.dumps(d))
    with pytest.raises(DiffwashError) as e:
        library.load_library(tmp_path / "bad.json")
    assert where in str(e.value) and "bad.json" in str(e.value)
    (tmp_path / "q.csv").write_text("pigment,amount,ground\nA,0.02,paper\n")
    assert main(["predict", str(tmp_path / "bad.json"), "--table", str(tmp_path / "q.csv"), "-o", str(tmp_path / "p.csv")]) == 2
    assert not (tmp_path / "p.csv").exists()


def test_the_pigment_report_names_what_the_rows_left_free_and_the_measurement_that_would_pin_it():
    P, B = 2, 4
    n = 2 * P * B + P
    diag = np.full(n, 0.01)
    diag[P * B + B : P * B + 2 * B] = 4.0  # B's log S: free
    diag[2 * P * B] = 1.0  # A's amount law: free
    rep = _posterior.pigment_report(np.zeros((n, 1)), diag, ("A", "B"), B, mixed={"A"})
    assert rep[0]["from_the_prior"] == ["amount law"] and "a second amount" in rep[0]["measure"]
    assert rep[1]["from_the_prior"] == ["scattering"] and rep[1]["sd_log_S"] == 2.0
    assert "over black" in rep[1]["measure"] and "never measured mixed" in rep[1]["measure"]
    lines = _posterior.uncertainty_lines(rep)
    assert len(lines) == 3 and lines[2].startswith("    B: log K 0.10, log S 2.00")
    # Already over black: not asked for again. From an RGB table: its spectrum is what would pin it.
    dark = _posterior.pigment_report(np.zeros((n, 1)), diag, ("A", "B"), B, mixed={"A"}, over_dark={"B"})
    assert "over black" not in dark[1]["measure"] and "never measured mixed" in dark[1]["measure"]
    rgb = _posterior.pigment_report(np.zeros((n, 1)), diag, ("A", "B"), B, mixed={"A"}, over_dark={"B"}, spectral=False)
    assert "over black" not in rgb[1]["measure"] and "spectrophotometer" in rgb[1]["measure"]
    assert "spectrophotometer" not in rgb[0]["measure"]  # A's spectra were pinned; its amount law was not


def test_a_fold_is_refitted_from_the_fits_start_not_pulled_towards_the_full_fit(tmp_path):
    """Issue 20: the held-out rows' predictions of a fold are those of a fit that never saw them. A generated table
    whose true mixing weights the model lacks (so a pair's rows move the fit): the fold's refit predicts the held-out
    pair as a fit of the other rows does, not as the full fit (which saw them) does."""
    from test_mix_fit import GRID as G7, _truth, _write_table

    from diffwash import measurements
    from diffwash.fit import MixModel, fit_mixtures
    from diffwash.fit.tables import _mixfit, _priors, _seen

    pal, paper = _truth(weights=(1.0, 4.0, 0.25))
    _write_table(tmp_path / "t.csv", pal, paper)
    m = measurements.read_measurements(tmp_path / "t.csv")
    test = np.array([set(p) == {"A", "B"} for p in m.pigments])
    model = MixModel(pairs=False)
    full = fit_mixtures(m, model=model, posterior=False).library
    direct = fit_mixtures(m.select(~test), model=model, posterior=False).library
    names, P = list(m.names), len(m.names)
    A, G = (jnp.asarray(x) for x in _mixfit._dense(m, names))
    obs = full.observation
    reflect = _mixfit._Reflect(A, G, P, model)
    band0 = jnp.asarray(_mixfit._init_band(m, np.asarray(A), names))
    priors = _priors.table_priors(np.asarray(A), np.asarray(G), model.one_amount)
    spectral = _mixfit._SpectralResiduals(reflect, jnp.asarray(m.values), band0, priors)
    band = jnp.log(jnp.concatenate([full.palette.K.T, full.palette.S.T], axis=1))
    lab_m = jnp.asarray(_mixfit.measured_lab(m, obs))
    pb = _seen._Problem(reflect, obs.lab, lab_m, band, model.ridge, _mixfit._SharedPrior(P, model, priors))
    start = (band0, _mixfit._shared_start(band0, priors, P, model))
    calls = []
    (held,) = _posterior.refit_held_out(spectral, start, pb, [test], rtol=1e-7, progress=lambda i, n: calls.append((i, n)))
    assert calls == [(1, 1)]  # each fold is announced as it begins
    rows = (m.select(test).pigments, m.select(test).amounts, m.select(test).ground)
    lab_full, lab_direct = full.predict(*rows).lab, direct.predict(*rows).lab
    off = lambda a, b: float(np.mean(_dE(a, b)))  # noqa: E731
    assert off(lab_full, lab_direct) > 1.0  # the held-out pair moves the fit (else this test shows nothing)
    assert off(held, lab_direct) < 0.3 * off(lab_full, lab_direct), (off(held, lab_direct), off(lab_full, lab_direct))


def test_a_paints_folds_run_as_far_as_the_fit_and_pair_folds_stay_capped(tmp_path):
    """Issue 24: the folds that hold out every mixture of one paint measure the `unmixed` model error. Stopped after
    40 + 8 steps they stayed near the fit's start, which predicts a never-mixed paint's mixtures better than a
    converged fit does (notebook 07, then 06: P1's at 3.8 instead of 17.7 mean CIEDE2000), and the regions of P12's mixtures
    held 44% of them. Each such fold now runs as far as the fit itself; the many leave-pairs-out folds keep their
    cap."""
    from test_mix_fit import _truth, _write_table

    from diffwash import measurements
    from diffwash.fit.tables import _mixfit

    _write_table(tmp_path / "t.csv", *_truth())
    m = measurements.read_measurements(tmp_path / "t.csv")
    m = m.select([len(set(p)) == 1 or "C" not in p for p in m.pigments])  # C is never measured mixed
    kind = np.array(_regions.kinds(m.pigments, _mixfit.pairs(m)))
    lab = np.random.default_rng(0).uniform(20, 80, (len(m), 3))
    calls = []

    def refit(folds, what, pairs=False, **steps):
        calls.append((what, steps, pairs))
        return [lab[t] + 1.0 for t in folds]

    scale, rows, how = _mixfit._model_errors(m, kind, lab, lab, np.zeros((8, len(m), 3)), refit)
    steps = {what: s for what, s, _ in calls}
    # Only the leave-pairs-out folds predict their held-out pairs with inferred terms, as the fit predicts a pair it
    # never measured; a paint never mixed has no terms to infer.
    assert {what: p for what, _, p in calls} == {"leave-pairs-out": True, "leave-one-paint's-mixtures-out": False}
    assert steps["leave-one-paint's-mixtures-out"] == {"steps": _posterior.PAINT_FOLD_STEPS,
                                                       "refine_steps": _posterior.PAINT_FOLD_REFINE_STEPS}  # fmt: skip
    assert _posterior.PAINT_FOLD_STEPS >= 400 and _posterior.PAINT_FOLD_REFINE_STEPS >= 100
    assert steps.get("leave-pairs-out", {}) == {}
    assert rows["unmixed"] > 0 and scale["unmixed"] > 0
    # A seen row's error is the one it has when left out of its pair's terms, where that is given: the fit's own
    # rows here are exact (lab against lab), so without it the seen pairs would need no model error at all.
    assert scale["seen"] == 0.0 and "seen_from" not in how
    held = np.where(kind == "seen", 3.0, np.nan)
    scale2, _, how2 = _mixfit._model_errors(m, kind, lab, lab, np.zeros((8, len(m), 3)), refit, held)
    assert scale2["seen"] > 1.0 and "left out of its pair's terms" in how2["seen_from"]
    assert scale2["single"] == scale["single"] and scale2["unseen"] == scale["unseen"]


def test_an_rgb_tables_fit_carries_regions_from_its_own_posterior_and_folds(tmp_path):
    """Issue 20: a library fitted to an RGB table (three channels, no spectra) predicts with `de2000_90` as a
    spectral one does: the Laplace covariance of its basis coefficients carried onto the bands, each pigment bounded
    by its own rows, and model errors from its rows and leave-pairs-out folds. Before, it had no regions at all."""
    from conftest import ROOT

    from diffwash import colorimetry, measurements
    from diffwash.fit import fit_mixtures
    from diffwash.fit.tables import _mixfit

    t = measurements.read_measurements(ROOT / "data" / "ntu-wpsm" / "ntu-rgb-train.csv")
    m = t.select([set(p) <= {"P1", "P4", "P7"} for p in t.pigments])
    fit = fit_mixtures(m)
    unc = fit.library.fit["uncertainty"]
    assert unc["noise_de2000"] > 0 and {"single", "seen", "unseen"} <= set(unc["model_error"])
    assert "leave-pairs-out" in unc["unseen_from"] and [r["name"] for r in unc["pigments"]] == ["P1", "P4", "P7"]
    post = fit.library.posterior
    B = len(_mixfit.RGB_GRID)
    assert post.factor.shape[0] == 2 * 3 * B + 3 and post.diagonal.shape == (2 * 3 * B + 3,)
    pred = fit.library.predict(m.pigments, m.amounts, m.ground)
    de = np.asarray(_dE(np.asarray(colorimetry.linear_srgb_to_lab(jnp.asarray(m.values))), pred.lab))
    assert np.all(np.isfinite(pred.de2000_90)) and np.all(pred.de2000_90 > 0)
    assert 0.8 <= np.mean(de <= pred.de2000_90) <= 1.0  # in-sample model errors: about 90% of its own rows
    # ... and `diffwash predict` writes them, for a pair the table never mixed too (P1+P4 is one it did).
    fit.library.save(tmp_path / "lib.json")
    (tmp_path / "q.csv").write_text("pigment,amount,ground\nP1,0.05,paper\nP1+P4,0.02+0.02,paper\n")
    assert main(["predict", str(tmp_path / "lib.json"), "--table", str(tmp_path / "q.csv"),
                 "-o", str(tmp_path / "p.csv")]) == 0  # fmt: skip
    head, *rows = (line.split(",") for line in (tmp_path / "p.csv").read_text().splitlines())
    col = head.index("de2000_90")
    assert len(rows) == 2 and all(float(r[col]) > 0 for r in rows)
