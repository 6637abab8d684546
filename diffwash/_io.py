"""File input and output: JSON with located errors, images, atomic writes, and the checks every command shares.

Nothing is ever half-written: every writer here writes to a temporary name in
the destination folder (or a temporary folder beside it) and renames it into
place once complete; a write that fails (a full disk) removes the temporary
and raises a one-line `FailureError` naming the file.

Only regular files are read (`check_input_file`, `open_input`): a folder, a named
pipe (which would block the read forever), a device (`/dev/zero` never ends) or a
socket is refused in one line naming what it is, and so is a file larger than
`max_file_bytes()` (default 256 MiB, `$DIFFWASH_MAX_FILE_BYTES` to change it),
checked from its size before a byte is read.

Images are checked before they are decoded: a header that announces more than
`max_image_pixels()` pixels (default 8192 x 8192, `$DIFFWASH_MAX_IMAGE_PIXELS`
to change it) is refused without allocating them.
"""

from __future__ import annotations

import contextlib
import contextvars
import errno
import json
import math
import os
import shutil
import stat
import struct
import tempfile
import threading
import warnings
import zlib
from collections.abc import Iterable, Iterator, Mapping
from pathlib import Path
from typing import Any

import numpy as np
import png  # pypng: 16-bit RGB PNGs, which Pillow cannot write

from ._errors import DiffwashError, FailureError
from ._lazy import lazy

# Pillow, imported when an image is first read or written through it.
Image = lazy("PIL.Image")
ImageOps = lazy("PIL.ImageOps")

__all__ = [
    "read_json", "write_json", "write_text", "atomic_path", "atomic_paths", "atomic_folder", "read_image",
    "write_png", "write_image", "save_figure", "image_format_for", "to_uint", "finite_number", "check_float32",
    "refuse_overwriting_inputs", "max_image_pixels", "image_pixel_limit", "MAX_IMAGE_PIXELS", "IMAGE_FORMATS",
    "FLOAT32_MAX", "check_input_file", "open_input", "env_limit", "max_file_bytes", "MAX_FILE_BYTES", "FILE_BYTES_ENV",
]  # fmt: skip

#: The largest magnitude float32 holds; diffwash computes in float32, so larger numbers are refused.
FLOAT32_MAX = float(np.finfo(np.float32).max)
#: Default largest image (pixels) read: 8192 x 8192, the largest image diffwash renders (a 48-50 MP photo fits).
MAX_IMAGE_PIXELS = 8192 * 8192
#: The environment variable that changes `MAX_IMAGE_PIXELS`.
PIXELS_ENV = "DIFFWASH_MAX_IMAGE_PIXELS"
#: Default largest input file (bytes) read: 256 MiB, far above any scene, table, library or photo diffwash reads.
MAX_FILE_BYTES = 256 * 1024 * 1024
#: The environment variable that changes `MAX_FILE_BYTES`.
FILE_BYTES_ENV = "DIFFWASH_MAX_FILE_BYTES"
#: Image formats written, by extension.
IMAGE_FORMATS = {".png": "png", ".jpg": "jpeg", ".jpeg": "jpeg"}
#: Image formats read through Pillow (PNG is read with pypng, which keeps 16 bits); no format that runs
#: external programs (EPS) or is rarely a photo.
_PILLOW_FORMATS = ("JPEG", "PNG", "TIFF", "WEBP", "BMP", "MPO")
_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
#: errno values that mean the disk (or a limit) is full: the work failed, the input was fine (exit 1).
_FULL = {errno.ENOSPC, errno.EDQUOT, errno.EFBIG, errno.EIO}


def env_limit(name: str, default: int, unit: str) -> int:
    """A size limit the environment variable `name` may set (a whole number >= 1 of `unit`), else `default`;
    anything else there is a one-line `DiffwashError` naming the variable."""
    env = os.environ.get(name, "").strip()
    if not env:
        return default
    try:
        n = float(env)
    except ValueError:
        n = math.nan
    if not (math.isfinite(n) and n >= 1 and n.is_integer()):
        raise DiffwashError(f"must be a whole number of {unit} >= 1, got {env!r}", field=name)
    return int(n)


