"""The `diffwash` command: a thin layer over the Python API.

Each subcommand lives in its own module here with `add_arguments(parser)` and
`run(args) -> int` (`COMMANDS` names it, with its one-line help); every one
calls a public function of the library. Errors caused by the user's input print
one line (`diffwash: error: FILE: FIELD: problem`) and exit with status 2; work
that fails (a fit that does not converge, a full disk) exits with 1, also with
one line and no traceback. Outputs are written to a temporary name and renamed,
so a failure leaves nothing half-written.

The command line starts at once: `diffwash --version` and `--help` import no subcommand, and a
subcommand's module is imported, and its arguments added, only when it is chosen. Those modules import
only what their parsers need (light: no JAX); the library's functions are reached as `diffwash.NAME`
when the command runs, and `diffwash` loads each on first use. JAX is imported, and its compilation
cache set up (`diffwash.enable_compilation_cache`), only when a command that uses it runs.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys
from collections.abc import Callable, Sequence
from pathlib import Path

import diffwash

from .. import DiffwashError, __version__

__all__ = ["main", "COMMANDS", "add_image_limit", "check_output"]

#: The subcommands, in the order `diffwash --help` lists them, with their one-line help. The module of
#: `fit-swatch` is `diffwash.cli.fit_swatch`; it is imported only when its command is chosen.
COMMANDS = {
    "pigments": "list the pigment library",
    "swatches": "draw a swatch chart of pigments over paper and over black",
    "render": "render a scene file as a watercolour PNG",
    "bake": "bake the glaze colour over (wash, unlit) thickness into a LUT texture",
    "export": "export the LUT, GLSL/WebGL2 shaders, the mesh (GLB) and a WebGL2 viewer",
    "preview": "render through the exported shaders and LUT with OpenGL (headless or in a window)",
    "swatch-card": "make a synthetic swatch-card photo and its layout (for fit-swatch)",
    "fit-swatch": "fit pigment K and S to a swatch-card photo or a table of measured colours",
    "fit-image": "fit scene parameters to target images",
    "predict": "predict the colour of single paints, mixtures and glaze stacks from a pigment library",
    "suggest": "rank candidate swatches by how much measuring them would shrink the 90%% regions of predictions",
    "demo": "run the whole product on bundled data",
}


class _Parser(argparse.ArgumentParser):
    """An argument parser whose usage errors are one line (exit status 2).

    `add_arguments(parser)`, if given, adds its arguments when it first parses: a subcommand's parser is
    filled in only when that subcommand is chosen.
    """

    def __init__(self, *args, add_arguments: Callable[[argparse.ArgumentParser], None] | None = None, **kwargs):
        super().__init__(*args, **kwargs)
        self._add_arguments = add_arguments

    def parse_known_args(self, args=None, namespace=None):  # type: ignore[override]
        if self._add_arguments is not None:
            add, self._add_arguments = self._add_arguments, None
            add(self)
        return super().parse_known_args(args, namespace)

    def error(self, message: str):  # type: ignore[override]
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def check_output(path: str, suffix: str, flag: str) -> Path:
    """An output path with the `suffix` its command writes, in a folder that exists; a one-line error otherwise."""
    out = Path(path)
    if out.suffix.lower() != suffix:
        raise DiffwashError(f"must be a {suffix} file, got {out.name!r}", field=flag)
    if not (out.parent if str(out.parent) else Path(".")).is_dir():
        raise DiffwashError("output folder does not exist", file=out.parent)
    return out


def add_image_limit(p: argparse.ArgumentParser) -> None:
    """The `--max-image-pixels` option of the commands that read photos or target images."""
    dio = diffwash.io
    p.add_argument("--max-image-pixels", metavar="N", default=None,
                   help=f"read images of up to N pixels (default: ${dio.PIXELS_ENV}, else {dio.MAX_IMAGE_PIXELS:,}); larger "
                        f"ones are refused from their header, before decoding")  # fmt: skip


def _parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="diffwash",
        description="A differentiable watercolour renderer: Kubelka-Munk pigment glazes over paper, "
        "fitted to photos and images, baked into a real-time lookup texture.",
    )
    parser.add_argument("--version", action="version", version=f"diffwash {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name, summary in COMMANDS.items():
        sub.add_parser(name, help=summary, add_arguments=_command_arguments(name))
    return parser


def _command_arguments(name: str) -> Callable[[argparse.ArgumentParser], None]:
    """What fills in the parser of command `name` once it is chosen: its module's description and arguments."""

    def add(p: argparse.ArgumentParser) -> None:
        module = importlib.import_module(f".{name.replace('-', '_')}", __name__)
        p.description = module.__doc__
        module.add_arguments(p)
        p.set_defaults(_run=module.run, _uses_jax=getattr(module, "USES_JAX", True))

    return add


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the exit status."""
    # Set for this call only (a caller's later subprocesses, a notebook kernel say, must not inherit them), where
    # the caller has not; each is read when its library is first imported:
    # - the commands draw figures into files only: no GUI backend for matplotlib;
    # - jaxlib 0.9 logs two lines to standard error for each program it loads from the compilation cache (a
    #   version it cannot check; "target machine feature +prefer-no-gather is not supported", a tuning attribute
    #   of this same machine, not an instruction set): they would bury a command's own one-line messages. "1" is
    #   what `import jax` sets in any process that imports it, and so what a command run from one inherits.
    before = {k: os.environ.get(k) for k in ("MPLBACKEND", "TF_CPP_MIN_LOG_LEVEL")}
    os.environ.setdefault("MPLBACKEND", "Agg")
    if before["TF_CPP_MIN_LOG_LEVEL"] in (None, "1"):
        os.environ["TF_CPP_MIN_LOG_LEVEL"] = "3"
    try:
        return _main(argv)
    finally:
        for k, v in before.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def _main(argv: Sequence[str] | None) -> int:
    parser = _parser()
    args = parser.parse_args(argv)
    try:
        if args._uses_jax:
            diffwash.enable_compilation_cache()
        with diffwash.io.image_pixel_limit(getattr(args, "max_image_pixels", None), "--max-image-pixels"):
            return int(args._run(args) or 0)
    except DiffwashError as e:
        print(f"diffwash: error: {e}", file=sys.stderr)
        return e.exit_code
    except BrokenPipeError:
        return 0
    except MemoryError:
        print("diffwash: error: out of memory", file=sys.stderr)
        return 1
    except OSError as e:  # not met in a writer (those say which file): the file system failed under us
        where = f"{e.filename}: " if e.filename else ""
        print(f"diffwash: error: {where}{e.strerror or e}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("diffwash: interrupted", file=sys.stderr)
        return 130
