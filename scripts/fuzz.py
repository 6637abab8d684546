"""Property-based fuzzing of every file reader diffwash has (hypothesis).

Each reader is given generated files: valid ones, valid ones mutated in their
structure (missing and unknown keys, wrong types, numbers that are huge, not
finite, or finite in JSON but not in float32, colliding names, headers that
lie about sizes), and byte-level corruptions (truncation, flipped, inserted and
overwritten bytes). Every input must either load or raise `DiffwashError`,
within a time limit: any other exception is a crash, running past the limit a
hang.

    python scripts/fuzz.py                         # 100,000 inputs over all readers
    python scripts/fuzz.py -n 5000 --reader table  # one reader
    python scripts/fuzz.py --save crashes/         # keep the inputs that crashed

It prints one row per reader (inputs, crashes, hangs, seconds) and exits with
status 1 if anything crashed or hung. `tests/test_fuzz.py` runs a few hundred
inputs per reader in CI.

Generated JSON documents come from hand-written generators (which know what a valid file looks like) and from
the formats' own pydantic declarations (`declared_docs`: every declared key, its type, bounds and length, values at
and past the edges), then mutated.

Readers (their public functions): scenes (`diffwash.load_scene`), swatch-card
layouts (`diffwash.fit.read_layout`), pigment files (`diffwash.pigments.load`),
pigment libraries (`diffwash.pigments.library`), mixable libraries (`diffwash.library.load_library`, then a
prediction that must be finite), measurement tables
(`diffwash.fit.read_table`), images (`diffwash._io.read_image`) and meshes
(`diffwash.load_mesh`: PLY, OBJ, STL, OFF, GLB through trimesh).

To fuzz a new reader, add a `Reader` to `READERS`; to teach the table fuzzer a
new column or a new kind of value (spectral columns, mixtures such as
`P1+P3,0.01+0.02,paper`), add it to `TABLE_VALUES` / `TABLE_COLUMNS`.
"""

from __future__ import annotations

import argparse
import contextlib
import csv
import io
import json
import math
import signal
import struct
import sys
import tempfile
import time
import traceback
import warnings
import zlib
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from hypothesis import HealthCheck, Phase, given, seed, settings
from hypothesis import strategies as st

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:  # the checkout's diffwash, as `python scripts/fuzz.py` from anywhere
    sys.path.insert(0, str(ROOT))

import diffwash  # noqa: E402
from diffwash import DiffwashError  # noqa: E402
from diffwash._io import read_image  # noqa: E402

# ---------------------------------------------------------------------------------------------------------------
# Values and mutations shared by the readers.

#: Numbers that break naive readers: not finite, finite in float64 but not float32, huge integers, signed zero.
SPECIAL_NUMBERS = (
    0, -0.0, 1, -1, 0.5, 1e-320, 1e-45, 3.4028235e38, 3.5e38, 1e39, -1e39, 1e300, -1e300, 1e308, 2**31, 2**63,
    10**30, -(10**30), 10**400, float("nan"), float("inf"), float("-inf"),
)  # fmt: skip

numbers = st.one_of(
    st.sampled_from(SPECIAL_NUMBERS),
    st.integers(-(2**70), 2**70),
    st.floats(allow_nan=True, allow_infinity=True),
    st.floats(-2.0, 2.0),
)
json_scalars = st.one_of(st.none(), st.booleans(), numbers, st.text(max_size=12))
json_values = st.recursive(
    json_scalars,
    lambda inner: st.one_of(st.lists(inner, max_size=5), st.dictionaries(st.text(max_size=8), inner, max_size=5)),
    max_leaves=12,
)


def _paths(doc: Any, prefix: tuple = ()) -> list[tuple]:
    """Every path (a tuple of keys and indices) into a JSON document."""
    out = [prefix]
    if isinstance(doc, dict):
        for k, v in doc.items():
            out += _paths(v, prefix + (k,))
    elif isinstance(doc, list):
        for i, v in enumerate(doc):
            out += _paths(v, prefix + (i,))
    return out


def _set(doc: Any, path: tuple, value: Any, *, delete: bool = False) -> Any:
    if not path:
        return value
    parent = doc
    for k in path[:-1]:
        parent = parent[k]
    if delete:
        del parent[path[-1]]
    else:
        parent[path[-1]] = value
    return doc


@st.composite
def mutated_json(draw: Any, base: Any) -> Any:
    """`base` (a JSON document) with a few random edits: a value replaced, a key removed or added."""
    doc = json.loads(json.dumps(base))
    for _ in range(draw(st.integers(0, 4))):
        paths = _paths(doc)
        path = draw(st.sampled_from(paths))
        op = draw(st.sampled_from(["number", "value", "delete", "add", "grow"]))
        if op == "number":
            doc = _set(doc, path, draw(numbers))
        elif op == "value":
            doc = _set(doc, path, draw(json_values))
        elif op == "delete" and path:
            doc = _set(doc, path, None, delete=True)
        elif op == "add":
            target = doc
            for k in path:
                target = target[k]
            if isinstance(target, dict):
                target[draw(st.text(max_size=8))] = draw(json_values)
            elif isinstance(target, list):
                target.append(draw(json_values))
        elif op == "grow":
            target = doc
            for k in path:
                target = target[k]
            if isinstance(target, list) and target:
                target.extend([target[0]] * draw(st.integers(1, 3)))
    return doc


