r"""Tables of measured paint, spectral or RGB, single pigments or mixtures.

A measurement table is a CSV file whose header starts `pigment,amount,ground`
and goes on with either

- band columns named by their wavelength in nm (`380,390,...,780`): reflectance
  on that grid (0..1; values a little above 1, from fluorescent brighteners,
  are data), or
- `r,g,b`: display sRGB, 8-bit (0-255) or 0-1 floats (the whole file on one
  scale, 0-1 when no value exceeds 1; mostly 0-1 fractions with a value above
  1 is refused as a typo). Values at the ends of the range are
  clipped by the gamut: bounds, not measurements.

```
pigment,amount,ground,380,390,...
paper,0,paper,0.83,0.81,...
P1,0.01,paper,0.12,0.10,...
P1+P3,0.01+0.02,paper,0.05,0.04,...
```

- `pigment`: a pigment's name, or several joined by `+` for a mixture brushed
  as one layer, or layers joined by `/` for a glaze stack, bottom first (`A/B`:
  B brushed over dry A; `A+B/C`: C over a mixed layer of A and B); a row
  `NAME,0,NAME` gives the colour of the ground `NAME` (averaged if repeated),
  e.g. `paper,0,paper` or `black,0,black`.
- `amount`: how much of each pigment (>= 0, any unit: mL on the sample's area,
  coats), as many `+`-joined numbers as there are pigments, layer by layer
  (`0.01+0.01/0.03` for `A+B/C`).
- `ground`: what the paint lies on, a ground that some row measures.

Other columns (neither a number nor `r`, `g`, `b`) are ignored. A *query* table
(`read_queries`) has just the first three columns (any others are ignored).

The single-pigment RGB tables of `diffwash.fit.read_table` are the special case
`r,g,b` with grounds `paper` and `black` (that reader fits them pigment by pigment).

Refused too, naming the line: amounts more than `AMOUNT_SPAN` times the
table's median amount (or less than its reciprocal), numbers float32 cannot
hold, and pigment names that differ only in case or spacing.

A measurement table is fitted jointly, all its rows at once, in memory and time that grow with its rows: one of
more than `MAX_TABLE_ROWS` rows is refused, naming the limit, as soon as its reader passes it (before any number is
parsed); `$DIFFWASH_MAX_TABLE_ROWS` (or `read_measurements(..., max_rows=N)`) raises it.

Every error names the file, the line and the column in one line.
"""

from __future__ import annotations

import csv
import math
import os
import re
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from . import _schema, colorimetry, spectral
from ._errors import DiffwashError
from ._io import check_float32, env_limit, open_input

__all__ = [
    "Measurements", "Queries", "read_measurements", "read_queries", "parse_mixture", "parse_stack", "format_stack",
    "split_layers", "refuse_colliding_names", "refuse_absurd_amounts", "max_table_rows", "too_many_rows",
]  # fmt: skip

#: Reflectance above this is taken for a table in percent, not a brightener's glow.
MAX_REFLECTANCE = 2.0
#: The most rows of measurements a table may have by default (`$DIFFWASH_MAX_TABLE_ROWS` raises it): the joint fit
#: holds every row's residuals and derivatives at once; NTU's spectral table (1,859 rows, 41 bands) peaks at 1.6 GB
#: and takes 2-5 minutes on 2 cores (docs/scaling.md), and a table this long about twice that.
MAX_TABLE_ROWS = 4000
ROWS_ENV = "DIFFWASH_MAX_TABLE_ROWS"
#: An amount more than this many times the table's median amount (or less than its reciprocal) is refused: a typo
#: (1e30 for 0.03) would dominate the fit's loss; real tables span well under a hundredfold.
AMOUNT_SPAN = 1e4


def _fail(msg: str, path: Any, line: int | None = None, column: str | None = None) -> DiffwashError:
    where = None if line is None else (f"line {line}" + (f": {column}" if column else ""))
    if line is None and column is not None:
        where = column
    return DiffwashError(msg, file=path, field=where)


