"""File formats declared once (pydantic v2): the checks, the located one-line errors and the docs' format tables.

A file kind is a pydantic model: its fields' types, ranges, defaults and
descriptions are the format. `validate(Model, data, file)` checks parsed JSON
against it before anything is computed and turns the first problem into a
`DiffwashError` naming the file and the key (`lib.json: pigments[1].K[3]: must
be >= 0, got -0.5`); `format_table(Model)` writes the Markdown table the docs
show, so the docs and the checks cannot drift apart (a test holds them equal).

Numbers are strict: a JSON number, never a bool or a numeric string, finite in
float32 (the precision diffwash computes in). Coefficients have headroom below
float32's largest value (`COEFFICIENT_MAX`), so that the products the
Kubelka-Munk maths forms of them stay finite.
"""

from __future__ import annotations

import difflib
import json
import os
import re
import types
import typing
from typing import Annotated, Any, Literal

import annotated_types as at
import pydantic
import pydantic.fields
from pydantic import AfterValidator, BaseModel, ConfigDict, Field

from ._errors import DiffwashError
from ._io import FLOAT32_MAX

__all__ = ["validate", "validate_rows", "format_table", "LibraryFile", "PigmentFile", "PigmentRecord", "LayoutFile", "MeasurementRow", "QueryRow",
           "COEFFICIENT_MAX", "GAMMA_MAX", "WEIGHT_RANGE", "name_key", "Shaped", "Vec3", "Flag"]

#: The largest K or S (per unit thickness) a file may hold: products of two stay far inside float32.
COEFFICIENT_MAX = 1e12
#: The largest amount-law exponent accepted (thickness = (amount / reference)^gamma).
GAMMA_MAX = 10.0
#: The range of a mixing weight (only ratios matter; a fit keeps their geometric mean at 1).
WEIGHT_RANGE = (1e-6, 1e6)
#: Reflectance above this is not a reflectance (a table in percent).
REFLECTANCE_MAX = 2.0
#: The smallest positive normal float32: a reference amount or weight below it is lost in float32.
FLOAT32_TINY = float.fromhex("0x1p-126")


def _float32(v: float) -> float:
    if not abs(v) <= FLOAT32_MAX:
        raise ValueError(f"{v:g} is out of float32 range (magnitude at most {FLOAT32_MAX:.4g}), which diffwash computes in")
    return v


#: A finite JSON number (ints taken as numbers; bools, strings, NaN and infinity refused) that float32 holds.
Number = Annotated[float, pydantic.Strict(), pydantic.AllowInfNan(False), AfterValidator(_float32)]
Coefficient = Annotated[Number, Field(ge=0, le=COEFFICIENT_MAX)]
Reflectance = Annotated[Number, Field(ge=0, le=REFLECTANCE_MAX)]
Text = Annotated[str, pydantic.Strict(), Field(min_length=1)]


def name_key(name: str) -> str:
    """A name as compared: case and runs of spaces ignored (`"Cadmium  red "` is `"cadmium red"`)."""
    return " ".join(name.casefold().split())


class _Part(BaseModel):
    """An object of a file: unknown keys are refused (a typo must not be silently ignored), naming a close key."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    @pydantic.model_validator(mode="before")
    @classmethod
    def _known_keys(cls, data: Any) -> Any:
        if isinstance(data, dict):
            for k in data:
                if k not in cls.model_fields:
                    close = difflib.get_close_matches(str(k), list(cls.model_fields), n=1)
                    hint = f"did you mean {close[0]!r}?" if close else f"one of {', '.join(cls.model_fields)}"
                    raise _Located(f"unknown key; {hint}", (k,))
        return data


#: Pydantic's errors about the form of a value (its JSON type, its length), as against its range.
_SHAPE = {"missing", "too_short", "too_long", "finite_number", "literal_error", "union_tag_invalid",
          "union_tag_not_found"}  # fmt: skip


def _is_shape(err: dict) -> bool:
    return err["type"] in _SHAPE or err["type"].endswith(("_type", "_parsing"))


def _shown(v: Any) -> str:
    shown = repr(v)
    return shown if len(shown) <= 60 else shown[:57] + "..."


def _relocated(err: dict, skip: int = 0) -> "_Located":
    """Pydantic's error `err` as a `_Located` (its message, its key path less the first `skip` parts)."""
    inner = (err.get("ctx") or {}).get("error")
    loc = tuple(err["loc"][skip:])
    if isinstance(inner, _Located):
        return _Located(str(inner), loc + inner.loc)
    return _Located(_message(err), loc)


