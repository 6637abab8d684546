"""The watercolour look's cost and real-time agreement (issue 13), against the plain model.

    python benchmarks/bench_look.py [--rounds 5] [--gl-size 1024] [--seconds 4] [--skip scene jax gl profile bound agreement lut]

0. `diffwash.render` of data/scenes/watercolour.json (every effect on, 512^2, 100k triangles, CPU float32),
   warm, against the same scene without its "watercolour" object; and the PSNR between the two images.
1. JAX kernels on the knot scene (stage 1's measurement, kept for comparison): the plain render kernel and the
   same kernel with the look's work (shadow lookup per vertex or per pixel, surface terms, the mix and stroke
   attributes, the G-buffer, the image terms with the edge blur, the glaze at the covered pixels, the paper's
   shading), no hatching. Rounds alternate; medians.
2. OpenGL (llvmpipe without a GPU), --gl-size^2, the showcase's 100k triangles: the exported LUT shader
   (the plain preview) against the look's passes (`diffwash._look_frame.LookFrame`: geometry pass into a
   float G-buffer with the shadow looked up per vertex and hatching, three edge passes on a reduced grid, the final
   pass with the 3D mix LUT), with and without hatching. Frames alternate in rounds; medians and the median
   of per-round ratios.
2b. The same frame pass by pass (`LookFrame.passes()`, `ctx.finish()` around each), and its geometry pass
   with hatching off, the shadow per pixel, and depth only (vertex processing and triangle setup).
2c. A lower bound for any frame that draws the look on this machine: the look's per-pixel work in ONE
   geometry pass straight to RGBA8 (no G-buffer, no full-screen pass, and no edge darkening, which needs
   the neighbours), then with effects stripped one by one down to the vertex stage alone, against the plain
   LUT shader in alternating rounds. These shaders are benchmark-only (not the look's image).
3. Agreement: `diffwash preview` (the look's OpenGL passes) against `diffwash.render`, the showcase at
   512^2, as 8-bit sRGB PSNR.
4. The 3D mix LUT's error by size.

Timings on a shared machine are provisional; the ratios (taken in alternating rounds) are what to compare.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "docs" / "images"))

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import diffwash  # noqa: E402
from diffwash import look as wl  # noqa: E402
from diffwash import shading  # noqa: E402

SCENE = ROOT / "data" / "scenes" / "knot.json"
SHOWCASE = ROOT / "data" / "scenes" / "watercolour.json"
LUT_SIZE = (64, 64, 16)
LUT_RANGE = 3.0  # the 3D LUT covers 3x the model's largest thicknesses (edges, granulation, noise thicken)


def _median_time(f, n=1):
    t0 = time.perf_counter()
    for _ in range(n):
        jax.block_until_ready(f())
    return (time.perf_counter() - t0) / n


def jax_costs(rounds: int) -> dict:
    """The plain render kernel against the same kernel with every look effect, back to back in each round."""
    import functools

    import make_watercolour as mw

    from diffwash._render import _kernel_args, _kernel_statics, _render_kernel, surface, surface_thicknesses
    from diffwash.ops import barycentrics, interpolate

    scene = diffwash.load_scene(SCENE)
    H, W = scene.height, scene.width
    p = scene.params
    mesh = scene.mesh
    vis = diffwash.rasterize(scene)
    kargs, statics = _kernel_args(scene, p, vis), _kernel_statics(scene)
    depth, vp = mw.shadow_map(scene)
    screen = wl.screen_textures()
    strokes = wl.stroke_field(np.asarray(mesh.vertices), np.asarray(mesh.faces), np.asarray(mesh.normals), direction="max")
    pigs = wl.Pigments.single(wl.pigment_look(p.wash, screen.paper), wl.pigment_look(p.unlit, screen.paper))
    extra = dict(depth=jnp.asarray(depth, jnp.float32), vp=jnp.asarray(vp, jnp.float32), tiled=jnp.asarray(wl.tile(screen, H, W)),
                 strokes=jnp.asarray(strokes), mix=jnp.zeros(len(strokes), jnp.float32), offset=jnp.float32(wl.normal_offset(vp)))  # fmt: skip
    look = jax.tree_util.tree_map(lambda x: jnp.asarray(x, jnp.float32), wl.Look())

    @functools.partial(jax.jit, static_argnames=("width", "height", "mode", "taps"))
    def look_kernel(vertices, faces, normals, camera, params, vis, both, ex, look, *, width, height, mode, taps=wl.SHADOW_TAPS):
        surf, clip = surface(vertices, faces, normals, camera, vis, both, width=width, height=height, mode=mode)
        wash, unlit = surface_thicknesses(surf, params)
        bary, _ = barycentrics(clip, faces, vis.pixel_tri, vis.pixels, width, height)
        if taps == "vertex":  # the lookup at the vertices, interpolated with the mix and stroke attributes
            sh_v = wl.shadow(ex["depth"], ex["vp"], vertices, look.shadow_bias, normals=normals, normal_offset=ex["offset"])
            msh = interpolate(jnp.stack([ex["mix"], ex["strokes"], sh_v], 1), faces, vis.pixel_tri, bary)
            ms, sh = msh[:, :2], msh[:, 2]
        else:
            P = interpolate(vertices, faces, vis.pixel_tri, bary)
            sh = wl.shadow(ex["depth"], ex["vp"], P, look.shadow_bias, normals=surf.N, normal_offset=ex["offset"], taps=taps)
            ms = interpolate(jnp.stack([ex["mix"], ex["strokes"]], 1), faces, vis.pixel_tri, bary)
        w, u = wl.surface_terms(wash, unlit, look, unlit_max=params.k_unlit, shadow=sh)
        n = width * height
        # The G-buffer as an image; the image terms run on it (elementwise but for the edge blur), and only
        # the glaze is restricted to the covered pixels (one gather: gathers cost more than arithmetic on a CPU).
        g = jnp.zeros((n, 4), w.dtype).at[vis.pixels].set(jnp.stack([w, u, ms[:, 0], ms[:, 1]], 1), mode="drop", unique_indices=True)
        t = wl.image_terms(g.reshape(height, width, 4), ex["tiled"], look, pigs).reshape(n, 2).at[vis.pixels].get(mode="fill", fill_value=0)
        rgb = shading.glaze(params, t[:, 0], t[:, 1])  # no mix map: the model's own glaze
        img = jnp.broadcast_to(jnp.asarray(params.paper, rgb.dtype), (n, 3)).at[vis.pixels].set(rgb, mode="drop", unique_indices=True)
        return wl.paper_shading(img.reshape(height, width, 3), ex["tiled"][..., 1], look.paper_shading)

    fns = {
        "plain render kernel": lambda: _render_kernel(*kargs, **statics, antialias=False),
        "render kernel with every look effect (per-vertex shadow)": lambda: look_kernel(*kargs, extra, look, **statics, taps="vertex"),
        "the same, per-pixel shadow (3x3 tent)": lambda: look_kernel(*kargs, extra, look, **statics, taps=3),
        "the same, per-pixel shadow (2x2)": lambda: look_kernel(*kargs, extra, look, **statics, taps=2),
        "edge darkening alone (local mean, 2 glazes)": functools.partial(jax.jit(lambda t, lk: wl.edge_darkening(t, lk.edge_darkening, lk.edge_width)),
                                                                         jnp.zeros((H, W, 2), jnp.float32), look),  # fmt: skip
    }
    for f in fns.values():
        jax.block_until_ready(f())
    times = {k: [] for k in fns}
    for _ in range(rounds):
        for k, f in fns.items():
            times[k].append(_median_time(f, 5))
    med = {k: 1e3 * statistics.median(v) for k, v in times.items()}
    plain = times["plain render kernel"]
    for k in list(times)[1:4]:
        med[f"ratio: {k} / plain (median of per-round ratios)"] = statistics.median([a / b for a, b in zip(times[k], plain)])
    return med


def _psnr8(a: np.ndarray, b: np.ndarray) -> float:
    """PSNR of two linear images as 8-bit display sRGB."""
    a8, b8 = (np.round(diffwash.colorimetry.to_display(np.asarray(x)) * 255) / 255 for x in (a, b))
    return float(10 * np.log10(1 / np.mean((a8 - b8) ** 2)))


def scene_costs(rounds: int) -> dict:
    """`diffwash.render` of data/scenes/watercolour.json (every effect on) against the same scene without its look.

    Warm (compiled, visibility and shadow-map pass cached), alternating rounds, medians; and the PSNR of the two
    images (how visible the look is).
    """
    import equinox as eqx

    look = diffwash.load_scene(SHOWCASE)
    plain = eqx.tree_at(lambda s: s.watercolour, look, None, is_leaf=lambda x: x is None)
    fns = {"plain (no watercolour object)": lambda: diffwash.render(plain), "every look effect on": lambda: diffwash.render(look)}
    images = {k: np.asarray(f()) for k, f in fns.items()}
    times = {k: [] for k in fns}
    for _ in range(rounds):
        for k, f in fns.items():
            times[k].append(_median_time(f, 3))
    out = {f"{k} (ms)": 1e3 * statistics.median(v) for k, v in times.items()}
    out["ratio look / plain (median of per-round ratios)"] = statistics.median(
        [a / b for a, b in zip(times["every look effect on"], times["plain (no watercolour object)"])]
    )
    out["PSNR look vs plain (dB, 8-bit sRGB)"] = _psnr8(*images.values())
    return out


# --- OpenGL ----------------------------------------------------------------------------------------


def gl_costs(size: int, seconds: float, rounds: int) -> dict:
    """Frames per second of the plain LUT shader and of the look's passes (`LookFrame`), the showcase at size^2."""
    import equinox as eqx

    from diffwash import preview
    from diffwash._look_frame import LookFrame

    ctx = preview.create_context()
    scene = diffwash.load_scene(SHOWCASE)
    no_hatch = eqx.tree_at(lambda s: s.watercolour.tam, scene, None, is_leaf=lambda x: x is None)
    looks = {"look, every effect on": LookFrame(ctx, scene, size=(size, size)),
             "look without hatching": LookFrame(ctx, no_hatch, size=(size, size))}  # fmt: skip

    res = _fps_rounds(ctx, {"plain LUT shader": _plain_draw(ctx, scene, size), **{k: lf.draw for k, lf in looks.items()}}, seconds, rounds)
    res["renderer"] = preview.renderer_name()
    return res


