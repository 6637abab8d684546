r"""The watercolour look's shaders, generated from `diffwash.look`'s own functions.

The look's per-pixel arithmetic is written once, in `diffwash.look`, against
the array namespace of `diffwash._xp`; this module traces those very
functions into GLSL, as `diffwash._glsl` does for the model:

- `surface_terms` (self-shadowing and hatching on the model's thicknesses)
  becomes `look_surface`, the geometry pass's last step;
- `pixel_terms` (edge darkening, strokes, granulation, staining, density,
  unevenness) with `edge_darken`, `stroke_factor`, `pigment_factor`,
  `deposit` and `unevenness_factor`, then `paper_shading` and the sRGB curve
  (`diffwash.colorimetry.srgb_encode`), become the final pass's functions.

Their uniforms are declared from the `Look`'s own declaration
(`diffwash.look.leaf_specs`: `look_<leaf>`, with its documentation), and the
screen tile's channels are read by their names (`diffwash.look.CHANNELS`).
What is written here by hand is the plumbing a GPU needs and JAX does not:
texture reads (the G-buffer and screen tile, the edge blur's passes and its
bilinear sample, the shadow map's percentage-closer taps, the tonal art map's
atlas, the 3D mix LUT), the passes' `main`s and their inputs and outputs.
The tests (tests/test_look_glsl.py) hold every piece against its JAX twin.

`geometry_sources`, `look_textures` and `look_frame_uniforms` give what a host
program draws with (`diffwash._look_frame.LookFrame`, the export's `look/`
folder, the viewer).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from . import colorimetry
from . import look as wl
from ._glsl import functions_source, uniform_values
from ._xp import GLSL, Expr, float_literal, glsl_session, trace_function
from .look import _hatching

__all__ = [
    "HEADERS",
    "header",
    "vec_literal",
    "FULLSCREEN_VERTEX",
    "MIX_LUT_SIZE",
    "MIX_LUT_RANGE",
    "look_symbols",
    "look_declarations",
    "generate",
    "glsl_paper",
    "glsl_strokes",
    "glsl_edge_passes",
    "glsl_edge_darkening",
    "glsl_shadow",
    "glsl_depth_pass",
    "glsl_hatching",
    "glsl_mix_lut",
    "mix_lut",
    "mix_lut_range",
    "glsl_surface",
    "glsl_final_pass",
    "geometry_sources",
    "look_textures",
    "look_frame_uniforms",
]

#: The `#version` line (and precision statements) of each target, as in `diffwash._glsl`.
HEADERS: dict[str, str] = {
    "glsl330": "#version 330 core\n",
    "webgl2": "#version 300 es\nprecision highp float;\nprecision highp int;\nprecision highp sampler2D;\n"
    "precision highp sampler3D;\nprecision highp sampler2DArray;\nprecision highp usampler2D;\n",
}
#: The 3D mix LUT's size (wash, unlit, mix): docs/watercolour.md measures its error by size.
MIX_LUT_SIZE = (64, 64, 16)
#: The 3D LUT covers this many times the model's largest thicknesses (edges, granulation and noise thicken).
MIX_LUT_RANGE = 3.0


def header(target: str) -> str:
    """The first lines of a shader for `target` (`"glsl330"` or `"webgl2"`)."""
    if target not in HEADERS:
        raise ValueError(f"target must be one of {', '.join(HEADERS)}, got {target!r}")
    return HEADERS[target]


def vec_literal(values) -> str:
    """`vecN(...)` of float literals for a sequence of 2 to 4 numbers."""
    values = [float(v) for v in values]
    if not 2 <= len(values) <= 4:
        raise ValueError(f"a GLSL vector has 2 to 4 components, got {len(values)}")
    return f"vec{len(values)}(" + ", ".join(float_literal(v) for v in values) + ")"


#: A full-screen triangle without vertex buffers (draw 3 vertices): every pixel centre runs the
#: fragment shader once; `gl_FragCoord.xy` is the pixel centre `(column + 0.5, row + 0.5)`.
FULLSCREEN_VERTEX = """\
void main() {
    vec2 p = vec2(float((gl_VertexID << 1) & 2), float(gl_VertexID & 2));
    gl_Position = vec4(p * 2.0 - 1.0, 0.0, 1.0);
}
"""

#: The pigments' uniforms (`PigmentLook.uniform()`), by their `Pigments` field.
_PIGMENT_UNIFORMS = {name: f"look_{name}_pigment" if not name.endswith("_b") else f"look_{name[:-2]}_pigment_b" for name in wl.Pigments._fields}


def look_symbols() -> tuple[wl.Look, wl.Pigments]:
    """A `Look` and `Pigments` whose leaves are the shaders' uniforms: what the traced look functions read."""
    look = wl.Look(**{name: Expr(f"look_{name}", 1, atom=True) for name in wl.leaf_specs()})
    pigments = wl.Pigments(*(Expr(u, 4, atom=True) for u in _PIGMENT_UNIFORMS.values()))
    return look, pigments


