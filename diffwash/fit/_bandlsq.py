r"""Levenberg-Marquardt for problems that separate by band, as an optimistix solver.

A spectral fit has many parameters per band (each pigment's `log K` and `log S`
at that wavelength) and a few shared ones (each pigment's amount law, mixing
weights, a surface term). The residuals of band `b` depend only on band `b`'s
parameters and the shared ones, so the Gauss-Newton matrix is *arrow-shaped*:
block diagonal over the bands, plus a dense border for the shared parameters.

`BandLevenbergMarquardt` is optimistix's Levenberg-Marquardt (the damped
Newton descent with the classical trust region) whose descent uses that
structure: the Jacobian comes from `Q + G` forward-mode products (one per
per-band parameter, seeded in every band at once, plus one per shared
parameter) instead of `B Q + G`, and each damped step is solved by a Schur
complement over the `B` small `Q x Q` blocks:

$$ \begin{pmatrix} H_b + \lambda I & H_{bg} \\ H_{bg}^\top & H_g + \lambda I \end{pmatrix}
   \begin{pmatrix} \delta_b \\ \delta_g \end{pmatrix} = -\begin{pmatrix} g_b \\ g_g \end{pmatrix},
   \qquad \bigl(H_g + \lambda I - \textstyle\sum_b H_{bg}^\top (H_b + \lambda I)^{-1} H_{bg}\bigr)\,\delta_g = \dots $$

with $\lambda$ = 1 / the trust region's step size, as `optimistix.DampedNewtonDescent`.

The problem's parameters are a pair `(band, shared)` of arrays of shapes `(B, Q)`
and `(G,)`; its residuals a pair `(per_band, shared)` of shapes `(B, M)` (row `b`
depending only on `band[b]` and `shared`) and `(H,)` (depending on `shared` only).

**References:**

- K. Levenberg (1944); D. Marquardt (1963).
- B. Triggs, P. McLauchlan, R. Hartley and A. Fitzgibbon, "Bundle adjustment: a
  modern synthesis" (2000), sec. 6 (the Schur complement of an arrow-shaped system).
- P. Kidger et al., optimistix.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jaxtyping import Array, Float, PyTree, Scalar

from .._lazy import lazy

scipy_linalg = lazy("scipy.linalg")
scipy_sparse_linalg = lazy("scipy.sparse.linalg")

__all__ = ["BandLevenbergMarquardt", "Convergence", "newton_decrement", "loss_floor", "GN_TOL", "band_covariance",
           "gauss_newton_blocks"]

#: A least-squares fit is at a minimum when a full Gauss-Newton step from where it stopped would lower its loss by
#: at most this fraction (`newton_decrement`): the gradient, measured in the fit's own scale (the curvature's),
#: is negligible against the loss. 1e-3 of the loss is a change of 0.05% in a mean CIEDE2000.
GN_TOL = 1e-3


def loss_floor(residuals: int) -> float:
    """The loss of 0.01 CIEDE2000 on every row of `residuals` colour residuals (3 per row): below it, shares of
    the loss are float noise, not distance from a minimum."""
    return 1e-4 * residuals / 3


def newton_decrement(H: Array, g: Array, f: Array, floor: float = 0.0) -> Array:
    r"""The share of the loss $f = \lVert r \rVert^2$ a full Gauss-Newton step would remove: $g^\top H^{-1} g / f$
    with $g = J^\top r$, $H = J^\top J$ (plus the priors' curvature).

    A relative gradient norm in the fit's own scale: invariant to how the parameters are scaled (each is measured
    by the curvature along it), and relative to the loss. Each diagonal entry of $H$ is raised by 1e-6 of itself
    (Marquardt's scaling, which keeps that invariance): a direction the data leave nearly free is not taken as
    infinitely far to go. `floor`: the loss below which it is measured against `floor` instead (`loss_floor`: a
    fit that reproduces its rows within 0.01 CIEDE2000 is at its minimum for any purpose).
    """
    d = jnp.diagonal(H)
    Hd = H + jnp.diag(1e-6 * d + jnp.finfo(H.dtype).tiny)
    step = jnp.linalg.solve(Hd, g)
    return jnp.vdot(g, step) / jnp.maximum(jnp.maximum(f, floor), jnp.finfo(f.dtype).tiny)


@dataclass(frozen=True)
class Convergence:
    """How a fit ended, and how far from a minimum.

    **Fields:**

    - `converged`: at a minimum: the loss stopped falling (relative decrease at most the tolerance) or a
      Gauss-Newton step would lower it by at most `GN_TOL` of itself.
    - `steps`: the steps taken.
    - `decrement`: the share of the loss a Gauss-Newton step from the end would remove (`newton_decrement`;
      NaN if not computed).
    - `last_decrease`: the relative decrease of the loss over the last `window` steps.
    - `window`: how many steps `last_decrease` spans.
    - `stage`: which stage of the fit this is (e.g. `"CIEDE2000 refinement"`).
    """

    converged: bool
    steps: int
    decrement: float = float("nan")
    last_decrease: float = float("nan")
    window: int = 0
    stage: str = ""

    def __bool__(self) -> bool:
        return bool(self.converged)

    def describe(self) -> str:
        """One line: where the fit stands (the numbers that say how far off a minimum it is)."""
        parts = []
        if np.isfinite(self.decrement):
            parts.append(f"a Gauss-Newton step would lower its loss by {100 * self.decrement:.3g}% more")
        if np.isfinite(self.last_decrease) and self.window:
            parts.append(f"its last {self.window} steps lowered it by {100 * self.last_decrease:.3g}%")
        what = f"{self.stage}: " if self.stage else ""
        state = "at a minimum" if self.converged else "not at a minimum"
        return f"{what}{state} after {self.steps} steps" + (f" ({'; '.join(parts)})" if parts else "")

    def to_dict(self) -> dict[str, Any]:
        fin = lambda v: float(v) if np.isfinite(v) else None  # noqa: E731
        return {"stage": self.stage, "converged": bool(self.converged), "steps": int(self.steps),
                "gauss_newton_decrement": fin(self.decrement), "last_decrease": fin(self.last_decrease),
                "window": int(self.window)}  # fmt: skip


class _State(eqx.Module):
    Hb: Float[Array, "b q q"]
    Hbg: Float[Array, "b q g"]
    Hg: Float[Array, "g g"]
    gb: Float[Array, "b q"]
    gg: Float[Array, "g"]


def _tangents(band: Array, shared: Array) -> tuple[Array, Array]:
    """Q + G tangents: unit per-band parameter q in every band at once, then each shared one."""
    B, Q = band.shape
    G = shared.shape[0]
    eye_q = jnp.eye(Q, dtype=band.dtype)
    tb = jnp.concatenate([jnp.broadcast_to(eye_q[:, None, :], (Q, B, Q)), jnp.zeros((G, B, Q), band.dtype)])
    tg = jnp.concatenate([jnp.zeros((Q, G), shared.dtype), jnp.eye(G, dtype=shared.dtype)])
    return tb, tg


class _BandDampedNewtonDescent(optx.AbstractDescent):
    """The damped Newton step of an arrow-shaped (band-separable) least-squares problem."""

    def init(self, y: PyTree, f_info_struct: PyTree) -> _State:
        band, shared = y
        B, Q = band.shape
        G = shared.shape[0]
        z = lambda *s: jnp.zeros(s, band.dtype)  # noqa: E731
        return _State(Hb=z(B, Q, Q), Hbg=z(B, Q, G), Hg=z(G, G), gb=z(B, Q), gg=z(G))

    def query(self, y: PyTree, f_info: optx.FunctionInfo.ResidualJac, state: _State) -> _State:
        del state
        band, shared = y
        Q = band.shape[1]
        J_rows, J_shared = jax.vmap(f_info.jac.mv)(_tangents(band, shared))  # (Q+G, B, M), (Q+G, H)
        r_rows, r_shared = f_info.residual
        Jb, Jgb = J_rows[:Q], J_rows[Q:]  # (Q, B, M), (G, B, M)
        Jg = J_shared[Q:]  # (G, H); the per-band seeds leave the shared residuals alone
        Hb = jnp.einsum("qbm,pbm->bqp", Jb, Jb)
        Hbg = jnp.einsum("qbm,gbm->bqg", Jb, Jgb)
        Hg = jnp.einsum("gbm,hbm->gh", Jgb, Jgb) + Jg @ Jg.T
        gb = jnp.einsum("qbm,bm->bq", Jb, r_rows)
        gg = jnp.einsum("gbm,bm->g", Jgb, r_rows) + Jg @ r_shared
        return _State(Hb=Hb, Hbg=Hbg, Hg=Hg, gb=gb, gg=gg)

    def step(self, step_size: Scalar, state: _State) -> tuple[PyTree, optx.RESULTS]:
        dtype = state.gb.dtype
        ok = step_size > jnp.finfo(dtype).eps
        lam = jnp.where(ok, 1 / jnp.where(ok, step_size, 1), jnp.finfo(dtype).max ** 0.25)
        Q, G = state.gb.shape[1], state.gg.shape[0]
        # Gauss-Newton proper (lambda -> 0 as the trust region grows) is singular along directions the
        # data leave free; a floor relative to the curvature's scale keeps every solve well posed.
        floor = jnp.sqrt(jnp.finfo(dtype).eps) * jnp.mean(jnp.diagonal(state.Hb, axis1=1, axis2=2))
        lam = jnp.maximum(lam, floor)
        Ab = state.Hb + lam * jnp.eye(Q, dtype=dtype)
        L = jnp.linalg.cholesky(Ab)
        solve_b = jax.vmap(lambda Lb, rhs: jax.scipy.linalg.cho_solve((Lb, True), rhs))
        Xg = solve_b(L, state.Hbg)  # (B, Q, G): A_b^-1 H_bg
        xb = solve_b(L, state.gb)  # (B, Q): A_b^-1 g_b
        schur = state.Hg + lam * jnp.eye(G, dtype=dtype) - jnp.einsum("bqg,bqh->gh", state.Hbg, Xg)
        rhs = state.gg - jnp.einsum("bqg,bq->g", state.Hbg, xb)
        dg = jnp.linalg.solve(schur, rhs)
        db = xb - jnp.einsum("bqg,g->bq", Xg, dg)
        finite = jnp.all(jnp.isfinite(db)) & jnp.all(jnp.isfinite(dg))
        result = optx.RESULTS.where(finite, optx.RESULTS.successful, optx.RESULTS.nonlinear_divergence)
        return (-jnp.where(finite, db, 0), -jnp.where(finite, dg, 0)), result


class BandLevenbergMarquardt(optx.AbstractGaussNewton):
    """Levenberg-Marquardt for band-separable least squares (see the module docstring).

    **Arguments:**

    - `rtol`, `atol`: the tolerances of optimistix's Cauchy termination.
    - `norm`: the norm of that termination (default `optimistix.max_norm`).
    - `cap`: stop after this many steps, as `optimistix.least_squares(..., max_steps=cap)` would (its result
      `nonlinear_max_steps_reached`), but as an array: solves capped at other step counts under one `max_steps`
      share one compiled program (a fit's cross-validation folds, capped below the fit's own bound). Default:
      no cap but `max_steps`.
    """

    rtol: float
    atol: float
    norm: Callable[[PyTree], Scalar]
    descent: _BandDampedNewtonDescent
    search: optx.ClassicalTrustRegion
    verbose: Callable[..., None]
    cap: Array

    def __init__(self, rtol: float, atol: float, norm: Callable[[PyTree], Scalar] = optx.max_norm,
                 cap: int | None = None):  # fmt: skip
        self.rtol = rtol
        self.atol = atol
        self.norm = norm
        self.descent = _BandDampedNewtonDescent()
        self.search = optx.ClassicalTrustRegion()
        self.verbose = _quiet
        self.cap = jnp.asarray(np.iinfo(np.int32).max if cap is None else cap, jnp.int32)

    def terminate(self, fn, y, args, options, state, tags):
        done, result = super().terminate(fn, y, args, options, state, tags)
        capped = state.num_steps >= self.cap
        # A result other than `successful` also ends optimistix's loop: the cap's is set only once it is reached.
        return done | capped, optx.RESULTS.where(done | ~capped, result, optx.RESULTS.nonlinear_max_steps_reached)


def _quiet(**kwargs) -> None:
    del kwargs


def gauss_newton_blocks(fn, y, n_rows: int):
    """The Gauss-Newton curvature of a band problem `fn` (`(band, shared), None -> (per band (B, M), shared
    (H,))`, the first `n_rows` columns of each band its rows' residuals) at `y = (band (B, Q), shared (G,))`, by
    blocks: `(sigma2, Hbb (B, Q, Q), Hbg (B, Q, G), Hgg (G, G))`, with `sigma2` the rows' noise variance (1.4826
    times their median absolute residual, squared: robust to a few rows fitted badly)."""
    Q = y[0].shape[1]
    Jr, Js, rows = (np.asarray(x, np.float64) for x in _jacobian(fn, y))
    sigma2 = float((1.4826 * np.median(np.abs(rows[:, :n_rows]))) ** 2)
    Jb, Jg = Jr[:Q].transpose(1, 0, 2), Jr[Q:].transpose(1, 0, 2)  # (B, Q, M), (B, G, M): batched products
    Hbb = Jb @ Jb.transpose(0, 2, 1)
    Hbg = Jb @ Jg.transpose(0, 2, 1)
    Hgg = np.sum(Jg @ Jg.transpose(0, 2, 1), axis=0) + Js[Q:] @ Js[Q:].T
    return sigma2, Hbb, Hbg, Hgg


@eqx.filter_jit
def _jacobian(fn, y):
    """The Jacobian of a band problem by its `Q + G` forward-mode products (`_tangents`), compiled: `(per band
    (Q + G, B, M), shared (Q + G, H), rows (B, M))`."""
    band, shared = y
    (rows, _), lin = jax.linearize(lambda b, s: fn((b, s), None), band, shared)
    Jr, Js = jax.vmap(lin)(*_tangents(band, shared))
    return Jr, Js, rows


def band_covariance(fn, y, n_rows: int, theta: np.ndarray, rank: int, tiny: float = 1e-9):
    r"""The Laplace covariance of a band-separable least-squares problem at `y`, restricted to the parameters
    `theta`, as its `rank` leading eigenvectors (scaled) plus the remaining diagonal, without forming the
    $(BQ + G)$-square matrix: $\Sigma = \sigma^2 H^{-1}$ with $H$ the Gauss-Newton matrix (arrow-shaped, as in
    `BandLevenbergMarquardt`), its band blocks and the Schur complement of the shared parameters factored once;
    the diagonal exactly, the eigenvectors by Lanczos iteration on products with $\Sigma$ (`scipy.sparse.linalg.eigsh`).

    **Arguments:**

    - `fn`: `(band, shared), None -> (per band (B, M), shared (H,))`; the first `n_rows` columns of each band are
      the rows' residuals (their median absolute value, times 1.4826, is $\sigma$: robust to a few bad rows).
    - `y`: `(band (B, Q), shared (G,))`.
    - `theta`: positions in `(band.ravel(), shared)` of the parameters kept.
    - `rank`: eigenvectors kept.
    - `tiny`: a ridge of this share of the largest curvature, for directions the problem leaves free.

    **Returns:** `(factor (m, rank), diagonal (m,), sigma)`: $\Sigma_\theta \approx F F^\top + \mathrm{diag}(d)$.
    """
    band, shared = y
    B, Q = band.shape
    G = shared.shape[0]
    sigma2, Hbb, Hbg, Hgg = gauss_newton_blocks(fn, y, n_rows)
    delta = tiny * max(float(np.max(np.diagonal(Hbb, axis1=1, axis2=2), initial=0.0)),
                       float(np.max(np.diag(Hgg), initial=0.0)), 1e-30)  # fmt: skip
    Dinv = np.linalg.inv(Hbb + delta * np.eye(Q))  # (B, Q, Q): small blocks
    X = Dinv @ Hbg  # (B, Q, G)
    schur = Hgg + delta * np.eye(G) - np.einsum("bqg,bqh->gh", Hbg, X)
    Sinv = scipy_linalg.pinvh(0.5 * (schur + schur.T))
    n = B * Q + G
    var = np.concatenate([(np.diagonal(Dinv, axis1=1, axis2=2) + np.einsum("bqg,gh,bqh->bq", X, Sinv, X)).ravel(),
                          np.diag(Sinv)])  # fmt: skip

    def cov(v):  # sigma^2 H^-1 on theta
        u = np.zeros(n)
        u[theta] = np.ravel(v)
        ub = u[: B * Q].reshape(B, Q)
        zg = Sinv @ (u[B * Q :] - np.einsum("bqg,bq->g", X, ub))
        zb = np.einsum("bqp,bp->bq", Dinv, ub) - X @ zg
        return sigma2 * np.concatenate([zb.ravel(), zg])[theta]

    m = len(theta)
    k = min(rank, m - 1)
    op = scipy_sparse_linalg.LinearOperator((m, m), matvec=cov, dtype=np.float64)
    ev, U = scipy_sparse_linalg.eigsh(op, k=k, which="LA", v0=np.ones(m), tol=1e-6)
    F = U * np.sqrt(np.maximum(ev, 0))
    diag = np.maximum(sigma2 * var[theta] - np.sum(F * F, axis=1), 0.0)
    return F, diag, float(np.sqrt(sigma2))