def _plain_draw(ctx, scene, size: int):
    """A draw of `scene` without its look through the exported LUT shader (`preview.Preview`), size^2: the ceiling."""
    import equinox as eqx

    from diffwash import preview

    base = preview.Preview(ctx, eqx.tree_at(lambda s: s.watercolour, scene, None, is_leaf=lambda x: x is None))
    fbo = base.framebuffer(size, size)

    def draw():
        ctx.viewport = (0, 0, size, size)
        base.draw(fbo)

    return draw


def _fps_rounds(ctx, draws: dict, seconds: float, rounds: int) -> dict:
    """Frames per second of each draw (the first is the reference), in alternating rounds of `seconds / rounds`
    each, `ctx.finish()` every 5 frames: medians, and each draw's frame time over the first's (median of
    per-round ratios)."""

    def fps(draw):
        frames, t0 = 0, time.perf_counter()
        while True:
            draw()
            frames += 1
            if frames % 5 == 0:
                ctx.finish()
                if time.perf_counter() - t0 >= seconds / rounds:
                    return frames / (time.perf_counter() - t0)

    for d in draws.values():
        d()
    ctx.finish()
    out = {k: [] for k in draws}
    for _ in range(rounds):
        for k, d in draws.items():
            out[k].append(fps(d))
    ref = next(iter(draws))
    res = {k: statistics.median(v) for k, v in out.items()}
    for k in list(draws)[1:]:
        res[f"{k.strip()} / {ref} (frame time)"] = statistics.median([b / a for a, b in zip(out[k], out[ref])])
    return res


