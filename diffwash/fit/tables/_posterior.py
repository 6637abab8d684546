r"""A spectral mixture fit's Laplace posterior and the model error it measures on its own table.

**Posterior.** At the CIEDE2000 refinement's minimum (`diffwash.fit.tables._seen`) the
Gauss-Newton matrix $H = J^\top J + \lambda^2 I + J_p^\top J_p$ (the rows' colour
residuals, the ridge that carries what the spectral stage learnt, the priors of
`diffwash.fit.tables._priors`) is the posterior precision in the residuals' noise scale
$\sigma^2$ (their mean square per CIELAB component, from the fit):
$\Sigma = \sigma^2 H^{-1}$, marginalised onto $\theta = (\log K, \log S, \log\gamma)$
and kept as its leading eigenvectors plus a diagonal (`diffwash._regions.Posterior`).

**Each pigment's block is bounded by its own rows** (`shrink_per_pigment`): where
the posterior's draws alone hold more than 90% of a pigment's own single-paint
rows, that pigment's block of the covariance is scaled down until they hold 90%.
The Laplace approximation is the curvature at the fit, and a parameter fitted where
the colour is flat in it (log S of a paint fitted to S near 0) gets a variance its
own rows refute a little further out; $\sigma$ is estimated robustly (the median
absolute residual).

**Model error** $s_c$ of a kind of row: the smallest that makes the 90% regions
(`diffwash._regions`) hold 90% of its rows: of the table's own rows for `single`
and `seen`; of held-out rows for `unseen` (leave-pairs-out folds, `pair_folds`) and
`unmixed` (folds that each hold out every mixture of one paint, where the table has
a paint it never mixed). Each fold is **refitted from the fit's own start** with its
rows weighed 0 (`refit_held_out`): the log-reflectance stage (at most `FOLD_STEPS`
steps) and the CIEDE2000 refinement (at most `FOLD_REFINE_STEPS`) with its ridge
towards the fold's own spectra; a paint's folds run as far as the fit itself
(`PAINT_FOLD_STEPS`). Nothing of the full fit, which saw the held-out rows, enters a
fold. (A first version took a few damped Gauss-Newton steps from the
full fit with the ridge pulling towards it, an approximate cross-validation after
Rad and Maleki: its regions held 72.8% of new pairs' rows instead of 90%.)

**Reference:** K. Rad and A. Maleki, "A scalable estimate of the out-of-sample
prediction error via approximate leave-one-out cross-validation", JRSS B 82 (2020).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from ... import _regions, colorimetry
from . import _seen
from .._bandlsq import BandLevenbergMarquardt, gauss_newton_blocks

__all__ = ["laplace", "marginal_covariance", "factored", "refit_held_out", "calibrate_scale", "shrink_per_pigment",
           "owners", "scaled"]

#: Leading eigenvectors of the covariance kept (the rest: its diagonal).
RANK = 24
#: A fold's refit: at most this many steps of the log-reflectance stage, and of the CIEDE2000 refinement.
FOLD_STEPS = 40
FOLD_REFINE_STEPS = 8
#: The folds that hold out every mixture of one paint (`unmixed`) run as far as the fit itself (`fit_mixtures`'
#: 400 steps, `_seen.refine_in_de2000`'s 100): they are few (one per paint mixed), and stopped early they stay
#: near the fit's start, which predicts a never-mixed paint's mixtures better than a converged fit does (notebook
#: 06: P1's mixtures at 3.8 mean CIEDE2000 after 40 + 8 steps, 17.7 converged), so the error came out too small.
PAINT_FOLD_STEPS = 400
PAINT_FOLD_REFINE_STEPS = 100


def _theta_index(B: int, P: int, gamma: bool) -> np.ndarray:
    """Positions in the fit's `(band.ravel(), shared)` of theta = (log K, log S per pigment, then log gamma)."""
    i, b = np.meshgrid(np.arange(P), np.arange(B), indexing="ij")
    k, s = (b * 2 * P + i).ravel(), (b * 2 * P + P + i).ravel()
    g = B * 2 * P + np.arange(P) if gamma else np.zeros(0, int)
    return np.concatenate([k, s, g])


