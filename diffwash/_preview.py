"""Preview a scene in OpenGL through the exported shaders and a baked LUT.

This is the real-time path as an engine would run it: the `glsl330` shaders of
`diffwash._glsl` (the very text `diffwash export` writes), the LUT as a
linearly filtered texture, the mesh in vertex buffers, drawn with moderngl. With
no display it renders headless through EGL (Mesa's llvmpipe on a machine without
a GPU); `show` opens a window (needs a display and the `glfw` package).

It is also how the tests hold the real-time path against `diffwash.render`.
"""

from __future__ import annotations

import os
from typing import Any

import moderngl
import numpy as np

from ._errors import DiffwashError, FailureError
from ._glsl import shader_sources, uniform_values
from .colorimetry import to_display
from ._scene import Scene
from ._look_frame import LookFrame
from .lut import Lut, bake, load_encoded
from .shading import Params, check_per_channel, paper_colour

__all__ = ["Preview", "create_context", "render", "has_display", "can_show", "renderer_name"]

_RENDERER = {"name": "not started"}


def create_context(*, standalone: bool = True) -> moderngl.Context:
    """A moderngl context: headless EGL (works with or without a display).

    Failure to create one is a one-line `FailureError` saying what to install.
    """
    try:
        ctx = moderngl.create_context(standalone=standalone, backend="egl", require=330)
        _RENDERER["name"] = f"{ctx.info['GL_RENDERER']}, {ctx.info['GL_VERSION']}"
        return ctx
    except Exception as e:
        first = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
        raise FailureError(
            f"cannot create a headless OpenGL 3.3 context through EGL ({first}); "
            "install Mesa's EGL (Debian: libegl1 libegl-mesa0 libgl1-mesa-dri, see scripts/install-system-deps)"
        ) from None


def _column_major(m: Any) -> bytes:
    return np.asarray(m, np.float32).T.tobytes()


class Preview:
    """A scene ready to draw in OpenGL: program, LUT texture, mesh buffers.

    **Arguments:**

    - `ctx`: a moderngl context (see `create_context`).
    - `scene`: the `Scene`.
    - `params`: shading `Params` (default: the scene's).
    - `lut`: a `Lut` (default: baked from `params` at 256^2 and quantised as the
      default export's 16-bit PNG stores it); an `"rt"` LUT
      selects the R/T shaders.
    - `shading`: `"per-pixel"` or `"per-vertex"` (default: the scene's).
    - `colour`: `"lut"` (default; `"lut-rt"` for an R/T LUT) or `"km"`
      (Kubelka-Munk per fragment, no LUT; for comparisons).
    - `linear`: write linear values (float framebuffer) instead of display sRGB.
    """

    def __init__(
        self,
        ctx: moderngl.Context,
        scene: Scene,
        params: Params | None = None,
        *,
        lut: Lut | None = None,
        shading: str | None = None,
        colour: str | None = None,
        linear: bool = False,
    ):
        self.ctx = ctx
        self.scene = scene
        self.params = scene.params if params is None else params
        self.shading = scene.shading if shading is None else shading
        if colour is None:
            colour = "lut-rt" if (lut is not None and lut.kind == "rt") else "lut"
        if colour == "km":
            check_per_channel(self.params, 'the per-fragment shader (colour="km")')
        if colour != "km" and lut is None:
            # What `diffwash export` writes by default: 256^2, 16-bit sRGB PNG.
            lut = load_encoded(bake(self.params, 256, kind="rt" if colour == "lut-rt" else "colour"), "png16")
        if colour != "km" and (lut.kind == "rt") != (colour == "lut-rt"):
            raise DiffwashError(f"a {lut.kind} LUT does not go with the {colour} shaders", field="lut")
        self.lut = lut
        self.colour = colour
        self.linear = linear
        vert, frag = shader_sources("glsl330", self.shading, colour=colour, lut_srgb=True, output_srgb=not linear)
        self.program = ctx.program(vertex_shader=vert, fragment_shader=frag)
        mesh = scene.mesh
        vertices = np.asarray(mesh.vertices, np.float32)
        normals = np.asarray(mesh.normals, np.float32)
        self._vbo = ctx.buffer(np.concatenate([vertices, normals], axis=1).tobytes())
        self._ibo = ctx.buffer(np.asarray(mesh.faces, np.uint32).tobytes())
        self.vao = ctx.vertex_array(
            self.program, [(self._vbo, "3f 3f", "position", "normal")], self._ibo
        )
        self.textures = []

        if colour != "km":
            # The LUT as its PNG stores it (sRGB-encoded), in float texels: filtering as on any GPU.
            encoded = to_display(np.asarray(lut.values, np.float64)).astype(np.float32)
            names = ["lut"] if colour == "lut" else ["lut_reflectance", "lut_transmittance"]
            for unit, name in enumerate(names):
                block = np.ascontiguousarray(encoded[..., 3 * unit : 3 * unit + 3])
                tex = ctx.texture((block.shape[1], block.shape[0]), 3, block.tobytes(), dtype="f4")
                tex.repeat_x = tex.repeat_y = False
                tex.filter = (moderngl.LINEAR, moderngl.LINEAR)
                self.textures.append((unit, name, tex))
        self._fbo = None
        self.set_uniforms(uniform_values(scene, self.params, lut=lut))

    def set_uniforms(self, values: dict[str, Any]) -> None:
        """Set the shader's uniforms from `uniform_values`-style values (unknown names are skipped)."""
        for name, v in values.items():
            if name not in self.program:
                continue
            if name in ("model", "view_projection", "normal_matrix"):
                self.program[name].write(_column_major(v))
            elif name == "two_sided":
                self.program[name].value = bool(v)
            else:
                self.program[name].value = tuple(v) if isinstance(v, (list, tuple)) else float(v)
        self._uniforms = {**getattr(self, "_uniforms", {}), **values}

    def background(self) -> tuple[float, float, float]:
        """The clear colour: bare paper, as the shader writes colours."""
        paper = np.asarray(paper_colour(self.params), np.float64)
        return tuple(float(c) for c in (paper if self.linear else to_display(paper)))

    def draw(self, fbo: moderngl.Framebuffer) -> None:
        """Draw the scene into `fbo` (cleared to the paper)."""

        fbo.use()
        ctx = self.ctx
        fbo.clear(*self.background(), 1.0, depth=1.0)
        ctx.enable(moderngl.DEPTH_TEST)
        if self._uniforms.get("two_sided", False):
            ctx.disable(moderngl.CULL_FACE)
        else:
            ctx.enable(moderngl.CULL_FACE)
            ctx.cull_face = "back"
        ctx.front_face = "ccw"
        for unit, name, tex in self.textures:
            tex.use(location=unit)
            self.program[name].value = unit
        self.vao.render(moderngl.TRIANGLES)

    def framebuffer(self, width: int, height: int) -> moderngl.Framebuffer:
        """An offscreen framebuffer of this size (8-bit, or float32 when `linear`), kept for reuse."""
        if self._fbo is None or self._fbo.size != (width, height):
            if self._fbo is not None:
                self._fbo.release()
            colour = self.ctx.texture((width, height), 4, dtype="f4" if self.linear else "f1")
            depth = self.ctx.depth_renderbuffer((width, height))
            self._fbo = self.ctx.framebuffer(color_attachments=[colour], depth_attachment=depth)
        return self._fbo

    def frame(self, width: int | None = None, height: int | None = None) -> np.ndarray:
        """Render one frame offscreen and read it back.

        **Returns:**

        `(H, W, 3)` float32, row 0 at the top: display sRGB values in [0, 1]
        (multiples of 1/255) or, when `linear`, linear values.
        """
        width = self.scene.width if width is None else width
        height = self.scene.height if height is None else height
        fbo = self.framebuffer(width, height)
        self.ctx.viewport = (0, 0, width, height)
        self.draw(fbo)
        if self.linear:
            data = np.frombuffer(fbo.read(components=3, dtype="f4"), np.float32).reshape(height, width, 3)
        else:
            data = np.frombuffer(fbo.read(components=3, dtype="f1"), np.uint8).reshape(height, width, 3) / np.float32(255)
        return np.ascontiguousarray(data[::-1]).astype(np.float32)  # OpenGL's row 0 is the bottom

    def release(self) -> None:
        """Free the GL objects (not the context)."""
        for obj in [self.vao, self._vbo, self._ibo, self.program, *[t for _, _, t in self.textures]]:
            obj.release()
        if self._fbo is not None:
            self._fbo.release()


