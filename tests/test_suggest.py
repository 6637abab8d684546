"""What to paint next (`diffwash suggest`, `diffwash.fit.suggest`): the ranking's laws on a library with a
known posterior, the command line on a small fitted library, and bad input."""

import csv
import io

import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import diffwash
from diffwash import _regions, library, measurements, mixing, spectral
from diffwash._errors import DiffwashError
from diffwash.cli import main

GRID = (400.0, 500.0, 600.0, 700.0)
NAMES = ("A", "B", "C")


def _palette(K=None, S=None):
    rng = np.random.default_rng(3)
    K = rng.uniform(0.2, 6.0, (3, len(GRID))) if K is None else K
    S = rng.uniform(0.3, 2.0, (3, len(GRID))) if S is None else S
    return mixing.Palette(K=jnp.asarray(K), S=jnp.asarray(S), law=mixing.AmountLaw(gamma=jnp.asarray([0.7, 0.9, 0.6])),
                          weights=jnp.ones(3), names=NAMES, wavelengths=GRID)  # fmt: skip


PAPER = np.linspace(0.80, 0.88, len(GRID))


def _library(scale=0.01, error=None, seed=0, rank=5):
    """A library of A, B, C whose posterior is given: a random factor and diagonal of `scale`, A+B measured mixed."""
    n = 3 * (2 * len(GRID) + 1)
    F = np.sqrt(scale) * np.random.default_rng(seed).standard_normal((n, rank))
    # (`unmixed`: a kind some libraries keep for mixtures holding a paint never measured mixed; others ignore it)
    error = {"single": 0.3, "seen": 0.6, "unseen": 2.0, "unmixed": 2.0} if error is None else error
    post = _regions.Posterior(F, np.full(n, scale), error, (("A", "B"),))
    return library.Library(_palette(), {"paper": PAPER}, spectral.observation(GRID), posterior=post)


def _rows(pigments, amounts, grounds=None):
    return library._as_queries(pigments, amounts, grounds)


CANDIDATES = (["A", "A+B", "A+C", "B+C", "A/C", "C", "A+C"],
              ["0.03", "0.01+0.02", "0.01+0.02", "0.02+0.02", "0.02/0.03", "0.05", "0.02+0.01"])  # fmt: skip


def test_a_pair_never_measured_mixed_ranks_above_one_already_measured_and_picks_are_distinct():
    res = diffwash.fit.suggest(_library(), _rows(*CANDIDATES), n=7)
    assert [p.rank for p in res.picks] == list(range(1, 8))
    assert sorted(p.row for p in res.picks) == list(range(7))  # every candidate once
    order = [p.pigment for p in res.picks]
    assert order.index("A+C") < order.index("A+B") and order.index("B+C") < order.index("A+B")
    assert all(p.score >= 0 for p in res.picks) and np.isfinite(res.mean_de2000_90)
    # Greedy: the second A+C row, scored after the first was measured, gains less than the first.
    ac = [p for p in res.picks if p.pigment == "A+C"]
    assert ac[1].score < ac[0].score
    # The queries' expected regions shrink as rows are measured.
    assert res.picks[0].mean_de2000_90 < res.mean_de2000_90
    assert res.picks[-1].mean_de2000_90 <= res.picks[0].mean_de2000_90
    text = res.csv_text().splitlines()
    assert text[0] == "rank,pigment,amount,ground,score,mean_de2000_90,line" and len(text) == 8


def test_the_score_of_a_pick_is_the_drop_of_the_queries_predictive_variance():
    lib = _library(error={"single": 0.3, "seen": 0.6})  # no unseen error: no kind changes, the parameters alone
    q = _rows(["A", "B+C", "A/B"], ["0.02", "0.02+0.01", "0.01/0.02"])
    one = diffwash.fit.suggest(lib, _rows(*CANDIDATES), n=1, queries=q)
    two = diffwash.fit.suggest(lib, _rows(*CANDIDATES), n=2, queries=q)
    assert one.picks[0] == two.picks[0] and one.queries == 3 and one.candidates == 7
    # A posterior that pins every parameter leaves only the model error: measuring gains nothing (no kind
    # changes without an unseen error), and the variance is the queries' model errors (B+C: none).
    pinned = _library(scale=0.0, error={"single": 0.3, "seen": 0.6})
    res = diffwash.fit.suggest(pinned, _rows(*CANDIDATES), n=3, queries=q)
    assert all(abs(p.score) < 1e-12 for p in res.picks)
    assert res.variance == pytest.approx(3 * (0.3**2 + 0.6**2) / 3)


@settings(max_examples=6, deadline=None)
@given(st.floats(1e-4, 0.1), st.lists(st.sampled_from(range(7)), min_size=5, max_size=5),
       st.floats(0.0, 3.0), st.floats(0.0, 3.0), st.integers(1, 5))  # fmt: skip