def look_declarations() -> str:
    """The uniforms of every `Look` leaf (`look_<leaf>`, documented from `leaf_specs`) and of the four pigments."""
    lines = ["// ---- The look's parameters (diffwash.look.Look, one uniform per leaf) ---------------------------"]
    for name, spec in wl.leaf_specs().items():
        lines.append(f"uniform float look_{name};".ljust(36) + f"// {spec.doc} (watercolour.{spec.effect}.{spec.key})")
    for uniform in _PIGMENT_UNIFORMS.values():
        lines.append(f"uniform vec4 {uniform};".ljust(36) + "// PigmentLook.uniform(): gamma, omega, mean deposit, log(rho / ref)")
    return "\n".join(lines) + "\n"


def generate(trace: Callable[[], Any]) -> str:
    """The GLSL functions that `trace()` calls (`diffwash._xp.shader_function`s), dependencies first."""
    with glsl_session() as session:
        trace()
    return "\n".join(session.functions.values())


def _floats(*names: str) -> list[Expr]:
    return [Expr(n, 1, atom=True) for n in names]


def glsl_paper() -> str:
    """`look_pigment_factor(h, pigment)` (with `look_deposit`), `look_unevenness_factor(nt, nd)` and
    `look_paper_relief(rgb, shade)`: `diffwash.look`'s functions, traced (no uniform declarations)."""
    look, pigments = look_symbols()
    h, nt, nd, shade = _floats("h", "turbulence_noise", "dispersion_noise", "shade")
    rgb = Expr("rgb", 3, atom=True)
    return "// ---- Pigment on paper (diffwash/look/_paper.py, traced) ------------------------------------------\n" + generate(
        lambda: (wl.pigment_factor(h, pigments.wash, look.granulation, look.density),
                 wl.unevenness_factor(nt, nd, look.turbulence, look.dispersion), wl.paper_shading(rgb, shade, look.paper_shading))
    )  # fmt: skip


def glsl_strokes() -> str:
    """`look_stroke_factor(stroke)`: `diffwash.look.stroke_factor`, traced (the stroke value is a vertex attribute)."""
    look, _ = look_symbols()
    (stroke,) = _floats("stroke")
    return generate(lambda: wl.stroke_factor(stroke, look.strokes))


