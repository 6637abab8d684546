"""Fit a pigment's K and S (per coat) to photos of its swatch card (PHOTO --layout LAYOUT.json), or every pigment of
a table of measured colours at once (--table MEASUREMENTS.csv), and write a library file (diffwash.library: what
predict, scenes and fit-image read; from three-channel data, per sRGB channel and a pigment file too) with the
fit's diagnostics. Cards whose layouts hold several pigments, alone or mixed ("pigment": "P1+P4", "coats": "1+2"),
are fitted jointly into a library, as a mixture table is. The layout and CSV formats are in docs/fitting.md; the
Python equivalents are diffwash.fit.fit_swatches(PHOTO, LAYOUT), diffwash.fit.fit_swatch_mixtures(PHOTOS, LAYOUTS)
and diffwash.fit.fit_table(CSV). A fit that does not converge writes nothing and exits with status 1, unless
--allow-unconverged.
"""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path

import numpy as np

import diffwash

from .. import DiffwashError, FailureError
from .. import io as dio
from . import _library_fit, add_image_limit, check_output

USES_JAX = True


def add_arguments(p) -> None:
    p.add_argument("photos", nargs="*", metavar="PHOTO",
                   help="photo(s) of one pigment's swatch card (PNG 8/16 bit, JPEG), or of cards whose layouts name "
                        "several pigments, alone or mixed (fitted jointly into a library)")  # fmt: skip
    p.add_argument("--layout", action="append", metavar="LAYOUT.json",
                   help="where the paper, black band and patches are in the photo (one per photo)")  # fmt: skip
    p.add_argument("--checker", action="store_true",
                   help="find an X-Rite ColorChecker Classic in each photo and calibrate the camera (tone curve and "
                        "colour matrix) from its 24 patches (needs the 'photo' extra)")  # fmt: skip
    p.add_argument("--tone-curve", choices=("auto", "camera", "srgb"), default="auto",
                   help="how a photo without references is read: a typical camera's tone curve (camera) or the sRGB "
                        "curve (srgb); auto (default): camera when the file's EXIF names a camera")  # fmt: skip
    p.add_argument("--table", metavar="CSV", help="fit every pigment of a measurement table instead of a photo")
    p.add_argument("-o", "--output", required=True, metavar="JSON", help="the library file to write (diffwash predict and scenes read it)")
    p.add_argument("--name", help="the pigment's name (default: the layout's 'name', else the photo's file name); "
                                  "on cards of several pigments, that of the patches that name none")
    p.add_argument("--report", metavar="PNG", help="also write a picture of observed vs fitted colours")
    p.add_argument("--linear", action="store_true", help="the table's r, g, b are linear reflectance, not sRGB")
    p.add_argument("--plain", action="store_true",
                   help="table: the plain fit (thickness = amount, sRGB residuals, no prior) instead of the model")
    p.add_argument("--thickness", choices=("power", "linear"),
                   help="table: thickness = amount**gamma (power, default) or amount")  # fmt: skip
    p.add_argument("--loss", choices=("noise", "de2000", "cie94", "lab", "srgb"),
                   help="residuals (default: noise for photos -- weighted by each patch's noise, with intervals -- "
                        "de2000 for tables)")
    p.add_argument("--mixing", choices=("duncan", "weights"), default="duncan",
                   help="spectral or mixture table, or cards of several pigments: Duncan's concentration-weighted sums (default), or with a fitted "
                        "mixing weight per pigment (docs/mixing.md says what each gives on pairs never seen mixed)")
    p.add_argument("--refine", choices=("de2000", "none"),
                   help="spectral table: after the log-reflectance fit, refine in CIEDE2000 with a ridge towards its "
                        "spectra (de2000, the default; docs/mixing.md), or stop at the log-reflectance fit")
    p.add_argument("--pair-terms", choices=("on", "off"),
                   help="table: fit pair terms for the pairs it measured mixed, and infer them for pairs "
                        "of paints each measured mixed with others (on, the default; docs/mixing.md), or Duncan's "
                        "sums for every mixture")
    p.add_argument("--surface", choices=("none", "saunderson"),
                   help="table: Saunderson's surface correction (default: none)")
    p.add_argument("--batch", choices=("auto", "vmap", "loop"),
                   help="table: pigments vmapped in one program, or one after another (default auto: "
                        "a loop on a CPU for up to 16 pigments, where it is faster)")  # fmt: skip
    p.add_argument("--max-steps", type=int, default=1000, metavar="N",
                   help="Levenberg-Marquardt steps at most per solve (default: %(default)s); a one-pigment card fit "
                        "weighted by its noise solves up to four times as it re-estimates the noise, and reports "
                        "the steps of all its solves")  # fmt: skip
    p.add_argument("--allow-unconverged", action="store_true", help="write the result even if the fit did not converge")
    add_image_limit(p)


