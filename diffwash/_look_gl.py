"""Running the look's shaders with moderngl: textures, and a full-screen pass read back (tests, figures, hosts).

The shaders are `diffwash._look_glsl`'s; this is OpenGL host code, outside the
model's `diffwash.look`, so that the model imports no OpenGL.
"""

from __future__ import annotations

import numpy as np

from ._lazy import lazy
from ._look_glsl import FULLSCREEN_VERTEX, header

moderngl = lazy("moderngl")

__all__ = ["texture", "texture3d", "run_fullscreen"]

# --- Running a pass (moderngl): for the tests, the figures and a host program --------------------------


def texture(ctx, array, *, linear: bool = False, repeat: bool = False, mipmaps=None):
    """A moderngl texture from an `(h, w, c)` array (float32 -> `"f4"`, uint8 -> `"f1"`), row 0 uploaded first.

    `mipmaps`: the finer-to-coarser list of the levels below level 0 (each
    `(h/2^k, w/2^k, c)`), written level by level (a tonal art map's own levels,
    not filtered ones); the texture then samples `LINEAR_MIPMAP_LINEAR`.
    """
    a = np.asarray(array)
    if a.ndim == 2:
        a = a[..., None]
    dtype = "f1" if a.dtype == np.uint8 else "f4"
    a = np.ascontiguousarray(a.astype(np.uint8 if dtype == "f1" else np.float32))
    tex = ctx.texture((a.shape[1], a.shape[0]), a.shape[2], a.tobytes(), dtype=dtype)
    tex.repeat_x = tex.repeat_y = repeat
    if mipmaps:
        tex.build_mipmaps(0, len(mipmaps))
        for level, m in enumerate(mipmaps, start=1):
            m = np.ascontiguousarray(np.asarray(m).astype(np.uint8 if dtype == "f1" else np.float32))
            tex.write(m.tobytes(), level=level)
        tex.filter = (moderngl.LINEAR_MIPMAP_LINEAR, moderngl.LINEAR)
    else:
        f = moderngl.LINEAR if linear else moderngl.NEAREST
        tex.filter = (f, f)
    return tex


def texture3d(ctx, array):
    """A linearly filtered, clamped moderngl 3D texture from a `(d, h, w, c)` float array (slice 0 first)."""
    a = np.ascontiguousarray(np.asarray(array, np.float32))
    tex = ctx.texture3d((a.shape[2], a.shape[1], a.shape[0]), a.shape[3], a.tobytes(), dtype="f4")
    tex.repeat_x = tex.repeat_y = tex.repeat_z = False
    tex.filter = (moderngl.LINEAR, moderngl.LINEAR)
    return tex


def run_fullscreen(ctx, fragment: str, size: tuple[int, int], *, textures=None, uniforms=None, components: int = 4, target: str = "glsl330"):
    """Draw `fragment` (a body without `#version`) over a `size = (width, height)` float32 target; read it back.

    **Arguments:**

    - `textures`: uniform name -> moderngl texture (bound to units 0, 1, ...).
    - `uniforms`: uniform name -> value (float, int, tuple, list for arrays);
      names the program does not use are skipped.

    **Returns:**

    `(height, width, components)` float32, row 0 = the target's row 0
    (`gl_FragCoord.y = 0.5`).
    """
    program = ctx.program(vertex_shader=header(target) + FULLSCREEN_VERTEX, fragment_shader=header(target) + fragment)
    try:
        for unit, (name, tex) in enumerate((textures or {}).items()):
            if name in program:
                tex.use(location=unit)
                program[name].value = unit
        for name, value in (uniforms or {}).items():
            if name not in program:
                continue
            if isinstance(value, (list, tuple)) and name.endswith("weights"):
                program[name].write(np.asarray(value, np.float32).tobytes())
            elif isinstance(value, np.ndarray) and value.shape == (4, 4):
                program[name].write(np.asarray(value, np.float32).T.tobytes())
            elif isinstance(value, (list, tuple)):
                program[name].value = tuple(float(v) for v in value)
            else:
                program[name].value = value
        out = ctx.texture(size, components, dtype="f4")
        fbo = ctx.framebuffer(color_attachments=[out])
        vao = ctx.vertex_array(program, [])
        try:
            fbo.use()
            ctx.viewport = (0, 0, size[0], size[1])
            vao.render(vertices=3)
            data = np.frombuffer(fbo.read(components=components, dtype="f4"), np.float32)
            return data.reshape(size[1], size[0], components).copy()
        finally:
            vao.release()
            fbo.release()
            out.release()
    finally:
        program.release()
