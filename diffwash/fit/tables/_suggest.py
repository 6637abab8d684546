r"""What to paint next: candidate swatches ranked by how much measuring them would shrink the 90% regions.

A library fitted with a posterior (the library's `"uncertainty"`, `diffwash._regions`: what `diffwash fit-swatch`
stores for swatch-card photos, and `--table` for a spectral table or an RGB one with mixtures) predicts each
row's CIELAB with a spread: the parameters drawn from their posterior $\theta_d$ ($D$ = 400 draws, the fixed seed
`diffwash predict` uses) pushed through the model, plus the model error $s_c$ of the row's kind. Stack the draws'
deviations of every row (candidates and queries, three CIELAB components each) as the columns of $Y$
($D \times 3N$) and write $A = Y/\sqrt D$, so that the rows' predictive covariance is $A^\top A$: an ensemble,
i.e. the posterior linearised statistically over its own draws rather than at its mode (a parameter fitted at an
edge, log S of a paint fitted to S = 0, is flat at the mode but not over the draws: `diffwash._regions.lab_draws`).

**Measuring a candidate** $c$ (columns $a_c$, $D \times 3$) observes its colour with noise
$R_c = (s_{k(c)}^2 + r^2)\, I_3$: the model error of its kind now ($s_{unseen}$ for a pair never measured
mixed: that pair's departure from Duncan's law is noise to the pigments' parameters, and the pair terms the
refit adds for it absorb it), plus $r^2$, the mean square per CIELAB axis of the library's own rows about its
fit (the fit record's `de_ab`; what a repeat of a measured row would scatter by). In the ensemble's weight
space (prior $\mathcal N(0, I_D)$) the Gaussian update is

$$ W \leftarrow W - W a_c (R_c + a_c^\top W a_c)^{-1} a_c^\top W, \qquad W_0 = I_D, $$

and the rows' covariance becomes $A^\top W A$. The parameter part of a candidate's **score** is the
reduction of the queries' mean predictive variance (CIELAB units squared, $\Delta L^2 + \Delta a^2 + \Delta b^2$),

$$ \frac1Q \operatorname{tr}\big((R_c + a_c^\top W a_c)^{-1} a_c^\top W G W a_c\big), \qquad
   G = \textstyle\sum_q a_q a_q^\top . $$

A measured mixture also makes its set of paints *seen* (`diffwash._regions.kinds`): the refit fits pair terms
for it, and its queries' model error drops from $s_{unseen}$ to $s_{seen}$; that is the score's second part,
$\frac1Q \sum_q 3\,\max(0, s_{k(q)}^2 - s_{k'(q)}^2)$. Both parts are $\geq 0$. Picks are greedy: each
choice updates $W$ and the seen sets before the next is scored, so a second row of a pair just picked is
scored as a `seen` row that adds no kind change. After each pick, the queries' mean `de2000_90` is recomputed
as `diffwash predict` computes it, from the transformed draws $L^\top Y$ ($W = L L^\top$, an ensemble square root) and the
updated kinds: the expected mean `de2000_90` after measuring the rows ranked so far (the mean over queries
that have a region).

Linear-Gaussian in the ensemble: it expects the measurement to shrink the spread, whatever value it turns
out to have; it cannot foresee that a refit moves the predictions (a better fit can be a *wider* region when
the refit finds a larger model error). With 400 draws, the correlation between two rows that share nothing
is estimated as about $\pm 0.05$ rather than 0, so a candidate far from every query still scores a little.

**Reference:** D. J. C. MacKay, "Information-based objective functions for active data selection", Neural
Computation 4 (1992); ensemble square-root update: M. K. Tippett et al., Monthly Weather Review 131 (2003).
"""

from __future__ import annotations

import csv
import io as _stdio
import os
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from ... import _regions
from ..._errors import DiffwashError
from ..._io import atomic_path
from ...library import Library, _as_queries, load_library
from ...measurements import Queries

__all__ = ["Pick", "Suggestions", "suggest", "write_suggestions"]

#: The smallest measurement noise per CIELAB axis (keeps the update well posed for a library without a fit record).
NOISE_FLOOR = 1e-3


