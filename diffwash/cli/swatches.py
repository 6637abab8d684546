"""Draw pigments at 0.25, 0.5, 1, 2 and 4 coats over white paper and over black, as a PNG (or JPEG) chart."""

from __future__ import annotations

from pathlib import Path

import diffwash

from .. import DiffwashError
from .. import io as dio


def add_arguments(p) -> None:
    p.add_argument("names", nargs="+", metavar="NAME", help="pigment names (or pigment files); 'all' for the whole library")
    p.add_argument("-o", "--output", required=True, metavar="IMAGE", help="where to write the chart: .png, or .jpg/.jpeg")
    p.add_argument("--coats", metavar="LIST", default="0.25,0.5,1,2,4", help="comma-separated coats (default: %(default)s)")
    p.add_argument("--paper", nargs=3, type=float, metavar=("R", "G", "B"), help="linear reflectance of the paper")


def run(args) -> int:
    dio.image_format_for(args.output, field="--output")
    dio.refuse_overwriting_inputs({"--output": args.output}, [n for n in args.names if Path(n).is_file()])
    try:
        coats = [float(c) for c in args.coats.split(",")]
    except ValueError:
        raise DiffwashError(f"must be comma-separated numbers, got {args.coats!r}", field="--coats") from None
    if not coats or any(not (c >= 0 and c < 1e6) for c in coats):
        raise DiffwashError(f"must be finite numbers >= 0, got {args.coats!r}", field="--coats")
    paper = args.paper if args.paper is not None else diffwash.shading.DEFAULT_PAPER
    if any(not (0 <= v <= 1) for v in paper):
        raise DiffwashError(f"must be reflectances in [0, 1], got {paper}", field="--paper")
    names = list(diffwash.pigments.library()) if [n.lower() for n in args.names] == ["all"] else args.names
    chosen = [diffwash.pigments.load(n) for n in names]
    diffwash.swatches.save_chart(args.output, chosen, coats, paper)
    print(f"wrote {args.output} ({len(chosen)} pigments x {len(coats)} coats)")
    return 0
