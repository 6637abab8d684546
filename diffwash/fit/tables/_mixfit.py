r"""Joint fit of mixable pigments to a measurement table: single paints and mixtures at once.

Every pigment's K and S per band, its amount law and (as a model term) its
mixing weight are fitted to all rows of a `diffwash.measurements.Measurements`
together, through the layer law of `diffwash.mixing`:

$$ Kx = \sum_i c_i K_i t_i(A), \quad Sx = \sum_i c_i S_i t_i(A), \quad
   c_i = \frac{w_i a_i}{\sum_j w_j a_j}, \quad t_i(A) = (A/a_0)^{\gamma_i}, $$

then `km.layer` over the row's measured ground (with, as a model term,
Saunderson's surface correction of internal reflectance $k_2$).

- **Spectral tables** (reflectance per band): least squares on log reflectance,
  band by band coupled only by the shared terms (amount laws, weights, $k_2$),
  solved by `BandLevenbergMarquardt` (Schur complement over the bands); then
  (`MixModel.loss = "de2000"`, the default) refined on CIEDE2000 residuals with
  a ridge towards those spectra (`diffwash.fit.tables._seen`).
- **RGB tables** (8-bit sRGB): the pigments are still spectral, on a 380-780 nm,
  10 nm grid, with $\log K(\lambda)$ and $\log S(\lambda)$ smooth (a basis of
  Gaussian bumps and a second-difference penalty): generic priors only. They are
  seen through the sRGB observation (D65, CIE 1931 2-degree), residuals in
  CIEDE2000; a channel clipped at 0 or 255 is a bound, not a measurement.
  Per-channel (3-band) mixing is measured to fail on mixtures (docs/mixing.md).

Which terms generalise to pairs never seen mixed is measured in docs/mixing.md.

**References:**

- D. R. Duncan, "The colour of pigment mixtures", Proc. Phys. Soc. 52 (1940).
- J. L. Saunderson, JOSA 32 (1942).
- B. Triggs et al., "Bundle adjustment: a modern synthesis" (2000).
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import equinox as eqx
import jax
import jax.flatten_util
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jaxtyping import Array

from ... import _regions, colorimetry, km, mixing, spectral
from ..._cache import relieve_compiled_programs
from ...library import Library
from ...measurements import Measurements
from . import _pairs, _posterior, _priors, _seen
from .._bandlsq import GN_TOL, BandLevenbergMarquardt, Convergence, band_covariance, loss_floor, newton_decrement

__all__ = ["MixModel", "MixtureFit", "fit_mixtures", "pair_folds", "pairs", "score_library", "residuals", "RGB_GRID"]

#: The grid of the spectral pigments an RGB table is fitted with (nm).
RGB_GRID = tuple(float(w) for w in range(380, 781, 10))
#: Saunderson's k2 lies in (0, K2_MAX).
K2_MAX = 0.9
#: Spectral residuals are log(R + LOG_FLOOR): relative errors, as the eye sees dark colours.
LOG_FLOOR = 0.01
#: An RGB fit's priors (times `MixModel.prior`), chosen by leave-pairs-out cross-validation on the RGB table
#: (fold seed 1, then measured on seeds 0 and 2; docs/mixing.md): the second-difference penalty on log K and
#: log S over the band grid, and the ridge on the spectral coefficients towards their start (both in
#: CIEDE2000 units per unit log K or S). Ten and twenty times weaker (the first defaults) fit the training
#: rows closer and new pairs worse (51.5%, 4.10 within dE*ab 5 / mean dE2000, against 71.3%, 2.96).
RGB_SMOOTH = 3.0
RGB_RIDGE = 2.0
#: An RGB fit stops when a step changes the parameters and the loss by less than this (relative): its flat
#: directions (spectra three channels cannot tell apart) otherwise creep on for hundreds of steps in float32.
RGB_RTOL = 1e-2
#: An RGB table's pair terms' ridge towards Duncan (`MixModel.pair_ridge`; spectral tables: `_pairs.PAIR_RIDGE`).
#: Three channels pin a pair's spectral terms less than 41 bands do: on rows of measured pairs held out of the
#: NTU RGB table (docs/mixing.md, `bench_mix.py --only seen-rgb`), 3 predicted them better than 1 on four seeds
#: (mean CIEDE2000 2.01 -> 1.93, 2.28 -> 2.16, 2.22 -> 2.11, 1.96 -> 1.85), pairs never mixed as well as before.
RGB_PAIR_RIDGE = 3.0


@dataclass(frozen=True)
class MixModel:
    """The model terms of a mixture fit.

    **Fields:**

    - `gamma`: each pigment's amount-law exponent fitted (else thickness = amount / reference).
    - `weights`: each pigment's mixing weight fitted (else all 1: Duncan).
    - `surface`: Saunderson's $k_2$ fitted (one for the table), else none.
    - `prior`: a factor on the weak priors (the ridge on the shared terms; for RGB tables, `RGB_SMOOTH` and
      `RGB_RIDGE`).
    - `own`: each pigment's amount law applied to its own amount, `Kx = sum_i K_i t_i(a_i)`, instead of
      Duncan's concentrations at the layer's total amount (measured worse: docs/mixing.md; kept to reproduce it).
    - `loss`: what a spectral fit minimises in the end: `"de2000"` (the log-reflectance fit, then refined on
      CIEDE2000 residuals with a ridge of weight `ridge` towards its spectra: `diffwash.fit.tables._seen`) or
      `"spectral"` (log reflectance only). RGB tables are always fitted in CIEDE2000.
    - `ridge`: the refinement's pull towards the spectral fit (CIEDE2000 units per unit log K or log S).
    - `refine_spacing`: the refinement moves the spectra only by sums of Gaussian bumps about this many nm apart
      (`diffwash.fit.tables._seen.smooth_basis`); 0: every band free (spiky spectra; docs/mixing.md).
    - `pairs`: after the pigments, fit `diffwash.mixing.PairTerms` for every pair the table measured mixed
      (`diffwash.fit.tables._pairs`; an RGB table's: on its pigments' smooth spectra, in CIEDE2000 of its sRGB).
    - `pair_ridge`: their ridge towards Duncan (CIEDE2000 units per unit parameter; None: `_pairs.PAIR_RIDGE` for
      spectral tables, `RGB_PAIR_RIDGE` for RGB tables; a fit's `model` holds the value it used).
    - `infer_pairs`: with `pairs`, a pair never measured mixed whose pigments were each measured mixed with others
      takes terms inferred from the measured pairs: its pigments' effects in them and what pairs of like paints
      did (`_pairs.infer_pair_terms`); off: such pairs keep Duncan's law.
    - `scatter_spread`, `gamma_spread`: the table's population priors (`diffwash.fit.tables._priors`): how far a
      pigment's log S (per band) and log amount-law exponent may stray from the table's mean (0: no prior).
    - `one_amount`: hold what the rows leave free (`diffwash.fit.tables._priors.TablePriors`): the amount law of a
      pigment whose layers all have one total amount at the prior exponent, and the scattering of a pigment
      measured alone at one amount over light grounds only near the table's population. Pigments measured at
      several amounts are not affected.
    """

    gamma: bool = True
    weights: bool = False
    surface: bool = False
    prior: float = 1.0
    own: bool = False
    loss: str = "de2000"
    ridge: float = 3.0
    refine_spacing: float = 50.0
    pairs: bool = True
    pair_ridge: float | None = None
    infer_pairs: bool = True
    scatter_spread: float = _priors.SCATTER_SPREAD
    gamma_spread: float = _priors.GAMMA_SPREAD
    one_amount: bool = True

    def describe(self) -> dict[str, Any]:
        return {"gamma": self.gamma, "weights": self.weights, "surface": self.surface, "prior": self.prior,
                "own": self.own, "loss": self.loss, "ridge": self.ridge, "refine_spacing": self.refine_spacing,
                "pairs": self.pairs, "pair_ridge": self.pair_ridge, "infer_pairs": self.infer_pairs,
                "effect_ridge": _pairs.EFFECT_RIDGE, "like_weight": _pairs.LIKE_WEIGHT,
                "like_scale": _pairs.LIKE_SCALE, "scatter_spread": self.scatter_spread,
                "gamma_spread": self.gamma_spread, "one_amount": self.one_amount}  # fmt: skip


@dataclass(frozen=True)
class MixtureFit:
    """The result of `fit_mixtures`: a `Library` and how well it fits each row.

    **Fields:**

    - `library`: the fitted `diffwash.library.Library` (its `fit` holds the record below).
    - `delta_e`: CIEDE2000 of each row, shape (N,); `delta_e_ab`: CIE 1976 dE*ab.
    - `converged`, `iterations`, `seconds`: how the solver ended.
    - `convergence`: each stage's `Convergence` (how far from a minimum it ended; `describe()` says it in words).
    """

    library: Library
    delta_e: np.ndarray
    delta_e_ab: np.ndarray
    converged: bool
    iterations: int
    seconds: float
    model: MixModel = field(default_factory=MixModel)
    convergence: tuple[Convergence, ...] = ()

    def summary(self) -> dict[str, float]:
        """Mean, median, 95th percentile and max dE2000, and the share within dE*ab 5."""
        d = self.delta_e
        return {"mean_de2000": float(d.mean()), "median_de2000": float(np.median(d)),
                "p95_de2000": float(np.percentile(d, 95)), "max_de2000": float(d.max()),
                "share_de_ab_5": float(np.mean(self.delta_e_ab <= 5))}  # fmt: skip

    def save(self, path) -> None:
        """Write the library (with its fit record) as JSON."""
        self.library.save(path)


def _dense(m: Measurements, names: list[str]) -> tuple[np.ndarray, np.ndarray]:
    """Each row's amounts per layer and pigment, shape (N, L, P) (L = 1 for a table without stacks; rows of
    fewer layers padded with empty, transparent layers on top), and its ground's reflectance (N, B)."""
    index = {n: i for i, n in enumerate(names)}
    layers = [m.row_layers(r) for r in range(len(m))]
    A = np.zeros((len(m), max(len(k) for k in layers), len(names)))
    for r, row in enumerate(layers):
        for at, (ps, amts) in enumerate(row):
            for n, a in zip(ps, amts):
                A[r, at, index[n]] += a
    G = np.stack([m.grounds[g] for g in m.ground])
    return A, G


