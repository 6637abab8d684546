r"""The shared core of pigment fitting: Kubelka-Munk layers over known grounds.

Both a swatch photo and a measurement table come down to the same data: rows
of (amount of paint, reflectance of the ground under it, observed linear RGB
reflectance), some channels clipped by the camera or by the sRGB gamut. This
module fits one pigment's `log K`, `log S` (and optionally the exponent of a
power law from amount to thickness) to such rows with optimistix's
Levenberg-Marquardt from several starting points, over a batch of pigments
(`jax.vmap`ped, or one after another where that is faster: `fit_rows`).

The model of one row (amount `a` over a ground of reflectance `R_g`):

$$ t = a^{\gamma}, \quad (R, T) = \mathrm{layer}(K, S, t), \quad
   \hat R = R + \frac{T^2 R_g}{1 - R R_g} $$

(`diffwash.km.layer` and `diffwash.km.over`, the renderer's own formulas), with
optionally Saunderson's correction between the inside of the paint film and
the measured reflectance. A channel measured at the end of its range (0 or 255)
is a bound, not a value: the prediction is compared with the bound only when it
lies on the wrong side of it.

**References:**

- C. J. Curtis et al., "Computer-Generated Watercolor", SIGGRAPH 1997, sec. 5.1
  (K and S from a layer over black and over white).
- J. L. Saunderson, "Calculation of the color of pigmented plastics", JOSA 32
  (1942) (the surface correction).
- D. B. Judd, "Fresnel reflection of diffusely incident light", J. Res. NBS 29
  (1942) (internal diffuse reflectance 0.596 for refractive index 1.5).
- K. Levenberg (1944), D. Marquardt (1963); P. Kidger et al., optimistix.
"""

from __future__ import annotations

import functools
from typing import Any, Literal

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jaxtyping import Array, ArrayLike, Bool, Float

from .. import colorimetry, km
from .._errors import DiffwashError
from .._shard import shard_leading, unpad
from ._bandlsq import GN_TOL, loss_floor, newton_decrement

__all__ = ["FitModel", "Rows", "predict", "predict_jit", "residuals", "fit_rows", "ground_pair_start", "JUDD_K2", "BATCH_MODES",
           "delta_e_displayed"]

#: Internal diffuse reflectance of a binder-air surface of refractive index 1.5
#: for light arriving diffusely from inside (Judd 1942): Saunderson's `k2`.
JUDD_K2 = 0.596


#: The residual kinds a `FitModel` knows.
LOSSES = ("de2000", "cie94", "lab", "srgb", "noise")