def test_scores_are_non_negative_and_picks_distinct(scale, rows, seen, unseen, n):
    cand = _rows([CANDIDATES[0][i] for i in rows], [CANDIDATES[1][i] for i in rows])
    error = {"single": 0.2, "seen": seen, "unseen": unseen, "unmixed": unseen}
    res = diffwash.fit.suggest(_library(scale, error), cand, n=n)
    assert len(res.picks) == n and len({p.row for p in res.picks}) == n
    assert all(p.score >= 0 and np.isfinite(p.score) for p in res.picks)
    assert all(np.isfinite(p.mean_de2000_90) for p in res.picks)


def test_a_library_without_a_posterior_or_an_empty_table_is_refused_in_python():
    lib = _library()
    with pytest.raises(DiffwashError, match="uncertainty.*fit-swatch --table"):
        diffwash.fit.suggest(library.Library(lib.palette, lib.grounds, lib.observation), _rows(*CANDIDATES))
    with pytest.raises(DiffwashError, match="no pigment 'D'"):
        diffwash.fit.suggest(lib, _rows(["A", "A+D"], ["0.01", "0.01+0.01"]))
    with pytest.raises(DiffwashError, match="has no candidate rows"):
        diffwash.fit.suggest(lib, _rows([], []))
    with pytest.raises(DiffwashError, match="n: must be a whole number"):
        diffwash.fit.suggest(lib, _rows(*CANDIDATES), n=0)


# The command line, on a library fitted by fit-swatch --table from a small table (A, B, C alone; A+B mixed).


def _write_table(path):
    rows = [((n,), (a,)) for n in NAMES for a in (0.01, 0.03, 0.08)]
    rows += [(("A", "B"), ab) for ab in ((0.01, 0.02), (0.03, 0.01), (0.02, 0.02))]
    A = np.zeros((len(rows), 3))
    for r, (ns, am) in enumerate(rows):
        for n, a in zip(ns, am):
            A[r, NAMES.index(n)] += a
    R = np.asarray(_palette().reflectance(jnp.asarray(A), jnp.asarray(PAPER)))
    R = R * np.exp(0.01 * np.random.default_rng(4).standard_normal(R.shape))  # measurement noise: 1%
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["pigment", "amount", "ground", *(f"{g:g}" for g in GRID)])
        w.writerow(["paper", "0", "paper", *PAPER])
        for (ns, am), r in zip(rows, R):
            w.writerow(["+".join(ns), "+".join(f"{a:g}" for a in am), "paper", *r])


@pytest.fixture(scope="module")
def fitted(tmp_path_factory):
    folder = tmp_path_factory.mktemp("suggest")
    _write_table(folder / "table.csv")
    assert main(["fit-swatch", "--table", str(folder / "table.csv"), "-o", str(folder / "lib.json")]) == 0
    (folder / "cand.csv").write_text("pigment,amount,ground\nA+B,0.01+0.02,paper\nA+C,0.02+0.02,paper\n"
                                     "B+C,0.01+0.03,paper\nA,0.05,paper\nA/C,0.02/0.02,paper\n")  # fmt: skip
    return folder


def test_suggest_ranks_through_the_command_line(fitted, tmp_path, capsys):
    out = tmp_path / "ranked.csv"
    assert main(["suggest", str(fitted / "lib.json"), "--table", str(fitted / "cand.csv"), "-n", "5", "-o", str(out)]) == 0
    said = capsys.readouterr()
    assert "5 candidates, 5 queries" in said.out and f"wrote {out}" in said.out and "picked 5/5" in said.err
    rows = list(csv.DictReader(io.StringIO(out.read_text())))
    assert [int(r["rank"]) for r in rows] == [1, 2, 3, 4, 5] and len({r["line"] for r in rows}) == 5
    assert all(float(r["score"]) >= 0 and float(r["mean_de2000_90"]) > 0 for r in rows)
    order = [r["pigment"] for r in rows]
    # A+B at 0.01+0.02 is a row the library was fitted to: it ranks below both pairs never measured mixed.
    assert order.index("A+B") > order.index("B+C") and order.index("A+B") > order.index("A+C")
    # Without -o the ranking goes to stdout; --for names the queries.
    (tmp_path / "q.csv").write_text("pigment,amount,ground\nB+C,0.02+0.02,paper\n")
    assert main(["suggest", str(fitted / "lib.json"), "--table", str(fitted / "cand.csv"), "-n", "2",
                 "--for", str(tmp_path / "q.csv")]) == 0  # fmt: skip
    said = capsys.readouterr()
    ranked = list(csv.DictReader(io.StringIO(said.out)))
    assert len(ranked) == 2 and ranked[0]["pigment"] == "B+C" and "1 queries" in said.err
    api = diffwash.fit.suggest(fitted / "lib.json", fitted / "cand.csv", 2, tmp_path / "q.csv")
    assert [p.pigment for p in api.picks] == [r["pigment"] for r in ranked]


