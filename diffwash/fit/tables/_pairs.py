r"""Fit `diffwash.mixing.PairTerms` to the mixtures of the pairs a table measured, pair by pair, in CIEDE2000
(a spectral table's, or an RGB table's, whose pigments are smooth spectra over `RGB_GRID`).

With the pigments fitted (their K, S and amount laws serve every pair, measured
mixed or not), what a measured pair does beyond Duncan's sums is fitted from
its own mixture rows alone: smooth spectral scales of $Kx$ and $Sx$
(`PAIR_BUMPS` Gaussian bumps each) and how those scales change with the
layer's total amount (`diffwash.mixing.PairTerms`), $2n + 2$ numbers per pair.
(A mixing weight per pair as well was measured to add nothing: docs/mixing.md.)
The residuals are CIEDE2000's (`colorimetry.delta_e_2000_residuals`), with a
ridge of weight `ridge` towards Duncan (all 0). The pairs are independent:
one small Levenberg-Marquardt problem each (dense $(2n+2)^2$ normal
equations, Marquardt's scaling), all of them at once under `jax.vmap`.

docs/mixing.md measures the terms on rows of measured pairs held out of the
fit, and chose the ridge and the number of bumps on a different split.

A pair never measured mixed, whose two pigments were each measured mixed with
others, takes terms inferred from the measured pairs (`infer_pair_terms`): part
of what a pair does beyond Duncan is its pigments' own (a paint that flocculates
or dilutes another's scattering does so in most of its mixtures), and part is
shared by pairs of like paints (a blue with a yellow does what another blue with
another yellow did).
"""

from __future__ import annotations

from collections.abc import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ... import colorimetry, mixing
from ..._schema import PAIR_AMOUNT_MAX, PAIR_BUMP_MAX
from .._bandlsq import GN_TOL, Convergence, loss_floor, newton_decrement

__all__ = ["fit_pair_terms", "held_out_de2000", "infer_pair_terms", "EFFECT_RIDGE", "LIKE_SCALE", "LIKE_WEIGHT",
           "PAIR_BUMPS", "PAIR_RIDGE", "PAIR_STEPS"]

#: Gaussian bumps per spectral scale (over the palette's band grid).
PAIR_BUMPS = 4
#: The ridge towards Duncan (CIEDE2000 units per unit parameter).
PAIR_RIDGE = 1.0
#: Levenberg-Marquardt steps per pair (a pair has 2 * PAIR_BUMPS + 2 parameters: it converges in far fewer).
PAIR_STEPS = 40
#: The ridge of the per-pigment effects that unmeasured pairs' terms are inferred from (`infer_pair_terms`), in
#: measured pairs: a pigment measured in that many pairs has its effect shrunk by half towards 0 (Duncan).
EFFECT_RIDGE = 10.0
#: The weight of the likeness of pairs (`infer_pair_terms`: pairs of like paints have like terms), against 1 for the
#: pigments' own effects.
LIKE_WEIGHT = 10.0
#: How far apart two paints may be and still be alike (`infer_pair_terms`), as a share of the median distance between
#: the table's paints (their standardised log K/S spectra).
LIKE_SCALE = 0.7


def measured_pairs(A: np.ndarray) -> list[tuple[int, int]]:
    """The pairs `(i, j)`, `i < j`, of the rows of an amount matrix (N, P) that hold exactly two pigments."""
    on = A > 0
    two = on.sum(axis=1) == 2
    return sorted({tuple(int(k) for k in np.flatnonzero(row)) for row in on[two]})


def _basis(wavelengths: tuple[float, ...], n: int) -> tuple[tuple[float, ...], float]:
    c = np.linspace(wavelengths[0], wavelengths[-1], n)
    return tuple(float(x) for x in c), float((c[1] - c[0]) * 0.8 if n > 1 else wavelengths[-1] - wavelengths[0])


def _terms(theta: Array, members, n: int, centres, width, wavelengths, inferred=()) -> mixing.PairTerms:
    """`PairTerms` of one pair (members `((0, 1),)`) or of `Q` pairs from parameters `(..., 2n + 2)`."""
    t = jnp.atleast_2d(theta)
    return mixing.PairTerms(members=members, k_bumps=t[:, :n], s_bumps=t[:, n : 2 * n], k_amount=t[:, 2 * n],
                            s_amount=t[:, 2 * n + 1], centres=centres, width=width, wavelengths=wavelengths,
                            inferred=inferred)  # fmt: skip


