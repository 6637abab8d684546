r"""A spectral mixture fit's Laplace posterior and the model error it measures on its own table.

**Posterior.** At the CIEDE2000 refinement's minimum (`diffwash.fit._seen`) the
Gauss-Newton matrix $H = J^\top J + \lambda^2 I + J_p^\top J_p$ (the rows' colour
residuals, the ridge that carries what the spectral stage learnt, the priors of
`diffwash.fit._priors`) is the posterior precision in the residuals' noise scale
$\sigma^2$ (their mean square per CIELAB component, from the fit):
$\Sigma = \sigma^2 H^{-1}$, marginalised onto $\theta = (\log K, \log S, \log\gamma)$
and kept as its leading eigenvectors plus a diagonal (`diffwash._regions.Posterior`).

**Model error of pairs never seen mixed**, by approximate leave-pairs-out
cross-validation: for each fold of `pair_folds`, a few damped Gauss-Newton steps
from the full fit with that fold's rows weighed 0 (the same compiled program for
every fold, instead of a fit per fold), then the fold's rows predicted. The
model error $s_c$ of a kind of row is the smallest that makes the 90% regions
(`diffwash._regions`) hold 90% of its rows: of these held-out rows for `unseen`,
of the table's own rows for `single` and `seen`. Where the posterior's draws alone
hold more than 90% of the table's single paints, the covariance is first scaled
down until they hold 90% (`shrink_to_rows`): $\sigma$ is estimated robustly (the
median absolute residual), but the Laplace approximation of a curved problem can
still be far too wide in directions the data leave nearly free.

**Reference:** K. Rad and A. Maleki, "A scalable estimate of the out-of-sample
prediction error via approximate leave-one-out cross-validation", JRSS B 82 (2020).
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .. import _regions, colorimetry
from ._bandlsq import _tangents
from ._seen import _Problem

__all__ = ["laplace", "held_out_lab", "calibrate_scale", "shrink_to_rows"]

#: Leading eigenvectors of the covariance kept (the rest: its diagonal).
RANK = 24
#: Damped Gauss-Newton steps per fold of the approximate cross-validation.
ALO_STEPS = 6


@eqx.filter_jit
def _weighted_normal_equations(pb: _Problem, y, w):
    """`_seen._normal_equations` with the rows' colour residuals weighed by `w` (N,); also the loss."""
    band, shared = y
    B, Q = band.shape
    R, reflect_jvp = jax.linearize(pb.reflect, band, shared)
    dR = jax.vmap(reflect_jvp)(*_tangents(band, shared))
    row = lambda Rn, ln: colorimetry.delta_e_2000_residuals(ln, pb.lab_of(Rn))  # noqa: E731
    E = jax.vmap(jax.jacfwd(row))(R, pb.lab_target) * w[:, None, None]
    r = row(R, pb.lab_target) * w[:, None]
    rb, rg = pb.ridge * (band - pb.band0), pb.shared_prior(shared)
    Jb = jnp.einsum("nib,qnb->nibq", E, dR[:Q]).reshape(-1, B * Q)
    Jg = jnp.einsum("nib,gnb->nig", E, dR[Q:]).reshape(Jb.shape[0], -1)
    Jp = jax.jacfwd(pb.shared_prior)(shared)
    J = jnp.concatenate([Jb, Jg], axis=1)
    H = J.T @ J
    H = H.at[: B * Q, : B * Q].add(pb.ridge**2 * jnp.eye(B * Q, dtype=H.dtype))
    H = H.at[B * Q :, B * Q :].add(Jp.T @ Jp)
    g = J.T @ r.ravel() + jnp.concatenate([pb.ridge * rb.ravel(), Jp.T @ rg])
    loss = jnp.sum(r * r) + jnp.sum(rb * rb) + jnp.sum(rg * rg)
    return H, g, loss, r


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
    (rows, _), lin = jax.linearize(lambda b, s: fn((b, s), None), band, shared)
    Jr, Js = jax.vmap(lin)(*_tangents(band, shared))  # (Q + G, B, M), (Q + G, H)
    Jr, Js, rows = (np.asarray(x, np.float64) for x in (Jr, Js, rows))
    sigma2 = float((1.4826 * np.median(np.abs(rows[:, :n_rows]))) ** 2)  # robust: a few rows fitted badly
    n = B * Q + G
    H = np.zeros((n, n))
    Hbb = np.einsum("qbm,pbm->bqp", Jr[:Q], Jr[:Q])
    Hbg = np.einsum("qbm,gbm->bqg", Jr[:Q], Jr[Q:])
    for b in range(B):
        sl = slice(b * Q, (b + 1) * Q)
        H[sl, sl] = Hbb[b]
        H[sl, B * Q :] = Hbg[b]
        H[B * Q :, sl] = Hbg[b].T
    H[B * Q :, B * Q :] = np.einsum("gbm,hbm->gh", Jr[Q:], Jr[Q:]) + Js[Q:] @ Js[Q:].T
    lam, V = np.linalg.eigh(0.5 * (H + H.T))
    lam = np.maximum(lam, 1e-9 * max(lam.max(), 1e-30))
    idx = _theta_index(B, P, gamma)
    Vt = V[idx]
    m = 2 * P * B + P
    full = np.zeros((m, m))
    full[: len(idx), : len(idx)] = sigma2 * (Vt / lam) @ Vt.T
    ev, U = np.linalg.eigh(full)
    top = np.argsort(ev)[::-1][: min(rank, m)]
    F = U[:, top] * np.sqrt(np.maximum(ev[top], 0))
    diag = np.maximum(np.diag(full) - np.sum(F * F, axis=1), 0.0)
    return F, diag, float(np.sqrt(sigma2))


