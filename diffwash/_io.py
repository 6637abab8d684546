"""File input and output: JSON with located errors, images, and atomic writes.

Nothing is ever half-written: every writer here writes to a temporary name in
the destination folder and renames it into place once complete.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import tempfile
import zlib
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from ._errors import DiffwashError

__all__ = ["read_json", "write_json", "atomic_path", "read_image", "write_png", "to_uint"]


def read_json(path: str | os.PathLike) -> Any:
    """Parse a JSON file; a missing file or bad JSON is a one-line `DiffwashError`."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise DiffwashError("no such file", file=path) from None
    except IsADirectoryError:
        raise DiffwashError("is a folder, not a file", file=path) from None
    except (OSError, UnicodeDecodeError) as e:
        raise DiffwashError(f"cannot read: {e}", file=path) from None
    try:
        return json.loads(text)
    except json.JSONDecodeError as e:
        raise DiffwashError(f"malformed JSON at line {e.lineno} column {e.colno}: {e.msg}", file=path) from None


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path beside `path`; on success rename it to `path`.

    On any exception the temporary file is removed and `path` is untouched. A
    missing or unwritable folder is a `DiffwashError`.
    """
    path = Path(path)
    folder = path.parent if str(path.parent) else Path(".")
    if not folder.is_dir():
        raise DiffwashError("output folder does not exist", file=folder)
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".part", dir=folder)
    except OSError as e:
        raise DiffwashError(f"cannot write here: {e.strerror}", file=folder) from None
    os.close(fd)
    tmp = Path(tmp)
    # mkstemp makes the file private (0600); give it the permissions a plain open() would.
    with contextlib.suppress(OSError):
        mask = os.umask(0)
        os.umask(mask)
        os.chmod(tmp, 0o666 & ~mask)
    try:
        yield tmp
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise


def write_text(path: str | os.PathLike, text: str) -> None:
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


def to_uint(img: np.ndarray, bits: int = 8) -> np.ndarray:
    """Float image in [0, 1] (clipped; NaN becomes 0) to unsigned integers of `bits` bits."""
    top = (1 << bits) - 1
    a = np.nan_to_num(np.asarray(img, np.float64), nan=0.0, posinf=1.0, neginf=0.0)
    return np.round(np.clip(a, 0, 1) * top).astype(np.uint16 if bits > 8 else np.uint8)


def write_png(path: str | os.PathLike, img: np.ndarray, bits: int = 8) -> None:
    """Write an (H, W, C) image (C = 1, 3 or 4) as an 8- or 16-bit PNG, atomically.

    Float images are taken as values in [0, 1] (already display-encoded);
    integer images are written as they are.
    """
    import png  # pypng: 16-bit RGB PNGs, which Pillow cannot write

    a = np.asarray(img)
    if a.ndim == 2:
        a = a[..., None]
    if a.ndim != 3 or a.shape[2] not in (1, 2, 3, 4):
        raise ValueError(f"image must be (H, W, C) with C in 1..4, got {a.shape}")
    if a.dtype.kind == "f":
        a = to_uint(a, bits)
    h, w, c = a.shape
    writer = png.Writer(w, h, greyscale=c <= 2, alpha=c in (2, 4), bitdepth=bits)
    with atomic_path(path) as tmp, open(tmp, "wb") as f:
        writer.write(f, a.reshape(h, w * c).astype(np.uint16 if bits > 8 else np.uint8))


def read_image(path: str | os.PathLike) -> tuple[np.ndarray, int]:
    """Read a PNG (8 or 16 bit), JPEG or any image Pillow knows, as displayed.

    EXIF orientation is applied. Alpha is dropped; greyscale becomes RGB.

    **Returns:**

    `(rgb, bits)`: a float64 (H, W, 3) array of display-encoded values in [0, 1]
    and the bit depth per channel of the file (8 or 16).
    """
    from PIL import Image, ImageOps, UnidentifiedImageError

    path = Path(path)
    if not path.is_file():
        raise DiffwashError("no such image file", file=path)
    with open(path, "rb") as f:
        head = f.read(8)
    if head == b"\x89PNG\r\n\x1a\n":
        import png

        try:
            with open(path, "rb") as f:
                w, h, rows, info = png.Reader(file=f).asDirect()
                a = np.vstack([np.asarray(r, np.uint16) for r in rows]).reshape(h, w, info["planes"])
        except (png.Error, zlib.error, ValueError, EOFError) as e:
            raise DiffwashError(f"not a readable PNG: {e}", file=path) from None
        bits = info["bitdepth"]
        a = a.astype(np.float64) / ((1 << bits) - 1)
        bits = 16 if bits > 8 else 8
        # Orientation from a PNG eXIf chunk, rare but honoured through Pillow.
        with Image.open(path) as im:
            orientation = im.getexif().get(0x0112, 1)
        a = _orient(a, orientation)
    else:
        try:
            with Image.open(path) as im:
                im = ImageOps.exif_transpose(im)
                bits = 16 if im.mode in ("I;16", "I;16B", "I") else 8
                a = np.asarray(im.convert("RGBA" if "A" in im.getbands() else "RGB"), np.float64) / 255.0
        except (UnidentifiedImageError, OSError) as e:
            raise DiffwashError(f"not a readable image: {e}", file=path) from None
    if a.shape[2] in (2, 4):
        a = a[..., :-1]
    if a.shape[2] == 1:
        a = np.repeat(a, 3, axis=2)
    return a, bits


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


def finite_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