def glsl_edge_passes(factor: int = wl.EDGE_DOWNSAMPLE, radius: int = wl.EDGE_RADIUS) -> dict[str, str]:
    """Fragment shader bodies of the three low-resolution passes (no `#version` line).

    - `"downsample"`: `look_source` (full resolution, `.rg` = wash, unlit)
      -> the mean of each `factor x factor` block;
    - `"blur_rows"`, `"blur_columns"`: `look_source` -> blurred along x, then y,
      with `uniform float look_edge_weights[radius + 1]` (weights of offsets
      0..radius, from `gaussian_weights_np(width / factor)`).

    Each writes `vec4(wash, unlit, 0, 0)` to `look_out` and is drawn as a
    full-screen triangle at the low resolution.
    """
    f = int(factor)
    down = f"""\
uniform sampler2D look_source;   // full resolution: .r wash, .g unlit
layout(location = 0) out vec4 look_out;

void main() {{
    ivec2 base = ivec2(gl_FragCoord.xy) * {f};
    ivec2 last = textureSize(look_source, 0) - 1;
    vec2 acc = vec2(0.0);
    for (int dy = 0; dy < {f}; ++dy)
        for (int dx = 0; dx < {f}; ++dx)
            acc += texelFetch(look_source, min(base + ivec2(dx, dy), last), 0).rg;
    look_out = vec4(acc * {float_literal(1.0 / (f * f))}, 0.0, 0.0);
}}
"""

    def blur_pass(axis: str) -> str:
        step = "ivec2(k, 0)" if axis == "x" else "ivec2(0, k)"
        return f"""\
uniform sampler2D look_source;   // low resolution: .r wash, .g unlit
uniform float look_edge_weights[{radius + 1}];   // Gaussian weights of offsets 0..{radius}
layout(location = 0) out vec4 look_out;

void main() {{
    ivec2 p = ivec2(gl_FragCoord.xy);
    ivec2 last = textureSize(look_source, 0) - 1;
    vec2 acc = vec2(0.0);
    for (int i = 0; i <= {2 * radius}; ++i) {{
        int k = i - {radius};
        acc += look_edge_weights[abs(k)] * texelFetch(look_source, clamp(p + {step}, ivec2(0), last), 0).rg;
    }}
    look_out = vec4(acc, 0.0, 0.0);
}}
"""

    return {"downsample": down, "blur_rows": blur_pass("x"), "blur_columns": blur_pass("y")}


def _edge_mean(factor: int) -> str:
    return f"""\
// ---- Edge darkening: the local mean (diffwash/look/_edges.py: local_mean) -------------------------
uniform sampler2D look_edge_blurred;   // low resolution (1/{int(factor)}): blurred wash and unlit, linear filtering

// Gaussian neighbourhood mean of (wash, unlit) at the full-resolution pixel `pixel` (column, row of
// the blurred texture's own orientation): a bilinear sample at low-resolution coordinate (x + 0.5) / f - 0.5.
vec2 look_edge_mean(ivec2 pixel) {{
    vec2 size = vec2(textureSize(look_edge_blurred, 0));
    vec2 uv = (vec2(pixel) + 0.5) / ({float_literal(float(factor))} * size);
    return texture(look_edge_blurred, uv).rg;
}}
"""


def glsl_edge_darkening(factor: int = wl.EDGE_DOWNSAMPLE) -> str:
    """`look_edge_mean(pixel)` (the bilinear sample of `look_edge_blurred` at a full-resolution pixel) and
    `look_edge_darken(t, mean)` (`diffwash.look.edge_darken`, traced; one glaze at a time)."""
    look, _ = look_symbols()
    t, mean = _floats("t", "mean")
    return _edge_mean(factor) + "\n" + generate(lambda: wl.edge_darken(t, mean, look.edge_darkening))