def Shaped(message: str, *, union: bool = False) -> Any:
    """Annotation: a value of the wrong form (JSON type, length; for a `union`, no member's form) is refused with
    `message` as a whole, while a problem inside a value of the right form names its own key and range."""

    def wrap(v: Any, handler: Any) -> Any:
        try:
            return handler(v)
        except pydantic.ValidationError as e:
            errors = e.errors(include_url=False)
            skip = 1 if union else 0  # a union's errors start with the member's tag
            inner = [x for x in errors if len(x["loc"]) > skip]
            if inner:
                raise _relocated(inner[0], skip) from None
            real = [x for x in errors if not _is_shape(x)]
            if real:
                raise _relocated(real[0], len(real[0]["loc"])) from None
            raise ValueError(f"{message}, got {_shown(v)}") from None

    return pydantic.WrapValidator(wrap)


def _nonzero(v: list) -> list:
    if not any(v):
        raise ValueError(f"must be a non-zero vector, got {v!r}")
    return v


#: A point or direction: a list of 3 finite numbers.
Vec3 = Annotated[list[Number], Field(min_length=3, max_length=3), Shaped("must be a list of 3 finite numbers")]
#: A non-zero direction.
Direction = Annotated[Vec3, AfterValidator(_nonzero)]
#: A JSON true or false (no 0 or 1).
Flag = Annotated[bool, pydantic.Strict()]
#: A whole JSON number (no 1.0, no bool).
Whole = Annotated[int, pydantic.Strict()]


def _not_blank(v: str) -> str:
    if not v.strip():
        raise ValueError("must not be blank")
    return v


#: Text with a non-space character.
Name = Annotated[Text, AfterValidator(_not_blank)]


#: Three non-negative numbers, one per linear sRGB channel.
Channels = Annotated[list[Coefficient], Field(min_length=3, max_length=3),
                     Shaped("must be a list of 3 numbers (red, green, blue)")]  # fmt: skip


class PigmentRecord(BaseModel):
    """One pigment of a pigment file (per linear sRGB channel; keys other than these are ignored)."""

    model_config = ConfigDict(extra="ignore", frozen=True)

    name: Name = Field(description="matched ignoring case and runs of spaces; two names of one file that match so "
                                   "are refused")  # fmt: skip
    K: Channels = Field(description="absorption per unit thickness (one coat = thickness 1): red, green, blue")
    S: Channels = Field(description="scattering per unit thickness: red, green, blue")
    density: Annotated[Number, Field(ge=0)] = Field(0.05, description="Curtis's pigment density: how much the "
                                                   "watercolour look's `paper.density` thickens the layer")  # fmt: skip
    staining: Annotated[Number, Field(ge=0)] = Field(1.0, description="Curtis's staining power: how firmly the "
                                                     "pigment stays on the paper's peaks (the look's granulation)")  # fmt: skip
    granularity: Annotated[Number, Field(ge=0)] = Field(0.5, description="Curtis's granularity: how much it settles "
                                                        "in the paper's valleys (the look's granulation)")  # fmt: skip


class PigmentFile(BaseModel):
    """A pigment file of several pigments (one pigment alone may also be a file: a `PigmentRecord` object)."""

    model_config = ConfigDict(extra="ignore", frozen=True)

    pigments: list[PigmentRecord] = Field(min_length=1, description="the pigments (`PigmentRecord`, above)")


