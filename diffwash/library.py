r"""A library of mixable pigments: what `diffwash fit-swatch --table` writes and `diffwash predict` reads.

A `Library` holds a `diffwash.mixing.Palette` (each pigment's K and S per band,
its amount law and its mixing weight), the grounds it was measured on, the
`diffwash.spectral.Observation` that turns its reflectance into colour, the
surface term and the record of the fit that made it. Its `predict` gives the
reflectance, sRGB and CIELAB of any layer of its pigments, single or mixed,
in one call:

```python
lib = diffwash.library.load_library("paints.json")  # written by diffwash fit-swatch --table
pred = lib.predict(["P1", "P1+P4", "P1/P4"], ["0.05", "0.02+0.03", "0.02/0.03"], ["paper"] * 3)
pred.srgb8, pred.lab, pred.reflectance
pred.de2000_90  # the CIEDE2000 radius holding the true colour with 90% probability (None: no uncertainty record)
```

(`P1/P4` is a glaze stack: P4 brushed over dry P1, `diffwash.mixing.stack_reflectance`.)

The file is JSON:

```
{"format": "diffwash-library", "version": 1,
 "observation": {"wavelengths": [380, ...], "illuminant": "D65", "observer": "...", "method": "ASTM E308"},
 "pigments": [{"name": "P1", "K": [...], "S": [...], "amount_law": {"kind": "power", "reference": 0.05,
               "gamma": 0.8}, "mixing_weight": 1.0}, ...],
 "grounds": {"paper": [...]}, "surface": {"k2": 0.0}, "fit": {...},
 "uncertainty": {"factor": [[...], ...], "diagonal": [...], "model_error": {"single": 0.4, "seen": 0.9,
                 "unseen": 2.1, "unmixed": 9.0}, "seen": [["P1", "P4"], ...], "record": {...}}}
```

`"observation": {"bands": "sRGB"}` for a library per linear sRGB channel: what the fits of three-channel data
write (`fit-swatch PHOTO`, `fit-swatch --table` of single paints; `library_from_pigments`), their pigments also
carrying `"density"`, `"staining"` and `"granularity"`, so the file is a pigment file too (`diffwash.pigments`:
K and S per unit thickness, thickness 1 being the law's reference amount). A pigment file of the older kind
(`{"name": ..., "K": [r, g, b], "S": [...]}` or `{"pigments": [...]}`, without `"format"`) loads as such a
library: amount law `t(a) = a^gamma` (gamma from its fit record, else 1), grounds from its fit record
(`"paper"`, `"black"`), else the shading model's default paper.

`"uncertainty"` (optional; `diffwash._regions.Posterior`) is what `de2000_90` is computed from: the
covariance of the parameters $\theta$ (per pigment $\log K$ over the bands, then per pigment $\log S$, then
each pigment's $\log\gamma$: n = 2PB + P) as $F F^\top + \mathrm{diag}(d)$, `factor` $F$ of n rows and
`diagonal` $d$ of n numbers; the model error $s$ (CIELAB units per axis) of single paints, of mixtures of sets
of pigments the table measured mixed (`seen`, listed), of the others (`unseen`) and, where the table has a paint it
never measured mixed, of mixtures holding such a paint (`unmixed`; files written before have no such kind, and
those rows get no region). A library without it
(older files, `fit_mixtures(..., posterior=False)`) loads and predicts as before, its `de2000_90`
None and `diffwash predict` writes no such column; a kind without a model error gets no region (NaN, an
empty cell).

`"observation": {"bands": "sRGB"}` for a library per linear sRGB channel.
"""

from __future__ import annotations

import csv
import io as _stdio
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from . import _regions, _schema, colorimetry, mixing, pigments, spectral
from ._errors import DiffwashError
from ._io import atomic_path, finite_number, read_json, write_json
from .measurements import Measurements, Queries, parse_stack, read_queries
from .shading import DEFAULT_PAPER

__all__ = ["Library", "Prediction", "load_library", "library_from_pigments", "predict"]

FORMAT = "diffwash-library"
VERSION = 1