def _rows(pairs, A):
    """Per pair, its rows' indices padded to the largest pair's count (Q, R), and which are real (Q, R)."""
    rows = [np.flatnonzero((A[:, i] > 0) & (A[:, j] > 0) & ((A > 0).sum(axis=1) == 2)) for i, j in pairs]
    R = max(len(r) for r in rows)
    idx = np.stack([np.pad(r, (0, R - len(r)), mode="edge") for r in rows])
    return idx, np.stack([np.arange(R) < len(r) for r in rows])


def _pack(palette: mixing.Palette, pairs, A, G, lab, dtype, use: np.ndarray | None = None):
    """Per pair, as arrays of `dtype`: its two pigments' K, S, amount-law exponents and weights, and its rows' two
    amounts, grounds, target colours and which are real (padded to the largest pair's count), only rows where
    `use` (N,) is true counted real: `_fit_pairs`'s arguments after the static ones."""
    A, G, lab = np.asarray(A), np.asarray(G), np.asarray(lab)
    idx, mask = _rows(pairs, A)
    if use is not None:
        mask = mask & np.asarray(use, bool)[idx]
    ij = np.asarray(pairs)
    A2 = np.stack([A[idx, ij[:, :1]], A[idx, ij[:, 1:]]], axis=-1)
    per_pigment = (palette.K, palette.S, palette.law.gamma, palette.weights)
    return (*(jnp.asarray(x, dtype)[ij] for x in per_pigment), *(jnp.asarray(x, dtype) for x in (A2, G[idx], lab[idx])),
            jnp.asarray(mask))  # fmt: skip


def _lm(jacobians: Callable[[np.ndarray], tuple[Array, Array]], theta0: np.ndarray, steps: int):
    """`steps` Levenberg-Marquardt steps on `Q` independent problems at once: `jacobians(theta)` of parameters
    (Q, n) gives each problem's residuals (Q, M) and their Jacobian (Q, M, n). Returns theta (Q, n), whether each
    converged: the last accepted step lowered its loss by less than 1e-4 relative, or no step lowers it any more
    (the damping grew past 1e8: a minimum as far as the arithmetic can tell), or a Gauss-Newton step would gain
    less than `GN_TOL` of its loss (out of steps at a minimum is not "not converged"), and that decrement (Q,).

    The loop runs in NumPy (float64) around one compiled program, `jacobians`, which the leave-one-row-out
    residuals (`held_out_de2000`) reuse: compiling the residuals' Jacobian once, not within a compiled loop, a
    second time after it and a third time for the leave-one-out, took the NTU fit's pair stage from 9 s to 3 s.
    """
    def at(th):
        r, J = jacobians(th)
        r, J = np.asarray(r, np.float64), np.asarray(J, np.float64)
        return r, J, np.sum(r * r, axis=-1)

    th = np.atleast_2d(np.asarray(theta0, np.float64))
    r, J, f = at(th)
    mu, gain = np.full(f.shape, 1e-3), np.ones(f.shape)
    eye = np.eye(th.shape[-1])
    for _ in range(steps):
        H, g = np.einsum("qmi,qmj->qij", J, J), np.einsum("qmi,qm->qi", J, r)
        d = np.diagonal(H, axis1=1, axis2=2)
        damp = mu[:, None] * (d + 1e-9 * d.mean(axis=1, keepdims=True) + 1e-12)
        delta = np.linalg.solve(H + damp[:, :, None] * eye, -g[..., None])[..., 0]
        rc, Jc, fc = at(th + delta)
        ok = fc < f
        gain = np.where(ok, (f - fc) / np.maximum(f, 1e-30), gain)
        th, r, J, f = (np.where(ok.reshape((-1,) + (1,) * (x.ndim - 1)), y, x)
                       for x, y in ((th, th + delta), (r, rc), (J, Jc), (f, fc)))  # fmt: skip
        mu = np.where(ok, mu / 3, mu * 4)
    H, g = np.einsum("qmi,qmj->qij", J, J), np.einsum("qmi,qm->qi", J, r)
    d = np.diagonal(H, axis1=1, axis2=2)
    step = np.linalg.solve(H + (1e-6 * d + np.finfo(np.float64).tiny)[:, :, None] * eye, g[..., None])[..., 0]
    dec = np.sum(g * step, axis=-1) / np.maximum(np.maximum(f, loss_floor(r.shape[-1])), np.finfo(np.float64).tiny)
    return th, (gain < 1e-4) | (mu > 1e8) | (dec <= GN_TOL), dec


