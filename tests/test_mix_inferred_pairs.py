"""Pair terms inferred for pairs never measured mixed (diffwash.fit.tables._pairs.infer_pair_terms): per-pigment
effects fitted to the measured pairs' terms, and what pairs of like paints did, marked in the library file, used by
the fit's leave-pairs-out folds that calibrate the unseen pairs' 90% regions."""

import dataclasses
import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import ROOT
from test_mix_pairs import GRID, TRUE, _palette, _terms, eqx_replace

from diffwash import _schema, library, measurements, spectral
from diffwash.cli import main
from diffwash.fit import MixModel, fit_mixtures
from diffwash.fit.tables import _mixfit, _pairs

NTU = ROOT / "data" / "ntu-wpsm" / "ntu-spectral-train.csv"
MEASURED = ((0, 1), (0, 2), (1, 2), (1, 3), (2, 3))  # of 5 pigments: (0, 3) never measured; 4 never mixed


def _additive(effects):
    """Terms of MEASURED that are exactly the sum of their pigments' effects (P, 10)."""
    theta = np.stack([effects[i] + effects[j] for i, j in MEASURED])
    return _terms(theta, MEASURED)


def test_terms_that_are_sums_of_pigment_effects_are_inferred_exactly_without_the_ridge():
    effects = np.random.default_rng(3).normal(0, 0.2, (5, 10))
    out = _pairs.infer_pair_terms(_additive(effects), ridge=1e-9)
    assert out.inferred == ((0, 3),)  # pigment 4 was never mixed: no pair of it is inferred
    assert out.members == MEASURED + ((0, 3),)
    theta = np.concatenate([out.k_bumps, out.s_bumps, np.asarray(out.k_amount)[:, None],
                            np.asarray(out.s_amount)[:, None]], axis=1)  # fmt: skip
    np.testing.assert_allclose(theta[-1], effects[0] + effects[3], atol=1e-6)
    np.testing.assert_allclose(theta[:-1], np.stack([effects[i] + effects[j] for i, j in MEASURED]), atol=1e-12)


def test_the_default_ridge_shrinks_inferred_terms_towards_duncan():
    effects = np.random.default_rng(4).normal(0, 0.2, (5, 10))
    exact = effects[0] + effects[3]
    got = _pairs.infer_pair_terms(_additive(effects))
    theta = np.concatenate([got.k_bumps[-1], got.s_bumps[-1], [got.k_amount[-1], got.s_amount[-1]]])
    # With 2-3 measured pairs per pigment and a ridge of 10, each effect keeps about a fifth of itself.
    assert 0.05 < np.linalg.norm(theta) / np.linalg.norm(exact) < 0.5
    assert float(theta @ exact) > 0


def test_inferring_again_changes_nothing_and_nothing_to_infer_is_the_same_terms():
    terms = _additive(np.random.default_rng(5).normal(0, 0.2, (5, 10)))
    once = _pairs.infer_pair_terms(terms)
    twice = _pairs.infer_pair_terms(once)
    assert twice.members == once.members and twice.inferred == once.inferred
    np.testing.assert_allclose(twice.k_bumps, once.k_bumps)
    every = _terms(np.zeros((3, 10)), ((0, 1), (0, 2), (1, 2)))
    assert _pairs.infer_pair_terms(every) is every
    assert _pairs.infer_pair_terms(None) is None


def test_inferred_terms_stay_within_what_a_library_file_may_hold():
    # Measured terms within the bounds (pigments 0 and 3 each at 0.8 of it, 1 and 2 at 0.1), whose effects add past it.
    bound = np.asarray([_schema.PAIR_BUMP_MAX] * 8 + [_schema.PAIR_AMOUNT_MAX] * 2)
    effects = np.asarray([0.8, 0.1, 0.1, 0.8, 0.0])[:, None] * bound
    out = _pairs.infer_pair_terms(_additive(effects), ridge=1e-9)
    assert float(jnp.max(out.k_bumps[-1])) == _schema.PAIR_BUMP_MAX
    assert float(jnp.max(out.s_amount[-1])) == _schema.PAIR_AMOUNT_MAX


def _theta(terms, q=-1):
    return np.concatenate([terms.k_bumps[q], terms.s_bumps[q], [terms.k_amount[q], terms.s_amount[q]]])


