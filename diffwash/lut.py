r"""The real-time path: the glaze colour baked into a 2D lookup table (LUT).

Smedresman's hardware implementation does no Kubelka-Munk arithmetic in the
shader: "a 2-dimensional function of the thicknesses of both these pigments is
pre-calculated and encoded into a texture", which the shader indexes with the
wash and unlit thicknesses it computes per vertex or per pixel. `bake` evaluates
`diffwash.shading.glaze` (the one source of truth) on that grid.

**Convention** (stated again in every sidecar). A LUT of `N` columns and `M`
rows, as an image with row 0 at the top:

- column `i` holds wash thickness `i / (N - 1) * wash_max`, left to right;
- row `j` holds unlit thickness `j / (M - 1) * unlit_max`, top to bottom;
- `wash_max = k_specular * k_wash` and `unlit_max = k_unlit`, the largest
  thicknesses the model produces, so the grid covers every shaded point.

A shader samples texel centres with `uv = (t * (N - 1) + 0.5) / N` per axis,
`t = thickness / max` in [0, 1] (docs/realtime.md). The table depends on the
pigments and the paper only; the constants only set its range, so they can be
tuned live in a shader without re-baking as long as the thicknesses stay within
the range.

Two kinds of table:

- `"colour"`: the linear RGB reflectance of the glazes over the paper, the
  seed's texture that "yields a final pixel color";
- `"rt"`: the reflectance `R` and transmittance `T` of the two glazes without
  the paper (`shading.glaze_layers`), the seed's suggested variant, so that a
  shader can composite over any paper: `R + T^2 P / (1 - R P)`. Three-channel
  pigments only (spectral glazes composite per band, not per sRGB channel).

Files (`save` / `load`): 16-bit sRGB PNG (`png16`, the default), 8-bit sRGB PNG
(`png8`), linear float32 OpenEXR (`exr`) or linear float32 NumPy (`npy`), each
with a JSON sidecar beside it (`lut.png` -> `lut.json`) holding the size, the
ranges, the encoding, the pigments, the paper, the model constants and the
diffwash version. An R/T table in PNG is two images, `<stem>_R.png` and
`<stem>_T.png`; in EXR one file with channels `R, G, B` (reflectance) and
`T.R, T.G, T.B` (transmittance); in NumPy one `(M, N, 6)` array.

**References:**

- G. Smedresman, "Hardware Accelerated Pigment-Based Rendering System",
  section "Hardware Implementation".
- IEC 61966-2-1:1999, the sRGB transfer function used by the PNG encodings.
"""

from __future__ import annotations

import contextlib
import json
import os
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import png
from jaxtyping import Array, ArrayLike, Float

from . import shading
from ._choices import LUT_FORMATS
from ._errors import DiffwashError
from ._io import atomic_path, check_input_file, open_input, read_json, write_png_blocks
from ._lazy import lazy
from ._mixture import Mixture
from ._scene import Scene, load_scene
from ._version import __version__
from .colorimetry import from_display, to_display
from .shading import DEFAULT_CONSTANTS, Params

OpenEXR = lazy("OpenEXR")

__all__ = [
    "Lut",
    "bake",
    "save",
    "load",
    "load_encoded",
    "encoded",
    "check_size",
    "files",
    "format_for",
    "sidecar",
    "sidecar_path",
    "FORMATS",
    "KINDS",
    "MIN_SIZE",
    "MAX_SIZE",
]

#: Smallest and largest number of samples per axis.
MIN_SIZE, MAX_SIZE = 2, 4096
#: File formats: name -> (file extension, encoding of the stored values); declared in `_choices` so
#: that `--help` can list them without loading JAX.
FORMATS = LUT_FORMATS
#: Kinds of table: the final colour over the paper, or the glazes' R and T.
KINDS = ("colour", "rt")
#: Identifies a sidecar file; bumped when its schema changes incompatibly.
SIDECAR_FORMAT = "diffwash-lut"
SIDECAR_VERSION = 1

_CONVENTION = {
    "columns": "column i of N (left to right) holds wash thickness i / (N - 1) * wash_max",
    "rows": "row j of M (from the top) holds unlit thickness j / (M - 1) * unlit_max",
    "sampling": "texel centres: u = (wash / wash_max * (N - 1) + 0.5) / N, v = (unlit / unlit_max * (M - 1) + 0.5) / M",
}