@st.composite
def mutated_bytes(draw: Any, data: bytes) -> bytes:
    """`data` with byte-level damage (often none): truncated, bytes flipped, inserted, overwritten or dropped."""
    data = bytearray(data)
    for _ in range(draw(st.sampled_from([0, 0, 0, 1, 1, 2, 3]))):
        op = draw(st.sampled_from(["truncate", "flip", "insert", "overwrite", "drop"]))
        i = draw(st.integers(0, len(data)))
        if op == "truncate":
            del data[i:]
        elif op == "flip" and i < len(data):
            data[i] ^= 1 << draw(st.integers(0, 7))
        elif op == "insert":
            data[i:i] = draw(st.binary(max_size=16))
        elif op == "overwrite":
            chunk = draw(st.binary(min_size=1, max_size=16))
            data[i : i + len(chunk)] = chunk
        elif op == "drop":
            del data[i : i + draw(st.integers(1, 16))]
    return bytes(data)


def json_file(base: st.SearchStrategy[Any]) -> st.SearchStrategy[bytes]:
    """JSON files: documents drawn from `base`, mutated, written (NaN and Infinity tokens included), damaged;
    now and then something that is not JSON at all, or nested too deeply."""

    def text(doc: Any) -> bytes:
        return json.dumps(doc, allow_nan=True).encode()

    documents = base.flatmap(mutated_json).map(text).flatmap(mutated_bytes)
    deep = st.integers(100, 200_000).map(lambda n: b"[" * n + b"]" * n)
    odd = st.sampled_from([b"9" * 5000, b"1e400", b"-1e400", b"NaN", b'"\\ud800"', b"\xff\xfe{}", b"{}" * 3, b""])
    return st.one_of(documents, documents, documents, documents, st.binary(max_size=64), deep, odd)


# ---------------------------------------------------------------------------------------------------------------
# Documents drawn from the formats' own declarations (diffwash._schema, diffwash._scene_schema): each field's type,
# bounds and length as declared (cross-field rules, such as a box's x0 < x1, only by chance). Mutated like the
# others (values past the edges, wrong types, keys dropped or added), they reach every key a format has, including
# keys a hand-written generator below forgets.


def _bounds_of(metadata: list) -> dict:
    out = {}
    for m in metadata:
        for k in ("gt", "ge", "lt", "le", "min_length", "max_length"):
            v = getattr(m, k, None)
            if v is not None:
                out[k] = v
        out.update(_bounds_of(getattr(m, "metadata", []) or []))
    return out


def _from_type(t: Any, metadata: list, depth: int = 0) -> st.SearchStrategy[Any]:
    """A strategy for values of the annotation `t` (with pydantic `metadata`: bounds, lengths)."""
    import types
    import typing

    import pydantic

    metadata = list(metadata)
    while typing.get_origin(t) is typing.Annotated:
        t, *more = typing.get_args(t)
        metadata += more
    b = _bounds_of(metadata)
    origin = typing.get_origin(t)
    if origin in (typing.Union, types.UnionType):
        return st.one_of([_from_type(a, [], depth + 1) for a in typing.get_args(t)])
    if origin is typing.Literal:
        return st.sampled_from(typing.get_args(t))
    if origin in (list, tuple):
        args = typing.get_args(t)
        if origin is tuple and args and args[-1] is not Ellipsis:
            return st.tuples(*[_from_type(a, [], depth + 1) for a in args]).map(list)
        lo = b.get("min_length", 0)
        hi = b.get("max_length", lo + 4 if depth < 3 else lo)
        return st.lists(_from_type(args[0] if args else Any, [], depth + 1), min_size=lo, max_size=max(lo, min(hi, lo + 6)))
    if origin is dict:
        lo = b.get("min_length", 0)
        return st.dictionaries(st.sampled_from(("paper", "P1", "P4", "cream") + _NAMES),
                               _from_type(typing.get_args(t)[1], [], depth + 1), min_size=lo, max_size=lo + 2)  # fmt: skip
    if isinstance(t, type) and issubclass(t, pydantic.BaseModel):
        return _from_model(t, depth + 1)
    if t is bool:
        return st.booleans()
    if t is int:
        lo, hi = b.get("ge", b.get("gt", -1) + 1), b.get("le", b.get("lt", 2**32) - 1)
        return st.integers(lo, min(hi, lo + 1000))
    if t is float:  # inside the declared range (the mutations take values past it); whole numbers as often
        lo = b.get("ge", b.get("gt", -1e3))
        hi = b.get("le", b.get("lt", max(lo, 0) + 1e3))
        inside = st.floats(float(lo), float(hi), exclude_min="gt" in b, exclude_max="lt" in b)
        whole = range(math.floor(lo) + 1, math.ceil(hi))
        return st.one_of(inside, st.integers(whole.start, whole.stop - 1)) if len(whole) else inside
    if t is str:
        return st.one_of(st.sampled_from(_NAMES + _PIGMENT_REFS + ("paper", "black", "P1", "P1+P4", "D65")),
                         st.text(max_size=10))  # fmt: skip
    return json_values


