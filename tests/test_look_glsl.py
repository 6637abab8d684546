"""Each look operator's GLSL (traced from diffwash/look by diffwash._look_glsl) run through moderngl (EGL) against its JAX version.

Float textures in and out, so agreement is to float32 rounding (~1e-5), not to 8-bit levels.
"""

import functools

import jax.numpy as jnp
import numpy as np
import pytest

from diffwash import _look_gl as _gl
from diffwash import _look_glsl as G
from diffwash import preview
from diffwash.look import _edges, _hatching, _look, _mix, _paper, _shadow, _textures
from diffwash.pigments import Pigment
from diffwash.shading import Params

H, W = 24, 20  # small, and not multiples of the edge blur's reduction in one direction


@pytest.fixture(scope="module")
def ctx():
    c = preview.create_context()
    yield c
    c.release()


def _rng(seed=0):
    return np.random.default_rng(seed)


PIGMENT = Pigment(K=np.array([0.22, 1.47, 0.57]), S=np.array([0.05, 0.003, 0.03]), density=0.02, staining=5.5, granularity=0.81)
PIGMENT_B = Pigment(K=np.array([0.86, 0.86, 0.06]), S=np.array([0.005, 0.005, 0.09]), density=0.01, staining=3.1, granularity=0.91)


def test_paper_operators(ctx):
    rng = _rng()
    paper = _textures.procedural_paper((32, 32), seed=1)
    look = _paper.pigment_look(PIGMENT_B, paper)
    inputs = np.stack([rng.uniform(0, 1, (H, W)), rng.normal(0, 1, (H, W)), rng.normal(0, 1, (H, W)), rng.normal(0, 0.3, (H, W))], -1)
    k = {"look_granulation": 0.7, "look_density": 0.4, "look_turbulence": 0.2, "look_dispersion": 0.1, "look_paper_shading": 0.3}
    frag = (
        "uniform sampler2D src; uniform vec4 pig; layout(location = 0) out vec4 o;\n"
        + G.look_declarations()
        + G.glsl_paper()
        + """void main() {
    vec4 s = texelFetch(src, ivec2(gl_FragCoord.xy), 0);
    o = vec4(look_pigment_factor(s.x, pig), look_unevenness_factor(s.y, s.z), look_paper_relief(vec3(0.5, 0.25, 1.0), s.w).xz);
}
"""
    )
    out = _gl.run_fullscreen(ctx, frag, (W, H), textures={"src": _gl.texture(ctx, inputs.astype(np.float32))}, uniforms={**k, "pig": look.uniform()})
    x = inputs.astype(np.float32).astype(np.float64)
    want_p = _paper.pigment_factor(x[..., 0], look, 0.7, 0.4)
    want_u = _paper.unevenness_factor(x[..., 1], x[..., 2], 0.2, 0.1)
    want_s = _paper.paper_shading(jnp.broadcast_to(jnp.asarray([0.5, 0.25, 1.0]), (H, W, 3)), x[..., 3], 0.3)
    np.testing.assert_allclose(out[..., 0], want_p, rtol=2e-6, atol=1e-6)
    np.testing.assert_allclose(out[..., 1], want_u, rtol=2e-6, atol=1e-6)
    np.testing.assert_allclose(out[..., 2:], np.asarray(want_s)[..., [0, 2]], rtol=2e-6, atol=1e-6)