def held_out_lab(pb: _Problem, y, folds: list[np.ndarray], steps: int = ALO_STEPS) -> list[np.ndarray]:
    """Each fold's rows' CIELAB as predicted by the fit refitted without them (module docstring), in fold order."""
    out = []
    n = pb.lab_target.shape[0]
    for test in folds:
        w = jnp.asarray(~np.asarray(test), y[0].dtype)
        yf, mu = y, 1e-3
        H, g, f, _ = _weighted_normal_equations(pb, yf, w)
        for _ in range(steps):
            d = jnp.diagonal(H)
            delta = jnp.linalg.solve(H + mu * jnp.diag(d + 1e-9 * jnp.mean(d)), -g)
            cand = (yf[0] + delta[: yf[0].size].reshape(yf[0].shape), yf[1] + delta[yf[0].size :])
            Hc, gc, fc, _ = _weighted_normal_equations(pb, cand, w)
            if float(fc) < float(f):
                yf, H, g, f, mu = cand, Hc, gc, fc, max(mu / 3, 1e-9)
            else:
                mu *= 4
        lab = np.asarray(pb.lab_of(pb.reflect(*yf)), np.float64)
        out.append(lab[np.asarray(test)] if n else lab)
    return out


def calibrate_scale(lab_true: np.ndarray, lab_pred: np.ndarray, spread: np.ndarray, level: float = _regions.LEVEL) -> float:
    """The smallest model error s (CIELAB units per axis) whose regions (`_regions.radius90` with the parameter
    draws' `spread`) hold `level` of the rows."""
    if len(lab_true) == 0:
        return float("nan")
    de = np.asarray(colorimetry.delta_e_2000(jnp.asarray(lab_true), jnp.asarray(lab_pred)), np.float64)

    def held(s):
        return np.mean(de <= _regions.radius90(lab_pred, spread, np.full(len(de), s), level=level))

    lo, hi = 0.0, 1.0
    while held(hi) < level and hi < 200:
        lo, hi = hi, 2 * hi
    for _ in range(12):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if held(mid) < level else (lo, mid)
    return 0.0 if held(0.0) >= level else hi


def shrink_to_rows(draw, lab_true: np.ndarray, lab_pred: np.ndarray, level: float = _regions.LEVEL) -> float:
    """The factor a <= 1 on the posterior covariance whose draws alone (`draw(a)` -> spread (D, N, 3)) hold
    `level` of the given (fitted) rows: 1 if they hold fewer. The Laplace covariance is only as good as its
    noise estimate and its linearisation; where its draws alone hold far more than `level` of the rows the
    fit saw, they are wider than the data allow."""
    de = np.asarray(colorimetry.delta_e_2000(jnp.asarray(lab_true), jnp.asarray(lab_pred)), np.float64)
    zero = np.zeros(len(de))

    def held(a):
        return np.mean(de <= _regions.radius90(lab_pred, draw(a), zero, level=level))

    if len(de) == 0 or held(1.0) <= level:
        return 1.0
    lo, hi = 0.0, 1.0
    for _ in range(8):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if held(mid) < level else (lo, mid)
    return hi


#: A parameter whose posterior standard deviation (natural log units) exceeds this was left free by the rows:
#: its value came from the fit's start and priors, not from the measurements (a factor of 1.65 either way).
FREE_SD = 0.5


def pigment_report(F: np.ndarray, diag: np.ndarray, names, B: int, mixed: set[str]) -> list[dict]:
    """Per pigment: the posterior standard deviation of log K and log S (root mean square over the bands) and of
    log gamma, what the measurements determined, and the measurement that would pin what they did not."""
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
            need.append("the paint over black, or a tint with white")
        if "amount law" in free:
            need.append("a second amount")
        if n not in mixed:
            need.append("a mixture with another paint (it was never measured mixed)")
        out.append({"name": n, "sd_log_K": round(k, 4), "sd_log_S": round(s, 4), "sd_log_gamma": round(g, 4),
                    "from_the_prior": free, "measure": "; ".join(need)})  # fmt: skip
    return out


def uncertainty_lines(report: list[dict]) -> list[str]:
    """`pigment_report` as lines for the command line."""
    lines = ["  what the measurements determined (posterior sd in natural log units; > 0.5: left to the prior):"]
    for r in report:
        free = ", ".join(r["from_the_prior"]) or "nothing"
        tail = f"; would pin it: {r['measure']}" if r["measure"] else ""
        lines.append(f"    {r['name']}: log K {r['sd_log_K']:.2f}, log S {r['sd_log_S']:.2f}, log gamma "
                     f"{r['sd_log_gamma']:.2f}; from the prior: {free}{tail}")  # fmt: skip
    return lines