def _two_kinds(seed=0):
    """Six pigments of two kinds (three absorb short waves, three long: K (6, 8), S), and every pair's terms but
    (0, 3)'s: `TRUE` for a pair of the two kinds, `-TRUE` for two of a kind. No per-pigment effects add to that."""
    kind = np.array([0, 0, 0, 1, 1, 1])
    shape = np.stack([np.linspace(2, -2, 8), np.linspace(-2, 2, 8)])
    K = np.exp(shape[kind] + np.random.default_rng(seed).normal(0, 0.1, (6, 8)))
    pairs = tuple((i, j) for i in range(6) for j in range(i + 1, 6) if (i, j) != (0, 3))
    theta = np.stack([np.asarray(TRUE) * (1.0 if kind[i] != kind[j] else -1.0) for i, j in pairs])
    return (K, np.ones_like(K)), _terms(theta, pairs)


def test_a_pair_of_like_paints_takes_what_like_pairs_did():
    pigments, terms = _two_kinds()
    true = np.asarray(TRUE)
    like = _pairs.infer_pair_terms(terms, ridge=1e-3, pigments=pigments)
    effects_only = _pairs.infer_pair_terms(terms, ridge=1e-3)
    assert like.inferred == effects_only.inferred == ((0, 3),)
    np.testing.assert_allclose(_theta(like), true, atol=1e-3)
    assert _theta(effects_only) @ true < 0  # the effects alone get it wrong: two of a kind pull the other way
    # With the default ridge, shrunk towards Duncan but pointing the right way.
    got = _theta(_pairs.infer_pair_terms(terms, pigments=pigments))
    assert 0.5 < got @ true / (true @ true) < 1.0


def test_without_likeness_the_inference_is_the_effects_ridge_regression():
    pigments, terms = _two_kinds(1)
    a = _pairs.infer_pair_terms(terms, pigments=pigments, like=0.0)
    b = _pairs.infer_pair_terms(terms)
    np.testing.assert_allclose(_theta(a), _theta(b), atol=1e-12)
    # Pigments all alike (no distance to scale by) are alike, not NaN.
    same = (np.ones((6, 8)), np.ones((6, 8)))
    assert np.isfinite(_theta(_pairs.infer_pair_terms(terms, pigments=same))).all()


def test_a_library_file_marks_inferred_pairs_and_reads_them_back(tmp_path):
    pal = _palette()
    terms = _pairs.infer_pair_terms(_terms(np.stack([TRUE, TRUE]), ((0, 1), (1, 2))))
    assert terms.inferred == ((0, 2),)
    lib = library.Library(eqx_replace(pal, terms), {"paper": np.full(len(GRID), 0.85)}, spectral.observation(GRID))
    lib.save(tmp_path / "lib.json")
    d = json.loads((tmp_path / "lib.json").read_text())
    flags = {tuple(e["pigments"]): e.get("inferred", False) for e in d["pair_terms"]["pairs"]}
    assert flags == {("A", "B"): False, ("B", "C"): False, ("A", "C"): True}
    again = library.load_library(tmp_path / "lib.json")
    assert again.palette.pairs.inferred == ((0, 2),)
    q = (["A+C", "A+B"], ["0.02+0.03", "0.02+0.03"])
    np.testing.assert_allclose(again.predict(*q).lab, lib.predict(*q).lab, atol=1e-9)
    # A palette of some of the pigments keeps the mark on the pairs it keeps, renumbered.
    sub = terms.subset([2, 0])
    assert sub.members == ((0, 1),) and sub.inferred == ((0, 1),)
    assert terms.subset([1, 2]).inferred == ()


def test_a_pair_terms_fit_on_some_rows_is_the_fit_of_those_rows_alone():
    """`use` (a fold's training rows): the whole table's shapes, the terms of a table holding only those rows."""
    pal = _palette()
    truth = eqx_replace(pal, _terms(np.stack([TRUE, TRUE]), ((0, 1), (1, 2))))
    obs = spectral.observation(GRID)
    A = np.array([[a, b, 0.0] for a in (0.01, 0.04) for b in (0.02, 0.06)] + [[0.0, 0.02, 0.03], [0.0, 0.05, 0.01]])
    paper = np.full((len(A), len(GRID)), 0.85)
    lab = np.asarray(obs.lab(truth.reflectance(jnp.asarray(A), jnp.asarray(paper))))
    use = np.array([True, False, True, True, False, False])
    some, _ = _pairs.fit_pair_terms(pal, A, paper, lab, obs.lab, use=use)
    alone, _ = _pairs.fit_pair_terms(pal, A[use], paper[use], lab[use], obs.lab)
    assert some.members == alone.members == ((0, 1),)  # B+C has no row to fit: no terms
    np.testing.assert_allclose(some.k_bumps, alone.k_bumps, atol=1e-6)
    assert _pairs.fit_pair_terms(pal, A, paper, lab, obs.lab, use=np.zeros(len(A), bool))[0] is None