class _Rows:
    """What tables and queries share: rows of pigments and amounts, each row one or more layers (`layers`: the
    pigments per layer, bottom first, or None where every row is one layer)."""

    @property
    def is_stack(self) -> np.ndarray:
        """Rows of more than one layer (glaze stacks), shape (N,)."""
        return _is_stack(self)

    def row_layers(self, i: int) -> list[tuple[tuple[str, ...], tuple[float, ...]]]:
        """Row `i`'s layers, bottom first: `[(names, amounts), ...]`."""
        return split_layers(self.pigments[i], self.amounts[i], None if self.layers is None else self.layers[i])

    def row_text(self, i: int) -> tuple[str, str]:
        """Row `i`'s pigment and amount as a table writes them (`A+B/C`, `0.01+0.01/0.03`)."""
        return format_stack(self.row_layers(i))


@dataclass(frozen=True)
class Measurements(_Rows):
    """Measured reflectance of paint layers, one row per sample.

    **Fields:**

    - `pigments`: the pigments of each row, a tuple of names (one for a single
      paint, several for a mixture; repeats kept as written), length N.
    - `amounts`: the amount of each of them, tuples parallel to `pigments`.
    - `ground`: the ground's name on each row, shape (N,).
    - `values`: measured reflectance per band (linear sRGB for an RGB table),
      shape (N, B).
    - `lo`, `hi`: values clipped at the bottom / top of the range (RGB tables;
      all False for spectra), shape (N, B).
    - `grounds`: each ground's reflectance, name -> shape (B,).
    - `wavelengths`: the band grid in nm, or None for an RGB table.
    - `path`, `lines`: the file and each row's line in it.
    - `layers`: for glaze stacks, each row's number of pigments per layer, bottom
      first (`(2, 1)` for `A+B/C`; `pigments` and `amounts` hold every layer's in
      that order); None: every row is one layer.
    """

    pigments: tuple[tuple[str, ...], ...]
    amounts: tuple[tuple[float, ...], ...]
    ground: np.ndarray
    values: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    grounds: dict[str, np.ndarray]
    wavelengths: tuple[float, ...] | None = None
    path: str | None = None
    lines: np.ndarray | None = field(default=None, repr=False)
    layers: tuple[tuple[int, ...], ...] | None = None

    def __len__(self) -> int:
        return len(self.pigments)

    @property
    def spectral(self) -> bool:
        return self.wavelengths is not None

    @property
    def names(self) -> list[str]:
        """The pigments in the order they first appear."""
        return list(dict.fromkeys(n for row in self.pigments for n in row))

    @property
    def is_mixture(self) -> np.ndarray:
        """Rows with a layer holding more than one distinct pigment, shape (N,)."""
        return _is_mixture(self)

    def observation(self, **kwargs: Any) -> spectral.Observation:
        """The `diffwash.spectral.Observation` of this table's bands (keywords: illuminant, observer, method)."""
        return spectral.observation(self.wavelengths, **kwargs)

    def select(self, mask: Any) -> "Measurements":
        """The rows where `mask` is True (grounds kept)."""
        m = np.asarray(mask, bool)
        ix = np.flatnonzero(m)
        return replace(self, pigments=tuple(self.pigments[i] for i in ix), amounts=tuple(self.amounts[i] for i in ix),
                       ground=self.ground[m], values=self.values[m], lo=self.lo[m], hi=self.hi[m],
                       lines=None if self.lines is None else self.lines[m],
                       layers=None if self.layers is None else tuple(self.layers[i] for i in ix))  # fmt: skip

    def _line(self, i: int) -> int:
        return int(self.lines[i]) if self.lines is not None else i + 2


@dataclass(frozen=True)
class Queries(_Rows):
    """Rows to predict: pigments, amounts and ground per row (as `Measurements`, without values)."""

    pigments: tuple[tuple[str, ...], ...]
    amounts: tuple[tuple[float, ...], ...]
    ground: np.ndarray
    path: str | None = None
    lines: np.ndarray | None = field(default=None, repr=False)
    layers: tuple[tuple[int, ...], ...] | None = None

    def __len__(self) -> int:
        return len(self.pigments)