class Lut(eqx.Module):
    """A baked table of glaze colours over (wash, unlit) thickness.

    **Fields:**

    - `values`: linear values, float32, shape `(M, N, 3)` for a `"colour"` table
      (rows = unlit thickness from the top, columns = wash thickness) or
      `(M, N, 6)` for an `"rt"` table (reflectance RGB, then transmittance RGB).
    - `wash_max`, `unlit_max`: the thickness at the last column and row.
    - `kind`: `"colour"` or `"rt"`.
    - `meta`: what it was baked from (pigments, paper, constants, version), as
      written in the sidecar.
    """

    values: Float[Array, "n_unlit n_wash c"]
    wash_max: float = eqx.field(static=True)
    unlit_max: float = eqx.field(static=True)
    kind: str = eqx.field(static=True, default="colour")
    meta: dict = eqx.field(static=True, default_factory=dict)

    @property
    def size(self) -> tuple[int, int]:
        """`(N, M)`: columns (wash samples) and rows (unlit samples)."""
        return int(self.values.shape[1]), int(self.values.shape[0])

    @property
    def wash(self) -> np.ndarray:
        """Wash thickness of each column, shape (N,)."""
        n = self.size[0]
        return np.arange(n) / (n - 1) * self.wash_max

    @property
    def unlit(self) -> np.ndarray:
        """Unlit thickness of each row (top to bottom), shape (M,)."""
        m = self.size[1]
        return np.arange(m) / (m - 1) * self.unlit_max

    @property
    def colour(self) -> np.ndarray:
        """The final linear colour (M, N, 3) over the paper the table was baked with."""
        if self.kind == "colour":
            return np.asarray(self.values[..., :3])
        paper = np.asarray(self.meta["paper"], np.float64)
        R, T = np.asarray(self.values[..., :3], np.float64), np.asarray(self.values[..., 3:], np.float64)
        return (R + T * T * paper / (1 - R * paper)).astype(np.float32)

    def lookup(self, wash: Float[ArrayLike, "*b"], unlit: Float[ArrayLike, "*b"]) -> Float[np.ndarray, "*b 3"]:
        """Bilinear lookup, as a GPU sampler does it with linear filtering.

        Thicknesses outside the range clamp to its edges (0 where a range is 0).

        **Returns:**

        The table's values at the points, shape `(*b, C)`, float64.
        """
        wash, unlit = np.broadcast_arrays(np.asarray(wash, np.float64), np.asarray(unlit, np.float64))
        n, m = self.size
        x = _unit(wash, self.wash_max) * (n - 1)
        y = _unit(unlit, self.unlit_max) * (m - 1)
        x0 = np.minimum(np.floor(x).astype(np.int64), n - 2)
        y0 = np.minimum(np.floor(y).astype(np.int64), m - 2)
        fx, fy = (x - x0)[..., None], (y - y0)[..., None]
        v = np.asarray(self.values, np.float64)
        top = v[y0, x0] * (1 - fx) + v[y0, x0 + 1] * fx
        bottom = v[y0 + 1, x0] * (1 - fx) + v[y0 + 1, x0 + 1] * fx
        return top * (1 - fy) + bottom * fy


def _unit(x: np.ndarray, top: float) -> np.ndarray:
    if top <= 0:
        return np.zeros_like(x)
    return np.clip(x / top, 0, 1)


def check_size(size: Any, field: str = "size") -> tuple[int, int]:
    """`size` (an int, or `(N, M)`) as `(N, M)`, each in [MIN_SIZE, MAX_SIZE]."""
    sizes = size if isinstance(size, (tuple, list)) else (size, size)
    if len(sizes) != 2:
        raise DiffwashError(f"must be one number or (columns, rows), got {size!r}", field=field)
    out = []
    for s in sizes:
        if isinstance(s, bool) or not isinstance(s, (int, np.integer)):
            raise DiffwashError(f"must be a whole number, got {s!r}", field=field)
        if not MIN_SIZE <= s <= MAX_SIZE:
            raise DiffwashError(f"must be between {MIN_SIZE} and {MAX_SIZE} samples, got {s}", field=field)
        out.append(int(s))
    return out[0], out[1]


def _params_of(scene_or_params: Scene | Params | str | os.PathLike) -> tuple[Params, str | None]:
    if isinstance(scene_or_params, Params):
        return scene_or_params, None
    if isinstance(scene_or_params, Scene):
        return scene_or_params.params, scene_or_params.path
    if isinstance(scene_or_params, (str, os.PathLike)):
        scene = load_scene(scene_or_params)
        return scene.params, scene.path
    raise TypeError(f"bake() takes a Scene, a Params or a scene file path, got {type(scene_or_params).__name__}")


