r"""Pigment mixtures in one layer, and each pigment's law from an amount of paint to a layer.

Kubelka-Munk sees a layer only through its optical depths $Kx$ and $Sx$ per
band (`diffwash.km.layer(K, S, x)` depends on `K x` and `S x` alone). A layer
brushed from amounts $a_1..a_n$ of $n$ paints, in all $A = \sum_i a_i$, has

$$ Kx = \sum_i c_i\, K_i\, t_i(A), \qquad Sx = \sum_i c_i\, S_i\, t_i(A), \qquad
   c_i = \frac{w_i a_i}{\sum_j w_j a_j}, $$

- $K_i$, $S_i$: pigment $i$'s absorption and scattering per unit thickness, per
  band (the last axis: wavelengths, or the three sRGB channels);
- $t_i(A)$: pigment $i$'s *amount law*, the thickness of a layer of amount $A$
  of that paint alone (`AmountLaw`: $t = (A / a_0)^{\gamma_i}$);
- $c_i$: the concentrations. With all mixing weights $w_i = 1$ they are
  Duncan's volume fractions (Duncan 1940: the mixture's K and S are the
  concentration-weighted sums of its pigments'); a weight $w_i \ne 1$ says how
  much more (or less) pigment $i$ counts in a mixture than its amount alone
  suggests (its *tinting strength* in a mix).

Pairs of pigments that were measured mixed may carry `PairTerms`: smooth
spectral scales of $Kx$ and $Sx$ that vanish unless both are in the layer, fitted
to its measurements (Duncan's sums miss by up to a few CIEDE2000 units on some
measured pairs; docs/mixing.md).

The law is applied to the layer's total amount: a paint mixed with itself is
itself at the summed amount, whatever the weights (the measured self-mixtures
of the NTU data are exactly that). A layer with nothing in it is the bare
ground, with finite gradients.

A *glaze stack* is layers brushed one over another, each dry before the next
(`stack_reflectance`): each layer is a mixture as above, and the stack is
Kubelka's layering of them over the ground, bottom up.

Everything here is a pure function of arrays (pigments on the second-to-last
axis, bands on the last), so a renderer, a LUT baker or a fit can call it
under `jax.jit`, `jax.vmap` and `jax.grad`. Which terms the NTU measurements
support (and which they do not): docs/mixing.md.

**References:**

- D. R. Duncan, "The colour of pigment mixtures", Proc. Phys. Soc. 52 (1940).
- P. Kubelka and F. Munk (1931); C. J. Curtis et al., "Computer-Generated
  Watercolor", SIGGRAPH 1997.
- J. L. Saunderson, "Calculation of the color of pigmented plastics", JOSA 32 (1942).
"""

from __future__ import annotations

import math
from typing import Any

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from . import km

__all__ = [
    "AmountLaw",
    "PairTerms",
    "Palette",
    "concentrations",
    "optical_depths",
    "reflectance",
    "stack_reflectance",
    "saunderson_in",
    "saunderson_out",
    "REFERENCE_AMOUNT",
]

#: Amount at which the default `AmountLaw` gives thickness 1 (mL on the NTU samples' area):
#: K and S are "per layer of this much paint", and the exponent barely moves them.
REFERENCE_AMOUNT = 0.05
#: The thickest layer an amount law gives (thickness 1 is the reference amount's): far past where any layer of
#: K + S >= 1e-12 is its masstone, and small enough that K and S (at most 1e12 in a file) times it stay finite
#: in float32, so that an amount of 1e30 gives the masstone, not NaN or black.
THICKNESS_MAX = 1e18
#: The largest optical depth Kx or Sx a layer gets (K, S <= 1e12 times `THICKNESS_MAX`).
OPTICAL_DEPTH_MAX = 1e30


def _float(x: ArrayLike) -> Array:
    return jnp.asarray(x, jnp.result_type(x, float))


