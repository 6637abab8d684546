"""What to paint next, on real paint: following `diffwash.fit.suggest` against measuring at random (NTU WPSM).

    python benchmarks/bench_suggest.py [--seeds 0 1 2] [--rounds 4] [--per-round 2] [--json PATH]

The NTU spectral table's seven paints that were measured mixed in all 21 of their pairs (P1, P3, P5, P7, P9,
P10, P13), on a 20 nm grid (21 bands, to keep each refit cheap). Per seed the 21 pairs are shuffled:

- **queries**: 6 pairs held out, 4 rows of each (24 rows): never measured, never candidates (with `--related N`,
  N more rows of each query pair, at other amounts than its queries', are candidates: the pairs one wants to
  predict may be painted at other amounts, as a user planning swatches would);
- **start**: every paint alone at amounts 0.02, 0.05 and 0.1 (21 rows; `--single-amounts` to change) and 2 rows
  of each of 3 pairs;
- **candidates**: 4 rows of each of the other 12 pairs and the start pairs' other 2 rows each (54 rows), their
  measured values hidden until a strategy measures them.

Each round a strategy measures `--per-round` candidates (adds their true rows to its table) and refits
(`fit_mixtures`, default model, with its posterior): `suggest` takes the top picks of
`diffwash.fit.suggest(library, candidates, n, queries)` (the queries given, as `--for` does), `random` draws
them uniformly. After every refit, on the queries: mean CIEDE2000 against the measured colours, the mean
`de2000_90` and the share of queries their regions hold. Prints Markdown tables; float32 on the CPU. Every
strategy, seed and round shares the JIT compilation cache (the persistent one included: a rerun is cheaper).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import replace
from pathlib import Path

import jax.numpy as jnp
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import diffwash  # noqa: E402
from diffwash import colorimetry, measurements  # noqa: E402
from diffwash.fit import fit_mixtures, suggest  # noqa: E402
from diffwash.fit.tables._mixfit import measured_lab, pairs  # noqa: E402

TABLE = ROOT / "data" / "ntu-wpsm" / "ntu-spectral-train.csv"
PAINTS = {"P1", "P3", "P5", "P7", "P9", "P10", "P13"}
SINGLE_AMOUNTS = (0.02, 0.05, 0.1)
QUERY_PAIRS, START_PAIRS, ROWS_PER_PAIR, START_ROWS = 6, 3, 4, 2


def load() -> measurements.Measurements:
    """The seven paints' rows on a 20 nm grid."""
    m = measurements.read_measurements(TABLE)
    m = m.select([set(p) <= PAINTS for p in m.pigments])
    bi = [i for i, w in enumerate(m.wavelengths) if w % 20 == 0]
    return replace(m, values=m.values[:, bi], lo=m.lo[:, bi], hi=m.hi[:, bi], wavelengths=tuple(m.wavelengths[i] for i in bi),
                   grounds={k: v[bi] for k, v in m.grounds.items()})  # fmt: skip


def _mixture(m: measurements.Measurements, i: int) -> frozenset:
    """Row `i`'s pigments with their amounts (`A+B` at a+b and `B+A` at b+a are the same swatch)."""
    return frozenset((p, round(a, 6)) for p, a in zip(m.pigments[i], m.amounts[i]))


def split(m: measurements.Measurements, seed: int, single_amounts=SINGLE_AMOUNTS, related: int = 0) -> dict[str, np.ndarray]:
    """Row indices of the start table, the candidates and the queries (module docstring)."""
    rng = np.random.default_rng(seed)
    key = [tuple(sorted(set(p))) for p in m.pigments]
    amt = np.array([sum(a) for a in m.amounts])
    start = []
    for p in sorted(PAINTS):
        for a in single_amounts:
            start.append(next(i for i, k in enumerate(key) if k == (p,) and abs(amt[i] - a) < 1e-9))
    ps = pairs(m)
    order = [ps[i] for i in rng.permutation(len(ps))]
    rows = {q: rng.permutation([i for i, k in enumerate(key) if k == q])[:ROWS_PER_PAIR] for q in order}
    query = np.concatenate([rows[q] for q in order[:QUERY_PAIRS]])
    cand = []
    for q in order[:QUERY_PAIRS]:  # the query pairs at other amounts (none of them the same swatch as a query)
        asked = {_mixture(m, i) for i in rows[q]}
        other, seen = [], set(asked)
        for i in rng.permutation([i for i, k in enumerate(key) if k == q]):
            if _mixture(m, int(i)) not in seen:
                seen.add(_mixture(m, int(i)))
                other.append(int(i))
        cand += other[:related]
    for j, q in enumerate(order[QUERY_PAIRS:]):
        if j < START_PAIRS:
            start += list(rows[q][:START_ROWS])
            cand += list(rows[q][START_ROWS:])
        else:
            cand += list(rows[q])
    return {"start": np.array(start), "candidates": np.array(cand), "queries": query}


def evaluate(lib, q: measurements.Measurements) -> dict[str, float]:
    pred = lib.predict(q)
    lab_m = measured_lab(q, lib.observation)
    de = np.asarray(colorimetry.delta_e_2000(jnp.asarray(lab_m), jnp.asarray(pred.lab)), np.float64)
    r90 = pred.de2000_90
    return {"mean_de2000": float(de.mean()), "mean_de2000_90": float(np.nanmean(r90)), "held": float(np.mean(de <= r90))}


