r"""90% regions of a library's predictions: its parameters' posterior and its model error, in CIEDE2000.

A library fitted by `diffwash.fit.fit_mixtures` may carry an `uncertainty` record
(`Posterior`): the Laplace (Gauss-Newton) covariance of its parameters
$\theta = (\log K_{i,b}, \log S_{i,b}, \log\gamma_i)$ and the model error it measured
on its own table. A prediction's colour is then uncertain by

$$ \mathrm{Lab}_n(\theta_d) - \mathrm{Lab}_n(\hat\theta) + s_c\, e_d, \qquad
   \theta_d \sim \mathcal N(\hat\theta, \Sigma_\theta),\ e_d \sim \mathcal N(0, I_3), $$

the parameters drawn from their posterior and pushed through the model (not linearised:
see `lab_draws`), $s_c$ the model error of the row's kind $c$: a single paint, a mixture of a set of paints the
table measured mixed (`seen`), one it never did of paints it measured in other mixtures (`unseen`), or one
holding a paint it never measured mixed at all (`unmixed`). `de2000_90` is the
CIEDE2000 radius around the prediction that holds 90% of those draws (`DRAWS`, a fixed
seed; CIEDE2000 is not a Euclidean distance in Lab, hence Monte Carlo).

$\Sigma_\theta$ is stored as a low-rank factor and a diagonal,
$\Sigma_\theta \approx F F^\top + \mathrm{diag}(d)$ (the format: `diffwash.library`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from . import colorimetry, mixing
from ._errors import DiffwashError

__all__ = ["KINDS", "Posterior", "kinds", "laid", "lab_draws", "radius90", "de2000_90"]

#: The kinds of row a model error is kept for (`kinds`).
KINDS = ("single", "seen", "unseen", "unmixed")
#: Monte Carlo draws (of the parameters, each with a draw of the model error) per row, and their seed.
DRAWS = 400
SEED = 0
#: The share a region holds.
LEVEL = 0.9


@dataclass(frozen=True)
class Posterior:
    """A library's parameter covariance and model error (module docstring).

    **Fields:**

    - `factor`: $F$, shape (n, r), n = 2 P B + P (per pigment log K over the bands, then log S, then log gamma:
      `[logK_0, ..., logK_{P-1}, logS_0, ..., logS_{P-1}, log_gamma]`, each block pigment by pigment).
    - `diagonal`: $d$, shape (n,).
    - `model_error`: kind (`KINDS`) -> $s_c$ (CIELAB units per axis); a kind absent: no region for it.
    - `seen`: the sets of pigments the table measured mixed (sorted name tuples).
    - `record`: how each was estimated (JSON-ready).
    """

    factor: np.ndarray
    diagonal: np.ndarray
    model_error: dict[str, float]
    seen: tuple[tuple[str, ...], ...] = ()
    record: dict[str, Any] | None = None

    def to_dict(self) -> dict[str, Any]:
        return {"parameters": "per pigment: log K per band, then log S per band, then log gamma",
                "factor": np.round(self.factor, 8).tolist(), "diagonal": np.round(self.diagonal, 10).tolist(),
                "model_error": {k: float(v) for k, v in self.model_error.items()},
                "seen": [list(s) for s in self.seen], "record": self.record}  # fmt: skip

    @staticmethod
    def from_dict(d: Any, n: int, path: Any = None) -> Posterior:
        """From the library's `"uncertainty"` object; `n` parameters expected."""
        where = "uncertainty"
        if not isinstance(d, dict):
            raise DiffwashError("must be an object", file=path, field=where)
        try:
            F = np.asarray(d.get("factor"), np.float64)
            diag = np.asarray(d.get("diagonal"), np.float64)
        except (TypeError, ValueError):
            F = diag = np.empty(0)
        if F.ndim != 2 or F.shape[0] != n or diag.shape != (n,) or not np.all(np.isfinite(F)) or np.any(~(diag >= 0)):
            raise DiffwashError(f"factor must be {n} rows of numbers and diagonal {n} numbers >= 0", file=path,
                                field=f"{where}.factor")  # fmt: skip
        me = d.get("model_error")
        if not isinstance(me, dict) or any(k not in KINDS or not _nonneg(v) for k, v in me.items()):
            raise DiffwashError(f"must map {', '.join(KINDS)} to numbers >= 0", file=path, field=f"{where}.model_error")
        seen = d.get("seen", [])
        if not isinstance(seen, list) or not all(isinstance(s, list) and all(isinstance(x, str) for x in s) for s in seen):
            raise DiffwashError("must be a list of lists of pigment names", file=path, field=f"{where}.seen")
        return Posterior(F, diag, {k: float(v) for k, v in me.items()}, tuple(tuple(sorted(s)) for s in seen),
                         d.get("record"))  # fmt: skip