def max_file_bytes() -> int:
    """The largest input file read, in bytes: `$DIFFWASH_MAX_FILE_BYTES`, else `MAX_FILE_BYTES`."""
    return env_limit(FILE_BYTES_ENV, MAX_FILE_BYTES, "bytes")


#: What a file that is not a regular file is, by its `stat` mode test.
_KINDS = ((stat.S_ISDIR, "is a folder, not a file"), (stat.S_ISFIFO, "is a named pipe (FIFO), not a regular file"),
          (stat.S_ISCHR, "is a character device, not a regular file"),
          (stat.S_ISBLK, "is a block device, not a regular file"),
          (stat.S_ISSOCK, "is a socket, not a regular file"))  # fmt: skip


def _check_stat(st: os.stat_result, path: Path, file: Any, field: str | None) -> None:
    shown = "" if file is None else f"{os.fspath(path)}: "
    where = path if file is None else file
    for test, what in _KINDS:
        if test(st.st_mode):
            raise DiffwashError(f"{shown}{what}; diffwash reads only regular files", file=where, field=field)
    if not stat.S_ISREG(st.st_mode):
        raise DiffwashError(f"{shown}is not a regular file; diffwash reads only regular files", file=where, field=field)
    limit = max_file_bytes()
    if st.st_size > limit:
        raise DiffwashError(f"{shown}is {st.st_size:,} bytes, over the limit of {limit:,} for an input file; to read it, "
                            f"raise the limit with {FILE_BYTES_ENV}=N", file=where, field=field)  # fmt: skip


def check_input_file(path: str | os.PathLike, *, file: Any = None, field: str | None = None) -> Path:
    """`path` as a `Path` if it is a regular file within `max_file_bytes()`; else a one-line `DiffwashError`.

    Only the file's `stat` is read (a named pipe is never opened, so nothing
    blocks). The error names `path`, or `file` and `field` (a scene naming the
    file) with `path` in the message.
    """
    path = Path(path)
    try:
        st = os.stat(path)
    except FileNotFoundError:
        raise DiffwashError("no such file" if file is None else f"no such file: {os.fspath(path)}", file=path if
                            file is None else file, field=field) from None  # fmt: skip
    except (OSError, ValueError) as e:
        shown = "" if file is None else f"{os.fspath(path)}: "
        raise DiffwashError(f"{shown}cannot read: {getattr(e, 'strerror', None) or e}", file=path if file is None else
                            file, field=field) from None  # fmt: skip
    _check_stat(st, path, file, field)
    return path


@contextlib.contextmanager
def open_input(path: str | os.PathLike, mode: str = "rb", **kwargs: Any) -> Iterator[Any]:
    """Open an input file for reading, refusing anything but a regular file within `max_file_bytes()`.

    The file is opened without blocking (a named pipe swapped in after a check
    cannot hang the read) and checked on the open descriptor. `mode` is `"rb"`
    or `"r"` (with `open`'s keywords: `encoding`, `newline`).
    """
    path = check_input_file(path)
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
    except OSError as e:
        raise DiffwashError(f"cannot read: {e.strerror or e}", file=path) from None
    try:
        _check_stat(os.fstat(fd), path, None, None)
        if hasattr(os, "set_blocking"):
            os.set_blocking(fd, True)
        f = os.fdopen(fd, mode, **kwargs)
    except BaseException:
        os.close(fd)
        raise
    with f:
        yield f