class AmountLaw(eqx.Module):
    r"""Amount of paint to layer thickness: $t(a) = (a / a_0)^{\gamma}$, one exponent per pigment.

    A pytree whose leaf is `gamma` (shape `(P,)` for a palette, `()` for one
    pigment); `reference` ($a_0$, the amount of thickness 1) is static. `gamma =
    1` is thickness proportional to amount; `gamma < 1` a wash that thickens
    less than the paint put on it (absorbent paper, pigment settling into the
    fibres). `t(0) = 0` with a finite (zero) gradient; `t` is capped at
    `THICKNESS_MAX`, past any layer's masstone, so that huge amounts stay finite.

    **Fields:**

    - `gamma`: the exponents, `> 0`.
    - `reference`: the amount of thickness 1 (default `REFERENCE_AMOUNT`).
    """

    gamma: Float[Array, "*p"]
    reference: float = eqx.field(static=True, default=REFERENCE_AMOUNT)

    def __call__(self, amount: Float[ArrayLike, "*#p"]) -> Float[Array, "*p"]:
        """The thickness at `amount` (`>= 0`; broadcast against `gamma`)."""
        a = _float(amount)
        g = jnp.asarray(self.gamma, a.dtype)
        ok = a > 0
        x = jnp.where(ok, a, 1) / self.reference
        return jnp.where(ok, jnp.exp(jnp.minimum(g * jnp.log(x), math.log(THICKNESS_MAX))), 0)

    def to_dict(self) -> dict[str, Any]:
        g = np.asarray(self.gamma, np.float64)
        return {"kind": "power", "reference": self.reference, "gamma": g.tolist() if g.ndim else float(g)}


def concentrations(amounts: Float[ArrayLike, "*n p"], weights: Float[ArrayLike, "*#n p"] | None = None) -> Float[Array, "*n p"]:
    r"""Concentrations $c_i = w_i a_i / \sum_j w_j a_j$ of the pigments of each layer.

    **Arguments:**

    - `amounts`: amount of each pigment, `>= 0`, pigments on the last axis.
    - `weights`: mixing weights `> 0` (broadcast against `amounts`); None for
      Duncan's volume fractions (all 1).

    **Returns:** the concentrations, summing to 1 over the last axis, or all 0
    (with zero gradient) where a layer holds nothing.
    """
    a = _float(amounts)
    # relative to the layer's largest amount: sums of amounts near float32's largest would overflow (brought
    # below 2^64 first: XLA divides through the reciprocal, which float32 loses for a divisor above about 1e38)
    top = jnp.max(a, axis=-1, keepdims=True)
    a, top = jnp.where(top > 2.0**64, a * 2.0**-64, a), jnp.where(top > 2.0**64, top * 2.0**-64, top)
    a = jnp.where(top > 0, a / jnp.where(top > 0, top, 1), 0)
    wa = a if weights is None else a * jnp.asarray(weights, a.dtype)
    total = jnp.sum(wa, axis=-1, keepdims=True)
    ok = total > 0
    return jnp.where(ok, wa / jnp.where(ok, total, 1), 0)