KEEP = {"P1", "P5", "P9"}  # of the NTU paints: P1+P5 and P1+P9 measured mixed, P5+P9 left out (to be inferred)


def _three_paints_lines(path):
    lines = path.read_text().splitlines()
    paints = [set(r.split(",")[0].split("+")) for r in lines[1:]]
    return [lines[0], *(r for r, p in zip(lines[1:], paints) if p <= KEEP | {"paper"} and p != {"P5", "P9"})]


@pytest.fixture(scope="module")
def three_paints():
    """Three real paints, two of their three pairs measured mixed: P5+P9 never."""
    m = measurements.read_measurements(NTU)
    return m.select([set(p) <= KEEP and set(p) != {"P5", "P9"} for p in m.pigments])


def _spy(monkeypatch):
    """Record each call of `_mixfit._fold_lab_with_pairs` (its held-out rows and what it returned)."""
    calls = []
    real = _mixfit._fold_lab_with_pairs

    def spy(*args):
        out = real(*args)
        calls.append((int(np.sum(args[-1])), out))
        return out

    monkeypatch.setattr(_mixfit, "_fold_lab_with_pairs", spy)
    return calls


def test_a_fit_infers_the_pair_it_never_measured_and_its_folds_predict_as_it_does(three_paints, monkeypatch):
    calls = _spy(monkeypatch)
    lib = fit_mixtures(three_paints, max_steps=60).library
    names = lib.palette.names
    pair = tuple(sorted((names.index("P5"), names.index("P9"))))
    assert lib.palette.pairs.inferred == (pair,) and len(lib.palette.pairs.members) == 3
    assert lib.fit["model"]["infer_pairs"] is True
    assert lib.fit["model"]["pair_ridge"] == _pairs.PAIR_RIDGE != _mixfit.RGB_PAIR_RIDGE  # a spectral table's
    # The unseen pairs' model error comes from leave-pairs-out folds predicted the same way: each fold infers
    # its held-out pairs' terms from its own measured pairs (one call per fold that holds rows out, all its rows).
    assert len(calls) == 2 and all(np.isfinite(lab).all() and len(lab) == n for n, lab in calls)
    assert lib.fit["uncertainty"]["model_error"]["unseen"] > 0
    q = (["P5+P9"] * 3, ["0.02+0.02", "0.05+0.01", "0.01+0.05"])
    duncan = library.Library(eqx_replace(lib.palette, _drop_inferred(lib.palette.pairs)), lib.grounds, lib.observation)
    got = lib.predict(*q)
    assert np.isfinite(got.lab).all() and np.isfinite(got.de2000_90).all()
    assert np.abs(got.lab - duncan.predict(*q).lab).max() > 1e-3  # the inferred terms act on the pair
    # ... and are those of the measured pairs and the fitted pigments' likeness.
    pal = lib.palette
    again = _pairs.infer_pair_terms(_drop_inferred(pal.pairs), pigments=(pal.K, pal.S))
    np.testing.assert_allclose(_theta(again), _theta(pal.pairs), atol=1e-6)
    assert np.abs(_theta(_pairs.infer_pair_terms(_drop_inferred(pal.pairs))) - _theta(again)).max() > 1e-4


def test_an_rgb_table_gets_pair_terms_and_infers_the_pair_it_never_measured(tmp_path, monkeypatch, capsys):
    """The RGB route fits its paints as smooth spectra: through `fit-swatch --table`, its measured pairs get terms,
    P5+P9 inferred ones (said, and marked in the library), and its folds predict their held-out pairs the same
    way."""
    table = tmp_path / "rgb.csv"
    table.write_text("\n".join(_three_paints_lines(ROOT / "data" / "ntu-wpsm" / "ntu-rgb-train.csv")) + "\n")
    assert not measurements.read_measurements(table).spectral
    calls = _spy(monkeypatch)
    assert main(["fit-swatch", "--table", str(table), "-o", str(tmp_path / "lib.json"), "--max-steps", "80",
                 "--allow-unconverged"]) == 0  # fmt: skip
    assert "pair terms inferred for 1 pair never measured mixed" in capsys.readouterr().out
    got = {tuple(e["pigments"]): e.get("inferred", False)
           for e in json.loads((tmp_path / "lib.json").read_text())["pair_terms"]["pairs"]}  # fmt: skip
    assert got == {("P1", "P5"): False, ("P1", "P9"): False, ("P5", "P9"): True}
    assert len(calls) == 2
    # Three channels pin a pair's terms less than 41 bands: an RGB table's ridge towards Duncan is its own.
    assert json.loads((tmp_path / "lib.json").read_text())["fit"]["model"]["pair_ridge"] == _mixfit.RGB_PAIR_RIDGE
    pred = library.load_library(tmp_path / "lib.json").predict(["P5+P9", "P1+P5"], ["0.02+0.02", "0.02+0.02"])
    assert np.isfinite(pred.lab).all() and np.isfinite(pred.de2000_90).all()


