"""The watercolour look in OpenGL: the preview's passes for a scene with a `"watercolour"` object.

A geometry pass into a float G-buffer (the model's thicknesses from the
exported thickness functions, the shadow lookup in a light depth map rendered
once, hatching from the tonal art map, the mix and stroke attributes), the
edge blur's three passes on a reduced grid (downsample, rows, columns), and
the final pass (screen tile, edge darkening, pigment factors, the 3D mix LUT,
paper shading). Every shader is generated from `diffwash.look`'s own functions, and the inputs (look values, stroke layer, mix
map, paper tile, tonal art map) are the scene's `Watercolour`'s, so the frame
agrees with `diffwash.render` (tests/test_look_preview.py). The shaders, the
textures and the uniforms come from `diffwash._look_glsl`; this module is
the OpenGL host code (moderngl), outside the model's `diffwash.look`.
"""

from __future__ import annotations

from typing import Any

import moderngl
import numpy as np

from . import _look_gl as _gl
from ._look_glsl import FULLSCREEN_VERTEX, geometry_sources, glsl_depth_pass, glsl_edge_passes, glsl_final_pass, header, look_frame_uniforms, look_textures
from .look import SHADOW_MAP_SIZE, edge_downsample

__all__ = ["LookFrame"]


def _geometry_program(ctx, hatching: bool, shadow: str = "vertex"):
    vert, frag = geometry_sources("glsl330", hatching, shadow)
    return ctx.program(vertex_shader=vert, fragment_shader=frag)


