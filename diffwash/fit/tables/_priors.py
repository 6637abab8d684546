r"""Priors shared by the pigments of a table: a population of scattering levels and amount laws.

One amount per paint over light grounds (or only over white paper) cannot tell a
pigment's absorption from its scattering, nor fix its amount law: a free fit then
picks extreme values (S = 0, exponents from 0.1 to 5) that reproduce the rows it saw
and mispredict every mixture. The pigments of one table are paints of one maker and
binder, so they are treated as draws from one population (empirical Bayes: the
population's centre is estimated from the table itself, its spread fixed):

$$ \log S_{b,i} \sim \mathcal N\bigl(\overline{\log S_b},\ \tau_S^2\bigr), \qquad
   \log \gamma_i \sim \mathcal N\bigl(\overline{\log \gamma},\ \tau_\gamma^2\bigr), $$

with $\overline{\cdot}$ the mean over the table's pigments (in band $b$ for $S$).
A pigment whose rows pin its scattering or its amount law moves away from the
population freely (its data outweigh the prior); one whose rows say nothing stays
near its peers instead of running off. The residuals below are those priors'
square roots, added to the fits' least-squares problems (`diffwash.fit.tables._mixfit`):
per band (they couple the pigments of one band only, so the band-separable solver
keeps its structure) and on the shared parameters.

**What one amount leaves free** (`TablePriors`, on by default: `MixModel.one_amount`). Independently of the
spreads above, the rows themselves say which pigments they cannot pin, and only those are held:

- a pigment whose every layer in the table has one total amount (one brushed amount per paint, mixtures at that
  same total) has no amount law: its exponent is held at `GAMMA_PRIOR` (with `GAMMA_PRIOR_SD`), or, where other
  pigments of the table fix theirs, near their mean (`GAMMA_PSEUDO` pseudo-pigments of weight on the prior);
- a pigment measured alone at one amount, only over light grounds (mean reflectance above `DARK`) and in no
  glaze stack, fixes its colour there, not its K and S apart: its log S per band is held near the table's mean
  in that band with the spread `SCATTER_PRIOR` (a one-constant K/S average is that prior at spread 0), and the
  mean scattering depth of such pigments' measured layers, $\overline{\log S_i t_i(a_i)}$, near `LEVEL`
  (spread `LEVEL_SPREAD`), which only decides where no row does (every paint opaque). The peers' mean shape in
  each band is itself held near 0 (spread `COMMON_SPREAD`): that is what ties the levels to the layers'
  scattering. Without it (until 2026-11-27) the levels could all move at once without changing a residual, and
  what no row decided was held at the fit's start, S = 1 per unit of amount: a table written in mL and the same
  in coats predicted glaze stacks up to 3 CIEDE2000 apart.

Pigments at several amounts (the NTU tables) get none of this: their fits are unchanged.

The values are learnt from real watercolour: the default fit of the whole NTU spectral table
(`data/ntu-wpsm/ntu-spectral-train.csv`: 13 Winsor & Newton paints at 11-12 amounts and their mixtures, 1,858
rows) has amount-law exponents 0.52-0.86 (geometric mean 0.685, standard deviation of log 0.154), and its log S
per band spreads across the 13 paints with a standard deviation of 0.68-1.22 (median 0.83; mean log S at
0.05 mL: -0.32). What they gave on held-out mixtures (a generated "other maker" and NTU itself) is in
docs/mixing.md ("One amount per paint").

**The explicit spreads** (`MixModel(scatter_spread=..., gamma_spread=...)`, every pigment of the table, off by
default: spreads 0; measured with every band free in the refinement): on notebook 07's example (NTU P1, P4, P7,
P12 with P1+P12 and P12+P7 held out, 32 rows) the held-out mean CIEDE2000 was 15.56 without them, 15.39 with
spreads (1.0, 0.3), 15.43 with (0.5, 0.2), 14.88 with (0.1, 0.3) and 12.44 with (0.03, 0.1) (the training
rows' mean went from 1.19 to 1.32): P12's log S rose from -9.1 to -2.4 and its exponent from 0.14 to 0.26, but
its mixtures stay far off, because what the
held-out rows need (how P12 mixes) is not what the priors constrain. On a noise-free generated table they bias
the recovered pigments (mean CIEDE2000 0.05 -> 0.10).
"""

