"""The JAX renderer against OpenGL (Mesa llvmpipe through a headless EGL context).

The reference is independent of diffwash: its camera matrices are built here
(gluLookAt / gluPerspective), and the watercolour model (bias, gain,
thicknesses, textbook Kubelka-Munk with sinh/cosh, compositing) is written
here in GLSL, per pixel and per vertex. OpenGL does its own rasterization,
clipping, depth test, back-face culling and perspective-correct interpolation.
Required (issue 3): PSNR >= 40 dB on 8-bit sRGB over the pixels both cover that
lie at least 2 pixels from any silhouette, and coverage IoU >= 0.98.
"""

from __future__ import annotations

import dataclasses

import moderngl
import numpy as np
import pytest
import scipy.ndimage

import diffwash
from diffwash._scene import Mesh, Scene, parse_scene

from conftest import DATA

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


@pytest.fixture(scope="module")
def gl():
    ctx = moderngl.create_context(standalone=True, backend="egl")
    vs = moderngl_source(VERTEX_SHADER)
    fs = moderngl_source(FRAGMENT_SHADER)
    prog = ctx.program(vertex_shader=vs, fragment_shader=fs)
    yield ctx, prog
    ctx.release()


def moderngl_source(src: str) -> str:
    # Both stages get the model (GLSL has no includes): insert it after #version.
    head, rest = src.split("\n", 2)[1], src.split("\n", 2)[2]
    return f"{head}\n{MODEL}\n{rest}"


def gl_render(gl, scene: Scene) -> np.ndarray:
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


def silhouette_band(covered: np.ndarray, depth: np.ndarray, radius: int = 2) -> np.ndarray:
    """Pixels within `radius` of a silhouette: a coverage edge or a jump in depth."""
    d = np.where(covered, depth, np.inf)
    edge = np.zeros_like(covered)
    for axis in (0, 1):
        a = np.take(covered, range(covered.shape[axis] - 1), axis=axis)
        b = np.take(covered, range(1, covered.shape[axis]), axis=axis)
        da = np.take(d, range(d.shape[axis] - 1), axis=axis)
        db = np.take(d, range(1, d.shape[axis]), axis=axis)
        with np.errstate(invalid="ignore"):
            jump = (a != b) | (np.abs(da - db) > 0.02 * np.minimum(da, db))
        sl_a = [slice(None)] * 2
        sl_b = [slice(None)] * 2
        sl_a[axis] = slice(0, -1)
        sl_b[axis] = slice(1, None)
        edge[tuple(sl_a)] |= jump
        edge[tuple(sl_b)] |= jump
    return scipy.ndimage.binary_dilation(edge, np.ones((2 * radius + 1,) * 2, bool))


def compare(gl, scene: Scene) -> tuple[float, float, int]:
    """(PSNR in dB, coverage IoU, pixels compared)."""
    ref = gl_render(gl, scene)
    vis = diffwash.rasterize(scene)
    ours = np.asarray(diffwash.render_rgba(scene, visibility=vis), np.float64)
    ours_cov = ours[..., 3] > 0.5
    ref_cov = ref[..., 3] > 0.5
    iou = (ours_cov & ref_cov).sum() / (ours_cov | ref_cov).sum()
    mask = ours_cov & ref_cov & ~silhouette_band(ours_cov, np.asarray(vis.depth))
    mse = np.mean((srgb8(ours[..., :3])[mask] - srgb8(ref[..., :3])[mask]) ** 2)
    psnr = 10 * np.log10(255**2 / max(mse, 1e-12))
    return psnr, iou, int(mask.sum())


def _knot_scene(shading: str) -> Scene:
    data = {
        "mesh": "knot-10k.ply",
        "image": {"width": 200, "height": 150},
        "camera": {"eye": [0.4, 0.6, 3.0], "target": [0.0, 0.0, 0.0], "up": [0.0, 1.0, 0.0], "fov_y": 45},
        "light": {"direction": [1.0, 1.2, 0.8]},
        "shading": shading,
        "wash": {"pigment": "Quinacridone Rose"},
        "unlit": {"pigment": "French Ultramarine"},
        "shininess": 15,
        "k_unlit": 1.3,
        "gain": 0.65,
        "bias": 0.4,
        "wash_reduction": 0.35,
    }
    return parse_scene(data, base=DATA / "meshes")


def _cut_knot_scene() -> Scene:
    """The knot with the near plane cutting through it (the cut shows what lies behind)."""
    scene = _knot_scene("per-pixel")
    return dataclasses.replace(scene, camera=dataclasses.replace(scene.camera, near=np.float64(2.75)))