def glsl_shadow(taps: int = wl.SHADOW_TAPS) -> str:
    """GLSL of `shadow` (`taps^2` `texelFetch`es of a float depth texture; the same filter and comparison).

    Uniforms: `look_shadow_map` (the depth map as OpenGL renders it: row 0 at
    `y_ndc = -1`), `look_light_view_projection`, `look_shadow_normal_offset`;
    it reads `look_shadow_bias` (`look_declarations`).
    """
    if taps not in (2, 3):
        raise ValueError(f"taps must be 2 or 3, got {taps}")
    if taps == 2:
        filt = """\
    vec2 q = (ndc.xy + 1.0) * 0.5 * vec2(size) - 0.5;   // one bilinear tap
    vec2 k0 = floor(q);
    vec2 g = q - k0;
    float wx[2] = float[2](1.0 - g.x, g.x);
    float wy[2] = float[2](1.0 - g.y, g.y);"""
    else:
        filt = """\
    vec2 q = (ndc.xy + 1.0) * 0.5 * vec2(size) - 1.0;   // tent: bilinear taps at +-1/2 texel
    vec2 k0 = floor(q);
    vec2 g = q - k0;
    float wx[3] = float[3]((1.0 - g.x) * 0.5, 0.5, g.x * 0.5);
    float wy[3] = float[3]((1.0 - g.y) * 0.5, 0.5, g.y * 0.5);"""
    return f"""\
// ---- Self-shadowing (diffwash/look/_shadow.py: shadow) --------------------------------------------------
uniform sampler2D look_shadow_map;          // light-space depth (z_ndc + 1) / 2, nearest filtering
uniform mat4 look_light_view_projection;    // orthographic, fits the mesh (light_view_projection)
uniform float look_shadow_normal_offset;    // world units along the normal

// 1 where the world point P (unit normal N) is hidden from the light, 0 where lit:
// {taps}x{taps} texels of percentage-closer comparisons.
float look_shadow_factor(vec3 P, vec3 N) {{
    vec3 ndc = (look_light_view_projection * vec4(P + look_shadow_normal_offset * N, 1.0)).xyz;
    float d = (ndc.z + 1.0) * 0.5 - look_shadow_bias;
    ivec2 size = textureSize(look_shadow_map, 0);
{filt}
    ivec2 base = ivec2(k0);
    float lit = 0.0;
    for (int i = 0; i < {taps}; ++i)
        for (int j = 0; j < {taps}; ++j) {{
            ivec2 t = clamp(base + ivec2(j, i), ivec2(0), size - 1);
            lit += wy[i] * wx[j] * (d <= texelFetch(look_shadow_map, t, 0).r ? 1.0 : 0.0);
        }}
    return 1.0 - lit;
}}
"""


def glsl_depth_pass() -> tuple[str, str]:
    """Vertex and fragment shader bodies of the light-space depth pass (no `#version` line).

    Draw the mesh with `look_light_view_projection` into a depth attachment
    (or a float colour target: the fragment shader also writes the depth to
    `look_depth`), cleared to 1, depth test `LESS`.
    """
    vert = """\
layout(location = 0) in vec3 position;      // object space (= world: the model matrix is the identity)
uniform mat4 look_light_view_projection;
void main() {
    gl_Position = look_light_view_projection * vec4(position, 1.0);
}
"""
    frag = """\
layout(location = 0) out vec4 look_depth;
void main() {
    look_depth = vec4(gl_FragCoord.z, 0.0, 0.0, 1.0);
}
"""
    return vert, frag


