"""Render a scene file as a watercolour image (8-bit sRGB PNG, or 16-bit with --bits 16; JPEG for a .jpg name).

The Python equivalent is `diffwash.render(diffwash.load_scene(SCENE))`.
"""

from __future__ import annotations

import re
import time
from pathlib import Path

import numpy as np

import diffwash

from .. import SHADING_MODES, DiffwashError, FailureError
from .. import io as dio

USES_JAX = True


def add_arguments(p) -> None:
    p.add_argument("scene", metavar="SCENE.json", help="the scene file (format: docs/scene-format.md)")
    p.add_argument("-o", "--output", required=True, metavar="IMAGE", help="where to write the image: .png, or .jpg/.jpeg")
    p.add_argument(
        "--shading", choices=SHADING_MODES, help="shading mode (default: the scene's, else per-pixel)"
    )
    p.add_argument("--size", metavar="WxH", help="image size in pixels, e.g. 1024x768 (default: the scene's)")
    p.add_argument("--antialias", action="store_true", help="antialias silhouette edges")
    p.add_argument("--alpha", action="store_true", help="write an RGBA PNG whose alpha is the coverage")
    p.add_argument("--bits", type=int, choices=(8, 16), default=8, help="bits per channel (default: %(default)s)")


def parse_size(text: str) -> tuple[int, int]:
    """`"WxH"` to `(width, height)`; a one-line `DiffwashError` naming --size otherwise."""
    m = re.fullmatch(r"\s*(\d+)\s*[xX]\s*(\d+)\s*", text)
    if not m:
        raise DiffwashError(f"must be WIDTHxHEIGHT in pixels, e.g. 512x512, got {text!r}", field="--size")
    return int(m.group(1)), int(m.group(2))


def _encode(strip, alpha: bool, bits: int, scene_file: str) -> np.ndarray:
    """A strip of linear RGBA as the file stores it: display sRGB colour, linear alpha, unsigned integers."""
    rgba = np.asarray(strip, np.float64)
    if not np.all(np.isfinite(rgba)):  # never expected; never written
        raise FailureError("the rendering has non-finite pixels; nothing was written", file=scene_file)
    values = diffwash.colorimetry.to_display(rgba[..., :3])
    if alpha:
        values = np.concatenate([values, np.clip(rgba[..., 3:], 0, 1)], axis=-1)
    return dio.to_uint(values, bits)


def run(args) -> int:
    out = Path(args.output)
    dio.refuse_overwriting_inputs({"--output": out}, [args.scene, *diffwash.referenced_files(args.scene)])
    dio.image_format_for(out, bits=args.bits, alpha=args.alpha, field="--output")
    size = parse_size(args.size) if args.size is not None else None
    start = time.perf_counter()
    scene = diffwash.load_scene(args.scene, shading=args.shading, size=size)
    # Strip by strip (bounded memory at any size), encoded as they come.
    image = np.empty((scene.height, scene.width, 4 if args.alpha else 3), np.uint16 if args.bits > 8 else np.uint8)
    for row, strip in diffwash.render_strips(scene, antialias=args.antialias, alpha=True):
        image[row : row + strip.shape[0]] = _encode(strip, args.alpha, args.bits, args.scene)
    dio.write_image(out, image, bits=args.bits)
    elapsed = time.perf_counter() - start
    n_tri = len(scene.mesh.faces)
    print(
        f"wrote {out} ({scene.width}x{scene.height}, {scene.shading}, {n_tri} triangles"
        f"{', antialiased' if args.antialias else ''}{', with alpha' if args.alpha else ''}) in {elapsed:.2f} s"
    )
    return 0
