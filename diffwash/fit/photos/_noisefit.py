r"""A pigment fit that knows its noise: weighted by each patch's own noise, with the calibration's uncertainty.

The rows of a swatch card (`diffwash.fit.photos._swatch`) each come with the
covariance of their mean colour, estimated from their pixels
(`diffwash.fit.photos._noise`). The fit minimises

$$ \chi^2 = \sum_i e_i^T C_i^{-1} e_i + \sum_{\text{photos}} \Big\| \frac{\delta g}{\sigma_g} \Big\|^2
   + \Big\| \frac{\delta b}{\sigma_b} \Big\|^2 + \text{(a weak prior)}, \qquad
   e_i = \hat R_i\, e^{\delta g} - R_i, $$

the residuals in standard deviations of the measurement. The calibration is
fitted jointly: each photo's per-channel gain (exposure and white balance, from
the paper box) may move by its own uncertainty $\sigma_g$ (`log_gain`), and so
may the black band's reflectance (`log_black`, the ground of the patches over
black); their uncertainty is thereby carried into K and S. The covariance of a
row is

$$ C_i = \Sigma_i + (\rho_i^2 + \tau^2)\,\mathrm{diag}(R_i^2), $$

$\Sigma_i$ the patch's measured covariance, $\rho_i$ the light-falloff model's
own uncertainty where the patch lies, and $\tau$ a relative dispersion between
patches that the pixels cannot show (an uneven glaze, a patch's edge, the
model's own error): when the fit is worse than the noise allows
($\chi^2 > $ its degrees of freedom $\nu$), $\tau$ is raised until
$\chi^2 = \nu$ and the fit is repeated (a variance-component estimate, as in
Birge's ratio, but relative). The covariance of the logs is then the
Gauss-Newton $(J^T J)^{-1}$, and intervals use Student's t with $\nu$ degrees
of freedom.

**References:**

- R. T. Birge, "The calculation of errors by the method of least squares",
  Phys. Rev. 40 (1932) (scaling by the fit's misfit).
- Y. Bard, "Nonlinear Parameter Estimation", Academic Press 1974, ch. 7
  (Gauss-Newton covariance; nuisance parameters with priors).
"""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from ..._lazy import lazy
from .._kmfit import COMPILER_OPTIONS, FitModel, Rows, _compiled, effective, pad_rows, predict

scipy_stats = lazy("scipy.stats")

__all__ = ["Observations", "NoiseFit", "fit_noise", "Uncertainty", "uncertainty", "PARAMETERS"]

#: The pigment's parameters, in the covariance's order.
PARAMETERS = tuple(f"{k}_{c}" for k in ("K", "S") for c in "rgb")


@dataclass(frozen=True)
class Observations:
    """One pigment's rows with their noise (numpy).

    **Fields:** `amount` (n,), `ground` (n, 3), `rgb` (n, 3), `cov` (n, 3, 3)
    (covariance of each row's colour), `lo`, `hi` (n, 3) (clipped: bounds),
    `weight` (n,), `photo` (n,) (index of the row's photo), `on_black` (n,)
    (the row lies on the black band), `relative` (n,) (a relative standard
    deviation to add: the calibration's uncertainty at the row), `floor` (n, 3)
    (at the noise floor), `gain_sd` (G, 3) (each photo's log-gain standard
    deviation), `black_sd` (3,) or None (the black band's log-reflectance
    standard deviation).
    """

    amount: np.ndarray
    ground: np.ndarray
    rgb: np.ndarray
    cov: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    weight: np.ndarray
    photo: np.ndarray
    on_black: np.ndarray
    relative: np.ndarray
    floor: np.ndarray
    gain_sd: np.ndarray
    black_sd: np.ndarray | None


@dataclass(frozen=True)
class NoiseFit:
    """What `fit_noise` found.

    **Fields:** `theta` (the solution: `log_K`, `log_S`, and the nuisance
    `log_gain`, `log_black`), `cov` (6, 6) (covariance of `(log_K, log_S)`,
    the calibration's uncertainty included), `dispersion` (tau), `chi2`,
    `dof`, `steps`, `converged`, `fitted` (n, 3) (the pigment's prediction at
    each row, before the nuisance gains), `jac_pred` (n, 3, 6) (its derivative
    with respect to the logs).
    """

    theta: dict[str, np.ndarray]
    cov: np.ndarray
    dispersion: float
    chi2: float
    dof: int
    steps: int
    converged: bool
    fitted: np.ndarray
    jac_pred: np.ndarray

    def quantile(self, level: float, two_sided: bool = True) -> float:
        """Student's t quantile for an interval of `level` with this fit's degrees of freedom."""
        p = 0.5 + level / 2 if two_sided else level
        return float(scipy_stats.t.ppf(p, max(self.dof, 1)))