def _srgb8(linear) -> str:
    d = diffwash.colorimetry.to_display(linear)
    return "(" + ", ".join(f"{int(round(255 * c)):3d}" for c in d) + ")"


def run(args) -> int:
    out = check_output(args.output, ".json", "--output")
    report = check_output(args.report, ".png", "--report") if args.report else None
    if args.max_steps < 1:
        raise DiffwashError(f"must be at least 1, got {args.max_steps}", field="--max-steps")
    dio.refuse_overwriting_inputs({"--output": out, "--report": report}, [*args.photos, *(args.layout or []), args.table])
    if args.table is not None:
        if args.photos or args.layout:
            raise DiffwashError("give either --table or photos with --layout, not both", field="--table")
        if args.checker:
            raise DiffwashError("only applies to photos", field="--checker")
        if args.tone_curve != "auto":
            raise DiffwashError("only applies to photos", field="--tone-curve")
        return _run_table(args, out, report)
    if not args.photos:
        raise DiffwashError("needs a PHOTO and its --layout, or --table CSV", field="PHOTO")
    for flag in ("plain", "thickness", "surface", "linear", "batch", "refine", "pair_terms"):
        if getattr(args, flag):
            raise DiffwashError("only applies to --table fits", field=f"--{flag.replace('_', '-')}")
    if not args.layout:
        raise DiffwashError("missing: each photo needs its layout file", field="--layout")
    if len(args.layout) != len(args.photos):
        raise DiffwashError(f"got {len(args.photos)} photos but {len(args.layout)} layouts (one per photo)",
                            field="--layout")  # fmt: skip
    return _run_photos(args, out, report)


def _finish(converged: bool, allow: bool, what: str) -> None:
    if not converged and not allow:
        raise FailureError(f"{what} did not converge; nothing was written (use --allow-unconverged to write it anyway, "
                           f"or raise --max-steps)")  # fmt: skip


def _wrote(*paths: Path | None) -> None:
    for p in paths:
        if p is not None:
            print(f"wrote {p}")


def _print_cameras(calibrations, photos) -> None:
    """Each photo's camera model fitted to its references, with its leave-one-out accuracy."""
    for c, ph in zip(calibrations, photos):
        if c.camera is not None:
            m = c.camera
            print(f"{ph}: calibrated from {m.references} references of known colour: {m.name}; accuracy (mean "
                  f"CIEDE2000 of each reference predicted from the others) {m.accuracy:.2f}")  # fmt: skip


