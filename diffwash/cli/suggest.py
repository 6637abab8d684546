"""What to paint next: LIBRARY.json --table CANDIDATES.csv [-n 5] [--for QUERIES.csv] [-o RANKED.csv].

Ranks the candidate rows (`pigment,amount,ground`, the rows of a query table: single paints, mixtures `A+B`,
glaze stacks `A/B`; measured values, if the table has any, are not read) by how much measuring them would shrink
the 90% regions (`de2000_90`) of the queries' predictions under the library's posterior (its "uncertainty": what
fit-swatch stores for swatch-card photos, noise-weighted as by default, and for tables, spectral ones refined in
CIEDE2000 as by default and RGB ones with mixtures or glaze stacks; a library without one is refused), greedily:
each pick is scored as if the ones above it were measured. Without --for the queries are the candidates
themselves. Writes `rank,pigment,amount,ground,score,mean_de2000_90,line`: the score is the reduction of the
queries' mean predictive variance (CIELAB units squared), mean_de2000_90 the queries' expected mean region once
that row and those above it are measured. The Python equivalent is diffwash.fit.suggest(LIBRARY, CANDIDATES, n,
QUERIES); docs/mixing.md says how it is computed and what following it gave on real paint.
"""

from __future__ import annotations

import sys
import time

import diffwash

from .. import DiffwashError
from .. import io as dio
from . import check_output

USES_JAX = True


def add_arguments(p) -> None:
    p.add_argument("library", metavar="LIBRARY.json",
                   help="a library with a posterior: fit-swatch's of swatch-card photos or of a table (not of an RGB "
                        "table of single paints only, nor with --refine none or a --loss other than noise)")  # fmt: skip
    p.add_argument("--table", required=True, metavar="CSV", help="the candidate rows: pigment,amount,ground")
    p.add_argument("-n", type=int, default=5, metavar="N", help="how many to rank (default 5)")
    p.add_argument("--for", dest="queries", metavar="CSV", default=None,
                   help="the rows whose regions should shrink (default: the candidates themselves)")  # fmt: skip
    p.add_argument("-o", "--output", metavar="CSV", default=None, help="write the ranking here (default: stdout)")


def _progress(i: int, n: int) -> None:
    """After each pick: on a terminal one line rewritten in place; elsewhere (a log file) a line per pick."""
    if sys.stderr.isatty():
        print(f"\rsuggest: picked {i}/{n}", end="" if i < n else "\n", file=sys.stderr, flush=True)
    else:
        print(f"suggest: picked {i}/{n}", file=sys.stderr, flush=True)


def run(args) -> int:
    t0 = time.perf_counter()
    if args.n < 1:
        raise DiffwashError(f"must be >= 1, got {args.n}", field="-n")
    out = None
    if args.output is not None:
        out = check_output(args.output, ".csv", "--output")
        dio.refuse_overwriting_inputs({"--output": out}, [p for p in (args.library, args.table, args.queries) if p])
    res = diffwash.fit.suggest(args.library, args.table, args.n, args.queries, progress=_progress)
    last = res.picks[-1].mean_de2000_90 if res.picks else float("nan")
    what = "the candidates themselves" if args.queries is None else args.queries
    lines = [f"{res.candidates} candidates, {res.queries} queries ({what}): mean de2000_90 now {res.mean_de2000_90:.3f}, "
             f"expected {last:.3f} after measuring the {len(res.picks)} ranked"]  # fmt: skip
    if out is None:
        sys.stdout.write(res.csv_text())
        print(*lines, f"done in {time.perf_counter() - t0:.2f} s", sep="\n", file=sys.stderr)
    else:
        diffwash.fit.write_suggestions(out, res)
        print(*lines, f"wrote {out}", f"done in {time.perf_counter() - t0:.2f} s", sep="\n")
    return 0