def _pair_residuals(lab_of, reference: float, k2, wavelengths, bumps: int, K, S, gam, w, A2, G2, lab2, mask):
    """One pair's rows' CIEDE2000 residuals (R, 3) as a function of its terms' parameters (0 on padding rows)."""
    centres, width = _basis(wavelengths, bumps)
    law = mixing.AmountLaw(gamma=gam, reference=reference)

    def rows(theta):
        terms = _terms(theta, ((0, 1),), bumps, centres, width, wavelengths)
        R = mixing.reflectance(K, S, A2, G2, law, w, k2, terms)
        return jnp.where(mask[:, None], colorimetry.delta_e_2000_residuals(lab2, lab_of(R)), 0)

    return rows


@eqx.filter_jit
def _jacobians(lab_of, reference: float, k2, wavelengths, bumps: int, ridge: float, K, S, gam, w, A2, G2, lab2, mask,
               theta):  # fmt: skip
    """Every pair's residuals at its terms' parameters `theta` (Q, n): its rows' CIEDE2000 residuals, flattened
    (3R), then the ridge's (n), and their Jacobian (Q, 3R + n, n) (`jax.vmap` over the leading axes). Module-level,
    with the data as arguments: a later fit of the same shapes finds it compiled."""

    def one(K, S, gam, w, A2, G2, lab2, mask, theta):
        rows = _pair_residuals(lab_of, reference, k2, wavelengths, bumps, K, S, gam, w, A2, G2, lab2, mask)
        res = lambda th: jnp.concatenate([rows(th).ravel(), ridge * th])  # noqa: E731
        return res(theta), jax.jacfwd(res)(theta)

    return jax.vmap(one)(K, S, gam, w, A2, G2, lab2, mask, theta)


def _fit_pairs(lab_of, reference: float, k2, wavelengths, bumps: int, ridge: float, steps: int, *packed):
    """Every pair's terms at once (`_lm` on `_jacobians`, from Duncan: all 0); `packed`: `_pack`'s arrays."""
    dtype = packed[0].dtype
    jac = lambda th: _jacobians(lab_of, reference, k2, wavelengths, bumps, ridge, *packed, jnp.asarray(th, dtype))  # noqa: E731
    theta, done, dec = _lm(jac, np.zeros((packed[0].shape[0], 2 * bumps + 2)), steps)
    return jnp.asarray(theta, dtype), done, dec


def fit_pair_terms(
    palette: mixing.Palette,
    A: Float[np.ndarray, "n p"],
    G: Float[np.ndarray, "n b"],
    lab_target: Float[np.ndarray, "n 3"],
    lab_of: Callable[[Array], Array],
    k2: float = 0.0,
    *,
    ridge: float = PAIR_RIDGE,
    bumps: int = PAIR_BUMPS,
    steps: int = PAIR_STEPS,
    use: np.ndarray | None = None,
) -> tuple[mixing.PairTerms | None, Convergence]:
    """Fit a spectral palette's `PairTerms` to the two-pigment rows among `A` (module docstring).

    **Arguments:**

    - `palette`: the fitted pigments (spectral: `wavelengths` set); its own pair terms are ignored.
    - `A`, `G`, `lab_target`: each row's amounts (N, P), ground reflectance (N, B) and measured CIELAB (N, 3).
    - `lab_of`: reflectance (..., B) to CIELAB (the library's observation).
    - `k2`: Saunderson's surface term of the palette's fit.
    - `ridge`, `bumps`, `steps`: the module's constants.
    - `use`: the rows the fit may use (N,) (a cross-validation fold's training rows; default all). The fit has the
      shapes of all rows' (its compiled program is the whole table's); a pair none of whose rows it may use has
      no terms.

    **Returns:** `(terms, convergence)`: the `PairTerms` (None when no row mixes exactly two pigments) and a
    `Convergence`, true when every pair's fit converged (`_lm`), naming the pair farthest from its minimum.
    """
    if palette.wavelengths is None:
        raise ValueError("pair terms need a spectral palette (a band grid)")
    pairs = measured_pairs(np.asarray(A))
    none = None, Convergence(converged=True, steps=0, stage="pair terms (none measured)")
    if not pairs:
        return none
    dtype = jnp.zeros(()).dtype
    packed = _pack(palette, pairs, A, G, lab_target, dtype, use)
    keep = np.flatnonzero(np.asarray(packed[-1]).any(axis=1))  # pairs with rows to fit; the rest pad the shapes
    if not len(keep):
        return none
    centres, width = _basis(palette.wavelengths, bumps)
    theta, done, dec = _fit_pairs(lab_of, palette.law.reference, jnp.asarray(k2, dtype), palette.wavelengths, bumps, ridge,
                                  steps, *packed)  # fmt: skip
    theta, done, dec = theta[keep], np.asarray(done)[keep], np.asarray(dec)[keep]
    pairs = [pairs[q] for q in keep]
    ij = np.asarray(pairs)
    # A library file holds pair terms within their declared bounds (`_schema.PairTerm`): clipped there, a fit's
    # library always loads again (fitted terms lie far inside: below 1.5 and 0.3 on the NTU table).
    bound = jnp.asarray([PAIR_BUMP_MAX] * (2 * bumps) + [PAIR_AMOUNT_MAX] * 2, theta.dtype)
    terms = _terms(jnp.clip(theta, -bound, bound), tuple(pairs), bumps, centres, width, palette.wavelengths)
    dec = np.asarray(dec, np.float64)
    if np.all(done):
        return terms, Convergence(converged=True, steps=steps, stage=f"pair terms ({len(pairs)} pairs)")
    worst = int(np.argmax(np.where(np.asarray(done), -np.inf, dec)))
    stage = f"pair terms ({len(pairs)} pairs; the farthest from a minimum: {palette.names[ij[worst, 0]]}+{palette.names[ij[worst, 1]]})"
    return terms, Convergence(converged=False, steps=steps, decrement=float(dec[worst]), stage=stage)