def read_json(path: str | os.PathLike) -> Any:
    """Parse a JSON file (a regular file, `open_input`); a missing file or bad JSON is a one-line `DiffwashError`."""
    path = Path(path)
    try:
        with open_input(path, "r", encoding="utf-8") as f:
            text = f.read()
    except (OSError, UnicodeDecodeError) as e:
        raise DiffwashError(f"cannot read: {e}", file=path) from None
    try:
        return json.loads(text)
    except json.JSONDecodeError as e:
        raise DiffwashError(f"malformed JSON at line {e.lineno} column {e.colno}: {e.msg}", file=path) from None
    except ValueError as e:  # an integer of more than 4300 digits
        raise DiffwashError(f"malformed JSON: {e}".splitlines()[0], file=path) from None
    except RecursionError:
        raise DiffwashError("malformed JSON: nested too deeply", file=path) from None


def finite_number(value: Any) -> bool:
    """Whether `value` is a JSON number (not a bool) that is finite as a float64."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return False
    try:
        return math.isfinite(value)
    except OverflowError:  # an integer too large for a float
        return False


def check_float32(value: Any, *, file: Any = None, field: str | None = None) -> float:
    """`value` (a finite number) as a float; refused, naming `file` and `field`, when float32 cannot hold it.

    JSON numbers such as 1e300 are finite in float64 but overflow to infinity in
    the float32 the renderer, the fits and the baked LUT compute in.
    """
    v = float(value)
    if not abs(v) <= FLOAT32_MAX:
        raise DiffwashError(f"{v:g} is out of float32 range (magnitude at most {FLOAT32_MAX:.4g}), which diffwash "
                            f"computes in", file=file, field=field)  # fmt: skip
    return v


def write_error(e: OSError, path: str | os.PathLike) -> DiffwashError:
    """A one-line error for an `OSError` met while writing `path`: exit 1 for a full disk, 2 otherwise."""
    cls = FailureError if e.errno in _FULL else DiffwashError
    return cls(f"cannot write: {e.strerror or e}; nothing was written", file=path)


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _folder_of(path: Path) -> Path:
    return path.parent if str(path.parent) else Path(".")


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path beside `path`; on success rename it to `path`.

    On any exception the temporary file is removed and `path` is untouched; an
    `OSError` (a full disk) becomes a one-line `FailureError` naming `path`. A
    missing or unwritable folder is a `DiffwashError`.
    """
    path = Path(path)
    folder = _folder_of(path)
    if not folder.is_dir():
        raise DiffwashError("output folder does not exist", file=folder)
    if path.is_dir():
        raise DiffwashError("is a folder, not a file", file=path)
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".part", dir=folder)
    except OSError as e:
        raise DiffwashError(f"cannot write here: {e.strerror}", file=folder) from None
    os.close(fd)
    tmp = Path(tmp)
    # mkstemp makes the file private (0600); give it the permissions a plain open() would.
    with contextlib.suppress(OSError):
        os.chmod(tmp, 0o666 & ~_umask())
    try:
        yield tmp
        os.replace(tmp, path)
    except BaseException as e:
        with contextlib.suppress(OSError):
            tmp.unlink()
        _reraise(e, tmp, path)


@contextlib.contextmanager
def atomic_folder(folder: str | os.PathLike, *, merge: bool = False) -> Iterator[Path]:
    """Yield a new temporary folder beside `folder`; on success it becomes `folder`, whole.

    An existing `folder` is replaced: moved aside, then removed once the new one
    is in place. With `merge` (and into an empty `folder`), the new folder's
    entries are moved into the existing `folder` instead (replacing entries of
    the same names, leaving the others). On any exception the temporary folder is removed and `folder` is
    untouched; an `OSError` (a full disk) becomes a one-line `FailureError`.
    Whether `folder` may be replaced is the caller's decision.
    """
    shown = Path(folder)
    folder = Path(os.path.abspath(folder))  # "." has a name and a parent too
    parent = folder.parent
    if not parent.is_dir():
        raise DiffwashError("output folder's parent does not exist", file=_folder_of(shown))
    if folder.exists() and not folder.is_dir():
        raise DiffwashError("exists and is not a folder", file=shown)
    try:
        tmp = Path(tempfile.mkdtemp(prefix=f".{folder.name}.", suffix=".part", dir=parent))
    except OSError as e:
        raise DiffwashError(f"cannot write here: {e.strerror}", file=parent) from None
    try:
        yield tmp
        os.chmod(tmp, 0o777 & ~_umask())
        if folder.is_dir() and (merge or not any(folder.iterdir())):
            for entry in sorted(tmp.iterdir()):
                _replace(entry, folder / entry.name)
            tmp.rmdir()
        else:
            _replace(tmp, folder)
    except BaseException as e:
        shutil.rmtree(tmp, ignore_errors=True)
        _reraise(e, tmp, shown)