@dataclass(frozen=True)
class Pick:
    """One ranked candidate.

    **Fields:**

    - `rank`: 1 for the first to measure.
    - `row`: its index in the candidate table (0-based); `line`: its line in the file (None for rows given in Python).
    - `pigment`, `amount`, `ground`: the row as a table writes it.
    - `score`: how much measuring it (after the ones ranked above) shrinks the queries' mean predictive
      variance, CIELAB units squared (module docstring); >= 0.
    - `mean_de2000_90`: the queries' expected mean `de2000_90` once it and the ones ranked above are measured.
    """

    rank: int
    row: int
    line: int | None
    pigment: str
    amount: str
    ground: str
    score: float
    mean_de2000_90: float


@dataclass(frozen=True)
class Suggestions:
    """The result of `suggest`: the picks in order, and where the queries stand now.

    **Fields:**

    - `picks`: the `Pick`s, best first.
    - `mean_de2000_90`: the queries' mean `de2000_90` now (as `diffwash predict` writes it).
    - `variance`: the queries' mean predictive variance now, CIELAB units squared.
    - `candidates`, `queries`: how many rows each table had.
    """

    picks: tuple[Pick, ...]
    mean_de2000_90: float
    variance: float
    candidates: int
    queries: int

    def csv_text(self) -> str:
        """The ranked table: `rank,pigment,amount,ground,score,mean_de2000_90,line`."""
        buf = _stdio.StringIO()
        w = csv.writer(buf, lineterminator="\n")
        w.writerow(["rank", "pigment", "amount", "ground", "score", "mean_de2000_90", "line"])
        for p in self.picks:
            w.writerow([p.rank, p.pigment, p.amount, p.ground, f"{p.score:.6f}", _fmt(p.mean_de2000_90),
                        "" if p.line is None else p.line])  # fmt: skip
        return buf.getvalue()


def _fmt(v: float) -> str:
    return f"{v:.4f}" if np.isfinite(v) else ""


def write_suggestions(path: str | os.PathLike, result: Suggestions) -> None:
    """Write `result.csv_text()` to `path` atomically."""
    with atomic_path(path) as tmp:
        Path(tmp).write_text(result.csv_text(), encoding="utf-8")


def _rows(table: Any, what: str) -> Queries:
    """A candidate or query table (a path, `Queries` or `Measurements`) as `Queries`; an empty one is refused."""
    try:
        q = _as_queries(table, None, None)
    except DiffwashError as e:
        if e.problem == "has no rows to predict":  # what the query reader says of a table without rows
            raise DiffwashError(f"has no {what} rows", file=e.file) from None
        raise
    if len(q) == 0:
        raise DiffwashError(f"has no {what} rows", file=q.path, field=None if q.path else what)
    return q