@dataclass(frozen=True)
class Prediction:
    """Predicted colour of layers, one row per query.

    **Fields:**

    - `reflectance`: per band of the library's grid (linear sRGB for an sRGB library), shape (N, B).
    - `linear_srgb`: linear sRGB (D65, unclipped), shape (N, 3).
    - `lab`: CIELAB relative to the observation's white, shape (N, 3).
    - `bands`: the band names (`"380"`, ... or `r, g, b`).
    - `de2000_90`: the CIEDE2000 radius around `lab` that holds the true colour with 90% probability, shape (N,)
      (NaN for a kind of row the library measured no model error for), or None for a library without an
      uncertainty record (`diffwash._regions`).
    """

    reflectance: np.ndarray
    linear_srgb: np.ndarray
    lab: np.ndarray
    bands: tuple[str, ...]
    de2000_90: np.ndarray | None = None

    @property
    def srgb8(self) -> np.ndarray:
        """Display sRGB on the 0-255 scale, unclipped floats, shape (N, 3)."""
        return 255 * np.asarray(colorimetry.srgb_encode(self.linear_srgb), np.float64)


@eqx.filter_jit
def _forward(palette: mixing.Palette, amounts, ground, k2, obs: spectral.Observation):
    R = palette.stack_reflectance(amounts, ground, k2)
    return R, obs.linear_srgb(R), obs.lab(R)


@dataclass(frozen=True)
class Library:
    """Mixable pigments, their grounds and how their reflectance is seen (module docstring).

    **Fields:**

    - `palette`: the `diffwash.mixing.Palette`.
    - `grounds`: ground name -> reflectance on the palette's bands.
    - `observation`: the `diffwash.spectral.Observation` of those bands.
    - `k2`: Saunderson's internal surface reflectance (0: none).
    - `fit`: the fit's record (model terms, per-row residuals, summary), JSON-ready, or None.
    - `extras`: per pigment, the renderer's other properties (`density`, `staining`, `granularity`) written
      with it, or None.
    - `posterior`: the parameters' covariance and model error (`diffwash._regions.Posterior`), or None.
    """

    palette: mixing.Palette
    grounds: dict[str, np.ndarray]
    observation: spectral.Observation
    k2: float = 0.0
    fit: dict[str, Any] | None = field(default=None, repr=False)
    extras: tuple[dict[str, float], ...] | None = field(default=None, repr=False)
    posterior: _regions.Posterior | None = field(default=None, repr=False)

    @property
    def names(self) -> tuple[str, ...]:
        return self.palette.names

    @property
    def spectral(self) -> bool:
        return self.observation.spectral

    def amounts(self, pigments, amounts, *, file: Any = None, lines: Any = None) -> np.ndarray:
        """Rows of pigment names and amounts as a dense `(N, P)` amount matrix (repeated names add up).

        A name the library lacks raises a `DiffwashError` naming the file, line and column.
        """
        return self.layer_amounts(pigments, amounts, file=file, lines=lines)[:, 0]

    def layer_amounts(self, pigments, amounts, layers=None, *, file: Any = None, lines: Any = None) -> np.ndarray:
        """Rows as glaze stacks: a dense `(N, L, P)` amount array, layer by layer, bottom first (`L`: the most
        layers of any row; rows of fewer layers are padded on top with empty layers, which are transparent).

        `layers`: each row's pigments per layer (`Queries.layers`; None: every row one layer). Names match
        ignoring case and runs of spaces. A ground's name at amount 0 is no paint (a measurement table's bare
        ground, `paper,0,paper`, is that ground). A name the library lacks raises a `DiffwashError` naming the
        file, line and column.
        """
        index = {_schema.name_key(n): i for i, n in enumerate(self.names)}
        bare = {_schema.name_key(g) for g in self.grounds}
        sizes = [(len(p),) for p in pigments] if layers is None else [tuple(k) for k in layers]
        out = np.zeros((len(pigments), max((len(k) for k in sizes), default=1), len(self.names)))
        for r, (names, amts, k) in enumerate(zip(pigments, amounts, sizes)):
            for n, a, at in zip(names, amts, np.repeat(np.arange(len(k)), k)):
                key = _schema.name_key(n)
                i = index.get(key)
                if i is None and a == 0 and key in bare:
                    continue
                if i is None:
                    where = f"line {int(lines[r])}: pigment" if lines is not None else f"row {r + 1}: pigment"
                    raise DiffwashError(f"no pigment {n!r} in the library (it has {', '.join(self.names)})",
                                        file=file, field=where)  # fmt: skip
                out[r, at, i] += a
        return out

    def ground_matrix(self, grounds, *, file: Any = None, lines: Any = None) -> np.ndarray:
        """Each row's ground reflectance, shape (N, B); an unknown ground raises a `DiffwashError`."""
        known = {k.lower(): v for k, v in self.grounds.items()}
        rows = []
        for r, g in enumerate(grounds):
            v = known.get(str(g).lower())
            if v is None:
                where = f"line {int(lines[r])}: ground" if lines is not None else f"row {r + 1}: ground"
                raise DiffwashError(f"no ground {str(g)!r} in the library (it has {', '.join(self.grounds)})",
                                    file=file, field=where)  # fmt: skip
            rows.append(v)
        return np.asarray(rows, np.float64).reshape(len(rows), len(self.observation.bands))

    def predict(self, pigments, amounts=None, grounds=None) -> Prediction:
        """Predict layers: a `Queries` (or a query CSV's path), or parallel lists of rows.

        **Arguments:**

        - `pigments`: a `diffwash.measurements.Queries` (or `Measurements`), a path to a query table,
          or per row a name (`"P1+P3"`; `"P1/P3"` for P3 glazed over P1), a tuple of names (one layer)
          or a tuple of such tuples (a stack, bottom layer first).
        - `amounts`: per row `"0.01+0.02"` (`"0.01/0.02"`), or numbers shaped as the row's names (rows
          given as lists only).
        - `grounds`: per row a ground's name (default: `paper`).

        **Returns:** a `Prediction`. Bad input raises a `DiffwashError`.
        """
        q = _as_queries(pigments, amounts, grounds)
        A = self.layer_amounts(q.pigments, q.amounts, q.layers, file=q.path, lines=q.lines)
        G = self.ground_matrix(q.ground, file=q.path, lines=q.lines)
        R, rgb, lab = _forward(self.palette, jnp.asarray(A), jnp.asarray(G), jnp.asarray(self.k2), self.observation)
        lab = np.asarray(lab, np.float64)
        r90 = None
        if self.posterior is not None:
            r90 = _regions.de2000_90(self.posterior, self.palette, A, G, self.k2, self.observation.lab, lab)
        return Prediction(np.asarray(R, np.float64), np.asarray(rgb, np.float64), lab, self.observation.bands, r90)

    def to_dict(self) -> dict[str, Any]:
        """The library as the JSON object of the module docstring."""
        p = self.palette
        gam = np.asarray(p.law.gamma, np.float64)
        pigs = [{"name": n, "K": np.asarray(p.K[i], np.float64).tolist(), "S": np.asarray(p.S[i], np.float64).tolist(),
                 "amount_law": {"kind": "power", "reference": p.law.reference, "gamma": float(gam[i])},
                 "mixing_weight": float(p.weights[i]), **(self.extras[i] if self.extras else {})}
                for i, n in enumerate(p.names)]  # fmt: skip
        out = {"format": FORMAT, "version": VERSION, "observation": self.observation.describe(), "pigments": pigs,
               "grounds": {k: np.asarray(v, np.float64).tolist() for k, v in self.grounds.items()},
               "surface": {"k2": float(self.k2)}}  # fmt: skip
        if p.pairs is not None:
            out["pair_terms"] = p.pairs.to_dict(p.names)
        if self.fit is not None:
            out["fit"] = self.fit
        if self.posterior is not None:
            out["uncertainty"] = self.posterior.to_dict()
        return out

    def save(self, path: str | os.PathLike) -> None:
        """Write the library as JSON (atomically)."""
        write_json(path, self.to_dict())


