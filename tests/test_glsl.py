"""The exported GLSL, run in real OpenGL (Mesa EGL), against diffwash.shading.

Harness shaders include the very functions the exported shaders use
(`functions_source`) and evaluate them per fragment on inputs given in float
textures, so the formulas are checked on arbitrary (N, L, V) and thicknesses,
edge cases included, independently of rasterization.
"""

import jax.numpy as jnp
import moderngl
import numpy as np
import pytest

import diffwash
from diffwash import colorimetry, lut, shading
from diffwash._glsl import TARGETS, functions_source, shader_sources
from diffwash.pigments import Pigment
from diffwash.shading import Params

_QUAD = """#version 330 core
void main() {
    vec2 p = vec2((gl_VertexID << 1) & 2, gl_VertexID & 2);
    gl_Position = vec4(p * 2.0 - 1.0, 0.0, 1.0);
}
"""

_THICKNESS_MAIN = """
uniform sampler2D in_N, in_L, in_V;
layout(location = 0) out vec4 result;
void main() {
    ivec2 p = ivec2(gl_FragCoord.xy);
    vec3 N = texelFetch(in_N, p, 0).xyz, L = texelFetch(in_L, p, 0).xyz, V = texelFetch(in_V, p, 0).xyz;
    result = vec4(watercolour_thickness(N, L, V), 0.0, 1.0);
}
"""

_COLOUR_MAIN = """
uniform sampler2D in_thickness;
layout(location = 0) out vec4 result;
void main() {
    vec2 t = texelFetch(in_thickness, ivec2(gl_FragCoord.xy), 0).xy;
    result = vec4(watercolour_colour(t), 1.0);
}
"""

W = 64  # harness images are W x H texels, one case per texel


@pytest.fixture(scope="module")
def ctx():
    c = moderngl.create_context(standalone=True, backend="egl", require=330)
    yield c
    c.release()


def _texture(ctx, data, components=3):
    h, w = data.shape[:2]
    t = ctx.texture((w, h), components, np.ascontiguousarray(data, np.float32).tobytes(), dtype="f4")
    t.filter = (moderngl.NEAREST, moderngl.NEAREST)
    return t


def _run(ctx, frag_body, inputs, uniforms, shape, textures=()):
    """Draw a full-screen pass of `frag_body`; `inputs` name -> (h, w, c) arrays; returns (h, w, 4) float32."""
    prog = ctx.program(vertex_shader=_QUAD, fragment_shader="#version 330 core\n" + frag_body)
    h, w = shape
    units = []
    for unit, (name, data) in enumerate(inputs.items()):
        tex = _texture(ctx, data, data.shape[2])
        tex.use(unit)
        prog[name].value = unit
        units.append(tex)
    for unit, (name, tex) in enumerate(textures, start=len(units)):
        tex.use(unit)
        prog[name].value = unit
    for name, v in uniforms.items():
        if name in prog:
            prog[name].value = v
    out = ctx.texture((w, h), 4, dtype="f4")
    fbo = ctx.framebuffer(color_attachments=[out])
    fbo.use()
    ctx.viewport = (0, 0, w, h)
    ctx.disable(moderngl.CULL_FACE | moderngl.DEPTH_TEST)
    vao = ctx.vertex_array(prog, [])
    vao.render(moderngl.TRIANGLES, vertices=3)
    result = np.frombuffer(fbo.read(components=4, dtype="f4"), np.float32).reshape(h, w, 4)
    for obj in (vao, fbo, out, prog, *units):
        obj.release()
    return result