def _reraise(e: BaseException, tmp: Path, final: Path) -> None:
    """Raise `e`, met while writing `final` through the temporary `tmp`, naming `final` rather than `tmp`: an
    `OSError` as a one-line error (`write_error`), a `DiffwashError` about something in `tmp` about `final`."""
    if isinstance(e, OSError):
        if e.filename is None:
            raise write_error(e, final) from None
        if _inside(e.filename, tmp) is not None:
            raise write_error(e, final / _inside(e.filename, tmp)) from None
    if isinstance(e, DiffwashError) and e.file is not None and _inside(e.file, tmp) is not None:
        raise type(e)(e.problem, file=final / _inside(e.file, tmp), field=e.field) from None
    raise e  # about another file: its own writer names it


def _inside(path: Any, tmp: Path) -> Path | None:
    """`path` relative to `tmp` (`.` for `tmp` itself), or None when it lies elsewhere."""
    try:
        return Path(os.path.abspath(os.fsdecode(path))).relative_to(tmp)
    except (ValueError, TypeError):
        return None


@contextlib.contextmanager
def atomic_paths(*paths: str | os.PathLike | None) -> Iterator[list[Path | None]]:
    """`atomic_path` for several files written together: temporary paths (None for None), all renamed into place
    once all are complete, or none on any exception."""
    with contextlib.ExitStack() as stack:
        yield [None if p is None else stack.enter_context(atomic_path(p)) for p in paths]


def _replace(new: Path, old: Path) -> None:
    """Rename `new` to `old`; an existing folder `old` is moved aside first and removed after."""
    if not (old.is_dir() and not old.is_symlink()):
        os.replace(new, old)
        return
    aside = old.with_name(f".{old.name}.old-{os.getpid()}")
    old.rename(aside)
    try:
        os.replace(new, old)
    except OSError:
        with contextlib.suppress(OSError):
            aside.rename(old)
        raise
    shutil.rmtree(aside, ignore_errors=True)


def write_text(path: str | os.PathLike, text: str) -> None:
    """Write `text` as UTF-8, atomically."""
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")


def _json_default(o: Any) -> Any:
    if isinstance(o, np.ndarray) or hasattr(o, "__array__"):
        return np.asarray(o).tolist()
    if isinstance(o, np.generic):
        return o.item()
    raise TypeError(f"cannot write {type(o).__name__} as JSON")


def write_json(path: str | os.PathLike, data: Any) -> None:
    """Write `data` as indented JSON, atomically. Non-finite floats are refused."""
    text = json.dumps(data, indent=2, default=_json_default, allow_nan=False)
    write_text(path, text + "\n")


def same_file(a: str | os.PathLike, b: str | os.PathLike) -> bool:
    """Whether two paths name the same file (after resolving links; either may not exist yet)."""
    try:
        return os.path.samefile(a, b)
    except OSError:
        return os.path.realpath(a) == os.path.realpath(b)