def _run_photos(args, out: Path, report: Path | None) -> int:
    t0 = time.perf_counter()
    if len(diffwash.fit.swatch_pigments(args.layout, name=args.name, default=Path(args.photos[0]).stem)) > 1:
        return _run_mixture_photos(args, out, report, t0)
    model = diffwash.fit.SWATCH_MODEL
    if args.loss is not None and args.loss != diffwash.fit.SWATCH_MODEL.loss:
        model = diffwash.fit.FitModel(thickness="linear", loss=args.loss)
    fit = diffwash.fit.fit_swatches(args.photos, args.layout, name=args.name, model=model, max_steps=args.max_steps,
                                    checker=args.checker, tone_curve=args.tone_curve)  # fmt: skip
    _print_cameras(fit.calibrations, args.photos)
    p = fit.pigment
    print(f"{p.name}: {len(fit.patches)} patches from {len(args.photos)} photo{'s' if len(args.photos) > 1 else ''}")
    print(f"  {'coats':>5}  {'ground':6}  {'observed sRGB':>15}  {'fitted sRGB':>15}  {'CIEDE2000':>9}")
    for q in fit.patches:
        flag = "  (clipped: a bound)" if any(q.bound) else ""
        if q.floor and any(q.floor):
            flag += "  (" + ", ".join(c for c, f in zip(("red", "green", "blue"), q.floor) if f) + " at the noise floor)"
        print(f"  {q.coats:5g}  {q.ground:6}  {_srgb8(q.observed):>15}  {_srgb8(q.fitted):>15}  {q.delta_e:9.2f}{flag}")
    print(f"  K = {np.round(p.K, 4).tolist()}, S = {np.round(p.S, 4).tolist()} per coat")
    for line in fit.interval_lines():
        print(f"  {line}")
    post = fit.posterior()
    if post is not None:
        print(f"  90% regions of predict: the posterior above and a model error (CIELAB units per axis) single "
              f"{post.model_error['single']:.2f}, the calibration's own error")  # fmt: skip
    status = "converged" if fit.converged else "did not converge"
    print(f"  mean CIEDE2000 {fit.mean_delta_e:.2f}; Levenberg-Marquardt {status} in {fit.iterations} steps")
    for c in fit.calibrations:
        for note in c.notes:
            print(f"  note: {note}")
    print(f"  {fit.identifiability}")
    _finish(fit.converged, args.allow_unconverged, "the fit")
    with dio.atomic_paths(out, report) as (out_tmp, report_tmp):  # both files or neither
        fit.save(out_tmp)
        if report is not None:
            photo, _ = dio.read_image(args.photos[0])
            diffwash.fit.save_swatch_report(report_tmp, fit, photo, diffwash.fit.read_layout(args.layout[0]))
    _wrote(out, report)
    print(f"done in {time.perf_counter() - t0:.2f} s")
    return 0


def _run_mixture_photos(args, out: Path, report: Path | None, t0: float) -> int:
    """Cards of several pigments, alone or mixed: one joint fit (`fit_swatch_mixtures`), one library."""
    if args.loss is not None:
        raise DiffwashError("does not apply to cards of several pigments (fitted jointly in CIEDE2000: "
                            "docs/fitting.md)", field="--loss")  # fmt: skip
    model = dataclasses.replace(diffwash.fit.CARD_MODEL, weights=args.mixing == "weights")
    fit = diffwash.fit.fit_swatch_mixtures(args.photos, args.layout, name=args.name, model=model,
                                           max_steps=args.max_steps, checker=args.checker,
                                           tone_curve=args.tone_curve)  # fmt: skip
    _print_cameras(fit.calibrations, args.photos)
    n = len(args.photos)
    paints = [fit.measurements.row_text(i) for i in range(len(fit.patches))]  # `A+B` mixed, `A/B` a glaze stack
    print(f"{len(fit.names)} pigments ({', '.join(fit.names)}) from {len(fit.patches)} patches "
          f"({_kinds_of_patches(fit.measurements)}) in {n} photo{'s' if n > 1 else ''}, fitted jointly as smooth "
          f"spectra seen through sRGB")  # fmt: skip
    width = max(len("pigment"), *(len(pigment) for pigment, _ in paints))
    cw = max(len("coats"), *(len(coats) for _, coats in paints))
    print(f"  {'pigment':<{width}}  {'coats':>{cw}}  {'ground':6}  {'observed sRGB':>15}  {'fitted sRGB':>15}  "
          f"{'CIEDE2000':>9}")  # fmt: skip
    for q, (pigment, coats) in zip(fit.patches, paints):
        flag = "  (clipped: a bound)" if any(q.bound) else ""
        print(f"  {pigment:<{width}}  {coats:>{cw}}  {q.ground:6}  {_srgb8(q.observed):>15}  "
              f"{_srgb8(q.fitted):>15}  {q.delta_e:9.2f}{flag}")  # fmt: skip
    status = "converged" if fit.converged else "did not converge"
    print(f"  mean CIEDE2000 {fit.mean_delta_e:.2f} (max {max(q.delta_e for q in fit.patches):.2f}); "
          f"Levenberg-Marquardt {status} in {fit.iterations} steps")  # fmt: skip
    for c in fit.calibrations:
        for note in c.notes:
            print(f"  note: {note}")
    _library_fit.print_uncertainty(fit.library)
    _finish(fit.converged, args.allow_unconverged, "the fit")
    with dio.atomic_paths(out, report) as (out_tmp, report_tmp):  # both files or neither
        fit.save(out_tmp)
        if report is not None:
            diffwash.fit.save_mixture_report(report_tmp, fit.mixture, fit.measurements)
    _wrote(out, report)
    print(f"  a library of {len(fit.names)} mixable pigments (amounts in coats): diffwash predict {out} --table ...")
    print(f"done in {time.perf_counter() - t0:.2f} s")
    return 0


