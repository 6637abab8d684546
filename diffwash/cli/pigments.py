"""Print a pigment library as a table (default: the seed's 12 pigments)."""

from __future__ import annotations

import json
import sys

import diffwash

from .. import io as dio

USES_JAX = False


def add_arguments(p) -> None:
    p.add_argument("--library", metavar="FILE", help="a pigment file to list instead of the built-in library")
    p.add_argument("--json", action="store_true", help="print JSON in the library schema instead of a table")


def _swatch(rgb) -> str:
    r, g, b = (int(round(255 * v)) for v in rgb)
    return f"\x1b[48;2;{r};{g};{b}m    \x1b[0m"


def run(args) -> int:
    lib = dio.read_pigments(args.library)  # checked as `pigments.library` checks them, without JAX
    if args.json:
        print(json.dumps({"pigments": lib}, indent=2))
        return 0
    colour = sys.stdout.isatty()  # a terminal also gets each pigment's colour, from the model (JAX)

    width = max(len("pigment"), *(len(p["name"]) for p in lib))
    head = f"{'pigment':<{width}}  {'K (r g b)':<20}  {'S (r g b)':<22}  {'density':>7}  {'staining':>8}  {'granularity':>11}"
    print(head)
    print("-" * len(head))
    for p in lib:
        K = " ".join(f"{v:<6g}" for v in p["K"])
        S = " ".join(f"{v:<6g}" for v in p["S"])
        line = f"{p['name']:<{width}}  {K:<20}  {S:<22}  {p['density']:>7g}  {p['staining']:>8g}  {p['granularity']:>11g}"
        if colour:
            line += "  " + _swatch(diffwash.swatches.swatch_colours(diffwash.pigments.parse(p), coats=(1.0,))[0][0])
        print(line)
    return 0
