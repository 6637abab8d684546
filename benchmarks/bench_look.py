"""The watercolour look's cost and real-time agreement (issue 13, stage 1), against the plain model.

    python benchmarks/bench_look.py [--rounds 5] [--gl-size 1024] [--seconds 4]

1. JAX, CPU, float32, the knot scene (100k triangles, 512^2): `diffwash.render` warm (the plain model) and,
   on the same covered pixels, the look's extra work as stage 2 will run it (shadow lookup, surface terms,
   the mix and stroke attributes interpolated, the G-buffer scattered, the image terms with the edge blur,
   the covered pixels gathered and glazed with the mixed pigments, the paper's shading) against the plain
   model's tail (glaze and scatter). Rounds alternate; medians. The ratio is (plain + extra) / plain.
2. OpenGL (llvmpipe without a GPU), --gl-size^2, 100k triangles: the exported LUT shader (the preview) against
   the look's pass structure: a geometry pass into a float G-buffer (model thicknesses, shadow lookup in a
   cached light depth map, hatching optional), three passes at half resolution (box downsample, blur rows,
   blur columns), and the final pass (screen tile, edge darkening, pigment factors, 3D mix LUT, paper
   shading). Frames alternate in rounds; medians and the median of per-round ratios.
3. Agreement: the look's OpenGL frame at the scene's size against the JAX pipeline of
   docs/images/make_watercolour.py (exact Kubelka-Munk, its own shadow map), as 8-bit sRGB PSNR.

Timings on a shared machine are provisional; the ratios (taken in alternating rounds) are what to compare.
"""

from __future__ import annotations

import argparse
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

#: The exported shaders' vertex inputs and matrices (as in `diffwash.shader_sources`).
_VERTEX_INPUTS = """\
layout(location = 0) in vec3 position;
layout(location = 1) in vec3 normal;
uniform mat4 model;
uniform mat3 normal_matrix;
uniform mat4 view_projection;
"""


def _geometry_program(ctx, hatching: bool, shadow: str = "vertex"):
    """The look's geometry pass: the model's thicknesses, shadow (and hatching), mix and stroke into the G-buffer.

    `shadow="vertex"`: the shadow lookup runs in the vertex shader and is interpolated (as in the JAX
    kernel's default); `"pixel"`: per fragment.
    """
    head = wl._gl.header("glsl330")
    model = diffwash.functions_source("glsl330", colour="km")  # the thickness model (the colour is the look's)
    vert = head + f"#define LOOK_VERTEX_SHADOW {int(shadow == 'vertex')}\n" + _VERTEX_INPUTS + wl.glsl_shadow() + """\
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
    frag = head + f"#define LOOK_HATCHING {int(hatching)}\n#define LOOK_VERTEX_SHADOW {int(shadow == 'vertex')}\n" + model + wl.glsl_surface() + """\
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
    vec4 h0 = vec4(0.0), h1 = vec4(0.0);
#if LOOK_HATCHING
    look_hatch_samples(world_position, N, dot(world_position - eye, eye_forward) * look_pixel_scale, h0, h1);
#endif
#if LOOK_VERTEX_SHADOW
    float shadow = v_shadow;
#else
    float shadow = look_shadow_factor(world_position, N);