@pytest.mark.parametrize(
    "cand, args, says",
    [
        ("pigment,amount,ground\nA,0.01,paper\nA+Z,0.01+0.01,paper\n", [], "cand.csv: line 3: pigment: no pigment 'Z'"),
        ("pigment,amount,ground\n", [], "cand.csv: has no candidate rows"),
        ("pigment,amount,ground\nA,0.01,black\n", [], "cand.csv: line 2: ground: no ground 'black'"),
        ("pigment,amount,ground\nA+B,0.01,paper\n", [], "cand.csv: line 2: amount"),
        ("pigment,amount,ground\nA,0.01,paper\n", ["-n", "0"], "-n: must be >= 1"),
        ("pigment,amount,ground\nA,0.01,paper\n", ["--for", "EMPTY"], "q.csv: has no query rows"),
    ],
)
def test_bad_input_is_one_line_naming_the_file_and_field_and_writes_nothing(fitted, tmp_path, capsys, cand, args, says):
    (tmp_path / "cand.csv").write_text(cand)
    (tmp_path / "q.csv").write_text("pigment,amount,ground\n")
    args = [str(tmp_path / "q.csv") if a == "EMPTY" else a for a in args]
    out = tmp_path / "ranked.csv"
    assert main(["suggest", str(fitted / "lib.json"), "--table", str(tmp_path / "cand.csv"), *args, "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and says in err[0] and not out.exists()


def test_a_library_without_a_posterior_is_refused_saying_how_to_get_one(tmp_path, capsys):
    lib = _library()
    library.Library(lib.palette, lib.grounds, lib.observation).save(tmp_path / "plain.json")
    (tmp_path / "cand.csv").write_text("pigment,amount,ground\nA,0.01,paper\n")
    assert main(["suggest", str(tmp_path / "plain.json"), "--table", str(tmp_path / "cand.csv")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "plain.json: uncertainty: has no posterior" in err[0] and "fit-swatch --table" in err[0]


def test_a_measurement_table_serves_as_candidates(fitted):
    m = measurements.read_measurements(fitted / "table.csv")
    res = diffwash.fit.suggest(fitted / "lib.json", m, n=3)
    assert len(res.picks) == 3 and res.candidates == len(m)


def test_on_real_paint_it_measures_the_pair_one_wants_at_other_amounts_first():
    """NTU paints (benchmarks/bench_suggest.py --related: following suggest then beats measuring at random on every
    seed): with the wanted pair's other amounts among the candidates, they are what suggest picks, not rows of the
    pairs already measured or of pairs nobody asked about."""
    from dataclasses import replace

    from conftest import ROOT

    m = measurements.read_measurements(ROOT / "data" / "ntu-wpsm" / "ntu-spectral-train.csv")
    m = m.select([set(p) <= {"P1", "P5", "P9"} for p in m.pigments])
    bi = [i for i, w in enumerate(m.wavelengths) if w % 40 == 0]  # 11 bands: a quick fit
    m = replace(m, values=m.values[:, bi], lo=m.lo[:, bi], hi=m.hi[:, bi], wavelengths=tuple(m.wavelengths[i] for i in bi),
                grounds={k: v[bi] for k, v in m.grounds.items()})  # fmt: skip
    key = [frozenset(p) for p in m.pigments]
    amount = [round(sum(a), 4) for a in m.amounts]
    rows = lambda pair: [i for i, k in enumerate(key) if k == frozenset(pair)]  # noqa: E731
    single = [i for i, k in enumerate(key) if len(k) == 1 and amount[i] in (0.02, 0.05, 0.1)]
    wanted, measured, other = rows(("P5", "P9")), rows(("P1", "P5")), rows(("P1", "P9"))
    start = single + measured[:3]
    queries = [i for i in wanted if m.amounts[i][0] == m.amounts[i][1]][:3]  # 1:1
    asked = {tuple(sorted(zip(m.pigments[i], m.amounts[i]))) for i in queries}
    related = [i for i in wanted if tuple(sorted(zip(m.pigments[i], m.amounts[i]))) not in asked][:2]
    cand = sorted(related + other[:6] + measured[3:6])
    lib = diffwash.fit.fit_mixtures(m.select(np.isin(np.arange(len(m)), start))).library
    res = diffwash.fit.suggest(lib, m.select(np.isin(np.arange(len(m)), cand)), n=2,
                               queries=m.select(np.isin(np.arange(len(m)), queries)))  # fmt: skip
    assert {p.pigment for p in res.picks} <= {"P5+P9", "P9+P5"}, [(p.pigment, p.amount, p.score) for p in res.picks]