def _whiten(obs: Observations, tau: float) -> np.ndarray:
    """The rows' whitening matrices: the inverse Cholesky factors of their covariance with dispersion `tau`."""
    rel2 = obs.relative**2 + tau**2
    C = obs.cov + rel2[:, None, None] * np.einsum("ni,ij->nij", obs.rgb**2, np.eye(3))
    C = C + np.eye(3) * 1e-14  # a floor (in reflectance^2) so that an exact, noiseless photo stays finite
    return np.linalg.inv(np.linalg.cholesky(C))


def _rows(obs: Observations, tau: float) -> Rows:
    n, M = len(obs.amount), pad_rows(len(obs.amount))

    def pad(a, fill):
        return np.concatenate([a, np.full((M - n,) + a.shape[1:], fill, a.dtype)])

    W = np.concatenate([_whiten(obs, tau), np.broadcast_to(np.eye(3), (M - n, 3, 3))])
    return Rows(amount=pad(obs.amount, 0.0), ground=pad(obs.ground, 0.5), rgb=pad(obs.rgb, 0.5),
                lo=pad(obs.lo, False), hi=pad(obs.hi, False), weight=pad(obs.weight, 0.0), whiten=W,
                photo=pad(obs.photo.astype(np.int32), 0), gain_sd=obs.gain_sd,
                on_black=pad(obs.on_black, False), black_sd=obs.black_sd)  # fmt: skip


def _cast(tree: Any) -> Any:
    dtype = jnp.zeros(()).dtype  # float32 unless x64 is enabled
    return jax.tree.map(lambda a: jnp.asarray(a, dtype) if np.asarray(a).dtype.kind == "f" else jnp.asarray(a), tree)


def _solve(model: FitModel, max_steps: int, rows: Rows, starts: list[dict[str, np.ndarray]], pins: Any):
    """Levenberg-Marquardt from each start; the best (lowest loss) run."""
    fn = _compiled(model, max_steps, False)
    rows = _cast(rows)
    pins = _cast(pins)
    best = None
    for theta0 in starts:
        out = fn(rows, _cast(theta0), pins)
        loss = float(out[1])
        if best is None or (np.isfinite(loss) and loss < best[0]):
            best = (loss, out)
    theta, loss, steps, ok, J, fitted = best[1]
    return ({k: np.asarray(v, np.float64) for k, v in theta.items()}, float(loss), int(steps), bool(ok),
            np.asarray(J, np.float64))  # fmt: skip


def _differences(model: FitModel, obs: Observations, theta: dict[str, np.ndarray]) -> np.ndarray:
    """The unwhitened differences `effective(prediction x gain) - observed`, (n, 3)."""
    args = _cast((theta, obs.amount, _grounds(obs, theta), obs.photo, obs.rgb))
    return np.asarray(_differences_jit(model, *args, jnp.asarray(obs.lo), jnp.asarray(obs.hi)), np.float64)


@functools.partial(jax.jit, static_argnums=0, compiler_options=COMPILER_OPTIONS)
def _differences_jit(model, theta, amount, ground, photo, rgb, lo, hi):
    pred = predict(model, theta, amount, ground) * jnp.exp(theta["log_gain"][photo])
    return effective(pred, rgb, lo, hi) - rgb


def _grounds(obs: Observations, theta: dict[str, np.ndarray]) -> np.ndarray:
    if "log_black" not in theta:
        return obs.ground
    return np.where(obs.on_black[:, None], obs.ground * np.exp(theta["log_black"]), obs.ground)


def _chi2(obs: Observations, diff: np.ndarray, tau: float) -> float:
    W = _whiten(obs, tau)
    r = np.einsum("nij,nj->ni", W, diff) * np.sqrt(obs.weight)[:, None]
    return float(np.sum(r * r))


def _dispersion(obs: Observations, diff: np.ndarray, dof: int) -> float:
    """The relative dispersion tau >= 0 that brings chi-square down to its degrees of freedom."""
    if dof < 1 or _chi2(obs, diff, 0.0) <= dof:
        return 0.0
    lo, hi = 0.0, 1.0
    while _chi2(obs, diff, hi) > dof and hi < 1e3:
        hi *= 4
    for _ in range(50):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if _chi2(obs, diff, mid) > dof else (lo, mid)
    return hi