class AmountLaw(_Part):
    """A pigment's law from an amount of paint to its layer's thickness, `t = (amount / reference)^gamma`."""

    kind: Literal["power"] = Field("power", description="the law's form; only `power`")
    reference: Annotated[Number, Field(gt=0, ge=FLOAT32_TINY)] = Field(
        0.05, description="the amount of thickness 1 (the table's unit: mL on the sample's area, or coats)")
    gamma: Annotated[Number, Field(gt=0, le=GAMMA_MAX)] = Field(
        1.0, description="the exponent: 1 is thickness proportional to amount")


class Pigment(BaseModel):
    """One pigment of a library (keys other than these are kept for other tools and ignored)."""

    model_config = ConfigDict(extra="ignore", frozen=True)

    name: Text = Field(description="unique ignoring case and spaces; no `+` or `/` (they join a mixture's names "
                                   "and a stack's layers)")
    K: list[Coefficient] = Field(description="absorption per unit thickness, one per band")
    S: list[Coefficient] = Field(description="scattering per unit thickness, one per band")
    amount_law: AmountLaw = Field(default_factory=AmountLaw, description="`{kind, reference, gamma}` (below)")
    mixing_weight: Annotated[Number, Field(ge=WEIGHT_RANGE[0], le=WEIGHT_RANGE[1])] = Field(
        1.0, description="how much the pigment counts in a mixture (1: Duncan's volume fraction)")

    @pydantic.field_validator("name")
    @classmethod
    def _no_plus(cls, v: str) -> str:
        if not v.strip():
            raise ValueError("must not be blank")
        for c, what in (("+", "the names of a mixture"), ("/", "the layers of a glaze stack")):
            if c in v:
                raise ValueError(f"must not hold '{c}' (it joins {what}), got {v!r}")
        return v


class Observation(_Part):
    """How the library's reflectance is seen: a band grid with its light and observer, or the sRGB channels."""

    bands: Literal["sRGB"] | None = Field(None, description="`\"sRGB\"` for pigments per linear sRGB channel")
    wavelengths: list[Number] | None = Field(None, description="the band centres in nm, increasing")
    illuminant: Text = Field("D65", description="colour-science's name of the light")
    observer: Text = Field("CIE 1931 2 Degree Standard Observer", description="colour-science's colour-matching "
                           "functions")  # fmt: skip
    method: Text | None = Field(None, description="`ASTM E308` or `Integration` (default: ASTM E308 where it applies)")


class Surface(_Part):
    """The surface term."""

    k2: Annotated[Number, Field(ge=0, lt=1)] = Field(0.0, description="Saunderson's internal surface reflectance")


#: The most a pair term may say, in magnitude: a bump is a log factor on K or S (e^10: 22,000 times), an amount
#: term one per e-fold of the layer's amount (fitted ones are below 1.5 and 0.3).
PAIR_BUMP_MAX, PAIR_AMOUNT_MAX = 10.0, 2.0


class PairBasis(_Part):
    """The Gaussian bumps the pair terms are made of."""

    centres: list[Number] = Field(min_length=1, description="the bumps' centres, nm")
    width: Annotated[Number, Field(gt=0)] = Field(description="the bumps' width, nm")