def gl_profile(size: int, rounds: int) -> dict:
    """Milliseconds per pass of `LookFrame` (every effect on) at size^2, and of its geometry pass with effects off.

    Each pass is drawn 3 times between `ctx.finish()` calls (llvmpipe renders when a pass's output is
    read or on finish), in alternating rounds; medians. "vertex processing and setup" is a depth-only
    draw of the mesh (what every geometry pass costs before shading); "plain LUT shader" is the
    exported preview, the frame rate's ceiling.
    """
    from diffwash import preview
    from diffwash import _look_glsl as _gl
    from diffwash._look_frame import LookFrame, _set_uniforms, geometry_sources

    ctx = preview.create_context()
    scene = diffwash.load_scene(SHOWCASE)
    lf = LookFrame(ctx, scene, size=(size, size))
    steps = {f"pass: {k}": f for k, f in lf.passes().items()}
    steps["whole frame (LookFrame.draw)"] = lf.draw
    geometry = lf.passes()["geometry"]

    def variant(hatching, shadow):
        vert, frag = geometry_sources("glsl330", hatching, shadow)
        prog = ctx.program(vertex_shader=vert, fragment_shader=frag)
        _set_uniforms(prog, lf.uniforms)
        vao = ctx.vertex_array(prog, [(lf.vbo, "3f 3f 1f 1f", "position", "normal", "mix_in", "stroke_in")], lf.ibo)

        def run():
            lf.geometry, lf.vao, saved = prog, vao, (lf.geometry, lf.vao)
            geometry()
            lf.geometry, lf.vao = saved

        return run

    steps["geometry: shadow per pixel (not per vertex)"] = variant(True, "pixel")
    steps["geometry: no hatching"] = variant(False, "vertex")
    steps["geometry: no hatching, shadow per pixel"] = variant(False, "pixel")
    head = _gl.header("glsl330")
    depth = ctx.program(vertex_shader=head + "layout(location = 0) in vec3 position;\nuniform mat4 model;\nuniform mat4 view_projection;\n"
                        "void main() { gl_Position = view_projection * (model * vec4(position, 1.0)); }\n",
                        fragment_shader=head + "void main() {}\n")  # fmt: skip
    _set_uniforms(depth, lf.uniforms)
    steps["geometry: vertex processing and setup (depth only)"] = _depth_only(ctx, lf, depth)
    steps["plain LUT shader (whole frame)"] = _plain_draw(ctx, scene, size)
    return _time_steps(ctx, steps, rounds)


