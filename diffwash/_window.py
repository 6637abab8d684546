"""An interactive OpenGL window for `diffwash preview --window` (glfw + moderngl).

The same `Preview` (exported `glsl330` shaders, LUT texture) drawn into a window:
left-drag orbits the camera about its target, right- or shift-drag moves the
light, the wheel zooms, `V` toggles per-vertex / per-pixel, `R` resets, `Esc`
closes.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ._errors import DiffwashError, FailureError

__all__ = ["run_window"]


def _rotate(v: np.ndarray, k: np.ndarray, t: float) -> np.ndarray:
    """Rotate `v` about the unit axis `k` by `t` radians (Rodrigues)."""
    return v * np.cos(t) + np.cross(k, v) * np.sin(t) + k * np.dot(k, v) * (1 - np.cos(t))


def run_window(
    scene: Any,
    params: Any = None,
    *,
    lut: Any = None,
    shading: str | None = None,
    frames: int | None = None,
    keep_last: bool = False,
) -> np.ndarray | None:
    """Show `scene` in a window until it is closed (or for `frames` frames); return the last frame if `keep_last`."""
    try:
        import glfw
    except ImportError:
        raise DiffwashError(
            "--window needs the glfw package (pip install glfw, or pip install 'diffwash[window]')", field="--window"
        ) from None
    import moderngl

    from ._camera import Camera
    from ._glsl import uniform_values
    from .preview import Preview

    if not glfw.init():
        raise FailureError("cannot open a window: glfw could not initialise (is the display reachable?)")
    try:
        glfw.window_hint(glfw.CONTEXT_VERSION_MAJOR, 3)
        glfw.window_hint(glfw.CONTEXT_VERSION_MINOR, 3)
        glfw.window_hint(glfw.OPENGL_PROFILE, glfw.OPENGL_CORE_PROFILE)
        glfw.window_hint(glfw.OPENGL_FORWARD_COMPAT, True)
        title = f"diffwash preview: {scene.path or 'scene'}"
        window = glfw.create_window(scene.width, scene.height, title, None, None)
        if not window:
            raise FailureError("cannot open a window with an OpenGL 3.3 core context")
        glfw.make_context_current(window)
        glfw.swap_interval(1)
        ctx = moderngl.create_context()
        modes = {}
        current = {"shading": scene.shading if shading is None else shading}

        def preview_for(mode: str) -> Preview:
            if mode not in modes:
                modes[mode] = Preview(ctx, scene, params, lut=lut, shading=mode)
            return modes[mode]

        p0 = preview_for(current["shading"])
        base = uniform_values(scene, p0.params, lut=p0.lut)
        cam = scene.camera
        target = np.asarray(cam.target, np.float64)
        up = np.asarray(cam.up, np.float64)
        up = up / np.linalg.norm(up)
        view = {"eye": np.asarray(cam.eye, np.float64), "light": np.asarray(base["light_direction"], np.float64)}
        vertices = np.asarray(scene.mesh.vertices, np.float64)
        centre = 0.5 * (vertices.min(0) + vertices.max(0))
        radius = float(np.max(np.linalg.norm(vertices - centre, axis=1)))
        drag: dict[str, Any] = {}

        def uniforms(width: int, height: int) -> dict:
            eye = view["eye"]
            if np.allclose(eye, np.asarray(cam.eye, np.float64)):
                near, far = float(cam.near), float(cam.far)
            else:
                c = float(np.linalg.norm(centre - eye))
                far = (c + radius) * 1.01
                near = max(c - radius, far * 1e-3) * 0.99
            camera = Camera(eye=eye, target=target, up=up, fov_y=cam.fov_y, near=near, far=far)
            vp = np.asarray(camera.view_projection(width / max(height, 1)), np.float64)
            return {**base, "eye": eye.tolist(), "light_direction": view["light"].tolist(), "view_projection": vp.tolist()}

        def on_button(win, button, action, mods):
            if action == glfw.PRESS:
                x, y = glfw.get_cursor_pos(win)
                drag.update(x=x, y=y, light=button == glfw.MOUSE_BUTTON_RIGHT or bool(mods & glfw.MOD_SHIFT))
            elif action == glfw.RELEASE:
                drag.clear()

        def on_move(win, x, y):
            if not drag:
                return
            dx, dy = x - drag["x"], y - drag["y"]
            drag.update(x=x, y=y)
            if drag["light"]:
                right = np.cross(up, view["eye"] - target)
                right /= np.linalg.norm(right)
                view["light"] = _rotate(_rotate(view["light"], up, dx * 0.01), right, dy * 0.01)
            else:
                d = _rotate(view["eye"] - target, up, -dx * 0.01)
                right = np.cross(up, d)
                right /= np.linalg.norm(right)
                d2 = _rotate(d, right, -dy * 0.01)
                if abs(np.dot(d2 / np.linalg.norm(d2), up)) < 0.995:
                    d = d2
                view["eye"] = target + d

        def on_scroll(win, dx, dy):
            d = view["eye"] - target
            view["eye"] = target + d * np.exp(-0.1 * dy)

        def on_key(win, key, scancode, action, mods):
            if action != glfw.PRESS:
                return
            if key == glfw.KEY_ESCAPE:
                glfw.set_window_should_close(win, True)
            elif key == glfw.KEY_V:
                current["shading"] = "per-vertex" if current["shading"] == "per-pixel" else "per-pixel"
                glfw.set_window_title(win, f"{title} ({current['shading']})")
            elif key == glfw.KEY_R:
                view["eye"] = np.asarray(cam.eye, np.float64)
                view["light"] = np.asarray(base["light_direction"], np.float64)

        glfw.set_mouse_button_callback(window, on_button)
        glfw.set_cursor_pos_callback(window, on_move)
        glfw.set_scroll_callback(window, on_scroll)
        glfw.set_key_callback(window, on_key)
        count = 0
        last = None
        while not glfw.window_should_close(window):
            width, height = glfw.get_framebuffer_size(window)
            p = preview_for(current["shading"])
            p.set_uniforms(uniforms(width, height))
            ctx.viewport = (0, 0, width, height)
            p.draw(ctx.screen)
            count += 1
            if keep_last:
                data = ctx.screen.read(viewport=(0, 0, width, height), components=3, dtype="f1")
                last = np.frombuffer(data, np.uint8).reshape(height, width, 3)[::-1] / np.float32(255)
            if frames is not None and count >= frames:
                break
            glfw.swap_buffers(window)
            glfw.poll_events()
        for p in modes.values():
            p.release()
        return last
    finally:
        glfw.terminate()