class PairTerm(_Part):
    """The terms of one pair of pigments measured mixed."""

    pigments: list[Text] = Field(min_length=2, max_length=2, description="the pair: two of the library's pigments")
    K_bumps: list[Annotated[Number, Field(ge=-PAIR_BUMP_MAX, le=PAIR_BUMP_MAX)]] = Field(
        description="the log factor on K per bump, one per centre")
    S_bumps: list[Annotated[Number, Field(ge=-PAIR_BUMP_MAX, le=PAIR_BUMP_MAX)]] = Field(
        description="the log factor on S per bump, one per centre")
    K_amount: Annotated[Number, Field(ge=-PAIR_AMOUNT_MAX, le=PAIR_AMOUNT_MAX)] = Field(
        0.0, description="the log factor on K per e-fold of the amount")
    S_amount: Annotated[Number, Field(ge=-PAIR_AMOUNT_MAX, le=PAIR_AMOUNT_MAX)] = Field(
        0.0, description="the log factor on S per e-fold of the amount")
    inferred: bool = Field(False, description="true: the pair was never measured mixed; its terms were inferred "
                           "from what its two pigments did in their measured pairs (docs/mixing.md)")


class PairTerms(_Part):
    """A library's `"pair_terms"` (docs/mixing.md)."""

    basis: PairBasis = Field(description="`{centres, width}`")
    pairs: list[PairTerm] = Field(description="one per pair measured mixed, and one per pair whose terms were inferred")


class LibraryFile(BaseModel):
    """A mixable library (`diffwash fit-swatch --table` writes it; `diffwash predict` reads it)."""

    model_config = ConfigDict(extra="ignore", frozen=True)

    format: Literal["diffwash-library"] = Field(description="`diffwash-library`")
    version: Literal[1] = Field(1, description="1")
    observation: Observation = Field(description="the band grid and how it is seen (below)")
    pigments: list[Pigment] = Field(min_length=1, description="the pigments (below), at least one")
    grounds: dict[str, list[Reflectance]] = Field(min_length=1, description="ground name -> reflectance per band "
                                                  "(0..2), at least one")  # fmt: skip
    surface: Surface = Field(default_factory=Surface, description="`{\"k2\": ...}` (below)")
    pair_terms: PairTerms | None = Field(None, description="the pair terms of pairs measured mixed, and those "
                                         "inferred for pairs that were not (docs/mixing.md)")  # fmt: skip
    fit: dict[str, Any] | None = Field(None, description="the fit's record (not read back)")

    @pydantic.model_validator(mode="after")
    def _consistent(self) -> "LibraryFile":
        o = self.observation
        if (o.bands is None) == (o.wavelengths is None):
            raise _Located("needs either \"wavelengths\" or \"bands\": \"sRGB\"", ("observation",))
        n = 3 if o.bands else len(o.wavelengths)
        seen: dict[str, int] = {}
        for i, p in enumerate(self.pigments):
            for key in ("K", "S"):
                if len(getattr(p, key)) != n:
                    raise _Located(f"must be a list of {n} numbers (one per band), got {len(getattr(p, key))}",
                                   ("pigments", i, key))  # fmt: skip
            k = name_key(p.name)
            if k in seen:
                raise _Located(f"{p.name.strip()!r} and pigments[{seen[k]}].name {self.pigments[seen[k]].name!r} name "
                               f"the same pigment (names are compared ignoring case and spaces)", ("pigments", i, "name"))
            seen[k] = i
        grounds: dict[str, str] = {}
        for g, v in self.grounds.items():
            if len(v) != n:
                raise _Located(f"must be a list of {n} numbers (one per band), got {len(v)}", ("grounds", g))
            if not g.strip() or name_key(g) in grounds:
                raise _Located("names a ground twice (ignoring case and spaces)" if g.strip() else "a ground needs a "
                               "name", ("grounds", g))  # fmt: skip
            grounds[name_key(g)] = g
        return self


class _Located(ValueError):
    """A problem found across fields, with the key it belongs to."""

    def __init__(self, message: str, loc: tuple):
        super().__init__(message)
        self.loc = loc


def _where(loc: tuple) -> str:
    out = ""
    for part in loc:
        out += f"[{part}]" if isinstance(part, int) else (f".{part}" if out else str(part))
    return out