def _from_model(model: Any, depth: int = 0) -> st.SearchStrategy[dict]:
    """Objects of a pydantic model: its required keys always, each optional key now and then."""

    @st.composite
    def draw_doc(draw: Any) -> dict:
        doc = {}
        for name, f in model.model_fields.items():
            key = f.alias or name
            if f.is_required() or draw(st.integers(0, 2)) == 0:
                doc[key] = draw(_from_type(f.annotation, f.metadata, depth))
        return doc

    return draw_doc()


def declared_docs(model_path: str) -> st.SearchStrategy[dict]:
    """Documents of the format declared as `model_path` (`module:Model` in diffwash)."""
    import importlib

    module, name = model_path.split(":")
    return st.deferred(lambda: _from_model(getattr(importlib.import_module(f"diffwash.{module}"), name)))


def _with_mesh(doc: dict) -> dict:
    """A declared scene document naming the fuzzing folder's mesh (the reader then gets past the mesh)."""
    return {**doc, "mesh": "tetra.ply"} if isinstance(doc, dict) and doc.get("mesh") != "garbage.obj" else doc


# ---------------------------------------------------------------------------------------------------------------
# Pigments and libraries.

_NAMES = ("Cadmium Red", "cadmium  red", "CADMIUM RED", "Cobalt Blue", "Rose", " ", "", "Ünicode ß", "SS")
#: A swatch-card patch's `pigment` and `coats` (layouts).
_MIXTURES = ("P1", "P1+P4", "P1 + p1", "P1+P4+P10", "P1+", "+", "", " ", "paper", "P1+Black", 3, None, ["P1"])
_MIXTURE_COATS = ("1+2", "1+1+1", "0+0", "1+-2", "1+x", "1+nan", "1+1e39", "2", "", "+", " 1 + 0.5 ", "1_0+1", [1, 2])


def _rgb(draw: Any) -> list[float]:
    return [draw(st.floats(0, 5)) for _ in range(3)]


@st.composite
def pigment_docs(draw: Any) -> dict:
    doc = {"name": draw(st.sampled_from(_NAMES[:5])), "K": _rgb(draw), "S": _rgb(draw)}
    if draw(st.booleans()):
        doc.update(density=0.02, staining=5.5, granularity=0.81)
    return doc


library_docs = st.lists(pigment_docs(), min_size=1, max_size=5).map(lambda ps: {"pigments": ps})

#: Numbers at and past the edges of the mixable library's declared ranges (diffwash/_schema.py), and non-numbers.
_EDGES = (0, -0.0, -1, 1e-45, 1e-6, 0.999999, 1, 10, 10.5, 1e6, 1e12, 1.1e12, 1e30, 3.4e38, 1e39, 10**400, math.nan,
          math.inf, "1", True, None, [1], {})  # fmt: skip


def _edge_or(draw: Any, lo: float, hi: float) -> Any:
    return draw(st.sampled_from(_EDGES)) if draw(st.integers(0, 3)) == 0 else draw(st.floats(lo, hi))


@st.composite
def mixable_library_docs(draw: Any) -> dict:
    """A mixable library (`"format": "diffwash-library"`) on a small grid, numbers now and then at the edges."""
    n = draw(st.integers(1, 4))
    waves = [400 + 100 * i for i in range(n)]
    pigments = []
    for _ in range(draw(st.integers(1, 3))):
        pigments.append({"name": draw(st.sampled_from(("P1", "p1", "P 1", "P  1", "P2", "A+B", "", " "))),
                         "K": [_edge_or(draw, 0, 1e4) for _ in range(n)], "S": [_edge_or(draw, 0, 1e4) for _ in range(n)],
                         "amount_law": {"kind": "power", "reference": _edge_or(draw, 1e-3, 1),
                                        "gamma": _edge_or(draw, 0.1, 5)},
                         "mixing_weight": _edge_or(draw, 0.01, 100)})  # fmt: skip
    return {"format": "diffwash-library", "version": 1, "observation": {"wavelengths": waves}, "pigments": pigments,
            "grounds": {"paper": [_edge_or(draw, 0, 1) for _ in range(n)]}, "surface": {"k2": _edge_or(draw, 0, 0.99)}}


def _load_mixable(path: Path, amount: float) -> Any:
    """Load a mixable library and predict its first pigment at `amount`: the prediction must be finite."""
    lib = diffwash.library.load_library(path)
    pred = lib.predict([lib.names[0]], [[amount]])
    if not np.all(np.isfinite(pred.lab)):
        raise AssertionError(f"non-finite prediction {pred.lab.tolist()} at amount {amount:g}")
    return lib

# ---------------------------------------------------------------------------------------------------------------
# Scenes: they name a mesh and pigment files in the fuzzing folder (written once by `prepare`).

_TETRA = b"ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n" \
    b"element face 4\nproperty list uchar int vertex_indices\nend_header\n" \
    b"0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 3\n"  # fmt: skip


