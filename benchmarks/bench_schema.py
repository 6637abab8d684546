"""How long the declared table format (`diffwash._schema.MeasurementRow`) takes to check a table at the row limit.

    python benchmarks/bench_schema.py [--rows 4000] [--repeats 5]

Prints the wall time of checking every row (one pydantic call over the rows, after the checker is built) and of a
whole `diffwash.measurements.read_measurements` of the same 41-band table. Issue 23's declared schemas must not
make reading a table slow: the checks took 65 ms for 4,000 rows when they were written (2026-11-26).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from diffwash import measurements  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rows", type=int, default=4000)
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    rng = np.random.default_rng(0)
    waves = range(380, 790, 10)
    rows = [f"P{i % 7},{rng.uniform(0.01, 0.05):.4f},paper," + ",".join(f"{v:.4f}" for v in rng.uniform(0, 1, 41))
            for i in range(args.rows - 1)]  # fmt: skip
    head = "pigment,amount,ground," + ",".join(map(str, waves)) + "\npaper,0,paper," + ",".join(["0.85"] * 41) + "\n"
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "t.csv"
        path.write_text(head + "\n".join(rows) + "\n")
        header, body = measurements._read_csv(path)
        col = measurements._key_columns(header, path)
        vcols, _ = measurements._band_columns(header, path)
        measurements._checked_rows("MeasurementRow", body[:1], header, col, vcols, path)  # the checker, built once
        check, read = [], []
        for _ in range(args.repeats):
            t = time.perf_counter()
            measurements._checked_rows("MeasurementRow", body, header, col, vcols, path)
            check.append(time.perf_counter() - t)
            t = time.perf_counter()
            measurements.read_measurements(path)
            read.append(time.perf_counter() - t)
    print(f"| rows | check every row, ms (median of {args.repeats}) | read_measurements, ms |\n|---|---|---|")
    print(f"| {args.rows} | {1000 * np.median(check):.0f} | {1000 * np.median(read):.0f} |")


if __name__ == "__main__":
    main()
