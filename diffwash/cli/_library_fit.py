"""`diffwash fit-swatch --table` for spectral tables and mixtures: one joint fit, one library file.

Single-pigment RGB tables (grounds paper and black, no mixtures, no glaze stacks) keep their own fit (`diffwash.fit.fit_table`);
every other table goes through `diffwash.fit.fit_mixtures`.
"""

from __future__ import annotations

import csv
import sys
import time
from pathlib import Path

import numpy as np

import diffwash

from .. import DiffwashError, FailureError
from .. import io as dio


def _needs_library(table: str) -> bool:
    """Band columns named by wavelength, or a `+` (mixture) or `/` (glaze stack) in the pigment column (a glance:
    the readers validate)."""
    try:
        with dio.open_input(table, "r", newline="", encoding="utf-8-sig") as f:
            rows = csv.reader(f)
            header = [h.strip().lower() for h in next(rows, [])]
            if any(h.replace(".", "", 1).isdigit() for h in header):
                return True
            col = header.index("pigment") if "pigment" in header else 0
            return any(len(r) > col and ("+" in r[col] or "/" in r[col]) for r in rows)
    except (OSError, UnicodeDecodeError, csv.Error, DiffwashError):
        return False  # the table's own reader says what is wrong with it


def wants_library(table: str, linear: bool) -> diffwash.measurements.Measurements | None:
    """The table's measurements if it needs the joint mixture fit (spectral, or with mixtures), else None
    (single-pigment RGB tables keep `diffwash.fit.fit_table` and its reader's errors)."""
    if not _needs_library(table):
        return None
    return diffwash.measurements.read_measurements(table, linear=linear)


def run_library(args, m: diffwash.measurements.Measurements, out: Path, report: Path | None) -> int:
    """Fit every pigment of `m` jointly and write the library to `out`."""
    t0 = time.perf_counter()
    for flag in ("plain", "thickness", "loss", "batch"):
        if getattr(args, flag):
            raise DiffwashError("does not apply to a spectral or mixture table (fitted jointly: see docs/mixing.md)",
                                field=f"--{flag}")  # fmt: skip
    if getattr(args, "linear", False) and m.spectral:
        raise DiffwashError("applies to r,g,b tables (a spectral table's band columns are reflectance already)",
                            field="--linear")  # fmt: skip
    if args.refine and not m.spectral:
        raise DiffwashError("applies to spectral tables (an RGB table is fitted in CIEDE2000 already)", field="--refine")
    model = diffwash.fit.MixModel(weights=args.mixing == "weights", surface=args.surface == "saunderson",
                     loss="spectral" if args.refine == "none" else "de2000", pairs=args.pair_terms != "off")
    fit = diffwash.fit.fit_mixtures(m, model=model, max_steps=args.max_steps, progress=_stage_printer(t0))
    kind = f"{len(m.wavelengths)} bands" if m.spectral else "sRGB, fitted as smooth spectra"
    s = fit.summary()
    stacks = f"{int(np.sum(m.is_stack))} glaze stacks; " if np.any(m.is_stack) else ""
    print(f"{len(fit.library.names)} pigments from {len(m)} rows ({int(np.sum(m.is_mixture))} mixtures; {stacks}{kind}); "
          f"model: {', '.join(f'{k}={v}' for k, v in model.describe().items())}")  # fmt: skip
    print(f"  mean CIEDE2000 {s['mean_de2000']:.2f} (median {s['median_de2000']:.2f}, 95th percentile "
          f"{s['p95_de2000']:.2f}, max {s['max_de2000']:.2f}); {100 * s['share_de_ab_5']:.1f}% within dE*ab 5")
    for r in (fit.library.fit or {}).get("dominant_rows", []):
        print(f"  line {r['line']} ({r['pigment']} at {r['amount']} on {r['ground']}, CIEDE2000 {r['de2000']:.1f}) holds "
              f"{100 * r['share']:.0f}% of the fit's loss: one row steers the fit; check it (a typo, a mislabelled "
              "sample)")  # fmt: skip
    status = "converged" if fit.converged else "did not converge"
    print(f"  Levenberg-Marquardt {status} in {fit.iterations} steps")
    for c in fit.convergence:
        print(f"  {c.describe()}")
    terms = fit.library.palette.pairs
    if terms is not None and terms.inferred:
        n = len(terms.inferred)
        print(f"  pair terms inferred for {n} pair{'s' if n != 1 else ''} never measured mixed, from their paints' "
              "effects in the measured pairs (marked \"inferred\" in the library; docs/mixing.md)")  # fmt: skip
    print_uncertainty(fit.library)
    if not fit.converged and not args.allow_unconverged:
        far = "; ".join(c.describe() for c in fit.convergence if not c)
        raise FailureError(f"the fit did not converge ({far}); nothing was written (use --allow-unconverged to write "
                           "it anyway, or raise --max-steps)")  # fmt: skip
    with dio.atomic_paths(out, report) as (out_tmp, report_tmp):  # both files or neither
        dio.write_json(out_tmp, fit.library.to_dict())
        if report is not None:
            diffwash.fit.save_mixture_report(report_tmp, fit, m)
    print(f"wrote {out}" + (f" and {report}" if report is not None else ""))
    print(f"done in {time.perf_counter() - t0:.2f} s")
    return 0


def _stage_printer(t0: float):
    """Where standard error is a terminal: a `progress` callback that says each stage of the fit as it begins,
    with the time so far (a large table's fit takes minutes); elsewhere None (logs keep only the summary)."""
    if not sys.stderr.isatty():
        return None
    return lambda stage: print(f"  {stage}... ({time.perf_counter() - t0:.0f} s)", file=sys.stderr, flush=True)


def print_uncertainty(lib) -> None:
    """A library's 90% regions' model errors and, per pigment, what its rows determined (its fit's record)."""
    unc = (lib.fit or {}).get("uncertainty")
    if unc is None:
        return
    errors = ", ".join(f"{k} {v:.2f}" for k, v in unc["model_error"].items())
    print(f"  90% regions: model error (CIELAB units per axis) {errors}")
    if str(unc.get("unmixed_from", "")).startswith("the prior"):
        print(f"    unmixed: {unc['unmixed_from']}")
    for line in diffwash.fit.uncertainty_lines(unc["pigments"]):
        print(line)
