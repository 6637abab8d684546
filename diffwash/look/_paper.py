r"""Pigment on paper: granulation, staining, density, unevenness and the paper's shading.

Every effect here multiplies a glaze's thickness by a factor read from the
screen-space textures (`diffwash.look._textures`), pixel by pixel, so the
Kubelka-Munk glaze (or its LUT) then turns more pigment into a darker,
more saturated colour, as it does for the model's own thickness.

**Granulation and staining** (Curtis et al. 1997, sec. 4.5). Curtis et al.
move pigment between the water and the paper with, per step,

$$ \delta_\downarrow = g\,(1 - h\gamma)\,\rho, \qquad
   \delta_\uparrow = d\,(1 + (h - 1)\gamma)\,\rho / \omega, $$

(`g` in the water, `d` on the paper, paper height `h` in [0, 1], granularity
$\gamma$, density $\rho$, staining power $\omega$). At equilibrium the fraction
of the pigment that lies on the paper is

$$ \phi(h) = \frac{a}{a + b/\omega}, \qquad a = 1 - \gamma h, \quad b = 1 - \gamma (1 - h): $$

granular pigments ($\gamma \to 1$) settle in the valleys ($h \to 0$) and are
lifted from the peaks, staining pigments ($\omega$ large) stay where they were
laid ($\phi \to 1$ everywhere), and a pigment with $\gamma = 0$ is even. The
thickness is multiplied by $1 + k_g (\phi(h) / \bar\phi - 1)$, $\bar\phi$ the
mean of $\phi$ over the paper tile (so the pigment's mean amount, hence the
model's tone, is kept) and $k_g$ the `granulation` strength (0: off, 1: the
equilibrium).

**Density.** $\rho$ cancels out of the equilibrium (it only sets the rate), so
the look uses it as the issue's user sees it: how strongly a pigment darkens
per unit thickness, relative to the seed table's typical pigment
(`DENSITY_REFERENCE`): the factor $(\rho / \rho_\text{ref})^{k_\rho}$, with
the `density` strength $k_\rho$ (0: off).

**Unevenness** (Bousseau et al. 2006, sec. 3.2). Pigment never lies even: a
low-frequency *turbulent flow* and a high-frequency *pigment dispersion*
texture modulate the pigment density. Bousseau et al. darken the colour with
$C' = C (1 - (1 - C)(d - 1))$; here the density acts on the thickness itself,
$\exp(k_t n_t + k_d n_d)$ (`n` the zero-mean, unit-deviation noises, `k` the
`turbulence` and `dispersion` amplitudes), which the glaze turns into colour.

**Paper shading.** The final colour is multiplied by $1 + k_s s$, `s` the
paper's relief shading (`paper_shade`), $k_s$ the `paper_shading` strength:
the paper's tooth shows through the pigment and on the bare paper alike, as on
a scan of a painting.

Each per-pixel function is written once against the array namespace of
`diffwash._xp`: the renderer runs it on JAX arrays, and `diffwash._look_glsl`
traces it into the look's shaders.

**References:**

- C. J. Curtis, S. E. Anderson, J. E. Seims, K. W. Fleischer and D. H. Salesin,
  "Computer-Generated Watercolor", SIGGRAPH 1997, secs. 4.5 and 4.7.
- A. Bousseau, M. Kaplan, J. Thollot and F. X. Sillion, "Interactive watercolor
  rendering with temporal coherence and abstraction", NPAR 2006, sec. 3.
- S. E. Montesdeoca, H. S. Seah, A. Semmo, P. Bénard, R. Vergne, J. Thollot and
  D. Benvenuti, "MNPR: A Framework for Real-Time Expressive Non-Photorealistic
  Rendering of 3D Computer Graphics", Expressive 2018 (pigment density and
  paper granulation as art-directable image-space controls).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from jaxtyping import Array, ArrayLike, Float

from .._xp import namespace, shader_function

__all__ = [
    "DENSITY_REFERENCE",
    "MIN_STAINING",
    "PigmentLook",
    "pigment_look",
    "deposit",
    "pigment_factor",
    "unevenness_factor",
    "paper_shading",
]

#: The density the look takes as neutral: the geometric mean of the seed table's 12 pigments' rho (0.030).
DENSITY_REFERENCE = 0.03
#: Staining powers below this are taken as this (omega = 0 would lift every grain).
MIN_STAINING = 1e-3
#: Densities below this are taken as this (rho = 0 would make an invisible pigment).
MIN_DENSITY = 1e-4


class PigmentLook(NamedTuple):
    """What the paper effects need of one pigment: static numbers, the same in JAX and in a shader.

    **Fields:** `granularity` (gamma, clipped into [0, 1]), `staining` (omega,
    at least `MIN_STAINING`), `deposit_mean` (the mean of `deposit` over the
    paper tile), `log_density` (`log(rho / DENSITY_REFERENCE)`).
    """

    granularity: float
    staining: float
    deposit_mean: float
    log_density: float

    def uniform(self) -> tuple[float, float, float, float]:
        """The `vec4` a shader receives for this pigment (`look_wash_pigment`, ...)."""
        return (self.granularity, self.staining, self.deposit_mean, self.log_density)


def _deposit_np(h: np.ndarray, gamma: float, omega: float) -> np.ndarray:
    a = 1 - gamma * h
    b = 1 - gamma * (1 - h)
    return a / (a + b / omega)


def pigment_look(pigment, paper: np.ndarray) -> PigmentLook:
    """The `PigmentLook` of a `Pigment` (its `granularity`, `staining`, `density`) on a paper tile.

    **Arguments:**

    - `pigment`: a `diffwash.Pigment` (or anything with those three attributes).
    - `paper`: the paper's height tile in [0, 1] (`ScreenTextures.paper`).
    """
    gamma = float(np.clip(pigment.granularity, 0.0, 1.0))
    omega = max(float(pigment.staining), MIN_STAINING)
    h = np.asarray(paper, np.float64)
    mean = float(np.mean(_deposit_np(h, gamma, omega)))
    rho = max(float(pigment.density), MIN_DENSITY)
    return PigmentLook(gamma, omega, mean, math.log(rho / DENSITY_REFERENCE))


@shader_function("look_deposit", [("h", "float"), ("gamma", "float"), ("omega", "float")], "float")
def deposit(h: Float[ArrayLike, "*b"], gamma: float, omega: float) -> Float[Array, "*b"]:
    r"""The fraction of a pigment lying on paper of height `h` at equilibrium (Curtis et al. 1997).

    $\phi(h) = a / (a + b/\omega)$, $a = 1 - \gamma h$, $b = 1 - \gamma(1 - h)$;
    `h` in [0, 1], `gamma` in [0, 1], `omega > 0`. The denominator is at least
    `min(1, 1/omega) > 0`.
    """
    (h,) = namespace(h, gamma, omega).asfloat(h)
    a = 1 - gamma * h
    b = 1 - gamma * (1 - h)
    return a / (a + b / omega)


@shader_function("look_pigment_factor", [("h", "float"), ("pigment", "vec4")], "float")
def pigment_factor(
    h: Float[ArrayLike, "*b"], pigment: PigmentLook, granulation: Float[ArrayLike, ""], density: Float[ArrayLike, ""]
) -> Float[Array, "*b"]:
    r"""The thickness factor of granulation, staining and density for one pigment.

    $$ \max\bigl(1 + k_g (\phi(h)/\bar\phi - 1),\ 0\bigr)\ \exp(k_\rho \log(\rho/\rho_\text{ref})) $$

    **Arguments:**

    - `h`: paper height at each pixel, in [0, 1].
    - `pigment`: the pigment's `PigmentLook` (in a shader, its `vec4`:
      `PigmentLook.uniform()`, indexed in the same order).
    - `granulation`: $k_g$, 0 (even) to 1 (Curtis's equilibrium); differentiable.
    - `density`: $k_\rho$, 0 (off) to 1; differentiable.

    **Returns:**

    The factor, `>= 0`, shape of `h`.
    """
    xp = namespace(h, pigment, granulation, density)
    granularity, staining, deposit_mean, log_density = (pigment[i] for i in range(4))
    g = 1 + granulation * (deposit(h, granularity, staining) / deposit_mean - 1)
    g = xp.where(g > 0, g, 0.0)
    return g * xp.exp(density * log_density)


@shader_function("look_unevenness_factor", [("turbulence_noise", "float"), ("dispersion_noise", "float")], "float")
def unevenness_factor(
    turbulence_noise: Float[ArrayLike, "*b"],
    dispersion_noise: Float[ArrayLike, "*b"],
    turbulence: Float[ArrayLike, ""],
    dispersion: Float[ArrayLike, ""],
) -> Float[Array, "*b"]:
    r"""Bousseau et al.'s turbulent flow and pigment dispersion as a thickness factor: $\exp(k_t n_t + k_d n_d)$.

    `turbulence_noise`, `dispersion_noise`: the zero-mean unit-deviation noises
    at each pixel; `turbulence`, `dispersion`: their amplitudes (0: off),
    differentiable.
    """
    xp = namespace(turbulence_noise, dispersion_noise, turbulence, dispersion)
    tn, dn = xp.asfloat(turbulence_noise, dispersion_noise)
    return xp.exp(turbulence * tn + dispersion * dn)


@shader_function("look_paper_relief", [("rgb", "vec3"), ("shade", "float")], "vec3")
def paper_shading(
    rgb: Float[ArrayLike, "*b 3"], shade: Float[ArrayLike, "*b"], strength: Float[ArrayLike, ""]
) -> Float[Array, "*b 3"]:
    r"""The paper's relief over the final colour: $C (1 + k_s s)$, clamped at 0.

    `shade`: the paper's zero-mean shading at each pixel (`ScreenTextures`
    channel `shade`); `strength`: $k_s$ (0: off), differentiable.
    """
    xp = namespace(rgb, shade, strength)
    rgb, shade = xp.asfloat(rgb, shade)
    f = 1 + strength * shade
    f = xp.where(f > 0, f, 0.0)
    return rgb * xp.expand(f)