def laplace(fn, y, n_rows: int, P: int, gamma: bool, rank: int = RANK):
    """The posterior of theta at `y` under the spectral stage's problem `fn` (`(band, shared), None -> (per band
    (B, M), shared)`, its first `n_rows` columns the rows' log-reflectance residuals): `(factor, diagonal, sigma)`.
    Without a fitted amount law the log gamma block is 0 (known)."""
    band, shared = y
    B, Q = band.shape
    G = shared.shape[0]
    sigma2, Hbb, Hbg, Hgg = gauss_newton_blocks(fn, y, n_rows)
    n = B * Q + G
    H = np.zeros((n, n))
    for b in range(B):
        sl = slice(b * Q, (b + 1) * Q)
        H[sl, sl] = Hbb[b]
        H[sl, B * Q :] = Hbg[b]
        H[B * Q :, sl] = Hbg[b].T
    H[B * Q :, B * Q :] = Hgg
    idx = _theta_index(B, P, gamma)
    m = 2 * P * B + P
    full = np.zeros((m, m))
    full[: len(idx), : len(idx)] = marginal_covariance(H, idx, sigma2)
    return (*factored(full, rank), float(np.sqrt(sigma2)))


def marginal_covariance(H: np.ndarray, idx: np.ndarray, sigma2: float) -> np.ndarray:
    r"""$\sigma^2 H^{-1}$ on the parameters `idx` (the others marginalised out), through H's eigendecomposition
    with its eigenvalues floored at 1e-9 of the largest (a direction nothing pins stays finite)."""
    lam, V = np.linalg.eigh(0.5 * (H + H.T))
    lam = np.maximum(lam, 1e-9 * max(lam.max(), 1e-30))
    Vt = V[idx]
    return sigma2 * (Vt / lam) @ Vt.T


def factored(full: np.ndarray, rank: int = RANK) -> tuple[np.ndarray, np.ndarray]:
    """A covariance as its `rank` leading eigenvectors (scaled: the factor $F$) and the diagonal they leave."""
    ev, U = np.linalg.eigh(full)
    top = np.argsort(ev)[::-1][: min(rank, full.shape[0])]
    F = U[:, top] * np.sqrt(np.maximum(ev[top], 0))
    return F, np.maximum(np.diag(full) - np.sum(F * F, axis=1), 0.0)


def refit_held_out(spectral, start, pb: _seen._Problem, folds: list[np.ndarray], *, rtol: float,
                   steps: int = FOLD_STEPS, refine_steps: int = FOLD_REFINE_STEPS, bound: int = 0,
                   progress: Callable[[int, int], None] | None = None,
                   predict: Callable[[Any, np.ndarray], np.ndarray] | None = None) -> list[np.ndarray]:  # fmt: skip
    """Each fold's rows' CIELAB as predicted by the fit refitted without them, in fold order.

    Each fold is the fit's own two stages run again from the fit's own `start` (which a table's single paints
    fix: every fold keeps them), its rows weighed 0: the log-reflectance stage `spectral`
    (`BandLevenbergMarquardt`, at most `steps` steps), then the CIEDE2000 refinement of `pb` (at most
    `refine_steps`) with its ridge towards that fold's own log-reflectance spectra. Nothing of the full fit,
    which saw the fold's rows, enters a fold; the folds and the fit share its compiled programs (the rows' weights
    are their argument). `progress(i, n)` is called as fold i of n begins. `predict(y, test)`: the held-out rows'
    CIELAB from the fold's parameters `y` (default: the pigments' alone, `pb.reflect`), for a fit whose
    predictions hold more than its pigments (pair terms, fitted to the fold's own rows). `bound`: the `max_steps` the
    fit's own log-reflectance solve was compiled with; folds capped at no more steps run under it, capped by the
    solver (`BandLevenbergMarquardt.cap`), and reuse its compiled program (one compilation fewer per fit)."""
    solver = BandLevenbergMarquardt(rtol=rtol, atol=rtol, cap=steps)
    bound = max(bound, steps)

    def one(test):
        test = np.asarray(test)
        w = jnp.asarray(~test, start[0].dtype)
        fold = eqx.tree_at(lambda f: f.w, spectral, w, is_leaf=lambda x: x is None)
        sol = optx.least_squares(fold, solver, start, max_steps=bound, throw=False)
        y, _, _ = _seen.refine_in_de2000(pb.reflect, pb.lab_of, pb.lab_target, sol.value, ridge=pb.ridge,
                                         shared_prior=pb.shared_prior, max_steps=refine_steps,
                                         rtol=max(rtol, 1e-5), weights=w, basis=pb.basis)  # fmt: skip
        if predict is not None:
            return np.asarray(predict(y, test), np.float64)
        return np.asarray(pb.lab_of(pb.reflect(*y)), np.float64)[test]

    out = []
    for i, test in enumerate(folds):
        if progress is not None:
            progress(i + 1, len(folds))
        out.append(one(test))
    return out