def _as_queries(pigments, amounts, grounds) -> Queries:
    if isinstance(pigments, Queries):
        return pigments
    if isinstance(pigments, Measurements):  # its rows
        return Queries(pigments=pigments.pigments, amounts=pigments.amounts, ground=pigments.ground,
                       path=pigments.path, lines=pigments.lines, layers=pigments.layers)  # fmt: skip
    if isinstance(pigments, (str, os.PathLike)) and amounts is None:
        return read_queries(pigments)
    names, amts, sizes = [], [], []
    for r, (p, a) in enumerate(zip(pigments, amounts)):
        if isinstance(p, str):
            n, v, k = parse_stack(p, a if isinstance(a, str) else "+".join(map(repr, np.atleast_1d(a).tolist())),
                                  line=r + 1)  # fmt: skip
        elif len(p) and not isinstance(p[0], str):  # layers of names
            n = tuple(x for layer in p for x in layer)
            v = tuple(float(x) for layer in a for x in layer)
            k = tuple(len(layer) for layer in p)
        else:
            n, v, k = tuple(p), tuple(float(x) for x in a), (len(p),)
        names.append(n)
        amts.append(v)
        sizes.append(k)
    g = ["paper"] * len(names) if grounds is None else [str(x).lower() for x in grounds]
    layers = tuple(sizes) if any(len(k) > 1 for k in sizes) else None
    return Queries(pigments=tuple(names), amounts=tuple(amts), ground=np.asarray(g), layers=layers)


