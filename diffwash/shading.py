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
thicknesses, and the shader generator (`diffwash._glsl`) traces these very
functions into GLSL (`diffwash._xp`), constants included.
"""

from __future__ import annotations

import equinox as eqx
import jax
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from . import km
from ._errors import DiffwashError
from ._choices import SHADING_MODES as SHADING_MODES  # the model's; declared in a leaf that --help can read
from ._xp import namespace, shader_function
from .pigments import Pigment, unlabelled
from .spectral import Observation

__all__ = [
    "Params",
    "bias",
    "gain",
    "safe_normalize",
    "thicknesses",
    "glaze",
    "glaze_layers",
    "colour",
    "paper_colour",
    "linear_srgb",
    "check_per_channel",
    "canonical",
    "CONSTANTS",
    "DEFAULT_CONSTANTS",
    "DEFAULT_PAPER",
    "GAIN_BIAS_EPS",
    "SHADING_MODES",
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
#: The model's scalar constants, in the order the scene file, the sidecars and the shaders list them.
CONSTANTS: tuple[str, ...] = tuple(DEFAULT_CONSTANTS)
#: Linear reflectance of the default paper (a warm white watercolour paper).
DEFAULT_PAPER = (0.92, 0.90, 0.84)
#: `bias` and `gain` clamp their shape parameter into `[eps, 1 - eps]` (the curves are singular at 0 and 1).
GAIN_BIAS_EPS = 1e-6

Scalar = Float[ArrayLike, ""]


class Params(eqx.Module):
    """Every differentiable shading parameter, as a pytree.

    Fields mirror the scene file's keys (`params.wash.K` is the scene's
    `"wash"` pigment's K); any of them can be differentiated with `jax.grad` or
    fitted with optimistix.

    **Fields:**

    - `wash`, `unlit`: the two glazes' pigments: `Pigment`s (`K`, `S`, shape
      (3,)), or spectral paint (`diffwash.Mixture`: library pigments
      mixed, `K` and `S` of shape (B,) on the library's bands).
    - `paper`: reflectance of the paper on the glazes' bands: shape (3,)
      (linear sRGB), or (B,).
    - `light`: direction towards the light, world space, shape (3,) (any length;
      the renderer normalises it).
    - `k_wash`, `k_specular`, `shininess`, `k_unlit`, `gain`, `bias`,
      `wash_reduction`: the model's scalar constants.
    - `observation`: how the bands are seen (`diffwash.spectral.Observation`,
      reflectance to linear sRGB) when the glazes are spectral; None when
      they are the three linear sRGB channels.
    """

    wash: Pigment
    unlit: Pigment
    paper: Float[ArrayLike, " C"] = eqx.field(default_factory=lambda: np.asarray(DEFAULT_PAPER))
    light: Float[ArrayLike, "3"] = eqx.field(default_factory=lambda: np.asarray([1.0, 1.0, 1.0]))
    k_wash: Scalar = DEFAULT_CONSTANTS["k_wash"]
    k_specular: Scalar = DEFAULT_CONSTANTS["k_specular"]
    shininess: Scalar = DEFAULT_CONSTANTS["shininess"]
    k_unlit: Scalar = DEFAULT_CONSTANTS["k_unlit"]
    gain: Scalar = DEFAULT_CONSTANTS["gain"]
    bias: Scalar = DEFAULT_CONSTANTS["bias"]
    wash_reduction: Scalar = DEFAULT_CONSTANTS["wash_reduction"]
    observation: Observation | None = None

    @property
    def wash_max(self) -> Scalar:
        """The largest wash thickness the model produces: `k_specular * k_wash`."""
        return self.k_specular * self.k_wash

    @property
    def unlit_max(self) -> Scalar:
        """The largest unlit thickness the model produces: `k_unlit`."""
        return self.k_unlit


def _number(x):
    """A Python number as a float64 NumPy scalar, as loaded scenes hold (one leaf type, not a weak one)."""
    return np.float64(x) if isinstance(x, (int, float)) and not isinstance(x, bool) else x


def canonical(params: Params) -> Params:
    """`params` as the compiled kernels take it: pigments without labels, numbers as float64 scalars.

    So relabelling a pigment or writing `replace(params, gain=0.3)` reuses the
    compiled programs instead of compiling new ones (labels are static
    metadata; a weakly typed Python number is another leaf type than a scene's).
    """
    return unlabelled(jax.tree.map(_number, params))


@shader_function("schlick_bias", [("t", "float"), ("b", "float")], "float")
def bias(t: Float[ArrayLike, "*#b"], b: Float[ArrayLike, "*#b"]) -> Float[Array, "*b"]:
    r"""Schlick's bias: $t / ((1/b - 2)(1 - t) + 1)$, for `t` in [0, 1].

    `b = 0.5` is the identity; `b > 0.5` pushes values up. `b` is clamped into
    `[GAIN_BIAS_EPS, 1 - GAIN_BIAS_EPS]`.

    **References:** C. Schlick, "Fast alternatives to Perlin's bias and gain
    functions", Graphics Gems IV (1994).
    """
    xp = namespace(t, b)
    b = xp.clip(b, GAIN_BIAS_EPS, 1 - GAIN_BIAS_EPS)
    return t / ((1 / b - 2) * (1 - t) + 1)


@shader_function("perlin_gain", [("t", "float"), ("g", "float")], "float")
def gain(t: Float[ArrayLike, "*#b"], g: Float[ArrayLike, "*#b"]) -> Float[Array, "*b"]:
    r"""Perlin's gain built on Schlick's bias, for `t` in [0, 1].

    `gain(t, g) = bias(2t, 1 - g) / 2` for `t < 1/2`, else
    `1 - bias(2 - 2t, 1 - g) / 2`. `g = 0.5` is the identity; `g > 0.5`
    steepens the middle.

    **References:** K. Perlin and E. M. Hoffert, "Hypertexture", SIGGRAPH 1989.
    """
    xp = namespace(t, g)
    (t,) = xp.asfloat(t)
    # Each branch sees only its own half of [0, 1] (the "double where").
    a = bias(2 * xp.minimum(t, 0.5), 1 - g) / 2
    c = 1 - bias(2 - 2 * xp.maximum(t, 0.5), 1 - g) / 2
    return xp.where(t < 0.5, a, c)


@shader_function("safe_normalize", [("v", "vec3")], "vec3")
def safe_normalize(v: Float[ArrayLike, "*b 3"]) -> Float[Array, "*b 3"]:
    """`v / |v|` along the last axis, and 0 (with a zero gradient) where `v = 0`."""
    xp = namespace(v)
    (v,) = xp.asfloat(v)
    n2 = xp.dot(v, v, keepdims=True)
    ok = n2 > 0
    return xp.where(ok, v / xp.sqrt(xp.where(ok, n2, 1)), 0)


@shader_function("pow01", [("x", "float"), ("n", "float")], "float")
def _pow01(x, n):
    """x**n for x in [0, 1] and n >= 0, with finite gradients (0**0 = 1)."""
    xp = namespace(x, n)
    ok = x > 0
    return xp.where(ok, xp.exp(n * xp.log(xp.where(ok, x, 1))), xp.where(n == 0, 1.0, 0.0))


@shader_function(
    "watercolour_thicknesses", [("N", "vec3"), ("L", "vec3"), ("V", "vec3")], [("wash", "float"), ("unlit", "float")]
)
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
    xp = namespace(N, L, V)
    N, L, V = xp.asfloat(N, L, V)
    H = safe_normalize(L + V)
    n_dot_h = xp.clip(xp.dot(H, N), 0, 1)
    n_dot_l = xp.dot(L, N)
    wash = (1 - _pow01(n_dot_h, xp.maximum(params.shininess, 0))) * params.k_specular * params.k_wash
    u = gain(bias(xp.clip(1 - n_dot_l, 0, 1), params.bias), params.gain)
    wash = wash * (1 - params.wash_reduction * u)
    return wash, params.k_unlit * u


@shader_function("watercolour_glaze_layers", [("wash", "float"), ("unlit", "float")], [("R", "vec3"), ("T", "vec3")])
def glaze_layers(
    params: Params, wash: Float[ArrayLike, "*b"], unlit: Float[ArrayLike, "*b"]
) -> tuple[Float[Array, "*b C"], Float[Array, "*b C"]]:
    """`(R, T)` of the unlit glaze lying on the wash glaze (paper not included).

    The seed's suggested variant: with `R` and `T` a shader can composite over
    any paper, `R + T^2 P / (1 - R P)`.
    """
    xp = namespace(wash, unlit)
    Rw, Tw = km.layer(params.wash.K, params.wash.S, xp.expand(wash))
    Ru, Tu = km.layer(params.unlit.K, params.unlit.S, xp.expand(unlit))
    return km.composite(Ru, Tu, Rw, Tw)


@shader_function("watercolour_glaze", [("wash", "float"), ("unlit", "float")], "vec3")
def glaze(params: Params, wash: Float[ArrayLike, "*b"], unlit: Float[ArrayLike, "*b"]) -> Float[Array, "*b C"]:
    """Linear reflectance of the unlit glaze on the wash glaze on the paper.

    **Arguments:**

    - `params`: the pigments and the paper.
    - `wash`, `unlit`: thicknesses (any matching shape).

    **Returns:**

    Linear reflectance per channel, shape `(*b, C)`.
    """
    R, T = glaze_layers(params, wash, unlit)
    return km.over(R, T, params.paper)


def linear_srgb(params: Params, R: Float[ArrayLike, "*b C"]) -> Float[ArrayLike, "*b 3"]:
    """Reflectance on the glazes' bands as linear sRGB: through `params.observation`, or `R` itself when
    the bands are the three sRGB channels."""
    return R if params.observation is None else params.observation.linear_srgb(R)


def colour(params: Params, wash: Float[ArrayLike, "*b"], unlit: Float[ArrayLike, "*b"]) -> Float[Array, "*b 3"]:
    """Linear sRGB of the glazes over the paper: `glaze` (per band), seen through the observation.

    What the renderer draws and the LUT holds; for three-channel pigments it is `glaze` itself.
    """
    return linear_srgb(params, glaze(params, wash, unlit))


def paper_colour(params: Params) -> Float[ArrayLike, " 3"]:
    """Linear sRGB of the bare paper (what uncovered pixels show)."""
    return linear_srgb(params, params.paper)


def check_per_channel(params: Params, what: str) -> None:
    """Refuse `what` (something that evaluates Kubelka-Munk per sRGB channel) for spectral glazes."""
    if params.observation is not None:
        raise DiffwashError(f"{what} evaluates Kubelka-Munk per sRGB channel, but this scene's glazes are "
                            f"spectral ({len(params.observation.bands)} bands): use the baked LUT, which holds "
                            "their colour", field="colour")  # fmt: skip