def conformal_level(n: int, level: float = _regions.LEVEL) -> float:
    """The share of `n` rows a model error fitted on them must hold so that a new row of their kind falls inside
    its region with probability `level`: `ceil((n + 1) level) / n`, at most 1 (split conformal prediction's
    finite-sample quantile; Vovk et al. 2005). On 1,700 rows it is `level`; on 9 rows, all 9 of them."""
    return min(1.0, float(np.ceil((n + 1) * level)) / max(n, 1))


def calibrate_scale(lab_true: np.ndarray, lab_pred: np.ndarray, spread: np.ndarray, level: float = _regions.LEVEL,
                    de: np.ndarray | None = None, share: float | None = None) -> float:  # fmt: skip
    """The smallest model error s (CIELAB units per axis) whose `level` regions (`_regions.radius90` with the
    parameter draws' `spread`) hold `share` of the rows (default: `level`; `conformal_level` for a few rows);
    `de`: the rows' CIEDE2000 errors, where not `lab_pred`'s (a row's error when it is left out of the fit)."""
    if len(lab_true) == 0:
        return float("nan")
    if de is None:
        de = np.asarray(colorimetry.delta_e_2000(jnp.asarray(lab_true), jnp.asarray(lab_pred)), np.float64)
    share = level if share is None else share

    def held(s):
        return np.mean(de <= _regions.radius90(lab_pred, spread, np.full(len(de), s), level=level))

    lo, hi = 0.0, 1.0
    while held(hi) < share and hi < 200:
        lo, hi = hi, 2 * hi
    for _ in range(12):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if held(mid) < share else (lo, mid)
    return 0.0 if held(0.0) >= share else hi


def owners(P: int, B: int) -> np.ndarray:
    """The pigment each entry of theta belongs to (`_regions.Posterior.factor`'s order), shape (2 P B + P,)."""
    return np.concatenate([np.repeat(np.arange(P), B), np.repeat(np.arange(P), B), np.arange(P)])


