"""Run diffwash end to end on bundled data: fit a pigment to a swatch-card photo, fit the shading
constants to a target image, bake the LUT, export the shaders and the WebGL2 viewer, draw an OpenGL
frame, and write a one-page report."""

from __future__ import annotations

import diffwash


def add_arguments(p) -> None:
    p.add_argument("-o", "--output", default="diffwash-demo", metavar="DIR",
                   help="output folder: new, empty, or a previous demo's, which is replaced (default: %(default)s)")
    p.add_argument("--force", action="store_true",
                   help="write into a folder that holds other files (those of the demo's names are replaced)")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress lines")


def run(args) -> int:
    res = diffwash.demo.run(args.output, progress=not args.quiet, force=args.force)
    diffwash.demo.main_summary(res)
    return 0