def _scalar(x: Any) -> float:
    return float(np.asarray(x))


def _meta(params: Params, source: str | None) -> dict:
    def pigment(p):
        if isinstance(p, Mixture):  # library pigments: the library's file and the proportions
            return {"name": p.name, **p.describe(), "library": Path(p.library).name if p.library else None}
        return {"name": p.name, "K": np.asarray(p.K, np.float64).tolist(), "S": np.asarray(p.S, np.float64).tolist()}

    meta = {
        "pigments": {"wash": pigment(params.wash), "unlit": pigment(params.unlit)},
        "paper": np.asarray(shading.paper_colour(params), np.float64).tolist(),
        "constants": {k: _scalar(getattr(params, k)) for k in DEFAULT_CONSTANTS},
        "light": {"direction": np.asarray(params.light, np.float64).tolist()},
        "diffwash_version": __version__,
    }
    if params.observation is not None:
        meta["observation"] = params.observation.describe()
    if source is not None:
        meta["scene"] = Path(source).name
    return meta


@jax.jit
def _bake_colour(params: Params, wash: Array, unlit: Array) -> Array:
    return shading.colour(params, wash, unlit)


@jax.jit
def _bake_rt(params: Params, wash: Array, unlit: Array) -> Array:
    return jnp.concatenate(shading.glaze_layers(params, wash, unlit), axis=-1)