from __future__ import annotations

from dataclasses import dataclass

import jax.numpy as jnp
import numpy as np

__all__ = ["GAMMA_SPREAD", "SCATTER_SPREAD", "scatter_population", "gamma_population", "TablePriors", "table_priors",
           "GAMMA_PRIOR", "GAMMA_PRIOR_SD", "SCATTER_PRIOR", "scatter_prior_variance"]

#: $\tau_S$: spread of a pigment's log S around the table's mean log S in the same band (natural log units).
SCATTER_SPREAD = 0.0
#: The scale of a spectral fit's residuals (log reflectance) the scattering prior is weighed against.
LOG_NOISE = 0.03
#: $\tau_\gamma$: spread of a pigment's log amount-law exponent around the table's mean.
GAMMA_SPREAD = 0.0


def scatter_population(log_s, spread: float, scale: float = 1.0):
    """Residuals of the scattering population prior for one band's (or every band's) `log S` of shape
    (..., P): `scale * (log S - mean over pigments) / spread`, shape (..., P). None when `spread` <= 0."""
    if spread <= 0 or log_s.shape[-1] < 2:
        return jnp.zeros(log_s.shape[:-1] + (0,), log_s.dtype)
    return scale * (log_s - jnp.mean(log_s, axis=-1, keepdims=True)) / spread


def gamma_population(log_gamma, spread: float, scale: float = 1.0):
    """Residuals of the amount-law population prior: `scale * (log gamma - mean) / spread`, shape (P,)."""
    if spread <= 0 or log_gamma.shape[-1] < 2:
        return jnp.zeros((0,), log_gamma.dtype)
    return scale * (log_gamma - jnp.mean(log_gamma)) / spread


#: The amount-law exponent a pigment measured at one amount is held at: the geometric mean of the NTU paints'.
GAMMA_PRIOR = 0.685
#: The spread (natural log) of that prior: the NTU paints' exponents' standard deviation of log.
GAMMA_PRIOR_SD = 0.154
#: Pseudo-pigments of weight on `GAMMA_PRIOR` when other pigments of the table fix their exponents.
GAMMA_PSEUDO = 2.0
#: The spread (natural log) of the shape of a weakly measured pigment's log S over the bands (log S less its level,
#: a latent per pigment) around the mean shape of its peers in each band: the NTU paints' (median over bands).
SCATTER_PRIOR = 0.59
#: The spread of the weakly measured pigments' levels of scattering (their layers' log S t(a), one per pigment)
#: around their mean: the NTU paints' (their mean log S over the bands spreads by 0.63). A wider spread (1.5, for
#: a palette from dyes to whites) predicted held-out mixtures worse on the generated tables (docs/mixing.md).
LEVEL_POP = 0.63
#: Where no row decides it, the mean level is held near LEVEL (S t = 1: a layer as scattering as it is thick,
#: mid-range of the NTU paints at 0.05 mL) with this spread: weak, it settles the common scale that opaque layers
#: leave free.
LEVEL = 0.0
LEVEL_SPREAD = 1.5
#: The spread (natural log) of the weakly measured pigments' mean scattering shape in one band around their mean
#: level: how far the peers' common log S t in a band may stray from their level. Weak; with many bands it ties
#: the levels (and so `LEVEL`) to the layers' scattering.
COMMON_SPREAD = 1.0
#: The model error (CIELAB units per axis) of a mixture predicted from a table that holds no mixture at all, where
#: no fold of the table can measure it (`diffwash.fit.tables._mixfit._model_errors`): the NTU watercolours' with each paint
#: once at 0.06 mL (13 rows), the error that makes the 90% regions hold 90% of their 198 mixtures at 0.06 mL (6.87;
#: 7.03 for the 216 at 0.03 mL, 6.52 for the 186 at 0.12 mL: `python benchmarks/bench_oneamount.py --only ntu`).
UNMIXED_PRIOR = 6.9
#: The log-reflectance scale the one-amount priors are weighed against (`TablePriors`), as the population priors
#: are (`LOG_NOISE`). Two rows of a paint fix its two parameters per band almost exactly, so the fit's residuals
#: cannot tell how noisy the rows are; this says how far they are trusted against the priors. Weighed against 0.01
#: instead (a spectrophotometer's repeatability), the priors were too weak: held-out mixtures of the generated
#: tables came out worse than a one-constant average (docs/mixing.md).
PRIOR_NOISE = LOG_NOISE
#: A ground darker than this (mean reflectance) separates K from S: paint over it is not "over light grounds".
DARK = 0.3


