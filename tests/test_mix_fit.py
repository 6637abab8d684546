"""Joint fit of mixable pigments (fit-swatch --table on spectral and mixture tables) and predict, through the
command line's entry point and the Python API."""

import csv
import json

import jax.numpy as jnp
import numpy as np
import pytest
from conftest import ROOT

import diffwash
from diffwash import library, measurements, mixing, spectral
from diffwash.cli import main

GRID = (400.0, 450.0, 500.0, 550.0, 600.0, 650.0, 700.0)
NAMES = ("A", "B", "C")
AMOUNTS = (0.01, 0.02, 0.04, 0.08)


def _truth(weights=(1.0, 1.0, 1.0)):
    rng = np.random.default_rng(3)
    K = rng.uniform(0.2, 6.0, (3, len(GRID)))
    S = rng.uniform(0.3, 2.0, (3, len(GRID)))
    law = mixing.AmountLaw(gamma=jnp.asarray([0.7, 0.9, 0.6]))
    pal = mixing.Palette(K=jnp.asarray(K), S=jnp.asarray(S), law=law, weights=jnp.asarray(weights), names=NAMES,
                         wavelengths=GRID)  # fmt: skip
    paper = np.linspace(0.80, 0.88, len(GRID))
    return pal, paper


def _rows():
    rows = [(("A",), (a,)) for a in AMOUNTS] + [(("B",), (a,)) for a in AMOUNTS] + [(("C",), (a,)) for a in AMOUNTS]
    for p, q in (("A", "B"), ("A", "C"), ("B", "C")):
        rows += [((p, q), (a, b)) for a in AMOUNTS[:3] for b in AMOUNTS[:3]]
    return rows


def _write_table(path, pal, paper):
    rows = _rows()
    A = np.zeros((len(rows), 3))
    for r, (ns, amts) in enumerate(rows):
        for n, a in zip(ns, amts):
            A[r, NAMES.index(n)] += a
    R = np.asarray(pal.reflectance(jnp.asarray(A), jnp.asarray(paper)))
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["pigment", "amount", "ground", *(f"{g:g}" for g in GRID)])
        w.writerow(["paper", "0", "paper", *paper])
        for (ns, amts), r in zip(rows, R):
            w.writerow(["+".join(ns), "+".join(f"{a:g}" for a in amts), "paper", *r])
    return rows, R


@pytest.fixture(scope="module")
def fitted(tmp_path_factory):
    """A spectral table made by known pigments, fitted through the command line (once for the module)."""
    folder = tmp_path_factory.mktemp("mix")
    pal, paper = _truth()
    _write_table(folder / "table.csv", pal, paper)
    status = main(["fit-swatch", "--table", str(folder / "table.csv"), "-o", str(folder / "lib.json")])
    assert status == 0
    return folder, pal, paper


def test_a_spectral_table_fits_to_a_library_that_predicts_unseen_amounts(fitted, capsys):
    folder, pal, paper = fitted
    lib = library.load_library(folder / "lib.json")
    assert lib.spectral and lib.names == ("A", "B", "C") and lib.observation.wavelengths == GRID
    record = json.loads((folder / "lib.json").read_text())
    assert record["fit"]["summary"]["mean_de2000"] < 0.05
    assert len(record["fit"]["rows"]) == len(_rows())
    # New amounts and proportions, never measured: the fitted library agrees with the pigments that made the table.
    A = np.array([[0.03, 0.05, 0.0], [0.0, 0.015, 0.06], [0.02, 0.02, 0.02]])
    pred = lib.predict([("A", "B"), ("B", "C"), ("A", "B", "C")], [(0.03, 0.05), (0.015, 0.06), (0.02,) * 3])
    true = np.asarray(pal.reflectance(jnp.asarray(A), jnp.asarray(paper)))
    np.testing.assert_allclose(pred.reflectance, true, atol=3e-3)


def test_predict_writes_rgb_lab_and_bands_through_the_cli(fitted, tmp_path):
    folder, pal, paper = fitted
    q = tmp_path / "q.csv"
    q.write_text("pigment,amount,ground\nA,0.03,paper\nA+C,0.01+0.03,paper\nB+B,0.01+0.02,paper\n")
    status = main(["predict", str(folder / "lib.json"), "--table", str(q), "-o", str(tmp_path / "p.csv")])
    assert status == 0
    with open(tmp_path / "p.csv") as f:
        rows = list(csv.reader(f))
    assert rows[0][:10] == ["pigment", "amount", "ground", "r", "g", "b", "L*", "a*", "b*", "de2000_90"]
    assert rows[0][10:] == [f"{g:g}" for g in GRID] and len(rows) == 4
    # Each row's 90% region: a single paint, a pair the table measured mixed, a paint mixed with itself.
    r90 = np.array([r[9] for r in rows[1:]], float)
    assert np.all(np.isfinite(r90)) and np.all(r90 > 0)
    # The same numbers as the one-call API; a paint mixed with itself is itself at the summed amount.
    api = library.predict(folder / "lib.json", q)
    np.testing.assert_allclose(np.array(rows[1][3:6], float), api.srgb8[0], atol=1e-3)
    np.testing.assert_allclose(np.array(rows[3][10:], float), api.reflectance[2], atol=1e-5)
    np.testing.assert_allclose(r90, api.de2000_90, atol=1e-4)
    single = library.predict(folder / "lib.json", ["B"], ["0.03"])
    np.testing.assert_allclose(api.reflectance[2], single.reflectance[0], atol=1e-6)
    # Lab is colour-science's, through the library's observation.
    lab = diffwash.colorimetry.xyz_to_lab(spectral.observation(GRID).xyz(api.reflectance), spectral.observation(GRID).white)
    np.testing.assert_allclose(api.lab, lab, atol=1e-6)


