r"""Pigments from a table of measured colours: every pigment at once.

A measurement table is a CSV file with the columns

```
pigment,amount,ground,r,g,b
paper,0,paper,240,240,235
black,0,black,20,20,22
Cobalt Blue,0.01,paper,0,124,198
Cobalt Blue,0.01,black,18,40,70
```

- `pigment`: the pigment's name; the rows named `paper` and `black` (amount 0)
  give the two grounds' colours (averaged if repeated);
- `amount`: how much paint, in any unit (>= 0): the fitted K and S are per
  unit of it (with the power law, thickness = amount**gamma, so the amount 1
  is thickness 1);
- `ground`: `paper` or `black`, what the paint lies on;
- `r, g, b`: the colour, display sRGB 0-255, or 0-1 floats (the whole file is
  on one scale: 0-1 when no value exceeds 1), or linear reflectance with
  `linear=True`. Values at the ends of the range (0 and 255, or 0 and 1) are
  clipped measurements: bounds, not values.

Extra columns are ignored. Every pigment is fitted in one call: one compiled
Levenberg-Marquardt from several starting points, `jax.vmap`ped over the
pigments or run per pigment (`fit_table`'s `batch`); see `diffwash.fit._kmfit`
for the model.
"""

from __future__ import annotations

import csv
import math
import os
import re
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from ... import colorimetry
from ..._cache import relieve_compiled_programs
from ..._errors import DiffwashError
from ..._io import check_float32, open_input
from ...library import Library, library_from_pigments
from ...measurements import max_table_rows, refuse_absurd_amounts, refuse_colliding_names, rgb_scale, too_many_rows
from ...pigments import Pigment
from .._kmfit import PLAIN, FitModel, Rows, batch_mode, fit_rows, log_sd, pad_rows, predict_jit, single_ground_start, starts_for
from .._kmfit import delta_e_displayed, paired_start

__all__ = ["MeasurementTable", "TableFit", "read_table", "fit_table", "read_ntu_wpsm", "PLAIN", "COLUMNS"]

#: The columns a measurement table must have.
COLUMNS = ("pigment", "amount", "ground", "r", "g", "b")
#: Linear values a clipped channel is bounded by: half an 8-bit code value inside the range.
CLIP_LO = 0.5 / 255 / 12.92
CLIP_HI = ((254.5 / 255 + 0.055) / 1.055) ** 2.4
GROUNDS = ("paper", "black")


@dataclass(frozen=True)
class MeasurementTable:
    """Measured colours of pigments at several amounts over paper and black.

    **Fields:**

    - `pigment`: the pigment's name on each row, shape (N,).
    - `amount`: amount of paint, shape (N,).
    - `ground`: `"paper"` or `"black"` on each row, shape (N,).
    - `rgb`: measured linear reflectance, shape (N, 3).
    - `lo`, `hi`: channels clipped at the bottom / top of the range, shape (N, 3).
    - `paper`, `black`: the grounds' linear reflectance, shape (3,) (`black` is
      None when the table has no black rows).
    - `path`: the file it was read from, if any.
    """

    pigment: np.ndarray
    amount: np.ndarray
    ground: np.ndarray
    rgb: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    paper: np.ndarray
    black: np.ndarray | None = None
    path: str | None = None
    lines: np.ndarray | None = field(default=None, repr=False)

    @property
    def names(self) -> list[str]:
        """The pigments in the order they first appear."""
        return list(dict.fromkeys(self.pigment.tolist()))

    def __len__(self) -> int:
        return len(self.amount)

    def select(self, mask: Any) -> "MeasurementTable":
        """The table restricted to the rows where `mask` is True (grounds kept)."""
        m = np.asarray(mask)
        lines = None if self.lines is None else self.lines[m]
        return replace(self, pigment=self.pigment[m], amount=self.amount[m], ground=self.ground[m],
                       rgb=self.rgb[m], lo=self.lo[m], hi=self.hi[m], lines=lines)  # fmt: skip

    def ground_rgb(self, ground: np.ndarray) -> np.ndarray:
        """Linear reflectance of the ground named on each row, shape (N, 3)."""
        black = self.black if self.black is not None else np.full(3, np.nan)
        return np.where((np.asarray(ground) == "black")[:, None], black, self.paper)


def _fail(msg: str, path: Any, field: str | None = None) -> DiffwashError:
    return DiffwashError(msg, file=path, field=field)