def prepare(folder: Path) -> None:
    """The files scenes may name: a small mesh, a pigment file and a library."""
    (folder / "tetra.ply").write_bytes(_TETRA)
    (folder / "pigment.json").write_text(json.dumps({"name": "Rose", "K": [0.2, 1.4, 0.5], "S": [0.05, 0, 0.03]}))
    (folder / "library.json").write_text(json.dumps({"pigments": [{"name": "A", "K": [1, 1, 1], "S": [0, 0, 0]},
                                                                  {"name": "a", "K": [1, 1, 1], "S": [0, 0, 0]}]}))  # fmt: skip
    (folder / "garbage.obj").write_bytes(b"v 1 2\nf 1 2 3 4 5\n")
    # A spectral pigment library (fit-swatch --table) for library glazes and mixtures.
    (folder / "paints.json").write_bytes((Path(__file__).resolve().parent.parent / "data" / "libraries" / "ntu-four.json").read_bytes())


_PIGMENT_REFS = ("Quinacridone Rose", "french ultramarine", "pigment.json", "library.json", "missing.json", "Nope")


@st.composite
def scene_docs(draw: Any) -> dict:
    def vec(lo: float = -3, hi: float = 3) -> list[float]:
        return [draw(st.floats(lo, hi)) for _ in range(3)]

    def pigment() -> Any:
        kind = draw(st.integers(0, 3))
        if kind == 0:
            return {"pigment": draw(st.sampled_from(_PIGMENT_REFS))}
        if kind == 1:
            return draw(st.sampled_from(_PIGMENT_REFS))
        if kind == 3:
            return _library_glaze(draw)
        return {"K": _rgb(draw), "S": _rgb(draw)}

    doc = {
        "mesh": draw(st.sampled_from(["tetra.ply", "tetra.ply", "missing.ply", "garbage.obj", ".", ""])),
        "image": {"width": draw(st.integers(1, 64)), "height": draw(st.integers(1, 64))},
        "camera": {"eye": vec(), "target": vec(-0.5, 0.5), "up": [0, 1, 0], "fov_y": draw(st.floats(1, 179))},
        "light": {"direction": vec()},
        "wash": pigment(),
        "unlit": pigment(),
    }
    for key in draw(st.sets(st.sampled_from(["k_wash", "k_specular", "shininess", "k_unlit", "gain", "bias",
                                             "wash_reduction", "paper", "shading", "backfaces"]))):  # fmt: skip
        doc[key] = draw(st.floats(0.01, 0.99)) if key != "paper" else _rgb(draw)
    if "paper" in doc and draw(st.booleans()):  # a library's ground, or a reflectance per band
        doc["paper"] = draw(st.sampled_from([{"ground": "paper"}, {"ground": "canvas"}, {"library": "paints.json",
                                             "ground": "Paper"}, [0.8] * 41, [0.8] * 40, {"ground": 3}]))  # fmt: skip
    if draw(st.booleans()):
        doc["watercolour"] = _watercolour_doc(draw)
    return doc


def _library_glaze(draw: Any) -> dict:
    """A glaze of library pigments: a known or unknown library, one pigment or a mix, an amount or none."""
    names = st.sampled_from(["P1", "p4", "P8", "P10", "P2", ""])
    doc: dict = {"library": draw(st.sampled_from(["paints.json", "paints.json", "pigment.json", "missing.json", 3]))}
    if draw(st.booleans()):
        doc["pigment"] = draw(names)
    else:
        doc["mix"] = draw(st.dictionaries(names, st.one_of(st.floats(-0.5, 1.5), st.just(0.5), st.text(max_size=2)),
                                          max_size=3))  # fmt: skip
    if draw(st.booleans()):
        doc["amount"] = draw(st.one_of(st.floats(-0.01, 1e3), st.just(0.0)))
    return doc


#: Values a watercolour key may be given: sensible, out of range, the wrong type, a missing file.
_LOOK_VALUES = st.one_of(st.floats(-1, 3), st.integers(-2, 400), st.sampled_from(["max", "min", "x", "", None, True]),
                         st.sampled_from(["missing.png", "tetra.ply", "Cadmium Yellow", "rose.json"]),
                         st.lists(st.floats(-2, 2), max_size=4))  # fmt: skip


def _watercolour_doc(draw: Any) -> Any:
    """A scene's "watercolour" object: effects on ({}), off (false), or with drawn keys (known and unknown)."""
    if draw(st.integers(0, 9)) == 0:
        return draw(st.sampled_from([None, [], "on", 1, False, True]))
    effects = ["paper", "edges", "unevenness", "strokes", "shadow", "hatching", "mix", "brush"]
    keys = {"paper": ["image", "seed", "relief", "granulation", "density", "shading"],
            "edges": ["darkening", "width"], "unevenness": ["turbulence", "dispersion"],
            "strokes": ["amplitude", "direction", "length", "seed"], "shadow": ["strength", "bias"],
            "hatching": ["amount", "scale"], "mix": ["wash", "unlit", "map"], "brush": ["size"]}
    doc = {}
    for effect in draw(st.sets(st.sampled_from(effects), max_size=4)):
        if draw(st.integers(0, 3)) == 0:
            doc[effect] = draw(st.sampled_from([False, True, None, 0]))
            continue
        obj = {k: draw(_LOOK_VALUES) for k in draw(st.sets(st.sampled_from(keys[effect] + ["other"]), max_size=3))}
        if effect == "mix" and draw(st.booleans()):
            obj["wash"] = {"pigment": draw(st.sampled_from(_PIGMENT_REFS))}
            obj["map"] = draw(st.sampled_from([{"axis": [0, 1, 0], "softness": 0.5}, {"axis": [0, 0, 0]}, "missing.npy"]))
        doc[effect] = obj
    return doc