def _bowl_scene(shading: str) -> Scene:
    """An open hemisphere seen from above at an angle: inside (back faces) and outside both show."""
    sphere = diffwash.load_mesh(DATA / "meshes" / "sphere.ply")
    v, f = np.asarray(sphere.vertices), np.asarray(sphere.faces)
    keep = v[f].mean(axis=1)[:, 1] < 0.35
    mesh = Mesh(vertices=v, faces=f[keep], normals=np.asarray(sphere.normals), closed=False)
    scene = _knot_scene(shading)
    cam = diffwash.Camera(
        eye=np.array([0.3, 2.2, 2.2]), target=np.zeros(3), up=np.array([0.0, 1.0, 0.0]), fov_y=40.0, near=1.0, far=6.0
    )
    params = scene.params
    params = dataclasses.replace(params, wash=diffwash.pigments.load("Cadmium Yellow"))
    return Scene(mesh=mesh, camera=cam, params=params, width=160, height=160, shading=shading, backfaces="auto")


def _ground_scene() -> Scene:
    """A ground grid that extends behind the camera: triangles cross the near plane."""
    n = 12
    xs = np.linspace(-4, 4, n + 1)
    zs = np.linspace(-8, 3, n + 1)
    gx, gz = np.meshgrid(xs, zs, indexing="ij")
    v = np.stack([gx.ravel(), -0.6 + 0.05 * np.sin(gx.ravel() * 2), gz.ravel()], axis=1)
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    a, b, c, d = idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]
    f = np.concatenate([np.stack([a, d, c], -1).reshape(-1, 3), np.stack([a, c, b], -1).reshape(-1, 3)])
    normals = np.tile([0.0, 1.0, 0.0], (len(v), 1))
    normals[:, 0] = -0.1 * np.cos(v[:, 0] * 2)
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    mesh = Mesh(vertices=v, faces=f, normals=normals, closed=False)
    cam = diffwash.Camera(
        eye=np.array([0.0, 0.2, 1.0]), target=np.array([0.0, -0.6, -0.4]), up=np.array([0.0, 1.0, 0.0]),
        fov_y=60.0, near=0.1, far=20.0,
    )  # fmt: skip
    params = _knot_scene("per-pixel").params
    return Scene(mesh=mesh, camera=cam, params=params, width=128, height=96, shading="per-pixel", backfaces="both")


@pytest.mark.parametrize("shading", ["per-pixel", "per-vertex"])
def test_knot_matches_opengl(gl, shading):
    psnr, iou, n = compare(gl, _knot_scene(shading))
    assert n > 5000
    assert iou >= 0.98, iou
    assert psnr >= 40, psnr


@pytest.mark.parametrize("shading", ["per-pixel", "per-vertex"])
def test_open_mesh_back_faces_match_opengl(gl, shading):
    scene = _bowl_scene(shading)
    assert not scene.cull_backfaces
    vis = diffwash.rasterize(scene)
    # Both sides really show: some visible triangles face away from the camera.
    from diffwash._barycentric import barycentrics
    from diffwash._raster import clip_positions, view_projection

    clip = clip_positions(np.asarray(scene.mesh.vertices), view_projection(scene.camera, 1.0))
    _, front = barycentrics(clip, np.asarray(scene.mesh.faces), vis.pixel_tri, vis.pixels, 160, 160)
    real = np.asarray(vis.pixels) < 160 * 160
    assert 0.1 < np.mean(~np.asarray(front)[real]) < 0.9
    psnr, iou, n = compare(gl, scene)
    assert n > 3000
    assert iou >= 0.98, iou
    assert psnr >= 40, psnr


def test_near_plane_crossing_matches_opengl(gl):
    scene = _ground_scene()
    w = np.asarray(scene.mesh.vertices) @ (-look_at(np.asarray(scene.camera.eye), scene.camera.target, scene.camera.up)[2, :3])
    w = w + (-look_at(np.asarray(scene.camera.eye), scene.camera.target, scene.camera.up)[2, 3])
    assert (w < float(scene.camera.near)).any() and (w > float(scene.camera.near)).any()  # really crosses
    psnr, iou, n = compare(gl, scene)
    assert n > 3000
    assert iou >= 0.98, iou
    assert psnr >= 40, psnr


def test_near_plane_cut_matches_opengl(gl):
    scene = _cut_knot_scene()
    full = diffwash.rasterize(_knot_scene("per-pixel"))
    cut = diffwash.rasterize(scene)
    assert (np.asarray(cut.tri_id) != np.asarray(full.tri_id)).sum() > 200  # the cut changes what is seen
    psnr, iou, n = compare(gl, scene)
    assert n > 3000
    assert iou >= 0.98, iou
    assert psnr >= 40, psnr