def _draws(lib: Library, q: Queries) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The rows' predicted CIELAB (N, 3), the posterior draws' deviations from it (D, N, 3), and their layers'
    amounts (N, L, P); every call draws the same parameters (`lab_draws`' fixed seed), so the deviations of separate
    calls form one ensemble."""
    A = lib.layer_amounts(q.pigments, q.amounts, q.layers, file=q.path, lines=q.lines)
    G = lib.ground_matrix(q.ground, file=q.path, lines=q.lines)
    lab = replace(lib, posterior=None).predict(q).lab  # the colour alone (its regions are computed here)
    return lab, _regions.lab_draws(lib.posterior, lib.palette, A, G, lib.k2, lib.observation.lab), A


def _residual_noise(lib: Library) -> float:
    """r^2: the mean square per CIELAB axis of the library's rows about its fit (its record's `de_ab`), or 0."""
    rows = (lib.fit or {}).get("rows") if isinstance(lib.fit, dict) else None
    de = [r.get("de_ab") for r in rows or [] if isinstance(r, dict)]
    de = np.array([d for d in de if isinstance(d, (int, float)) and np.isfinite(d)], np.float64)
    return float(np.mean(de**2) / 3) if len(de) else 0.0


def _mixed_sets(names: tuple[str, ...], A: np.ndarray) -> frozenset[tuple[str, ...]]:
    """The sets of paints a row mixes within one layer (sorted, lower case; paints at amount 0 left out), from its
    layers' amounts `A` (L, P) of the library's paints `names`: what measuring it makes seen."""
    sets = (tuple(sorted(names[i].lower() for i in np.flatnonzero(layer > 0))) for layer in A)
    return frozenset(s for s in sets if len(s) > 1)


class _State:
    """The greedy selection's state: the ensemble weight matrix W = L L^T (L: the ensemble's square-root
    transform, kept so that the draws can be conditioned) and the seen sets (module docstring)."""

    def __init__(self, lib: Library, cand: Queries, qry: Queries):
        post = lib.posterior
        self.lab_q, Yq, amounts_q = _draws(lib, qry)
        _, Yc, amounts_c = (self.lab_q, Yq, amounts_q) if qry is cand else _draws(lib, cand)
        D = Yq.shape[0]
        self.Yq, self.Ac, self.Aq = Yq, Yc / np.sqrt(D), Yq / np.sqrt(D)
        self.G = np.einsum("dqi,eqi->de", self.Aq, self.Aq)
        self.L = np.eye(D)  # W = L L^T
        self.error = {k: post.model_error.get(k, np.nan) for k in _regions.KINDS}
        self.r2 = _residual_noise(lib)
        self.seen = {tuple(sorted(n.lower() for n in s)) for s in post.seen}
        self.cand, self.qry = cand, qry
        self.laid_c, self.laid_q = _regions.laid(lib.palette, amounts_c), _regions.laid(lib.palette, amounts_q)
        self.mixed = [_mixed_sets(lib.palette.names, a) for a in amounts_c]

    def s2(self, kinds: list[str]) -> np.ndarray:
        """The squared model error of each kind (NaN where the library measured none)."""
        return np.array([self.error[k] for k in kinds], np.float64) ** 2

    def noise(self) -> np.ndarray:
        """Each candidate's measurement noise variance per CIELAB axis (kinds as they stand), shape (C,)."""
        return np.nan_to_num(self.s2(_regions.kinds(self.laid_c, self.seen))) + self.r2 + NOISE_FLOOR**2

    def kind_gain(self) -> np.ndarray:
        """Each candidate's second score part: the queries' mean model-error variance it removes, shape (C,)."""
        now = self.s2(_regions.kinds(self.laid_q, self.seen))
        out = np.zeros(len(self.cand))
        for sets in set(self.mixed):
            new = sets - self.seen
            if not new:
                continue
            after = self.s2(_regions.kinds(self.laid_q, self.seen | new))
            drop = np.where(np.isfinite(now) & np.isfinite(after), np.maximum(now - after, 0.0), 0.0)
            gain = 3 * float(np.sum(drop)) / len(self.qry)
            out[[i for i, m in enumerate(self.mixed) if m == sets]] = gain
        return out

    def scores(self) -> tuple[np.ndarray, np.ndarray]:
        """Each candidate's score, and per candidate R_c + a_c^T W a_c (C, 3, 3)."""
        D, C, _ = self.Ac.shape
        V = (self.L @ (self.L.T @ self.Ac.reshape(D, -1))).reshape(D, C, 3)
        S = np.einsum("dci,dcj->cij", self.Ac, V) + self.noise()[:, None, None] * np.eye(3)
        T = np.einsum("dci,dcj->cij", V, (self.G @ V.reshape(D, -1)).reshape(D, C, 3))
        param = np.trace(np.linalg.solve(S, T), axis1=1, axis2=2) / len(self.qry)
        return np.maximum(param, 0.0) + self.kind_gain(), S

    def measure(self, c: int, S: np.ndarray) -> None:
        """Condition on candidate `c` (`S` from `scores`): W - W a (R + a^T W a)^-1 a^T W, as L (I - Q K Q^T),
        Q R_b the QR factors of B = L^T a and I - K the square root of I - R_b S^-1 R_b^T (3 x 3); then the
        seen sets."""
        Q, Rb = np.linalg.qr(self.L.T @ self.Ac[:, c, :])
        lam, U = np.linalg.eigh(Rb @ np.linalg.solve(S[c], Rb.T))
        K = (U * (1 - np.sqrt(np.clip(1 - lam, 0.0, None)))) @ U.T
        self.L = self.L - (self.L @ Q) @ K @ Q.T
        self.seen |= self.mixed[c]

    def variance(self) -> float:
        """The queries' mean predictive variance now (parameters and model error), CIELAB units squared."""
        s2 = np.nan_to_num(self.s2(_regions.kinds(self.laid_q, self.seen)))
        return float((np.sum((self.L.T @ self.G) * self.L.T) + 3 * np.sum(s2)) / len(self.qry))

    def mean_de2000_90(self) -> float:
        """The queries' mean `de2000_90` under the current W and seen sets (NaN if no query has a region)."""
        s = np.sqrt(self.s2(_regions.kinds(self.laid_q, self.seen)))
        ok = np.isfinite(s)
        if not ok.any():
            return float("nan")
        spread = np.einsum("ed,eni->dni", self.L, self.Yq[:, ok])  # covariance Y^T L L^T Y
        return float(np.mean(_regions.radius90(self.lab_q[ok], spread, s[ok])))