def _degrees_of_freedom(obs: Observations) -> int:
    """Observed channels that are values (not satisfied bounds) minus the pigment's six parameters."""
    values = (obs.weight[:, None] > 0) & ~(obs.lo | obs.hi)
    return int(values.sum()) - 6


def fit_noise(model: FitModel, obs: Observations, starts: list[dict[str, np.ndarray]], *, max_steps: int = 1000,
              rounds: int = 3) -> NoiseFit:  # fmt: skip
    """Fit one pigment to rows with their noise (module docstring).

    **Arguments:**

    - `model`: the `FitModel` (loss `"noise"`).
    - `obs`: the `Observations`.
    - `starts`: starting points (`log_K`, `log_S`, (3,) each).
    - `max_steps`: Levenberg-Marquardt steps at most, per run.
    - `rounds`: at most this many refits as the dispersion is re-estimated.

    **Returns:** a `NoiseFit`.
    """
    G = obs.gain_sd.shape[0]
    # The black band's nuisance is always there (without a band it touches no row and only its prior holds it
    # at 0): one compiled program serves cards with and without a band.
    nuisance = {"log_gain": np.zeros((G, 3)), "log_black": np.zeros(3)}
    if obs.black_sd is None:
        obs = dataclasses.replace(obs, black_sd=np.ones(3))
    starts = [{**s, **nuisance} for s in starts]
    pins = (np.zeros(6), np.zeros(6))
    dof = _degrees_of_freedom(obs)
    tau = 0.0
    theta, loss, steps, ok, J = _solve(model, max_steps, _rows(obs, tau), starts, pins)
    total = steps
    for _ in range(rounds):
        new = _dispersion(obs, _differences(model, obs, theta), dof)
        if abs(new - tau) <= 0.05 * max(new, 1e-3):
            break
        tau = new
        theta, loss, steps, ok, J = _solve(model, max_steps, _rows(obs, tau), [theta], pins)
        total += steps
    cov = _covariance(J)
    chi2 = _chi2(obs, _differences(model, obs, theta), tau)
    fitted, jac = _prediction_and_jacobian(model, theta, obs.amount, _grounds(obs, theta))
    return NoiseFit(theta=theta, cov=cov[:6, :6], dispersion=tau, chi2=chi2, dof=dof, steps=total, converged=ok,
                    fitted=fitted, jac_pred=jac)  # fmt: skip


def _covariance(J: np.ndarray) -> np.ndarray:
    """(J^T J)^-1 of a whitened Jacobian (a pseudo-inverse: an undetermined direction gets an infinite variance)."""
    w, V = np.linalg.eigh(J.T @ J)
    tiny = max(float(w.max()), 1e-300) * 1e-12
    good = w > tiny
    cov = (V * np.where(good, 1 / np.where(good, w, 1), 0.0)) @ V.T
    touched = np.any((np.abs(V) > 1e-3) & ~good[None, :], axis=1)
    cov[touched, :] = np.inf
    cov[:, touched] = np.inf
    return cov


@functools.partial(jax.jit, compiler_options=COMPILER_OPTIONS)
def _pred_jac(log_KS: jax.Array, amount: jax.Array, ground: jax.Array):
    def f(x):
        return predict(FitModel(thickness="linear"), {"log_K": x[:3], "log_S": x[3:]}, amount, ground)

    return f(log_KS), jax.jacfwd(f)(log_KS)


def _prediction_and_jacobian(model: FitModel, theta: dict[str, np.ndarray], amount: Any, ground: Any):
    """The pigment's prediction (n, 3) and its derivative with respect to (log_K, log_S), (n, 3, 6)."""
    if model.thickness != "linear":
        raise ValueError("the noise-aware fit models thickness = coats (thickness='linear')")
    x = np.concatenate([theta["log_K"], theta["log_S"]])
    p, J = _pred_jac(*(_cast((x, np.asarray(amount, np.float64), np.asarray(ground, np.float64)))))
    return np.asarray(p, np.float64), np.asarray(J, np.float64)