def scaled(F: np.ndarray, diag: np.ndarray, a: np.ndarray, owner: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The covariance $C (F F^T + diag) C$, $C$ = diag(sqrt(a) of each entry's pigment), as a factor and diagonal."""
    c = np.asarray(a, np.float64)[owner]
    return F * np.sqrt(c)[:, None], diag * c


def shrink_per_pigment(draw, row_pigment: np.ndarray, P: int, lab_true: np.ndarray, lab_pred: np.ndarray,
                       level: float = _regions.LEVEL) -> np.ndarray:  # fmt: skip
    r"""Each pigment's factor $a_i \le 1$ on its block of the posterior covariance, so that its draws alone
    (`draw(a)` -> spread (D, N, 3) of the rows, `a` of shape (P,)) hold at most `level` of its own single-paint
    rows (`row_pigment`: each row's pigment), i.e. are no wider than those rows allow: 1 where they already hold
    fewer, or the pigment has no single rows.

    The Laplace covariance is the curvature at the fit: a parameter fitted where the colour is flat in it (log S
    of a paint fitted to S near 0) gets a variance that the same rows refute a little further out (a draw with S
    of 1 makes that paint opaque, and its own rows' colours move by tens of CIEDE2000). Bounding each pigment's
    draws by its own rows keeps the posterior where the data still hold; what the rows cannot tell (how such a
    paint mixes) is then the model error's to carry (`unmixed`, measured by refitting without a paint's
    mixtures). A pigment's single rows depend on its own parameters only, so every pigment is bisected at once."""
    de = np.asarray(colorimetry.delta_e_2000(jnp.asarray(lab_true), jnp.asarray(lab_pred)), np.float64)
    row_pigment = np.asarray(row_pigment)
    count = np.bincount(row_pigment, minlength=P)

    def held(a):
        inside = de <= _regions.radius90(lab_pred, draw(a), np.zeros(len(de)), level=level)
        return np.bincount(row_pigment, weights=inside, minlength=P) / np.maximum(count, 1)

    if len(de) == 0:
        return np.ones(P)
    free = (held(np.ones(P)) > level) & (count > 0)
    lo, hi = np.zeros(P), np.ones(P)
    for _ in range(12):  # 12 halvings: a factor down to 2.4e-4 (a standard deviation down to 1.6%)
        if not free.any():
            break
        mid = 0.5 * (lo + hi)
        below = held(np.where(free, mid, 1.0)) < level
        lo, hi = np.where(free & below, mid, lo), np.where(free & ~below, mid, hi)
    return np.where(free, hi, 1.0)


#: A parameter whose posterior standard deviation (natural log units) exceeds this was left free by the rows:
#: its value came from the fit's start and priors, not from the measurements (a factor of 1.65 either way).
FREE_SD = 0.5


def pigment_report(F: np.ndarray, diag: np.ndarray, names, B: int, mixed: set[str], over_dark: set[str] = frozenset(),
                   spectral: bool = True) -> list[dict]:  # fmt: skip
    """Per pigment: the posterior standard deviation of log K and log S (root mean square over the bands) and of
    log gamma, what the measurements determined, and the measurement that would pin what they did not: the paint
    over black or tinted with white, unless it is in `over_dark` (measured over a dark ground already); for an RGB
    table (`spectral` False), whose three channels leave most of each spectrum to the prior however the paint was
    brushed, a spectrophotometer's reading."""
    sd = np.sqrt(np.sum(F * F, axis=1) + diag)
    P = len(names)
    out = []
    for i, n in enumerate(names):
        k = float(np.sqrt(np.mean(sd[i * B : (i + 1) * B] ** 2)))
        s = float(np.sqrt(np.mean(sd[P * B + i * B : P * B + (i + 1) * B] ** 2)))
        g = float(sd[2 * P * B + i])
        free = [what for what, v in (("absorption", k), ("scattering", s), ("amount law", g)) if v > FREE_SD]
        need = []
        if "scattering" in free or "absorption" in free:
            if n not in over_dark:
                need.append(OVER_DARK)
            if not spectral:
                need.append(SPECTRUM)
        if "amount law" in free:
            need.append("a second amount")
        if n not in mixed:
            need.append("a mixture with another paint (it was never measured mixed)")
        out.append({"name": n, "sd_log_K": round(k, 4), "sd_log_S": round(s, 4), "sd_log_gamma": round(g, 4),
                    "from_the_prior": free, "measure": "; ".join(need)})  # fmt: skip
    return out


#: The measurement that tells a paint's absorption from its scattering.
OVER_DARK = "the paint over black, or a tint with white"
#: The measurement an RGB table lacks to fix a paint's spectra.
SPECTRUM = "its reflectance spectrum (a spectrophotometer's reading: three channels leave most of it to the prior)"


def uncertainty_lines(report: list[dict]) -> list[str]:
    """`pigment_report` as lines for the command line."""
    lines = ["  what the measurements determined (posterior sd in natural log units; > 0.5: left to the prior):"]
    for r in report:
        free = ", ".join(r["from_the_prior"]) or "nothing"
        tail = f"; would pin it: {r['measure']}" if r["measure"] else ""
        lines.append(f"    {r['name']}: log K {r['sd_log_K']:.2f}, log S {r['sd_log_S']:.2f}, log gamma "
                     f"{r['sd_log_gamma']:.2f}; from the prior: {free}{tail}")  # fmt: skip
    return lines