def held_out_de2000(
    palette: mixing.Palette,
    A: Float[np.ndarray, "n p"],
    G: Float[np.ndarray, "n b"],
    lab_target: Float[np.ndarray, "n 3"],
    lab_of: Callable[[Array], Array],
    k2: float = 0.0,
    *,
    ridge: float = PAIR_RIDGE,
) -> np.ndarray:
    r"""Each two-pigment row's CIEDE2000 as predicted by its pair's terms fitted without it (N,): NaN for the others.

    A pair's terms have $2n + 2$ parameters, so a pair measured in a row or two reproduces those rows whatever
    its other amounts do: its rows' own residuals say little of how well the terms predict the pair elsewhere.
    Leaving each row out (the pigments kept, as they serve every pair) says that. It is the closed form of least
    squares, at the fit's Gauss-Newton matrix $H = J^\top J + \lambda^2 I$ (the ridge $\lambda$ included): row
    $i$'s residuals $r_i$ with it left out are $(I - J_i H^{-1} J_i^\top)^{-1} r_i$. A pair of one row is then
    predicted from the ridge alone, which is Duncan's law, as it should be.
    """
    terms = palette.pairs
    out = np.full(len(A), np.nan)
    if terms is None or not terms.members:
        return out
    pairs = [tuple(int(x) for x in p) for p in terms.members]
    dtype = jnp.asarray(terms.k_bumps).dtype
    idx, mask = _rows(pairs, np.asarray(A))
    theta = jnp.concatenate([terms.k_bumps, terms.s_bumps, terms.k_amount[:, None], terms.s_amount[:, None]], 1)
    n = theta.shape[1]
    r, J = _jacobians(lab_of, palette.law.reference, jnp.asarray(k2, dtype), palette.wavelengths, terms.k_bumps.shape[1],
                      ridge, *_pack(palette, pairs, A, G, lab_target, dtype), theta.astype(dtype))  # fmt: skip
    r, J = np.asarray(r, np.float64), np.asarray(J, np.float64)  # (Q, 3R + n), (Q, 3R + n, n): the ridge's rows last
    H = np.einsum("qmi,qmj->qij", J, J)  # the rows' J^T J plus ridge^2 I
    Q, R = idx.shape
    Jr, rr = J[:, : 3 * R].reshape(Q, R, 3, n), r[:, : 3 * R].reshape(Q, R, 3)
    HiJ = np.linalg.solve(H[:, None], np.swapaxes(Jr, -1, -2))  # (Q, R, n, 3): H^-1 J_i^T
    hat = Jr @ HiJ  # (Q, R, 3, 3): J_i H^-1 J_i^T
    de = np.linalg.norm(np.linalg.solve(np.eye(3) - hat, rr[..., None])[..., 0], axis=-1)
    out[idx[mask]] = de[mask]
    return out


def _likeness(pigments, mixed: list[int], scale: float) -> np.ndarray:
    """How alike the `mixed` pigments are (M, M), 1 on the diagonal: a Gaussian of the distance between their log K/S
    spectra, each band standardised over those pigments, at `scale` times the median distance between them."""
    K, S = (np.asarray(x, np.float64)[mixed] for x in pigments)
    tiny = np.finfo(np.float64).tiny
    f = np.log(np.maximum(K, tiny)) - np.log(np.maximum(S, tiny))
    f = (f - f.mean(axis=0)) / (f.std(axis=0) + 1e-9)
    d = np.sqrt(np.sum((f[:, None] - f[None]) ** 2, axis=-1))
    off = d[np.triu_indices(len(mixed), 1)]
    median = float(np.median(off)) if off.size else 0.0
    return np.exp(-0.5 * (d / (scale * median)) ** 2) if median > 0 else np.ones_like(d)


