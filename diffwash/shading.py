r"""The watercolour shading model: two pigment glazes over paper.

After Lum and Ma (2001) as Smedresman makes it real-time: a white page receives

- a *wash* glaze, thick everywhere except in highlights (the inverse of a
  specular term), and
- an *unlit* glaze on the side away from the light (the inverse of a diffuse
  term, shaped by Schlick's bias and Perlin's gain),

composited with Kubelka-Munk over the paper. Per shaded point with unit normal
`N`, unit direction to the light `L`, unit direction to the eye `V` and
`H = normalize(L + V)`:

$$ w = \bigl(1 - \mathrm{clamp}(H\cdot N, 0, 1)^{n}\bigr)\, k_\text{specular}\, k_\text{wash}, \qquad
   u = \mathrm{gain}\bigl(\mathrm{bias}(\mathrm{clamp}(1 - L\cdot N, 0, 1), b), g\bigr), $$

then `w <- w (1 - wash_reduction u)` and the unlit thickness is `k_unlit u`.
The colour is `over(composite(unlit, wash), paper)`: the unlit glaze on top of
the wash, on top of the paper.

This module is the one source of truth for the model: the renderer evaluates it
per pixel or per vertex, the LUT baker evaluates `glaze` on a grid of
thicknesses, and the exported shaders are tested against both.
"""

from __future__ import annotations

from typing import Any

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from . import km
from .pigments import Pigment

__all__ = [
    "Params",
    "bias",
    "gain",
    "safe_normalize",
    "thicknesses",
    "glaze",
    "glaze_layers",
    "DEFAULT_CONSTANTS",
    "DEFAULT_PAPER",
]

#: Model constants a scene may leave out, with their defaults.
DEFAULT_CONSTANTS: dict[str, float] = {
    "k_wash": 1.0,
    "k_specular": 1.0,
    "shininess": 20.0,
    "k_unlit": 1.0,
    "gain": 0.5,
    "bias": 0.5,
    "wash_reduction": 0.0,
}
#: Linear reflectance of the default paper (a warm white watercolour paper).
DEFAULT_PAPER = (0.92, 0.90, 0.84)

_EPS_01 = 1e-6  # gain and bias are clamped into [eps, 1 - eps]


class Params(eqx.Module):
    """Every differentiable shading parameter, as a pytree.

    Fields mirror the scene file's keys (`params.wash.K` is the scene's
    `"wash"` pigment's K); any of them can be differentiated with `jax.grad` or
    fitted with optimistix.

    **Fields:**

    - `wash`, `unlit`: the two glazes' pigments (`K`, `S`, shape (3,)).
    - `paper`: linear reflectance of the paper, shape (3,).
    - `light`: direction towards the light, world space, shape (3,) (any length;
      the renderer normalises it).
    - `k_wash`, `k_specular`, `shininess`, `k_unlit`, `gain`, `bias`,
      `wash_reduction`: the model's scalar constants.
    """

    wash: Pigment
    unlit: Pigment
    paper: Any = eqx.field(default_factory=lambda: np.asarray(DEFAULT_PAPER))
    light: Any = eqx.field(default_factory=lambda: np.asarray([1.0, 1.0, 1.0]))
    k_wash: Any = DEFAULT_CONSTANTS["k_wash"]
    k_specular: Any = DEFAULT_CONSTANTS["k_specular"]
    shininess: Any = DEFAULT_CONSTANTS["shininess"]
    k_unlit: Any = DEFAULT_CONSTANTS["k_unlit"]
    gain: Any = DEFAULT_CONSTANTS["gain"]
    bias: Any = DEFAULT_CONSTANTS["bias"]
    wash_reduction: Any = DEFAULT_CONSTANTS["wash_reduction"]

    @property
    def wash_max(self) -> Any:
        """The largest wash thickness the model produces: `k_specular * k_wash`."""
        return self.k_specular * self.k_wash

    @property
    def unlit_max(self) -> Any:
        """The largest unlit thickness the model produces: `k_unlit`."""
        return self.k_unlit


def bias(t: Float[ArrayLike, "*#b"], b: Float[ArrayLike, "*#b"]) -> Float[Array, "*b"]:
    r"""Schlick's bias: $t / ((1/b - 2)(1 - t) + 1)$, for `t` in [0, 1].

    `b = 0.5` is the identity; `b > 0.5` pushes values up. `b` is clamped into
    `[1e-6, 1 - 1e-6]`.
    """
    b = jnp.clip(b, _EPS_01, 1 - _EPS_01)
    return t / ((1 / b - 2) * (1 - t) + 1)