def _vector(d: dict, key: str, n: int | None, path: Any, where: str) -> np.ndarray:
    v = d.get(key)
    try:
        a = np.asarray(v, np.float64)
    except (TypeError, ValueError):
        a = np.empty(0)
    if a.ndim != 1 or (n is not None and a.shape[0] != n) or not np.all(np.isfinite(a)) or np.any(a < 0):
        want = f"{n} " if n is not None else ""
        raise DiffwashError(f"{key} must be a list of {want}finite numbers >= 0", file=path, field=f"{where}.{key}")
    return a


def _observation(o: Any, path: Any) -> spectral.Observation:
    if not isinstance(o, dict):
        raise DiffwashError("needs an observation (wavelengths, or \"bands\": \"sRGB\")", file=path,
                            field="observation")  # fmt: skip
    if o.get("bands") == "sRGB":
        return spectral.observation()
    try:
        return spectral.observation(o.get("wavelengths") or [], illuminant=o.get("illuminant", "D65"),
                                    observer=o.get("observer", spectral.DEFAULT_OBSERVER), method=o.get("method"))
    except DiffwashError as e:  # the same problem, located in this file
        raise DiffwashError(e.problem, file=path, field=f"observation.{e.field or 'wavelengths'}") from None


def _pair_terms(spec: _schema.PairTerms, names: list[str], obs: spectral.Observation, path: Any) -> mixing.PairTerms:
    """`PairTerms` from a library's `"pair_terms"`, declared (`_schema.PairTerms`: types, ranges) and checked
    here against the library: the pairs' pigments, one bump per centre, each pair once."""
    if not obs.spectral:
        raise DiffwashError("pair terms need a spectral library (a band grid)", file=path, field="pair_terms")
    centres = tuple(float(c) for c in spec.basis.centres)
    index = {n: i for i, n in enumerate(names)}
    members, inferred, cols = [], [], {k: [] for k in ("K_bumps", "S_bumps", "K_amount", "S_amount")}
    for q, e in enumerate(spec.pairs):
        where = f"pair_terms.pairs[{q}]"
        two = e.pigments
        if any(n not in index for n in two) or two[0] == two[1]:
            raise DiffwashError(f"pigments must name two different pigments of the library ({', '.join(names)})",
                                file=path, field=f"{where}.pigments")  # fmt: skip
        i, j = index[two[0]], index[two[1]]
        members.append((min(i, j), max(i, j)))
        if e.inferred:
            inferred.append(members[-1])
        for k in ("K_bumps", "S_bumps"):
            if len(getattr(e, k)) != len(centres):
                raise DiffwashError(f"must be a list of {len(centres)} numbers (one per centre of the basis), got "
                                    f"{len(getattr(e, k))}", file=path, field=f"{where}.{k}")  # fmt: skip
        for k in cols:
            cols[k].append(getattr(e, k))
    if len(set(members)) != len(members):
        raise DiffwashError("names a pair twice", file=path, field="pair_terms.pairs")
    q, n = len(members), len(centres)
    arr = {k: jnp.asarray(np.asarray(v, np.float64).reshape((q, n) if k.endswith("bumps") else (q,)))
           for k, v in cols.items()}  # fmt: skip
    return mixing.PairTerms(members=tuple(members), k_bumps=arr["K_bumps"],
                            s_bumps=arr["S_bumps"], k_amount=arr["K_amount"], s_amount=arr["S_amount"],
                            centres=centres, width=float(spec.basis.width), wavelengths=obs.wavelengths,
                            inferred=tuple(inferred))  # fmt: skip