def test_the_library_file_round_trips(fitted, tmp_path):
    folder, _, _ = fitted
    lib = library.load_library(folder / "lib.json")
    lib.save(tmp_path / "again.json")
    again = library.load_library(tmp_path / "again.json")
    np.testing.assert_array_equal(np.asarray(again.palette.K), np.asarray(lib.palette.K))
    np.testing.assert_array_equal(np.asarray(again.palette.law.gamma), np.asarray(lib.palette.law.gamma))
    assert again.grounds.keys() == lib.grounds.keys()
    np.testing.assert_allclose(again.posterior.factor, lib.posterior.factor, atol=1e-8)
    assert again.posterior.model_error == lib.posterior.model_error


def test_the_ntu_rgb_table_reads_as_mixtures_with_clipped_bounds():
    m = measurements.read_measurements(ROOT / "data" / "ntu-wpsm" / "ntu-rgb-train.csv")
    assert not m.spectral and m.is_mixture.sum() > 300 and set(m.grounds) == {"paper"}
    assert m.hi.any() or m.lo.any()


def test_pair_folds_hold_out_whole_pairs():
    m = measurements.read_measurements(ROOT / "data" / "ntu-wpsm" / "ntu-rgb-train.csv")
    folds = diffwash.fit.pair_folds(m, 3, seed=1)
    seen = set()
    for train, test in folds:
        held = {tuple(sorted(set(p))) for p, t in zip(m.pigments, test) if t}
        trained = {tuple(sorted(set(p))) for p, t, x in zip(m.pigments, train, m.is_mixture) if t and x}
        assert held and not held & trained and not held & seen
        assert not np.any(test & ~m.is_mixture)  # single paints always train
        seen |= held


def test_an_rgb_mixture_table_fits_smooth_spectra_through_srgb(tmp_path, capsys):
    """8-bit sRGB of mixtures made by smooth spectral pigments: the RGB route fits them as smooth spectra."""
    wl = np.arange(380.0, 781.0, 10.0)
    bump = lambda c, w: np.exp(-0.5 * ((wl - c) / w) ** 2)  # noqa: E731
    K = np.stack([0.3 + 5 * bump(500, 60), 0.3 + 5 * bump(430, 40), 0.3 + 4 * bump(620, 50)])
    S = np.full((3, len(wl)), 0.8)
    pal = mixing.Palette(K=jnp.asarray(K), S=jnp.asarray(S), law=mixing.AmountLaw(gamma=jnp.asarray([0.8, 0.8, 0.8])),
                         weights=jnp.ones(3), names=NAMES, wavelengths=tuple(float(x) for x in wl))  # fmt: skip
    paper = np.full(len(wl), 0.85)
    obs = spectral.observation(wl)
    rows = _rows()
    A = np.zeros((len(rows), 3))
    for r, (ns, amts) in enumerate(rows):
        for n, a in zip(ns, amts):
            A[r, NAMES.index(n)] += a
    rgb = np.asarray(obs.srgb(pal.reflectance(jnp.asarray(A), jnp.asarray(paper))))
    with open(tmp_path / "t.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["pigment", "amount", "ground", "r", "g", "b"])
        w.writerow(["paper", "0", "paper", *np.round(255 * np.asarray(obs.srgb(paper))).astype(int)])
        for (ns, amts), c in zip(rows, rgb):
            w.writerow(["+".join(ns), "+".join(f"{a:g}" for a in amts), "paper", *np.round(255 * np.clip(c, 0, 1)).astype(int)])
    assert main(["fit-swatch", "--table", str(tmp_path / "t.csv"), "-o", str(tmp_path / "lib.json")]) == 0
    lib = library.load_library(tmp_path / "lib.json")
    assert lib.spectral and len(lib.observation.wavelengths) == 41
    assert lib.fit["summary"]["mean_de2000"] < 1.0
    assert np.all(np.isfinite(np.asarray(lib.palette.K))) and np.all(np.asarray(lib.palette.S) > 0)