_TYPES = {"model_type": "must be an object {...}", "model_attributes_type": "must be an object {...}",
          "dict_type": "must be an object {...}", "list_type": "must be a list [...]",
          "tuple_type": "must be a list [...]", "float_type": "must be a number", "string_type": "must be text",
          "missing": "missing key", "extra_forbidden": "unknown key", "finite_number": "must be a finite number",
          "int_type": "must be a whole number", "bool_type": "must be true or false",
          "float_parsing": "not a number", "int_from_float": "must be a whole number"}  # fmt: skip


_BOUNDS = {"greater_than": (">", "gt"), "greater_than_equal": (">=", "ge"), "less_than": ("<", "lt"),
           "less_than_equal": ("<=", "le")}  # fmt: skip


def _message(err: dict) -> str:
    kind = err["type"]
    got = err.get("input")
    shown = _shown(got)
    if kind == "missing":
        return _TYPES[kind]
    if kind == "float_type" and isinstance(got, int) and not isinstance(got, bool):
        return f"{shown} is out of float32 range (magnitude at most {FLOAT32_MAX:.4g}), which diffwash computes in"
    if kind == "too_short":
        n = err["ctx"]["min_length"]
        return "must not be empty" if n == 1 else f"must have at least {n} items, got {err['ctx']['actual_length']}"
    if kind == "too_long":
        return f"must have at most {err['ctx']['max_length']} items, got {_shown(got)}"
    if kind == "literal_error":
        expected = err["ctx"]["expected"]
        names = re.findall(r"'([^']*)'", expected)
        return f"must be one of {', '.join(names) or expected}, got {shown}"
    if kind == "float_parsing":
        return f"not a number: {shown}"
    if kind == "string_too_short":
        return "must not be empty"
    if kind in _BOUNDS:  # a number given as text (a table's) is shown as written
        sign, key = _BOUNDS[kind]
        return f"must be {sign} {err['ctx'][key]:g}, got {got.strip() if isinstance(got, str) else shown}"
    if kind in _TYPES:
        return f"{_TYPES[kind]}, got {shown}"
    msg = err["msg"].removeprefix("Value error, ")
    msg = msg.replace("Input should be", "must be").replace("List should have", "must have")
    return msg if kind == "value_error" else f"{msg}, got {shown}"


def validate(model: type[BaseModel], data: Any, file: str | os.PathLike | None = None, *, what: str | None = None) -> Any:
    """`data` (parsed JSON) checked against `model`; the first problem is a `DiffwashError` naming `file` and key.

    `what` names the file kind for a file that is not a JSON object (`a scene must be a JSON object, got list`).
    """
    if what is not None and not isinstance(data, dict):
        raise DiffwashError(f"a {what} must be a JSON object, got {type(data).__name__}", file=file)
    try:
        return model.model_validate(data)
    except _Located as e:
        raise DiffwashError(str(e), file=file, field=_where(e.loc)) from None
    except pydantic.ValidationError as e:
        located = _relocated(e.errors(include_url=False)[0])
        raise DiffwashError(str(located), file=file, field=_where(located.loc) or None) from None


def validate_rows(adapter: pydantic.TypeAdapter, rows: list, file: Any, lines: list[int], columns: dict) -> list:
    """Rows of a table (dicts) checked at once against `adapter` (a `TypeAdapter` of a list of row models); the
    first problem is a `DiffwashError` naming `file`, the line (`lines[i]`) and the column (`columns[key]`: the
    header's name of a row model's key, or for a list-valued key the list of names of its items)."""
    try:
        return adapter.validate_python(rows)
    except pydantic.ValidationError as e:
        located = _relocated(e.errors(include_url=False)[0])
        i, key, *rest = located.loc
        column = columns.get(key, key)
        if not isinstance(column, str):
            column = column[rest[0]] if rest else ",".join(column)
        raise DiffwashError(str(located), file=file, field=f"line {lines[i]}: {column}") from None