def refuse_overwriting_inputs(
    outputs: Mapping[str, str | os.PathLike | None],
    inputs: Iterable[str | os.PathLike | None],
    *,
    folders: Iterable[str] = (),
) -> None:
    """Refuse, before any work, an output that names an input, or two outputs that name one file.

    **Arguments:**

    - `outputs`: output paths by the option that names them (`{"--output": "out.json"}`); None is skipped.
    - `inputs`: the input files (None is skipped).
    - `folders`: the options in `outputs` that name a folder written whole: an
      input inside it is refused too.

    Raises a `DiffwashError` naming the output, its option and the input.
    """
    outs = [(flag, Path(p)) for flag, p in outputs.items() if p is not None]
    ins = [Path(p) for p in inputs if p is not None]
    folders = set(folders)
    for flag, out in outs:
        root = Path(os.path.realpath(out))
        for inp in ins:
            inside = flag in folders and Path(os.path.realpath(inp)).is_relative_to(root)
            if inside or same_file(out, inp):
                what = "holds the input" if inside and not same_file(out, inp) else "is the input"
                raise DiffwashError(f"{what} {os.fspath(inp)}; refusing to overwrite an input", file=out, field=flag)
    for i, (flag, out) in enumerate(outs):
        for other, path in outs[i + 1 :]:
            if same_file(out, path):
                raise DiffwashError(f"is also the {other} output; each output needs its own file", file=out, field=flag)


def image_format_for(path: str | os.PathLike, *, bits: int = 8, alpha: bool = False, field: str | None = None) -> str:
    """The image format an output's extension names, `"png"` or `"jpeg"`, checked against what it must hold.

    Any other extension is refused, and so is a JPEG asked to hold 16 bits or
    alpha (it has neither): never a file whose bytes are not what its name says.
    """
    suffix = Path(path).suffix.lower()
    if suffix not in IMAGE_FORMATS:
        raise DiffwashError(f"cannot tell the image format from the extension {suffix or '(none)'!r}; "
                            f"use .png, .jpg or .jpeg", file=path, field=field)  # fmt: skip
    fmt = IMAGE_FORMATS[suffix]
    if fmt == "jpeg" and (bits != 8 or alpha):
        what = "16 bits per channel" if bits != 8 else "an alpha channel"
        raise DiffwashError(f"a JPEG cannot hold {what}; write a .png", file=path, field=field)
    return fmt


def to_uint(img: np.ndarray, bits: int = 8) -> np.ndarray:
    """Float image in [0, 1] (clipped; NaN becomes 0) to unsigned integers of `bits` bits."""
    top = (1 << bits) - 1
    a = np.nan_to_num(np.asarray(img, np.float64), nan=0.0, posinf=1.0, neginf=0.0)
    return np.round(np.clip(a, 0, 1) * top).astype(np.uint16 if bits > 8 else np.uint8)


def _channels(img: np.ndarray) -> np.ndarray:
    a = np.asarray(img)
    if a.ndim == 2:
        a = a[..., None]
    if a.ndim != 3 or a.shape[2] not in (1, 2, 3, 4):
        raise ValueError(f"image must be (H, W, C) with C in 1..4, got {a.shape}")
    return a