def bake(
    scene_or_params: Scene | Params | str | os.PathLike,
    size: int | tuple[int, int] = 256,
    *,
    kind: str = "colour",
    progress: Callable[[float], None] | None = None,
) -> Lut:
    """Evaluate the glaze on the grid of (wash, unlit) thicknesses.

    **Arguments:**

    - `scene_or_params`: a `Scene`, a shading `Params`, or the path of a scene
      file (a fitted scene file works as it is).
    - `size`: samples per axis, `N` (square) or `(N, M)` = (wash columns,
      unlit rows); each within [2, 4096].
    - `kind`: `"colour"` (the final colour over the paper) or `"rt"` (the
      glazes' reflectance and transmittance, for compositing over any paper).
    - `progress`: called with the fraction done, for large tables.

    **Returns:**

    A `Lut` with linear float32 values: column `i` holds wash thickness
    `i / (N - 1) * wash_max` and row `j` (from the top) unlit thickness
    `j / (M - 1) * unlit_max`, with `wash_max = k_specular * k_wash` and
    `unlit_max = k_unlit`.
    """
    n, m = check_size(size)
    if kind not in KINDS:
        raise DiffwashError(f"must be one of {', '.join(KINDS)}, got {kind!r}", field="kind")
    params, source = _params_of(scene_or_params)
    if kind == "rt" and params.observation is not None:
        raise DiffwashError("an R/T table is composited over the paper per sRGB channel in the shader, which "
                            "spectral glazes do not allow (their colour is not a product of channels): bake the "
                            "colour table", file=source, field="kind (--rt)")  # fmt: skip
    wash_max, unlit_max = _scalar(params.wash_max), _scalar(params.unlit_max)
    for name, v in (("wash_max", wash_max), ("unlit_max", unlit_max)):
        if not np.isfinite(v) or v < 0:
            raise DiffwashError(f"must be a finite number >= 0, got {v}", field=name)
    dtype = jnp.zeros(()).dtype  # float32, or float64 when jax_enable_x64 is on
    wash = (np.arange(n) / (n - 1) * wash_max).astype(dtype)
    unlit = (np.arange(m) / (m - 1) * unlit_max).astype(dtype)
    # Rows in blocks of a fixed shape (the last one padded): one compilation per
    # table width, bounded memory for 4096^2 tables.
    bands = len(np.atleast_1d(np.asarray(params.paper)))
    rows = max(1, min(m, (1 << 18) * 3 // (n * max(bands, 3))))  # about 2^18 texels x 3 bands per block
    evaluate = _bake_colour if kind == "colour" else _bake_rt
    canonical = shading.canonical(params)  # one compiled program for any pigment names
    channels = 3 if kind == "colour" else 6
    out = np.empty((m, n, channels), np.float32)
    wash_block = np.broadcast_to(wash, (rows, n))
    for start in range(0, m, rows):
        stop = min(start + rows, m)
        u = np.zeros(rows, dtype)
        u[: stop - start] = unlit[start:stop]
        block = evaluate(canonical, wash_block, np.broadcast_to(u[:, None], (rows, n)))
        out[start:stop] = np.asarray(block)[: stop - start]
        if progress is not None:
            progress(stop / m)
    if not np.all(np.isfinite(out)):
        raise DiffwashError("the glaze is not finite for these pigments (NaN or inf in the table)", field="pigments")
    return Lut(values=out, wash_max=wash_max, unlit_max=unlit_max, kind=kind, meta=_meta(params, source))


# --- files -----------------------------------------------------------------------------------------


def sidecar_path(path: str | os.PathLike) -> Path:
    """The sidecar of a LUT file: `lut.png` -> `lut.json` (a `.json` path is its own)."""
    path = Path(path)
    return path if path.suffix.lower() == ".json" else path.with_suffix(".json")


def files(path: str | os.PathLike, fmt: str, kind: str) -> dict[str, Path]:
    """Every file a LUT of `kind` saved as `fmt` at `path` occupies, by what it holds (images and sidecar)."""
    path = Path(path)
    images = _image_paths(path, kind) if fmt.startswith("png") else {kind: path}
    return {**images, "sidecar": sidecar_path(path)}


def _image_paths(path: Path, kind: str) -> dict[str, Path]:
    if kind == "colour":
        return {"colour": path}
    return {"reflectance": path.with_name(f"{path.stem}_R{path.suffix}"), "transmittance": path.with_name(f"{path.stem}_T{path.suffix}")}


def format_for(path: str | os.PathLike, fmt: str | None = None) -> str:
    """The file format for `path`: `fmt` if given (checked against the extension), else from the extension."""
    suffix = Path(path).suffix.lower()
    if fmt is None:
        by_ext = {".png": "png16", ".exr": "exr", ".npy": "npy"}
        if suffix not in by_ext:
            raise DiffwashError(f"cannot tell the LUT format from the extension {suffix!r}; use .png, .exr or .npy", file=path)
        return by_ext[suffix]
    if fmt not in FORMATS:
        raise DiffwashError(f"must be one of {', '.join(FORMATS)}, got {fmt!r}", field="format")
    if suffix != FORMATS[fmt][0]:
        raise DiffwashError(f"a {fmt} LUT needs a {FORMATS[fmt][0]} file name, got {suffix or 'none'!r}", file=path)
    return fmt


def sidecar(lut: Lut, fmt: str, files: dict[str, str]) -> dict:
    """The sidecar JSON of `lut` stored as `fmt` in `files` (kind -> file name)."""
    n, m = lut.size
    meta = dict(lut.meta)
    data = {
        "format": SIDECAR_FORMAT,
        "format_version": SIDECAR_VERSION,
        "kind": lut.kind,
        "size": [n, m],
        "wash_max": lut.wash_max,
        "unlit_max": lut.unlit_max,
        "encoding": FORMATS[fmt][1],
        "storage": fmt,
        "files": files,
        "convention": _CONVENTION,
        "pigments": meta.pop("pigments", None),
        "paper": meta.pop("paper", None),
        "constants": meta.pop("constants", None),
        "diffwash_version": meta.pop("diffwash_version", __version__),
    }
    if lut.kind == "rt":
        data["channels"] = "reflectance R then transmittance T of the unlit glaze on the wash glaze (paper not included)"
    data.update(meta)  # light, scene
    return data


#: Samples (texels x channels) encoded at once by `encoded`: the sRGB encoding works in float64 with a few temporaries, so a
#: 4096^2 table is encoded in blocks of rows (a few MB) rather than whole (several GB).
_ENCODE_BLOCK = 1 << 18


def encoded(lut: Lut, fmt: str) -> np.ndarray:
    """The values as `fmt` stores them: sRGB-encoded and quantised for PNGs, linear float32 otherwise."""
    values = np.asarray(lut.values)
    if fmt not in ("png16", "png8"):
        return np.asarray(values, np.float32)
    out = np.empty(values.shape, np.uint16 if fmt == "png16" else np.uint8)
    for start, block in _encoded_blocks(values, fmt):
        out[start : start + len(block)] = block
    return out


def _encoded_blocks(values: np.ndarray, fmt: str) -> Any:
    """`(first row, block)` of `values` (rows first) sRGB-encoded and quantised for a `fmt` PNG, block by block."""
    top, dtype = (65535, np.uint16) if fmt == "png16" else (255, np.uint8)
    rows = max(1, _ENCODE_BLOCK // max(1, int(np.prod(values.shape[1:]))))
    for start in range(0, values.shape[0], rows):
        yield start, np.round(to_display(values[start : start + rows]) * top).astype(dtype)


def save(path: str | os.PathLike, lut: Lut, fmt: str | None = None) -> list[Path]:
    """Write `lut` to `path` in `fmt` (default from the extension: `.png` = png16) and its sidecar.

    Nothing is half-written: every file goes to a temporary name first and is
    renamed into place once all are complete.

    **Returns:**

    The paths written, the sidecar last.
    """

    path = Path(path)
    fmt = format_for(path, fmt)
    side = sidecar_path(path)
    data = None if fmt.startswith("png") else encoded(lut, fmt)  # a PNG is encoded row block by row block
    targets = _image_paths(path, lut.kind) if fmt.startswith("png") else {lut.kind: path}
    header = sidecar(lut, fmt, {k: p.name for k, p in targets.items()})
    text = json.dumps(header, indent=2, allow_nan=False) + "\n"
    with contextlib.ExitStack() as stack:
        temps = {k: stack.enter_context(atomic_path(p)) for k, p in targets.items()}
        side_tmp = stack.enter_context(atomic_path(side))
        if fmt.startswith("png"):
            bits = 16 if fmt == "png16" else 8
            values = np.asarray(lut.values)
            m, n = values.shape[:2]
            for i, tmp in enumerate(temps.values()):
                blocks = (block for _, block in _encoded_blocks(values[..., 3 * i : 3 * i + 3], fmt))
                with open(tmp, "wb") as f:
                    write_png_blocks(f, n, m, blocks, bits=bits)
        elif fmt == "exr":
            _write_exr(temps[lut.kind], data, header)
        else:
            with open(temps[lut.kind], "wb") as f:
                np.save(f, data, allow_pickle=False)
        side_tmp.write_text(text, encoding="utf-8")
    return [*targets.values(), side]


def _write_exr(path: Path, data: np.ndarray, header: dict) -> None:

    names = ["R", "G", "B"] if data.shape[-1] == 3 else ["R", "G", "B", "T.R", "T.G", "T.B"]
    channels = {name: np.ascontiguousarray(data[..., c]) for c, name in enumerate(names)}
    head = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage, "diffwash": json.dumps(header)}
    with OpenEXR.File(head, channels) as f:
        f.write(str(path))


def _read_exr(path: Path, channels: int) -> np.ndarray:

    with OpenEXR.File(str(path)) as f:
        ch = {k: np.asarray(v.pixels) for k, v in f.channels().items()}
    parts = []
    for group, names in (("RGB", ["R", "G", "B"]), ("T", ["T.R", "T.G", "T.B"]))[: channels // 3]:
        if group in ch and np.ndim(ch[group]) == 3:
            parts.append(ch[group].reshape(*ch[group].shape[:2], 3))
        elif all(n in ch for n in names):
            parts.append(np.stack([ch[n] for n in names], axis=-1))
        else:
            raise DiffwashError(f"OpenEXR file lacks the channels {', '.join(names)}", file=path)
    return np.concatenate(parts, axis=-1).astype(np.float32)


def _read_png(path: Path) -> tuple[np.ndarray, int]:

    if not os.path.lexists(path):
        raise DiffwashError("no such LUT image (named in the sidecar)", file=path)
    try:
        with open_input(path, "rb") as f:
            w, h, rows, info = png.Reader(file=f).asDirect()
            a = np.vstack([np.asarray(r, np.uint16) for r in rows]).reshape(h, w, info["planes"])
    except png.Error as e:
        raise DiffwashError(f"not a readable PNG: {e}", file=path) from None
    if info["planes"] != 3:
        raise DiffwashError(f"a LUT PNG must be RGB, got {info['planes']} channels", file=path)
    return a, info["bitdepth"]


def load_encoded(table: Lut, fmt: str = "png16") -> Lut:
    """`table` as it comes back from a `fmt` file: quantised to the file's encoding and decoded."""
    if fmt not in FORMATS:
        raise DiffwashError(f"must be one of {', '.join(FORMATS)}, got {fmt!r}", field="format")
    if FORMATS[fmt][1] == "linear":
        return table
    top = 65535 if fmt == "png16" else 255
    values = from_display(encoded(table, fmt).astype(np.float64) / top).astype(np.float32)
    return Lut(values=values, wash_max=table.wash_max, unlit_max=table.unlit_max, kind=table.kind, meta=table.meta)


def load(path: str | os.PathLike) -> Lut:
    """Read a LUT written by `save` (or `diffwash bake`), through its sidecar.

    **Arguments:**

    - `path`: the sidecar (`lut.json`) or the LUT file beside it (`lut.png`).

    **Returns:**

    The `Lut`, values decoded to linear float32.
    """
    side = sidecar_path(path)
    if not os.path.lexists(side):
        raise DiffwashError(f"no sidecar {side.name} beside the LUT (it holds the LUT's range and encoding)", file=side)
    head = read_json(side)
    if not isinstance(head, dict) or head.get("format") != SIDECAR_FORMAT:
        raise DiffwashError(f"not a diffwash LUT sidecar (no \"format\": \"{SIDECAR_FORMAT}\")", file=side, field="format")
    if head.get("format_version") != SIDECAR_VERSION:
        raise DiffwashError(f"unsupported sidecar version {head.get('format_version')!r}", file=side, field="format_version")
    for key in ("kind", "size", "wash_max", "unlit_max", "encoding", "storage", "files"):
        if key not in head:
            raise DiffwashError("missing key", file=side, field=key)
    kind, fmt = head["kind"], head["storage"]
    if kind not in KINDS:
        raise DiffwashError(f"must be one of {', '.join(KINDS)}, got {kind!r}", file=side, field="kind")
    if fmt not in FORMATS:
        raise DiffwashError(f"must be one of {', '.join(FORMATS)}, got {fmt!r}", file=side, field="storage")
    try:
        n, m = check_size(tuple(head["size"]))
    except (DiffwashError, TypeError):
        raise DiffwashError(f"must be [columns, rows], each in [{MIN_SIZE}, {MAX_SIZE}]", file=side, field="size") from None
    files = head["files"]
    wanted = ["colour"] if kind == "colour" else (["reflectance", "transmittance"] if fmt.startswith("png") else ["rt"])
    if not isinstance(files, dict) or any(not isinstance(files.get(k), str) for k in wanted):
        raise DiffwashError(f"must name the file(s) {', '.join(wanted)}", file=side, field="files")
    folder = side.parent
    channels = 3 if kind == "colour" else 6
    if fmt.startswith("png"):
        parts = []
        for k in wanted:
            a, bits = _read_png(folder / files[k])
            expected = 16 if fmt == "png16" else 8
            if bits != expected:
                raise DiffwashError(f"is a {bits}-bit PNG but the sidecar says {fmt}", file=folder / files[k])
            parts.append(a.astype(np.float64) / ((1 << bits) - 1))
        values = np.concatenate(parts, axis=-1)
    else:
        file = folder / files[wanted[0]]
        if not os.path.lexists(file):
            raise DiffwashError("no such LUT file (named in the sidecar)", file=file)
        check_input_file(file)
        if fmt == "exr":
            values = _read_exr(file, channels)
        else:
            try:
                values = np.load(file, allow_pickle=False)
            except (ValueError, OSError) as e:
                raise DiffwashError(f"not a readable .npy file: {e}", file=file) from None
    if values.shape != (m, n, channels):
        raise DiffwashError(f"holds an array of shape {values.shape}, the sidecar says {(m, n, channels)}", file=side, field="size")
    if head["encoding"] == "srgb":
        values = from_display(values)
    elif head["encoding"] != "linear":
        raise DiffwashError(f"must be srgb or linear, got {head['encoding']!r}", file=side, field="encoding")
    meta = {k: head[k] for k in ("pigments", "paper", "constants", "light", "diffwash_version", "scene", "observation") if k in head}
    return Lut(
        values=np.asarray(values, np.float32),
        wash_max=float(head["wash_max"]),
        unlit_max=float(head["unlit_max"]),
        kind=kind,
        meta=meta,
    )


def print_progress(fraction: float) -> None:
    """A `progress` callback for `bake` that prints a percentage on stderr."""
    print(f"\rbaking {100 * fraction:5.1f}%", end="" if fraction < 1 else "\n", file=sys.stderr, flush=True)
