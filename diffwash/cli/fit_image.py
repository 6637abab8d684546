"""Fit named scene parameters (pigment K and S, gain, bias, thickness constants, shininess, light, paper, a library
mixture's proportions and amount (wash.mix, wash.amount, unlit.mix, unlit.amount), and the watercolour look's
strengths, widths and amplitudes by their scene keys, e.g. watercolour.edges.darkening) to one or
more target images with an optimistix solver, and write the fitted scene file, which diffwash render, bake and
export read. Several views: one --scene per target, or one scene and --cameras CAMERAS.json (a list of camera
objects, one per target). Parameters, gauges and losses are described in docs/fitting.md; the Python equivalent
is diffwash.fit.fit_image(TARGETS, SCENES, FIT). A fit that does not converge writes nothing and exits with
status 1, unless --allow-unconverged.
"""

from __future__ import annotations

import time

import numpy as np

import diffwash

from .. import DiffwashError, FailureError
from .. import io as dio
from . import add_image_limit, check_output

USES_JAX = True


def add_arguments(p) -> None:
    p.add_argument("targets", nargs="+", metavar="TARGET", help="target image(s), sRGB PNG (8/16 bit) or JPEG")
    p.add_argument("--scene", action="append", required=True, metavar="SCENE.json",
                   help="the scene (one for all targets, or one per target)")  # fmt: skip
    p.add_argument("--cameras", metavar="JSON", help="a list of cameras, one per target, for a single --scene")
    p.add_argument("--fit", required=True, metavar="LIST",
                   help=f"comma-separated parameters to fit: {', '.join(diffwash.fit.FITTABLE)}")  # fmt: skip
    p.add_argument("-o", "--output", required=True, metavar="JSON", help="the fitted scene file to write")
    p.add_argument("--loss", choices=diffwash.fit.IMAGE_LOSSES, default="linear",
                   help="compare in linear RGB or CIELAB (default: %(default)s)")
    p.add_argument("--solver", choices=diffwash.fit.SOLVERS, default="lm",
                   help="optimistix solver (default: %(default)s, Levenberg-Marquardt)")
    p.add_argument("--max-steps", type=int, default=100, metavar="N",
                   help="solver steps at most (default: %(default)s)")
    p.add_argument("--report", metavar="PNG",
                   help="also write a picture: target, start, fitted, difference, loss curve")  # fmt: skip
    p.add_argument("--quiet", action="store_true", help="do not print the loss at each step")
    p.add_argument("--allow-unconverged", action="store_true", help="write the result even if the fit did not converge")
    add_image_limit(p)


def run(args) -> int:
    t0 = time.perf_counter()
    out = check_output(args.output, ".json", "--output")
    report = check_output(args.report, ".png", "--report") if args.report else None
    if args.max_steps < 1:
        raise DiffwashError(f"must be at least 1, got {args.max_steps}", field="--max-steps")
    scene_files = [f for s in args.scene for f in (s, *diffwash.referenced_files(s))]
    dio.refuse_overwriting_inputs({"--output": out, "--report": report}, [*args.targets, *scene_files, args.cameras])
    names = diffwash.fit.parse_fit_list(args.fit)
    scenes = [diffwash.load_scene(s) for s in args.scene]
    if args.cameras:
        if len(scenes) != 1:
            raise DiffwashError("--cameras goes with a single --scene", field="--cameras")
        scenes = diffwash.fit.load_cameras(args.cameras, scenes[0])
    if len(scenes) not in (1, len(args.targets)):
        raise DiffwashError(f"got {len(args.targets)} targets but {len(scenes)} scenes (one per target, or one)",
                            field="--scene")  # fmt: skip
    n_views = len(args.targets)
    print(f"fitting {', '.join(names)} to {n_views} view{'s' if n_views > 1 else ''} "
          f"({scenes[0].width}x{scenes[0].height}), loss {args.loss}, solver {args.solver}", flush=True)  # fmt: skip
    fit = diffwash.fit.fit_image(args.targets, scenes, names, loss=args.loss, solver=args.solver, max_steps=args.max_steps,
                    progress=not args.quiet)  # fmt: skip
    for note in fit.notes:
        print(f"  {note}")
    print(f"  {'parameter':<15} {'start':>28} {'fitted':>28}")
    for n in names:
        fmt = lambda v: np.array2string(np.asarray(v), precision=5, separator=", ")  # noqa: E731
        held = "  (held: gauge)" if n in fit.held else ""
        print(f"  {n:<15} {fmt(fit.start[n]):>28} {fmt(fit.fitted[n]):>28}{held}")
    rms = ", ".join(f"{r:.3g}" for r in fit.rms)
    unit = "linear reflectance" if args.loss == "linear" else "CIELAB units"
    status = "converged" if fit.converged else f"NOT converged ({fit.message})"
    print(f"  {status} after {fit.iterations} steps; rms residual per view: {rms} ({unit})")
    if not fit.converged and not args.allow_unconverged:
        raise FailureError(f"the fit did not converge ({fit.message}); nothing was written (use --allow-unconverged "
                           f"to write it anyway, or raise --max-steps)")  # fmt: skip
    with dio.atomic_paths(out, report) as (out_tmp, report_tmp):  # both files or neither
        fit.save(out_tmp)
        if report is not None:
            diffwash.fit.save_image_report(report_tmp, fit, args.targets, scenes)
    print(f"wrote {out}")
    if report is not None:
        print(f"wrote {report}")
    print(f"done in {time.perf_counter() - t0:.2f} s")
    return 0
