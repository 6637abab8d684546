"""The `diffwash` command: a thin layer over the Python API.

Each subcommand lives in its own module here with `NAME`, `HELP`,
`add_arguments(parser)` and `run(args) -> int`; every one calls a public
function of the library. Errors caused by the user's input print one line
(`diffwash: error: FILE: FIELD: problem`) and exit with status 2; work that
fails (a fit that does not converge, a full disk) exits with 1, also with one
line and no traceback. Outputs are written to a temporary name and renamed,
so a failure leaves nothing half-written.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys
from collections.abc import Sequence
from pathlib import Path

import jax

from .. import DiffwashError, __version__
from .. import io as dio

__all__ = ["main", "COMMANDS", "add_image_limit", "check_output"]

#: Subcommand modules, in the order `diffwash --help` lists them.
COMMANDS = (
    "pigments", "swatches", "render", "bake", "export", "preview", "swatch_card", "fit_swatch", "fit_image", "predict", "demo",
)  # fmt: skip


def enable_compilation_cache() -> None:
    """Keep JAX's compiled programs on disk so that later runs start fast.

    The folder is `$DIFFWASH_CACHE_DIR` or `~/.cache/diffwash/jax`;
    `DIFFWASH_CACHE_DIR=off` turns the cache off.
    """
    folder = os.environ.get("DIFFWASH_CACHE_DIR", os.path.join(os.path.expanduser("~"), ".cache", "diffwash", "jax"))
    if folder.lower() in ("", "off", "0", "none"):
        return
    try:
        os.makedirs(folder, exist_ok=True)
    except OSError:
        return
    jax.config.update("jax_compilation_cache_dir", folder)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.2)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)


class _Parser(argparse.ArgumentParser):
    """An argument parser whose usage errors are one line (exit status 2)."""

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
    for name in COMMANDS:
        module = importlib.import_module(f".{name}", __name__)
        p = sub.add_parser(module.NAME, help=module.HELP, description=module.__doc__)
        module.add_arguments(p)
        p.set_defaults(_run=module.run, _uses_jax=getattr(module, "USES_JAX", True))
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the exit status."""
    # The commands draw figures into files only: no GUI backend (matplotlib reads this when first imported).
    # Set for this call only: a caller's later subprocesses (a notebook kernel, say) must not inherit it.
    backend_before = os.environ.get("MPLBACKEND")
    os.environ.setdefault("MPLBACKEND", "Agg")
    try:
        return _main(argv)
    finally:
        if backend_before is None:
            os.environ.pop("MPLBACKEND", None)


def _main(argv: Sequence[str] | None) -> int:
    parser = _parser()
    args = parser.parse_args(argv)
    try:
        if args._uses_jax:
            enable_compilation_cache()
        with dio.image_pixel_limit(getattr(args, "max_image_pixels", None), "--max-image-pixels"):
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