def write_png(path: str | os.PathLike, img: np.ndarray, bits: int = 8) -> None:
    """Write an (H, W, C) image (C = 1, 3 or 4) as an 8- or 16-bit PNG, atomically.

    Float images are taken as values in [0, 1] (already display-encoded);
    integer images are written as they are.
    """

    a = _channels(img)
    h, w, c = a.shape
    step = max(1, (1 << 18) // max(1, w * c))  # rows quantised at once: a float image is not copied whole
    blocks = (to_uint(a[y : y + step], bits) if a.dtype.kind == "f" else a[y : y + step] for y in range(0, h, step))
    with atomic_path(path) as tmp, open(tmp, "wb") as f:
        write_png_blocks(f, w, h, blocks, bits=bits, greyscale=c <= 2, alpha=c in (2, 4))


def write_png_blocks(f: Any, width: int, height: int, blocks: Any, *, bits: int, greyscale: bool = False,
                     alpha: bool = False) -> None:  # fmt: skip
    """Write a PNG of `width` x `height` pixels to the open file `f` from `blocks` of its rows, top first: integer
    arrays `(rows, width, channels)`, each packed into bytes by NumPy as it comes (pypng packs 16-bit samples one by
    one in Python), so an image made block by block is never held whole."""
    writer = png.Writer(width, height, greyscale=greyscale, alpha=alpha, bitdepth=bits)
    dtype = ">u2" if bits > 8 else "u1"
    rows = (row.tobytes() for b in blocks for row in np.asarray(b).astype(dtype).reshape(len(b), -1))
    written = writer.write_packed(f, rows)
    if written != height:
        raise ValueError(f"a PNG of {height} rows was given {written}")


def write_image(path: str | os.PathLike, img: np.ndarray, bits: int = 8, *, quality: int = 95) -> None:
    """Write an (H, W, C) image in the format its extension names, atomically.

    `.png`: 8 or 16 bits, with alpha if C is 2 or 4 (`write_png`). `.jpg` /
    `.jpeg`: 8-bit JPEG (Pillow) at `quality`; it has no alpha and no 16 bits,
    so those are refused rather than silently dropped. Any other extension is
    refused. Float images are display-encoded values in [0, 1].
    """
    a = _channels(img)
    if image_format_for(path, bits=bits, alpha=a.shape[2] in (2, 4)) == "png":
        write_png(path, a, bits)
        return

    a = to_uint(a, 8) if a.dtype.kind == "f" else a.astype(np.uint8)
    im = Image.fromarray(a[..., 0] if a.shape[2] == 1 else a)
    with atomic_path(path) as tmp:
        im.save(tmp, format="JPEG", quality=quality)


def save_figure(path: str | os.PathLike, fig: Any, **kwargs: Any) -> None:
    """Save a matplotlib figure in the format its extension names (PNG or JPEG), atomically."""
    fmt = image_format_for(path)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format=fmt, **kwargs)


_PIXEL_LIMIT: contextvars.ContextVar[int | None] = contextvars.ContextVar("max_image_pixels", default=None)


def _parse_pixels(value: Any, field: str) -> int:
    try:
        n = float(value)
    except (TypeError, ValueError):
        n = math.nan
    if not (math.isfinite(n) and n >= 1 and n.is_integer()):
        raise DiffwashError(f"must be a whole number of pixels >= 1, got {value!r}", field=field)
    return int(n)


def max_image_pixels() -> int:
    """The most pixels an image read may have: `image_pixel_limit`'s, else `$DIFFWASH_MAX_IMAGE_PIXELS`,
    else `MAX_IMAGE_PIXELS`."""
    limit = _PIXEL_LIMIT.get()
    if limit is not None:
        return limit
    env = os.environ.get(PIXELS_ENV, "").strip()
    return _parse_pixels(env, PIXELS_ENV) if env else MAX_IMAGE_PIXELS


@contextlib.contextmanager
def image_pixel_limit(limit: int | None, field: str = "max_image_pixels") -> Iterator[None]:
    """Within the block, images of up to `limit` pixels are read (None: the default limit)."""
    token = _PIXEL_LIMIT.set(None if limit is None else _parse_pixels(limit, field))
    try:
        yield
    finally:
        _PIXEL_LIMIT.reset(token)


def _check_pixels(width: int, height: int, path: Path, limit: int, advice: str | None = None) -> None:
    if width * height > limit:
        advice = advice or f"to read it, raise the limit with {PIXELS_ENV}=N or --max-image-pixels N"
        raise DiffwashError(
            f"is {width}x{height} = {width * height:,} pixels by its header, over the limit of {limit:,} (refused "
            f"before decoding: a small file can hold a huge image); {advice}", file=path)  # fmt: skip


_PILLOW_LOCK = threading.Lock()


@contextlib.contextmanager
def _pillow_guard() -> Iterator[None]:
    """Pillow with its own decompression-bomb check off (ours, the same check with our limit, runs on the
    header before anything is decoded) and its warnings about odd but readable files silenced."""

    with _PILLOW_LOCK, warnings.catch_warnings():
        warnings.simplefilter("ignore")
        old = Image.MAX_IMAGE_PIXELS
        Image.MAX_IMAGE_PIXELS = None
        try:
            yield
        finally:
            Image.MAX_IMAGE_PIXELS = old