@dataclass(frozen=True)
class TablePriors:
    """Which pigments a table's rows leave free, and what holds them (static: part of the compiled functions).

    **Fields:**

    - `gamma_fixed`: indices of the pigments whose every layer has one total amount (no amount law).
    - `gamma_free`: the others (their exponents, if any, centre the fixed ones' prior).
    - `scatter_weak`: indices of the pigments measured alone at one amount over light grounds only.
    - `log_amount`: every pigment's log(a / a0) (a0 = 0.05) at its measured amount alone (the geometric mean of its
      amounts; 0 where it is never alone): a layer's scattering depth is then log S + gamma log_amount.
    - `fixed_log_amount`: for each pigment of `gamma_fixed`, log(A / a0) of the one total amount of its layers.
    """

    gamma_fixed: tuple[int, ...] = ()
    gamma_free: tuple[int, ...] = ()
    scatter_weak: tuple[int, ...] = ()
    log_amount: tuple[float, ...] = ()
    fixed_log_amount: tuple[float, ...] = ()

    def gamma_centre(self, log_gamma: np.ndarray) -> float:
        """The log exponent `gamma_fixed` holds its pigments at (`gamma_fixed`'s centre), from `log_gamma` (P,)."""
        prior = float(np.log(GAMMA_PRIOR))
        free = np.asarray(log_gamma, np.float64)[list(self.gamma_free)]
        return (float(np.sum(free)) + GAMMA_PSEUDO * prior) / (len(free) + GAMMA_PSEUDO)

    def describe(self, names, spectral: bool = True, gamma: bool = True) -> dict:
        """The priors that hold this table's pigments, by name, for the fit record (`spectral`: the scattering
        prior applies to spectral fits only; `gamma`: the amount law is fitted)."""
        weak = [names[i] for i in self.scatter_weak] if spectral else []
        return {"amount_law_at_prior": [names[i] for i in self.gamma_fixed] if gamma else [],
                "gamma_prior": GAMMA_PRIOR, "gamma_prior_sd": GAMMA_PRIOR_SD, "scattering_held_by_population": weak,
                "scatter_shape_spread": SCATTER_PRIOR, "scatter_level_spread": LEVEL_POP,
                "scatter_common_spread": COMMON_SPREAD, "scatter_level_centre": LEVEL,
                "scatter_level_centre_spread": LEVEL_SPREAD}  # fmt: skip


def scatter_prior_variance(n: int) -> float:
    r"""The variance (natural log, squared) of one band's log S of a weakly measured pigment under the priors alone
    (`scatter_weak` and `scatter_level`, `n` >= 1 such pigments, in the priors' own scale), its peers' parameters
    given: what the population says of this pigment before its own rows do. Its shape $x$ about its peers' and its
    level $\ell$ about theirs are independent, with precisions

    $$ h_x = \frac{1 - 1/n}{\tau_{shape}^2} + \frac{1}{n^2 \tau_{common}^2}, \qquad
       h_\ell = \frac{1 - 1/n}{\tau_{level}^2} + \frac{1}{n^2 \tau_{LEVEL}^2}, $$

    and log S = x + \ell: the variance is $1/h_x + 1/h_\ell$ (0.764 for 40 pigments; 0.745, `SCATTER_PRIOR`^2 +
    `LEVEL_POP`^2, for many). What a fit's rows add to a pigment is measured against it (`_mixfit._from_priors`).
    A pigment alone (`n` = 1) has no shape prior (`scatter_weak` holds it only with a peer): the value is then a
    yardstick of the same size, not a prior's variance."""
    h_x = (1 - 1 / n) / SCATTER_PRIOR**2 + 1 / (n * n * COMMON_SPREAD**2)
    h_level = (1 - 1 / n) / LEVEL_POP**2 + 1 / (n * n * LEVEL_SPREAD**2)
    return 1 / h_x + 1 / h_level