def glsl_hatching(tones: int = wl.TONES, levels: int = wl.TAM_LEVELS, size: int = 256) -> str:
    """GLSL of `hatch_ink_at`: the ink at tone `tau` from the map's atlas (`tam_atlas`), triplanar, explicit LOD.

    Uniforms: `look_tam` (the atlas, RG, REPEAT, LINEAR_MIPMAP_LINEAR, levels
    0..levels-1), `look_hatch_scale` (texels of level 0 per object unit).
    `float look_hatch_ink(P, N, pixel_size, tau)`: three fetches, one per
    projection, each reading the two tones around `tau`.
    """
    pad = _hatching.atlas_pad(levels)
    tile = size + 2 * pad
    return f"""\
// ---- Hatching: a tonal art map (diffwash/look/_hatching.py, after Praun et al. 2001) ---------------
uniform sampler2D look_tam;         // tam_atlas: {tones} tiles of {size} + 2 x {pad} rows (level 0), tile k = tones k, k + 1 (RG)
uniform float look_hatch_scale;     // texels of level 0 per object unit

// The map's ink at tone tau at object-space point P (normal N), for a pixel covering pixel_size object
// units: triplanar projection, explicit level of detail; tone 0 is blank paper.
float look_hatch_ink(vec3 P, vec3 N, float pixel_size, float tau) {{
    float x = pixel_size * look_hatch_scale;
    float lod = x > 0.0 ? clamp(log2(x), 0.0, {float_literal(levels - 1)}) : 0.0;
    vec3 a = abs(N) * abs(N);
    a = a * a;                        // |N|^{_hatching._TRIPLANAR_SHARPNESS:g}
    a /= max(a.x + a.y + a.z, 1e-12);
    vec3 q = P * (look_hatch_scale / {float_literal(size)});   // texture coordinates: level 0 is {size} texels
    float t = clamp(tau, 0.0, 1.0) * {float_literal(tones)};
    float k = clamp(floor(t), 0.0, {float_literal(tones - 1)});
    float g = t - k;
    // The rows of tile k: the same fraction of the atlas at every level (the padding halves with the tile).
    vec3 v = (k * {float_literal(tile)} + {float_literal(pad)} + fract(vec3(q.z, q.x, q.y)) * {float_literal(size)}) / {float_literal(tones * tile)};
    vec2 s = a.x * textureLod(look_tam, vec2(q.y, v.x), lod).rg + a.y * textureLod(look_tam, vec2(q.z, v.y), lod).rg
           + a.z * textureLod(look_tam, vec2(q.x, v.z), lod).rg;
    return (1.0 - g) * s.x + g * s.y;
}}
"""


def glsl_mix_lut() -> str:
    """GLSL of `diffwash.look.lookup_mix_lut`: a `sampler3D` (linear filtering, clamp to edge) at texel centres.

    Uniforms `look_mix_lut` (texture width = wash, height = unlit, depth =
    mix; slice 0 = mix 0, row 0 = unlit 0 uploaded first), `lut_wash_max`,
    `lut_unlit_max` (as for the 2D LUT).
    """
    return """\
// ---- More than one shade: the 3D LUT over (wash, unlit, mix) (diffwash/look/_mix.py) ---------------
uniform sampler3D look_mix_lut;   // linear colour; x = wash, y = unlit, z = mix
uniform float lut_wash_max;
uniform float lut_unlit_max;

vec3 look_mix_colour(float wash, float unlit, float mix_) {
    vec3 size = vec3(textureSize(look_mix_lut, 0));
    vec3 t = vec3(lut_wash_max > 0.0 ? wash / lut_wash_max : 0.0,
                  lut_unlit_max > 0.0 ? unlit / lut_unlit_max : 0.0,
                  mix_);
    vec3 uvw = (clamp(t, 0.0, 1.0) * (size - 1.0) + 0.5) / size;
    return texture(look_mix_lut, uvw).rgb;
}
"""


def _surface(hatching: bool) -> str:
    """`look_surface`: `diffwash.look.surface_terms` traced, its hatching reading `look_hatch_ink`."""
    look, _ = look_symbols()
    t, P, N = Expr("t", 2, atom=True), Expr("P", 3, atom=True), Expr("N", 3, atom=True)
    unlit_max, shadow, pixel_size = _floats("unlit_max", "shadow", "pixel_size")
    hatch = (lambda tau: GLSL.call("look_hatch_ink", 1, P, N, pixel_size, tau)) if hatching else None

    def body(t, unlit_max, shadow, P, N, pixel_size):
        return GLSL.stack(wl.surface_terms(t[0], t[1], look, unlit_max=unlit_max, shadow=shadow, hatch=hatch))

    params = [("t", "vec2"), ("unlit_max", "float"), ("shadow", "float"), ("P", "vec3"), ("N", "vec3"), ("pixel_size", "float")]
    with glsl_session():
        return trace_function("look_surface", body, params, "vec2")


