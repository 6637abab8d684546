r"""The watercolour look as a pipeline of array operators, in the order the renderer applies them.

**1. Surface terms** (per shaded point, where the renderer computes the
model's wash and unlit thickness; the geometry pass of a shader):
`surface_terms` thickens the unlit glaze in the object's own shadow
(`_shadow`) and turns it into hatching for a pen-and-wash style
(`_hatching`).

**2. The G-buffer**: per pixel `(wash, unlit, mix, stroke)`, `(H, W, 4)`:
the thicknesses, the pigment mix and the brush-stroke value (`_strokes`, a
per-vertex attribute interpolated like the normals), all zero where nothing
is drawn (row 0 at the top, as every diffwash image). Coverage is not needed
here (bare paper is thickness 0); the renderer keeps its own alpha.

**3. Image terms** (`image_terms`, full-screen passes of a shader): edge
darkening (`_edges`, the only neighbourhood operator: a separable blur at
reduced resolution) of the smooth thicknesses, then per pixel the brush
strokes, the paper's granulation, staining and density for each glaze's
pigment mixture, and the turbulence and dispersion of the pigment
(`_paper`), all as factors on the thickness. Strokes come after the edge
darkening so that the edges are the wash's, not every stroke's.

**4. Glaze**: the Kubelka-Munk glazes of the (mixed) pigments over the
paper (`_mix.glaze_mix`, or its 3D LUT `_mix.lookup_mix_lut`; with no mix map,
`diffwash.shading.glaze` or the 2D LUT).

**5. Paper shading**: the paper's relief over the colour (`_paper`).

Every continuous parameter is a leaf of `Look` (differentiable with
`jax.grad`, fittable with optimistix); zero strengths and widths give back
the plain model exactly (`OFF`; a zero edge width alone keeps the blur grid's
own narrow edge). `glsl_final_pass` writes steps 3-5 as one fragment
shader over the G-buffer, `glsl_surface` step 1 for the geometry pass;
`look_uniforms` gives their uniforms from the same Python values.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, NamedTuple

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from ._edges import EDGE_RADIUS, edge_darkening, edge_downsample, gaussian_weights_np, glsl_edge_darkening
from ._hatching import TAM_LEVELS, glsl_hatching, hatch_ink
from ._mix import glsl_mix_lut
from ._paper import PigmentLook, glsl_paper, paper_shading, pigment_factor, unevenness_factor
from ._shadow import DEFAULT_BIAS, glsl_shadow
from ._strokes import glsl_strokes, stroke_factor

__all__ = [
    "Look",
    "DEFAULT_LOOK",
    "OFF",
    "Pigments",
    "surface_terms",
    "image_terms",
    "compose",
    "look_uniforms",
    "glsl_surface",
    "glsl_final_pass",
]

#: The look's defaults: what `"watercolour": {}` turns on (docs/watercolour.md gives the reasons).
DEFAULT_LOOK: dict[str, float] = {
    "edge_darkening": 3.0,
    "edge_width": 3.0,
    "granulation": 0.6,
    "density": 0.25,
    "turbulence": 0.18,
    "dispersion": 0.08,
    "paper_shading": 0.08,
    "strokes": 0.12,
    "shadow": 0.7,
    "shadow_bias": DEFAULT_BIAS,
    "hatching": 0.0,
}


class Look(eqx.Module):
    """The look's continuous parameters, as a pytree (every field differentiable).

    **Fields:**

    - `edge_darkening`: pigment gathered at a glaze's edge, $k_e$ (0: off).
    - `edge_width`: the edge's width, the blur's sigma in pixels (at 0 the
      blur grid's own width remains, about `edge_downsample(H)` pixels).
    - `granulation`: the paper's effect on granular pigments, $k_g$ in [0, 1].
    - `density`: how much a pigment's density scales its thickness, $k_\\rho$.
    - `turbulence`, `dispersion`: amplitudes of the low- and high-frequency
      unevenness.
    - `paper_shading`: the strength of the paper's relief shading.
    - `strokes`: the amplitude of the brush-stroke layer.
    - `shadow`: how far the unlit glaze thickens in the object's own shadow
      (0: off, 1: as thick as on the side facing away from the light).
    - `shadow_bias`: the shadow map's depth bias (a step: zero gradient).
    - `hatching`: how far the unlit glaze becomes hatching (0: a wash, 1: pen
      strokes only).
    """

    edge_darkening: Any = DEFAULT_LOOK["edge_darkening"]
    edge_width: Any = DEFAULT_LOOK["edge_width"]
    granulation: Any = DEFAULT_LOOK["granulation"]
    density: Any = DEFAULT_LOOK["density"]
    turbulence: Any = DEFAULT_LOOK["turbulence"]
    dispersion: Any = DEFAULT_LOOK["dispersion"]
    paper_shading: Any = DEFAULT_LOOK["paper_shading"]
    strokes: Any = DEFAULT_LOOK["strokes"]
    shadow: Any = DEFAULT_LOOK["shadow"]
    shadow_bias: Any = DEFAULT_LOOK["shadow_bias"]
    hatching: Any = DEFAULT_LOOK["hatching"]


#: Every effect off: `compose` then gives the plain model's image.
OFF = Look(**{k: 0.0 for k in DEFAULT_LOOK})


class Pigments(NamedTuple):
    """The `PigmentLook`s of the four pigments a mixed pair of glazes uses (the `_b` ones at mix = 1).

    Without a mix map, pass the same pigment twice (`Pigments.single(wash, unlit)`).
    """

    wash: PigmentLook
    wash_b: PigmentLook
    unlit: PigmentLook
    unlit_b: PigmentLook

    @classmethod
    def single(cls, wash: PigmentLook, unlit: PigmentLook) -> "Pigments":
        return cls(wash, wash, unlit, unlit)


def surface_terms(
    wash: Float[ArrayLike, "*b"],
    unlit: Float[ArrayLike, "*b"],
    look: Look,
    *,
    unlit_max: Float[ArrayLike, ""],
    shadow: Float[ArrayLike, "*b"] | None = None,
    hatch: Float[ArrayLike, "*b T"] | Callable[[Array], Array] | None = None,
) -> tuple[Float[Array, "*b"], Float[Array, "*b"]]:
    r"""Shadow and hatching on the model's thicknesses at shaded points.

    $$ u_1 = u + k_\text{shadow}\, s\, (u_\max - u), \qquad
       u' = u_1 + k_\text{hatching} (u_\max\, \mathrm{ink}(u_1 / u_\max) - u_1), $$

    with `s` the shadow factor (`_shadow.shadow`) and `ink(tau)` the tonal
    art map's ink at tone `tau` (`hatch`: the map's samples of every tone at
    the point, `_hatching.hatch_samples`; or a function `tau -> ink`, e.g.
    `_hatching.hatch_ink_at`, which reads only the two tones it needs). Each
    term is skipped when its input is None; the wash is unchanged.

    **Arguments:**

    - `wash`, `unlit`: the model's thicknesses (`diffwash.shading.thicknesses`).
    - `look`: the `Look`.
    - `unlit_max`: the model's largest unlit thickness (`params.k_unlit`).
    - `shadow`, `hatch`: see above.
    """
    w, u = jnp.asarray(wash), jnp.asarray(unlit)
    if shadow is not None:
        u = u + look.shadow * jnp.asarray(shadow) * (unlit_max - u)
    if hatch is not None:
        ok = unlit_max > 0
        tau = jnp.where(ok, u / jnp.where(ok, unlit_max, 1.0), 0.0)
        ink = hatch(tau) if callable(hatch) else hatch_ink(hatch, tau)
        u = u + look.hatching * (unlit_max * ink - u)
    return w, u


def _lerp(a: Array, b: Array, t: Array) -> Array:
    return a + t * (b - a)


def _pigment_factor(h: Array, a: PigmentLook, b: PigmentLook, m: Array, look: Look) -> Array:
    fa = pigment_factor(h, a, look.granulation, look.density)
    if b == a:  # no mix map: one pigment (a static check, no work for the second)
        return fa
    return _lerp(fa, pigment_factor(h, b, look.granulation, look.density), m)


def image_terms(
    gbuffer: Float[ArrayLike, "*p 4"],
    screen: Float[ArrayLike, "*p 6"],
    look: Look,
    pigments: Pigments,
    *,
    mean: Float[ArrayLike, "*p 2"] | None = None,
) -> Float[Array, "*p 2"]:
    r"""Edge darkening, then strokes, granulation, staining, density and unevenness, on the G-buffer's thicknesses.

    $$ t' = \mathrm{edge}(t)\ \exp(k_\text{strokes} b)\ \mathrm{lerp}(F_a(h), F_b(h), m)\ \exp(k_t n_t + k_d n_d) $$

    per glaze, `F` the pigment factors (`_paper.pigment_factor`) of the
    glaze's two pigments, `m` the mix, `b` the stroke value, `h` the paper.

    **Arguments:**

    - `gbuffer`: `(wash, unlit, mix, stroke)` per pixel: an `(H, W, 4)` image,
      or any list of pixels when `mean` is given.
    - `screen`: the screen textures at the same pixels (`_textures.tile`).
    - `look`: the `Look`.
    - `pigments`: the four pigments' `PigmentLook`.
    - `mean`: the glazes' local mean at those pixels (`_edges.local_mean` of
      the G-buffer's `(H, W, 2)` thicknesses, with `edge_downsample(H)`); by
      default computed here from the `(H, W, 4)` image. With it, any set of
      pixels can be processed: the edge blur is the only operator that needs
      the whole image.

    **Returns:**

    `(*p, 2)`: the wash and unlit thickness to glaze.
    """
    g = jnp.asarray(gbuffer)
    s = jnp.asarray(screen)
    factor = edge_downsample(g.shape[0]) if mean is None else 1
    t = edge_darkening(g[..., :2], look.edge_darkening, look.edge_width, mean=mean, factor=factor)
    h, m = s[..., 0], g[..., 2]
    b = stroke_factor(g[..., 3], look.strokes)
    w = t[..., 0] * b * _pigment_factor(h, pigments.wash, pigments.wash_b, m, look) * unevenness_factor(s[..., 2], s[..., 3], look.turbulence, look.dispersion)
    u = t[..., 1] * b * _pigment_factor(h, pigments.unlit, pigments.unlit_b, m, look) * unevenness_factor(s[..., 4], s[..., 5], look.turbulence, look.dispersion)
    return jnp.stack([w, u], axis=-1)


def compose(
    gbuffer: Float[ArrayLike, "H W 4"],
    screen: Float[ArrayLike, "H W 6"],
    look: Look,
    pigments: Pigments,
    glaze: Any,
) -> Float[Array, "H W 3"]:
    """Steps 3 to 5: image terms, the glaze, the paper's shading: linear RGB.

    `glaze(wash, unlit, mix) -> (..., 3)`: e.g. `lambda w, u, m: glaze_mix(params,
    wash_b, unlit_b, w, u, m)`, or a LUT lookup.
    """
    g = jnp.asarray(gbuffer)
    t = image_terms(g, screen, look, pigments)
    rgb = glaze(t[..., 0], t[..., 1], g[..., 2])
    return paper_shading(rgb, jnp.asarray(screen)[..., 1], look.paper_shading)


def look_uniforms(look: Look, pigments: Pigments, *, height: int, radius: int = EDGE_RADIUS) -> dict[str, Any]:
    """The uniforms of `glsl_surface` and `glsl_final_pass` (and the edge passes) for a `Look`.

    The same numbers the JAX operators use: the strengths as floats, the
    pigments' `vec4`s, and `look_edge_weights` (`gaussian_weights_np(width /
    f, radius)`, offsets 0..radius, `f = edge_downsample(height)` for an
    image `height` pixels tall).
    """
    factor = edge_downsample(height)
    f = lambda x: float(np.asarray(x))  # noqa: E731
    out: dict[str, Any] = {
        "look_edge_darkening": f(look.edge_darkening),
        "look_granulation": f(look.granulation),
        "look_density": f(look.density),
        "look_turbulence": f(look.turbulence),
        "look_dispersion": f(look.dispersion),
        "look_paper_shading": f(look.paper_shading),
        "look_strokes": f(look.strokes),
        "look_shadow": f(look.shadow),
        "look_shadow_bias": f(look.shadow_bias),
        "look_hatching": f(look.hatching),
        "look_wash_pigment": pigments.wash.uniform(),
        "look_wash_pigment_b": pigments.wash_b.uniform(),
        "look_unlit_pigment": pigments.unlit.uniform(),
        "look_unlit_pigment_b": pigments.unlit_b.uniform(),
    }
    weights = gaussian_weights_np(f(look.edge_width) / factor, radius)
    out["look_edge_weights"] = [float(v) for v in weights[radius:]]
    return out


def glsl_surface(*, tam_levels: int = TAM_LEVELS, tam_size: int = 256) -> str:
    """GLSL of `surface_terms` for a geometry pass, with the shadow and hatching functions it calls
    (`tam_levels`, `tam_size`: the tonal art map's levels and level-0 side, as `glsl_hatching`).

    `vec2 look_surface(vec2 t, float unlit_max, float shadow, vec3 P, vec3 N, float pixel_size)` (the
    point, its normal and footprint for the hatching, read only where `LOOK_HATCHING` is 1, the default);
    the pass writes `vec4(look_surface(...), mix, stroke)` to the G-buffer.
    """
    return (
        glsl_shadow()
        + "\n"
        + glsl_hatching(levels=tam_levels, size=tam_size)
        + """
// ---- Surface terms (diffwash/look/_look.py: surface_terms) -----------------------------------------
uniform float look_shadow;     // how far the unlit glaze thickens in the object's own shadow
uniform float look_hatching;   // how far the unlit glaze becomes hatching

#ifndef LOOK_HATCHING
#define LOOK_HATCHING 1
#endif
vec2 look_surface(vec2 t, float unlit_max, float shadow, vec3 P, vec3 N, float pixel_size) {
    float u = t.y + look_shadow * shadow * (unlit_max - t.y);
#if LOOK_HATCHING
    float tau = unlit_max > 0.0 ? u / unlit_max : 0.0;
    u = u + look_hatching * (unlit_max * look_hatch_ink(P, N, pixel_size, tau) - u);
#endif
    return vec2(t.x, u);
}
"""
    )


def glsl_final_pass(*, height: int, colour: str = "mix") -> str:
    """The final full-screen pass (no `#version` line): G-buffer -> image terms -> glaze -> paper shading.

    Reads `look_gbuffer` (RGBA float: wash, unlit, mix, stroke; `texelFetch`
    at the fragment), `look_screen0` / `look_screen1` (the screen tile,
    `ScreenTextures.rgba()`), `look_edge_blurred` (`glsl_edge_passes`' output).
    `uniform int look_flip_rows` says whether the G-buffer's rows run bottom
    to top (an OpenGL render: the screen tile's row is then `look_rows - 1 -
    y`); `look_rows` is the image height. `colour="mix"` glazes with the 3D
    LUT (`glsl_mix_lut`); the result is linear RGB unless `LOOK_OUTPUT_SRGB`
    is defined to 1. `height`: the image's, which sets the edge blur's
    reduction (`edge_downsample`).
    """
    factor = edge_downsample(height)
    if colour != "mix":
        raise ValueError("the final pass glazes with the 3D mix LUT (a 2D LUT is the mix LUT with one slice pair)")
    return (
        """\
#ifndef LOOK_OUTPUT_SRGB
#define LOOK_OUTPUT_SRGB 0
#endif
uniform sampler2D look_gbuffer;    // wash, unlit, mix, stroke (full resolution)
uniform sampler2D look_screen0;    // paper height, paper shade, turbulence (wash), dispersion (wash)
uniform sampler2D look_screen1;    // turbulence (unlit), dispersion (unlit)
uniform int look_flip_rows;        // 1: the G-buffer's row 0 is the image's bottom row
uniform int look_rows;             // image height in pixels
uniform vec4 look_wash_pigment;    // PigmentLook.uniform(): gamma, omega, mean deposit, log(rho / ref)
uniform vec4 look_wash_pigment_b;
uniform vec4 look_unlit_pigment;
uniform vec4 look_unlit_pigment_b;
layout(location = 0) out vec4 look_colour;
"""
        + glsl_paper()
        + glsl_strokes()
        + glsl_edge_darkening(factor)
        + glsl_mix_lut()
        + """
vec3 look_srgb_encode(vec3 c) {
    c = clamp(c, 0.0, 1.0);
    return mix(1.055 * pow(c, vec3(1.0 / 2.4)) - 0.055, 12.92 * c, lessThanEqual(c, vec3(0.0031308)));
}

void main() {
    ivec2 frag = ivec2(gl_FragCoord.xy);
    vec4 g = texelFetch(look_gbuffer, frag, 0);
    int row = look_flip_rows != 0 ? look_rows - 1 - frag.y : frag.y;
    ivec2 tile = textureSize(look_screen0, 0);
    ivec2 tc = ivec2(frag.x % tile.x, row % tile.y);
    vec4 s0 = texelFetch(look_screen0, tc, 0);
    vec4 s1 = texelFetch(look_screen1, tc, 0);
    vec2 t = look_edge_darken(g.rg, look_edge_mean(frag));
    float m = g.b;
    float fw = mix(look_pigment_factor(s0.x, look_wash_pigment), look_pigment_factor(s0.x, look_wash_pigment_b), m);
    float fu = mix(look_pigment_factor(s0.x, look_unlit_pigment), look_pigment_factor(s0.x, look_unlit_pigment_b), m);
    float b = look_stroke_factor(g.a);
    float w = t.x * b * fw * look_unevenness_factor(s0.z, s0.w);
    float u = t.y * b * fu * look_unevenness_factor(s1.x, s1.y);
    vec3 c = look_paper_shading_apply(look_mix_colour(w, u, m), s0.y);
#if LOOK_OUTPUT_SRGB
    c = look_srgb_encode(c);
#endif
    look_colour = vec4(c, 1.0);
}
"""
    )