def read_table(path: str | os.PathLike, *, linear: bool = False) -> MeasurementTable:
    """Read and validate a measurement table (CSV, format in the module docstring).

    **Arguments:**

    - `path`: the CSV file.
    - `linear`: the r, g, b columns hold linear reflectance (0-1, or 0-255)
      rather than display sRGB.

    **Returns:**

    The `MeasurementTable` (colours as linear reflectance). Bad input raises a
    `DiffwashError` naming the file, the line and the column.
    """
    path = Path(path)
    try:
        with open_input(path, "r", newline="", encoding="utf-8-sig") as f:
            reader = csv.reader(f)
            header = next(reader, None)
            body = [(i + 2, row) for i, row in enumerate(reader)]
    except (OSError, UnicodeDecodeError, csv.Error) as e:
        raise _fail(f"cannot read as CSV: {e}", path) from None
    if header is None:
        raise _fail("is empty (expected a header line pigment,amount,ground,r,g,b)", path)
    names = [h.strip().lower() for h in header]
    missing = [c for c in COLUMNS if c not in names]
    if missing:
        listed = ", ".join(repr(c) for c in missing)
        raise _fail(f"missing column{'s' if len(missing) > 1 else ''} {listed} (the header must name "
                    f"{','.join(COLUMNS)}; found {','.join(h.strip() for h in header)})", path)  # fmt: skip
    col = {c: names.index(c) for c in COLUMNS}
    filled = [line for line, row in body if row and any(c.strip() for c in row)]
    if len(filled) > max_table_rows():
        raise too_many_rows(max_table_rows(), path, filled[max_table_rows()])
    pig, amt, gnd, vals, lines = [], [], [], [], []
    for line, row in body:
        if not row or all(not c.strip() for c in row):
            continue
        if len(row) < len(header):
            raise _fail(f"has {len(row)} values, the header {len(header)}", path, f"line {line}")
        name = row[col["pigment"]].strip()
        if not name:
            raise _fail("empty pigment name", path, f"line {line}: pigment")
        ground = row[col["ground"]].strip().lower()
        if ground not in GROUNDS:
            raise _fail(f"unknown ground {row[col['ground']].strip()!r} (must be paper or black)", path,
                        f"line {line}: ground")  # fmt: skip
        numbers = []
        for c in ("amount", "r", "g", "b"):
            text = row[col[c]].strip()
            try:
                v = float(text)
            except ValueError:
                raise _fail(f"not a number: {text!r}", path, f"line {line}: {c}") from None
            if not math.isfinite(v):
                raise _fail(f"must be a finite number, got {text!r}", path, f"line {line}: {c}")
            check_float32(v, file=path, field=f"line {line}: {c}")
            if v < 0:
                raise _fail(f"must be >= 0, got {text}", path, f"line {line}: {c}")
            numbers.append(v)
        pig.append(name)
        amt.append(numbers[0])
        gnd.append(ground)
        vals.append(numbers[1:])
        lines.append(line)
    if not pig:
        raise _fail("has no rows of measurements", path)
    refuse_colliding_names(pig, lines, path)
    refuse_absurd_amounts(amt, lines, path)
    vals = np.asarray(vals, np.float64)
    top = rgb_scale(vals, path, lines)
    return _make_table(np.asarray(pig), np.asarray(amt), np.asarray(gnd), vals / top, linear=linear,
                       path=path, lines=np.asarray(lines))  # fmt: skip


def _make_table(pig, amt, gnd, unit, *, linear, path=None, lines=None) -> MeasurementTable:
    """Build a table from values on a 0-1 scale: split off the ground rows, linearise."""
    unit = np.asarray(unit, np.float64)
    lines = lines if lines is not None else np.arange(len(pig)) + 1
    lo, hi = unit <= 0, unit >= 1
    rgb = unit if linear else np.asarray(colorimetry.srgb_decode(unit), np.float64)
    key = np.char.lower(np.asarray(pig, str))
    grounds = {}
    for g in GROUNDS:
        rows = key == g
        if not np.any(rows):
            continue
        bad = rows & (amt != 0)
        if np.any(bad):
            raise _fail(f"a {g!r} row gives the bare ground and must have amount 0", path,
                        f"line {lines[bad][0]}: amount")  # fmt: skip
        wrong = rows & (gnd != g)
        if np.any(wrong):
            raise _fail(f"the {g!r} row must have ground {g}", path, f"line {lines[wrong][0]}: ground")
        clipped = (lo | hi)[rows]
        if np.any(clipped):
            i = lines[rows][int(np.argmax(np.any(clipped, axis=1)))]
            raise _fail(f"the {g} is clipped (a value at the end of the range): its colour is unknown", path,
                        f"line {i}")  # fmt: skip
        grounds[g] = rgb[rows].mean(axis=0)
    keep = ~np.isin(key, GROUNDS)
    if not np.any(keep):
        raise _fail("has only paper/black rows: no pigment to fit", path)
    for g in GROUNDS:
        used = keep & (gnd == g)
        if np.any(used) and g not in grounds:
            raise _fail(f"rows lie on {g} but no {g!r} row gives its colour (add a row '{g},0,{g},R,G,B')", path,
                        f"line {lines[used][0]}: ground")  # fmt: skip
    if "paper" not in grounds:
        raise _fail("no 'paper' row gives the paper's colour (add a row 'paper,0,paper,R,G,B')", path)
    return MeasurementTable(
        pigment=np.asarray(pig, object)[keep].astype(str), amount=np.asarray(amt, np.float64)[keep],
        ground=np.asarray(gnd)[keep], rgb=rgb[keep], lo=lo[keep], hi=hi[keep], paper=grounds["paper"],
        black=grounds.get("black"), path=None if path is None else os.fspath(path), lines=lines[keep],
    )  # fmt: skip


