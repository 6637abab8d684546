"""An interactive OpenGL window for `diffwash preview --window` (glfw + moderngl).

The same `Preview` (exported `glsl330` shaders, LUT texture) drawn into a window:
left-drag orbits the camera about its target, right- or shift-drag moves the
light, the wheel zooms, `V` toggles per-vertex / per-pixel, `R` resets, `Esc`
closes. glfw is an optional dependency (`pip install 'diffwash[window]'`).

A scene with a `"watercolour"` object is drawn by the look's passes
(`diffwash._look_frame.LookFrame`, per-pixel thickness, at the scene's image
size): the orbit updates the camera's uniforms, and moving the light draws
the light's depth map again.
"""

from __future__ import annotations

from typing import Any

import moderngl
import numpy as np

from ._camera import Camera
from ._errors import DiffwashError, FailureError
from ._glsl import uniform_values
from ._preview import Preview, has_display
from ._look_frame import LookFrame
from ._look_glsl import glsl_depth_pass, header
from .look import light_view_projection
from .shading import SHADING_MODES

__all__ = ["show"]


def _rotate(v: np.ndarray, k: np.ndarray, t: float) -> np.ndarray:
    """Rotate `v` about the unit axis `k` by `t` radians (Rodrigues)."""
    return v * np.cos(t) + np.cross(k, v) * np.sin(t) + k * np.dot(k, v) * (1 - np.cos(t))


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


class _Orbit:
    """The window's view: an eye orbiting the camera's target, a light to turn, a zoom."""

    def __init__(self, scene: Any, light: Any):
        cam = scene.camera
        self.camera = cam
        self.target = np.asarray(cam.target, np.float64)
        self.up = _unit(np.asarray(cam.up, np.float64))
        vertices = np.asarray(scene.mesh.vertices, np.float64)
        self.centre = 0.5 * (vertices.min(0) + vertices.max(0))
        self.radius = float(np.max(np.linalg.norm(vertices - self.centre, axis=1)))
        self.home = (np.asarray(cam.eye, np.float64), np.asarray(light, np.float64))
        self.eye, self.light = self.home
        self.drag: dict[str, Any] = {}

    def reset(self) -> None:
        self.eye, self.light = self.home

    def press(self, x: float, y: float, light: bool) -> None:
        self.drag = {"x": x, "y": y, "light": light}

    def release(self) -> None:
        self.drag = {}

    def move(self, x: float, y: float) -> None:
        """Orbit the eye, or turn the light, by the mouse's motion since the last event."""
        if not self.drag:
            return
        dx, dy = x - self.drag["x"], y - self.drag["y"]
        self.drag.update(x=x, y=y)
        if self.drag["light"]:
            right = _unit(np.cross(self.up, self.eye - self.target))
            self.light = _rotate(_rotate(self.light, self.up, dx * 0.01), right, dy * 0.01)
            return
        d = _rotate(self.eye - self.target, self.up, -dx * 0.01)
        d2 = _rotate(d, _unit(np.cross(self.up, d)), -dy * 0.01)
        if abs(np.dot(_unit(d2), self.up)) < 0.995:  # never over the pole (the up vector would flip)
            d = d2
        self.eye = self.target + d

    def zoom(self, steps: float) -> None:
        self.eye = self.target + (self.eye - self.target) * np.exp(-0.1 * steps)

    def uniforms(self, base: dict, width: int, height: int) -> dict:
        """`base` with the eye, the light and a view-projection for this viewport."""
        cam = self.camera
        if np.allclose(self.eye, self.home[0]):
            near, far = float(cam.near), float(cam.far)
        else:
            c = float(np.linalg.norm(self.centre - self.eye))
            far = (c + self.radius) * 1.01
            near = max(c - self.radius, far * 1e-3) * 0.99
        camera = Camera(eye=self.eye, target=self.target, up=self.up, fov_y=cam.fov_y, near=near, far=far)
        vp = np.asarray(camera.view_projection(width / max(height, 1)), np.float64)
        return {**base, "eye": self.eye.tolist(), "light_direction": self.light.tolist(), "view_projection": vp.tolist()}