def infer_pair_terms(
    terms: mixing.PairTerms | None,
    ridge: float = EFFECT_RIDGE,
    *,
    pigments: tuple[np.ndarray, np.ndarray] | None = None,
    like: float = LIKE_WEIGHT,
    scale: float = LIKE_SCALE,
) -> mixing.PairTerms | None:
    r"""`terms` (fitted to measured pairs) and, for every pair never measured mixed whose two
    pigments were each measured mixed with others, terms inferred from the measured pairs (`inferred`).

    A measured pair's $2n + 2$ numbers are read as one effect per pigment, plus a part that like pairs share, plus
    the pair's own: a Gaussian process over pairs whose covariance is

    $$ k\big((i, j), (k, l)\big) = \delta_{ik} + \delta_{il} + \delta_{jk} + \delta_{jl}
       + w\,(\kappa_{ik}\kappa_{jl} + \kappa_{il}\kappa_{jk}) , $$

    with the pairs' own parts as its noise (variance $\lambda$ = `ridge`), and the mean $0$: Duncan's law. The first
    sum alone is the ridge regression of the measured terms on their pigments, $e_i + e_j$ with the effects
    $E = (X^\top X + \lambda I)^{-1} X^\top \Theta$ ($X$ the incidence of pairs and pigments): shrunk towards 0
    where few measured pairs say little of a pigment. The second says that a pair of paints like another pair's
    paints does what that pair did: $\kappa$ (`_likeness`, from `pigments` = (K, S), each (P, B)) is how alike two
    paints' absorption spectra are, $w$ = `like`, `scale` its width. Without `pigments` only the effects count.
    A pair never measured takes the process's mean there, $k_*^\top (K + \lambda I)^{-1} \Theta$, within the
    terms' declared bounds. A pigment never measured mixed has nothing to infer from, and its pairs no terms
    (their rows are `unmixed`, `diffwash._regions.kinds`). docs/mixing.md measures the inferred terms on pairs
    held out of the fit, and how the constants were chosen.
    """
    if terms is None or not terms.members:
        return terms
    before = set(terms.inferred)  # inferred earlier: inferred again, from the measured pairs alone
    rows = [q for q, p in enumerate(terms.members) if tuple(p) not in before]
    measured = [tuple(int(x) for x in terms.members[q]) for q in rows]
    mixed, seen = sorted({i for p in measured for i in p}), set(measured)
    new = [(i, j) for a, i in enumerate(mixed) for j in mixed[a + 1 :] if (i, j) not in seen]
    if not new:
        return terms
    q = np.asarray(rows)
    theta = np.concatenate([np.asarray(terms.k_bumps, np.float64)[q], np.asarray(terms.s_bumps, np.float64)[q],
                            np.asarray(terms.k_amount, np.float64)[q, None],
                            np.asarray(terms.s_amount, np.float64)[q, None]], axis=1)  # fmt: skip
    at = {p: k for k, p in enumerate(mixed)}  # pigment -> its row among the mixed
    M, N = np.asarray([[at[i] for i in p] for p in measured]), np.asarray([[at[i] for i in p] for p in new])
    eye = np.eye(len(mixed))
    kappa = _likeness(pigments, mixed, scale) if pigments is not None else np.zeros_like(eye)

    def cov(a, b):  # the covariance (len(a), len(b)) of the terms of pairs a and b (rows of pigment indices)
        (i, j), (k, l) = (a[:, None, 0], a[:, None, 1]), (b[None, :, 0], b[None, :, 1])
        shared = eye[i, k] + eye[i, l] + eye[j, k] + eye[j, l]
        return shared + like * (kappa[i, k] * kappa[j, l] + kappa[i, l] * kappa[j, k])

    mean = cov(N, M) @ np.linalg.solve(cov(M, M) + ridge * np.eye(len(measured)), theta)
    n = theta.shape[1] // 2 - 1
    bound = np.asarray([PAIR_BUMP_MAX] * (2 * n) + [PAIR_AMOUNT_MAX] * 2)
    inferred = np.clip(mean, -bound, bound)
    full = np.concatenate([theta, inferred]).astype(np.asarray(terms.k_bumps).dtype)
    return _terms(jnp.asarray(full), tuple(measured) + tuple(new), n, terms.centres, terms.width, terms.wavelengths,
                  inferred=tuple(new))