#: The paints of the NTU WPSM subset (Winsor & Newton), by pigment index.
NTU_PAINTS = {
    "P1": "Cadmium Red", "P2": "Alizarin Crimson", "P3": "Burnt Sienna", "P4": "Lemon Yellow",
    "P5": "Cadmium Yellow", "P6": "Raw Sienna", "P7": "Sap Green",
}  # fmt: skip
#: The dataset's paper in 8-bit sRGB (its README: the paper's spectrum under D65, CIE 1931 2-degree).
NTU_PAPER = (240, 240, 235)


def read_ntu_wpsm(path: str | os.PathLike, paper: Sequence[float] = NTU_PAPER) -> MeasurementTable:
    """Read the NTU watercolour pigment measurements (their CSV layout) as a table.

    Columns: sample name `C<code>_R_<amount>ml`, `Pigment index` (P1..P7), `R`,
    `G`, `B` (8-bit sRGB). All samples lie on paper, whose colour (not in the
    file) is `paper`. Paints are named as in `NTU_PAINTS`.

    **References:** M.-Y. Chen et al., "Deep learning based spectral watercolor
    pigment mixing", arXiv:1904.00275 (2019).
    """
    path = Path(path)
    with open_input(path, "r", newline="", encoding="utf-8") as f:
        rows = list(csv.reader(f))
    pig, amt, vals = [], [], []
    for i, row in enumerate(rows[1:], start=2):
        m = re.search(r"_([0-9.]+)ml$", row[0].strip())
        if m is None or len(row) < 5:
            raise _fail(f"not a sample row: {row!r}", path, f"line {i}")
        pig.append(NTU_PAINTS.get(row[1].strip(), row[1].strip()))
        amt.append(float(m.group(1)))
        vals.append([float(v) for v in row[2:5]])
    pig = ["paper", *pig]
    amt = [0.0, *amt]
    vals = np.asarray([list(paper), *vals]) / 255.0
    gnd = np.asarray(["paper"] * len(pig))
    return _make_table(np.asarray(pig), np.asarray(amt), gnd, vals, linear=False, path=path,
                       lines=np.arange(len(pig)) + 1)  # fmt: skip


