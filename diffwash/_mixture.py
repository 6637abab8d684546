r"""A glaze's paint from a pigment library: one library pigment, or several mixed in one layer.

A scene's `wash` or `unlit` glaze may name pigments of a library written by
`diffwash fit-swatch --table` (`diffwash.library`): `{"library": "paints.json",
"mix": {"P1": 0.6, "P3": 0.4}}`. The glaze then holds a `Mixture`: the library
pigments it uses (K and S per band, amount law, mixing weight), their
proportions $p_i$ in the paint, and the amount of paint $A$ a glaze of
thickness 1 holds. Its coefficients per unit of the shading model's thickness
are Duncan's sums of `diffwash.mixing.optical_depths` (with the library's
pair terms for a pair it measured mixed, `diffwash.mixing.PairTerms`),

$$ K = \sum_i c_i\, K_i\, t_i(A), \qquad S = \sum_i c_i\, S_i\, t_i(A), \qquad
   c_i = \frac{w_i p_i}{\sum_j w_j p_j}, $$

with $t_i$ pigment $i$'s amount law and $w_i$ its mixing weight: a glaze of
thickness 1 is the library's prediction for a layer of $A$ of that paint, and
a glaze of thickness $x$ has optical depths $K x$ and $S x$. By default $A$ is
the laws' reference amount (`diffwash.mixing.REFERENCE_AMOUNT`), where every
law gives thickness 1, so K and S are the plain concentration-weighted sums.

`Mixture.K` and `Mixture.S` are computed from the leaves (proportions, amount,
the pigments' coefficients and laws) in JAX, so `diffwash.render`
differentiates through them. The proportions are shares: the model normalises
them (scaling them all changes nothing); scene files give them summing to 1.
"""

from __future__ import annotations

import os
from typing import Any

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from . import mixing
from ._errors import DiffwashError
from .library import Library

__all__ = ["Mixture", "mixture", "check_fittable"]


class Mixture(eqx.Module):
    """Pigments of a library mixed in one glaze, per band (module docstring).

    A pytree whose leaves are differentiable: the pigments' coefficients and
    laws (`palette`), the `proportions` and the `amount`.

    **Fields:**

    - `palette`: the `diffwash.mixing.Palette` of the pigments the glaze uses,
      K and S of shape (P, B) on the library's bands.
    - `proportions`: each pigment's share of the paint, shape (P,), `>= 0`
      (normalised by the model).
    - `amount`: the amount of paint in a glaze of thickness 1, in the
      library's unit (mL on the measured samples' area), `> 0`.
    - `library`: the library file it came from (static; for writing the scene back).
    """

    palette: mixing.Palette
    proportions: Float[ArrayLike, " p"]
    amount: Float[ArrayLike, ""] = mixing.REFERENCE_AMOUNT
    library: str | None = eqx.field(static=True, default=None)

    @property
    def name(self) -> str:
        """The pigments' names joined by `+` (`"P1+P3"`)."""
        return "+".join(self.palette.names)

    def optical_depths(self) -> tuple[Float[Array, " b"], Float[Array, " b"]]:
        """`(K, S)` per unit of the shading model's thickness, per band."""
        p = jnp.asarray(self.proportions, jnp.result_type(self.proportions, float))
        total = jnp.sum(p)
        ok = total > 0
        amounts = jnp.where(ok, p / jnp.where(ok, total, 1), 0) * self.amount
        return self.palette.optical_depths(amounts)

    @property
    def K(self) -> Float[Array, " b"]:
        """Absorption per unit thickness, per band."""
        return self.optical_depths()[0]

    @property
    def S(self) -> Float[Array, " b"]:
        """Scattering per unit thickness, per band."""
        return self.optical_depths()[1]

    def describe(self, relative_to: str | os.PathLike | None = None) -> dict[str, Any]:
        """The glaze as a scene file writes it: `{"library": ..., "mix": {...}, "amount": ...}`.

        The library's path is made relative to `relative_to` (the folder the
        scene file will live in) where given.
        """
        out: dict[str, Any] = {}
        if self.library is not None:
            out["library"] = _relative(self.library, relative_to)
        p = np.asarray(self.proportions, np.float64)
        p = p / p.sum() if p.sum() > 0 else p
        out["mix"] = {n: float(v) for n, v in zip(self.palette.names, p)}
        out["amount"] = float(np.asarray(self.amount))
        return out


