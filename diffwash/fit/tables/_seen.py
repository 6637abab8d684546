r"""Refine a band-separable spectral fit in CIEDE2000: the colour differences the eye sees.

A spectral fit in log reflectance (`BandLevenbergMarquardt`) weighs every band
alike, the violet and deep-red ends as much as the middle of the spectrum. Where
the model cannot fit a row exactly, that compromise is not the one the eye
would make. This refinement starts from such a fit and minimises

$$ \sum_n \bigl\lVert r_{00}\bigl(\mathrm{Lab}_n,\ \mathrm{Lab}(R_n(\theta))\bigr)\bigr\rVert^2
   + \lambda^2 \lVert \theta_{band} - \theta_{band}^{(0)} \rVert^2 + \lVert p(\theta_{shared}) \rVert^2 $$

($r_{00}$: `colorimetry.delta_e_2000_residuals`, whose norm is CIEDE2000), with a
ridge that holds the spectra near the spectral fit (three colour coordinates per
row cannot pin 41 bands: the ridge keeps what the spectral fit learnt there).

**In a smooth basis** (`basis`, `smooth_basis`; the default of spectral mixture fits,
`MixModel.refine_spacing`): the refinement moves each pigment's log K and log S spectra only by smooth
changes, sums of Gaussian bumps about 50 nm apart, $\theta_{band} = \theta^{(0)}_{band} + \Phi C$. Free per
band, it bought colour with single bands (a spike of 0.03 in reflectance at 590 nm in predicted mixtures of
the NTU paints, spectra 3.8 times as rough as the measured ones), which a smooth paint cannot have; in the
basis they are as smooth as the log-reflectance fit's, and pairs never seen mixed are predicted better
(docs/mixing.md).

The Jacobian is assembled from its structure instead of one forward-mode
product per parameter: a row's reflectance in band $b$ depends only on band
$b$'s parameters and the shared ones (`Q + G` products give all of
$\partial R/\partial\theta$, as in `_bandlsq`), and its colour residuals on its
$B$ reflectances (a $3 \times B$ Jacobian per row). Each Levenberg-Marquardt
step (Marquardt's scaling by the diagonal) solves the dense normal equations.

**References:** K. Levenberg (1944); D. Marquardt (1963); G. Sharma, W. Wu and
E. N. Dalal, "The CIEDE2000 color-difference formula", CR&A 30 (2005).
"""

from __future__ import annotations

from collections.abc import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ... import colorimetry
from .._bandlsq import GN_TOL, Convergence, _tangents, loss_floor

__all__ = ["refine_in_de2000", "smooth_basis"]


class _Problem(eqx.Module):
    """The refinement's problem. A Module (its functions Modules too, where the caller's are): a later fit of
    the same shapes finds `_derivatives` compiled, where closures would compile again."""

    reflect: Callable[[Array, Array], Array]
    lab_of: Callable[[Array], Array]
    lab_target: Array
    band0: Array
    ridge: float = eqx.field(static=True)
    shared_prior: Callable[[Array], Array]
    w: Array | None = None  # each row's weight (N,) on its colour residuals; None: 1
    basis: Array | None = None  # (B, K): the refinement moves the band parameters in this basis (`smooth_basis`)

    def weigh(self, r):
        """The rows' colour residuals (N, ...) weighed by `w`."""
        return r if self.w is None else r * self.w.reshape(self.w.shape + (1,) * (r.ndim - 1))