def glsl_surface(*, tam_levels: int = wl.TAM_LEVELS, tam_size: int = 256) -> str:
    """The geometry pass's look: the shadow and hatching lookups, and `diffwash.look.surface_terms` traced.

    `vec2 look_surface(vec2 t, float unlit_max, float shadow, vec3 P, vec3 N, float pixel_size)` (the
    point, its normal and footprint for the hatching, read only where `LOOK_HATCHING` is 1, the default);
    the pass writes `vec4(look_surface(...), mix, stroke)` to the G-buffer. With `look_declarations`
    (`tam_levels`, `tam_size`: the tonal art map's levels and level-0 side, as `glsl_hatching`).
    """
    return (
        look_declarations()
        + "\n"
        + glsl_shadow()
        + "\n"
        + glsl_hatching(levels=tam_levels, size=tam_size)
        + "\n// ---- Surface terms (diffwash/look/_look.py: surface_terms, traced) -------------------------------\n"
        + "#ifndef LOOK_HATCHING\n#define LOOK_HATCHING 1\n#endif\n#if LOOK_HATCHING\n"
        + _surface(True)
        + "#else\n"
        + _surface(False)
        + "#endif\n"
    )


def _screen(name: str) -> str:
    """The screen tile's channel `name` (`diffwash.look.CHANNELS`) as the final pass reads it: `s0.x` ... `s1.y`."""
    i = wl.CHANNELS.index(name)
    return f"s{i // 4}.{'xyzw'[i % 4]}"


def _final_functions() -> str:
    """`look_pixel_terms`, `look_paper_shading` and `srgb_encode`, traced in one session (each function once)."""
    look, pigments = look_symbols()
    names = ["wash", "unlit", "mean_wash", "mean_unlit", "mix_proportion", "stroke", "paper", "turbulence_wash", "dispersion_wash",
             "turbulence_unlit", "dispersion_unlit"]  # fmt: skip
    args = _floats(*names)
    rgb, shade = Expr("rgb", 3, atom=True), Expr("shade", 1, atom=True)
    return generate(lambda: (wl.pixel_terms(*args, look, pigments), wl.paper_shading(rgb, shade, look.paper_shading),
                             colorimetry.srgb_encode(rgb)))  # fmt: skip


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
    reduction (`edge_downsample`). The per-pixel arithmetic is
    `diffwash.look.pixel_terms`, `paper_shading` and the sRGB curve, traced.
    """
    factor = wl.edge_downsample(height)
    if colour != "mix":
        raise ValueError("the final pass glazes with the 3D mix LUT (a 2D LUT is the mix LUT with one slice pair)")
    screen = ", ".join(_screen(c) for c in ("paper", "turbulence_wash", "dispersion_wash", "turbulence_unlit", "dispersion_unlit"))
    return (
        """\
#ifndef LOOK_OUTPUT_SRGB
#define LOOK_OUTPUT_SRGB 0
#endif
uniform sampler2D look_gbuffer;    // wash, unlit, mix, stroke (full resolution)
uniform sampler2D look_screen0;    // the screen tile's channels 0-3 (diffwash.look.CHANNELS)
uniform sampler2D look_screen1;    // the screen tile's channels 4-5
uniform int look_flip_rows;        // 1: the G-buffer's row 0 is the image's bottom row
uniform int look_rows;             // image height in pixels
layout(location = 0) out vec4 look_colour;
"""
        + look_declarations()
        + "\n"
        + _edge_mean(factor)
        + "\n"
        + glsl_mix_lut()
        + "\n// ---- The image terms, the paper's shading and sRGB (diffwash.look, diffwash.colorimetry; traced) ---\n"
        + _final_functions()
        + f"""