def _distinct(values) -> int:
    return len({float(f"{v:.6g}") for v in values})


def table_priors(A: np.ndarray, G: np.ndarray, on: bool = True) -> TablePriors:
    """`TablePriors` of a table: `A` each row's amounts per layer and pigment (N, L, P), `G` its ground (N, B)."""
    P = A.shape[2]
    if not on:
        return TablePriors(gamma_free=tuple(range(P)))
    totals = A.sum(axis=2)  # (N, L)
    stack = np.count_nonzero(totals, axis=1) > 1
    light = G.mean(axis=1) > DARK
    fixed, weak, log_amount, fixed_at = [], [], [], []
    for i in range(P):
        used = A[:, :, i] > 0
        if _distinct(totals[used]) <= 1:
            fixed.append(i)
            fixed_at.append(float(np.log(totals[used][0] / 0.05)) if used.any() else 0.0)
        alone = ~stack & (np.count_nonzero(A.sum(axis=1), axis=1) == 1) & used.any(axis=1)
        amounts = A[alone, :, i].sum(axis=1)
        if _distinct(amounts) <= 1 and np.all(light[alone]) and not np.any(stack & used.any(axis=1)):
            weak.append(i)
        log_amount.append(float(np.mean(np.log(amounts / 0.05))) if len(amounts) else 0.0)
    free = tuple(i for i in range(P) if i not in fixed)
    return TablePriors(tuple(fixed), free, tuple(weak), tuple(log_amount), tuple(fixed_at))


def scatter_weak(log_s, log_gamma, level, priors: TablePriors, scale: float):
    """Per-band residuals (B, n + 1) of the weakly measured pigments' scattering shape (`TablePriors`): their
    measured layers' scattering depths `log S + gamma log(a / a0)` (invariant to trading the amount law against K
    and S, which one amount leaves free) less each one's `level` (a latent, shape (n,)), against the mean of the
    same over those pigments in the band (spread `SCATTER_PRIOR`); and that mean itself (spread `COMMON_SPREAD`),
    which ties the levels to the layers' scattering (without it, moving every level at once changed nothing, and
    `LEVEL` held nothing). None (B, 0) when fewer than two pigments are weakly measured. `log_s` (B, P),
    `log_gamma` (P,)."""
    w = np.asarray(priors.scatter_weak, int)
    if len(w) < 2:
        return jnp.zeros(log_s.shape[:-1] + (0,), log_s.dtype)
    shape = log_s[:, w] + jnp.exp(log_gamma[w]) * jnp.asarray(priors.log_amount, log_s.dtype)[w] - level
    common = jnp.mean(shape, axis=-1, keepdims=True)  # (B, 1): the peers' mean shape in the band
    return scale * jnp.concatenate([(shape - common) / SCATTER_PRIOR, common / COMMON_SPREAD], axis=-1)


def scatter_level(level, priors: TablePriors, scale: float):
    """Residuals of the weakly measured pigments' scattering levels (the latents of `scatter_weak`, shape (n,)):
    each against their mean (spread `LEVEL_POP`), and the mean against `LEVEL` (spread `LEVEL_SPREAD`)."""
    if not len(priors.scatter_weak):
        return jnp.zeros((0,), level.dtype)
    mean = jnp.mean(level, keepdims=True)
    return scale * jnp.concatenate([(level - mean) / LEVEL_POP, (mean - LEVEL) / LEVEL_SPREAD])


def gamma_fixed(log_gamma, priors: TablePriors, scale: float):
    """Residuals of the amount-law prior of the pigments measured at one amount (`TablePriors`): each one's log
    gamma against log `GAMMA_PRIOR`, or, when other pigments fix theirs, against their mean shrunk towards it."""
    f, free = np.asarray(priors.gamma_fixed, int), np.asarray(priors.gamma_free, int)
    if not len(f):
        return jnp.zeros((0,), log_gamma.dtype)
    prior = jnp.log(jnp.asarray(GAMMA_PRIOR, log_gamma.dtype))
    centre = (jnp.sum(log_gamma[free]) + GAMMA_PSEUDO * prior) / (len(free) + GAMMA_PSEUDO) if len(free) else prior
    return scale * (log_gamma[f] - centre) / GAMMA_PRIOR_SD