def gain(t: Float[ArrayLike, "*#b"], g: Float[ArrayLike, "*#b"]) -> Float[Array, "*b"]:
    r"""Perlin's gain built on Schlick's bias, for `t` in [0, 1].

    `gain(t, g) = bias(2t, 1 - g) / 2` for `t < 1/2`, else
    `1 - bias(2 - 2t, 1 - g) / 2`. `g = 0.5` is the identity; `g > 0.5`
    steepens the middle.
    """
    t = jnp.asarray(t)
    lo = t < 0.5
    # Each branch sees only its own half of [0, 1] (the "double where").
    a = bias(2 * jnp.minimum(t, 0.5), 1 - g) / 2
    c = 1 - bias(2 - 2 * jnp.maximum(t, 0.5), 1 - g) / 2
    return jnp.where(lo, a, c)


def safe_normalize(v: Float[ArrayLike, "*b 3"], axis: int = -1) -> Float[Array, "*b 3"]:
    """`v / |v|`, and 0 (with a zero gradient) where `v = 0`."""
    v = jnp.asarray(v)
    n2 = jnp.sum(v * v, axis=axis, keepdims=True)
    ok = n2 > 0
    return jnp.where(ok, v / jnp.sqrt(jnp.where(ok, n2, 1)), 0)


def _pow01(x: Array, n: Array) -> Array:
    """x**n for x in [0, 1] and n >= 0, with finite gradients (0**0 = 1)."""
    ok = x > 0
    return jnp.where(ok, jnp.exp(n * jnp.log(jnp.where(ok, x, 1))), jnp.where(n == 0, 1.0, 0.0))


def thicknesses(
    N: Float[ArrayLike, "*#b 3"],
    L: Float[ArrayLike, "*#b 3"],
    V: Float[ArrayLike, "*#b 3"],
    params: Params,
) -> tuple[Float[Array, "*b"], Float[Array, "*b"]]:
    """Wash and unlit thickness at points with unit normal `N`, light `L`, eye `V`.

    `N`, `L`, `V` are unit vectors (world space) on the last axis. `H` is
    `normalize(L + V)` (0 where `L = -V`).

    **Returns:**

    `(wash, unlit)` thicknesses, with the wash reduction applied.
    """
    N, L, V = jnp.asarray(N), jnp.asarray(L), jnp.asarray(V)
    H = safe_normalize(L + V)
    n_dot_h = jnp.clip(jnp.sum(H * N, axis=-1), 0, 1)
    n_dot_l = jnp.sum(L * N, axis=-1)
    wash = (1 - _pow01(n_dot_h, jnp.maximum(params.shininess, 0))) * params.k_specular * params.k_wash
    u = gain(bias(jnp.clip(1 - n_dot_l, 0, 1), params.bias), params.gain)
    wash = wash * (1 - params.wash_reduction * u)
    return wash, params.k_unlit * u


def glaze_layers(
    params: Params, wash: Float[ArrayLike, "*b"], unlit: Float[ArrayLike, "*b"]
) -> tuple[Float[Array, "*b 3"], Float[Array, "*b 3"]]:
    """`(R, T)` of the unlit glaze lying on the wash glaze (paper not included).

    The seed's suggested variant: with `R` and `T` a shader can composite over
    any paper, `R + T^2 P / (1 - R P)`.
    """
    wash = jnp.asarray(wash)[..., None]
    unlit = jnp.asarray(unlit)[..., None]
    Rw, Tw = km.layer(params.wash.K, params.wash.S, wash)
    Ru, Tu = km.layer(params.unlit.K, params.unlit.S, unlit)
    return km.composite(Ru, Tu, Rw, Tw)


def glaze(params: Params, wash: Float[ArrayLike, "*b"], unlit: Float[ArrayLike, "*b"]) -> Float[Array, "*b 3"]:
    """Linear RGB reflectance of the unlit glaze on the wash glaze on the paper.

    **Arguments:**

    - `params`: the pigments and the paper.
    - `wash`, `unlit`: thicknesses (any matching shape).

    **Returns:**

    Linear RGB reflectance, shape `(*b, 3)`.
    """
    R, T = glaze_layers(params, wash, unlit)
    return km.over(R, T, jnp.asarray(params.paper))