def _unit(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _directions(seed, n):
    rng = np.random.default_rng(seed)
    N = _unit(rng.normal(size=(n, 3)))
    L = _unit(rng.normal(size=(n, 3)))
    V = _unit(rng.normal(size=(n, 3)))
    # Edge cases: L = -V (H = 0), L = N, L = -N, V = N = L, N perpendicular to L and to V, grazing.
    e = np.array([0.0, 0.0, 1.0])
    x = np.array([1.0, 0.0, 0.0])
    special = [(e, x, -x), (e, e, e), (e, -e, e), (e, x, x), (x, e, e), (e, _unit(x + 1e-4 * e), e), (e, e, _unit(x + 1e-3 * e))]
    for i, (n_, l_, v_) in enumerate(special):
        N[i], L[i], V[i] = n_, l_, v_
    return N, L, V


PARAM_SETS = [
    dict(),
    dict(shininess=0.0, k_wash=1.7, k_specular=0.6),
    dict(shininess=1.0, bias=0.01, gain=0.99, wash_reduction=1.0, k_unlit=2.5),
    dict(shininess=200.0, bias=0.99, gain=0.01, wash_reduction=0.4),
    dict(shininess=7.5, bias=0.3, gain=0.7, wash_reduction=0.25, k_unlit=0.0),
]


def _params(**kw):
    base = dict(wash=diffwash.pigments.load("cadmium yellow"), unlit=diffwash.pigments.load("phthalo green"))
    return Params(**{**base, **kw})


def _model_uniforms(p):
    return {k: float(getattr(p, k)) for k in ("k_wash", "k_specular", "shininess", "k_unlit", "gain", "bias", "wash_reduction")}


@pytest.mark.parametrize("i", range(len(PARAM_SETS)))
def test_thickness_formulas_match_shading(ctx, i):
    p = _params(**PARAM_SETS[i])
    N, L, V = _directions(i, W * W)
    inputs = {name: a.reshape(W, W, 3) for name, a in (("in_N", N), ("in_L", L), ("in_V", V))}
    got = _run(ctx, functions_source("glsl330") + _THICKNESS_MAIN, inputs, _model_uniforms(p), (W, W))
    got = got[..., :2].reshape(-1, 2)
    wash, unlit = shading.thicknesses(N, L, V, p)
    expected = np.stack([np.asarray(wash), np.asarray(unlit)], axis=-1)
    assert np.all(np.isfinite(got))
    scale = max(float(p.wash_max), float(p.unlit_max), 1.0)
    np.testing.assert_allclose(got, expected, atol=3e-5 * scale, rtol=0)


def _thickness_grid(p, n, seed):
    rng = np.random.default_rng(seed)
    t = np.stack([rng.uniform(-0.1, 1.1, n) * float(p.wash_max), rng.uniform(-0.1, 1.1, n) * float(p.unlit_max)], -1)
    t[:4] = [[0, 0], [float(p.wash_max), 0], [0, float(p.unlit_max)], [float(p.wash_max), float(p.unlit_max)]]
    return t


def _expected_colour(p, t):
    clamped = np.clip(t, 0, [float(p.wash_max), float(p.unlit_max)])
    return np.asarray(shading.glaze(p, clamped[:, 0], clamped[:, 1]))


def test_km_per_fragment_matches_glaze(ctx):
    for i, kw in enumerate(PARAM_SETS[:3]):
        p = _params(**kw)
        t = np.abs(_thickness_grid(p, W * W, i))  # the KM shader does not clamp to a LUT range
        uniforms = {**_model_uniforms(p), "paper": tuple(np.asarray(p.paper)), "wash_K": tuple(p.wash.K), "wash_S": tuple(p.wash.S)}
        uniforms.update({"unlit_K": tuple(p.unlit.K), "unlit_S": tuple(p.unlit.S)})
        src = functions_source("glsl330", colour="km", output_srgb=False) + _COLOUR_MAIN
        got = _run(ctx, src, {"in_thickness": t.reshape(W, W, 2)}, uniforms, (W, W))[..., :3].reshape(-1, 3)
        np.testing.assert_allclose(got, np.asarray(shading.glaze(p, t[:, 0], t[:, 1])), atol=3e-6, rtol=0)


def test_km_per_fragment_extreme_pigments(ctx):
    """S = 0, K = 0 and very thick layers stay finite and right in float32 GLSL."""
    p = Params(
        wash=Pigment(K=np.array([0.0, 2.0, 40.0]), S=np.array([3.0, 0.0, 0.5]), name="w"),
        unlit=Pigment(K=np.array([0.0, 0.0, 9.0]), S=np.array([0.0, 1.0, 0.0]), name="u"),
        k_wash=30.0,
        k_unlit=30.0,
    )
    t = np.abs(_thickness_grid(p, W * W, 7))
    uniforms = {"paper": tuple(np.asarray(p.paper)), "wash_K": tuple(p.wash.K), "wash_S": tuple(p.wash.S)}
    uniforms.update({"unlit_K": tuple(p.unlit.K), "unlit_S": tuple(p.unlit.S)})
    got = _run(ctx, functions_source("glsl330", colour="km", output_srgb=False) + _COLOUR_MAIN, {"in_thickness": t.reshape(W, W, 2)}, uniforms, (W, W))
    assert np.all(np.isfinite(got))
    np.testing.assert_allclose(got[..., :3].reshape(-1, 3), np.asarray(shading.glaze(p, t[:, 0], t[:, 1])), atol=5e-6, rtol=0)


def _lut_textures(ctx, values, srgb):
    """Upload a LUT the way an engine does: top image row first, linear filtering, clamp to edge."""
    data = colorimetry.to_display(values) if srgb else values
    texs = []
    for k in range(values.shape[-1] // 3):
        t = _texture(ctx, data[..., 3 * k : 3 * k + 3])
        t.filter = (moderngl.LINEAR, moderngl.LINEAR)
        t.repeat_x = t.repeat_y = False
        texs.append(t)
    return texs


@pytest.mark.parametrize("kind, srgb", [("colour", True), ("colour", False), ("rt", True)])
def test_lut_lookup_matches_glaze(ctx, kind, srgb):
    """The 256^2 LUT sampled by the exported lookup (half-texel addressing, row order) is the glaze."""
    p = _params(**PARAM_SETS[2])
    table = lut.bake(p, 256, kind=kind)
    t = _thickness_grid(p, W * W, 3)
    colour = "lut" if kind == "colour" else "lut-rt"
    names = ["lut"] if kind == "colour" else ["lut_reflectance", "lut_transmittance"]
    texs = _lut_textures(ctx, np.asarray(table.values, np.float64), srgb)
    uniforms = {"lut_wash_max": table.wash_max, "lut_unlit_max": table.unlit_max, "paper": tuple(np.asarray(p.paper))}
    src = functions_source("glsl330", colour=colour, lut_srgb=srgb, output_srgb=False) + _COLOUR_MAIN
    got = _run(ctx, src, {"in_thickness": t.reshape(W, W, 2)}, uniforms, (W, W), textures=list(zip(names, texs)))
    got = got[..., :3].reshape(-1, 3)
    np.testing.assert_allclose(got, _expected_colour(p, t), atol=4e-4, rtol=0)
    # Displayed in 8 bits, the LUT and the exact glaze are the same image.
    enc = lambda c: np.round(colorimetry.to_display(c) * 255)  # noqa: E731
    assert np.abs(enc(got) - enc(_expected_colour(p, t))).max() <= 1
    for tex in texs:
        tex.release()


def test_lut_addressing_hits_texel_centres(ctx):
    """On a tiny random table, grid thicknesses return the stored samples exactly: this fails with
    uv = t (no half-texel offset) or with the rows upside down."""
    rng = np.random.default_rng(0)
    values = rng.uniform(0, 1, (4, 5, 3))  # M = 4 rows (unlit), N = 5 columns (wash)
    table = lut.Lut(values=values.astype(np.float32), wash_max=2.0, unlit_max=3.0)
    i, j = np.meshgrid(np.arange(5), np.arange(4))
    t = np.stack([i / 4 * 2.0, j / 3 * 3.0], -1).reshape(-1, 2)
    # ... and midpoints return the bilinear mean (the GPU's 8-bit filter weights allow ~1/256).
    mid = np.stack([(np.arange(4) + 0.5) / 4 * 2.0, np.full(4, 1.5)], -1)
    t = np.concatenate([t, mid])
    texs = _lut_textures(ctx, values, srgb=False)
    src = functions_source("glsl330", colour="lut", lut_srgb=False, output_srgb=False) + _COLOUR_MAIN
    got = _run(ctx, src, {"in_thickness": t.reshape(1, -1, 2)}, {"lut_wash_max": 2.0, "lut_unlit_max": 3.0}, (1, len(t)), textures=[("lut", texs[0])])
    got = got[0, :, :3]
    np.testing.assert_allclose(got[:20], values.reshape(-1, 3), atol=1e-6)
    np.testing.assert_allclose(got[20:], table.lookup(mid[:, 0], mid[:, 1]), atol=4e-3)
    # With LUT_FLIP_Y the same table uploaded bottom row first gives the same samples.
    flipped = _lut_textures(ctx, values[::-1].copy(), srgb=False)
    src = functions_source("glsl330", colour="lut", lut_srgb=False, output_srgb=False, flip_y=True) + _COLOUR_MAIN
    got = _run(ctx, src, {"in_thickness": t.reshape(1, -1, 2)}, {"lut_wash_max": 2.0, "lut_unlit_max": 3.0}, (1, len(t)), textures=[("lut", flipped[0])])
    np.testing.assert_allclose(got[0, :20, :3], values.reshape(-1, 3), atol=1e-6)


@pytest.mark.parametrize("target", list(TARGETS))
@pytest.mark.parametrize("shading_mode", ["per-vertex", "per-pixel"])
@pytest.mark.parametrize("colour", ["lut", "lut-rt", "km"])
def test_sources_declare_scene_uniforms(target, shading_mode, colour):
    vert, frag = shader_sources(target, shading_mode, colour=colour)
    both = vert + frag
    assert vert.startswith(TARGETS[target]) and frag.startswith(TARGETS[target])
    for name in ("k_wash", "k_specular", "shininess", "k_unlit", "gain", "bias", "wash_reduction", "light_direction", "eye"):
        assert f"uniform float {name};" in both or f"uniform vec3 {name};" in both
    if colour != "km":
        assert "(clamp(t, 0.0, 1.0) * (size - 1.0) + 0.5) / size" in frag


@pytest.mark.parametrize("shading_mode", ["per-vertex", "per-pixel"])
@pytest.mark.parametrize("colour", ["lut", "lut-rt", "km"])
def test_glsl330_programs_link(ctx, shading_mode, colour):
    vert, frag = shader_sources("glsl330", shading_mode, colour=colour)
    prog = ctx.program(vertex_shader=vert, fragment_shader=frag)
    assert "light_direction" in prog and "view_projection" in prog
    prog.release()


def test_bad_options():
    with pytest.raises(diffwash.DiffwashError, match="target"):
        shader_sources("hlsl")
    with pytest.raises(diffwash.DiffwashError, match="shading"):
        shader_sources("glsl330", "per-face")


def test_jnp_reference_is_float64():
    # The harness tests compare against float64 JAX (conftest enables x64).
    assert jnp.zeros(()).dtype == jnp.float64