def test_inference_can_be_turned_off(three_paints):
    lib = fit_mixtures(three_paints, max_steps=20, posterior=False, model=MixModel(infer_pairs=False)).library
    assert lib.palette.pairs.inferred == () and len(lib.palette.pairs.members) == 2


def _drop_inferred(terms):
    keep = [q for q, p in enumerate(terms.members) if tuple(p) not in set(terms.inferred)]
    k = np.asarray(keep)
    return _pairs._terms(jnp.concatenate([terms.k_bumps[k], terms.s_bumps[k], terms.k_amount[k, None],
                                          terms.s_amount[k, None]], axis=1),
                         tuple(terms.members[q] for q in keep), terms.k_bumps.shape[1], terms.centres, terms.width,
                         terms.wavelengths)  # fmt: skip


def test_canonical_pair_terms_predict_the_same_colours_and_key_one_compiled_prediction():
    """`PairTerms.canonical`: the pairs sorted, no `inferred` marks (static fields, so part of a compiled program's
    key): every layer's reflectance is unchanged, and two folds' terms (other pairs inferred, in other orders)
    become one structure, so the folds share one compiled prediction (`_mixfit._fold_lab_with_pairs`)."""
    theta = np.random.default_rng(5).normal(0, 0.3, (3, 10))
    one = dataclasses.replace(_terms(theta, ((1, 2), (0, 1), (0, 2))), inferred=((0, 2),))
    other = dataclasses.replace(_terms(theta[[1, 2, 0]], ((0, 1), (0, 2), (1, 2))), inferred=((1, 2),))
    assert one.canonical().members == ((0, 1), (0, 2), (1, 2)) and one.canonical().inferred == ()
    assert jax.tree_util.tree_structure(one.canonical()) == jax.tree_util.tree_structure(other.canonical())
    assert jax.tree_util.tree_structure(one) != jax.tree_util.tree_structure(other)
    pal = _palette()
    amounts = jnp.asarray(np.random.default_rng(6).uniform(0, 0.1, (20, 3)) * (np.arange(20) % 4 > 0)[:, None])
    paper = jnp.full(len(GRID), 0.85)
    for t in (one, other):
        np.testing.assert_allclose(eqx_replace(pal, t.canonical()).reflectance(amounts, paper),
                                   eqx_replace(pal, t).reflectance(amounts, paper), rtol=1e-12, atol=1e-14)


def test_every_leave_pairs_out_fold_predicts_through_the_same_program(monkeypatch):
    """`_mixfit._fold_lab_with_pairs` predicts every row of the table with its pairs in one order: each fold's
    prediction has the same pytree structure and shapes (one compiled `_forward` for all folds; before, each fold
    predicted its own held-out rows with its pairs in the order it fitted and inferred them, and compiled again),
    and it returns its own held-out rows."""
    m = measurements.read_measurements(NTU)
    m = m.select([set(p) <= {"P1", "P4", "P7", "P12"} for p in m.pigments])
    names, obs = m.names, m.observation()
    P, B = len(names), len(obs.wavelengths)
    rng = np.random.default_rng(0)
    params = (rng.uniform(0.2, 3, (P, B)), rng.uniform(0.3, 2, (P, B)), np.full(P, 0.7), np.ones(P), 0.0)
    rows = _mixfit._PairRows.of(m, names, dict(m.grounds), obs)
    seen = []
    predict = library.Library.predict
    monkeypatch.setattr(library.Library, "predict", lambda self, q, *a: seen.append(
        (jax.tree_util.tree_structure(self.palette), len(q))) or predict(self, q, *a))
    folds = [t for _, t in _mixfit.pair_folds(m)]
    model = MixModel(pair_ridge=_pairs.PAIR_RIDGE)
    held = [_mixfit._fold_lab_with_pairs(m, names, model, obs, dict(m.grounds), rows, params, t) for t in folds[:2]]
    assert [h.shape for h in held] == [(int(t.sum()), 3) for t in folds[:2]]
    assert seen[0] == seen[1] and seen[0][1] == len(m)