def _nonneg(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and bool(np.isfinite(v)) and v >= 0


def kinds(pigments, seen) -> list[str]:
    """Each row's kind: `single` (one distinct pigment), `seen` (a set measured mixed), `unmixed` (a mixture holding
    a pigment the table never measured mixed with anything), else `unseen` (pigments each measured mixed, never
    together)."""
    sets = {tuple(sorted(x.lower() for x in s)) for s in seen}
    mixed = {x for s in sets for x in s}
    out = []
    for names in pigments:
        key = tuple(sorted({n.lower() for n in names}))
        if len(key) <= 1:  # one pigment, or none (the bare ground)
            out.append("single")
        elif key in sets:
            out.append("seen")
        else:
            out.append("unseen" if set(key) <= mixed else "unmixed")
    return out


def theta(palette: mixing.Palette) -> jnp.ndarray:
    """The posterior's parameter vector of a palette (`Posterior.factor`'s order)."""
    return jnp.concatenate([jnp.log(palette.K).ravel(), jnp.log(palette.S).ravel(), jnp.log(palette.law.gamma)])


def _with_theta(palette: mixing.Palette, th) -> mixing.Palette:
    P, B = palette.K.shape
    K, S, g = jnp.exp(th[: P * B]).reshape(P, B), jnp.exp(th[P * B : 2 * P * B]).reshape(P, B), jnp.exp(th[2 * P * B :])
    return eqx.tree_at(lambda p: (p.K, p.S, p.law.gamma), palette, (K, S, g))


def lab_draws(post: Posterior, palette: mixing.Palette, A, G, k2, lab_of, draws: int = DRAWS) -> np.ndarray:
    """CIELAB of each row under `draws` parameter vectors drawn from the posterior (fixed seed), minus the
    prediction at the fitted parameters: shape (draws, N, 3). Sampling, not the delta method: a parameter the
    data leave free may sit where the colour is flat in it (log S of a pigment fitted to S = 0), and its
    linearisation would then say it does not matter."""
    th0 = theta(palette)
    rng = np.random.default_rng(SEED)
    z = rng.standard_normal((draws, post.factor.shape[1]))
    u = rng.standard_normal((draws, post.diagonal.shape[0]))
    dev = z @ post.factor.T + u * np.sqrt(post.diagonal)
    ths = jnp.clip(th0 + jnp.asarray(dev, th0.dtype), -30.0, 30.0)
    out = _draw_labs(palette, jnp.asarray(A, th0.dtype), jnp.asarray(G, th0.dtype), jnp.asarray(k2, th0.dtype),
                     lab_of, ths)  # fmt: skip
    return np.asarray(out, np.float64)


@eqx.filter_jit
def _draw_labs(palette, A, G, k2, lab_of, ths):
    lab0 = lab_of(palette.stack_reflectance(A, G, k2))
    one = lambda th: lab_of(_with_theta(palette, th).stack_reflectance(A, G, k2)) - lab0  # noqa: E731
    return jax.lax.map(one, ths)


def radius90(lab: np.ndarray, spread: np.ndarray, scale: np.ndarray, level: float = LEVEL) -> np.ndarray:
    """The CIEDE2000 radius around each `lab` (N, 3) that holds `level` of `lab + spread + scale e`, `spread`
    the parameter draws' deviations (D, N, 3), `e` standard normal in CIELAB (fixed seed), shape (N,). Every row
    takes the same draws of `e` (as of the parameters): two rows that lay down the same paint get the same radius,
    not two Monte Carlo estimates of it."""
    lab = np.asarray(lab, np.float64)
    if len(lab) == 0:
        return np.zeros(0)
    e = np.random.default_rng(SEED + 1).standard_normal((spread.shape[0], 1, 3))
    samples = lab[None] + spread + np.asarray(scale, np.float64)[None, :, None] * e
    de = np.asarray(colorimetry.delta_e_2000(jnp.asarray(lab[None]), jnp.asarray(samples)), np.float64)
    return np.quantile(de, level, axis=0)


def laid(palette: mixing.Palette, A) -> list[tuple[str, ...]]:
    """The pigments each row of amounts `A` (N, P) or stacks (N, L, P) lays down (an amount above 0): what its kind
    depends on (`P1+P4` at `0.02+0` is P1 alone, and `P1/P4` at `0.02/0` too)."""
    on = np.asarray(A).reshape(len(A), -1, len(palette.names)).sum(axis=1) > 0
    return [tuple(palette.names[i] for i in np.flatnonzero(row)) for row in on]


def de2000_90(post: Posterior, palette: mixing.Palette, A, G, k2, lab_of, lab) -> np.ndarray:
    """Each row's `de2000_90` (NaN where the library measured no model error for its kind), its kind from the
    pigments the row lays down (`laid`)."""
    s = np.array([post.model_error.get(k, np.nan) for k in kinds(laid(palette, A), post.seen)])
    ok = np.isfinite(s)
    out = np.full(len(lab), np.nan)
    if ok.any():
        spread = lab_draws(post, palette, np.asarray(A)[ok], np.asarray(G)[ok], k2, lab_of)
        out[ok] = radius90(np.asarray(lab)[ok], spread, s[ok])
    return out