def _type_name(t: Any) -> str:
    origin = typing.get_origin(t)
    args = typing.get_args(t)
    if origin is Annotated:
        return _type_name(args[0])
    if origin is Literal:
        return " or ".join(f"`{a!r}`".replace("'", '"') for a in args).replace("`False`", "`false`")
    if origin in (typing.Union, types.UnionType):
        return " or ".join(dict.fromkeys(_type_name(a) for a in args if a is not type(None)))
    if origin is list:
        return f"list of {_type_name(args[0])}"
    if origin is tuple:
        return f"list of {len(args)} {_type_name(args[0])}"
    if origin is dict:
        return "object"
    if isinstance(t, type) and issubclass(t, BaseModel):
        return f"`{t.__name__}` object"
    return {float: "number", str: "text", int: "whole number", bool: "`true` or `false`"}.get(
        t, "anything" if t is Any else getattr(t, "__name__", str(t)))


def _bounds(t: Any, metadata: list) -> str:
    items = list(metadata)
    while typing.get_origin(t) is Annotated:
        t, *more = typing.get_args(t)
        items += more
    if typing.get_origin(t) in (typing.Union, types.UnionType):
        return "; ".join(filter(None, dict.fromkeys(_bounds(a, []) for a in typing.get_args(t))))
    items = [x for m in items for x in (m.metadata if isinstance(m, pydantic.fields.FieldInfo) else [m])]
    out = []
    if typing.get_origin(t) is tuple:
        out += [f"[{i}] {b}" for i, a in enumerate(typing.get_args(t)) if (b := _bounds(a, []))]
    if typing.get_origin(t) is list:
        sizes = {type(m): m for m in items if isinstance(m, (at.MinLen, at.MaxLen))}
        lo, hi = sizes.get(at.MinLen), sizes.get(at.MaxLen)
        if lo and hi and lo.min_length == hi.max_length:
            out.append(f"{lo.min_length} items")
        elif lo and lo.min_length:
            out.append(f"at least {lo.min_length}")
        inner = _bounds(typing.get_args(t)[0], [])
        return ", ".join(out + ([f"each {inner}"] if inner else []))
    for m in items:
        for k in ("gt", "ge", "lt", "le"):
            v = getattr(m, k, None)
            if v is not None and isinstance(m, (at.Gt, at.Ge, at.Lt, at.Le)):
                if k == "ge" and v == FLOAT32_TINY:
                    continue
                sign = {"gt": ">", "ge": ">=", "lt": "<", "le": "<="}[k]
                out.append(f"{sign} {_bound(v)}")
        if isinstance(m, at.MinLen) and m.min_length:
            out.append("not empty" if t is str else f"at least {m.min_length}")
    return ", ".join(out)


def _bound(v: float) -> str:
    """A bound as the docs write it: a power of two above a million as `2^n` (a seed's `< 2^32`), else `%g`."""
    if isinstance(v, int) and v > 1e6 and v & (v - 1) == 0:
        return f"2^{v.bit_length() - 1}"
    return f"{v:g}"


def format_table(model: type[BaseModel]) -> str:
    """The Markdown table of `model`'s keys: key, type, range, default, meaning."""
    rows = ["| key | type | range | default | meaning |", "|---|---|---|---|---|"]
    for name, f in model.model_fields.items():
        default = "required" if f.is_required() else ("`{}`" if f.default_factory is not None or isinstance(
            f.default, BaseModel) else "none" if f.default is None else f"`{json.dumps(f.default)}`")  # fmt: skip
        bounds = _bounds(f.annotation, f.metadata) or "-"
        rows.append(f"| `{name}` | {_type_name(f.annotation)} | {bounds} | {default} | {f.description or ''} |")
    return "\n".join(rows)



# --- swatch-card layouts (diffwash.fit.parse_layout) ---------------------------------------------------------------


def _whole_pixel(v: float) -> float:
    if not float(v).is_integer():
        raise ValueError(f"must be a whole pixel coordinate, got {v!r}")
    return v