class PairTerms(eqx.Module):
    r"""Corrections to Duncan's law for pairs of pigments that were measured mixed.

    A layer's optical depths are scaled, for every pair $(i, j)$ of `members`,
    by smooth spectra that vanish unless both pigments are in the layer:

    $$ Kx \leftarrow Kx\, \exp \sum_{(i,j)} 4 v_i v_j \bigl(\phi(\lambda)^\top \kappa_{ij}
       + \kappa^A_{ij} \log(A / a_0)\bigr), $$

    and $Sx$ alike with $\sigma_{ij}$, $\sigma^A_{ij}$; $v$ are the volume
    fractions, $A$ the layer's total amount, $a_0$ the amount law's reference
    and $\phi$ Gaussian bumps over the band grid (`basis`). A pigment alone is
    untouched; a 1:1 mixture of a pair gets the pair's whole correction; a
    layer of three or more pigments gets each of its measured pairs' terms in
    proportion to $v_i v_j$, so the model is smooth in the amounts. All terms 0 is
    Duncan. Fitted per pair (`diffwash.fit`), they describe what a measured pair
    did that its pigments alone do not. A pair never measured mixed whose
    pigments were each measured mixed with others may carry terms inferred from
    what those pigments did in their measured pairs (`inferred`; docs/mixing.md
    measures both).

    **Fields:**

    - `members`: the pairs, as pigment indices `(i, j)` with `i < j`, shape `(Q, 2)` (static).
    - `k_bumps`, `s_bumps`: $\kappa$, $\sigma$, shape `(Q, n)`.
    - `k_amount`, `s_amount`: $\kappa^A$, $\sigma^A$, shape `(Q,)`.
    - `centres`, `width`: the bumps' centres and width (nm; static).
    - `wavelengths`: the band grid the bumps are evaluated on (static).
    - `inferred`: the members whose terms were inferred, not fitted to their own mixtures (static).
    """

    members: tuple[tuple[int, int], ...] = eqx.field(static=True)
    k_bumps: Float[Array, "q n"]
    s_bumps: Float[Array, "q n"]
    k_amount: Float[Array, " q"]
    s_amount: Float[Array, " q"]
    centres: tuple[float, ...] = eqx.field(static=True)
    width: float = eqx.field(static=True)
    wavelengths: tuple[float, ...] = eqx.field(static=True)
    inferred: tuple[tuple[int, int], ...] = eqx.field(static=True, default=())

    def basis(self) -> np.ndarray:
        """The bumps on the band grid, shape (B, n)."""
        wl, c = np.asarray(self.wavelengths)[:, None], np.asarray(self.centres)[None, :]
        return np.exp(-0.5 * ((wl - c) / self.width) ** 2)

    def scales(self, amounts: Float[Array, "*n p"], reference: float) -> tuple[Float[Array, "*n b"], Float[Array, "*n b"]]:
        """The factors of $Kx$ and $Sx$ (the class docstring), shape `(..., B)`; 1 for a pigment alone."""
        i, j = np.asarray(self.members, int).reshape(-1, 2).T
        v = concentrations(amounts)
        inter = 4 * v[..., i] * v[..., j]  # (..., Q)
        total = jnp.sum(amounts, axis=-1, keepdims=True)
        ok = total > 0
        cap = math.log(THICKNESS_MAX)  # the amount law's cap: past it a layer is its masstone
        lt = jnp.where(ok, jnp.clip(jnp.log(jnp.where(ok, total, 1) / reference), -cap, cap), 0)
        phi = jnp.asarray(self.basis(), amounts.dtype)
        ck = (inter @ self.k_bumps) @ phi.T + (inter * lt) @ self.k_amount[:, None]
        cs = (inter @ self.s_bumps) @ phi.T + (inter * lt) @ self.s_amount[:, None]
        # Terms within their declared bounds can still add up (many bumps on one band, a thick layer): the factor
        # is capped at e^±27.6 (10^±12, COEFFICIENT_MAX), so that K and S stay finite in float32.
        cap_f = math.log(1e12)
        return jnp.exp(jnp.clip(ck, -cap_f, cap_f)), jnp.exp(jnp.clip(cs, -cap_f, cap_f))

    def subset(self, index: list[int]) -> PairTerms | None:
        """The terms of the pairs among pigments `index` (a palette of those pigments, in that order), or None."""
        where = {old: new for new, old in enumerate(index)}
        keep = [q for q, (i, j) in enumerate(self.members) if i in where and j in where]
        if not keep:
            return None
        pair = lambda q: tuple(sorted((where[self.members[q][0]], where[self.members[q][1]])))  # noqa: E731
        inferred = set(self.inferred)
        return self._take(keep, tuple(pair(q) for q in keep),
                          tuple(pair(q) for q in keep if tuple(self.members[q]) in inferred))

    def canonical(self) -> PairTerms:
        """The same terms with the pairs in sorted order and no `inferred` marks: what a layer's colour depends on,
        and nothing else. `members` and `inferred` are static (part of a compiled program's key): palettes whose
        pairs were fitted and inferred in other orders (a fit's cross-validation folds, each holding out other
        pairs) then share one compiled prediction."""
        order = sorted(range(len(self.members)), key=lambda q: tuple(self.members[q]))
        return self._take(order, tuple(tuple(int(x) for x in self.members[q]) for q in order), ())

    def _take(self, rows: list[int], members: tuple[tuple[int, int], ...],
              inferred: tuple[tuple[int, int], ...]) -> PairTerms:  # fmt: skip
        """The terms of this object's pairs at positions `rows`, in that order, as pairs `members` (one per row)
        marked `inferred` (`subset` and `canonical`)."""
        k = np.asarray(rows, int)
        return PairTerms(members=members, k_bumps=jnp.asarray(self.k_bumps)[k], s_bumps=jnp.asarray(self.s_bumps)[k],
                         k_amount=jnp.asarray(self.k_amount)[k], s_amount=jnp.asarray(self.s_amount)[k],
                         centres=self.centres, width=self.width, wavelengths=self.wavelengths, inferred=inferred)

    def to_dict(self, names: tuple[str, ...]) -> dict[str, Any]:
        f = lambda x: np.asarray(x, np.float64).tolist()  # noqa: E731
        inferred = set(self.inferred)
        pairs = [{"pigments": [names[i], names[j]], "K_bumps": f(self.k_bumps[q]), "S_bumps": f(self.s_bumps[q]),
                  "K_amount": f(self.k_amount[q]), "S_amount": f(self.s_amount[q]),
                  **({"inferred": True} if (i, j) in inferred else {})}
                 for q, (i, j) in enumerate(self.members)]  # fmt: skip
        return {"basis": {"centres": list(self.centres), "width": self.width}, "pairs": pairs}