# ---------------------------------------------------------------------------------------------------------------
# Swatch-card layouts (read against a 64 x 48 photo, or without a photo).


def _box(draw: Any) -> list[int]:
    x0, y0 = draw(st.integers(0, 60)), draw(st.integers(0, 44))
    return [x0, y0, x0 + draw(st.integers(1, 8)), y0 + draw(st.integers(1, 8))]


@st.composite
def layout_docs(draw: Any) -> dict:
    doc: dict[str, Any] = {"paper": {"box": _box(draw)}}
    if draw(st.booleans()):
        doc["paper"]["reflectance"] = [draw(st.floats(0.01, 1)) for _ in range(3)]
    if draw(st.booleans()):
        doc["black"] = {"box": _box(draw)}
    doc["patches"] = [{"box": _box(draw), "coats": draw(st.floats(0.1, 8)),
                       "ground": draw(st.sampled_from(["paper", "black"]))}
                      for _ in range(draw(st.integers(1, 4)))]  # fmt: skip
    for p in doc["patches"]:  # a patch may name its paint: one pigment or a mixture, coats of each
        if draw(st.booleans()):
            p["pigment"] = draw(st.sampled_from(_MIXTURES))
            p["coats"] = draw(st.one_of(st.sampled_from(_MIXTURE_COATS), st.floats(0.1, 8)))
    if draw(st.booleans()):
        doc["name"] = draw(st.sampled_from(_NAMES))
    return doc


# ---------------------------------------------------------------------------------------------------------------
# Measurement tables (CSV). Extend here: a new column is a key of TABLE_VALUES listed in TABLE_COLUMNS (or
# EXTRA_COLUMNS), a new kind of value one more strategy in its column's list.


def _number_text(lo: float, hi: float) -> st.SearchStrategy[str]:
    return st.one_of(
        st.floats(lo, hi).map(repr),
        st.integers(int(lo), int(hi)).map(str),
        st.sampled_from(SPECIAL_NUMBERS).map(str),
        st.sampled_from(["", " ", "nan", "inf", "-inf", "1e39", "1e400", "0x10", "1,5", "--1", "1e", "٣", "1_000"]),
    )


#: Strategies for the text of each column's cells.
TABLE_VALUES: dict[str, list[st.SearchStrategy[str]]] = {
    "pigment": [st.sampled_from(["paper", "black", "Paper", "Cobalt Blue", "cobalt blue", "Rose", "", " "]),
                st.text(max_size=10)],  # fmt: skip
    "amount": [_number_text(0, 2)],
    "ground": [st.sampled_from(["paper", "black", "Black ", "white", ""])],
    "r": [_number_text(0, 255)],
    "g": [_number_text(0, 255)],
    "b": [_number_text(0, 1)],
}
#: The columns a table has (in a drawn order, some left out now and then), and others it may have.
TABLE_COLUMNS = ("pigment", "amount", "ground", "r", "g", "b")
EXTRA_COLUMNS = ("note", "R", " amount ")


@st.composite
def mixture_table_files(draw: Any) -> bytes:
    """Tables in the spectral/mixture format: band columns (or r, g, b), mixture rows, amounts per paint."""
    bands = draw(st.sampled_from([[str(w) for w in range(380, 790, 10)], [str(w) for w in range(400, 710, 50)],
                                  ["380", "380", "390"], ["700", "400"], ["r", "g", "b"], ["nm", "x"]]))  # fmt: skip
    rows = [["pigment", "amount", "ground", *bands]]
    if draw(st.booleans()):
        rows.append(["paper", "0", "paper", *["0.85"] * len(bands)])
    value = st.one_of(_number_text(0, 1.05), st.sampled_from(["nan", "-0.1", "", "1e400", "inf"]))
    for _ in range(draw(st.integers(0, 6))):
        n = draw(st.integers(1, 3))
        names = [draw(st.sampled_from(["P1", "P2", "P13", "paper", "", "p1"])) for _ in range(n)]
        amounts = [draw(st.sampled_from(["0.01", "0.02", "0", "-0.01", "nan", "x", ""])) for _ in range(draw(st.integers(1, 3)))]
        row = ["+".join(names), "+".join(amounts), draw(st.sampled_from(["paper", "black", ""]))]
        row += [draw(value) for _ in range(len(bands) - draw(st.integers(0, 1)))]
        rows.append(row)
    out = io.StringIO()
    csv.writer(out, lineterminator="\n").writerows(rows)
    return draw(mutated_bytes(out.getvalue().encode()))