def _nonempty_box(v: list) -> list:
    if v[2] <= v[0] or v[3] <= v[1]:
        raise ValueError(f"is empty: needs x0 < x1 and y0 < y1, got {v!r}")
    return v


#: A pixel box `[x0, y0, x1, y1]` of the photo as displayed, `x0 < x1`, `y0 < y1`.
Box = Annotated[list[Annotated[Number, AfterValidator(_whole_pixel)]], Field(min_length=4, max_length=4),
                AfterValidator(_nonempty_box), Shaped("must be [x0, y0, x1, y1] (4 pixel coordinates)")]  # fmt: skip
_Fraction = Annotated[Number, Field(ge=0, le=1)]


class LayoutPaper(_Part):
    """The box of bare paper, which calibrates exposure and white balance."""

    box: Box = Field(description="`[x0, y0, x1, y1]`, whole pixels")
    reflectance: Annotated[list[Annotated[Number, Field(gt=0, le=1)]], Field(min_length=3, max_length=3),
                           Shaped("must be 3 linear reflectances (red, green, blue)")] | None = Field(
        None, description="the paper's linear RGB reflectance; by default diffwash's paper (0.92, 0.90, 0.84)")
    lab: Annotated[tuple[Annotated[Number, Field(gt=0, le=100)], Annotated[Number, Field(ge=-200, le=200)],
                         Annotated[Number, Field(ge=-200, le=200)]],
                   Shaped("must be [L, a, b] (CIELAB, D65)")] | None = Field(  # fmt: skip
        None, description="or its CIELAB (D65, CIE 1931 2-degree), as a spectrophotometer gives it")

    @pydantic.model_validator(mode="after")
    def _one_colour(self) -> "LayoutPaper":
        if self.reflectance is not None and self.lab is not None:
            raise _Located("give the paper's reflectance or its lab, not both", ("lab",))
        return self


class LayoutBlack(_Part):
    """The box of the bare black band (needed when a patch lies on black)."""

    box: Box = Field(description="`[x0, y0, x1, y1]`, whole pixels")


class LayoutPatch(_Part):
    """A painted patch."""

    box: Box = Field(description="`[x0, y0, x1, y1]`, whole pixels")
    coats: Annotated[Number | Text, Shaped("must be a number of coats > 0 ('+'-joined numbers for a mixture)",
                                           union=True)] = Field(  # fmt: skip
        description="the thickness in coats (> 0); for a `pigment` of several, `+`-joined numbers (>= 0) per "
        "pigment and `/`-joined groups per layer")
    ground: Literal["paper", "black"] = Field(description="what the paint lies on")
    pigment: Name | None = Field(None, description="the paint: a name, `+`-joined names (a mixture), `/`-joined "
                                 "layers (a glaze stack, bottom first); by default the card's pigment")  # fmt: skip


class LayoutReference(_Part):
    """A patch of known colour: exactly one of `lab`, `reflectance`, `spectrum` (with `wavelengths`)."""

    box: Box = Field(description="`[x0, y0, x1, y1]`, whole pixels")
    lab: Annotated[tuple[Annotated[Number, Field(ge=0, le=100)], Annotated[Number, Field(ge=-200, le=200)],
                         Annotated[Number, Field(ge=-200, le=200)]],
                   Shaped("must be [L, a, b] (CIELAB, D65)")] | None = Field(  # fmt: skip
        None, description="CIELAB (D65, CIE 1931 2-degree): L in [0, 100], a and b in [-200, 200]")
    reflectance: Annotated[list[_Fraction], Field(min_length=3, max_length=3),
                           Shaped("must be 3 linear sRGB reflectances (red, green, blue)")] | None = Field(
        None, description="linear sRGB reflectance")
    spectrum: Annotated[list[Annotated[Number, Field(ge=0, le=1.5)]], Field(min_length=1)] | None = Field(
        None, description="reflectance per wavelength")
    wavelengths: Annotated[list[Number], Field(min_length=1)] | None = Field(
        None, description="the spectrum's wavelengths in nm, increasing, spanning 400-700")

    @pydantic.model_validator(mode="after")
    def _one_colour(self) -> "LayoutReference":
        given = [k for k in ("lab", "reflectance", "spectrum") if getattr(self, k) is not None]
        if len(given) != 1:
            raise _Located("needs exactly one of lab, reflectance, spectrum (with wavelengths)", ())
        wl = self.wavelengths
        if wl is not None and given != ["spectrum"]:
            raise _Located("only goes with a spectrum", ("wavelengths",))
        if given == ["spectrum"]:
            if wl is None:
                raise _Located("missing key: a spectrum needs its wavelengths (nm)", ("wavelengths",))
            if len(self.spectrum) != len(wl):
                raise _Located(f"must be {len(wl)} reflectances, one per wavelength, got {len(self.spectrum)}",
                               ("spectrum",))  # fmt: skip
            if any(b <= a for a, b in zip(wl, wl[1:])) or wl[0] > 400 or wl[-1] < 700:
                raise _Located("must increase and span 400-700 nm", ("wavelengths",))
        return self