def suggest(
    library: Library | str | os.PathLike,
    candidates: Any,
    n: int = 5,
    queries: Any = None,
    *,
    progress: Callable[[int, int], None] | None = None,
) -> Suggestions:
    r"""Rank candidate swatches by how much measuring them would shrink the queries' 90% regions.

    **Arguments:**

    - `library`: a `diffwash.library.Library` with a posterior (`"uncertainty"`: what `fit-swatch` stores for
      swatch-card photos, and `fit-swatch --table` for a spectral table or an RGB one with mixtures), or its file.
    - `candidates`: the rows one could paint and measure: a query table's path (`pigment,amount,ground`; a
      measurement table works too, its values unread), or a `diffwash.measurements.Queries`/`Measurements`.
      Single paints, mixtures (`A+B`), glaze stacks (`A/B`), on any ground of the library.
    - `n`: how many to pick (greedily, each conditioning the next; at most the number of candidates).
    - `queries`: the rows whose regions should shrink, the same kinds of table; None: the candidates themselves.
    - `progress`: called as `progress(i, n)` after each pick.

    **Returns:** `Suggestions` (its `picks` best first, each with its score and the queries' expected mean
    `de2000_90` once it and the ones above are measured). A library without a posterior, an empty table, a
    pigment or ground the library lacks, `n` < 1 raise a `DiffwashError` naming the file and the field.
    """
    lib = library if isinstance(library, Library) else load_library(library)
    where = None if isinstance(library, Library) else os.fspath(library)
    if lib.posterior is None:
        raise DiffwashError("has no posterior (\"uncertainty\"): suggest needs the one diffwash fit-swatch --table "
                            "stores for a spectral table (refined in CIEDE2000, the default) or an RGB table with "
                            "mixtures or glaze stacks, or diffwash fit-swatch for swatch-card photos (noise-weighted, "
                            "the default); an RGB table of single paints, --refine none, another --loss and older "
                            "pigment files give none", file=where, field="uncertainty")  # fmt: skip
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
        raise DiffwashError(f"must be a whole number >= 1, got {n!r}", field="n")
    cand = _rows(candidates, "candidate")
    qry = cand if queries is None else _rows(queries, "query")
    st = _State(lib, cand, qry)
    before, var0 = st.mean_de2000_90(), st.variance()
    picks: list[Pick] = []
    taken = np.zeros(len(cand), bool)
    for k in range(min(int(n), len(cand))):
        score, S = st.scores()
        c = int(np.argmax(np.where(taken, -np.inf, score)))
        taken[c] = True
        st.measure(c, S)
        text = cand.row_text(c)
        line = None if cand.lines is None else int(cand.lines[c])
        picks.append(Pick(k + 1, c, line, text[0], text[1], str(cand.ground[c]), float(score[c]), st.mean_de2000_90()))
        if progress is not None:
            progress(k + 1, min(int(n), len(cand)))
    return Suggestions(tuple(picks), before, var0, len(cand), len(qry))
