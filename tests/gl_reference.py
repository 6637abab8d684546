"""An OpenGL reference for the renderer, independent of diffwash's shading code.

Mesa llvmpipe through a headless EGL context (moderngl). The camera matrices are
built here (gluLookAt / gluPerspective) and the watercolour model (bias, gain,
thicknesses, textbook Kubelka-Munk with sinh/cosh, compositing) is written here
in GLSL, per pixel and per vertex; OpenGL does its own rasterization, clipping,
depth test, back-face culling and perspective-correct interpolation.
Used by tests/test_render_opengl.py and benchmarks/bench_render.py.
"""

from __future__ import annotations

import moderngl
import numpy as np


VERTEX_SHADER = """
#version 330
uniform mat4 u_vp;
uniform vec3 u_eye;
in vec3 in_pos;
in vec3 in_normal;
out vec3 v_pos;
out vec3 v_normal;
out vec2 v_front;  // per-vertex thicknesses (wash, unlit), front side
out vec2 v_back;   // and with the normal reversed (back faces)
vec2 thicknesses(vec3 N, vec3 L, vec3 V);
uniform vec3 u_light;
void main() {
    gl_Position = u_vp * vec4(in_pos, 1.0);
    v_pos = in_pos;
    v_normal = in_normal;
    vec3 L = normalize(u_light);
    vec3 V = normalize(u_eye - in_pos);
    v_front = thicknesses(in_normal, L, V);
    v_back = thicknesses(-in_normal, L, V);
}
"""

MODEL = """
uniform float u_k_wash, u_k_specular, u_shininess, u_k_unlit, u_gain, u_bias, u_wash_reduction;
float schlick_bias(float t, float b) { return t / ((1.0 / b - 2.0) * (1.0 - t) + 1.0); }
float perlin_gain(float t, float g) {
    return t < 0.5 ? schlick_bias(2.0 * t, 1.0 - g) / 2.0 : 1.0 - schlick_bias(2.0 - 2.0 * t, 1.0 - g) / 2.0;
}
vec2 thicknesses(vec3 N, vec3 L, vec3 V) {
    vec3 H = normalize(L + V);
    float nh = clamp(dot(H, N), 0.0, 1.0);
    float wash = (1.0 - pow(nh, u_shininess)) * u_k_specular * u_k_wash;
    float u = perlin_gain(schlick_bias(clamp(1.0 - dot(L, N), 0.0, 1.0), u_bias), u_gain);
    return vec2(wash * (1.0 - u_wash_reduction * u), u_k_unlit * u);
}
"""

FRAGMENT_SHADER = """
#version 330
uniform vec3 u_eye, u_light, u_paper;
uniform vec3 u_wash_K, u_wash_S, u_unlit_K, u_unlit_S;
uniform int u_per_vertex;
in vec3 v_pos;
in vec3 v_normal;
in vec2 v_front;
in vec2 v_back;
out vec4 colour;
vec2 thicknesses(vec3 N, vec3 L, vec3 V);
// Kubelka-Munk, textbook form (Curtis et al. 1997, sec. 5).
void layer(vec3 K, vec3 S, float x, out vec3 R, out vec3 T) {
    vec3 a = 1.0 + K / S;
    vec3 b = sqrt(a * a - 1.0);
    vec3 sh = sinh(b * S * x), ch = cosh(b * S * x);
    vec3 c = a * sh + b * ch;
    R = sh / c;
    T = b / c;
}
void main() {
    vec2 th;
    if (u_per_vertex == 1) {
        th = gl_FrontFacing ? v_front : v_back;
    } else {
        vec3 N = normalize(v_normal);
        if (!gl_FrontFacing) N = -N;
        th = thicknesses(N, normalize(u_light), normalize(u_eye - v_pos));
    }
    vec3 Rw, Tw, Ru, Tu;
    layer(u_wash_K, u_wash_S, th.x, Rw, Tw);
    layer(u_unlit_K, u_unlit_S, th.y, Ru, Tu);
    vec3 d = 1.0 - Ru * Rw;
    vec3 R = Ru + Tu * Tu * Rw / d;
    vec3 T = Tu * Tw / d;
    colour = vec4(R + T * T * u_paper / (1.0 - R * u_paper), 1.0);
}
"""