void main() {{
    ivec2 frag = ivec2(gl_FragCoord.xy);
    vec4 g = texelFetch(look_gbuffer, frag, 0);
    int row = look_flip_rows != 0 ? look_rows - 1 - frag.y : frag.y;
    ivec2 tile = textureSize(look_screen0, 0);
    ivec2 tc = ivec2(frag.x % tile.x, row % tile.y);
    vec4 s0 = texelFetch(look_screen0, tc, 0);
    vec4 s1 = texelFetch(look_screen1, tc, 0);
    vec2 mean = look_edge_mean(frag);
    float w, u;
    look_pixel_terms(g.r, g.g, mean.x, mean.y, g.b, g.a, {screen}, w, u);
    vec3 c = look_paper_relief(look_mix_colour(w, u, g.b), {_screen("shade")});
#if LOOK_OUTPUT_SRGB
    c = srgb_encode(clamp(c, 0.0, 1.0));
#endif
    look_colour = vec4(c, 1.0);
}}
"""
    )


#: The exported shaders' vertex inputs and matrices (as in `diffwash.shader_sources`).
_VERTEX_INPUTS = """\
layout(location = 0) in vec3 position;
layout(location = 1) in vec3 normal;
uniform mat4 model;
uniform mat3 normal_matrix;
uniform mat4 view_projection;
"""


def geometry_sources(target: str, hatching: bool, shadow: str = "vertex") -> tuple[str, str]:
    """The look's geometry pass for `target`: the model's thicknesses, shadow (and hatching), mix and stroke into the G-buffer.

    `shadow="vertex"` (what the preview, the viewer and export draw): the shadow lookup runs in the vertex
    shader and is interpolated, as `diffwash.render` does (`_watercolour.vertex_shadow`); `"pixel"`: per
    fragment (for measurements). Returns the vertex and fragment shader.
    """
    head = header(target)
    model = functions_source(target, colour="km")  # the thickness model (the colour is the look's)
    vert = head + f"#define LOOK_VERTEX_SHADOW {int(shadow == 'vertex')}\n" + _VERTEX_INPUTS + look_declarations() + glsl_shadow() + """\
layout(location = 2) in float mix_in;
layout(location = 3) in float stroke_in;
out vec3 world_position;
out vec3 world_normal;
out float v_mix;
out float v_stroke;
out float v_shadow;
void main() {
    vec4 world = model * vec4(position, 1.0);
    world_position = world.xyz;
    world_normal = normal_matrix * normal;
#if LOOK_VERTEX_SHADOW
    v_shadow = look_shadow_factor(world.xyz, normalize(world_normal));
#else
    v_shadow = 0.0;
#endif
    v_mix = mix_in;
    v_stroke = stroke_in;
    gl_Position = view_projection * world;
}
"""
    frag = head + f"#define LOOK_HATCHING {int(hatching)}\n#define LOOK_VERTEX_SHADOW {int(shadow == 'vertex')}\n" + model + glsl_surface() + """\
in float v_shadow;
in vec3 world_position;
in vec3 world_normal;
in float v_mix;
in float v_stroke;
uniform bool two_sided;
uniform vec3 eye_forward;
uniform float look_pixel_scale;   // 2 tan(fov_y / 2) / height: a pixel's size per unit of eye depth
layout(location = 0) out vec4 gbuffer;
void main() {
    vec3 N = safe_normalize(world_normal);
    if (two_sided && !gl_FrontFacing) N = -N;
    vec3 L = safe_normalize(light_direction);
    vec3 V = safe_normalize(eye - world_position);
    vec2 t = watercolour_thickness(N, L, V);
#if LOOK_VERTEX_SHADOW
    float shadow = v_shadow;
#else
    float shadow = look_shadow_factor(world_position, N);
#endif
    float pixel_size = dot(world_position - eye, eye_forward) * look_pixel_scale;
    gbuffer = vec4(look_surface(t, k_unlit, shadow, world_position, N, pixel_size), v_mix, v_stroke);
}
"""
    return vert, frag


def _glaze_b(args: Any, w: Any, u: Any, m: Any) -> Any:
    p, wash_b, unlit_b = args
    return wl.glaze_mix(p, wash_b, unlit_b, w, u, m)


def mix_lut_range(p: Any) -> tuple[float, float]:
    """The wash and unlit thickness the look's 3D mix LUT covers for shading `Params` `p` (`MIX_LUT_RANGE` times
    the 2D LUT's)."""
    return MIX_LUT_RANGE * float(p.wash_max), MIX_LUT_RANGE * float(p.unlit_max)


