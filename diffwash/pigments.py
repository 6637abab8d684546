"""The pigment library: Kubelka-Munk coefficients of watercolour pigments.

A pigment is its absorption `K` and scattering `S` per unit thickness for red,
green and blue, plus the three properties Curtis et al. (1997) use for pigment
transport (density, staining, granularity).

Pigment files are JSON, described by the JSON Schema `data/pigments/schema.json`
shipped with the package: either one pigment object

    {"name": "Quinacridone Rose", "K": [0.22, 1.47, 0.57], "S": [0.05, 0.003, 0.03],
     "density": 0.02, "staining": 5.5, "granularity": 0.81}

or a library `{"pigments": [pigment, ...]}`. `name`, `K` and `S` are required;
`density`, `staining` and `granularity` default to 0.05, 1.0 and 0.5. Other keys
are ignored (fitted pigments carry their diagnostics there). A
`diffwash.library` file per sRGB channel (what the fits write) is such a
library: its pigments' K and S are per unit thickness, thickness 1 being its
amount law's reference amount (1 coat for swatch cards).

The default library is the seed's table of 12 pigments (Smedresman, after
Curtis et al.), `data/pigments/seed.json`.
"""

from __future__ import annotations

import dataclasses
import difflib
import os
from pathlib import Path
from typing import Any

import equinox as eqx
import jax
from jaxtyping import ArrayLike, Float

from . import _pigment_files
from ._errors import DiffwashError
from ._io import read_json as _read_json
from ._io import write_json
from ._pigment_files import DEFAULTS as DEFAULTS
from ._pigment_files import key as _key

__all__ = ["Pigment", "unlabelled", "load", "library", "names", "parse", "save", "DEFAULTS"]


class Pigment(eqx.Module):
    """A watercolour pigment: a pytree whose leaves are its coefficients.

    **Fields:**

    - `K`: absorption per unit thickness, shape (3,) (red, green, blue), `>= 0`.
    - `S`: scattering per unit thickness, shape (3,), `>= 0`.
    - `density`, `staining`, `granularity`: Curtis et al.'s rho, omega, gamma
      (scalars; differentiable leaves like `K` and `S`).
    - `name`: the pigment's label: static metadata, which the compiled kernels
      never see (`unlabelled`), so relabelling a pigment compiles nothing.
    """

    K: Float[ArrayLike, " C"]
    S: Float[ArrayLike, " C"]
    density: Float[ArrayLike, ""] = DEFAULTS["density"]
    staining: Float[ArrayLike, ""] = DEFAULTS["staining"]
    granularity: Float[ArrayLike, ""] = DEFAULTS["granularity"]
    name: str = eqx.field(static=True, default="pigment")

    def to_dict(self) -> dict[str, Any]:
        """The pigment as a JSON-ready dict in the library schema."""
        return _pigment_files.to_dict(self)


def unlabelled(tree: Any) -> Any:
    """`tree` with every `Pigment` in it relabelled to the default label (what compiled kernels take)."""

    def strip(x: Any) -> Any:
        return dataclasses.replace(x, name="pigment") if isinstance(x, Pigment) and x.name != "pigment" else x

    return jax.tree.map(strip, tree, is_leaf=lambda x: isinstance(x, Pigment))


def parse(obj: Any, *, file: str | os.PathLike | None = None, where: str = "") -> Pigment:
    """Validate one pigment object (a dict from JSON) and make a `Pigment`.

    Errors name `file` and the field, e.g. `lib.json: pigments[2].K: must be >= 0`.
    """
    return Pigment(**_pigment_files.parse_record(obj, file=file, where=where))


def _read_file(path: str | os.PathLike) -> list[Pigment]:
    data = _read_json(path)
    if isinstance(data, dict) and data.get("format") == "diffwash-library":
        obs = data.get("observation")
        if not (isinstance(obs, dict) and obs.get("bands") == "sRGB"):
            raise DiffwashError("is a spectral pigment library (K and S per wavelength), not three-channel pigments: "
                                'a scene takes its paint as {"library": FILE, "pigment": NAME}', file=path)  # fmt: skip
    return [Pigment(**r) for r in _pigment_files.read_records(path)]


def library(path: str | os.PathLike | None = None) -> dict[str, Pigment]:
    """All pigments of a pigment file (default: the seed's 12), by name, in file order."""
    pigments = _read_file(path if path is not None else _pigment_files.default_library_path())
    return {p.name: p for p in pigments}


def names() -> list[str]:
    """Names of the default library's pigments."""
    return list(library())


def _find(pigments: dict[str, Pigment], name: str, file: Any) -> Pigment:
    by_key = {_key(n): p for n, p in pigments.items()}
    if _key(name) in by_key:
        return by_key[_key(name)]
    close = _close_names(_key(name), list(by_key))
    hint = f"; did you mean {', '.join(repr(by_key[c].name) for c in close)}?" if close else ""
    where = f"not in {file}" if file else "not in the pigment library"
    raise DiffwashError(f"unknown pigment {name!r} ({where}){hint}")


def _close_names(key: str, keys: list[str], n: int = 3) -> list[str]:
    """Names like `key`, by the whole name or by one of its words ("rose")."""

    def score(k: str) -> float:
        whole = difflib.SequenceMatcher(None, key, k).ratio()
        words = max(difflib.SequenceMatcher(None, key, w).ratio() for w in k.split())
        return max(whole, words)

    scored = sorted(((score(k), k) for k in keys), reverse=True)
    return [k for s, k in scored[:n] if s >= 0.6]


def _looks_like_path(s: str) -> bool:
    return s.lower().endswith(".json") or os.sep in s or "/" in s


def load(name_or_path: str | os.PathLike, name: str | None = None) -> Pigment:
    """Load a pigment by name from the default library, or from a pigment file.

    **Arguments:**

    - `name_or_path`: a pigment name (matched case-insensitively, spaces
      normalised, e.g. `"french ultramarine"`), or the path of a pigment file.
    - `name`: with a file that holds several pigments, which one.

    **Returns:**

    The `Pigment`. Unknown names raise `DiffwashError` suggesting close names.
    """
    if isinstance(name_or_path, os.PathLike) or _looks_like_path(str(name_or_path)) or Path(name_or_path).is_file():
        path = Path(name_or_path)
        if not os.path.lexists(path):
            raise DiffwashError("no such pigment file", file=path)
        pigments = _read_file(path)
        if name is not None:
            return _find({p.name: p for p in pigments}, name, path)
        if len(pigments) > 1:
            listed = ", ".join(p.name for p in pigments)
            raise DiffwashError(f"holds {len(pigments)} pigments ({listed}); say which by name", file=path)
        return pigments[0]
    return _find(library(), str(name_or_path) if name is None else name, None)


def save(path: str | os.PathLike, pigments: Pigment | list[Pigment], **extra: Any) -> None:
    """Write one pigment (an object) or several (a library) as JSON, atomically.

    `extra` keys are added at the top level (e.g. fit diagnostics).
    """
    if isinstance(pigments, Pigment):
        data = {**pigments.to_dict(), **extra}
    else:
        data = {"pigments": [p.to_dict() for p in pigments], **extra}
    write_json(path, data)