class _LookView:
    """The look's passes following the window's orbit: the camera's uniforms, and the light's depth map when it moves."""

    def __init__(self, ctx: Any, scene: Any, params: Any = None):
        self.ctx, self.frame = ctx, LookFrame(ctx, scene, params)
        self.vertices = np.asarray(scene.mesh.vertices, np.float64)
        vert, frag = glsl_depth_pass()
        head = header("glsl330")
        self.depth = ctx.program(vertex_shader=head + vert, fragment_shader=head + frag)
        self.depth_vao = ctx.vertex_array(self.depth, [(self.frame.vbo, "3f 20x", "position")], self.frame.ibo)
        size = self.frame.shadow_map.size
        self.depth_fbo = ctx.framebuffer([self.frame.shadow_map], ctx.depth_renderbuffer(size))
        self.light = np.asarray(self.frame.uniforms["light_direction"], np.float64)

    def _set(self, values: dict) -> None:
        for prog in (self.frame.geometry, self.depth):
            for name, v in values.items():
                if name in prog:
                    a = np.asarray(v, np.float32)
                    prog[name].write((a.T if a.ndim == 2 else a).tobytes())

    def _shadow_map(self, light: np.ndarray) -> None:
        """The light's depth map again, for a light that moved (as `LookFrame` draws it for the scene's)."""
        vp = np.asarray(light_view_projection(self.vertices, light), np.float64)
        self._set({"look_light_view_projection": vp})
        ctx = self.ctx
        self.depth_fbo.use()
        ctx.viewport = (0, 0, *self.depth_fbo.size)
        self.depth_fbo.clear(1.0, 1.0, 1.0, 1.0, depth=1.0)
        ctx.enable(moderngl.DEPTH_TEST)
        ctx.disable(moderngl.CULL_FACE)
        self.depth_vao.render(moderngl.TRIANGLES)
        self.light = light

    def draw(self, values: dict) -> Any:
        """Draw the look for the orbit's uniforms (`_Orbit.uniforms`); returns the framebuffer holding the frame."""
        light = np.asarray(values["light_direction"], np.float64)
        if not np.array_equal(light, self.light):
            self._shadow_map(light)
        eye = np.asarray(values["eye"], np.float64)
        forward = np.asarray(self.frame.scene.camera.target, np.float64) - eye
        self._set({"view_projection": values["view_projection"], "eye": eye, "light_direction": light,
                   "eye_forward": forward / np.linalg.norm(forward)})  # fmt: skip
        self.frame.draw()
        return self.frame.ofbo


def _glfw() -> Any:
    try:
        import glfw  # optional: the `window` extra
    except ImportError:
        raise DiffwashError(
            "--window needs the glfw package (pip install glfw, or pip install 'diffwash[window]')", field="--window"
        ) from None
    return glfw


def _open(glfw: Any, width: int, height: int, title: str, *, resizable: bool = True) -> Any:
    """A window with an OpenGL 3.3 core context, made current."""
    glfw.window_hint(glfw.RESIZABLE, resizable)
    glfw.window_hint(glfw.CONTEXT_VERSION_MAJOR, 3)
    glfw.window_hint(glfw.CONTEXT_VERSION_MINOR, 3)
    glfw.window_hint(glfw.OPENGL_PROFILE, glfw.OPENGL_CORE_PROFILE)
    glfw.window_hint(glfw.OPENGL_FORWARD_COMPAT, True)
    window = glfw.create_window(width, height, title, None, None)
    if not window:
        raise FailureError("cannot open a window with an OpenGL 3.3 core context")
    glfw.make_context_current(window)
    glfw.swap_interval(1)
    return window