#: The bound's shader variants, cumulative: what each strips from the one-pass look.
BOUND_VARIANTS = (
    ("one pass: every effect but edge darkening", {}),
    ("  - hatching", {"hatching": False}),
    ("  - the 3D mix LUT (colour = thicknesses)", {"hatching": False, "lut": False}),
    ("  - the screen tile (paper, unevenness)", {"hatching": False, "lut": False, "screen": False}),
    ("  - the model (vertex stage and setup alone)", {"hatching": False, "lut": False, "screen": False, "model": False}),
)


def _bound_fragment(*, hatching: bool = True, lut: bool = True, screen: bool = True, model: bool = True) -> str:
    """A one-pass fragment shader doing the look's per-pixel work (`glsl_surface`, then `glsl_final_pass`'s
    per-pixel terms) on the interpolated attributes of `geometry_sources`' vertex shader; no edge darkening."""
    from diffwash._glsl import functions_source
    from diffwash import _look_glsl as _gl
    from diffwash._look_glsl import glsl_mix_lut, glsl_paper, glsl_strokes, glsl_surface

    ins = "in float v_shadow;\nin vec3 world_position;\nin vec3 world_normal;\nin float v_mix;\nin float v_stroke;\n"
    out = "layout(location = 0) out vec4 colour;\n"
    if not model:
        return _gl.header("glsl330") + ins + out + "void main() { colour = vec4(v_mix, v_stroke, v_shadow, 1.0); }\n"
    tile = "texelFetch(look_screen{k}, ivec2(int(gl_FragCoord.x) % tile.x, (look_rows - 1 - int(gl_FragCoord.y)) % tile.y), 0)"
    return (
        _gl.header("glsl330") + f"#define LOOK_HATCHING {int(hatching)}\n" + functions_source("glsl330", colour="km") + glsl_surface()
        + glsl_paper() + glsl_strokes() + glsl_mix_lut() + ins + out
        + "uniform vec3 eye_forward;\nuniform float look_pixel_scale;\nuniform int look_rows;\n"
        "uniform sampler2D look_screen0;\nuniform sampler2D look_screen1;\n"
        "void main() {\n"
        "    vec3 N = safe_normalize(world_normal);\n"
        "    vec2 t = watercolour_thickness(N, safe_normalize(light_direction), safe_normalize(eye - world_position));\n"
        "    t = look_surface(t, k_unlit, v_shadow, world_position, N, dot(world_position - eye, eye_forward) * look_pixel_scale);\n"
        "    ivec2 tile = textureSize(look_screen0, 0);\n"
        + (f"    vec4 s0 = {tile.format(k=0)};\n    vec4 s1 = {tile.format(k=1)};\n" if screen else "    vec4 s0 = vec4(0.5), s1 = vec4(0.5);\n")
        + "    float m = v_mix, b = look_stroke_factor(v_stroke);\n"
        "    float w = t.x * b * mix(look_pigment_factor(s0.x, look_wash_pigment), look_pigment_factor(s0.x, look_wash_pigment_b), m)"
        " * look_unevenness_factor(s0.z, s0.w);\n"
        "    float u = t.y * b * mix(look_pigment_factor(s0.x, look_unlit_pigment), look_pigment_factor(s0.x, look_unlit_pigment_b), m)"
        " * look_unevenness_factor(s1.x, s1.y);\n"
        + ("    vec3 c = look_mix_colour(w, u, m);\n" if lut else "    vec3 c = vec3(w, u, m);\n")
        + "    colour = vec4(pow(clamp(look_paper_relief(c, s0.y), 0.0, 1.0), vec3(1.0 / 2.2)), 1.0);\n}\n"
    )