@dataclass(frozen=True)
class Uncertainty:
    """The uncertainty of a fitted pigment: covariance, degrees of freedom, and what the photo cannot determine.

    **Fields:**

    - `log_cov`: covariance of `(log K_r, log K_g, log K_b, log S_r, log S_g, log S_b)`, (6, 6).
    - `dof`, `dispersion`, `chi2`: the fit's degrees of freedom, relative dispersion tau and chi-square.
    - `reason`: per parameter, why the photo does not determine it (`""` where it does):
      `"noise floor"` (its information comes from channels at the camera's noise floor),
      `"clipped"` (from clipped channels), `"weak"` (its 90% interval spans more than a factor of 10).
    - `side`: per parameter with a reason, the side the data bound it on: +1 an upper bound
      (e.g. a scattering at the noise floor: "S < x"), -1 a lower bound, 0 none.
    """

    log_cov: np.ndarray
    dof: int
    dispersion: float
    chi2: float
    reason: tuple[str, ...]
    side: tuple[int, ...]

    def quantile(self, level: float, two_sided: bool = True) -> float:
        """Student's t quantile for an interval of `level` with this fit's degrees of freedom."""
        p = 0.5 + level / 2 if two_sided else level
        return float(scipy_stats.t.ppf(p, max(self.dof, 1)))

    @property
    def log_sd(self) -> np.ndarray:
        """Standard deviations of the six logs."""
        return np.sqrt(np.diag(self.log_cov))

    def intervals(self, log_value: np.ndarray, level: float = 0.9) -> tuple[np.ndarray, np.ndarray]:
        """Intervals of the six logs holding the truth with probability `level`.

        Two-sided where the photo determines the parameter; one-sided where it only
        bounds it (`side` +1: `(-inf, upper]`, -1: `[lower, inf)`, 0: everything).
        """
        sd = self.log_sd
        two = self.quantile(level)
        one = self.quantile(level, two_sided=False)
        lo, hi = log_value - two * sd, log_value + two * sd
        for j, (why, side) in enumerate(zip(self.reason, self.side)):
            if why and side > 0:
                lo[j], hi[j] = -np.inf, log_value[j] + one * sd[j]
            elif why and side < 0:
                lo[j], hi[j] = log_value[j] - one * sd[j], np.inf
            elif why and not np.isfinite(sd[j]):
                lo[j], hi[j] = -np.inf, np.inf
        return lo, hi

    def to_dict(self) -> dict[str, Any]:
        return {"dof": self.dof, "dispersion": round(float(self.dispersion), 6), "chi2": round(float(self.chi2), 4),
                "log_cov": [[float(v) if np.isfinite(v) else None for v in row] for row in self.log_cov],
                "undetermined": {PARAMETERS[j]: {"reason": r, "side": s}
                                 for j, (r, s) in enumerate(zip(self.reason, self.side)) if r}}  # fmt: skip


def uncertainty(res: NoiseFit, obs: Observations) -> Uncertainty:
    """What the fit determines, and how well (`Uncertainty`)."""
    sd = np.sqrt(np.diag(res.cov))
    reason, side = [], []
    informative = obs.weight > 0
    for j in range(6):
        c = j % 3
        floor_rows = informative & obs.floor[:, c]
        lo_rows = informative & obs.lo[:, c]
        hi_rows = informative & obs.hi[:, c]
        other = informative & ~(obs.floor[:, c] | obs.lo[:, c] | obs.hi[:, c])
        slope = res.jac_pred[:, c, j]
        # How much of the parameter's information (sum of squared standardised sensitivities) each kind of row gives.
        se = np.sqrt(obs.cov[:, c, c] + (obs.relative**2 + res.dispersion**2) * obs.rgb[:, c] ** 2) + 1e-12
        info = (slope / se) ** 2
        from_floor = info[floor_rows].sum() + info[lo_rows].sum()
        from_values = info[other].sum()
        why, s = "", 0
        if from_floor > 3 * from_values and (floor_rows.any() or lo_rows.any()):
            rows = floor_rows | lo_rows
            why, s = "noise floor", int(np.sign(slope[rows].sum()))
        elif hi_rows.any() and (not np.isfinite(sd[j]) or sd[j] > 1.0):
            why, s = "clipped", -int(np.sign(slope[hi_rows].sum()))
        elif not np.isfinite(sd[j]) or 2 * 1.645 * sd[j] > np.log(10):
            why = "weak"
        reason.append(why)
        side.append(s)
    return Uncertainty(log_cov=res.cov, dof=res.dof, dispersion=res.dispersion, chi2=res.chi2,
                       reason=tuple(reason), side=tuple(side))  # fmt: skip