class FitModel(eqx.Module):
    """How measured colours are modelled and compared (static configuration).

    **Fields:**

    - `thickness`: `"linear"` (thickness = amount) or `"power"` (thickness =
      amount**gamma with a fitted exponent gamma per pigment: a wash on absorbent
      paper does not thicken in proportion to the paint put on it; the amount 1
      is thickness 1 whatever gamma is).
    - `surface`: `"none"` (the measured reflectance is the Kubelka-Munk one, as in
      diffwash's shading model) or `"saunderson"` (Saunderson's correction with
      `k1 = 0`, a specular-excluded measurement, and `k2 = k2`).
    - `k2`: Saunderson's internal reflectance (default Judd's 0.596).
    - `loss`: residuals per row: `"de2000"` (the CIEDE2000 difference, the
      figure of merit itself), `"cie94"` (CIE 1994: CIELAB differences with
      chroma and hue weighted by the observed chroma, as CIEDE2000 does but
      without its hue terms; about half the compile time), `"lab"` (CIELAB
      differences), `"srgb"` (display sRGB differences x 100; the plain fit)
      or `"noise"` (linear differences whitened by each row's covariance,
      `Rows.whiten`: residuals in standard deviations of the measurement, so
      that the sum of squares is a chi-square and the fit knows its noise;
      with `Rows.gain_sd`, each photo's calibration gain is fitted too, within
      its own uncertainty).
    - `prior`: weight of a weak prior pulling each pigment's three `log K` (and
      three `log S`) towards their mean, in CIEDE2000 units per unit of log
      (default 0.01: moving a coefficient by a factor e away from the others
      costs a hundredth of a CIEDE2000 unit). It only decides the directions
      the data leave free: a clipped channel, whose coefficient is otherwise
      only bounded, or a channel already opaque at the thinnest amount, where
      only K/S is seen and K and S would drift to infinity together. 0 turns
      it off. (On the NTU training amounts the held-out error is the same
      within 0.01 CIEDE2000 for weights 0.01 to 0.3; larger weights converge
      in fewer steps but bias weakly determined coefficients of noise-free
      data by several per cent.)
    """

    thickness: Literal["linear", "power"] = eqx.field(static=True, default="power")
    surface: Literal["none", "saunderson"] = eqx.field(static=True, default="none")
    k2: float = eqx.field(static=True, default=JUDD_K2)
    loss: Literal["de2000", "cie94", "lab", "srgb", "noise"] = eqx.field(static=True, default="de2000")
    prior: float = eqx.field(static=True, default=0.01)

    def __check_init__(self):
        if self.thickness not in ("linear", "power"):
            raise ValueError(f"thickness must be 'linear' or 'power', got {self.thickness!r}")
        if self.surface not in ("none", "saunderson"):
            raise ValueError(f"surface must be 'none' or 'saunderson', got {self.surface!r}")
        if self.loss not in LOSSES:
            raise ValueError(f"loss must be one of {', '.join(LOSSES)}, got {self.loss!r}")
        if not 0 <= self.k2 < 1:
            raise ValueError(f"k2 must be in [0, 1), got {self.k2!r}")
        if not self.prior >= 0:
            raise ValueError(f"prior must be >= 0, got {self.prior!r}")

    def describe(self) -> dict[str, Any]:
        """The configuration as JSON-ready dict (written with fitted pigments)."""
        out = {"thickness": self.thickness, "surface": self.surface, "loss": self.loss, "prior": self.prior}
        if self.surface == "saunderson":
            out["k1"], out["k2"] = 0.0, self.k2
        return out


#: The plain fit: thickness proportional to amount, display-sRGB residuals, no prior.
PLAIN = FitModel(thickness="linear", surface="none", loss="srgb", prior=0.0)


class Rows(eqx.Module):
    """Observations of one pigment (or a batch of pigments on a leading axis).

    **Fields:**

    - `amount`: amount of paint (thickness before the power law), `>= 0`, shape (M,).
    - `ground`: linear reflectance of the ground under each row, shape (M, 3).
    - `rgb`: observed linear reflectance, shape (M, 3).
    - `lo`, `hi`: channels clipped at the bottom / top of their range (the
      observation is then a bound), shape (M, 3).
    - `weight`: weight of each row (0 for padding rows), shape (M,).
    - `whiten`: for the `"noise"` loss, each row's whitening matrix, the inverse
      of the Cholesky factor of its covariance (linear reflectance), shape (M, 3, 3).
    - `photo`, `gain_sd`: for the `"noise"` loss, the photo each row was measured
      in, shape (M,), and the standard deviation of each photo's calibrated
      log gain per channel, shape (G, 3): the gains are then fitted as nuisance
      parameters `log_gain` (G, 3) with that prior (a row's prediction is
      multiplied by `exp(log_gain[photo])`).
    - `on_black`, `black_sd`: for the `"noise"` loss, which rows lie on the black
      band, shape (M,), and the standard deviation of its measured log
      reflectance, shape (3,): fitted as the nuisance `log_black` (3,) with that
      prior (those rows' ground is multiplied by `exp(log_black)`).
    """

    amount: Float[Array, "*p m"]
    ground: Float[Array, "*p m 3"]
    rgb: Float[Array, "*p m 3"]
    lo: Bool[Array, "*p m 3"]
    hi: Bool[Array, "*p m 3"]
    weight: Float[Array, "*p m"]
    whiten: Float[Array, "*p m 3 3"] | None = None
    photo: Any = None
    gain_sd: Float[Array, "*p g 3"] | None = None
    on_black: Any = None
    black_sd: Float[Array, "*p 3"] | None = None