def gl_bound(size: int, seconds: float, rounds: int) -> dict:
    """Frames per second of `_bound_fragment`'s variants (the showcase at size^2, every texture and uniform
    as `LookFrame` sets them) and of the plain LUT shader, in alternating rounds."""
    from diffwash import preview
    from diffwash._look_frame import LookFrame, _bind, _set_uniforms, geometry_sources

    ctx = preview.create_context()
    scene = diffwash.load_scene(SHOWCASE)
    lf = LookFrame(ctx, scene, size=(size, size))
    vert, _ = geometry_sources("glsl330", True)
    target = ctx.framebuffer([ctx.texture((size, size), 4, dtype="f1")], ctx.depth_renderbuffer((size, size)))
    units = {"look_shadow_map": lf.shadow_map, "look_mix_lut": lf.lut, "look_screen0": lf.s0, "look_screen1": lf.s1, "look_tam": lf.tam}

    def one_pass(options):
        prog = ctx.program(vertex_shader=vert, fragment_shader=_bound_fragment(**options))
        _set_uniforms(prog, lf.uniforms)
        vao = ctx.vertex_array(prog, [(lf.vbo, "3f 3f 1f 1f", "position", "normal", "mix_in", "stroke_in")], lf.ibo)
        return _mesh_pass(ctx, target, (size, size), vao, scene.cull_backfaces, lambda: _bind(prog, units), clear=1.0)

    draws = {"plain LUT shader": _plain_draw(ctx, scene, size),
             "look (LookFrame, every effect)": lf.draw, **{name: one_pass(o) for name, o in BOUND_VARIANTS}}  # fmt: skip
    return _fps_rounds(ctx, draws, seconds, rounds)


def _depth_only(ctx, lf, prog):
    vao = ctx.vertex_array(prog, [(lf.vbo, "3f 20x", "position")], lf.ibo)
    return _mesh_pass(ctx, lf.gfbo, lf.size, vao, lf.scene.cull_backfaces)


def _mesh_pass(ctx, fbo, size, vao, cull: bool, bind=None, clear: float = 0.0):
    """A draw of the mesh into `fbo` as the look's geometry pass sets it up (cleared to `clear`, depth test,
    back faces culled where the scene says), `bind()` first (textures); the state is restored after."""
    import moderngl

    def run():
        fbo.use()
        ctx.viewport = (0, 0, *size)
        fbo.clear(clear, clear, clear, clear, depth=1.0)
        ctx.enable(moderngl.DEPTH_TEST)
        ctx.enable(moderngl.CULL_FACE) if cull else ctx.disable(moderngl.CULL_FACE)
        if bind is not None:
            bind()
        vao.render(moderngl.TRIANGLES)
        ctx.disable(moderngl.DEPTH_TEST)
        ctx.disable(moderngl.CULL_FACE)

    return run


def _time_steps(ctx, steps: dict, rounds: int, repeat: int = 3) -> dict:
    for f in steps.values():
        f()
    ctx.finish()
    times = {k: [] for k in steps}
    for _ in range(rounds):
        for k, f in steps.items():
            ctx.finish()
            t0 = time.perf_counter()
            for _ in range(repeat):
                f()
            ctx.finish()
            times[k].append((time.perf_counter() - t0) / repeat)
    return {k: 1e3 * statistics.median(v) for k, v in times.items()}