def library_from_dict(d: Any, path: Any = None) -> Library:
    """A `Library` from its JSON object, checked against its declaration (`diffwash._schema.LibraryFile`: types,
    ranges, float32, names colliding ignoring case and spaces) before anything is computed; one-line errors name
    the file and the key. A pigment file of the older kind (no `"format"`) is converted on load."""
    if isinstance(d, dict) and "format" not in d and ("K" in d or isinstance(d.get("pigments"), list)):
        return _from_pigment_file(d, path)  # an older pigment file: converted on load
    if not isinstance(d, dict) or d.get("format") != FORMAT:
        raise DiffwashError(f"is not a {FORMAT} file (no \"format\": \"{FORMAT}\")", file=path)
    spec = _schema.validate(_schema.LibraryFile, d, path)
    obs = _observation(spec.observation.model_dump(exclude_none=True), path)
    names = [p.name for p in spec.pigments]
    K, S = np.array([p.K for p in spec.pigments], np.float64), np.array([p.S for p in spec.pigments], np.float64)
    gam = np.array([p.amount_law.gamma for p in spec.pigments])
    refs = np.array([p.amount_law.reference for p in spec.pigments])
    ref = float(refs[0])
    if np.any(refs != ref):
        # Thickness (a / r_i)^g_i = (a / r)^g_i (r / r_i)^g_i: another reference is a factor on that pigment's K and S.
        if spec.pair_terms is not None:
            i = int(np.flatnonzero(refs != ref)[0])
            raise DiffwashError(f"differs from pigments[0]'s ({ref:g}); pair terms need one reference amount",
                                file=path, field=f"pigments[{i}].amount_law.reference")  # fmt: skip
        factor = (ref / refs) ** gam
        K, S = K * factor[:, None], S * factor[:, None]
        big = np.flatnonzero(np.max(np.maximum(K, S), axis=1) > _schema.COEFFICIENT_MAX)
        if len(big):
            raise DiffwashError(f"is too far from pigments[0]'s ({ref:g}): on one reference amount its K or S would "
                                f"exceed {_schema.COEFFICIENT_MAX:g}", file=path,
                                field=f"pigments[{int(big[0])}].amount_law.reference")  # fmt: skip
    palette = mixing.Palette(K=jnp.asarray(K), S=jnp.asarray(S), law=mixing.AmountLaw(gamma=jnp.asarray(gam), reference=ref),
                             weights=jnp.asarray([p.mixing_weight for p in spec.pigments]), names=tuple(names),
                             wavelengths=obs.wavelengths)  # fmt: skip
    if spec.pair_terms is not None:
        palette = eqx.tree_at(lambda p: p.pairs, palette, _pair_terms(spec.pair_terms, names, obs, path),
                              is_leaf=lambda x: x is None)  # fmt: skip
    grounds = {k.lower(): np.asarray(v, np.float64) for k, v in spec.grounds.items()}
    extras = [_extras(p, path, f"pigments[{i}]") for i, p in enumerate(d["pigments"])]
    post = None
    if d.get("uncertainty") is not None:
        post = _regions.Posterior.from_dict(d["uncertainty"], len(names) * (2 * K.shape[1] + 1), path)
    return Library(palette=palette, grounds=grounds, observation=obs, k2=spec.surface.k2, fit=d.get("fit"),
                   extras=tuple(extras) if any(extras) else None, posterior=post)  # fmt: skip


def _extras(p: dict, path: Any, where: str) -> dict[str, float]:
    """A library pigment's renderer properties (`density`, `staining`, `granularity`) where it has them."""
    out = {}
    for key in pigments.DEFAULTS:
        if key in p:
            if not finite_number(p[key]) or p[key] < 0:
                raise DiffwashError("must be a finite number >= 0", file=path, field=f"{where}.{key}")
            out[key] = float(p[key])
    return out


def library_from_pigments(
    pigs: list[pigments.Pigment],
    *,
    gamma: Any = None,
    reference: float = 1.0,
    grounds: dict[str, Any] | None = None,
    k2: float = 0.0,
    fit: dict[str, Any] | None = None,
) -> Library:
    """A library per linear sRGB channel from three-channel pigments (what the fits of sRGB data write).

    **Arguments:**

    - `pigs`: the `diffwash.pigments.Pigment`s, K and S per unit thickness (thickness 1 at `reference`).
    - `gamma`: each pigment's amount-law exponent, thickness = (amount / reference)**gamma (default 1).
    - `reference`: the amount of thickness 1 (1: the fits' amounts, coats for swatch cards).
    - `grounds`: ground name -> linear sRGB reflectance (default: the shading model's paper as `paper`).
    - `k2`: Saunderson's internal reflectance (0: none).
    - `fit`: the fit's record.

    **Returns:** the `Library` (its pigments keep their density, staining and granularity).
    """
    gam = np.ones(len(pigs)) if gamma is None else np.asarray(gamma, np.float64).reshape(len(pigs))
    grounds = {"paper": DEFAULT_PAPER} if grounds is None else grounds
    palette = mixing.Palette(K=jnp.asarray(np.stack([np.asarray(p.K, np.float64) for p in pigs])),
                             S=jnp.asarray(np.stack([np.asarray(p.S, np.float64) for p in pigs])),
                             law=mixing.AmountLaw(gamma=jnp.asarray(gam), reference=float(reference)),
                             weights=jnp.ones(len(pigs)), names=tuple(p.name for p in pigs))  # fmt: skip
    extras = tuple({k: float(getattr(p, k)) for k in pigments.DEFAULTS} for p in pigs)
    ground = {str(k).lower(): np.asarray(v, np.float64).reshape(3) for k, v in grounds.items() if v is not None}
    return Library(palette=palette, grounds=ground, observation=spectral.observation(), k2=float(k2), fit=fit,
                   extras=extras)  # fmt: skip