def _bind(glfw: Any, window: Any, orbit: _Orbit, state: dict, title: str) -> None:
    """Mouse and keyboard: orbit, light, zoom, `V` (shading mode), `R` (reset), `Esc`."""

    def on_button(win, button, action, mods):
        if action == glfw.PRESS:
            x, y = glfw.get_cursor_pos(win)
            orbit.press(x, y, light=button == glfw.MOUSE_BUTTON_RIGHT or bool(mods & glfw.MOD_SHIFT))
        elif action == glfw.RELEASE:
            orbit.release()

    def on_key(win, key, scancode, action, mods):
        if action != glfw.PRESS:
            return
        if key == glfw.KEY_ESCAPE:
            glfw.set_window_should_close(win, True)
        elif key == glfw.KEY_V:
            state["shading"] = SHADING_MODES[1 - SHADING_MODES.index(state["shading"])]
            glfw.set_window_title(win, f"{title} ({state['shading']})")
        elif key == glfw.KEY_R:
            orbit.reset()

    glfw.set_mouse_button_callback(window, on_button)
    glfw.set_cursor_pos_callback(window, lambda win, x, y: orbit.move(x, y))
    glfw.set_scroll_callback(window, lambda win, dx, dy: orbit.zoom(dy))
    glfw.set_key_callback(window, on_key)


def _loop(glfw: Any, window: Any, ctx: Any, draw: Any, frames: int | None, keep_last: bool) -> np.ndarray | None:
    """Draw until the window closes (or for `frames` frames); the last frame shown when `keep_last`."""
    count, last = 0, None
    while not glfw.window_should_close(window):
        width, height = glfw.get_framebuffer_size(window)
        draw(width, height)
        count += 1
        if keep_last:
            data = ctx.screen.read(viewport=(0, 0, width, height), components=3, dtype="f1")
            last = np.frombuffer(data, np.uint8).reshape(height, width, 3)[::-1] / np.float32(255)
        if frames is not None and count >= frames:
            break
        glfw.swap_buffers(window)
        glfw.poll_events()
    return last


def show(
    scene: Any,
    params: Any = None,
    *,
    lut: Any = None,
    shading: str | None = None,
    frames: int | None = None,
    keep_last: bool = False,
) -> np.ndarray | None:
    """Open a window showing the scene through the exported shaders; orbit with the mouse.

    Left-drag orbits the camera around its target, right-drag (or shift-drag)
    moves the light, the wheel zooms, `V` toggles per-vertex/per-pixel, `R`
    resets, `Esc` closes. `frames` closes the window after that many frames
    (for scripted use). With `keep_last` it returns the last frame shown
    (`(H, W, 3)` display sRGB, row 0 at the top).

    Needs a display and the `glfw` package (`pip install 'diffwash[window]'`).
    """
    if not has_display():
        raise DiffwashError("--window needs a display (neither DISPLAY nor WAYLAND_DISPLAY is set); "
                            "use -o FRAME.png to render headless", field="--window")  # fmt: skip
    glfw = _glfw()
    if not glfw.init():
        raise FailureError("cannot open a window: glfw could not initialise (is the display reachable?)")
    try:
        look = getattr(scene, "watercolour", None) is not None
        title = f"diffwash preview: {scene.path or 'scene'}" + (" (watercolour look)" if look else "")
        window = _open(glfw, scene.width, scene.height, title, resizable=not look)
        ctx = moderngl.create_context()
        state = {"shading": scene.shading if shading is None else shading}
        if look:
            view = _LookView(ctx, scene, params)
            base = view.frame.uniforms
            draw = lambda width, height: ctx.copy_framebuffer(ctx.screen, view.draw(orbit.uniforms(base, scene.width, scene.height)))  # noqa: E731
        else:
            previews: dict[str, Preview] = {}
            first = previews.setdefault(state["shading"], Preview(ctx, scene, params, lut=lut, shading=state["shading"]))
            base = uniform_values(scene, first.params, lut=first.lut)

            def draw(width: int, height: int) -> None:
                mode = state["shading"]
                p = previews.get(mode) or previews.setdefault(mode, Preview(ctx, scene, params, lut=lut, shading=mode))
                p.set_uniforms(orbit.uniforms(base, width, height))
                ctx.viewport = (0, 0, width, height)
                p.draw(ctx.screen)

        orbit = _Orbit(scene, base["light_direction"])
        _bind(glfw, window, orbit, state, title)
        return _loop(glfw, window, ctx, draw, frames, keep_last)
    finally:
        glfw.terminate()
