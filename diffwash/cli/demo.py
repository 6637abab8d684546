"""Run diffwash end to end on bundled data and write the results to a folder."""

from __future__ import annotations

from pathlib import Path

NAME = "demo"
HELP = "run the whole product on bundled data"


def add_arguments(p) -> None:
    p.add_argument("-o", "--output", default="diffwash-demo", metavar="DIR", help="output folder (default: %(default)s)")


def run(args) -> int:
    from .. import pigments
    from .._errors import DiffwashError
    from ..swatches import save_chart

    out = Path(args.output)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise DiffwashError(f"cannot create the output folder: {e.strerror}", file=out) from None
    chart = out / "swatches.png"
    save_chart(chart, list(pigments.library().values()))
    print(f"wrote {chart}: the 12 seed pigments at 0.25-4 coats over paper and over black")
    return 0