class LookFrame:
    """The look's passes in OpenGL for one scene with a watercolour look.

    **Arguments:**

    - `ctx`: a moderngl context (`diffwash.preview.create_context()`).
    - `scene`: a `Scene` whose `watercolour` is set.
    - `params`: shading `Params` (default: the scene's).
    - `size`: `(width, height)` of the frame (default: the scene's image).

    `frame()` draws and returns the 8-bit display sRGB frame, `(H, W, 3)`
    float in [0, 1], row 0 at the top; `draw()` only draws (for timing).
    Per-pixel thicknesses whatever the scene's shading mode.
    """

    def __init__(self, ctx: Any, scene: Any, params: Any = None, *, size: tuple[int, int] | None = None):
        wc = scene.watercolour
        if wc is None:
            raise ValueError("the scene has no watercolour look")
        self.ctx, self.scene = ctx, scene
        W, H = size or (scene.width, scene.height)
        self.size = (W, H)
        p = scene.params if params is None else params
        mesh = scene.mesh
        v = np.asarray(mesh.vertices, np.float32)
        zeros = np.zeros((len(v), 1), np.float32)
        mix = zeros if wc.mix is None else np.asarray(wc.mix, np.float32)[:, None]
        strokes = zeros if wc.strokes is None else np.asarray(wc.strokes, np.float32)[:, None]
        attrs = np.concatenate([v, np.asarray(mesh.normals, np.float32), mix, strokes], 1)
        self.vbo = ctx.buffer(np.ascontiguousarray(attrs).tobytes())
        self.ibo = ctx.buffer(np.asarray(mesh.faces, np.uint32).tobytes())
        hatching = wc.tam is not None
        self.geometry = _geometry_program(ctx, hatching)
        self.vao = ctx.vertex_array(self.geometry, [(self.vbo, "3f 3f 1f 1f", "position", "normal", "mix_in", "stroke_in")], self.ibo)
        textures, wash_max, unlit_max = look_textures(scene, p)
        self.uniforms = look_frame_uniforms(scene, p, wash_max, unlit_max, size=(W, H))
        # The light's depth map: rendered once (the light and the mesh do not move).
        self.light_vp = np.asarray(self.uniforms["look_light_view_projection"], np.float32)
        self.shadow_map = self._depth_pass(SHADOW_MAP_SIZE)
        self.lut = _gl.texture3d(ctx, textures["mix_lut"][0])
        second = textures["screen1"][0]
        second = np.concatenate([second, np.zeros(second.shape[:2] + (2,), np.float32)], axis=-1)
        self.s0, self.s1 = _gl.texture(ctx, textures["screen0"][0]), _gl.texture(ctx, second)
        self.tam = None
        if hatching:
            self.tam = _gl.texture(ctx, textures["tam"][0], repeat=True, mipmaps=textures["tam"][1:])
        self._targets(W, H)

    def _targets(self, W: int, H: int) -> None:
        ctx = self.ctx
        self.gbuf = ctx.texture((W, H), 4, dtype="f4")
        self.gbuf.filter = (moderngl.NEAREST, moderngl.NEAREST)
        self.gfbo = ctx.framebuffer([self.gbuf], ctx.depth_renderbuffer((W, H)))
        f = edge_downsample(H)
        self.low_size = (-(-W // f), -(-H // f))
        self.low = [ctx.texture(self.low_size, 4, dtype="f4") for _ in range(2)]
        for t in self.low:
            t.filter = (moderngl.LINEAR, moderngl.LINEAR)
            t.repeat_x = t.repeat_y = False
        self.lfbo = [ctx.framebuffer([t]) for t in self.low]
        head = header("glsl330")
        full_vs = head + FULLSCREEN_VERTEX
        passes = glsl_edge_passes(f)
        self.edge_programs = [ctx.program(vertex_shader=full_vs, fragment_shader=head + passes[k]) for k in ("downsample", "blur_rows", "blur_columns")]
        self.final = ctx.program(vertex_shader=full_vs, fragment_shader=head + "#define LOOK_OUTPUT_SRGB 1\n" + glsl_final_pass(height=H))
        self.out = ctx.texture((W, H), 4, dtype="f1")
        self.ofbo = ctx.framebuffer([self.out])
        self.fullscreen = [ctx.vertex_array(prog, []) for prog in [*self.edge_programs, self.final]]
        for prog in [self.geometry, *self.edge_programs, self.final]:
            _set_uniforms(prog, self.uniforms)

    def _depth_pass(self, size):
        vert, frag = glsl_depth_pass()
        head = header("glsl330")
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

    def passes(self) -> dict[str, Any]:
        """The frame's passes in order, each a function that draws it (`draw()` runs them all; for timing one)."""
        ctx = self.ctx
        W, H = self.size
        units = {"look_shadow_map": self.shadow_map, "look_mix_lut": self.lut, "look_screen0": self.s0, "look_screen1": self.s1}
        if self.tam:
            units["look_tam"] = self.tam

        def geometry():
            self.gfbo.use()
            ctx.viewport = (0, 0, W, H)
            self.gfbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
            ctx.enable(moderngl.DEPTH_TEST)
            ctx.enable(moderngl.CULL_FACE) if self.scene.cull_backfaces else ctx.disable(moderngl.CULL_FACE)
            _bind(self.geometry, units)
            self.vao.render(moderngl.TRIANGLES)
            ctx.disable(moderngl.DEPTH_TEST)
            ctx.disable(moderngl.CULL_FACE)

        def edge(vao, prog, src, dst):
            def run():
                dst.use()
                ctx.viewport = (0, 0, *self.low_size)
                _bind(prog, {"look_source": src})
                vao.render(vertices=3)

            return run

        def final():
            self.ofbo.use()
            ctx.viewport = (0, 0, W, H)
            _bind(self.final, {**units, "look_gbuffer": self.gbuf, "look_edge_blurred": self.low[0]})
            self.fullscreen[3].render(vertices=3)

        out = {"geometry": geometry}
        edges = zip(("edge downsample", "edge blur rows", "edge blur columns"), self.fullscreen[:3], self.edge_programs,
                    [self.gbuf, self.low[0], self.low[1]], [self.lfbo[0], self.lfbo[1], self.lfbo[0]])  # fmt: skip
        out.update({name: edge(vao, prog, src, dst) for name, vao, prog, src, dst in edges})
        out["final"] = final
        return out

    def draw(self):
        for run in self.passes().values():
            run()

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
        if name in ("model", "view_projection", "normal_matrix") or np.ndim(v) == 2:  # matrices, row-major
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