def _is_stack(rows: Any) -> np.ndarray:
    if rows.layers is None:
        return np.zeros(len(rows.pigments), bool)
    return np.array([len(k) > 1 for k in rows.layers], bool)


def _is_mixture(rows: Any) -> np.ndarray:
    return np.array([any(len(set(n)) > 1 for n, _ in rows.row_layers(i)) for i in range(len(rows.pigments))], bool)


def split_layers(names: tuple[str, ...], amounts: tuple[float, ...], sizes: tuple[int, ...] | None
                 ) -> list[tuple[tuple[str, ...], tuple[float, ...]]]:  # fmt: skip
    """A row's flat `names` and `amounts` cut into layers of `sizes` pigments (None: one layer), bottom first."""
    sizes = (len(names),) if sizes is None else tuple(sizes)
    if sum(sizes) != len(names) or len(names) != len(amounts):
        raise ValueError(f"layer sizes {sizes} do not cover {len(names)} pigments and {len(amounts)} amounts")
    ends = np.cumsum((0, *sizes)).tolist()
    return [(tuple(names[a:b]), tuple(amounts[a:b])) for a, b in zip(ends[:-1], ends[1:])]


def format_stack(layers: list[tuple[tuple[str, ...], tuple[float, ...]]]) -> tuple[str, str]:
    """Layers `[(names, amounts), ...]` (bottom first) as a table's pigment and amount text: `+` within a
    layer, `/` between layers (`A+B/C`, `0.01+0.01/0.03`); the inverse of `parse_stack`."""
    return ("/".join("+".join(n) for n, _ in layers),
            "/".join("+".join(f"{a:g}" if float(a).is_integer() else repr(float(a)) for a in v) for _, v in layers))


def parse_stack(pigment: str, amount: str, *, path: Any = None, line: int | None = None
                ) -> tuple[tuple[str, ...], tuple[float, ...], tuple[int, ...]]:  # fmt: skip
    """Split a glaze stack `A+B/C`, `0.01+0.01/0.03` into its layers (bottom first), each by `parse_mixture`.

    **Returns:** `(names, amounts, sizes)`: every layer's names and amounts in order, and the number of
    pigments in each layer (`(2, 1)` here; `(n,)` for a row of one layer). Bad input (an empty layer, as
    many layers of pigments as of amounts, and `parse_mixture`'s rules per layer) raises a `DiffwashError`
    naming the file, the line and the column.
    """
    p_layers, a_layers = pigment.split("/"), amount.split("/")
    for text, parts, column in ((pigment, p_layers, "pigment"), (amount, a_layers, "amount")):
        if len(parts) > 1 and any(not t.strip() for t in parts):
            raise _fail(f"empty layer in {text.strip()!r} (layers are joined by '/', bottom first)", path, line,
                        column)  # fmt: skip
    if len(p_layers) != len(a_layers):
        np_, na = len(p_layers), len(a_layers)
        raise _fail(f"{np_} layer{'s' if np_ > 1 else ''} of pigments ({pigment.strip()}) but {na} layer"
                    f"{'s' if na > 1 else ''} of amounts ({amount.strip()}): give one '/'-separated amount per "
                    "layer", path, line, "amount")  # fmt: skip
    names, amounts, sizes = [], [], []
    for p, a in zip(p_layers, a_layers):
        n, v = parse_mixture(p, a, path=path, line=line)
        names += n
        amounts += v
        sizes.append(len(n))
    return tuple(names), tuple(amounts), tuple(sizes)