def read_image(
    path: str | os.PathLike, *, max_pixels: int | None = None, colour: bool = True, opaque: bool = True,
    advice: str | None = None,
) -> tuple[np.ndarray, int]:
    """Read a PNG (8 or 16 bit), JPEG, TIFF, WebP or BMP image, as displayed, for fitting.

    The size in the file's header is checked before anything is decoded. EXIF
    orientation is applied.

    **Arguments:**

    - `path`: the image file.
    - `max_pixels`: the most pixels accepted (default `max_image_pixels()`).
    - `advice`: what the refusal of a larger image says to do (default: how to raise the limit).
    - `colour`: refuse a greyscale image (a greyscale file, or R = G = B at every
      pixel): the fits measure colour, and a grey photo would fit a grey
      pigment. False: greyscale becomes RGB.
    - `opaque`: refuse an image with transparent or translucent pixels (alpha
      below full): the colour under them is not what the camera saw. False:
      alpha is dropped.

    **Returns:**

    `(rgb, bits)`: a float64 (H, W, 3) array of display-encoded values in [0, 1]
    and the bit depth per channel of the file (8 or 16). Anything unreadable or
    refused raises a one-line `DiffwashError` naming the file.
    """
    path = Path(path)
    if not os.path.lexists(path):
        raise DiffwashError("no such image file", file=path)
    limit = max_image_pixels() if max_pixels is None else max_pixels
    try:
        with open_input(path, "rb") as f:
            head = f.read(8)
    except OSError as e:
        raise DiffwashError(f"cannot read: {e.strerror or e}", file=path) from None
    a, bits, grey = (_read_png if head == _PNG_SIGNATURE else _read_pillow)(path, limit, advice)
    if a.shape[2] in (2, 4):
        alpha = a[..., -1]
        if opaque and not np.all(alpha >= 1.0):
            share = float(np.mean(alpha < 1.0))
            what = "fully transparent (alpha 0 everywhere)" if not np.any(alpha > 0) else \
                f"transparent or translucent in {share:.1%} of its pixels (alpha below 1)"  # fmt: skip
            raise DiffwashError(f"is {what}: the colour under transparent pixels is not what a camera saw; "
                                "flatten it onto its background first", file=path)  # fmt: skip
        a = a[..., :-1]
    if a.shape[2] == 3 and colour and not grey and a.size and float(np.max(np.ptp(a, axis=2))) <= 0.5 / 255:
        grey = True
    if grey and colour:
        raise DiffwashError("is a greyscale image: the fits measure colour, and a grey photo would fit a grey "
                            "pigment; use the colour original", file=path)  # fmt: skip
    if a.shape[2] == 1:
        a = np.repeat(a, 3, axis=2)
    return a, bits


def _read_png(path: Path, limit: int, advice: str | None = None) -> tuple[np.ndarray, int, bool]:
    """A PNG through pypng (16 bits kept): size checked from the header first."""

    try:
        with open(path, "rb") as f:
            reader = png.Reader(file=f)
            reader.preamble()
            _check_pixels(reader.width, reader.height, path, limit, advice)
            w, h, rows, info = reader.asDirect()
            a = np.empty((h, w * info["planes"]), np.uint16)
            n = 0
            for n, row in enumerate(rows, start=1):
                if n > h:
                    break
                a[n - 1] = row
            if n != h:
                raise png.FormatError(f"image data ends after {n} of {h} rows")
            a = a.reshape(h, w, info["planes"])
        orientation = _png_orientation(path)
    except (png.Error, zlib.error, ValueError, EOFError, OverflowError, struct.error, IndexError) as e:
        raise DiffwashError(f"not a readable PNG: {e}".splitlines()[0], file=path) from None
    except OSError as e:
        raise DiffwashError(f"cannot read: {e.strerror or e}", file=path) from None
    bits = info["bitdepth"]
    a = a.astype(np.float64) / ((1 << bits) - 1)
    return _orient(a, orientation), 16 if bits > 8 else 8, bool(info["greyscale"])