def _thickness(model: FitModel, amount: Array, log_gamma: Array) -> Array:
    if model.thickness == "linear":
        return amount
    ok = amount > 0
    return jnp.where(ok, jnp.exp(jnp.exp(log_gamma) * jnp.log(jnp.where(ok, amount, 1))), 0)


def _to_internal(model: FitModel, R: Array) -> Array:
    """Measured reflectance to the reflectance inside the film (inverse Saunderson, k1 = 0)."""
    if model.surface == "none":
        return R
    k2 = model.k2
    return R / (1 - k2 + k2 * R)


def _to_measured(model: FitModel, R: Array) -> Array:
    if model.surface == "none":
        return R
    k2 = model.k2
    return (1 - k2) * R / (1 - k2 * R)


def predict(
    model: FitModel, theta: dict[str, Array], amount: Float[ArrayLike, "*m"], ground: Float[ArrayLike, "*m 3"]
) -> Float[Array, "*m 3"]:
    """Measured linear reflectance of the pigment `theta` at `amount` over `ground`.

    **Arguments:**

    - `model`: the `FitModel`.
    - `theta`: `{"log_K": (3,), "log_S": (3,), "log_gamma": ()}`.
    - `amount`: amounts, any shape `*m`.
    - `ground`: the grounds' measured linear reflectance, shape `(*m, 3)`.

    **Returns:**

    Linear RGB reflectance, shape `(*m, 3)`.
    """
    amount = jnp.asarray(amount)
    t = _thickness(model, amount, theta.get("log_gamma", 0.0))[..., None]
    R, T = km.layer(jnp.exp(theta["log_K"]), jnp.exp(theta["log_S"]), t)
    inside = km.over(R, T, _to_internal(model, jnp.asarray(ground)))
    return _to_measured(model, inside)


@functools.partial(jax.jit, static_argnums=0)
def predict_jit(model: FitModel, theta: dict[str, Array], amount: Array, ground: Array) -> Array:
    """`predict`, compiled (for evaluating fitted pigments outside a fit)."""
    return predict(model, theta, amount, ground)