def parse_mixture(pigment: str, amount: str, *, path: Any = None, line: int | None = None) -> tuple[tuple[str, ...], tuple[float, ...]]:
    """Split `P1+P3` and `0.01+0.02` into names and amounts, checking both.

    **Returns:** `(names, amounts)`. Bad input (counts differ, an empty name, an
    amount that is not a finite number >= 0) raises a `DiffwashError`.
    """
    names = tuple(n.strip() for n in pigment.split("+"))
    if any(not n for n in names):
        raise _fail(f"empty pigment name in {pigment.strip()!r}", path, line, "pigment")
    texts = [t.strip() for t in re.split(r"(?<![eE])\+", amount)]  # not the + of an exponent (1e+30)
    if len(texts) != len(names):
        raise _fail(f"{len(names)} pigment{'s' if len(names) > 1 else ''} ({pigment.strip()}) but {len(texts)} "
                    f"amount{'s' if len(texts) > 1 else ''} ({amount.strip()})", path, line, "amount")  # fmt: skip
    amounts = []
    for t in texts:
        v = _number(t, path, line, "amount")
        if v < 0:
            raise _fail(f"must be >= 0, got {t}", path, line, "amount")
        amounts.append(v)
    return names, tuple(amounts)


def _number(text: str, path: Any, line: int, column: str) -> float:
    try:
        v = float(_schema.plain_number_text(text))
    except ValueError:
        raise _fail(f"not a number: {text!r}", path, line, column) from None
    if not math.isfinite(v):
        raise _fail(f"must be a finite number, got {text!r}", path, line, column)
    return check_float32(v, file=path, field=f"line {line}: {column}" if line is not None else column)


def refuse_absurd_amounts(amounts: Any, lines: Any, path: Any) -> None:
    """Refuse a positive amount more than `AMOUNT_SPAN` times the table's median positive amount, or less than
    its reciprocal, naming the line (per row a number, or a tuple for a mixture)."""
    rows = [(int(line), a) for row, line in zip(amounts, lines) for a in np.atleast_1d(row) if a > 0]
    if len(rows) < 3:
        return
    median = float(np.median([a for _, a in rows]))
    for line, a in rows:
        if not median / AMOUNT_SPAN <= a <= median * AMOUNT_SPAN:
            raise _fail(f"{a:g} is {a / median:.3g} times the table's median amount {median:g}: a typo? (amounts "
                        f"beyond {AMOUNT_SPAN:g} times the median, either way, are refused: one would dominate the fit)",
                        path, line, "amount")  # fmt: skip


def refuse_colliding_names(names: Any, lines: Any, path: Any) -> None:
    """Refuse pigment names (per row, tuples) that differ as written but not ignoring case and runs of spaces
    (`P1` and `p1`, `P 1` and `P  1`): a library could not tell them apart."""
    seen: dict[str, tuple[str, int]] = {}
    for row, line in zip(names, lines):
        for n in (row,) if isinstance(row, str) else row:
            key = _schema.name_key(n)
            first = seen.setdefault(key, (n, int(line)))
            if first[0] != n:
                raise _fail(f"{n!r} and {first[0]!r} (line {first[1]}) name the same pigment (names are compared "
                            f"ignoring case and spaces): write them alike, or name two pigments apart", path,
                            int(line), "pigment")  # fmt: skip


def max_table_rows() -> int:
    """The most rows a measurement table may have: `$DIFFWASH_MAX_TABLE_ROWS`, else `MAX_TABLE_ROWS`."""
    return env_limit(ROWS_ENV, MAX_TABLE_ROWS, "rows")


def too_many_rows(limit: int, path: Any, line: int) -> DiffwashError:
    """The refusal of a table whose row at `line` is one more than `limit`."""
    return _fail(f"has more than {limit:,} rows of measurements, the most fitted at once (memory and time grow with "
                 f"the rows: docs/scaling.md); fit a sample of the rows, or raise the limit with {ROWS_ENV}=N", path,
                 line)  # fmt: skip