def look_at(eye, target, up):
    f = np.asarray(target, float) - eye
    f /= np.linalg.norm(f)
    s = np.cross(f, up)
    s /= np.linalg.norm(s)
    u = np.cross(s, f)
    m = np.eye(4)
    m[0, :3], m[1, :3], m[2, :3] = s, u, -f
    m[:3, 3] = -m[:3, :3] @ eye
    return m


def perspective(fov_y, aspect, near, far):
    f = 1 / np.tan(np.radians(fov_y) / 2)
    return np.array(
        [
            [f / aspect, 0, 0, 0],
            [0, f, 0, 0],
            [0, 0, (far + near) / (near - far), 2 * far * near / (near - far)],
            [0, 0, -1, 0],
        ]
    )


def create(ctx: moderngl.Context | None = None):
    """A standalone EGL context (llvmpipe without a GPU) and the reference program: `(ctx, prog)`."""
    ctx = ctx or moderngl.create_context(standalone=True, backend="egl")
    prog = ctx.program(vertex_shader=moderngl_source(VERTEX_SHADER), fragment_shader=moderngl_source(FRAGMENT_SHADER))
    return ctx, prog


def moderngl_source(src: str) -> str:
    # Both stages get the model (GLSL has no includes): insert it after #version.
    head, rest = src.split("\n", 2)[1], src.split("\n", 2)[2]
    return f"{head}\n{MODEL}\n{rest}"


def gl_render(gl, scene) -> np.ndarray:
    """The scene drawn by OpenGL: (H, W, 4) float32 linear RGB + coverage, row 0 at the top."""
    ctx, prog = gl
    cam, p, w, h = scene.camera, scene.params, scene.width, scene.height
    eye = np.asarray(cam.eye, float)
    vp = perspective(float(cam.fov_y), w / h, float(cam.near), float(cam.far)) @ look_at(eye, cam.target, cam.up)
    prog["u_vp"].write(vp.T.astype("f4").tobytes())  # column-major
    values = {
        "u_eye": eye,
        "u_light": p.light,
        "u_paper": p.paper,
        "u_wash_K": p.wash.K,
        "u_wash_S": p.wash.S,
        "u_unlit_K": p.unlit.K,
        "u_unlit_S": p.unlit.S,
    }
    for name, v in values.items():
        prog[name].value = tuple(float(c) for c in np.asarray(v))
    for name in ("k_wash", "k_specular", "shininess", "k_unlit", "gain", "bias", "wash_reduction"):
        prog[f"u_{name}"].value = float(getattr(p, name))
    prog["u_per_vertex"].value = int(scene.shading == "per-vertex")
    mesh = scene.mesh
    data = np.concatenate([mesh.vertices, mesh.normals], axis=1).astype("f4")
    vbo = ctx.buffer(data.tobytes())
    ibo = ctx.buffer(np.asarray(mesh.faces, "i4").tobytes())
    vao = ctx.vertex_array(prog, [(vbo, "3f 3f", "in_pos", "in_normal")], index_buffer=ibo, index_element_size=4)
    colour = ctx.texture((w, h), 4, dtype="f4")
    depth = ctx.depth_renderbuffer((w, h))
    fbo = ctx.framebuffer(color_attachments=[colour], depth_attachment=depth)
    fbo.use()
    ctx.viewport = (0, 0, w, h)
    fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
    ctx.enable(moderngl.DEPTH_TEST)
    ctx.front_face = "ccw"
    if scene.cull_backfaces:
        ctx.enable(moderngl.CULL_FACE)
        ctx.cull_face = "back"
    else:
        ctx.disable(moderngl.CULL_FACE)
    vao.render(moderngl.TRIANGLES)
    out = np.frombuffer(fbo.read(components=4, dtype="f4"), "f4").reshape(h, w, 4)[::-1].copy()
    for obj in (vao, vbo, ibo, fbo, colour, depth):
        obj.release()
    # Uncovered pixels show the paper.
    out[..., :3] = np.where(out[..., 3:] > 0, out[..., :3], np.asarray(p.paper, "f4"))
    return out


def srgb8(linear: np.ndarray) -> np.ndarray:
    """IEC 61966-2-1 sRGB encoding to 8 bits."""
    x = np.clip(linear, 0, 1)
    v = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)
    return np.round(v * 255).astype(np.float64)