@dataclass(frozen=True)
class TableFit:
    """Pigments fitted to a measurement table.

    **Fields:**

    - `pigments`: the fitted `Pigment`s (K, S per unit thickness), in table order.
    - `gamma`: each pigment's thickness exponent (thickness = amount**gamma; 1
      with the linear model), shape (P,).
    - `model`: the `FitModel` used.
    - `paper`, `black`: the grounds' linear reflectance (from the table).
    - `delta_e`: each pigment's CIEDE2000 at its own rows, a list of arrays.
    - `iterations`, `converged`: Levenberg-Marquardt steps and convergence per pigment.
    - `log_sd`: per pigment, the standard deviations of the fitted
      `log_K`, `log_S` (and `log_gamma`) (`diffwash.fit._kmfit.log_sd`).
    """

    pigments: list[Pigment]
    gamma: np.ndarray
    model: FitModel
    paper: np.ndarray
    black: np.ndarray | None
    delta_e: list[np.ndarray]
    iterations: np.ndarray
    converged: np.ndarray
    log_sd: list[dict[str, np.ndarray]]

    @property
    def names(self) -> list[str]:
        return [p.name for p in self.pigments]

    def _index(self, name: str) -> int:
        key = " ".join(name.casefold().split())
        for i, n in enumerate(self.names):
            if " ".join(n.casefold().split()) == key:
                return i
        raise DiffwashError(f"no fitted pigment named {name!r} (have: {', '.join(self.names)})")

    def predict(self, name: str, amount: Any, ground: Any = "paper") -> np.ndarray:
        """Measured linear reflectance of pigment `name` at `amount` over `ground`.

        `ground` is `"paper"`, `"black"`, a linear reflectance (3,), or one of
        those per amount. **Returns:** (len(amount), 3).
        """
        i = self._index(name)
        amount = np.atleast_1d(np.asarray(amount, np.float64))
        if isinstance(ground, str) or (np.ndim(ground) == 1 and np.asarray(ground).dtype.kind in "US"):
            names = np.broadcast_to(np.asarray(ground), amount.shape)
            if np.any(names == "black") and self.black is None:
                raise DiffwashError("the table had no black rows: the black ground is unknown")
            g = np.where((names == "black")[:, None], self.black if self.black is not None else 0, self.paper)
        else:
            g = np.broadcast_to(np.asarray(ground, np.float64), amount.shape + (3,))
        p = self.pigments[i]
        theta = {"log_K": np.log(np.maximum(p.K, 1e-300)), "log_S": np.log(np.maximum(p.S, 1e-300)),
                 "log_gamma": np.log(self.gamma[i])}  # fmt: skip
        return np.asarray(predict_jit(self.model, theta, amount, g), np.float64)

    def evaluate(self, table: MeasurementTable) -> np.ndarray:
        """CIEDE2000 between the table's measured colours and the fit's prediction, per row.

        The prediction is clipped into the displayable range as the measurement
        was (a clipped channel that the prediction exceeds counts as equal).
        """
        pred = np.empty_like(table.rgb)
        for name in dict.fromkeys(table.pigment.tolist()):
            rows = table.pigment == name
            pred[rows] = self.predict(name, table.amount[rows], table.ground[rows])
        return delta_e_displayed(pred, table.rgb)

    def to_dict(self) -> dict[str, Any]:
        """Fit diagnostics per pigment, JSON-ready."""
        out = {}
        for i, p in enumerate(self.pigments):
            d = {
                "thickness_exponent": float(self.gamma[i]),
                "rows": int(len(self.delta_e[i])),
                "delta_e_2000": [round(float(v), 4) for v in self.delta_e[i]],
                "mean_delta_e_2000": float(np.mean(self.delta_e[i])),
                "iterations": int(self.iterations[i]),
                "converged": bool(self.converged[i]),
                "log_sd": {k: [float(x) if np.isfinite(x) else None for x in np.atleast_1d(v)]
                           for k, v in self.log_sd[i].items()},
            }  # fmt: skip
            out[p.name] = d
        return out

    @property
    def library(self) -> Library:
        """The pigments as a `diffwash.library.Library` per sRGB channel: thickness = amount**gamma (the law's
        reference amount 1), the table's grounds, the diagnostics as its fit record. `Library.predict` gives
        what `predict` does."""
        fit = {
            "source": "diffwash fit-swatch --table",
            "model": self.model.describe(),
            "paper": self.paper.tolist(),
            "black": None if self.black is None else self.black.tolist(),
            "pigments": self.to_dict(),
        }
        k2 = self.model.k2 if self.model.surface == "saunderson" else 0.0
        return library_from_pigments(self.pigments, gamma=self.gamma, grounds={"paper": self.paper, "black": self.black},
                                     k2=k2, fit=fit)  # fmt: skip

    def save(self, path: str | os.PathLike) -> None:
        """Write the library file (`diffwash.library`, per sRGB channel; also a pigment file) with diagnostics:
        what `diffwash predict`, scenes and `fit-image` read."""
        self.library.save(path)