def _read_csv(path: Path, max_rows: int | None = None) -> tuple[list[str], list[tuple[int, list[str]]]]:
    """The header and the non-blank rows `(line, values)`; more than `max_rows` rows are refused as they come."""
    body = []
    try:
        with open_input(path, "r", newline="", encoding="utf-8-sig") as f:
            reader = csv.reader(f)
            header = next(reader, None)
            for row in reader:
                if not (row and any(c.strip() for c in row)):
                    continue
                if max_rows is not None and len(body) >= max_rows:
                    raise too_many_rows(max_rows, path, reader.line_num)
                body.append((reader.line_num, row))
    except (OSError, UnicodeDecodeError, csv.Error) as e:
        raise _fail(f"cannot read as CSV: {e}", path) from None
    if header is None:
        raise _fail("is empty (expected a header line starting pigment,amount,ground)", path)
    for n, row in body:
        if len(row) != len(header):
            raise _fail(f"has {len(row)} values, the header {len(header)}", path, n)
    return header, body


def _key_columns(header: list[str], path: Path) -> dict[str, int]:
    names = [h.strip().lower() for h in header]
    for j, n in enumerate(names):
        if n and n in names[:j]:
            raise _fail(f"column {header[j].strip()!r} appears twice (columns {names.index(n) + 1} and {j + 1}): "
                        "which one holds the values?", path, 1, "header")  # fmt: skip
    missing = [c for c in ("pigment", "amount", "ground") if c not in names]
    if missing:
        raise _fail(f"missing column{'s' if len(missing) > 1 else ''} {', '.join(map(repr, missing))} (the header "
                    f"starts pigment,amount,ground; found {','.join(h.strip() for h in header)})", path)  # fmt: skip
    return {c: names.index(c) for c in ("pigment", "amount", "ground")}


def _band_columns(header: list[str], path: Path) -> tuple[list[int], tuple[float, ...] | None]:
    """Indices of the value columns and the grid (None for r, g, b)."""
    waves = []
    for j, h in enumerate(header):
        try:
            w = float(h.strip())
        except ValueError:
            continue
        waves.append((j, w))
    names = [h.strip().lower() for h in header]
    if waves:
        if any(c in names for c in ("r", "g", "b")):
            raise _fail("has both wavelength columns and r, g, b: which are the measurements?", path)
        grid = spectral.check_grid([w for _, w in waves], file=path, field="header")
        return [j for j, _ in waves], grid
    missing = [c for c in ("r", "g", "b") if c not in names]
    if missing:
        raise _fail("needs band columns named by wavelength in nm (380,390,...) or r,g,b after "
                    f"pigment,amount,ground (missing {', '.join(missing)})", path)  # fmt: skip
    return [names.index(c) for c in ("r", "g", "b")], None


def _checked_rows(model: str, body: list, header: list[str], col: dict[str, int], vcols: list[int], path: Path) -> list:
    """The rows as `_schema.MeasurementRow`s or `QueryRow`s (`model`), all checked at once: the first problem
    names the file, the line and the column."""
    columns: dict[str, Any] = {k: k for k in col}
    if model == "MeasurementRow":
        for n, r in body:  # `1_0` is 10 to float() and to pydantic, but to no CSV reader (one test a row: fast)
            if "_" in "".join(r[j] for j in vcols):
                j = next(j for j in vcols if "_" in r[j])
                raise _fail(f"not a number: {r[j].strip()!r}", path, n, header[j].strip())
        rows = [{"pigment": r[col["pigment"]], "amount": r[col["amount"]], "ground": r[col["ground"]],
                 "values": [r[j] for j in vcols]} for _, r in body]  # fmt: skip
        columns["values"] = [header[j].strip() for j in vcols]
    else:
        rows = [{"pigment": r[col["pigment"]], "amount": r[col["amount"]], "ground": r[col["ground"]]} for _, r in body]
    if model not in _ADAPTERS:
        _ADAPTERS[model] = _schema.row_adapter(getattr(_schema, model))
    return _schema.validate_rows(_ADAPTERS[model], rows, path, [n for n, _ in body], columns)


#: The row checkers, made at first use (building one takes a few milliseconds).
_ADAPTERS: dict[str, Any] = {}