def mix_lut(scene: Any, p: Any) -> tuple[np.ndarray, float, float]:
    """The look's 3D mix LUT for shading `Params` `p` (float32, `look.bake_mix_lut`'s layout) and its wash and unlit
    ranges (`mix_lut_range`). One function for every call, so a widget's re-bake reuses its compiled program."""
    wc = scene.watercolour
    wash_max, unlit_max = mix_lut_range(p)
    wash_b = p.wash if wc.wash_b is None else wc.wash_b
    unlit_b = p.unlit if wc.unlit_b is None else wc.unlit_b
    table = wl.bake_mix_lut(_glaze_b, (p, wash_b, unlit_b), MIX_LUT_SIZE, wash_max=wash_max, unlit_max=unlit_max)
    return np.ascontiguousarray(np.asarray(table, np.float32)), wash_max, unlit_max


def look_textures(scene: Any, p: Any) -> tuple[dict[str, list[np.ndarray]], float, float]:
    """The look's input textures, each a list of levels (the mix LUT, the screen tile in two, the tonal art
    map's atlas), and the mix LUT's wash and unlit ranges: what `LookFrame` uploads and export writes."""
    wc = scene.watercolour
    table, wash_max, unlit_max = mix_lut(scene, p)
    c = np.asarray(wc.screen, np.float32)
    out = {
        "mix_lut": [table],
        "screen0": [np.ascontiguousarray(c[..., :4])],
        "screen1": [np.ascontiguousarray(c[..., 4:6])],
    }
    if wc.tam is not None:
        out["tam"] = wl.tam_atlas(wc.tam)
    return out, wash_max, unlit_max


def look_frame_uniforms(scene: Any, p: Any, wash_max: float, unlit_max: float, size: tuple[int, int] | None = None) -> dict[str, Any]:
    """Every uniform of the look's passes for a `size = (width, height)` frame (default: the scene's image),
    as JSON-ready values (matrices as row-major nested lists): what `LookFrame` sets and export writes."""
    wc = scene.watercolour
    W, H = size or (scene.width, scene.height)
    u = {**uniform_values(scene, p, aspect=W / H), **wl.look_uniforms(wc.look, wc.pigments, height=H)}
    cam = scene.camera
    forward = np.asarray(cam.target, np.float64) - np.asarray(cam.eye, np.float64)
    light_vp = np.asarray(wl.light_view_projection(np.asarray(scene.mesh.vertices), np.asarray(p.light)), np.float64)
    u.update(
        eye_forward=(forward / np.linalg.norm(forward)).tolist(),
        look_pixel_scale=float(2 * np.tan(np.radians(float(cam.fov_y)) / 2) / H),
        look_light_view_projection=light_vp.tolist(),
        look_shadow_normal_offset=wl.normal_offset(light_vp.astype(np.float32)),
        lut_wash_max=wash_max,
        lut_unlit_max=unlit_max,
        look_flip_rows=1,
        look_rows=H,
    )
    if not wc.shadow:
        u["look_shadow"] = 0.0
    if wc.tam is not None:
        u["look_hatch_scale"] = float(wc.hatch_scale)
    return {k: [float(x) for x in v] if isinstance(v, tuple) else v for k, v in u.items()}