def _from_pigment_file(d: dict, path: Any) -> Library:
    """An older pigment file (one pigment, or `{"pigments": [...]}`) as a library per sRGB channel: amount law
    and grounds from its fit record where it has them (`fit-swatch --table` wrote `thickness_exponent`)."""
    if isinstance(d.get("pigments"), list):
        if not d["pigments"]:
            raise DiffwashError("must be a non-empty list of pigments", file=path, field="pigments")
        pigs = [pigments.parse(p, file=path, where=f"pigments[{i}]") for i, p in enumerate(d["pigments"])]
    else:
        pigs = [pigments.parse(d, file=path)]
    fit = d.get("fit") if isinstance(d.get("fit"), dict) else {}
    per = fit.get("pigments") if isinstance(fit.get("pigments"), dict) else {}
    gamma = []
    for p in pigs:
        g = (per.get(p.name) or {}).get("thickness_exponent", 1.0) if isinstance(per.get(p.name), dict) else 1.0
        gamma.append(float(g) if finite_number(g) and g > 0 else 1.0)
    grounds = {}
    for k in ("paper", "black"):
        v = fit.get(k)
        if isinstance(v, list) and len(v) == 3 and all(finite_number(x) and 0 <= x for x in v):
            grounds[k] = v
    model = fit.get("model") if isinstance(fit.get("model"), dict) else {}
    k2 = model.get("k2", 0.0) if model.get("surface") == "saunderson" and finite_number(model.get("k2")) else 0.0
    return library_from_pigments(pigs, gamma=gamma, grounds=grounds or None, k2=k2, fit=d.get("fit"))


def load_library(path: str | os.PathLike) -> Library:
    """Read a library file (module docstring); bad content raises a `DiffwashError`."""
    return library_from_dict(read_json(path), path)


def predict(library: Library | str | os.PathLike, pigments, amounts=None, grounds=None) -> Prediction:
    """One call: load `library` if it is a path, then `Library.predict(pigments, amounts, grounds)`."""
    lib = library if isinstance(library, Library) else load_library(library)
    return lib.predict(pigments, amounts, grounds)


def prediction_csv(queries: Queries, pred: Prediction) -> str:
    """The CSV text `diffwash predict` writes: the query columns, `r,g,b` (8-bit sRGB), `L*,a*,b*`, `de2000_90`
    (where the library has an uncertainty record; empty where it has no model error for the row's kind), the
    bands."""
    buf = _stdio.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    bands = list(pred.bands) if pred.bands != spectral.RGB else []
    r90 = pred.de2000_90
    w.writerow(["pigment", "amount", "ground", "r", "g", "b", "L*", "a*", "b*", *(["de2000_90"] if r90 is not None else []),
                *bands])  # fmt: skip
    rgb = pred.srgb8
    for i in range(len(queries)):
        row = [*queries.row_text(i), queries.ground[i]]
        row += [f"{v:.4f}" for v in rgb[i]] + [f"{v:.4f}" for v in pred.lab[i]]
        row += [] if r90 is None else [f"{r90[i]:.4f}" if np.isfinite(r90[i]) else ""]
        row += [f"{v:.6f}" for v in pred.reflectance[i]] if bands else []
        w.writerow(row)
    return buf.getvalue()


def write_prediction(path: str | os.PathLike, queries: Queries, pred: Prediction) -> None:
    """Write `prediction_csv` to `path` atomically."""
    with atomic_path(path) as tmp:
        Path(tmp).write_text(prediction_csv(queries, pred), encoding="utf-8")