def read_measurements(path: str | os.PathLike, *, linear: bool = False, max_rows: int | None = None) -> Measurements:
    """Read and validate a measurement table (format in the module docstring).

    **Arguments:**

    - `path`: the CSV file.
    - `linear`: for an RGB table, the r, g, b columns hold linear reflectance
      rather than display sRGB.
    - `max_rows`: the most rows accepted (default `max_table_rows()`: `$DIFFWASH_MAX_TABLE_ROWS`, else
      `MAX_TABLE_ROWS`); a longer table is refused as soon as the reader passes the limit.

    **Returns:**

    The `Measurements`, values as linear reflectance. Bad input raises a
    `DiffwashError` naming the file, the line and the column.
    """
    path = Path(path)
    header, body = _read_csv(path, max_table_rows() if max_rows is None else max_rows)
    col = _key_columns(header, path)
    vcols, grid = _band_columns(header, path)
    pigs, amts, gnds, vals, lines, sizes = [], [], [], [], [], []
    for (n, _), row in zip(body, _checked_rows("MeasurementRow", body, header, col, vcols, path)):
        names, amounts, size = parse_stack(row.pigment, row.amount, path=path, line=n)
        pigs.append(names)
        amts.append(amounts)
        gnds.append(row.ground.strip().lower())
        vals.append(row.values)
        lines.append(n)
        sizes.append(size)
    if not pigs:
        raise _fail("has no rows of measurements", path)
    refuse_colliding_names(pigs, lines, path)
    refuse_absurd_amounts(amts, lines, path)
    vals = np.asarray(vals, np.float64)
    lines = np.asarray(lines)
    if grid is None:
        vals, lo, hi = _rgb_values(vals, linear, path, lines)
    else:
        big = vals > MAX_REFLECTANCE
        if np.any(big):
            i, j = np.argwhere(big)[0]
            raise _fail(f"reflectance {vals[i, j]:g} is far above 1 (is the table in percent? reflectance is 0..1)",
                        path, int(lines[i]), spectral.RGB[0] if grid is None else _wl(grid[j]))  # fmt: skip
        lo = hi = np.zeros(vals.shape, bool)
    m = _split_grounds(pigs, amts, np.asarray(gnds), vals, lo, hi, grid, path, lines, sizes)
    return m if np.any(m.is_stack) else replace(m, layers=None)


def _wl(w: float) -> str:
    return str(int(w)) if float(w).is_integer() else repr(w)


def rgb_scale(vals: np.ndarray, path: Any, lines: Any) -> float:
    """The top of an r, g, b table's scale: 255, or 1 when no value exceeds 1.

    A table whose values are mostly fractions between 0 and 1 but with some
    above 1 is a 0-1 table with a typo, not a 0-255 one (read as 0-255 it would
    fit near-black paint without a word): refused, naming the first value above 1.
    """
    vals = np.asarray(vals, np.float64)
    if np.any(vals > 255):
        i, j = np.argwhere(vals > 255)[0]
        raise _fail(f"colour values must be 0-255 (or 0-1), got {vals[i, j]:g}", path, int(lines[i]), "rgb"[j])
    if not np.any(vals > 1):
        return 1.0
    fractions = np.mean((vals > 0) & (vals < 1) & (vals != np.round(vals)))
    if fractions > 0.5:
        i, j = np.argwhere(vals > 1)[0]
        raise _fail(f"{vals[i, j]:g} is above 1 in a table whose values are mostly 0-1 fractions ({fractions:.0%}): "
                    f"a typo? (a 0-255 table has whole numbers, a 0-1 table none above 1)", path, int(lines[i]),
                    "rgb"[j])  # fmt: skip
    return 255.0


def _rgb_values(vals: np.ndarray, linear: bool, path: Path, lines: np.ndarray) -> tuple[np.ndarray, ...]:
    unit = vals / rgb_scale(vals, path, lines)
    lo, hi = unit <= 0, unit >= 1
    lin = unit if linear else np.asarray(colorimetry.srgb_decode(unit), np.float64)
    return lin, lo, hi


