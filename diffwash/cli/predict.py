"""Predict the colour of layers of a library's pigments: LIBRARY.json --table QUERIES.csv -o PRED.csv.

Each query row `pigment,amount,ground` -- a single paint (`P1,0.05,paper`), a mixture in one layer
(`P1+P3,0.01+0.02,paper`) or a glaze stack, its layers joined by `/`, bottom first (`P1/P3,0.02/0.03,paper`:
P3 brushed over dry P1) -- gets its predicted `r,g,b` (8-bit sRGB, unclipped), `L*,a*,b*` (CIELAB, the
library's illuminant and observer), `de2000_90` where the library has a posterior (its "uncertainty"): the
CIEDE2000 radius of the row's 90% region (empty for a kind of row the library has no model error for), and,
for a spectral library, its reflectance on the library's bands. LIBRARY is any diffwash library (what
fit-swatch writes from swatch-card photos or from a table) or an older pigment file. The Python equivalent is
diffwash.library.predict(LIBRARY, QUERIES).
"""

from __future__ import annotations

import time

import diffwash

from .. import io as dio
from . import check_output

USES_JAX = True


def add_arguments(p) -> None:
    p.add_argument("library", metavar="LIBRARY.json",
                   help="a diffwash library (fit-swatch of swatch-card photos or of a table) or an older pigment file")
    p.add_argument("--table", required=True, metavar="CSV",
                   help="the rows to predict: pigment,amount,ground (A+B a mixture, A/B a glaze stack, bottom first)")
    p.add_argument("-o", "--output", required=True, metavar="CSV", help="the predictions to write")


def run(args) -> int:
    t0 = time.perf_counter()
    out = check_output(args.output, ".csv", "--output")
    dio.refuse_overwriting_inputs({"--output": out}, [args.library, args.table])
    lib = diffwash.library.load_library(args.library)
    queries = diffwash.measurements.read_queries(args.table)
    pred = lib.predict(queries)
    diffwash.library.write_prediction(out, queries, pred)
    print(f"{len(queries)} rows predicted from {len(lib.names)} pigments ({'spectral, ' + str(len(pred.bands)) + ' bands' if lib.spectral else 'sRGB'})")
    print(f"wrote {out}")
    print(f"done in {time.perf_counter() - t0:.2f} s")
    return 0