def run_strategy(m, parts, strategy: str, seed: int, rounds: int, per_round: int) -> list[dict]:
    rng = np.random.default_rng(1000 + seed)
    have, left = list(parts["start"]), list(parts["candidates"])
    q = m.select(np.isin(np.arange(len(m)), parts["queries"]))
    out = []
    for r in range(rounds + 1):
        t0 = time.perf_counter()
        fit = fit_mixtures(m.select(np.isin(np.arange(len(m)), have)))
        score = {"strategy": strategy, "seed": seed, "round": r, "rows": len(have), "fit_s": time.perf_counter() - t0,
                 "converged": bool(fit.converged), **evaluate(fit.library, q)}  # fmt: skip
        if r == rounds:
            out.append(score)
            break
        t0 = time.perf_counter()
        if strategy == "suggest":
            cand = m.select(np.isin(np.arange(len(m)), left))  # rows in table order, as `left` sorted
            res = suggest(fit.library, cand, per_round, q)
            order = np.sort(left)
            picks = [int(order[p.row]) for p in res.picks]
            score["expected_mean_de2000_90"] = res.picks[-1].mean_de2000_90
        else:
            picks = [int(i) for i in rng.choice(left, per_round, replace=False)]
        score["pick_s"] = time.perf_counter() - t0
        score["picked"] = [m.row_text(i)[0] + "@" + m.row_text(i)[1] for i in picks]
        out.append(score)
        print(json.dumps(score), file=sys.stderr, flush=True)
        have += picks
        left = [i for i in left if i not in picks]
    return out


def table(results: list[dict], rounds: int) -> str:
    """Per round and strategy, the means over seeds; for suggest, also what it expected the round before."""
    lines = ["| round | rows | strategy | held-out mean dE2000 | mean de2000_90 (suggest expected) | held by the regions | "
             "seeds where suggest < random: dE2000, de2000_90 |", "| --- | --- | --- | --- | --- | --- | --- |"]  # fmt: skip
    for r in range(rounds + 1):
        by = {s: sorted((x for x in results if x["strategy"] == s and x["round"] == r), key=lambda x: x["seed"])
              for s in ("suggest", "random")}  # fmt: skip
        wins = ""
        if by["suggest"] and len(by["suggest"]) == len(by["random"]):
            a, b = by["suggest"], by["random"]
            w1 = sum(x["mean_de2000"] < y["mean_de2000"] for x, y in zip(a, b))
            w2 = sum(x["mean_de2000_90"] < y["mean_de2000_90"] for x, y in zip(a, b))
            wins = f"{w1}/{len(a)}, {w2}/{len(a)}"
        for s, xs in by.items():
            if not xs:
                continue
            mean = {k: np.mean([x[k] for x in xs]) for k in ("mean_de2000", "mean_de2000_90", "held", "rows")}
            before = [x for x in results if x["strategy"] == s and x["round"] == r - 1 and "expected_mean_de2000_90" in x]
            expect = f" ({np.mean([x['expected_mean_de2000_90'] for x in before]):.2f})" if before else ""
            lines.append(f"| {r} | {mean['rows']:.0f} | {s} | {mean['mean_de2000']:.2f} | {mean['mean_de2000_90']:.2f}{expect} | "
                         f"{100 * mean['held']:.0f}% | {wins if s == 'suggest' else ''} |")  # fmt: skip
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--rounds", type=int, default=4)
    ap.add_argument("--per-round", type=int, default=2)
    ap.add_argument("--single-amounts", type=float, nargs="+", default=list(SINGLE_AMOUNTS),
                    help="the amounts each paint is measured alone at in the start table")  # fmt: skip
    ap.add_argument("--related", type=int, default=0,
                    help="rows of each query pair, at other amounts than the queries', among the candidates")
    ap.add_argument("--json", default=None, help="write every round's numbers here")
    ap.add_argument("--table-from", default=None, metavar="JSON", help="print the tables of an earlier --json, run nothing")
    args = ap.parse_args()
    if args.table_from:
        results = json.loads(Path(args.table_from).read_text())
        print(table(results, max(x["round"] for x in results)))
        return
    diffwash.enable_compilation_cache()
    t0 = time.perf_counter()
    m = load()
    results = []
    for seed in args.seeds:
        parts = split(m, seed, args.single_amounts, args.related)
        for strategy in ("suggest", "random"):
            results += run_strategy(m, parts, strategy, seed, args.rounds, args.per_round)
            if args.json:  # as it goes: a long run that stops keeps what it measured
                Path(args.json).write_text(json.dumps(results, indent=1))
    print(f"NTU WPSM, 7 paints, 21 bands; seeds {args.seeds}; alone at {args.single_amounts}; {args.per_round} rows measured per round; "
          f"{len(parts['queries'])} query rows of {QUERY_PAIRS} pairs never measured; {len(parts['candidates'])} candidates"
          f" ({args.related} rows of each query pair at other amounts among them)\n")
    print(table(results, args.rounds))
    print(f"\nwall {time.perf_counter() - t0:.0f} s; mean refit {np.mean([x['fit_s'] for x in results]):.1f} s")


if __name__ == "__main__":
    main()