@eqx.filter_jit
def _derivatives(pb: _Problem, y):
    """What the Jacobian is assembled from: each row's colour residuals' derivatives by its reflectances `E`
    (N, 3, B), the reflectances' by each band-column and shared parameter `dR` (Q + G, N, B), the shared prior's
    Jacobian `Jp`, and the residuals (colour (3N), ridge, prior)."""
    band, shared = y
    R, reflect_jvp = jax.linearize(pb.reflect, band, shared)  # R once; then Q + G tangents through its linearisation
    dR = jax.vmap(reflect_jvp)(*_tangents(band, shared))  # (Q + G, N, B)
    row = lambda Rn, ln: colorimetry.delta_e_2000_residuals(ln, pb.lab_of(Rn))  # noqa: E731
    E = pb.weigh(jax.vmap(jax.jacfwd(row))(R, pb.lab_target))  # (N, 3, B)
    r, rb, rg = pb.weigh(row(R, pb.lab_target)), pb.ridge * (band - pb.band0), pb.shared_prior(shared)
    return E, dR, jax.jacfwd(pb.shared_prior)(shared), r.ravel(), rb.ravel(), rg


@eqx.filter_jit
def _blocks(E, dR, Q: int):
    """The colour residuals' Jacobian blocks `Jb` (3N, B Q) and `Jg` (3N, G) from `_derivatives`' `E` and `dR`.

    A program of its own (as is `_normal_blocks`): compiled together with `_derivatives`, XLA fused the linearised
    reflectance into these products and computed it again for their elements (a refinement step on the NTU table
    took 0.33 s instead of 0.08 s)."""
    Jb = jnp.einsum("nib,qnb->nibq", E, dR[:Q]).reshape(3 * E.shape[0], -1)
    Jg = jnp.einsum("nib,gnb->nig", E, dR[Q:]).reshape(3 * E.shape[0], -1)
    return Jb, Jg


def _linearised(pb: _Problem, y, rows: bool):
    """What a step at `y` is solved from (`rows`: the Jacobian's blocks, `_jacobians`; else the normal equations,
    `_normal_equations`) and the loss at `y`, summed from the residuals `_derivatives` returns with them: the loss
    has no compiled program of its own (it cost 2 s of a 13 s cold refinement of an 80-row table), and an accepted
    step's next linearisation is the one its loss came from."""
    E, dR, Jp, r, rb, rg = d = _derivatives(pb, y)
    loss = sum(float(np.sum(np.square(np.asarray(x, np.float64)))) for x in (r, rb, rg))
    Q = int(y[0].shape[1])
    return ((*_blocks(E, dR, Q), Jp, r, rb, rg) if rows else _normal_blocks(*d, Q, pb.ridge, pb.basis)), loss


def _jacobians(pb: _Problem, y):
    """The colour residuals' Jacobian in its two blocks, `Jb` (3N, B Q) and `Jg` (3N, G), the shared prior's `Jp`,
    and the residuals (colour, ridge, prior)."""
    return _linearised(pb, y, True)[0]


def _normal_equations(pb: _Problem, y):
    r"""The Gauss-Newton matrix and gradient; with a `pb.basis` $\Phi$ (B, K), in the coefficients C of the band
    parameters' change `band - band0 = phi @ C` ((K Q) + G parameters instead of (B Q) + G)."""
    return _linearised(pb, y, False)[0]


@eqx.filter_jit
def _normal_blocks(E, dR, Jp, r, rb, rg, Q: int, ridge: float, phi):
    """`_normal_equations` from `_derivatives` (`Q` band columns; `phi`: the basis or None)."""
    Jb, Jg = _blocks(E, dR, Q)
    if phi is None:
        n = Jb.shape[1]
        ridge_H, ridge_g = ridge**2 * jnp.eye(n, dtype=Jb.dtype), ridge * rb
    else:
        B, K = phi.shape
        Jb = jnp.einsum("nbq,bk->nkq", Jb.reshape(-1, B, Q), phi).reshape(Jb.shape[0], K * Q)
        n = K * Q
        ridge_H = ridge**2 * jnp.kron(phi.T @ phi, jnp.eye(Q, dtype=phi.dtype))
        ridge_g = ridge * jnp.einsum("bq,bk->kq", rb.reshape(B, Q), phi).ravel()
    J = jnp.concatenate([Jb, Jg], axis=1)
    H = J.T @ J
    H = H.at[:n, :n].add(ridge_H)
    H = H.at[n:, n:].add(Jp.T @ Jp)
    g = J.T @ r + jnp.concatenate([ridge_g, Jp.T @ rg])
    return H, g