def _pack(table: MeasurementTable, model: FitModel) -> tuple[Rows, dict[str, np.ndarray], list[np.ndarray]]:
    names = table.names
    index = [np.flatnonzero(table.pigment == n) for n in names]
    M = pad_rows(max(len(ix) for ix in index))
    P = len(names)
    amount = np.zeros((P, M))
    ground = np.full((P, M, 3), 0.5)
    rgb = np.full((P, M, 3), 0.5)
    lo = np.zeros((P, M, 3), bool)
    hi = np.zeros((P, M, 3), bool)
    weight = np.zeros((P, M))
    g_all = table.ground_rgb(table.ground)
    starts = []
    scale = np.ones(P)
    for p, ix in enumerate(index):
        n = len(ix)
        # Amounts are fitted relative to their geometric mean: log K and the exponent gamma are
        # then nearly uncorrelated (with amounts far from 1, K a**gamma ties them together).
        pos = table.amount[ix][table.amount[ix] > 0]
        scale[p] = float(np.exp(np.mean(np.log(pos)))) if len(pos) else 1.0
        amount[p, :n] = table.amount[ix] / scale[p]
        ground[p, :n] = g_all[ix]
        # A clipped reading stands for anything beyond half a code value from the end of the range.
        rgb[p, :n] = np.where(table.lo[ix], CLIP_LO, np.where(table.hi[ix], CLIP_HI, table.rgb[ix]))
        lo[p, :n], hi[p, :n] = table.lo[ix], table.hi[ix]
        weight[p, :n] = 1.0
        starts.append(_start(table, ix, g_all, model, scale[p]))
    stacked = {k: np.stack([s[k] for s in starts]) for k in starts[0]}
    rows = Rows(amount=amount, ground=ground, rgb=rgb, lo=lo, hi=hi, weight=weight)
    return rows, stacked, scale


def _start(
    table: MeasurementTable, ix: np.ndarray, g_all: np.ndarray, model: FitModel, scale: float
) -> dict[str, np.ndarray]:
    """Starting points for one pigment: Curtis's inversion if it was measured over both grounds."""
    amount, ground, rgb = table.amount[ix] / scale, table.ground[ix], table.rgb[ix]
    start = paired_start(amount, ground, rgb, table.paper, table.black)
    if start is not None:
        K0, S0 = start
    else:
        pos = amount > 0
        if not np.any(pos):
            K0 = S0 = np.ones(3)
        else:
            K0, S0 = single_ground_start(amount[pos], g_all[ix][pos], rgb[pos])
    return starts_for(model, K0, S0)


def fit_table(
    table: MeasurementTable | str | os.PathLike,
    *,
    model: FitModel = FitModel(),
    linear: bool = False,
    max_steps: int = 1000,
    batch: str = "auto",
) -> TableFit:
    """Fit every pigment of a measurement table at once.

    **Arguments:**

    - `table`: a `MeasurementTable` or the path of a CSV (`read_table`).
    - `model`: the `FitModel` (default: power-law thickness, CIEDE2000
      residuals, clipped values as bounds, a weak prior; `PLAIN` is the plain
      fit: thickness = amount, sRGB residuals).
    - `linear`: with a path, its colours are linear reflectance.
    - `max_steps`: Levenberg-Marquardt steps at most (per start).
    - `batch`: `"vmap"` (one compiled program, `jax.vmap`ped over the
      pigments), `"loop"` (the unbatched program per pigment) or `"auto"`
      (loop on a CPU for up to 16 pigments, where it is faster warm and
      cold; vmap otherwise). The results agree either way.

    **Returns:**

    A `TableFit`: the pigments (K, S per unit thickness) and diagnostics.
    """
    relieve_compiled_programs()  # before this fit compiles: a long-lived process may run out of memory maps
    batch_mode(batch, 1)  # a bad value fails before any file is read
    if not isinstance(table, MeasurementTable):
        table = read_table(table, linear=linear)
    rows, starts, scale = _pack(table, model)
    res = fit_rows(model, rows, starts, max_steps=max_steps, batch=batch)
    theta = {k: np.asarray(v, np.float64) for k, v in res.theta.items()}
    jac = np.asarray(res.jacobian, np.float64)
    sizes = {k: int(np.prod(theta[k].shape[1:])) for k in res.param_names}
    pigments, gamma, sds = [], [], []
    for p, name in enumerate(table.names):
        g = float(np.exp(theta["log_gamma"][p])) if "log_gamma" in theta else 1.0
        # Back from "per unit of relative amount" to per unit of thickness amount**gamma.
        unit = scale[p] ** -g
        K, S = np.exp(theta["log_K"][p]) * unit, np.exp(theta["log_S"][p]) * unit
        pigments.append(Pigment(K=K, S=S, name=name))
        gamma.append(g)
        sds.append(log_sd(jac[p], sizes, float(res.loss[p])))
    out = TableFit(
        pigments=pigments, gamma=np.asarray(gamma), model=model, paper=table.paper, black=table.black,
        delta_e=[], iterations=np.asarray(res.steps), converged=np.asarray(res.converged), log_sd=sds,
    )  # fmt: skip
    des = [out.evaluate(table.select(table.pigment == n)) for n in table.names]
    return replace(out, delta_e=des)