def _one_layer(A: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The rows of `A` (N, L, P) that are a single layer (the rest are glaze stacks), and their amounts (n, P)."""
    rows = np.flatnonzero(np.count_nonzero(A.sum(axis=2), axis=1) <= 1)
    return rows, A[rows].sum(axis=1)


class _PairRows(NamedTuple):
    """The rows pair terms are fitted to (a table's single layers: a stack's layers get no fitted terms): their
    indices `one` (n,), amounts `A1` (n, P), grounds on the palette's bands `G1` (n, B) and measured CIELAB `lab1`."""

    one: np.ndarray
    A1: np.ndarray
    G1: np.ndarray
    lab1: np.ndarray

    @classmethod
    def of(cls, m: Measurements, names, grounds: dict, obs: spectral.Observation) -> "_PairRows":
        """`m`'s, with `grounds` each ground's reflectance on the palette's bands (an RGB table's: smooth spectra)."""
        one, A1 = _one_layer(_dense(m, list(names))[0])
        G = np.stack([np.asarray(grounds[g], np.float64) for g in m.ground])
        return cls(one, A1, G[one], measured_lab(m, obs)[one])


def _layer(K, S, A, G, gamma, w, k2, own: bool = False, bands_first: bool = False):
    """Reflectance of rows `A` (N, P), or glaze stacks (N, L, P) bottom layer first, over grounds `G` (N, B);
    k2 may be 0 (traced). Layers stack as in `mixing.stack_reflectance`. `K`, `S`: (P, B).

    `bands_first`: the reflectance as (B, N), computed in that layout (not transposed at the end): the spectral
    stage's residuals are per band, and XLA on the CPU fuses a transpose into the elementwise Kubelka-Munk chain
    badly, about 10 times slower in the Jacobian's forward-mode products (NTU's table: 0.67 s against 0.07 s)."""
    law = mixing.AmountLaw(gamma=gamma)
    A = A[:, 0] if A.ndim == 3 and A.shape[1] == 1 else A  # one layer: the same arithmetic as before stacks
    if own:  # experiment: each pigment's law at its own amount, t_i(a_i)
        u = law(A) * w
    else:  # mixing.optical_depths' shares (its law, without pair terms)
        u = mixing.concentrations(A, w) * law(jnp.sum(A, axis=-1, keepdims=True))
    out = "b..." if bands_first else "...b"
    Kx, Sx = jnp.einsum(f"...p,pb->{out}", u, K), jnp.einsum(f"...p,pb->{out}", u, S)
    g = mixing.saunderson_in(G.T if bands_first else G, k2)
    R, T = km.layer(Kx, Sx, 1.0)
    if A.ndim == 2:
        return mixing.saunderson_out(km.over(R, T, g), k2)
    for i in range(A.shape[1]):  # bottom layer first; k2 only at the top surface
        g = km.over(R[..., i], T[..., i], g) if bands_first else km.over(R[:, i], T[:, i], g)
    return mixing.saunderson_out(g, k2)


def _shared(shared, P: int, model: MixModel):
    """Amount-law exponents, mixing weights and k2 from the shared parameters (frozen ones at their defaults)."""
    gam = jnp.exp(shared[:P]) if model.gamma else jnp.ones(P, shared.dtype)
    w = jnp.exp(shared[P : 2 * P]) if model.weights else jnp.ones(P, shared.dtype)
    k2 = K2_MAX * jax.nn.sigmoid(shared[2 * P]) if model.surface else jnp.zeros((), shared.dtype)
    return gam, w, k2


def _shared_prior(shared, P: int, model: MixModel, priors: _priors.TablePriors):
    """Weak ridge: exponents near 1, weights near 1 (their common scale is otherwise free), k2 near 0.04; the
    amount laws' population prior (`_priors.gamma_population`) and the prior exponent of the pigments the table
    measured at one amount (`_priors.gamma_fixed`, in the log-reflectance residuals' scale)."""
    lam = 0.01 * model.prior
    pop = _priors.gamma_population(shared[:P], model.gamma_spread if model.gamma else 0.0)
    one = _priors.gamma_fixed(shared[:P], priors if model.gamma else _priors.TablePriors(), _priors.PRIOR_NOISE)
    level = _priors.scatter_level(shared[2 * P + 1 :], priors, _priors.PRIOR_NOISE)
    return jnp.concatenate([lam * shared[: 2 * P], lam * (shared[2 * P : 2 * P + 1] + 3.0), pop, one, level])


def _levels(band: np.ndarray, priors: _priors.TablePriors, P: int, log_gamma=None) -> np.ndarray:
    """The weakly measured pigments' scattering levels (`_priors.scatter_weak`) that `band` (B, 2P) implies: each
    one's mean log S t(a) over the bands (a start, and the latents' value at a fit's end)."""
    w = np.asarray(priors.scatter_weak, int)
    g = np.exp(log_gamma) if log_gamma is not None else np.full(P, _priors.GAMMA_PRIOR)
    return (band[:, P:].mean(axis=0) + g * np.asarray(priors.log_amount))[w] if len(w) else np.zeros(0)


def _pin_amount_laws(y, priors: _priors.TablePriors, P: int, model: MixModel):
    """Each pigment measured at one amount moved along the direction its rows leave exactly flat, to its prior
    exponent: gamma to `priors.gamma_centre`, log K and log S by -(change of gamma) log(A / a0), so every layer it
    is in keeps its optical depths (each is at that one amount A). The solver creeps along such a direction, whose
    only curvature is the prior's, and stops wherever its first steps left it."""
    band, shared = y
    if not model.gamma or not priors.gamma_fixed:
        return y
    lg = np.asarray(shared[:P], np.float64)
    fixed = np.asarray(priors.gamma_fixed, int)
    step = priors.gamma_centre(lg) - lg[fixed]
    shift = np.zeros(2 * P)
    shift[fixed] = shift[P + fixed] = -(np.exp(lg[fixed] + step) - np.exp(lg[fixed])) * np.asarray(priors.fixed_log_amount)
    return band + jnp.asarray(shift, band.dtype), shared.at[fixed].add(jnp.asarray(step, shared.dtype))


def _init_band(m: Measurements, A: np.ndarray, names: list[str]) -> np.ndarray:
    """log K, log S per band from each pigment's thickest single layer: S = 1, K/S from its R_inf."""
    P = len(names)
    Y = m.values
    B = Y.shape[1]
    one, A1 = _one_layer(A)
    logK, logS = np.zeros((B, P)), np.zeros((B, P))
    for i in range(P):
        single = one[(A1[:, i] > 0) & (np.count_nonzero(A1, axis=1) == 1)]
        rows = single if len(single) else np.flatnonzero(A[:, :, i].sum(axis=1) > 0)
        r = np.clip(Y[rows[np.argmax(A[rows].sum(axis=(1, 2)))]], 0.02, 0.95)
        logK[:, i] = np.log((1 - r) ** 2 / (2 * r))
    return np.concatenate([logK, logS], axis=1)


class _Reflect(eqx.Module):
    """`(band, shared) -> R`: every row's reflectance (N, B) from the per-band `log K, log S` (B, 2P) and the
    shared terms.

    The fits' functions are Modules holding their data, not closures over it: a compiled solver is then
    found again by every later fit of the same shapes and model terms (a closure is a new function each
    time, and compiles again: 6.8 s of a 7 s repeat of a small spectral fit)."""

    A: Array
    G: Array
    P: int = eqx.field(static=True)
    model: MixModel = eqx.field(static=True)

    def __call__(self, band, shared, bands_first: bool = False):
        """(N, B); `bands_first`: (B, N) (`_layer`)."""
        gam, w, k2 = _shared(shared, self.P, self.model)
        K, S = jnp.exp(band[:, : self.P]).T, jnp.exp(band[:, self.P :]).T
        return _layer(K, S, self.A, self.G, gam, w, k2, self.model.own, bands_first)


class _SharedPrior(eqx.Module):
    """`shared -> residuals` of the shared terms' prior (`_shared_prior`)."""

    P: int = eqx.field(static=True)
    model: MixModel = eqx.field(static=True)
    priors: _priors.TablePriors = eqx.field(static=True)

    def __call__(self, shared):
        return _shared_prior(shared, self.P, self.model, self.priors)


class _SpectralResiduals(eqx.Module):
    """The spectral stage's residuals `((band, shared), args) -> (per band, shared prior)`: log reflectance
    per band, a weak pull of each band's `log K, log S` towards its start, and the priors on scattering (the
    population's, `MixModel.scatter_spread`; the weakly measured pigments', `_priors.scatter_weak`)."""

    reflect: _Reflect
    Y: Array
    band0: Array
    priors: _priors.TablePriors = eqx.field(static=True)
    w: Array | None = None  # each row's weight (N,) on its log-reflectance residuals (a fold's 0s); None: 1

    def __call__(self, y, args):
        band, shared = y
        P, model = self.reflect.P, self.reflect.model
        eps = 1e-3 * model.prior
        R = self.reflect(band, shared, bands_first=True)  # (B, N): see `_layer`
        pop = _priors.scatter_population(band[:, P:], model.scatter_spread, _priors.LOG_NOISE)
        weak = _priors.scatter_weak(band[:, P:], jnp.log(_shared(shared, P, model)[0]), shared[2 * P + 1 :], self.priors,
                                    _priors.PRIOR_NOISE)  # fmt: skip
        rows = jnp.log(R + LOG_FLOOR) - jnp.log(self.Y.T + LOG_FLOOR)
        per_band = jnp.concatenate([rows if self.w is None else rows * self.w, eps * (band - self.band0),
                                    pop, weak], axis=1)  # fmt: skip
        return per_band, _shared_prior(shared, P, model, self.priors)


def _shared_start(band0, priors: _priors.TablePriors, P: int, model: MixModel):
    """The spectral stage's start of the shared terms: amount-law exponents 1 (a pigment measured at one amount:
    the prior's), mixing weights 1, the surface term's logit -3, the weakly measured pigments' levels."""
    log_gamma0 = np.zeros(P)
    log_gamma0[list(priors.gamma_fixed) if model.gamma else []] = np.log(_priors.GAMMA_PRIOR)  # one amount: the prior
    levels = _levels(np.asarray(band0), priors, P)
    return jnp.asarray(np.concatenate([log_gamma0, np.zeros(P), [-3.0], levels]), band0.dtype)


def _refine_basis(obs: spectral.Observation, model: MixModel, dtype):
    """The CIEDE2000 refinement's smooth basis over the table's bands (`MixModel.refine_spacing`), or None."""
    phi = _seen.smooth_basis(obs.wavelengths, model.refine_spacing)
    return None if phi is None else jnp.asarray(phi, dtype)


def _fit_spectral(m: Measurements, names, model: MixModel, max_steps: int, rtol: float, obs: spectral.Observation,
                  say: Callable[[str], None] = lambda msg: None):  # fmt: skip
    A, G = _dense(m, names)
    P = len(names)
    dtype = jnp.zeros(()).dtype
    A, G, Y = (jnp.asarray(x, dtype) for x in (A, G, m.values))
    band0 = jnp.asarray(_init_band(m, np.asarray(A), names), dtype)
    reflect = _Reflect(A, G, P, model)
    priors = _priors.table_priors(np.asarray(A), np.asarray(G), model.one_amount)
    shared0 = _shared_start(band0, priors, P, model)
    fn = _SpectralResiduals(reflect, Y, band0, priors, jnp.ones(len(m), dtype))  # weights: as its folds'
    if _solved_in_chunks(m, band0):
        y, ok, steps = _solve_in_chunks(fn, (band0, shared0), None, max_steps, rtol, judge=model.loss != "de2000")
        ok = dataclasses.replace(ok, stage="log-reflectance fit")
    else:
        solver = BandLevenbergMarquardt(rtol=rtol, atol=rtol)
        sol = optx.least_squares(fn, solver, (band0, shared0), max_steps=max_steps, throw=False)
        y, steps = sol.value, int(sol.stats["num_steps"])
        ok = Convergence(converged=bool(sol.result == optx.RESULTS.successful), steps=steps, stage="log-reflectance fit")
    y = _pin_amount_laws(y, priors, P, model)
    if model.loss == "de2000":
        say("CIEDE2000 refinement")
        y, ok, more = _seen.refine_in_de2000(reflect, obs.lab, obs.lab(Y), y, ridge=model.ridge,
                                             shared_prior=_SharedPrior(P, model, priors), max_steps=max_steps,
                                             rtol=max(rtol, 1e-5), basis=_refine_basis(obs, model, dtype))  # fmt: skip
        steps += more
    band, shared = _pin_amount_laws(y, priors, P, model)
    gam, w, k2 = _shared(shared, P, model)
    K, S = np.exp(np.asarray(band[:, :P], np.float64)).T, np.exp(np.asarray(band[:, P:], np.float64)).T
    return K, S, np.asarray(gam, np.float64), np.asarray(w, np.float64), float(k2), ok, steps


def _solved_in_chunks(m: Measurements, band0) -> bool:
    """Few rows, many band parameters: most band directions are the weak prior's, along which the solver would creep
    to max_steps; `_fit_spectral` stops when a chunk of steps no longer lowers the loss (`_solve_in_chunks`)."""
    return 3 * len(m) < band0.size


def _compiled_bound(m: Measurements, band0, max_steps: int) -> int:
    """The `max_steps` `_fit_spectral`'s log-reflectance solve is compiled with (its folds share it)."""
    return min(CHUNK, max_steps) if _solved_in_chunks(m, band0) else max_steps


def _rgb_basis(n: int = 10) -> np.ndarray:
    """Gaussian bumps over RGB_GRID, shape (B, n) (plus a constant column)."""
    wl = np.asarray(RGB_GRID)
    c = np.linspace(wl[0], wl[-1], n)
    width = (c[1] - c[0]) * 0.8
    phi = np.exp(-0.5 * ((wl[:, None] - c[None, :]) / width) ** 2)
    return np.concatenate([np.ones((len(wl), 1)), phi], axis=1)


def _rgb_init(m: Measurements, A: np.ndarray, phi: np.ndarray, obs: spectral.Observation) -> np.ndarray:
    """Coefficients (2P, n) from each pigment's thickest single layer: K/S per channel spread over its
    wavelengths (where the channel's row of the observation weighs most), projected onto the basis."""
    P = A.shape[2]
    W = np.abs(np.asarray(obs.to_rgb, np.float64))
    W = W / W.sum(axis=1, keepdims=True)  # (B, 3): how much each band belongs to each channel
    coef = np.zeros((2 * P, phi.shape[1]))
    pinv = np.linalg.pinv(phi)
    one, A1 = _one_layer(A)
    for i in range(P):
        single = one[(A1[:, i] > 0) & (np.count_nonzero(A1, axis=1) == 1)]
        rows = single if len(single) else np.flatnonzero(A[:, :, i].sum(axis=1) > 0)
        r = np.clip(m.values[rows[np.argmax(A[rows].sum(axis=(1, 2)))]], 0.02, 0.95)
        logks = W @ np.log((1 - r) ** 2 / (2 * r))
        coef[i] = pinv @ logks
    return coef


class _RGBResiduals(eqx.Module):
    """An RGB fit's residuals `((coefficients, shared), to_rgb) -> (one "band", shared prior)`: CIEDE2000 of
    every row (a channel at 0 or 255 a bound), the second-difference penalty and the ridge towards the start."""

    A: Array
    G: Array
    Y: Array
    lo: Array
    hi: Array
    phi: Array
    coef0: Array
    white: Array
    P: int = eqx.field(static=True)
    model: MixModel = eqx.field(static=True)
    priors: _priors.TablePriors = eqx.field(static=True)
    w: Array | None = None  # each row's weight (N,) on its colour residuals (a cross-validation fold's 0s); None: 1

    def rgb(self, y, args):
        """Every row's linear sRGB (N, 3) at `y` (`args`: the bands' sRGB matrix)."""
        P, model = self.P, self.model
        flat, shared = y
        coef = flat.reshape(2 * P, self.phi.shape[1])
        gam, w, k2 = _shared(shared, P, model)
        logks = coef @ self.phi.T  # (2P, B)
        K, S = jnp.exp(logks[:P]), jnp.exp(logks[P:])
        return _layer(K, S, self.A, self.G, gam, w, k2, model.own) @ args

    def __call__(self, y, args):
        P = self.P
        flat, shared = y
        coef = flat.reshape(2 * P, self.phi.shape[1])
        rgb = self.rgb(y, args)
        clamp = jax.lax.stop_gradient(rgb)
        target = jnp.where(self.hi, jnp.maximum(self.Y, clamp), jnp.where(self.lo, jnp.minimum(self.Y, clamp), self.Y))
        lab_p = colorimetry.xyz_to_lab(colorimetry.linear_srgb_to_xyz(rgb), self.white)
        lab_m = colorimetry.xyz_to_lab(colorimetry.linear_srgb_to_xyz(target), self.white)
        r = colorimetry.delta_e_2000_residuals(lab_m, lab_p)
        r = (r if self.w is None else r * self.w[:, None]).ravel()
        model = self.model
        # One "band" holding every coefficient: BandLevenbergMarquardt is then a dense LM by normal equations.
        ridge = RGB_RIDGE * model.prior * (coef - self.coef0).ravel()  # pins the directions three channels leave free
        D = np.diff(np.eye(self.phi.shape[1] - 1), n=2, axis=0)  # second differences of the bumps' coefficients
        per_band = jnp.concatenate([r, RGB_SMOOTH * model.prior * (coef[:, 1:] @ D.T).ravel(), ridge])[None]
        return per_band, _shared_prior(shared, P, model, self.priors)


@eqx.filter_jit
def _rgb_lab(fn: _RGBResiduals, y, args):
    """Every row's CIELAB as the RGB fit `fn` predicts it at `y` (sRGB, D65)."""
    return colorimetry.xyz_to_lab(colorimetry.linear_srgb_to_xyz(fn.rgb(y, args)), fn.white)


def _fit_rgb(m: Measurements, names, model: MixModel, max_steps: int, rtol: float):
    obs = spectral.observation(RGB_GRID)
    A, G3 = _dense(m, names)
    P = len(names)
    dtype = jnp.zeros(()).dtype
    phi = _rgb_basis()
    # Each ground's spectrum: flat, scaled per channel to its measured colour (the smoothest fit there is).
    grounds = {g: _flat_ground(v, obs) for g, v in m.grounds.items()}
    G = np.stack([grounds[g] for g in m.ground])
    coef0 = jnp.asarray(_rgb_init(m, A, phi, obs), dtype)
    shared0 = jnp.zeros(2 * P + 1, dtype).at[2 * P].set(-3.0)
    cast = lambda x: jnp.asarray(x, dtype)  # noqa: E731
    fn = _RGBResiduals(cast(A), cast(G), cast(m.values), jnp.asarray(m.lo), jnp.asarray(m.hi), cast(phi), coef0,
                       cast(colorimetry.WHITE_D65), P, model,
                       dataclasses.replace(_priors.table_priors(A, G, model.one_amount), scatter_weak=()),
                       jnp.ones(len(m), dtype))  # weights: as its folds', which then share its compiled solver  # fmt: skip
    start, args = (coef0.reshape(1, -1), shared0), cast(obs.to_rgb)
    (flat, shared), ok, steps = _solve_in_chunks(fn, start, args, max_steps, rtol)
    gam, w, k2 = _shared(shared, P, model)
    out = (*_rgb_spectra(flat, P), np.asarray(gam, np.float64), np.asarray(w, np.float64), float(k2))
    return (*out, ok, steps), grounds, obs, _RGBFit(fn, start, (flat, shared), args, max_steps, rtol)


def _rgb_spectra(flat, P: int) -> tuple[np.ndarray, np.ndarray]:
    """K and S (P, B) over `RGB_GRID` of an RGB fit's basis coefficients `flat` ((2P, n) in any shape: log K and
    log S are their sums of `_rgb_basis`)."""
    phi = _rgb_basis()
    logks = np.asarray(flat, np.float64).reshape(2 * P, phi.shape[1]) @ phi.T
    return np.exp(logks[:P]), np.exp(logks[P:])


@dataclasses.dataclass(frozen=True)
class _RGBFit:
    """An RGB fit's problem, its start and solution, for its posterior (`_rgb_posterior`)."""

    fn: _RGBResiduals
    start: tuple
    y: tuple
    args: Array
    max_steps: int
    rtol: float


def _chunk_loss(sol: optx.Solution) -> float:
    """The sum of squares where a chunk of `_solve_in_chunks` ended, from the residuals the solver holds at its
    accepted point (optimistix's Gauss-Newton state pairs them with `sol.value`): no program of its own (one cost
    1.6 s of a 42 s cold fit of an 80-row, 77-band table)."""
    leaves = jax.tree_util.tree_leaves(sol.state.f_info.residual)
    return sum(float(np.sum(np.square(np.asarray(r, np.float64)))) for r in leaves)


#: Steps per call of the solver in `_solve_in_chunks`.
CHUNK = 40


def _solve_in_chunks(fn, y, args, max_steps: int, rtol: float, judge: bool = True):
    """Levenberg-Marquardt in chunks of CHUNK steps, ended by the solver's own test or a plateau of the loss.

    In float32 an RGB fit reaches a point where no step lowers the loss by a representable amount: the
    trust region then rejects every step and optimistix's Cauchy test (which needs an accepted step) never
    fires. A chunk that lowers the loss by less than `rtol` relative is that plateau: converged. Out of steps,
    the fit is converged if a Gauss-Newton step would lower the loss by at most `GN_TOL` of itself.
    Returns `(y, Convergence, steps)` (`judge` False: out of steps is not judged, for a stage whose result only
    starts the next).
    """
    solver = BandLevenbergMarquardt(rtol=rtol, atol=rtol)
    # The loss is read where each chunk ends (`_chunk_loss`); the first chunk, from the start, is never a plateau.
    prev, first, steps = float("inf"), float("inf"), 0
    decrease = lambda a, b: (a - b) / a if np.isfinite(a) else float("nan")  # noqa: E731
    while steps < max_steps:
        sol = optx.least_squares(fn, solver, y, args=args, max_steps=min(CHUNK, max_steps - steps), throw=False)
        y, steps = sol.value, steps + int(sol.stats["num_steps"])
        now = _chunk_loss(sol)
        if sol.result == optx.RESULTS.successful or (np.isfinite(prev) and prev - now <= rtol * prev):
            return y, Convergence(True, steps, last_decrease=decrease(prev, now), window=CHUNK, stage="fit"), steps
        first, prev = prev, now
    dec = float(_decrement(fn, y, args)) if judge else float("nan")  # not judged: a later stage starts from here
    return y, Convergence(dec <= GN_TOL, steps, decrement=dec, last_decrease=decrease(first, prev), window=CHUNK,
                          stage="fit"), steps  # fmt: skip


@eqx.filter_jit
def _decrement(fn, y, args):
    """`newton_decrement` of the least-squares problem `fn` at `y` (its Jacobian by forward mode)."""
    flat, unravel = jax.flatten_util.ravel_pytree(y)
    res = lambda v: jnp.concatenate([jnp.ravel(r) for r in jax.tree_util.tree_leaves(fn(unravel(v), args))])  # noqa: E731
    r, J = res(flat), jax.jacfwd(res)(flat)
    return newton_decrement(J.T @ J, J.T @ r, jnp.sum(r * r), loss_floor(r.shape[0]))


def _flat_ground(linear_rgb: np.ndarray, obs: spectral.Observation) -> np.ndarray:
    """A smooth spectrum whose linear sRGB is `linear_rgb`: the least-norm combination of three smooth bumps."""
    wl = np.asarray(RGB_GRID)
    bumps = np.exp(-0.5 * ((wl[:, None] - np.array([450.0, 550.0, 620.0])) / 60) ** 2)  # (B, 3)
    M = np.asarray(obs.to_rgb, np.float64).T @ bumps  # (3, 3)
    return bumps @ np.linalg.solve(M, np.asarray(linear_rgb, np.float64))


def fit_mixtures(
    m: Measurements, *, model: MixModel = MixModel(), max_steps: int = 400, rtol: float | None = None,
    posterior: bool = True, progress: Callable[[str], None] | None = None, **observe: Any,
) -> MixtureFit:
    r"""Fit every pigment of a measurement table jointly, single paints and mixtures (module docstring).

    **Arguments:**

    - `m`: the `diffwash.measurements.Measurements` (spectral or RGB).
    - `model`: the `MixModel` terms (default: Duncan with a fitted amount law per pigment).
    - `max_steps`: Levenberg-Marquardt steps at most.
    - `rtol`: the solver's tolerance (default: 1e-4 in float32, 1e-7 in float64).
    - `posterior`: keep the parameters' Laplace posterior and the model error measured on the table
      (`diffwash.fit.tables._posterior`; an RGB table's: `_rgb_posterior`), so that predictions carry
      `de2000_90` (spectral tables: when fitted in CIEDE2000, the default).
    - `progress`: called with the name of each stage as it begins (a fit of a large table takes minutes).
    - `observe`: `illuminant`, `observer`, `method` of the `diffwash.spectral.Observation`
      (spectral tables; RGB tables are seen as sRGB: D65, CIE 1931 2-degree).

    **Returns:** a `MixtureFit` (its `library` ready to save and predict with).
    """
    relieve_compiled_programs()  # before this fit compiles: a long-lived process may run out of memory maps
    t0 = time.perf_counter()
    say = progress if progress is not None else (lambda msg: None)
    names = m.names
    held_seen = None
    if model.pair_ridge is None:
        model = dataclasses.replace(model, pair_ridge=_pairs.PAIR_RIDGE if m.spectral else RGB_PAIR_RIDGE)
    if rtol is None:  # RGB: see RGB_RTOL
        rtol = 1e-7 if jnp.zeros(()).dtype == jnp.float64 else (1e-4 if m.spectral else RGB_RTOL)
    if m.spectral:
        obs = m.observation(**observe)
        say("log-reflectance fit")
        K, S, gam, w, k2, ok, steps = _fit_spectral(m, names, model, max_steps, rtol, obs, say)
        grounds = dict(m.grounds)
    else:
        (K, S, gam, w, k2, ok, steps), grounds, obs, rgb_fit = _fit_rgb(m, names, model, max_steps, rtol)
    stages = [ok if isinstance(ok, Convergence) else Convergence(converged=bool(ok), steps=steps, stage="fit")]
    w = w / np.exp(np.mean(np.log(w)))  # the weights' common scale is free: geometric mean 1
    palette = mixing.Palette(K=jnp.asarray(K), S=jnp.asarray(S), law=mixing.AmountLaw(gamma=jnp.asarray(gam)),
                             weights=jnp.asarray(w), names=tuple(names), wavelengths=obs.wavelengths)  # fmt: skip
    one_layer = None
    if model.pairs:
        one_layer = _PairRows.of(m, names, grounds, obs)
        one, A1, G1, lab1 = one_layer
        if n_pairs := len(pairs(m)):
            say(f"pair terms ({n_pairs} pairs)")
        terms, pairs_ok = _pairs.fit_pair_terms(palette, A1, G1, lab1, obs.lab, k2, ridge=model.pair_ridge)
        palette = eqx.tree_at(lambda p: p.pairs, palette, terms, is_leaf=lambda x: x is None)
        stages.append(pairs_ok)
        if posterior and terms is not None:  # how well the terms predict their pairs elsewhere (`_model_errors`)
            held_seen = np.full(len(m), np.nan)
            held_seen[one] = _pairs.held_out_de2000(palette, A1, G1, lab1, obs.lab, k2, ridge=model.pair_ridge)
        if model.infer_pairs and terms is not None:
            inferred = _pairs.infer_pair_terms(terms, pigments=(palette.K, palette.S))
            palette = eqx.tree_at(lambda p: p.pairs, palette, inferred)
    # the folds infer their held-out pairs' terms where the fit inferred terms (`_fold_lab_with_pairs`)
    fold_rows = one_layer if model.infer_pairs and palette.pairs is not None else None
    ok = all(bool(c) for c in stages)
    lib = Library(palette=palette, grounds=grounds, observation=obs, k2=k2)
    de, de_ab = residuals(lib, m)
    fit = MixtureFit(lib, de, de_ab, ok, steps, time.perf_counter() - t0, model)
    rows = _row_record(m, de, de_ab)
    record = {"model": model.describe(), "table": m.path, "converged": ok, "iterations": steps,
              "convergence": [c.to_dict() for c in stages], "summary": fit.summary(), "rows": rows,
              "dominant_rows": dominant_rows(de, rows)}  # fmt: skip
    if model.one_amount:
        priors = _priors.table_priors(*_dense(m, list(names)))
        record["priors"] = priors.describe(list(names), spectral=m.spectral, gamma=model.gamma)
    post = None
    if posterior and m.spectral and model.loss == "de2000":
        say("posterior")
        post = _spectral_posterior(m, list(names), model, palette, k2, obs, lib, say, held_seen, fold_rows, max_steps)
        record["uncertainty"] = post.record
    elif posterior and not m.spectral:
        say("posterior")
        post = _rgb_posterior(m, list(names), model, palette, k2, obs, lib, rgb_fit, say, held_seen, fold_rows)
        record["uncertainty"] = post.record
    lib = Library(palette=palette, grounds=grounds, observation=obs, k2=k2, fit=record, posterior=post)
    return MixtureFit(lib, de, de_ab, ok, steps, time.perf_counter() - t0, model, tuple(stages))


def _spectral_posterior(m: Measurements, names, model: MixModel, palette, k2: float, obs, lib: Library,
                        say: Callable[[str], None] = lambda msg: None, held_seen: np.ndarray | None = None,
                        fold_rows: _PairRows | None = None, max_steps: int = 400):  # fmt: skip
    """The fit's `_regions.Posterior`: Laplace covariance from the spectral stage's problem, each pigment's block
    bounded by its own rows, and the model error of each kind of row (`_model_errors`; `held_seen`: each row's
    CIEDE2000 with it left out of its pair's terms, `_pairs.held_out_de2000`; `fold_rows`, where the fit inferred
    pair terms: the rows a leave-pairs-out fold fits its own pairs' terms to, `_fold_lab_with_pairs`)."""
    P = len(names)
    dtype = jnp.zeros(()).dtype
    A, G = _dense(m, names)
    A, G, Y = (jnp.asarray(x, dtype) for x in (A, G, m.values))
    band = jnp.asarray(np.concatenate([np.log(np.asarray(palette.K)).T, np.log(np.asarray(palette.S)).T], 1), dtype)
    w = np.asarray(palette.weights, np.float64)
    gam = np.asarray(palette.law.gamma, np.float64)
    k2_logit = np.log(k2 / (K2_MAX - k2)) if model.surface and 0 < k2 < K2_MAX else -3.0
    reflect = _Reflect(A, G, P, model)
    band0 = jnp.asarray(_init_band(m, np.asarray(A), names), dtype)
    priors = _priors.table_priors(np.asarray(A), np.asarray(G), model.one_amount)
    levels = _levels(np.asarray(band, np.float64), priors, P, np.log(gam))
    shared = jnp.asarray(np.concatenate([np.log(gam), np.log(w), [k2_logit], levels]), dtype)
    spectral = _SpectralResiduals(reflect, Y, band0, priors, jnp.ones(len(m), dtype))
    if band.size + shared.size <= LAPLACE_DENSE:
        F, diag, sigma = _posterior.laplace(spectral, (band, shared), len(m), P, model.gamma)
    else:  # never the dense (BQ + G)-square matrix and its eigendecompositions: minutes for 40 paints x 77 bands
        theta = _posterior._theta_index(int(band.shape[0]), P, model.gamma)
        F, diag, sigma = band_covariance(spectral, (band, shared), len(m), theta, _posterior.RANK)
        F, diag = _theta_padded(F, diag, int(band.shape[0]), P)
    if (priors.scatter_weak or (model.gamma and priors.gamma_fixed)) and sigma < _priors.PRIOR_NOISE:
        # The fit weighed the one-amount priors against rows of noise PRIOR_NOISE: a paint's rows fix its parameters
        # almost exactly, so their residuals cannot tell their noise. The posterior is that objective's, at that
        # noise: at the residuals' own (0.003 on a generated table) the rows' ground contrast pinned log S to 0.05.
        up = _priors.PRIOR_NOISE / sigma
        F, diag, sigma = F * up, diag * up**2, _priors.PRIOR_NOISE
    from_prior = _from_priors(priors, F, diag, sigma, int(band.shape[0]), P, model)
    pb = _seen._Problem(reflect, obs.lab, jnp.asarray(measured_lab(m, obs), dtype), band, float(model.ridge),
                        _SharedPrior(P, model, priors), basis=_refine_basis(obs, model, dtype))  # fmt: skip
    start = (band0, _shared_start(band0, priors, P, model))  # the fit's own start (`_fit_spectral`)
    def refit(folds, what, pairs: bool = False, **steps):
        """Each fold's held-out CIELAB; `pairs`: predicted as the fit predicts a pair it never measured
        (`_fold_lab_with_pairs`)."""
        def predict(y, test):
            band, shared = y
            K, S = jnp.exp(band[:, :P]).T, jnp.exp(band[:, P:]).T
            return _fold_lab_with_pairs(m, names, model, obs, lib.grounds, fold_rows,
                                        (K, S, *_shared(shared, P, model)), test)  # fmt: skip

        predict = predict if pairs and fold_rows is not None else None
        return _posterior.refit_held_out(spectral, start, pb, folds, rtol=1e-7 if dtype == jnp.float64 else 1e-4,
                                         bound=_compiled_bound(m, start[0], max_steps),
                                         progress=lambda i, n: say(f"{what} fold {i}/{n}"), predict=predict, **steps)

    return _regions_of(m, names, (F, diag, sigma), from_prior, palette, k2, obs, lib, (np.asarray(A), np.asarray(G)),
                       refit, {"noise_log_reflectance": round(sigma, 6)}, held_seen)  # fmt: skip


def _fold_lab_with_pairs(m: Measurements, names, model: MixModel, obs, grounds: dict, rows: _PairRows, params,
                         test: np.ndarray) -> np.ndarray:  # fmt: skip
    """A leave-pairs-out fold's held-out rows' CIELAB as the fit would predict them from the fold's rows alone: the
    fold's pigments `params` = (K, S, gamma, weights, k2) on the palette's bands (`grounds`: each ground's
    reflectance there), its measured pairs' terms fitted to its own among the table's single-layer `rows` (the
    whole table's shapes: one compiled program for every fold), and the held-out pairs' terms inferred from those
    (`_pairs.infer_pair_terms`)."""
    K, S, gam, w, k2 = params
    palette = mixing.Palette(K=jnp.asarray(K), S=jnp.asarray(S), law=mixing.AmountLaw(gamma=jnp.asarray(gam)),
                             weights=jnp.asarray(w), names=tuple(names), wavelengths=obs.wavelengths)  # fmt: skip
    terms, _ = _pairs.fit_pair_terms(palette, rows.A1, rows.G1, rows.lab1, obs.lab, k2, ridge=model.pair_ridge,
                                     use=~np.asarray(test)[rows.one])  # fmt: skip
    inferred = _pairs.infer_pair_terms(terms, pigments=(palette.K, palette.S))
    # Every fold predicts every row of the table, its pairs in one order (`PairTerms.canonical`): the folds share
    # one compiled prediction (each fold's held-out rows, and its measured and inferred pairs, differ).
    palette = eqx.tree_at(lambda p: p.pairs, palette, inferred if inferred is None else inferred.canonical(),
                          is_leaf=lambda x: x is None)  # fmt: skip
    lib = Library(palette=palette, grounds=dict(grounds), observation=obs, k2=float(k2))
    return np.asarray(lib.predict(m).lab, np.float64)[np.asarray(test)]  # its rows with their layers


def _regions_of(m: Measurements, names, laplace, from_prior: dict, palette, k2: float, obs, lib: Library, rows,
                refit, record: dict, held_seen: np.ndarray | None = None) -> _regions.Posterior:  # fmt: skip
    """A fit's `_regions.Posterior` from its Laplace covariance `laplace` = (factor, diagonal, sigma) over theta:
    each pigment's block bounded by its own single rows (`_posterior.shrink_per_pigment`), and the model error of
    each kind of row (`_model_errors`, its folds refitted by `refit`); `rows` = (A, G): the rows' layer amounts
    (N, L, P) and grounds on the palette's bands (N, B)."""
    F, diag, _ = laplace
    P, B = len(names), int(np.asarray(palette.K).shape[1])
    lab_m = measured_lab(m, obs)
    pred = lib.predict(m)  # the rows with their layers: a stack is not a mixture
    kind = np.array(_regions.kinds(m.pigments, pairs(m)))
    An, Gn = rows
    owner = _posterior.owners(P, B)

    def draw(a, sel=slice(None)):
        return _regions.lab_draws(_regions.Posterior(*_posterior.scaled(F, diag, a, owner), {}), palette, An[sel],
                                  Gn[sel], k2, obs.lab)  # fmt: skip

    one = kind == "single"
    index = {n: i for i, n in enumerate(names)}
    row_pigment = np.array([index[p[0]] for p, k in zip(m.pigments, kind) if k == "single"], int)
    a = _posterior.shrink_per_pigment(lambda a: draw(a, one), row_pigment, P, lab_m[one], pred.lab[one])
    F, diag = _posterior.scaled(F, diag, a, owner)
    scale, counts, how = _model_errors(m, kind, lab_m, pred.lab, draw(np.ones(P)), refit, held_seen)
    dark = (An.sum(axis=1) > 0) & (Gn.mean(axis=1) < _priors.DARK)[:, None]  # (N, P): a paint over a dark ground
    over_dark = {n for i, n in enumerate(names) if dark[:, i].any()}
    # A paint whose scattering the one-amount priors decided is reported at the Laplace covariance's, unbounded by
    # its own rows: that bound calibrates the regions, and it squeezes the directions those rows cannot see as well
    # (a paint measured once over two light grounds was reported "log S 0.05; from the prior: scattering"). The
    # prior gives those directions their curvature; elsewhere (a paint fitted to S near 0, flat there: a Laplace sd
    # of 42) the bounded covariance says more.
    unbounded = np.array(["scattering" in from_prior.get(i, []) for i in range(P)])
    F_rep, diag_rep = _posterior.scaled(*laplace[:2], np.where(unbounded, 1.0, a), owner)
    report = _posterior.pigment_report(F_rep, diag_rep, names, B, {n for p in pairs(m) for n in p}, over_dark,
                                       m.spectral)  # fmt: skip
    record = {**record, "covariance_scale": {n: round(float(x), 6) for n, x in zip(names, a)},
              "model_error": {k: round(v, 4) for k, v in scale.items()}, "rows": counts, **how,
              "pigments": _mark_priors(report, from_prior)}  # fmt: skip
    return _regions.Posterior(F, diag, scale, tuple(pairs(m)), record)


def _rgb_posterior(m: Measurements, names, model: MixModel, palette, k2: float, obs, lib: Library, fit: "_RGBFit",
                   say: Callable[[str], None] = lambda msg: None, held_seen: np.ndarray | None = None,
                   fold_rows: _PairRows | None = None) -> _regions.Posterior:  # fmt: skip
    """An RGB fit's `_regions.Posterior`, as a spectral fit's (`_regions_of`): the Laplace covariance of its basis
    coefficients and amount laws (`_rgb_laplace`) carried onto the bands, and its folds refitted from the fit's own
    start to the fit's own test (an RGB fit is quick); a leave-pairs-out fold's held-out pairs predicted with the
    terms it infers for them, where the fit infers terms (`_fold_lab_with_pairs`)."""
    P = len(names)
    F, diag, sigma = _rgb_laplace(fit, len(m), P, model.gamma)
    from_prior = _from_priors(fit.fn.priors, F, diag, sigma, int(np.asarray(palette.K).shape[1]), P, model)

    def refit(folds, what, pairs: bool = False, **steps):
        out = []
        for i, test in enumerate(folds):
            say(f"{what} fold {i + 1}/{len(folds)}")
            w = jnp.asarray(~np.asarray(test), fit.fn.Y.dtype)
            fold = eqx.tree_at(lambda f: f.w, fit.fn, w)
            (flat, shared), _, _ = _solve_in_chunks(fold, fit.start, fit.args, fit.max_steps, fit.rtol, judge=False)
            if pairs and fold_rows is not None:
                params = (*_rgb_spectra(flat, P), *_shared(shared, P, model))
                out.append(_fold_lab_with_pairs(m, names, model, obs, lib.grounds, fold_rows, params, test))
            else:
                out.append(np.asarray(_rgb_lab(fit.fn, (flat, shared), fit.args), np.float64)[np.asarray(test)])
        return out

    return _regions_of(m, names, (F, diag, sigma), from_prior, palette, k2, obs, lib,
                       (np.asarray(fit.fn.A), np.asarray(fit.fn.G)), refit, {"noise_de2000": round(sigma, 6)},
                       held_seen)  # fmt: skip


@eqx.filter_jit
def _rgb_jacobian(fn: "_RGBResiduals", v, n_flat: int, shape, args):
    def res(v):
        per_band, prior = fn((v[:n_flat].reshape(shape), v[n_flat:]), args)
        return jnp.concatenate([per_band.ravel(), prior.ravel()])

    return res(v), jax.jacfwd(res)(v)


def _rgb_laplace(fit: "_RGBFit", n_rows: int, P: int, gamma: bool, rank: int = _posterior.RANK):
    r"""The Laplace posterior of an RGB fit over theta = (log K, log S per band of `RGB_GRID`, log gamma):
    `(factor, diagonal, sigma)` as `_posterior.laplace` gives a spectral fit's. The fit's parameters are basis
    coefficients $c$ (log K and log S $= \Phi c$ per pigment) and the shared terms; $\Sigma_c = \sigma^2 H^{-1}$ at
    the fit (H the Gauss-Newton matrix of every residual: the rows' CIEDE2000 components, the smoothness and ridge
    priors, the shared terms' prior; $\sigma$ 1.4826 times the rows' median absolute component), marginalised onto
    $c$ and log gamma and carried onto the bands, $\Sigma_\theta = M \Sigma_c M^\top$, $M$ = diag($\Phi$ per
    pigment and quantity, identity on log gamma). Without a fitted amount law the log gamma block is 0."""
    flat, shared = fit.y
    phi = np.asarray(fit.fn.phi, np.float64)
    n_flat = int(flat.size)
    v = jnp.concatenate([flat.ravel(), shared])
    r, J = (np.asarray(x, np.float64) for x in _rgb_jacobian(fit.fn, v, n_flat, flat.shape, fit.args))
    sigma2 = float((1.4826 * np.median(np.abs(r[: 3 * n_rows]))) ** 2)
    idx = np.concatenate([np.arange(n_flat), n_flat + np.arange(P) if gamma else np.zeros(0, int)])
    cov = _posterior.marginal_covariance(J.T @ J, idx, sigma2)  # over (c, log gamma)
    B = phi.shape[0]
    M = np.zeros((2 * P * B + P, len(idx)))
    M[: 2 * P * B, :n_flat] = np.kron(np.eye(2 * P), phi)
    if gamma:
        M[2 * P * B :, n_flat:] = np.eye(P)
    return (*_posterior.factored(M @ cov @ M.T, rank), float(np.sqrt(sigma2)))


def _model_errors(m: Measurements, kind, lab_m, lab_p, spread, refit, held_seen: np.ndarray | None = None):
    """The model error of each kind of row (`_regions.KINDS`), the smallest that makes the regions hold
    `_posterior.conformal_level` of its rows (90%, more on a few rows): of the table's own rows for `single` and `seen`
    (a `seen` row whose pair has fitted terms with its CIEDE2000 left out of them, `held_seen`, where given: a
    pair's terms reproduce the few rows they were fitted to, which says nothing of its other amounts);
    for `unseen`, of the held-out rows of leave-pairs-out folds, and for `unmixed`, of folds that hold out every
    mixture of one paint (only where the table has a paint it never mixed: else no row can be of that kind), the
    largest of the folds' (a paint's mixtures are mispredicted together, and paints differ: the error that holds
    90% of each left-out paint's mixtures); each fold refitted from the fit's start by `refit(folds, what, **steps)`
    -> each fold's held-out CIELAB, a paint's folds converged (`_posterior.PAINT_FOLD_STEPS`). A table that mixes
    nothing takes `unmixed` from `_priors.UNMIXED_PRIOR`."""
    scale, rows, how = {}, {}, {}
    for k in ("single", "seen"):
        sel = kind == k
        rows[k] = int(sel.sum())
        if not sel.any():
            continue
        de = None
        if k == "seen" and held_seen is not None and np.isfinite(held_seen[sel]).any():
            own = np.asarray(colorimetry.delta_e_2000(jnp.asarray(lab_m[sel]), jnp.asarray(lab_p[sel])), np.float64)
            de = np.where(np.isfinite(held_seen[sel]), held_seen[sel], own)
            how["seen_from"] = ("each two-pigment row left out of its pair's terms (closed form at the fit's Gauss-Newton "
                                "matrix); other rows in the fit")  # fmt: skip
        scale[k] = _posterior.calibrate_scale(lab_m[sel], lab_p[sel], spread[:, sel], de=de,
                                              share=_posterior.conformal_level(rows[k]))  # fmt: skip
    converged = {"steps": _posterior.PAINT_FOLD_STEPS, "refine_steps": _posterior.PAINT_FOLD_REFINE_STEPS}
    for k, folds, what, steps in (("unseen", [t for _, t in pair_folds(m)], "leave-pairs-out", {}),
                                  ("unmixed", paint_folds(m), "leave-one-paint's-mixtures-out", converged)):  # fmt: skip
        folds = [t for t in folds if t.any()]
        test = np.concatenate([np.flatnonzero(t) for t in folds]) if folds else np.zeros(0, int)
        rows[k] = len(test)
        if not len(test):
            continue
        held = refit(folds, what, pairs=k == "unseen", **steps)
        if k == "unseen":
            scale[k] = _posterior.calibrate_scale(lab_m[test], np.concatenate(held), spread[:, test],
                                                  share=_posterior.conformal_level(len(test)))  # fmt: skip
        else:  # a fold's rows are one paint's: they fail together; hold 90% of each paint's, the worst included
            scale[k] = max(_posterior.calibrate_scale(lab_m[t], h, spread[:, t],
                                                      share=_posterior.conformal_level(int(t.sum())))
                           for t, h in zip(folds, held))  # fmt: skip
        how[f"{k}_from"] = f"{what} cross-validation, {len(folds)} folds refitted from the fit's start"
    if not pairs(m):  # a table that mixes nothing: every mixture holds a paint never mixed, and no fold can tell
        scale["unmixed"] = _priors.UNMIXED_PRIOR
        how["unmixed_from"] = ("the prior (the table holds no mixture): the NTU watercolours' model error with each "
                               "paint measured once; measure a few mixtures to have the table's own")  # fmt: skip
    return scale, rows, how


#: Problems of at most this many parameters take the posterior of `_posterior.laplace` (dense); larger ones
#: `_bandlsq.band_covariance` (the same covariance, through the band structure).
LAPLACE_DENSE = 2000


def _theta_padded(F, diag, B: int, P: int):
    """A covariance over theta without the amount laws (`MixModel.gamma` off) padded with their zero rows, as
    `_posterior.laplace` returns it."""
    m = 2 * P * B + P
    if F.shape[0] == m:
        return F, diag
    pad = m - F.shape[0]
    return np.concatenate([F, np.zeros((pad, F.shape[1]))]), np.concatenate([diag, np.zeros(pad)])


#: A parameter held by a prior came from it, not from the rows, where its posterior variance exceeds this share of
#: the prior's own variance (the rows then add less precision than the prior holds).
FROM_PRIOR = 0.5


def _from_priors(priors: _priors.TablePriors, F, diag, sigma: float, B: int, P: int, model: MixModel) -> dict:
    """Per pigment index, what the table's priors (`_priors.TablePriors`) decided rather than its rows: the amount
    law of every pigment measured at one amount; the scattering of a weakly measured pigment whose posterior
    variance of log S (mean over bands) is above `FROM_PRIOR` of the prior's (both in the residuals' scale)."""
    out: dict[int, list[str]] = {}
    if model.gamma:
        for i in priors.gamma_fixed:
            out.setdefault(i, []).append("amount law")
    var = np.sum(F * F, axis=1) + diag
    if not priors.scatter_weak:
        return out
    prior_var = _priors.scatter_prior_variance(len(priors.scatter_weak)) * (sigma / _priors.PRIOR_NOISE) ** 2
    for i in priors.scatter_weak:
        if np.mean(var[P * B + i * B : P * B + (i + 1) * B]) > FROM_PRIOR * prior_var:
            out.setdefault(i, []).append("scattering")
    return out


def _mark_priors(report: list[dict], from_prior: dict) -> list[dict]:
    """`_posterior.pigment_report` with what the priors decided named as such (`from_the_prior`, `priors`) and the
    measurement that would pin it (a second amount; the paint over black, or a tint with white)."""
    need = {"amount law": "a second amount", "scattering": _posterior.OVER_DARK}
    for i, held in from_prior.items():
        r = report[i]
        r["priors"] = held
        r["from_the_prior"] = list(dict.fromkeys([*r["from_the_prior"], *held]))
        asks = [x for x in r["measure"].split("; ") if x]
        r["measure"] = "; ".join(dict.fromkeys([*[need[h] for h in held], *asks]))
    return report


def measured_lab(m: Measurements, obs: spectral.Observation) -> np.ndarray:
    """CIELAB of a table's measured rows (spectral: through `obs`; RGB: sRGB, D65)."""
    if m.spectral:
        return np.asarray(obs.lab(jnp.asarray(m.values)), np.float64)
    return np.asarray(colorimetry.linear_srgb_to_lab(jnp.asarray(m.values)), np.float64)


def residuals(lib: Library, m: Measurements) -> tuple[np.ndarray, np.ndarray]:
    """CIEDE2000 and CIE 1976 dE*ab between a library's predictions and a table's rows, shape (N,) each."""
    pred = lib.predict(m)
    lab_m = measured_lab(m, lib.observation)
    lab_p = pred.lab if m.spectral else np.asarray(colorimetry.linear_srgb_to_lab(jnp.asarray(pred.linear_srgb)))
    de = np.asarray(colorimetry.delta_e_2000(jnp.asarray(lab_m), jnp.asarray(lab_p)), np.float64)
    return de, np.linalg.norm(lab_m - lab_p, axis=1)


#: A row holding more than this share of a fit's summed squared CIEDE2000 is reported (`dominant_rows`): one row
#: then steers the fit (a typo, a mislabelled patch), however well the fit says it converged.
DOMINANT_SHARE = 0.25


def dominant_rows(de: np.ndarray, rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The rows (`_row_record`'s, with their `"share"` of the loss) that hold more than `DOMINANT_SHARE` of the
    summed squared CIEDE2000 of a fit of at least 4 rows, worst first."""
    de = np.asarray(de, np.float64)
    total = float(np.sum(de * de))
    if len(de) < 4 or total <= 0:
        return []
    share = de * de / total
    return [{**rows[i], "share": round(float(share[i]), 4)} for i in np.argsort(-share) if share[i] > DOMINANT_SHARE]


def _row_record(m: Measurements, de: np.ndarray, de_ab: np.ndarray) -> list[dict[str, Any]]:
    lines = m.lines if m.lines is not None else np.arange(len(m)) + 2
    return [{"line": int(lines[i]), "pigment": m.row_text(i)[0], "amount": m.row_text(i)[1], "ground": str(m.ground[i]),
             "de2000": round(float(de[i]), 4), "de_ab": round(float(de_ab[i]), 4)} for i in range(len(m))]  # fmt: skip


def _mixed_sets(m: Measurements, r: int) -> list[tuple[str, ...]]:
    """The pigment sets (sorted names) mixed within the layers of row `r`."""
    return [tuple(sorted(set(n))) for n, _ in m.row_layers(r) if len(set(n)) > 1]


def pairs(m: Measurements) -> list[tuple[str, ...]]:
    """The distinct pigment sets mixed in one layer in a table's rows (sorted names), in order of appearance."""
    return list(dict.fromkeys(k for r in range(len(m)) for k in _mixed_sets(m, r)))


def pair_folds(m: Measurements, folds: int = 4, seed: int = 0) -> list[tuple[np.ndarray, np.ndarray]]:
    """Leave-pairs-out cross-validation: `(train, test)` row masks, each fold holding out the mixtures of
    about `1/folds` of the pairs (every single paint stays in training).

    The test rows are pairs the fit never saw mixed: what a library must predict for a new pair.
    """
    ps = pairs(m)
    order = np.random.default_rng(seed).permutation(len(ps))
    key = [_mixed_sets(m, r) for r in range(len(m))]  # a stack is held out with any pair mixed in its layers
    out = []
    for f in range(folds):
        held = {ps[i] for i in order[f::folds]}
        test = np.array([any(k in held for k in ks) for ks in key], bool)
        out.append((~test, test))
    return out


def paint_folds(m: Measurements, most: int = 3, seed: int = 0) -> list[np.ndarray]:
    """Test-row masks of folds that each hold out every mixture of one paint, for `most` paints at most (drawn with
    `seed`): a fit that never saw that paint mixed, as a library that never saw a paint mixed must predict its
    mixtures. None where every paint of the table is measured mixed (no query can then be of that kind)."""
    mixed = sorted({n for p in pairs(m) for n in p})
    if not mixed or set(m.names) <= set(mixed):
        return []
    key = [_mixed_sets(m, r) for r in range(len(m))]
    chosen = np.random.default_rng(seed).permutation(len(mixed))[:most]
    return [np.array([any(mixed[i] in k for k in ks) for ks in key], bool) for i in sorted(chosen)]


def score_library(lib: Library, m: Measurements) -> dict[str, float]:
    """Share of rows within CIE dE*ab 5 and mean CIEDE2000 of a library's predictions of a table's rows."""
    de, de_ab = residuals(lib, m)
    return {"rows": len(m), "share_de_ab_5": float(np.mean(de_ab <= 5)), "mean_de2000": float(np.mean(de))}