def smooth_basis(wavelengths, spacing: float) -> np.ndarray:
    """Gaussian bumps over the bands at `wavelengths` (nm): one about every `spacing` nm, the first and last at the
    ends, each of standard deviation the bumps' spacing. Shape (B, K); None where `spacing` is 0 or None."""
    if not spacing:
        return None
    wl = np.asarray(wavelengths, np.float64)
    span = float(wl[-1] - wl[0])
    k = max(2, int(round(span / spacing)) + 1)
    c = np.linspace(wl[0], wl[-1], k)
    return np.exp(-0.5 * ((wl[:, None] - c[None, :]) / (span / (k - 1))) ** 2)


@eqx.filter_jit
def _dense_step(H, g, mu):
    """The damped step (Marquardt's scaling by the diagonal) from the normal equations."""
    d = jnp.diagonal(H)
    return jnp.linalg.solve(H + mu * jnp.diag(d + 1e-9 * jnp.mean(d)), -g)


@eqx.filter_jit
def _row_step(jac, ridge: float, mu):
    r"""The same damped step without forming the (B Q)-square matrix, for tables with fewer colour residuals
    than band parameters ($3N < BQ$: few rows, many pigments or bands). The band block is
    $A = J_b^\top J_b + \mathrm{diag}(a)$, inverted through its $3N$ rows (Woodbury), and the shared parameters
    are eliminated by the Schur complement: $O((3N)^2 BQ)$ instead of $O((BQ)^3)$."""
    Jb, Jg, Jp, r, rb, rg = jac
    dbb = jnp.sum(Jb * Jb, axis=0) + ridge**2
    Hgg = Jg.T @ Jg + Jp.T @ Jp
    dgg = jnp.diagonal(Hgg)
    floor = 1e-9 * jnp.mean(jnp.concatenate([dbb, dgg]))
    a = ridge**2 + mu * (dbb + floor)
    Ja = Jb / a
    C = jnp.eye(Jb.shape[0], dtype=Jb.dtype) + Ja @ Jb.T
    a_inv = lambda X: X / a[:, None] - Ja.T @ jnp.linalg.solve(C, Ja @ X)  # noqa: E731
    gb, gg = Jb.T @ r + ridge * rb, Jg.T @ r + Jp.T @ rg
    Hbg = Jb.T @ Jg
    AiHbg, Aigb = a_inv(Hbg), a_inv(gb[:, None])[:, 0]
    schur = Hgg + mu * jnp.diag(dgg + floor) - Hbg.T @ AiHbg
    dg = jnp.linalg.solve(schur, -(gg - Hbg.T @ Aigb))
    return jnp.concatenate([-(Aigb + AiHbg @ dg), dg]), jnp.concatenate([gb, gg])


