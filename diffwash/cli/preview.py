"""Render a scene through the exported real-time shaders and a baked LUT with OpenGL.

Headless (EGL; Mesa's llvmpipe without a GPU) with -o FRAME.png; in a window with
--window (needs a display and the glfw package; with -o too, the last frame shown is
saved when the window closes). Without either, it opens a window when it can and
otherwise writes preview.png.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import diffwash

from .. import SHADING_MODES, DiffwashError
from .. import io as dio
from .bake import parse_lut_size


def add_arguments(p) -> None:
    p.add_argument("scene", metavar="SCENE.json", help="scene file")
    p.add_argument("-o", "--output", metavar="FRAME.png", help="write one frame (8-bit sRGB, .png or .jpg), headless (with --window: the last frame shown)")
    p.add_argument("--shading", choices=SHADING_MODES, help="thickness per pixel or per vertex (default: the scene's)")
    p.add_argument("--size", metavar="WxH", help="image size (default: the scene's)")
    p.add_argument("--lut", metavar="LUT", help="a baked LUT (its sidecar .json or the image beside it); default: bake one")
    p.add_argument("--lut-size", default="256", metavar="N", help="size of the LUT baked when --lut is not given (default: %(default)s)")
    p.add_argument("--rt", action="store_true", help="bake an R/T LUT and use the shaders that composite over the paper")
    p.add_argument("--window", action="store_true", help="show the scene in a window (orbit with the mouse)")
    p.add_argument("--frames", type=int, default=None, help=argparse.SUPPRESS)


def _size(text: str):
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise DiffwashError(f"must be WIDTHxHEIGHT, got {text!r}", field="--size") from None
    return w, h


def _lut_files(path) -> list:
    """The files of a LUT given as its sidecar or its image: the sidecar and the images beside it."""
    if not path:
        return []
    side = Path(path).with_suffix(".json")
    stems = [side.stem, f"{side.stem}_R", f"{side.stem}_T"]
    return [Path(path), side, *(p for s in stems for x in (".png", ".exr", ".npy") if (p := side.with_name(s + x)).exists())]


def run(args) -> int:
    size = _size(args.size) if args.size else None
    window = args.window or (args.output is None and diffwash.preview.can_show())
    if args.window and not diffwash.preview.has_display():
        raise DiffwashError("needs a display (neither DISPLAY nor WAYLAND_DISPLAY is set); use -o FRAME.png to render headless", field="--window")
    out = args.output or (None if window else "preview.png")
    if out is not None:
        dio.image_format_for(out, field="--output")
        dio.refuse_overwriting_inputs({"--output": out}, [args.scene, *diffwash.referenced_files(args.scene), *_lut_files(args.lut)])
    scene = diffwash.load_scene(args.scene, shading=args.shading, size=size)
    if args.lut:
        table = diffwash.lut.load(args.lut)
    else:
        # As `diffwash export` writes it by default: a 16-bit sRGB PNG.
        table = diffwash.lut.load_encoded(diffwash.lut.bake(scene, parse_lut_size(args.lut_size, "--lut-size"), kind="rt" if args.rt else "colour"), "png16")
    if window:
        last = diffwash.preview.show(scene, lut=table, frames=args.frames, keep_last=out is not None)
        if out and last is not None:
            dio.write_image(out, last)
            print(f"wrote {out} (the window's last frame)")
        return 0
    frame = diffwash.preview.render(scene, lut=table)
    dio.write_image(out, frame)
    print(f"wrote {out} ({scene.width}x{scene.height}, {scene.shading}, {table.size[0]}x{table.size[1]} {table.kind} LUT, OpenGL: {diffwash.preview.renderer_name()})")
    return 0