def _png_orientation(path: Path) -> int:
    """The EXIF orientation tag of a PNG's eXIf chunk (rare; 1 when there is none)."""

    with open(path, "rb") as f:
        f.seek(8)
        while True:
            head = f.read(8)
            if len(head) < 8:
                return 1
            length, kind = struct.unpack(">I4s", head)
            if kind == b"eXIf":
                exif = Image.Exif()
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    try:
                        exif.load(f.read(length))
                        value = exif.get(0x0112, 1)
                    except Exception:  # a malformed EXIF block: no orientation (as Pillow reads it)
                        return 1
                return value if isinstance(value, int) else 1
            if kind == b"IEND":
                return 1
            f.seek(length + 4, os.SEEK_CUR)


def _read_pillow(path: Path, limit: int, advice: str | None = None) -> tuple[np.ndarray, int, bool]:
    """A JPEG (or TIFF, WebP, BMP) through Pillow: size checked from the header first."""

    try:
        with _pillow_guard(), Image.open(path, formats=_PILLOW_FORMATS) as im:
            _check_pixels(im.width, im.height, path, limit, advice)
            im = ImageOps.exif_transpose(im)
            bands = im.getbands()
            grey = "R" not in bands and im.mode != "P"
            bits = 16 if im.mode.startswith("I;16") else 8
            if bits == 16:
                a = np.asarray(im, np.float64)[..., None] / 65535.0
            else:
                alpha = "A" in bands or "transparency" in im.info
                target = ("LA" if alpha else "L") if grey else ("RGBA" if alpha else "RGB")
                a = np.asarray(im.convert(target), np.float64) / 255.0
    except (Image.UnidentifiedImageError, KeyError) as e:  # KeyError: a format Pillow identifies but is not allowed
        if not isinstance(e, KeyError) or not _known_image(path):
            raise DiffwashError("is not an image diffwash reads (PNG, JPEG, TIFF, WebP or BMP)", file=path) from None
        raise DiffwashError(f"not a readable image: {e}".splitlines()[0], file=path) from None
    except (OSError, ValueError, SyntaxError, EOFError, struct.error, IndexError,
            TypeError, ZeroDivisionError, MemoryError) as e:  # fmt: skip
        raise DiffwashError(f"not a readable image: {e}".splitlines()[0], file=path) from None
    if a.ndim == 2:
        a = a[..., None]
    return a, bits, grey


#: The first bytes of the image formats read: a file starting otherwise is not one of them.
_MAGIC = (b"\xff\xd8\xff", b"II*\x00", b"MM\x00*", b"BM", b"RIFF", _PNG_SIGNATURE)


def _known_image(path: Path) -> bool:
    """Whether the file starts like a JPEG, TIFF, BMP, WebP (RIFF) or PNG."""
    with contextlib.suppress(OSError), open(path, "rb") as f:
        return f.read(8).startswith(_MAGIC)
    return False


def _orient(a: np.ndarray, orientation: int) -> np.ndarray:
    """Apply an EXIF orientation tag (1..8) to an (H, W, C) array."""
    ops = {
        2: lambda x: x[:, ::-1],
        3: lambda x: x[::-1, ::-1],
        4: lambda x: x[::-1],
        5: lambda x: np.swapaxes(x, 0, 1),
        6: lambda x: np.swapaxes(x, 0, 1)[:, ::-1],
        7: lambda x: np.swapaxes(x, 0, 1)[::-1, ::-1],
        8: lambda x: np.swapaxes(x, 0, 1)[::-1],
    }
    return np.ascontiguousarray(ops.get(orientation, lambda x: x)(a))
