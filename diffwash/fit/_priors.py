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
square roots, added to the fits' least-squares problems (`diffwash.fit._mixfit`):
per band (they couple the pigments of one band only, so the band-separable solver
keeps its structure) and on the shared parameters.

**Off by default** (spreads 0): they have not yet been shown to help on held-out data. On the mixing
notebook's example (NTU P1, P4, P7, P12 with P1+P12 and P12+P7 held out, 32 rows) the held-out mean CIEDE2000
was 15.56 without them, 15.39 with spreads (1.0, 0.3), 15.43 with (0.5, 0.2), 14.88 with (0.1, 0.3) and 12.44
with (0.03, 0.1) (`MixModel(scatter_spread=..., gamma_spread=...)`; the training rows' mean went from 1.19 to
1.32): P12's log S rose from -9.1 to -2.4 and its exponent from 0.14 to 0.26, but its mixtures stay far off,
because what the held-out rows need (how P12 mixes) is not what the priors constrain. On a noise-free
generated table they bias the recovered pigments (mean CIEDE2000 0.05 -> 0.10). The whole-table
cross-validation of a setting (`benchmarks/bench_mix.py --only noprior,...`) is not yet measured.
"""

from __future__ import annotations

import jax.numpy as jnp

__all__ = ["GAMMA_SPREAD", "SCATTER_SPREAD", "scatter_population", "gamma_population"]

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