def optical_depths(
    K: Float[ArrayLike, "*#n p b"],
    S: Float[ArrayLike, "*#n p b"],
    amounts: Float[ArrayLike, "*#n p"],
    law: AmountLaw,
    weights: Float[ArrayLike, "*#n p"] | None = None,
    pairs: PairTerms | None = None,
) -> tuple[Float[Array, "*n b"], Float[Array, "*n b"]]:
    r"""$Kx$ and $Sx$ of a layer of mixed pigments (the module docstring's law).

    **Arguments:**

    - `K`, `S`: each pigment's coefficients per unit thickness, shape `(..., P, B)`.
    - `amounts`: each pigment's amount in the layer, shape `(..., P)` (0 for absent ones).
    - `law`: the pigments' `AmountLaw` (its `gamma` of shape `(P,)`).
    - `weights`: mixing weights, shape `(P,)`; None for Duncan's.
    - `pairs`: `PairTerms` for the pairs measured mixed, or None.

    **Returns:** `(Kx, Sx)`, shape `(..., B)`: `km.layer(Kx, Sx, 1)` is the layer.
    """
    a = _float(amounts)
    total = jnp.sum(a, axis=-1, keepdims=True)
    u = concentrations(a, weights) * law(total)  # (..., P): each pigment's share of the layer
    K, S = jnp.asarray(K, a.dtype), jnp.asarray(S, a.dtype)
    Kx, Sx = jnp.einsum("...p,...pb->...b", u, K), jnp.einsum("...p,...pb->...b", u, S)
    if pairs is not None:
        fk, fs = pairs.scales(a, law.reference)
        # capped where a pair term's growth with the amount is extrapolated far past the data: finite in float32
        Kx, Sx = jnp.minimum(Kx * fk, OPTICAL_DEPTH_MAX), jnp.minimum(Sx * fs, OPTICAL_DEPTH_MAX)
    return Kx, Sx


def saunderson_in(R: Float[ArrayLike, "*b"], k2: float) -> Float[Array, "*b"]:
    r"""Measured reflectance to the reflectance inside the film (Saunderson, $k_1 = 0$): $R/(1 - k_2 + k_2 R)$."""
    R = _float(R)
    return R / (1 - k2 + k2 * R)


def saunderson_out(R: Float[ArrayLike, "*b"], k2: float) -> Float[Array, "*b"]:
    r"""Reflectance inside the film to measured reflectance (Saunderson, $k_1 = 0$): $(1 - k_2) R / (1 - k_2 R)$."""
    R = _float(R)
    return (1 - k2) * R / (1 - k2 * R)


def reflectance(
    K: Float[ArrayLike, "*#n p b"],
    S: Float[ArrayLike, "*#n p b"],
    amounts: Float[ArrayLike, "*#n p"],
    ground: Float[ArrayLike, "*#n b"],
    law: AmountLaw,
    weights: Float[ArrayLike, "*#n p"] | None = None,
    k2: float | Array = 0.0,
    pairs: PairTerms | None = None,
) -> Float[Array, "*n b"]:
    r"""Reflectance of a mixed layer over an opaque ground, per band.

    $(R, T) = \mathrm{layer}(Kx, Sx, 1)$ from `optical_depths`, then
    `km.over(R, T, ground)`; with `k2 > 0`, Saunderson's surface correction
    around it (the ground taken inside the film, the result back out).

    **Returns:** the measured reflectance, shape `(..., B)`.
    """
    Kx, Sx = optical_depths(K, S, amounts, law, weights, pairs)
    g = saunderson_in(_float(ground), k2)  # k2 = 0: the identity (k2 may be traced)
    R, T = km.layer(Kx, Sx, 1.0)
    return saunderson_out(km.over(R, T, g), k2)


