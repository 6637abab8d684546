"""Bake a scene's glaze colours into a 2D lookup texture (LUT) over (wash, unlit) thickness.

Column i of N holds wash thickness i/(N-1) * wash_max, row j (from the top) of M
holds unlit thickness j/(M-1) * unlit_max, with wash_max = k_specular * k_wash
and unlit_max = k_unlit. A sidecar JSON beside the LUT (lut.png -> lut.json)
records the size, ranges, encoding, pigments, paper and constants.
"""

from __future__ import annotations

import sys

import diffwash

from .. import DiffwashError
from .. import io as dio


def parse_lut_size(text: str, field: str = "--size"):
    """`"256"` -> 256, `"256x128"` -> (256, 128) (columns x rows); range checked by the library."""
    parts = text.lower().split("x")
    try:
        values = [int(p) for p in parts]
    except ValueError:
        raise DiffwashError(f"must be N or NxM (whole numbers), got {text!r}", field=field) from None
    if len(values) not in (1, 2):
        raise DiffwashError(f"must be N or NxM, got {text!r}", field=field)
    try:
        return diffwash.lut.check_size(values[0] if len(values) == 1 else tuple(values), field=field)
    except DiffwashError as e:
        raise DiffwashError(e.problem, field=field) from None


def lut_outputs(path, fmt: str, kind: str) -> dict:
    """The files a LUT written to `path` occupies besides `path` itself (its sidecar, its R and T images),
    by what they are, for `refuse_overwriting_inputs`."""
    return {f"--output ({k}{'' if k == 'sidecar' else ' image'})": p
            for k, p in diffwash.lut.files(path, fmt, kind).items() if k not in ("colour", kind)}  # fmt: skip


def add_arguments(p) -> None:
    p.add_argument("scene", metavar="SCENE.json", help="scene file (a fitted scene file works as it is)")
    p.add_argument("-o", "--output", required=True, metavar="LUT", help="LUT file: .png, .exr or .npy (the sidecar goes beside it)")
    p.add_argument("--size", default="256", metavar="N", help="samples per axis, 2..4096, or NxM (wash x unlit) (default: %(default)s)")
    p.add_argument(
        "--format",
        choices=list(diffwash.LUT_FORMATS),
        default=None,
        help="png16 (16-bit sRGB, the default for .png), png8 (8-bit sRGB), exr (linear float), npy (linear float)",
    )
    p.add_argument("--rt", action="store_true", help="bake reflectance R and transmittance T of the glazes (no paper) instead of the colour")


def run(args) -> int:
    size = parse_lut_size(args.size)
    fmt = diffwash.lut.format_for(args.output, args.format)
    kind = "rt" if args.rt else "colour"
    dio.refuse_overwriting_inputs({"--output": args.output, **lut_outputs(args.output, fmt, kind)},
                              [args.scene, *diffwash.referenced_files(args.scene)])  # fmt: skip
    scene = diffwash.load_scene(args.scene)
    large = size[0] * size[1] >= 2048 * 2048 and sys.stderr.isatty()
    table = diffwash.lut.bake(scene, size, kind=kind, progress=diffwash.lut.print_progress if large else None)
    written = diffwash.lut.save(args.output, table, fmt)
    n, m = table.size
    print(f"wrote {', '.join(str(w) for w in written)} ({n}x{m} {table.kind} LUT, {fmt}; wash_max {table.wash_max:g}, unlit_max {table.unlit_max:g})")
    return 0
