"""Pigment files read and checked as plain data: NumPy only, no JAX.

`diffwash.pigments` builds its `Pigment`s (pytrees) from these records; `diffwash pigments` prints
them as they are, so listing a library loads no JAX. The format is declared in `diffwash._schema`
(`PigmentFile`, `PigmentRecord`) and documented in docs/pigments.md.
"""

from __future__ import annotations

import os
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from . import _schema
from ._errors import DiffwashError
from ._io import read_json

__all__ = ["DEFAULTS", "default_library_path", "key", "parse_record", "read_pigments", "read_records", "to_dict"]

#: Values of the optional keys when a pigment file leaves them out (`_schema.PigmentRecord`'s defaults).
DEFAULTS = {k: _schema.PigmentRecord.model_fields[k].default for k in ("density", "staining", "granularity")}


def default_library_path() -> Path:
    """The seed's table of 12 pigments, shipped with the package."""
    return Path(str(resources.files("diffwash") / "data" / "pigments" / "seed.json"))


#: How pigment names are matched: case and runs of spaces ignored (the declared formats' rule).
key = _schema.name_key


def parse_record(obj: Any, *, file: str | os.PathLike | None = None, where: str = "") -> dict[str, Any]:
    """Validate one pigment object (a dict from JSON) against its declaration (`_schema.PigmentRecord`): `name`,
    `K` and `S` (float64 arrays) and the optional keys (`DEFAULTS`).

    Errors name `file` and the field, e.g. `lib.json: pigments[2].K[0]: must be >= 0`.
    """
    try:
        rec = _schema.validate(_schema.PigmentRecord, obj, file, what="pigment")
    except DiffwashError as e:
        if not where:
            raise
        raise DiffwashError(e.problem, file=file, field=f"{where}.{e.field}" if e.field else where) from None
    return _record(rec)


def _record(rec: _schema.PigmentRecord) -> dict[str, Any]:
    return {"name": rec.name.strip(), "K": np.asarray(rec.K, np.float64), "S": np.asarray(rec.S, np.float64),
            **{k: float(getattr(rec, k)) for k in DEFAULTS}}  # fmt: skip


def read_records(path: str | os.PathLike | None = None) -> list[dict[str, Any]]:
    """Every pigment of a pigment file (default: the seed's 12), checked, in file order."""
    path = path if path is not None else default_library_path()
    data = read_json(path)
    if isinstance(data, dict) and "pigments" in data:
        pigs = _schema.validate(_schema.PigmentFile, data, path).pigments
        records = [_record(p) for p in pigs]
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