def _kinds_of_patches(m) -> str:
    """`N mixtures` (patches of one layer mixing pigments), and `, M glaze stacks` where there are any."""
    stacks = int(np.sum(m.is_stack))
    mixtures = int(np.sum(m.is_mixture & ~m.is_stack))
    return f"{mixtures} mixtures" + (f", {stacks} glaze stacks" if stacks else "")


def _run_table(args, out: Path, report: Path | None) -> int:
    mixtures = _library_fit.wants_library(args.table, args.linear)
    if mixtures is not None:  # spectral bands or mixtures: one joint fit, one library
        return _library_fit.run_library(args, mixtures, out, report)
    t0 = time.perf_counter()
    if args.refine:
        raise DiffwashError("only applies to spectral or mixture tables (a single-pigment RGB table is fitted in "
                            "CIEDE2000 already)", field="--refine")  # fmt: skip
    if args.pair_terms:
        raise DiffwashError("only applies to spectral tables with mixtures", field="--pair-terms")
    if args.loss == "noise":
        raise DiffwashError("a table has no pixels to estimate noise from: choose de2000, cie94, lab or srgb",
                            field="--loss")  # fmt: skip
    base = diffwash.fit.PLAIN if args.plain else diffwash.fit.FitModel()
    model = diffwash.fit.FitModel(
        thickness=args.thickness or base.thickness,
        surface=args.surface or base.surface,
        loss=args.loss or base.loss,
        prior=base.prior,
    )
    table = diffwash.fit.read_table(args.table, linear=args.linear)
    fit = diffwash.fit.fit_table(table, model=model, max_steps=args.max_steps, batch=args.batch or "auto")
    print(f"{len(fit.pigments)} pigments from {len(table)} measurements; model: "
          f"{', '.join(f'{k}={v}' for k, v in model.describe().items())}")  # fmt: skip
    width = max(len("pigment"), *(len(n) for n in fit.names))
    print(f"  {'pigment':<{width}}  {'rows':>4}  {'mean dE':>7}  {'max dE':>6}  {'gamma':>5}  {'steps':>5}  converged")
    for i, p in enumerate(fit.pigments):
        de = fit.delta_e[i]
        print(f"  {p.name:<{width}}  {len(de):4d}  {np.mean(de):7.2f}  {np.max(de):6.2f}  {fit.gamma[i]:5.3f}  "
              f"{int(fit.iterations[i]):5d}  {'yes' if fit.converged[i] else 'NO'}")  # fmt: skip
    allde = np.concatenate(fit.delta_e)
    print(f"  mean CIEDE2000 over all rows: {allde.mean():.2f}")
    bad = [fit.names[i] for i in range(len(fit.pigments)) if not fit.converged[i]]
    _finish(not bad, args.allow_unconverged, f"the fit of {', '.join(bad)}")
    with dio.atomic_paths(out, report) as (out_tmp, report_tmp):  # both files or neither
        fit.save(out_tmp)
        if report is not None:
            diffwash.fit.save_table_report(report_tmp, fit, table)
    _wrote(out, report)
    print(f"  a library of {len(fit.pigments)} pigments (amounts as in the table): diffwash predict {out} --table ...")
    print(f"done in {time.perf_counter() - t0:.2f} s")
    return 0
