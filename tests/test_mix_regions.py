"""90% regions of a library's predictions (`de2000_90`): the Monte Carlo radius, the kinds of row, the library
file's uncertainty record, and libraries without one."""

import json

import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from diffwash import _regions, library, mixing, spectral
from diffwash._errors import DiffwashError
from diffwash.cli import main
from diffwash.fit import _posterior

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


def test_rows_are_single_seen_or_unseen():
    got = _regions.kinds([("A",), ("A", "A"), ("B", "A"), ("A", "C"), ("a", "b")], (("A", "B"),))
    assert got == ["single", "single", "seen", "unseen", "seen"]


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