@st.composite
def table_files(draw: Any) -> bytes:
    columns = list(draw(st.permutations(TABLE_COLUMNS)))
    if draw(st.integers(0, 9)) == 0:
        columns.remove(draw(st.sampled_from(columns)))
    columns += draw(st.lists(st.sampled_from(EXTRA_COLUMNS), max_size=2))
    rows = [columns]
    good = [["paper", "0", "paper", "240", "240", "235"], ["black", "0", "black", "20", "20", "22"]]
    for _ in range(draw(st.integers(0, 8))):
        if draw(st.booleans()) and good:
            fields = dict(zip(TABLE_COLUMNS, good.pop(0)))
        else:
            fields = {c: draw(st.one_of(*TABLE_VALUES[c])) for c in TABLE_COLUMNS}
        row = [fields.get(c, draw(st.text(max_size=5))) for c in columns]
        cut = draw(st.integers(0, 12))
        rows.append(row[:cut] if cut < len(row) else row)
    out = io.StringIO()
    csv.writer(out, lineterminator=draw(st.sampled_from(["\n", "\r\n", "\r"]))).writerows(rows)
    data = (b"\xef\xbb\xbf" if draw(st.booleans()) else b"") + out.getvalue().encode()
    return draw(mutated_bytes(data))


# ---------------------------------------------------------------------------------------------------------------
# Images: small PNGs and JPEGs of every mode, then damaged, or with headers that lie about their size.


def _lie_about_size(data: bytes, width: int, height: int, fix_crc: bool) -> bytes:
    """Rewrite the size in a PNG's IHDR or a JPEG's SOF header."""
    if data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) >= 33:
        ihdr = struct.pack(">II", width, height) + data[24:29]
        crc = struct.pack(">I", zlib.crc32(b"IHDR" + ihdr) & 0xFFFFFFFF) if fix_crc else data[29:33]
        return data[:16] + ihdr + crc + data[33:]
    i = data.find(b"\xff\xc0")
    if i >= 0 and len(data) >= i + 9:
        return data[: i + 5] + struct.pack(">HH", min(height, 65535), min(width, 65535)) + data[i + 9 :]
    return data


@st.composite
def image_files(draw: Any) -> tuple[bytes, str]:
    from PIL import Image

    w, h = draw(st.integers(1, 24)), draw(st.integers(1, 24))
    mode = draw(st.sampled_from(["RGB", "RGBA", "L", "LA", "P", "1", "I;16", "CMYK", "RGB16"]))
    fmt = "JPEG" if mode == "CMYK" else draw(st.sampled_from(["PNG", "JPEG"])) if mode in ("RGB", "L") else "PNG"
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    buf = io.BytesIO()
    if mode == "RGB16":
        import png

        png.Writer(w, h, greyscale=False, bitdepth=16).write(buf, rng.integers(0, 65536, (h, w * 3), dtype=np.uint16))
    else:
        base = Image.fromarray(rng.integers(0, 256, (h, w, 4), dtype=np.uint8), "RGBA")
        im = base.convert(mode) if mode != "I;16" else Image.fromarray(rng.integers(0, 65536, (h, w), dtype=np.uint16))
        extra: dict[str, Any] = {}
        if draw(st.booleans()):
            exif = Image.Exif()
            exif[0x0112] = draw(st.sampled_from([1, 3, 6, 8, 0, 9, 65535]))
            extra["exif"] = exif
        im.save(buf, format=fmt, **extra)
    data = buf.getvalue()
    if draw(st.integers(0, 4)) == 0:
        side = st.sampled_from([0, 1, 8193, 30000, 65535, 2**31 - 1, 2**32 - 1])
        data = _lie_about_size(data, draw(side), draw(side), draw(st.booleans()))
    data = draw(mutated_bytes(data))
    suffix = {"PNG": ".png", "JPEG": ".jpg"}[fmt] if draw(st.integers(0, 9)) else draw(st.sampled_from([".png", ".jpg", ".tif", ""]))
    return data, suffix


# ---------------------------------------------------------------------------------------------------------------
# Meshes: valid meshes exported by trimesh, hand-written text formats with lying counts, then damaged.

_coordinate = st.one_of(st.floats(-2, 2), st.sampled_from([float(x) for x in SPECIAL_NUMBERS if not (isinstance(x, int) and x.bit_length() > 1000)]))


@st.composite
def _mesh_arrays(draw: Any) -> tuple[np.ndarray, np.ndarray]:
    n = draw(st.integers(3, 12))
    special = draw(st.integers(0, 5)) == 0
    coord = _coordinate if special else st.floats(-2, 2)
    v = np.array([[draw(coord) for _ in range(3)] for _ in range(n)], np.float64)
    f = np.array([[draw(st.integers(0, n - 1)) for _ in range(3)] for _ in range(draw(st.integers(1, 12)))])
    return v, f