def refine_in_de2000(
    reflect: Callable[[Array, Array], Float[Array, "n b"]],
    lab_of: Callable[[Array], Float[Array, "*n 3"]],
    lab_target: Float[Array, "n 3"],
    y0: tuple[Float[Array, "b q"], Float[Array, " g"]],
    *,
    ridge: float,
    shared_prior: Callable[[Array], Array],
    max_steps: int = 100,
    rtol: float = 1e-5,
    weights: Array | None = None,
    basis: Array | None = None,
) -> tuple[tuple[Array, Array], bool, int]:
    """Levenberg-Marquardt on CIEDE2000 residuals from a spectral fit `y0 = (band, shared)` (module docstring).

    **Arguments:**

    - `reflect`: `(band, shared) -> R`, reflectance of every row, shape (N, B); row `n`, band `b` must depend
      on `band[b]` and `shared` only.
    - `lab_of`: reflectance (..., B) to CIELAB (..., 3).
    - `lab_target`: the measured colours, shape (N, 3).
    - `ridge`: weight of the pull of `band` towards `y0`'s (CIEDE2000 units per unit parameter).
    - `shared_prior`: residuals of the shared parameters' prior.
    - `max_steps`, `rtol`: at most this many linearisations; stop when an accepted step lowers the loss by
      less than `rtol` relative.
    - `weights`: each row's weight on its colour residuals, shape (N,) (None: 1; 0 leaves a row out, as a
      cross-validation fold does: the fit and its folds then share one compiled program).
    - `basis`: (B, K) or None: move the band parameters only along it, `band = band0 + basis @ C` (K Q
      coefficients C; `smooth_basis`), with the ridge on the change in the bands. None: every band free.

    **Returns:** `((band, shared), convergence, steps)`: the `Convergence` (true as a bool when converged: the
    loss stopped falling, or, out of steps, a Gauss-Newton step would lower it by at most `GN_TOL`; it says
    how far off a minimum the fit ended).
    """
    band0 = y0[0]
    w = jnp.ones(lab_target.shape[0], band0.dtype) if weights is None else jnp.asarray(weights, band0.dtype)
    phi = None if basis is None else jnp.asarray(basis, band0.dtype)
    pb = _Problem(reflect, lab_of, jnp.asarray(lab_target), band0, float(ridge), shared_prior, w, phi)
    n_band = band0.size if phi is None else phi.shape[1] * band0.shape[1]
    # few rows, many free band parameters: never form the square matrix (a basis keeps it small: always formed)
    rows = phi is None and 3 * lab_target.shape[0] < n_band
    state = lambda y: _linearised(pb, y, rows)  # noqa: E731
    to_band = (lambda d: d.reshape(band0.shape)) if phi is None else (  # noqa: E731
        lambda d: phi @ d.reshape(phi.shape[1], band0.shape[1]))
    # mu as an array: a Python float would be a static argument of the compiled step, compiled again for each value
    solve = (lambda st, mu: _row_step(st, pb.ridge, jnp.asarray(mu, band0.dtype))) if rows else (  # noqa: E731
        lambda st, mu: (_dense_step(*st, jnp.asarray(mu, band0.dtype)), st[1]))
    y = y0
    st, f = state(y)
    floor = loss_floor(3 * lab_target.shape[0])
    history = [f]
    mu, step, stopped = 1e-3, 0, False
    while step < max_steps and not stopped:
        step += 1
        while True:
            delta, _ = solve(st, mu)
            cand = (y[0] + to_band(delta[:n_band]), y[1] + delta[n_band:])
            st_new, f_new = state(cand)  # an accepted step's next linearisation, computed once
            if f_new < f:
                break
            mu *= 4.0
            if mu > 1e12:  # no step lowers the loss: a minimum as far as float arithmetic can tell
                return y, _ended(solve(st, 1e-6), f, history, step, True, floor), step
        mu = max(mu / 3.0, 1e-9)
        stopped = f - f_new <= rtol * f
        y, f, st = cand, f_new, st_new
        history.append(f)
    # Stopped by the small decrease, or out of steps: at a minimum if a Gauss-Newton step would gain little.
    return y, _ended(solve(st, 1e-6), f, history, step, stopped, floor), step


def _ended(newton, f: float, history: list[float], steps: int, stopped: bool, floor: float) -> Convergence:
    """How the refinement ended: converged if it stopped on its own test or a Gauss-Newton step gains < GN_TOL.
    `newton`: the barely damped step and the gradient there (`newton_decrement`'s share of the loss)."""
    delta, g = newton
    dec = float(-jnp.vdot(g, delta)) / max(f, floor, 1e-30)
    window = min(5, len(history) - 1)
    last = (history[-1 - window] - history[-1]) / history[-1 - window] if window else 0.0
    return Convergence(converged=bool(stopped or dec <= GN_TOL), steps=steps, decrement=dec, last_decrease=last,
                       window=window, stage="CIEDE2000 refinement")  # fmt: skip