def stack_reflectance(
    K: Float[ArrayLike, "*#n p b"],
    S: Float[ArrayLike, "*#n p b"],
    amounts: Float[ArrayLike, "*#n l p"],
    ground: Float[ArrayLike, "*#n b"],
    law: AmountLaw,
    weights: Float[ArrayLike, "*#n p"] | None = None,
    k2: float | Array = 0.0,
    pairs: PairTerms | None = None,
) -> Float[Array, "*n b"]:
    r"""Reflectance of a glaze stack: layers of mixed pigments, bottom first, over an opaque ground.

    Each layer $l$ is a mixed layer of its own amounts (`optical_depths`: the
    amount law at the layer's total, Duncan's sums, pair terms within the
    layer), $(R_l, T_l) = \mathrm{layer}(Kx_l, Sx_l, 1)$. Kubelka's layering
    puts them on the ground from the bottom up,

    $$ \rho_0 = g, \qquad \rho_l = R_l + \frac{T_l^2\, \rho_{l-1}}{1 - R_l\, \rho_{l-1}}
       \quad (\texttt{km.over}), $$

    exact for homogeneous layers (each reflects alike from both sides) over an
    opaque body. Saunderson's surface correction (`k2 > 0`) belongs to the
    stack's one interface with air, its top: the ground is taken inside the
    film once (`saunderson_in`) and the top of the stack back out once
    (`saunderson_out`). Between layers of one binder (gum arabic on gum arabic)
    there is no step of refractive index, so no internal surface term.

    A layer with nothing in it is transparent ($R = 0$, $T = 1$: `over` returns
    what lies beneath exactly, with finite gradients), so rows of fewer layers
    are padded with all-zero layers anywhere in the stack. With one layer this
    is `reflectance` (evaluated by it, so the numbers are the same).

    **Arguments:** as `reflectance`, with `amounts` of shape `(..., L, P)`: each
    layer's amount of each pigment, bottom layer first.

    **Returns:** the measured reflectance, shape `(..., B)`.
    """
    a = _float(amounts)
    if a.shape[-2] == 1:
        return reflectance(K, S, a[..., 0, :], ground, law, weights, k2, pairs)
    Kx, Sx = optical_depths(K, S, a, law, weights, pairs)  # (..., L, B)
    R, T = km.layer(Kx, Sx, 1.0)
    rho = saunderson_in(_float(ground), k2)
    for i in range(a.shape[-2]):
        rho = km.over(R[..., i, :], T[..., i, :], rho)
    return saunderson_out(rho, k2)


class Palette(eqx.Module):
    """Pigments that can be mixed: coefficients per band, amount laws and mixing weights.

    A pytree whose leaves are the arrays (the names and the grid are static), so
    it passes through `jax.jit` and a fit can differentiate it.

    **Fields:**

    - `K`, `S`: per unit thickness, shape (P, B), on the bands of `wavelengths`
      (nm) or, with `wavelengths` None, the three linear sRGB channels.
    - `law`: the `AmountLaw` (one exponent per pigment).
    - `weights`: mixing weights, shape (P,) (all 1: Duncan).
    - `names`: the pigments' names.
    - `wavelengths`: the band grid, or None for sRGB channels.
    - `pairs`: `PairTerms` for pairs measured mixed (None: Duncan for every mixture).
    """

    K: Float[Array, "p b"]
    S: Float[Array, "p b"]
    law: AmountLaw
    weights: Float[Array, "p"]
    names: tuple[str, ...] = eqx.field(static=True)
    wavelengths: tuple[float, ...] | None = eqx.field(static=True, default=None)
    pairs: PairTerms | None = None

    def reflectance(self, amounts: Float[ArrayLike, "*n p"], ground: Float[ArrayLike, "*#n b"], k2: float = 0.0) -> Float[Array, "*n b"]:
        """Reflectance of layers with `amounts` of each pigment (shape `(..., P)`) over `ground`."""
        return reflectance(self.K, self.S, amounts, ground, self.law, self.weights, k2, self.pairs)

    def stack_reflectance(self, amounts: Float[ArrayLike, "*n l p"], ground: Float[ArrayLike, "*#n b"], k2: float = 0.0) -> Float[Array, "*n b"]:
        """Reflectance of glaze stacks with `amounts` of each pigment per layer (shape `(..., L, P)`, bottom
        layer first) over `ground` (`stack_reflectance`)."""
        return stack_reflectance(self.K, self.S, amounts, ground, self.law, self.weights, k2, self.pairs)

    def optical_depths(self, amounts: Float[ArrayLike, "*n p"]) -> tuple[Float[Array, "*n b"], Float[Array, "*n b"]]:
        """$Kx$, $Sx$ of layers with `amounts` of each pigment (its pair terms included)."""
        return optical_depths(self.K, self.S, amounts, self.law, self.weights, self.pairs)
