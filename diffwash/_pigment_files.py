"""Pigment files read and checked as plain data: NumPy only, no JAX.

`diffwash.pigments` builds its `Pigment`s (pytrees) from these records; `diffwash pigments` prints
them as they are, so listing a library loads no JAX. The format is documented in `diffwash.pigments`.
"""

from __future__ import annotations

import os
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from ._errors import DiffwashError
from ._io import check_float32, finite_number, read_json

__all__ = ["DEFAULTS", "default_library_path", "key", "parse_record", "read_pigments", "read_records", "to_dict"]

#: Values of the optional keys when a pigment file leaves them out.
DEFAULTS = {"density": 0.05, "staining": 1.0, "granularity": 0.5}


def default_library_path() -> Path:
    """The seed's table of 12 pigments, shipped with the package."""
    return Path(str(resources.files("diffwash") / "data" / "pigments" / "seed.json"))


def key(name: str) -> str:
    """How pigment names are matched: case and runs of spaces ignored."""
    return " ".join(name.casefold().split())


def _rgb(value: Any, file: Any, field: str) -> np.ndarray:
    if not isinstance(value, list) or len(value) != 3:
        got = f"{len(value)} values" if isinstance(value, list) else type(value).__name__
        raise DiffwashError(f"must be a list of 3 numbers (red, green, blue), got {got}", file=file, field=field)
    for v in value:
        if not finite_number(v):
            raise DiffwashError(f"must be finite numbers, got {v!r}", file=file, field=field)
        check_float32(v, file=file, field=field)
        if v < 0:
            raise DiffwashError(f"must be >= 0, got {v!r}", file=file, field=field)
    return np.asarray(value, np.float64)


def parse_record(obj: Any, *, file: str | os.PathLike | None = None, where: str = "") -> dict[str, Any]:
    """Validate one pigment object (a dict from JSON): `name`, `K` and `S` (float64 arrays) and the optional keys.

    Errors name `file` and the field, e.g. `lib.json: pigments[2].K: must be >= 0`.
    """
    ctx = f"{where}." if where else ""
    if not isinstance(obj, dict):
        raise DiffwashError(f"a pigment must be a JSON object, got {type(obj).__name__}", file=file, field=where or None)
    for k in ("name", "K", "S"):
        if k not in obj:
            raise DiffwashError("missing key", file=file, field=ctx + k)
    name = obj["name"]
    if not isinstance(name, str) or not name.strip():
        raise DiffwashError("must be a non-empty string", file=file, field=ctx + "name")
    record: dict[str, Any] = {"name": name.strip(), "K": _rgb(obj["K"], file, ctx + "K"), "S": _rgb(obj["S"], file, ctx + "S")}
    for k, default in DEFAULTS.items():
        v = obj.get(k, default)
        if not finite_number(v) or v < 0:
            raise DiffwashError(f"must be a finite number >= 0, got {v!r}", file=file, field=ctx + k)
        record[k] = check_float32(v, file=file, field=ctx + k)
    return record


def read_records(path: str | os.PathLike | None = None) -> list[dict[str, Any]]:
    """Every pigment of a pigment file (default: the seed's 12), checked, in file order."""
    path = path if path is not None else default_library_path()
    data = read_json(path)
    if isinstance(data, dict) and "pigments" in data:
        items = data["pigments"]
        if not isinstance(items, list) or not items:
            raise DiffwashError("must be a non-empty list of pigments", file=path, field="pigments")
        records = [parse_record(p, file=path, where=f"pigments[{i}]") for i, p in enumerate(items)]
        _refuse_colliding_names([r["name"] for r in records], path)
        return records
    return [parse_record(data, file=path)]


def _refuse_colliding_names(names: list[str], path: Any) -> None:
    """Two pigments whose names match as `load` matches names (ignoring case and runs of spaces) are refused:
    a name would pick one of them silently."""
    seen: dict[str, int] = {}
    for i, name in enumerate(names):
        j = seen.setdefault(key(name), i)
        if j != i:
            raise DiffwashError(f"{name!r} and pigments[{j}].name {names[j]!r} name the same pigment "
                                "(names are matched ignoring case and spaces)", file=path,
                                field=f"pigments[{i}].name")  # fmt: skip


def to_dict(record: Any) -> dict[str, Any]:
    """A pigment (a record or a `Pigment`) as a JSON-ready dict in the library schema."""
    get = record.get if isinstance(record, dict) else lambda k: getattr(record, k)
    return {
        "name": get("name"),
        "K": [float(v) for v in np.asarray(get("K"))],
        "S": [float(v) for v in np.asarray(get("S"))],
        "density": float(get("density")),
        "staining": float(get("staining")),
        "granularity": float(get("granularity")),
    }


def read_pigments(path: str | os.PathLike | None = None) -> list[dict[str, Any]]:
    """The pigments of a pigment file (default: the seed's 12) as JSON-ready dicts in the library schema, in file order.

    Checked as `diffwash.pigments.library` checks them (one-line errors naming the file and the field), without
    making `Pigment`s: NumPy only, no JAX. `diffwash pigments` prints these.
    """
    return [to_dict(r) for r in read_records(path)]