def test_edge_passes_match_local_mean_and_darkening(ctx):
    rng = _rng(1)
    t = np.zeros((H, W, 2))
    t[4:18, 3:15] = rng.uniform(0.3, 1.0, (14, 12, 2))  # a wash with edges, and the paper around it
    t = t.astype(np.float32)
    f, R, width, strength = _edges.EDGE_DOWNSAMPLE, _edges.EDGE_RADIUS, 2.5, 1.7
    passes = G.glsl_edge_passes(f, R)
    weights = list(_edges.gaussian_weights_np(width / f, R)[R:])
    src = np.concatenate([t, np.zeros((H, W, 2), np.float32)], -1)
    lw, lh = -(-W // f), -(-H // f)
    low = _gl.run_fullscreen(ctx, passes["downsample"], (lw, lh), textures={"look_source": _gl.texture(ctx, src)})
    np.testing.assert_allclose(low[..., :2], _edges.downsample(t.astype(np.float64), f), rtol=1e-6, atol=1e-7)
    rows = _gl.run_fullscreen(ctx, passes["blur_rows"], (lw, lh), textures={"look_source": _gl.texture(ctx, low)}, uniforms={"look_edge_weights": weights})
    cols = _gl.run_fullscreen(ctx, passes["blur_columns"], (lw, lh), textures={"look_source": _gl.texture(ctx, rows)}, uniforms={"look_edge_weights": weights})
    want_low = _edges.blur(_edges.downsample(t.astype(np.float64), f), width / f, R)
    np.testing.assert_allclose(cols[..., :2], want_low, rtol=1e-5, atol=1e-6)
    frag = (
        "uniform sampler2D thick; layout(location = 0) out vec4 o;\n"
        + G.look_declarations()
        + G.glsl_edge_darkening(f)
        + """void main() {
    ivec2 p = ivec2(gl_FragCoord.xy);
    vec2 m = look_edge_mean(p);
    vec2 t = texelFetch(thick, p, 0).rg;
    o = vec4(m, look_edge_darken(t.x, m.x), look_edge_darken(t.y, m.y));
}
"""
    )
    blurred = _gl.texture(ctx, cols, linear=True)
    out = _gl.run_fullscreen(ctx, frag, (W, H), textures={"look_edge_blurred": blurred, "thick": _gl.texture(ctx, src)}, uniforms={"look_edge_darkening": strength})
    mean = _edges.local_mean(t.astype(np.float64), width, f, R)
    np.testing.assert_allclose(out[..., :2], mean, rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(out[..., 2:], _edges.edge_darkening(t.astype(np.float64), strength, width, factor=f, radius=R), rtol=1e-5, atol=1e-6)


def test_shadow_lookup(ctx):
    rng = _rng(2)
    depth = rng.uniform(0.2, 0.9, (16, 16))
    vertices = rng.uniform(-1, 1, (40, 3))
    vp = np.asarray(_shadow.light_view_projection(vertices, [0.3, 1.0, 0.5]))
    P = rng.uniform(-0.9, 0.9, (H, W, 3))
    N = rng.normal(0, 1, (H, W, 3))
    N /= np.linalg.norm(N, axis=-1, keepdims=True)
    bias, offset = 0.01, 0.02
    frag = (
        "uniform sampler2D pos; uniform sampler2D nrm; layout(location = 0) out vec4 o;\n"
        + G.look_declarations()
        + G.glsl_shadow()
        + "void main() { ivec2 p = ivec2(gl_FragCoord.xy); o = vec4(look_shadow_factor(texelFetch(pos, p, 0).xyz, texelFetch(nrm, p, 0).xyz)); }\n"
    )
    tex = {
        "look_shadow_map": _gl.texture(ctx, depth[::-1].astype(np.float32)),  # OpenGL's row 0 is the light's bottom
        "pos": _gl.texture(ctx, P.astype(np.float32)),
        "nrm": _gl.texture(ctx, N.astype(np.float32)),
    }
    uni = {"look_light_view_projection": vp, "look_shadow_bias": bias, "look_shadow_normal_offset": offset}
    out = _gl.run_fullscreen(ctx, frag, (W, H), textures=tex, uniforms=uni)[..., 0]
    want = _shadow.shadow(depth.astype(np.float32).astype(np.float64), vp.astype(np.float32).astype(np.float64),
                          P.astype(np.float32).astype(np.float64), bias, normals=N.astype(np.float32).astype(np.float64), normal_offset=offset)  # fmt: skip
    assert 0.1 < float(np.mean(np.asarray(want))) < 0.9  # both lit and shadowed points
    # A comparison may flip where a depth is within float32 rounding of the stored one: all but a few agree.
    close = np.abs(out - np.asarray(want)) < 1e-5
    assert close.mean() > 0.98, close.mean()


def test_hatching_ink(ctx):
    # The shader's atlas (one fetch per projection for both tones) against hatch_ink_at (the renderer's
    # reads of the map's own levels), at levels from 0 to past the last and tones across the range.
    rng = _rng(3)
    tam = _hatching.tonal_art_map(size=32, levels=3, seed=2)
    scale = 40.0
    P = rng.uniform(-1, 1, (H, W, 3))
    N = rng.normal(0, 1, (H, W, 3))
    N /= np.linalg.norm(N, axis=-1, keepdims=True)
    pixel = rng.uniform(0.005, 0.2, (H, W))  # lods from 0 to past the last level
    tau = rng.uniform(-0.1, 1.1, (H, W))
    frag = (
        "uniform sampler2D pos; uniform sampler2D nrm; layout(location = 0) out vec4 o0;\n"
        + G.glsl_hatching(levels=3, size=32)
        + """void main() {
    ivec2 p = ivec2(gl_FragCoord.xy);
    vec4 s = texelFetch(pos, p, 0), n = texelFetch(nrm, p, 0);
    o0 = vec4(look_hatch_ink(s.xyz, n.xyz, s.w, n.w));
}
"""
    )
    atlas = _hatching.tam_atlas(tam)
    assert [a.shape for a in atlas] == [(8 * 40, 32, 2), (8 * 20, 16, 2), (8 * 10, 8, 2)]  # each level half the last
    pos = np.concatenate([P, pixel[..., None]], -1).astype(np.float32)
    nrm = np.concatenate([N, tau[..., None]], -1).astype(np.float32)
    tex = {"look_tam": _gl.texture(ctx, atlas[0], repeat=True, mipmaps=atlas[1:]), "pos": _gl.texture(ctx, pos), "nrm": _gl.texture(ctx, nrm)}
    out = _gl.run_fullscreen(ctx, frag, (W, H), textures=tex, uniforms={"look_hatch_scale": scale})[..., 0]
    p64, n64 = pos.astype(np.float64), nrm.astype(np.float64)
    want = _hatching.hatch_ink_at([np.asarray(t, np.float64) for t in tam], p64[..., :3], n64[..., :3], p64[..., 3], scale, n64[..., 3])
    np.testing.assert_allclose(out, want, atol=1e-4)


def test_mix_lut_lookup(ctx):
    rng = _rng(4)
    table = rng.uniform(0, 1, (5, 7, 6, 3)).astype(np.float32)
    wash_max, unlit_max = 1.3, 0.8
    pts = np.stack([rng.uniform(-0.1, 1.5, (H, W)), rng.uniform(-0.1, 1.0, (H, W)), rng.uniform(-0.1, 1.1, (H, W)), np.zeros((H, W))], -1)
    frag = (
        "uniform sampler2D pts; layout(location = 0) out vec4 o;\n"
        + G.glsl_mix_lut()
        + "void main() { vec4 s = texelFetch(pts, ivec2(gl_FragCoord.xy), 0); o = vec4(look_mix_colour(s.x, s.y, s.z), 0.0); }\n"
    )
    tex = {"look_mix_lut": _gl.texture3d(ctx, table), "pts": _gl.texture(ctx, pts.astype(np.float32))}
    out = _gl.run_fullscreen(ctx, frag, (W, H), textures=tex, uniforms={"lut_wash_max": wash_max, "lut_unlit_max": unlit_max})
    p = pts.astype(np.float32).astype(np.float64)
    want = _mix.lookup_mix_lut(table.astype(np.float64), p[..., 0], p[..., 1], p[..., 2], wash_max=wash_max, unlit_max=unlit_max)
    # A GPU's linear filter weights are fixed point (llvmpipe: 8 bits of the texel fraction).
    np.testing.assert_allclose(out[..., :3], want, atol=3e-3)


def test_surface_terms(ctx):
    rng = _rng(5)
    look = _look.Look(shadow=0.6, hatching=0.45)
    tam = _hatching.tonal_art_map(size=32, levels=3, seed=2)
    scale = 40.0
    t = rng.uniform(0, 1.2, (H, W, 2))
    P = rng.uniform(-1, 1, (H, W, 3))
    N = rng.normal(0, 1, (H, W, 3))
    N /= np.linalg.norm(N, axis=-1, keepdims=True)
    shadow, pixel = rng.uniform(0, 1, (H, W)), rng.uniform(0.005, 0.2, (H, W))
    frag = (
        "uniform sampler2D th; uniform sampler2D pos; uniform sampler2D nrm; layout(location = 0) out vec4 o;\n"
        + G.glsl_surface(tam_levels=3, tam_size=32)
        + """void main() {
    ivec2 p = ivec2(gl_FragCoord.xy);
    vec4 th_ = texelFetch(th, p, 0), s = texelFetch(pos, p, 0), n = texelFetch(nrm, p, 0);
    o = vec4(look_surface(th_.rg, 1.3, th_.b, s.xyz, n.xyz, s.w), 0.0, 0.0);
}
"""
    )
    f32 = lambda a: np.ascontiguousarray(a, np.float32)  # noqa: E731
    atlas = _hatching.tam_atlas(tam)
    tex = {"th": _gl.texture(ctx, f32(np.concatenate([t, shadow[..., None], 0 * shadow[..., None]], -1))),
           "pos": _gl.texture(ctx, f32(np.concatenate([P, pixel[..., None]], -1))),
           "nrm": _gl.texture(ctx, f32(np.concatenate([N, 0 * pixel[..., None]], -1))),
           "look_tam": _gl.texture(ctx, atlas[0], repeat=True, mipmaps=atlas[1:])}  # fmt: skip
    out = _gl.run_fullscreen(ctx, frag, (W, H), textures=tex, uniforms={"look_shadow": 0.6, "look_hatching": 0.45, "look_hatch_scale": scale})
    g = lambda a: f32(a).astype(np.float64)  # noqa: E731
    hatch = functools.partial(_hatching.hatch_ink_at, [np.asarray(x, np.float64) for x in tam], g(P), g(N), g(pixel), scale)
    w, u = _look.surface_terms(g(t[..., 0]), g(t[..., 1]), look, unlit_max=1.3, shadow=g(shadow), hatch=hatch)
    np.testing.assert_allclose(out[..., 0], w, rtol=2e-6, atol=1e-6)
    np.testing.assert_allclose(out[..., 1], u, rtol=0, atol=1e-4)


def test_final_pass_matches_compose(ctx):
    """The whole image-space pipeline: G-buffer -> edge passes -> final pass, against `compose` with the same LUT."""
    rng = _rng(6)
    screen = _textures.screen_textures(shape=(16, 12), seed=3)
    pigs = _look.Pigments(*(_paper.pigment_look(p, screen.paper) for p in (PIGMENT, PIGMENT_B, PIGMENT_B, PIGMENT)))
    look = _look.Look(edge_darkening=2.0, edge_width=2.0, granulation=0.8, density=0.3, turbulence=0.2, dispersion=0.1, paper_shading=0.2, strokes=0.25)
    g = np.zeros((H, W, 4), np.float32)
    g[3:20, 2:17, 0] = rng.uniform(0.2, 1.0, (17, 15))
    g[3:20, 2:17, 1] = rng.uniform(0.0, 1.0, (17, 15))
    g[3:20, 2:17, 2] = rng.uniform(0.0, 1.0, (17, 15))
    g[3:20, 2:17, 3] = rng.normal(0, 1, (17, 15))  # the stroke layer
    params = Params(wash=PIGMENT, unlit=PIGMENT_B)
    glaze = lambda p, w, u, m: _mix.glaze_mix(p, PIGMENT_B, PIGMENT, w, u, m)  # noqa: E731
    wash_max = unlit_max = 4.0  # the darkened, granulated thickness stays inside the table
    table = _mix.bake_mix_lut(glaze, params, (32, 32, 8), wash_max=wash_max, unlit_max=unlit_max)
    uni = _look.look_uniforms(look, pigs, height=H)
    f = _edges.edge_downsample(H)
    passes = G.glsl_edge_passes(f)
    lw, lh = -(-W // f), -(-H // f)
    low = _gl.run_fullscreen(ctx, passes["downsample"], (lw, lh), textures={"look_source": _gl.texture(ctx, g)})
    low = _gl.run_fullscreen(ctx, passes["blur_rows"], (lw, lh), textures={"look_source": _gl.texture(ctx, low)}, uniforms=uni)
    low = _gl.run_fullscreen(ctx, passes["blur_columns"], (lw, lh), textures={"look_source": _gl.texture(ctx, low)}, uniforms=uni)
    s0, s1 = screen.rgba()
    tex = {"look_gbuffer": _gl.texture(ctx, g), "look_screen0": _gl.texture(ctx, s0), "look_screen1": _gl.texture(ctx, s1),
           "look_edge_blurred": _gl.texture(ctx, low, linear=True), "look_mix_lut": _gl.texture3d(ctx, table)}  # fmt: skip
    uni = {**uni, "look_flip_rows": 0, "look_rows": H, "lut_wash_max": wash_max, "lut_unlit_max": unlit_max}
    out = _gl.run_fullscreen(ctx, G.glsl_final_pass(height=H), (W, H), textures=tex, uniforms=uni)[..., :3]
    lut = lambda w, u, m: _mix.lookup_mix_lut(table.astype(np.float64), w, u, m, wash_max=wash_max, unlit_max=unlit_max)  # noqa: E731
    want = _look.compose(g.astype(np.float64), _textures.tile(screen, H, W).astype(jnp.float64), look, pigs, lut)
    np.testing.assert_allclose(out, want, atol=2e-3)  # the 3D LUT's fixed-point filter weights (see test_mix_lut_lookup)
    exact = _look.compose(g.astype(np.float64), _textures.tile(screen, H, W).astype(jnp.float64), look, pigs, lambda w, u, m: glaze(params, w, u, m))
    assert float(np.max(np.abs(out - np.asarray(exact)))) < 0.03  # a coarse 32 x 32 x 8 table over [0, 4]


def _sources(target):
    """Every look shader for `target`, complete (`#version` first), as (name, kind, source)."""
    head = G.header(target)
    out = [("fullscreen", "vertex", head + G.FULLSCREEN_VERTEX)]
    for name, body in G.glsl_edge_passes().items():
        out.append((name, "fragment", head + body))
    out.append(("final", "fragment", head + G.glsl_final_pass(height=512)))
    vert, frag = G.glsl_depth_pass()
    out += [("depth", "vertex", head + vert), ("depth", "fragment", head + frag)]
    surface = (
        "in vec3 P; in vec3 N; in vec2 t; layout(location = 0) out vec4 o;\n"
        + G.glsl_surface()
        + "void main() { o = vec4(look_surface(t, 1.0, look_shadow_factor(P, N), P, N, 0.01), 0.0, 0.0); }\n"
    )
    out.append(("surface", "fragment", head + surface))
    return out


def test_every_shader_compiles_as_glsl330(ctx):
    for name, kind, src in _sources("glsl330"):
        if kind == "fragment":
            vert = _sources("glsl330")[0][2] if name != "depth" else G.header("glsl330") + G.glsl_depth_pass()[0]
            if name == "surface":
                vert = G.header("glsl330") + "out vec3 P; out vec3 N; out vec2 t; void main() { P = vec3(0.0); N = vec3(0.0, 0.0, 1.0); t = vec2(0.0); gl_Position = vec4(0.0); }\n"
            ctx.program(vertex_shader=vert, fragment_shader=src).release()


def test_every_shader_compiles_as_webgl2():
    """The same sources with the WebGL2 header, compiled by Chromium's WebGL2 (SwiftShader): GLSL ES 3.00."""
    from playwright.sync_api import sync_playwright

    from test_viewer import CHROMIUM, CHROMIUM_ARGS

    sources = [{"name": n, "kind": k, "src": s} for n, k, s in _sources("webgl2")]
    js = """(sources) => {
        const gl = document.createElement('canvas').getContext('webgl2');
        if (!gl) return [['webgl2', 'no context']];
        const errors = [];
        for (const s of sources) {
            const sh = gl.createShader(s.kind === 'vertex' ? gl.VERTEX_SHADER : gl.FRAGMENT_SHADER);
            gl.shaderSource(sh, s.src);
            gl.compileShader(sh);
            if (!gl.getShaderParameter(sh, gl.COMPILE_STATUS)) errors.push([s.name + ' ' + s.kind, gl.getShaderInfoLog(sh)]);
        }
        return errors;
    }"""
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        try:
            page = browser.new_page()
            page.set_content("<html><body></body></html>")
            errors = page.evaluate(js, sources)
        finally:
            browser.close()
    assert errors == [], errors