def _text_mesh(kind: str, v: np.ndarray, f: np.ndarray, draw: Any) -> bytes:
    lie = draw(st.sampled_from([0, 0, 0, 1, -1, 10**9]))
    big = draw(st.sampled_from([0, 0, 0, 1, -1, 10**9]))  # face indices off the end
    if kind == "obj":
        lines = [f"v {x!r} {y!r} {z!r}" for x, y, z in v] + [f"f {a + 1 + big} {b + 1} {c + 1}" for a, b, c in f]
        return ("\n".join(lines) + "\n").encode()
    if kind == "off":
        lines = ["OFF", f"{len(v) + lie} {len(f)} 0"] + [f"{x!r} {y!r} {z!r}" for x, y, z in v]
        return ("\n".join(lines + [f"3 {a + big} {b} {c}" for a, b, c in f]) + "\n").encode()
    head = (f"ply\nformat ascii 1.0\nelement vertex {len(v) + lie}\nproperty float x\nproperty float y\n"
            f"property float z\nelement face {len(f)}\nproperty list uchar int vertex_indices\nend_header\n")  # fmt: skip
    body = [f"{x!r} {y!r} {z!r}" for x, y, z in v] + [f"3 {a + big} {b} {c}" for a, b, c in f]
    return (head + "\n".join(body) + "\n").encode()


@st.composite
def mesh_files(draw: Any) -> tuple[bytes, str]:
    import trimesh

    v, f = draw(_mesh_arrays())
    kind = draw(st.sampled_from(["ply", "plyb", "obj", "stl", "stla", "glb", "off", "ply-text", "obj-text"]))
    if kind.endswith("-text") or kind == "off":
        data, suffix = _text_mesh(kind.split("-")[0], v, f, draw), "." + kind.split("-")[0]
    else:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            mesh = trimesh.Trimesh(np.nan_to_num(v, posinf=1e30, neginf=-1e30), f, process=False)
            file_type = {"plyb": "ply", "stla": "stl_ascii"}.get(kind, kind)
            extra = {"encoding": "ascii"} if kind == "ply" else {}
            data = mesh.export(file_type=file_type, **extra)
        data = data.encode() if isinstance(data, str) else data
        suffix = "." + {"plyb": "ply", "stla": "stl"}.get(kind, kind)
    return draw(mutated_bytes(data)), suffix


# ---------------------------------------------------------------------------------------------------------------
# The readers, and running one input.


@dataclass(frozen=True)
class Reader:
    """A file reader under test: what its files look like (bytes, or bytes and a suffix) and how it reads them."""

    name: str
    files: st.SearchStrategy[Any]
    read: Callable[[Path, Any], Any]  # (path, a drawn option) -> anything
    suffix: str = ""
    options: st.SearchStrategy[Any] = st.none()


def _load_pigment(path: Path, name: Any) -> Any:
    return diffwash.pigments.load(path, name=name)


READERS: dict[str, Reader] = {
    r.name: r
    for r in (
        Reader("scene", json_file(st.one_of(scene_docs(), scene_docs(),
                                            declared_docs("_scene_schema:SceneFile").map(_with_mesh))),
               lambda p, o: diffwash.load_scene(p), ".json"),  # fmt: skip
        Reader("layout", json_file(st.one_of(layout_docs(), declared_docs("_schema:LayoutFile"))),
               lambda p, size: diffwash.fit.read_layout(p, size=size), ".json",
               st.sampled_from([None, (64, 48), (1, 1)])),  # fmt: skip
        Reader("pigment", json_file(st.one_of(pigment_docs(), library_docs, declared_docs("_schema:PigmentRecord"))),
               _load_pigment, ".json", st.sampled_from([None, "Rose", "cadmium red"])),  # fmt: skip
        Reader("library", json_file(st.one_of(library_docs, declared_docs("_schema:PigmentFile"))),
               lambda p, o: diffwash.pigments.library(p), ".json"),  # fmt: skip
        Reader("mixable", json_file(st.one_of(mixable_library_docs(), declared_docs("_schema:LibraryFile"))),
               _load_mixable, ".json", st.sampled_from([0.0, 1e-30, 0.05, 1.0, 1e30, 3e38])),  # fmt: skip
        Reader("table", table_files(), lambda p, linear: diffwash.fit.read_table(p, linear=linear), ".csv",
               st.booleans()),  # fmt: skip
        Reader("measurements", mixture_table_files(),
               lambda p, queries: (diffwash.measurements.read_queries if queries else diffwash.measurements.read_measurements)(p),
               ".csv", st.booleans()),  # fmt: skip
        Reader("image", image_files(), lambda p, loose: read_image(p, colour=not loose, opaque=not loose), "",
               st.booleans()),  # fmt: skip
        Reader("mesh", mesh_files(), lambda p, o: diffwash.load_mesh(p)),
    )
}


class Hang(BaseException):
    """Raised by the alarm when one input runs past its time limit (a BaseException: no `except Exception`
    in a reader swallows it)."""


@contextlib.contextmanager
def time_limit(seconds: float):
    def ring(signum: int, frame: Any) -> None:
        raise Hang()

    old = signal.signal(signal.SIGALRM, ring)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)


@dataclass
class Outcome:
    """What one input did: `"ok"` (loaded or refused with `DiffwashError`), `"crash"` or `"hang"`."""

    kind: str
    detail: str = ""

    @property
    def ok(self) -> bool:
        return self.kind == "ok"