#endif
    gbuffer = vec4(look_surface(t, k_unlit, shadow, h0, h1), v_mix, v_stroke);
}
"""
    return ctx.program(vertex_shader=vert, fragment_shader=frag)


class LookFrame:
    """The look's passes in OpenGL for one scene (the stage-2 preview in miniature)."""

    def __init__(self, ctx, scene, look, *, hatching=False, size=None):
        import moderngl

        self.ctx, self.scene, self.look = ctx, scene, look
        W, H = size or (scene.width, scene.height)
        self.size = (W, H)
        p = scene.params
        mesh = scene.mesh
        v = np.asarray(mesh.vertices, np.float32)
        self.strokes = wl.stroke_field(np.asarray(mesh.vertices), np.asarray(mesh.faces), np.asarray(mesh.normals), direction="max")
        attrs = np.concatenate([v, np.asarray(mesh.normals, np.float32), np.zeros((len(v), 1), np.float32), self.strokes[:, None]], 1)
        self.vbo = ctx.buffer(np.ascontiguousarray(attrs).tobytes())
        self.ibo = ctx.buffer(np.asarray(mesh.faces, np.uint32).tobytes())
        self.geometry = _geometry_program(ctx, hatching)
        self.vao = ctx.vertex_array(self.geometry, [(self.vbo, "3f 3f 1f 1f", "position", "normal", "mix_in", "stroke_in")], self.ibo)
        self.screen = wl.screen_textures()
        pigs = wl.Pigments.single(wl.pigment_look(p.wash, self.screen.paper), wl.pigment_look(p.unlit, self.screen.paper))
        self.uniforms = {**diffwash.uniform_values(scene, aspect=W / H), **wl.look_uniforms(look, pigs, height=H)}
        fov = np.radians(float(scene.camera.fov_y))
        fwd = np.asarray(scene.camera.target, np.float64) - np.asarray(scene.camera.eye, np.float64)
        self.uniforms.update(eye_forward=list(fwd / np.linalg.norm(fwd)), look_pixel_scale=2 * np.tan(fov / 2) / H)
        # The light's depth map: rendered once (the light and the mesh do not move).
        self.light_vp = np.asarray(wl.light_view_projection(np.asarray(mesh.vertices), p.light), np.float32)
        self.uniforms["look_light_view_projection"] = self.light_vp
        self.uniforms["look_shadow_normal_offset"] = wl.normal_offset(self.light_vp)
        self.shadow_map = self._depth_pass(wl.SHADOW_MAP_SIZE)
        wash_max, unlit_max = LUT_RANGE * float(p.wash_max), LUT_RANGE * float(p.unlit_max)
        table = wl.bake_mix_lut(lambda q, w, u, m: wl.glaze_mix(q, q.wash, q.unlit, w, u, m), p, LUT_SIZE, wash_max=wash_max, unlit_max=unlit_max)
        self.uniforms.update(lut_wash_max=wash_max, lut_unlit_max=unlit_max, look_flip_rows=1, look_rows=H)
        self.lut = wl._gl.texture3d(ctx, table)
        s0, s1 = self.screen.rgba()
        self.s0, self.s1 = wl._gl.texture(ctx, s0), wl._gl.texture(ctx, s1)
        self.tam = None
        if hatching:
            tam = wl.tonal_art_map()
            self.tam = [wl._gl.texture(ctx, tam[0][..., 4 * i : 4 * i + 4], repeat=True, mipmaps=[lv[..., 4 * i : 4 * i + 4] for lv in tam[1:]]) for i in range(2)]
            self.uniforms["look_hatch_scale"] = 190.0 * H / 512
        self.gbuf = ctx.texture((W, H), 4, dtype="f4")
        self.gbuf.filter = (moderngl.NEAREST, moderngl.NEAREST)
        self.gfbo = ctx.framebuffer([self.gbuf], ctx.depth_renderbuffer((W, H)))
        f = wl.edge_downsample(H)
        self.low_size = (-(-W // f), -(-H // f))
        self.low = [ctx.texture(self.low_size, 4, dtype="f4") for _ in range(2)]
        for t in self.low:
            t.filter = (moderngl.LINEAR, moderngl.LINEAR)
            t.repeat_x = t.repeat_y = False
        self.lfbo = [ctx.framebuffer([t]) for t in self.low]
        head = wl._gl.header("glsl330")
        full_vs = head + wl._gl.FULLSCREEN_VERTEX
        passes = wl.glsl_edge_passes(f)
        self.edge_programs = [ctx.program(vertex_shader=full_vs, fragment_shader=head + passes[k]) for k in ("downsample", "blur_rows", "blur_columns")]
        self.final = ctx.program(vertex_shader=full_vs, fragment_shader=head + "#define LOOK_OUTPUT_SRGB 1\n" + wl.glsl_final_pass(height=H))
        self.out = ctx.texture((W, H), 4, dtype="f1")
        self.ofbo = ctx.framebuffer([self.out])
        self.fullscreen = [ctx.vertex_array(prog, []) for prog in [*self.edge_programs, self.final]]
        for prog in [self.geometry, *self.edge_programs, self.final]:
            _set_uniforms(prog, self.uniforms)

    def _depth_pass(self, size):
        import moderngl

        vert, frag = wl.glsl_depth_pass()
        head = wl._gl.header("glsl330")
        prog = self.ctx.program(vertex_shader=head + vert, fragment_shader=head + frag)
        _set_uniforms(prog, {"look_light_view_projection": self.light_vp})
        depth = self.ctx.texture((size, size), 1, dtype="f4")
        depth.filter = (moderngl.NEAREST, moderngl.NEAREST)
        fbo = self.ctx.framebuffer([depth], self.ctx.depth_renderbuffer((size, size)))
        vao = self.ctx.vertex_array(prog, [(self.vbo, "3f 20x", "position")], self.ibo)
        fbo.use()
        self.ctx.viewport = (0, 0, size, size)
        fbo.clear(1.0, 1.0, 1.0, 1.0, depth=1.0)
        self.ctx.enable(moderngl.DEPTH_TEST)
        self.ctx.disable(moderngl.CULL_FACE)
        vao.render(moderngl.TRIANGLES)
        return depth

    def draw(self):
        import moderngl

        ctx = self.ctx
        W, H = self.size
        units = {"look_shadow_map": self.shadow_map, "look_mix_lut": self.lut, "look_screen0": self.s0, "look_screen1": self.s1}
        if self.tam:
            units.update(look_tam0=self.tam[0], look_tam1=self.tam[1])
        self.gfbo.use()
        ctx.viewport = (0, 0, W, H)
        self.gfbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
        ctx.enable(moderngl.DEPTH_TEST)
        ctx.enable(moderngl.CULL_FACE) if self.scene.cull_backfaces else ctx.disable(moderngl.CULL_FACE)
        _bind(self.geometry, units)
        self.vao.render(moderngl.TRIANGLES)
        ctx.disable(moderngl.DEPTH_TEST)
        ctx.disable(moderngl.CULL_FACE)
        ctx.viewport = (0, 0, *self.low_size)
        sources = [self.gbuf, self.low[0], self.low[1]]
        targets = [self.lfbo[0], self.lfbo[1], self.lfbo[0]]
        for vao, prog, src, dst in zip(self.fullscreen[:3], self.edge_programs, sources, targets):
            dst.use()
            _bind(prog, {"look_source": src})
            vao.render(vertices=3)
        self.ofbo.use()
        ctx.viewport = (0, 0, W, H)
        _bind(self.final, {**units, "look_gbuffer": self.gbuf, "look_edge_blurred": self.low[0]})
        self.fullscreen[3].render(vertices=3)

    def frame(self) -> np.ndarray:
        self.draw()
        W, H = self.size
        data = np.frombuffer(self.ofbo.read(components=3, dtype="f1"), np.uint8).reshape(H, W, 3)
        return data[::-1] / 255.0


def _bind(prog, textures):
    for unit, (name, tex) in enumerate(textures.items()):
        if name in prog:
            tex.use(location=unit)
            prog[name].value = unit


def _set_uniforms(prog, values):
    for name, v in values.items():
        if name not in prog:
            continue
        if name in ("model", "view_projection", "normal_matrix"):
            prog[name].write(np.asarray(v, np.float32).T.tobytes())
        elif isinstance(v, np.ndarray) and v.shape == (4, 4):
            prog[name].write(np.asarray(v, np.float32).T.tobytes())
        elif name == "look_edge_weights":
            prog[name].write(np.asarray(v, np.float32).tobytes())
        elif isinstance(v, bool):
            prog[name].value = v
        elif isinstance(v, (list, tuple)):
            prog[name].value = tuple(float(x) for x in v)
        elif name in ("look_flip_rows", "look_rows"):
            prog[name].value = int(v)
        else:
            prog[name].value = float(v)


def gl_costs(size: int, seconds: float, rounds: int) -> dict:
    from diffwash import preview

    ctx = preview.create_context()
    scene = diffwash.load_scene(SCENE)
    base = preview.Preview(ctx, scene)
    bfbo = base.framebuffer(size, size)
    looks = {"look": LookFrame(ctx, scene, wl.Look(), size=(size, size)),
             "look + hatching": LookFrame(ctx, scene, wl.Look(hatching=0.5), hatching=True, size=(size, size))}  # fmt: skip

    def fps(draw):
        frames, t0 = 0, time.perf_counter()
        while True:
            draw()
            frames += 1
            if frames % 5 == 0:
                ctx.finish()
                if time.perf_counter() - t0 >= seconds / rounds:
                    return frames / (time.perf_counter() - t0)

    def base_draw():
        ctx.viewport = (0, 0, size, size)
        base.draw(bfbo)

    draws = {"plain LUT shader": base_draw, **{k: lf.draw for k, lf in looks.items()}}
    for d in draws.values():
        d()
    ctx.finish()
    out = {k: [] for k in draws}
    for _ in range(rounds):
        for k, d in draws.items():
            out[k].append(fps(d))
    res = {k: statistics.median(v) for k, v in out.items()}
    for k in looks:
        res[f"{k} / plain (frame time)"] = statistics.median([b / a for a, b in zip(out[k], out["plain LUT shader"])])
    res["renderer"] = preview.renderer_name()
    return res


def agreement() -> float:
    import make_watercolour as mw

    from diffwash import preview

    scene = diffwash.load_scene(SCENE)
    ctx = preview.create_context()
    gl = LookFrame(ctx, scene, wl.Look()).frame()
    geo = mw.pixel_geometry(scene)
    strokes = wl.stroke_field(np.asarray(scene.mesh.vertices), np.asarray(scene.mesh.faces), np.asarray(scene.mesh.normals), direction="max")
    ref = mw.render_look(scene, wl.Look(), geo, wl.screen_textures(), mw.Extras(strokes=strokes), mw.shadow_map(scene))
    ref8 = np.round(diffwash.colorimetry.to_display(ref) * 255) / 255
    mse = float(np.mean((gl - ref8) ** 2))
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
    ap.add_argument("--skip", nargs="*", default=[], choices=["scene", "jax", "gl", "agreement", "lut"])
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
    if "lut" not in args.skip:
        print(f"\n3D mix LUT over {LUT_RANGE}x the model's thickness range, against the exact glaze (8-bit sRGB levels)\n")
        print("| table | max | rms | RGBA8 bytes |\n| --- | ---: | ---: | ---: |")
        for name, e in lut_errors():
            print(f"| {name} | {e['max']:.2f} | {e['rms']:.3f} | {int(e['bytes']) if 'bytes' in e else '-'} |")
    if "agreement" not in args.skip:
        print(f"\nOpenGL look frame against the JAX pipeline (512^2, 8-bit sRGB): PSNR {agreement():.1f} dB")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