def agreement() -> float:
    """PSNR of the look's OpenGL frame (`diffwash preview`) against `diffwash.render`, the showcase, 8-bit sRGB."""
    from diffwash import preview

    scene = diffwash.load_scene(SHOWCASE)
    gl = preview.render(scene)
    ref8 = np.round(diffwash.colorimetry.to_display(np.asarray(diffwash.render(scene))) * 255) / 255
    mse = float(np.mean((np.asarray(gl, np.float64) - ref8) ** 2))
    return 10 * np.log10(1 / mse)


def lut_errors() -> list[tuple[str, dict]]:
    """The 3D mix LUT's error against the exact mixed glaze, by size (knot pigments mixed towards yellow and green)."""
    from diffwash import pigments

    lib = pigments.library()
    p = diffwash.load_scene(SCENE).params
    wash_b, unlit_b = lib["Cadmium Yellow"], lib["Hookers Green"]

    def glaze(q, w, u, m):
        return wl.glaze_mix(q, wash_b, unlit_b, w, u, m)

    rng = dict(wash_max=LUT_RANGE * float(p.wash_max), unlit_max=LUT_RANGE * float(p.unlit_max))
    rows = [(f"{n}x{m}x{k}", wl.mix_lut_error(glaze, p, (n, m, k), **rng)) for n, m, k in
            [(16, 16, 4), (32, 32, 8), (64, 64, 8), (64, 64, 16), (64, 64, 32), (128, 128, 16), (256, 256, 16)]]  # fmt: skip
    rows.append(("two exact 2D LUTs blended (colour mix)", wl.blended_pair_error(glaze, p, **rng)))
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--gl-size", type=int, default=1024)
    ap.add_argument("--seconds", type=float, default=4.0)
    ap.add_argument("--skip", nargs="*", default=[], choices=["scene", "jax", "gl", "profile", "bound", "agreement", "lut"])
    args = ap.parse_args(argv)
    if "scene" not in args.skip:
        print("| diffwash.render, data/scenes/watercolour.json, 512^2, 100k triangles, CPU float32 | value |\n| --- | ---: |")
        for k, v in scene_costs(args.rounds).items():
            print(f"| {k} | {v:.2f} |")
        print()
    if "jax" not in args.skip:
        print("| JAX, 512^2, 100k triangles, CPU float32 | ms |\n| --- | ---: |")
        for k, v in jax_costs(args.rounds).items():
            print(f"| {k} | {v:.2f} |")
    if "gl" not in args.skip:
        res = gl_costs(args.gl_size, args.seconds, args.rounds)
        print(f"\nOpenGL: {res.pop('renderer')}, {args.gl_size}^2, 100k triangles\n\n| frame | fps or ratio |\n| --- | ---: |")
        for k, v in res.items():
            print(f"| {k} | {v:.2f} |")
    if "profile" not in args.skip:
        print(f"\nOpenGL passes, {args.gl_size}^2 (LP_NUM_THREADS={os.environ.get('LP_NUM_THREADS', 'unset')}, {os.cpu_count()} cores)\n")
        print("| pass or variant | ms |\n| --- | ---: |")
        for k, v in gl_profile(args.gl_size, args.rounds).items():
            print(f"| {k} | {v:.1f} |")
    if "bound" not in args.skip:
        print(f"\nA lower bound: the look's per-pixel work in one pass, then less (OpenGL, {args.gl_size}^2, 100k triangles)\n")
        print("| frame | fps or ratio |\n| --- | ---: |")
        for k, v in gl_bound(args.gl_size, args.seconds, args.rounds).items():
            print(f"| {k} | {v:.2f} |")
    if "lut" not in args.skip:
        print(f"\n3D mix LUT over {LUT_RANGE}x the model's thickness range, against the exact glaze (8-bit sRGB levels)\n")
        print("| table | max | rms | RGBA8 bytes |\n| --- | ---: | ---: | ---: |")
        for name, e in lut_errors():
            print(f"| {name} | {e['max']:.2f} | {e['rms']:.3f} | {int(e['bytes']) if 'bytes' in e else '-'} |")
    if "agreement" not in args.skip:
        print(f"\ndiffwash preview against diffwash.render, data/scenes/watercolour.json (512^2, 8-bit sRGB): PSNR {agreement():.1f} dB")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