def pad_rows(n: int) -> int:
    """Rows are padded to a multiple of 8, so that a few compiled fits serve any card or table."""
    return max(8, -(-n // 8) * 8)


def effective(pred: Array, obs: Array, lo: Array, hi: Array) -> Array:
    """The prediction as the clipped measurement would have recorded it.

    A channel clipped at the bottom reads `obs` for any true value at or below
    `obs`: there the prediction counts as `max(pred, obs)` (no error while it
    stays below the bound). Likewise `min(pred, obs)` at the top.
    """
    return jnp.where(lo, jnp.maximum(pred, obs), jnp.where(hi, jnp.minimum(pred, obs), pred))


def row_errors(model: FitModel, pred: Array, obs: Array, lo: Array, hi: Array, obs_lab: Array | None = None,
               whiten: Array | None = None) -> Array:  # fmt: skip
    """Residuals per row, shape (M, 3): their squares sum to CIEDE2000^2 with `de2000` (CIE94^2 with `cie94`).

    `obs_lab`, the observations in CIELAB, may be given precomputed; `whiten`
    (M, 3, 3) is needed by the `noise` loss.
    """
    eff = effective(pred, obs, lo, hi)
    if model.loss == "noise":
        if whiten is None:
            raise ValueError("the 'noise' loss needs the rows' whitening matrices (Rows.whiten)")
        return jnp.einsum("mij,mj->mi", whiten, eff - obs)
    if model.loss == "srgb":
        return 100 * (colorimetry.srgb_encode(eff) - colorimetry.srgb_encode(obs))
    lab_o = colorimetry.linear_srgb_to_lab(obs) if obs_lab is None else obs_lab
    lab_p = colorimetry.linear_srgb_to_lab(eff)
    if model.loss == "de2000":
        return colorimetry.delta_e_2000_residuals(lab_p, lab_o)
    if model.loss == "cie94":
        return colorimetry.delta_e_1994_residuals(lab_o, lab_p)
    return lab_p - lab_o


def residuals(theta: dict[str, Array], args: tuple) -> Array:
    """The least-squares residual vector of one pigment (rows, then the prior).

    `args` is `(model, rows)`, or `(model, rows, obs_lab)` with the observations in CIELAB.
    """
    model, rows = args[0], args[1]
    obs_lab = args[2] if len(args) > 2 else None
    ground = rows.ground
    if "log_black" in theta:  # the black band's nuisance reflectance (the noise loss)
        ground = jnp.where(rows.on_black[:, None], ground * jnp.exp(theta["log_black"]), ground)
    pred = predict(model, theta, rows.amount, ground)
    if "log_gain" in theta:  # the calibration's nuisance gains (the noise loss)
        pred = pred * jnp.exp(theta["log_gain"][rows.photo])
    r = row_errors(model, pred, rows.rgb, rows.lo, rows.hi, obs_lab, rows.whiten) * jnp.sqrt(rows.weight)[:, None]
    parts = [r.ravel()]
    if model.prior > 0:
        for key in ("log_K", "log_S"):
            v = theta[key]
            parts.append(model.prior * (v - jnp.mean(v)))
    if "log_gain" in theta:
        parts.append((theta["log_gain"] / rows.gain_sd).ravel())
    if "log_black" in theta:
        parts.append(theta["log_black"] / rows.black_sd)
    if len(args) > 3 and args[3] is not None:  # pins: (weights, values) on the flattened pigment parameters
        w, v = args[3]
        parts.append(w * (jnp.concatenate([theta["log_K"], theta["log_S"]]) - v))
    return jnp.concatenate(parts)


def _tolerance(dtype) -> float:
    return 1e-7 if jnp.dtype(dtype) == jnp.float64 else 1e-4


#: XLA options for the fits' compiled programs: these problems are tiny, so
#: LLVM's expensive optimisations cost far more (seconds of compile time on a
#: cold start) than they could ever save at run time.
COMPILER_OPTIONS = {"xla_backend_optimization_level": 0, "xla_llvm_disable_expensive_passes": True}


def _solve_one(model: FitModel, max_steps: int, rows: Rows, theta0: dict[str, Array], pins: Any = None):
    """One pigment from one start: the solution, its loss, steps, convergence, Jacobian, prediction.

    `pins`, `(weights, values)` of shape (6,) each, add residuals `weights * (theta - values)` on the
    flattened `(log_K, log_S)`: a profile fit holds one parameter with a large weight.
    """
    tol = _tolerance(rows.rgb.dtype)
    solver = optx.LevenbergMarquardt(rtol=tol, atol=tol)
    # The observations' CIELAB once, outside the solver (which traces the residuals several times).
    args = (model, rows, colorimetry.linear_srgb_to_lab(rows.rgb), pins)
    sol = optx.least_squares(residuals, solver, theta0, args=args, max_steps=max_steps, throw=False)
    # The solver's own residuals and Jacobian at the accepted point: no second trace of the model.
    info = sol.state.f_info
    r = info.residual
    J = info.jac.as_matrix()
    fitted = predict(model, sol.value, rows.amount, rows.ground)
    # Out of steps at a minimum (a Gauss-Newton step would gain < GN_TOL of the loss) is converged too.
    at_minimum = newton_decrement(J.T @ J, J.T @ r, jnp.sum(r * r), loss_floor(3 * rows.rgb.shape[-2])) <= GN_TOL
    ok = (sol.result == optx.RESULTS.successful) | at_minimum
    return sol.value, jnp.sum(r * r), sol.stats["num_steps"], ok, J, fitted


@functools.lru_cache(maxsize=None)
def _compiled(model: FitModel, max_steps: int, batched: bool):
    """The jitted fit from one starting point (batched over pigments with `jax.vmap`)."""

    def one(rows: Rows, theta0: dict[str, Array], pins: Any = None):
        return _solve_one(model, max_steps, rows, theta0, pins)

    fn = jax.vmap(one) if batched else one
    return jax.jit(fn, compiler_options=COMPILER_OPTIONS)


#: Multiplicative perturbations of (K, S) around the data-driven start.
_START_FACTORS = ((1.0, 1.0), (1.0, 0.1), (1.0, 10.0), (0.3, 1.0), (3.0, 1.0), (1.0, 100.0))


def ground_pair_start(
    R1: np.ndarray, g1: np.ndarray, R2: np.ndarray, g2: np.ndarray, thickness: float
) -> tuple[np.ndarray, np.ndarray] | None:
    r"""Curtis's black/white inversion from one layer seen over two grounds.

    Over a ground of reflectance `g` the layer shows `R_i = R + T^2 g / (1 - R g)`;
    two grounds give the layer's own `R` (linear in the data, the quadratic
    terms cancel) and `T^2`:

    $$ R = \frac{g_1 R_2 - g_2 R_1}{g_1 - g_2 + g_1 g_2 (R_2 - R_1)}, \qquad
       T^2 = \frac{(R_1 - R)(1 - R g_1)}{g_1}. $$

    Over ideal black and white it would show `R` and `R + T^2 / (1 - R)`,
    which `diffwash.km.invert_black_white` turns into `K`, `S` (divided by the
    layer's thickness to make them per unit).

    **Returns:**

    `(K, S)` per unit thickness, or None where the grounds are too alike to tell.
    """
    R1, g1, R2, g2 = (np.asarray(v, np.float64) for v in (R1, g1, R2, g2))
    if np.any(np.abs(g1 - g2) < 0.1) or thickness <= 0:
        return None
    den = g1 - g2 + g1 * g2 * (R2 - R1)
    R = np.clip((g1 * R2 - g2 * R1) / np.where(np.abs(den) > 1e-9, den, 1e-9), 1e-4, 0.98)
    gt = np.where(g1 > g2, g1, g2)
    Rt = np.where(g1 > g2, R1, R2)
    T2 = np.clip((Rt - R) * (1 - R * gt) / gt, 1e-8, (1 - R) ** 2)
    R_white = R + T2 / (1 - R)
    K, S = _invert(R_white, R)
    return np.asarray(K, np.float64) / thickness, np.asarray(S, np.float64) / thickness


_invert = jax.jit(km.invert_black_white)


def paired_start(
    amount: np.ndarray, ground: np.ndarray, rgb: np.ndarray, paper: np.ndarray, black: np.ndarray | None
) -> tuple[np.ndarray, np.ndarray] | None:
    """Curtis's inversion (`ground_pair_start`) at every amount seen over both paper and black.

    `ground` holds "paper"/"black" per row. **Returns:** the median (in log) of the
    per-amount `(K, S)` estimates, or None where no amount was seen over both.
    """
    estimates = []
    if black is not None:
        for a in np.unique(amount[amount > 0]):
            on_p = (amount == a) & (ground == "paper")
            on_b = (amount == a) & (ground == "black")
            if np.any(on_p) and np.any(on_b):
                ks = ground_pair_start(rgb[on_p].mean(0), paper, rgb[on_b].mean(0), black, float(a))
                if ks is not None:
                    estimates.append(ks)
    if not estimates:
        return None
    K0 = np.exp(np.median([np.log(k) for k, _ in estimates], axis=0))
    S0 = np.exp(np.median([np.log(s) for _, s in estimates], axis=0))
    return K0, S0


def single_ground_start(amount: np.ndarray, ground: np.ndarray, rgb: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A rough (K, S) per unit amount from rows over one kind of ground.

    `K` from the thinnest row as if it were a pure absorber over its ground
    (`R = R_g exp(-2 K t)`), `S` from the thickest row as if it were already
    opaque (`K/S = (1 - R)^2 / (2 R)`). Only a starting point.
    """
    order = np.argsort(amount)
    t1, g1, r1 = amount[order[0]], ground[order[0]], rgb[order[0]]
    tn, rn = amount[order[-1]], rgb[order[-1]]
    ratio = np.clip(r1 / np.maximum(g1, 1e-4), 1e-4, None)
    K = np.where(ratio < 0.98, -np.log(np.minimum(ratio, 0.98)) / (2 * t1), 0.01 / t1)
    Rn = np.clip(rn, 1e-3, 0.98)
    k_over_s = (1 - Rn) ** 2 / (2 * Rn)
    S = K / np.maximum(k_over_s, 1e-3)
    scale = 1 / max(float(tn), 1e-9)
    return np.clip(K, 1e-3 * scale, 1e4 * scale), np.clip(S, 1e-3 * scale, 1e4 * scale)


def starts_for(model: FitModel, K0: np.ndarray, S0: np.ndarray) -> dict[str, np.ndarray]:
    """The multistart set around one estimate: `(len(_START_FACTORS), ...)` arrays."""
    log_K = np.stack([np.log(K0 * fk) for fk, _ in _START_FACTORS])
    log_S = np.stack([np.log(S0 * fs) for _, fs in _START_FACTORS])
    out = {"log_K": log_K, "log_S": log_S}
    if model.thickness == "power":
        out["log_gamma"] = np.zeros(len(_START_FACTORS))
    return out


class BatchFit(eqx.Module):
    """Fitted parameters of a batch of pigments and how the fit went (leading axis P).

    `jacobian` is the residuals' Jacobian at the solution, columns in the
    order of `param_names`; `fitted` the predicted linear colour of each row.
    """

    theta: dict[str, Any]
    loss: Any
    steps: Any
    converged: Any
    jacobian: Any
    fitted: Any
    param_names: tuple[str, ...] = eqx.field(static=True)


#: How `fit_rows` runs a batch of pigments.
BATCH_MODES = ("auto", "vmap", "loop")

#: With `batch="auto"` on a CPU, batches up to this many pigments run one after another.
LOOP_MAX_PIGMENTS = 16


def batch_mode(batch: str, n_pigments: int) -> str:
    """`"vmap"` or `"loop"` for `batch` (see `fit_rows`)."""
    if batch not in BATCH_MODES:
        raise DiffwashError(f"must be one of {', '.join(BATCH_MODES)}, got {batch!r}", field="batch")
    if batch != "auto":
        return batch
    return "loop" if jax.default_backend() == "cpu" and n_pigments <= LOOP_MAX_PIGMENTS else "vmap"


def fit_rows(
    model: FitModel, rows: Rows, starts: dict[str, np.ndarray], *, max_steps: int = 1000, batch: str = "vmap"
) -> BatchFit:
    """Fit a batch of pigments to their rows with Levenberg-Marquardt, all at once.

    Levenberg-Marquardt runs from each starting point and each pigment keeps
    its best (lowest loss) solution. The pigments' problems are independent;
    `batch` says how they run:

    - `"vmap"`: one compiled program, `jax.vmap`ped over the pigments (the
      way to fit many pigments on an accelerator), the pigments sharded over
      all devices (`diffwash._shard`; docs/scaling.md);
    - `"loop"`: the unbatched program once per pigment. On a CPU with a few
      pigments this is the faster of the two, warm and cold: a vmapped
      `while_loop` steps every pigment until the slowest has converged, and
      batching the solver's loop costs seconds of tracing and compilation
      (`benchmarks/bench_fit.py` measures both);
    - `"auto"`: `"loop"` on a CPU for up to `LOOP_MAX_PIGMENTS` pigments,
      else `"vmap"`.

    One pigment always runs unbatched.

    **Arguments:**

    - `model`: the `FitModel`.
    - `rows`: a `Rows` batch, leading axis P (pigments), rows padded to one M
      with `weight = 0`.
    - `starts`: starting points, arrays with leading axes (P, number of starts).
    - `max_steps`: the most LM steps.

    **Returns:**

    A `BatchFit`: per pigment the solution (`theta` arrays with leading axis P),
    its loss (sum of squared residuals), steps, whether LM converged, the
    Jacobian of the residuals there and the fitted colours.
    """
    dtype = jnp.zeros(()).dtype  # float32 unless x64 is enabled
    rows = jax.tree.map(lambda a: jnp.asarray(a, dtype) if np.asarray(a).dtype.kind == "f" else jnp.asarray(a), rows)
    starts = {k: jnp.asarray(v, dtype) for k, v in starts.items()}
    P = rows.amount.shape[0]
    n_starts = next(iter(starts.values())).shape[1]
    # Levenberg-Marquardt from every start (one compiled program, called once per start), keeping
    # each pigment's best: a fit from a single start can stop in a poor local minimum, or on a
    # plateau where float32 steps look converged.
    vmapped = P > 1 and batch_mode(batch, P) == "vmap"
    fn = _compiled(model, max_steps, vmapped)
    runs = []
    for s in range(n_starts):
        theta0 = {k: v[:, s] for k, v in starts.items()}
        if vmapped:  # the pigments split over all devices (a no-op with one)
            (rows_s, theta_s), _ = shard_leading((rows, theta0), P)
            out = unpad(fn(rows_s, theta_s), P)
        else:
            each = [fn(jax.tree.map(lambda a: a[p], rows), {k: v[p] for k, v in theta0.items()}) for p in range(P)]
            out = jax.tree.map(lambda *a: np.stack([np.asarray(x) for x in a]), *each)
        runs.append(out)
    losses = np.stack([np.asarray(r[1]) for r in runs])  # (starts, P)
    best = np.argmin(np.where(np.isfinite(losses), losses, np.inf), axis=0)
    out = jax.tree.map(lambda *a: np.stack([np.asarray(x) for x in a])[best, np.arange(P)], *runs)
    theta, loss, steps, ok, J, fitted = out
    names = tuple(sorted(theta))  # the order in which the Jacobian's columns are flattened
    return BatchFit(theta=theta, loss=loss, steps=steps, converged=ok, jacobian=J, fitted=fitted, param_names=names)


def log_sd(jacobian: np.ndarray, sizes: dict[str, int], loss: float) -> dict[str, np.ndarray]:
    """Standard deviations of the fitted log-parameters (Gauss-Newton covariance).

    **Arguments:**

    - `jacobian`: the residuals' Jacobian (n_res, n_params) at the solution.
    - `sizes`: the parameters' names and sizes, in the Jacobian's column order.
    - `loss`: the sum of squared residuals.

    The covariance is `s^2 (J^T J)^-1` with `s^2` the residual variance (at
    least 1: one unit of colour difference, about a just-noticeable
    difference, when the fit is better than that), so the figures read as how
    far each parameter can move before the fit gets noticeably worse.
    Infinite where a direction is not determined at all.
    """
    J = np.asarray(jacobian, np.float64)
    n_res, n_par = J.shape
    s2 = max(float(loss) / max(n_res - n_par, 1), 1.0)
    w, V = np.linalg.eigh(J.T @ J)
    tiny = max(float(w.max()), 1e-300) * 1e-10
    good = w > tiny
    inv_w = np.where(good, 1 / np.where(good, w, 1), 0.0)
    var = (V * V) @ inv_w
    # A parameter that an undetermined direction moves is itself undetermined.
    touched = np.any((np.abs(V) > 1e-3) & ~good[None, :], axis=1)
    sd = np.where(touched, np.inf, np.sqrt(s2 * var))
    out, i = {}, 0
    for k, n in sizes.items():
        out[k] = sd[i : i + n]
        i += n
    return out


def delta_e_displayed(pred_linear: Any, obs_linear: Any) -> np.ndarray:
    """CIEDE2000 between two linear colours after clipping both into the sRGB cube."""
    return np.asarray(_delta_e_displayed(np.asarray(pred_linear), np.asarray(obs_linear)), np.float64)


@jax.jit
def _delta_e_displayed(pred: Any, obs: Any) -> Any:
    p = jnp.clip(colorimetry.srgb_encode(pred), 0, 1)
    o = jnp.clip(colorimetry.srgb_encode(obs), 0, 1)
    return colorimetry.delta_e_2000(colorimetry.srgb_to_lab(p), colorimetry.srgb_to_lab(o))