def _refuse_paints_never_laid(pigs, amts, keep, lines, path) -> None:
    """Refuse a pigment whose every amount in the table is 0: no row shows it, and a fit would invent it."""
    laid: dict[str, float] = {}
    first: dict[str, tuple[int, str]] = {}  # each name's first row, as written there
    for i in np.flatnonzero(keep):
        for n, a in zip(pigs[i], amts[i]):
            key = _schema.name_key(n)
            laid[key] = max(laid.get(key, 0.0), a)
            first.setdefault(key, (i, n))
    for key, most in laid.items():
        if most == 0:
            i, name = first[key]
            raise _fail(f"{name!r} is only ever at amount 0: no row shows its paint (measure it at an amount > 0, "
                        f"or leave its rows out)", path, int(lines[i]), "amount")  # fmt: skip


def _split_grounds(pigs, amts, gnds, vals, lo, hi, grid, path, lines, sizes) -> Measurements:
    is_ground = np.array([len(p) == 1 and p[0].lower() == g for p, g in zip(pigs, gnds)])
    grounds = {}
    for g in dict.fromkeys(gnds[is_ground].tolist()):
        rows = np.flatnonzero(is_ground & (gnds == g))
        nonzero = [i for i in rows if amts[i][0] != 0]
        if nonzero:
            raise _fail(f"a {g!r} row gives the bare ground and must have amount 0", path, int(lines[nonzero[0]]),
                        "amount")  # fmt: skip
        clipped = np.any(lo[rows] | hi[rows], axis=1)
        if np.any(clipped):
            raise _fail(f"the {g} is clipped (a value at the end of the range): its colour is unknown", path,
                        int(lines[rows[np.argmax(clipped)]]))  # fmt: skip
        grounds[g] = vals[rows].mean(axis=0)
    ground_names = {g.lower() for g in grounds}
    keep = ~is_ground
    for i in np.flatnonzero(keep):
        if gnds[i] not in grounds:
            raise _fail(f"no row measures the ground {str(gnds[i])!r} (add a row '{gnds[i]},0,{gnds[i]},...')", path,
                        int(lines[i]), "ground")  # fmt: skip
        bad = [n for n in pigs[i] if n.lower() in ground_names]
        if bad:
            raise _fail(f"{bad[0]!r} names a ground, not a pigment (a ground row is '{bad[0]},0,{bad[0]}')", path,
                        int(lines[i]), "pigment")  # fmt: skip
    if not np.any(keep):
        raise _fail("has only ground rows: no pigment to fit", path)
    _refuse_paints_never_laid(pigs, amts, keep, lines, path)
    ix = np.flatnonzero(keep)
    return Measurements(
        pigments=tuple(pigs[i] for i in ix), amounts=tuple(amts[i] for i in ix), ground=gnds[keep],
        values=vals[keep], lo=lo[keep], hi=hi[keep], grounds=grounds, wavelengths=grid,
        path=os.fspath(path), lines=lines[keep], layers=tuple(sizes[i] for i in ix),
    )  # fmt: skip


def read_queries(path: str | os.PathLike) -> Queries:
    """Read rows to predict: `pigment,amount,ground` (other columns ignored).

    Pigment and ground names are checked against a library by its `predict`;
    here: the columns, `+`-joined counts and amounts, `/`-joined layers.
    """
    path = Path(path)
    header, body = _read_csv(path)
    col = _key_columns(header, path)
    pigs, amts, gnds, lines, sizes = [], [], [], [], []
    for (n, _), row in zip(body, _checked_rows("QueryRow", body, header, col, [], path)):
        names, amounts, size = parse_stack(row.pigment, row.amount, path=path, line=n)
        pigs.append(names)
        amts.append(amounts)
        gnds.append(row.ground.strip().lower())
        lines.append(n)
        sizes.append(size)
    if not pigs:
        raise _fail("has no rows to predict", path)
    stacked = any(len(k) > 1 for k in sizes)
    return Queries(pigments=tuple(pigs), amounts=tuple(amts), ground=np.asarray(gnds), path=os.fspath(path),
                   lines=np.asarray(lines), layers=tuple(sizes) if stacked else None)  # fmt: skip