def _relative(path: str, folder: str | os.PathLike | None) -> str:
    if folder is None:
        return path
    try:
        return os.path.relpath(os.path.abspath(path), os.path.abspath(folder))
    except ValueError:  # another drive (Windows)
        return path


def mixture(
    library: Library,
    proportions: dict[str, float],
    amount: float | None = None,
    *,
    source: str | os.PathLike | None = None,
) -> Mixture:
    """A `Mixture` of `library`'s pigments.

    **Arguments:**

    - `library`: a `diffwash.library.Library`.
    - `proportions`: pigment name (matched ignoring case) -> share of the paint, `>= 0`.
    - `amount`: the amount of paint in a glaze of thickness 1; None: the laws'
      reference amount (thickness 1 for every pigment).
    - `source`: the library's file, recorded for writing the scene back.

    **Returns:** the `Mixture` (float64 leaves). Unknown names raise a `DiffwashError`.
    """
    index = {n.lower(): i for i, n in enumerate(library.names)}
    missing = [n for n in proportions if n.lower() not in index]
    if missing:
        raise DiffwashError(f"no pigment {missing[0]!r} in the library (it has {', '.join(library.names)})")
    idx = [index[n.lower()] for n in proportions]
    pal = library.palette
    f64 = lambda a: np.asarray(a, np.float64)  # noqa: E731
    gamma = np.broadcast_to(f64(pal.law.gamma), (len(library.names),))
    palette = mixing.Palette(
        K=f64(pal.K)[idx], S=f64(pal.S)[idx], law=mixing.AmountLaw(gamma=gamma[idx], reference=pal.law.reference),
        weights=np.broadcast_to(f64(pal.weights), (len(library.names),))[idx],
        names=tuple(library.names[i] for i in idx), wavelengths=pal.wavelengths,
        pairs=None if pal.pairs is None else pal.pairs.subset(idx),
    )  # fmt: skip
    a = pal.law.reference if amount is None else amount
    return Mixture(palette=palette, proportions=f64(list(proportions.values())), amount=np.float64(a),
                   library=None if source is None else os.path.abspath(source))  # fmt: skip


#: What `fit_image` fits per sRGB channel, and so not in a scene whose glazes are spectral: their K and S and
#: the paper live on the library's bands.
_PER_CHANNEL = ("wash.K", "wash.S", "unlit.K", "unlit.S", "paper")
#: What `fit_image` fits of a glaze that is a library mixture: its proportions and its amount.
_OF_MIXTURE = ("mix", "amount")


def check_fittable(params: Any, names: tuple[str, ...]) -> None:
    """Refuse, in one line naming the parameter, what `fit_image` cannot fit in `params`.

    A spectral scene's pigments or paper by channel; a glaze's `mix` or `amount` when that glaze is not
    a library mixture (or, for `mix`, a single library pigment: no proportions to fit); a glaze's K or S
    together with its `mix` or `amount` (K and S would replace the mixture).
    """
    if getattr(params, "observation", None) is not None:
        for n in names:
            if n in _PER_CHANNEL:
                raise DiffwashError(f"cannot fit {n!r} of a scene whose glazes are spectral (library pigments, "
                                    f"{len(params.observation.bands)} bands): their K, S and the paper come from the "
                                    "library; fit the shading constants, the light, the mixtures' proportions and "
                                    "amounts (wash.mix, wash.amount, ...) or refit the library", field="--fit")  # fmt: skip
    for n in names:
        glaze, _, which = n.partition(".")
        if glaze not in ("wash", "unlit") or which not in _OF_MIXTURE:
            continue
        paint = getattr(params, glaze)
        if not isinstance(paint, Mixture):
            raise DiffwashError(f"cannot fit {n!r}: the scene's {glaze} is the pigment {paint.name!r}, not a mixture "
                                f'of library pigments (a glaze {{"library": FILE, "mix": {{...}}}})', field="--fit")  # fmt: skip
        if which == "mix" and len(paint.palette.names) < 2:
            raise DiffwashError(f"cannot fit {n!r}: the scene's {glaze} is one library pigment ({paint.name}), so it "
                                f'has no proportions to fit; give it a "mix" of two or more', field="--fit")  # fmt: skip
        for other in (f"{glaze}.K", f"{glaze}.S"):
            if other in names:
                raise DiffwashError(f"cannot fit {n!r} together with {other!r}: fitted K and S replace the {glaze}'s "
                                    "mixture; fit one or the other", field="--fit")  # fmt: skip