def run_one(reader: Reader, drawn: Any, option: Any, folder: Path, limit: float = 10.0) -> Outcome:
    """Write one generated file into `folder` and read it with `reader`, warnings counted as crashes."""
    data, suffix = drawn if isinstance(drawn, tuple) else (drawn, reader.suffix)
    path = folder / f"input{suffix}"
    path.write_bytes(data)
    printed = io.StringIO()  # what a reader (or a library under it, e.g. through logging) prints
    try:
        with warnings.catch_warnings(), time_limit(limit), contextlib.redirect_stderr(printed), \
                contextlib.redirect_stdout(printed):  # fmt: skip
            warnings.simplefilter("error")
            reader.read(path, option)
    except DiffwashError as e:
        if "\n" in str(e):
            return Outcome("crash", f"DiffwashError of more than one line: {str(e)!r}")
    except Hang:
        return Outcome("hang", f"ran past {limit:g} s")
    except BaseException as e:  # anything else is a crash: what the user would see as a traceback
        if isinstance(e, KeyboardInterrupt):
            raise
        return Outcome("crash", "".join(traceback.format_exception(e, limit=-4)))
    if printed.getvalue():
        return Outcome("crash", f"printed to the terminal:\n{printed.getvalue()[-2000:]}")
    return Outcome("ok")


@dataclass
class Tally:
    """A reader's counts, and the first input of each kind of crash."""

    inputs: int = 0
    crashes: int = 0
    hangs: int = 0
    seconds: float = 0.0
    examples: dict[str, tuple[bytes, str]] = field(default_factory=dict)


def _signature(detail: str) -> str:
    lines = [ln for ln in detail.strip().splitlines() if ln.strip()]
    where = [ln.strip() for ln in lines if ln.strip().startswith("File ")]
    return (where[-1] if where else "") + " | " + (lines[-1].split(":")[0] if lines else "")


def fuzz(reader: Reader, n: int, folder: Path, *, seed_value: int = 0, limit: float = 10.0) -> Tally:
    """Run `n` generated inputs through `reader`; never stops at a crash (they are counted and kept)."""
    tally = Tally()
    first = [True]  # the first input pays for the reader's lazy imports (JAX, colour: seconds on a busy machine)

    @seed(seed_value)
    @settings(max_examples=n, deadline=None, database=None, phases=[Phase.generate],
              suppress_health_check=list(HealthCheck))  # fmt: skip
    @given(drawn=reader.files, option=reader.options)
    def one(drawn: Any, option: Any) -> None:
        out = run_one(reader, drawn, option, folder, max(limit, 300.0) if first[0] else limit)
        first[0] = False
        tally.inputs += 1
        if out.kind == "crash":
            tally.crashes += 1
        elif out.kind == "hang":
            tally.hangs += 1
        if not out.ok:
            data = drawn if isinstance(drawn, bytes) else drawn[0]
            tally.examples.setdefault(_signature(out.detail) or out.kind, (data, out.detail))

    start = time.perf_counter()
    while tally.inputs < n:  # hypothesis may stop a run early; go on with another seed until n inputs ran
        before = tally.inputs
        one()
        seed_value += 1
        one = seed(seed_value)(one)
        if tally.inputs == before:
            break
    tally.seconds = time.perf_counter() - start
    return tally


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("-n", "--inputs", type=int, default=100_000, help="inputs in total (default: %(default)s)")
    parser.add_argument("--reader", action="append", choices=list(READERS), help="fuzz only these readers")
    parser.add_argument("--seed", type=int, default=0, help="random seed (default: %(default)s)")
    parser.add_argument("--limit", type=float, default=10.0, help="seconds one input may take (default: %(default)s)")
    parser.add_argument("--save", metavar="DIR", help="write the first input of each kind of crash here")
    args = parser.parse_args(argv)
    names = args.reader or list(READERS)
    per = math.ceil(args.inputs / len(names))
    print(f"{'reader':<8} {'inputs':>8} {'crashes':>8} {'hangs':>6} {'seconds':>8}", flush=True)
    total = Tally()
    bad: dict[str, tuple[bytes, str]] = {}
    with tempfile.TemporaryDirectory(prefix="diffwash-fuzz-") as tmp:
        folder = Path(tmp)
        prepare(folder)
        for name in names:
            t = fuzz(READERS[name], per, folder, seed_value=args.seed, limit=args.limit)
            print(f"{name:<8} {t.inputs:>8} {t.crashes:>8} {t.hangs:>6} {t.seconds:>8.1f}", flush=True)
            total.inputs += t.inputs
            total.crashes += t.crashes
            total.hangs += t.hangs
            total.seconds += t.seconds
            bad.update({f"{name}: {k}": v for k, v in t.examples.items()})
    print(f"{'total':<8} {total.inputs:>8} {total.crashes:>8} {total.hangs:>6} {total.seconds:>8.1f}")
    for i, (sig, (data, detail)) in enumerate(bad.items()):
        print(f"\n--- {sig}\n{detail.strip()}\ninput ({len(data)} bytes): {data[:200]!r}")
        if args.save:
            Path(args.save).mkdir(parents=True, exist_ok=True)
            (Path(args.save) / f"crash-{i}.bin").write_bytes(data)
    return 1 if total.crashes or total.hangs else 0


if __name__ == "__main__":
    sys.exit(main())