class LayoutFile(_Part):
    """A swatch-card layout (`diffwash fit-swatch --layout`): where things are in the photo, in pixels as displayed."""

    paper: LayoutPaper = Field(description="`{box, reflectance}` (below); a box of bare paper is needed to "
                               "calibrate exposure and white balance")  # fmt: skip
    black: LayoutBlack | None = Field(None, description="`{box}`: bare black, needed when a patch lies on black")
    patches: list[LayoutPatch] = Field(min_length=1, description="the painted patches (below), at least one")
    references: list[LayoutReference] = Field([], description="patches of known colour (below)")
    name: Name | None = Field(None, description="the card's pigment")
    meta: Any = Field(None, description="anything; ignored")


# --- measurement and query tables (diffwash.measurements) ----------------------------------------------------------

def plain_number_text(v: Any) -> Any:
    """`v`, unless it is text that Python's float() reads but a table's reader should not: digits grouped by
    `_` (`1_0` is not 10 in a CSV file, and no other program reads it so)."""
    if isinstance(v, str) and "_" in v:
        raise ValueError(f"not a number: {v.strip()!r}")
    return v


#: A table's number: CSV text such as `0.12` or `1e-3`, finite in float32.
#: (`measurements` refuses digits grouped by `_` before the rows are checked: `plain_number_text`, once per row.)
TableNumber = Annotated[float, pydantic.AllowInfNan(False), AfterValidator(_float32)]


class QueryRow(_Part):
    """A row of a query table (`diffwash predict`): the columns `pigment,amount,ground` (others are ignored)."""

    pigment: str = Field(description="a pigment's name, `+`-joined names (a mixture brushed as one layer) or "
                         "`/`-joined layers (a glaze stack, bottom first); names are compared ignoring case and "
                         "spaces")  # fmt: skip
    amount: str = Field(description="how much of each pigment (>= 0, any unit: mL on the sample's area, coats), "
                        "`+`-joined per pigment and `/`-joined per layer like `pigment`")  # fmt: skip
    ground: Name = Field(description="what the paint lies on: a ground that a row `NAME,0,NAME` measures")


class MeasurementRow(QueryRow):
    """A row of a measurement table: `pigment,amount,ground` and the measured values, one column per band."""

    values: list[Annotated[TableNumber, Field(ge=0)]] = Field(
        description="the columns named by wavelength in nm (`380,390,...`: reflectance, 0..1, a little above 1 "
        "from brighteners; above 2 refused), or `r,g,b` (display sRGB, 0-255 or 0-1 for the whole table)")


def row_adapter(model: type[BaseModel]) -> pydantic.TypeAdapter:
    """The checker of a table's rows of `model`, all at once (`validate_rows`)."""
    return pydantic.TypeAdapter(list[model])