def render(
    scene: Scene,
    params: Params | None = None,
    *,
    lut: Lut | None = None,
    shading: str | None = None,
    colour: str | None = None,
    linear: bool = False,
    ctx: moderngl.Context | None = None,
) -> np.ndarray:
    """Render `scene` headless through the exported shaders and a LUT.

    **Arguments:**

    - `scene`: the `Scene` (its image size is the frame's).
    - `params`: shading `Params` (default: the scene's).
    - `lut`: the `Lut` to sample (default: baked from `params` at 256^2).
    - `shading`: `"per-pixel"` or `"per-vertex"` (default: the scene's).
    - `colour`: `"lut"`, `"lut-rt"` or `"km"` (see `Preview`).
    - `linear`: return linear RGB from a float framebuffer instead of the 8-bit
      display sRGB a screen shows.
    - `ctx`: a moderngl context to reuse (default: a new headless EGL one).

    **Returns:**

    `(H, W, 3)` float32, row 0 at the top; uncovered pixels show the paper.
    A scene with a watercolour look is drawn by the look's passes
    (`diffwash._look_frame.LookFrame`: its own 3D mix LUT, per-pixel
    thicknesses; `lut`, `shading` and `colour` do not apply, `linear` is refused).
    """
    own = ctx is None
    ctx = create_context() if own else ctx
    try:
        if getattr(scene, "watercolour", None) is not None:
            if linear:
                raise ValueError("the watercolour look's frame is display sRGB (linear=False)")
            return np.asarray(LookFrame(ctx, scene, params).frame(), np.float32)
        p = Preview(ctx, scene, params, lut=lut, shading=shading, colour=colour, linear=linear)
        try:
            return p.frame()
        finally:
            p.release()
    finally:
        if own:
            ctx.release()


def has_display() -> bool:
    """Whether a window could be opened (an X11 or Wayland display is set)."""
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def can_show() -> bool:
    """Whether `show` can open a window: a display, and the glfw package."""
    if not has_display():
        return False
    try:
        import glfw  # noqa: F401
    except ImportError:
        return False
    return True


def renderer_name() -> str:
    """The OpenGL renderer and version of the last context `create_context` made."""
    return _RENDERER["name"]
