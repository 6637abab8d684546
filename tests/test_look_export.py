"""The watercolour look exported: the WebGL2 viewer in Chromium, the glsl330 files drawn with moderngl from
the folder alone, and the window preview, each against `diffwash render` of data/scenes/watercolour.json."""

import json
import os
import shutil
import struct
import subprocess
import sys

import moderngl
import numpy as np
import pytest
from conftest import ROOT
from test_look_preview import _showcase
from test_viewer import Page, browser, psnr  # noqa: F401  (browser: the module's Chromium fixture)

import diffwash
from diffwash import preview
from diffwash._export import EXPORT_FILES, export
from diffwash._io import read_image
from diffwash._window import _LookView, _Orbit
from diffwash.look import light_view_projection

SIZE = 256  # silhouette pixels (where SwiftShader and llvmpipe cover differently) weigh less than at 128


@pytest.fixture(scope="module")
def scene_path(tmp_path_factory):
    return _showcase(tmp_path_factory.mktemp("look"), size=SIZE)


@pytest.fixture(scope="module")
def scene(scene_path):
    return diffwash.load_scene(scene_path)


@pytest.fixture(scope="module")
def reference(scene):
    """`diffwash render` of the showcase, as 8-bit display sRGB."""
    image = diffwash.render(scene)
    return np.round(diffwash.colorimetry.to_display(np.asarray(image)) * 255) / 255


@pytest.fixture(scope="module")
def exported(scene_path, scene):
    out = {}
    for target in ("webgl2", "glsl330"):
        out[target] = scene_path.parent / target
        export(scene, out[target], target=target, size=32)
    return out


def test_export_writes_the_passes(exported, tmp_path):
    folder = exported["glsl330"]
    names = {p.name for p in folder.iterdir()}
    assert names == {*EXPORT_FILES, "look"}
    graph = json.loads((folder / "look" / "passes.json").read_text())
    assert [p["name"] for p in graph["passes"]] == ["shadow_depth", "geometry", "edge_downsample", "edge_rows", "edge_columns", "final"]
    for p in graph["passes"]:
        for key in ("vertex", "fragment"):
            assert (folder / "look" / p.get(key, "fullscreen.vert")).read_text().startswith("#version 330 core")
    assert (exported["webgl2"] / "look" / "final.frag").read_text().startswith("#version 300 es")
    for spec in graph["textures"].values():
        assert all((folder / "look" / f).is_file() for f in spec["files"])
    assert "shadow_depth" in (folder / "look" / "README.md").read_text()
    # A plain scene exports as before: no look folder, no extra attributes.
    plain = tmp_path / "plain.json"
    data = json.loads((ROOT / "data" / "scenes" / "knot.json").read_text())
    data["mesh"] = str((ROOT / "data" / "scenes" / data["mesh"]).resolve())
    plain.write_text(json.dumps(data))
    export(plain, tmp_path / "out", size=8)
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == sorted(EXPORT_FILES)
    assert set(_glb(tmp_path / "out" / "mesh.glb")[0]) == {"POSITION", "NORMAL"}


# ---- (a) the viewer in Chromium --------------------------------------------------------------------


def test_viewer_draws_the_look(browser, exported, scene, reference):  # noqa: F811
    page = Page(browser, (exported["webgl2"] / "viewer.html").as_uri())
    try:
        assert page.page.evaluate("window.diffwashViewer.look")
        first = page.canvas()
        assert first.shape == (SIZE, SIZE, 3)
        vs_render = psnr(first, reference)
        vs_preview = psnr(first, preview.render(scene))
        print(f"look viewer in Chromium: {vs_render:.1f} dB against diffwash render, {vs_preview:.1f} dB against the OpenGL preview")
        assert vs_render >= 38
        assert page.errors() == []
        assert len(page.requests) == 1 and page.requests[0].startswith("file://")  # self-contained
        _orbit_and_light(page, first, np.asarray(scene.mesh.vertices))
        assert page.errors() == []
    finally:
        page.close()


def _orbit_and_light(page, first, vertices):
    box = page.page.locator("#view").bounding_box()
    cx, cy = box["x"] + box["width"] / 2, box["y"] + box["height"] / 2
    before = page.frames()
    page.page.mouse.move(cx, cy)
    page.page.mouse.down()
    page.page.mouse.move(cx + 40, cy + 10, steps=4)
    page.page.mouse.up()
    page.wait_frame(before)
    assert psnr(page.canvas(), first) < 25  # the view moved
    before = page.frames()
    page.page.click("#reset")
    page.wait_frame(before)
    assert psnr(page.canvas(), first) > 60
    # Moving the light redraws the shadow map with the light's own matrix (the page's twin of the Python one).
    before = page.frames()
    page.page.locator("#light-azimuth").fill("120")
    page.wait_frame(before)
    assert psnr(page.canvas(), first) < 25
    light = page.page.evaluate("window.diffwashViewer.state.light")
    js = page.page.evaluate("(l) => window.diffwashViewer.lightViewProjection(l)", light)
    np.testing.assert_allclose(js, light_view_projection(vertices, np.asarray(light)), atol=1e-5)


def test_viewer_without_float_targets_shows_the_plain_model(browser, exported):  # noqa: F811
    page = browser.new_page(viewport={"width": 700, "height": 500})
    messages = []
    page.on("console", lambda m: messages.append((m.type, m.text)))
    page.on("pageerror", lambda e: messages.append(("pageerror", str(e))))
    page.add_init_script(
        "const get = WebGL2RenderingContext.prototype.getExtension;"
        "WebGL2RenderingContext.prototype.getExtension = function (n) { return n === 'EXT_color_buffer_float' ? null : get.call(this, n); };"
    )
    try:
        page.goto((exported["webgl2"] / "viewer.html").as_uri())
        page.wait_for_function("window.diffwashViewer && window.diffwashViewer.frames > 0", timeout=60000)
        assert not page.evaluate("window.diffwashViewer.look")
        assert "EXT_color_buffer_float" in page.locator("#error").text_content()
        assert [t for t, _ in messages] == ["warning"], messages
    finally:
        page.close()


# ---- (b) the glsl330 files, drawn with moderngl from the folder alone -----------------------------


def _glb(path):
    """The GLB's vertex attributes (name -> float32 array) and triangle indices."""
    data = path.read_bytes()
    n = struct.unpack_from("<I", data, 12)[0]
    gltf = json.loads(data[20 : 20 + n])
    binary = data[20 + n + 8 :]

    def accessor(i):
        a = gltf["accessors"][i]
        view = gltf["bufferViews"][a["bufferView"]]
        comps = {"SCALAR": 1, "VEC3": 3}[a["type"]]
        dtype = {5126: np.float32, 5125: np.uint32, 5123: np.uint16}[a["componentType"]]
        start = view.get("byteOffset", 0) + a.get("byteOffset", 0)
        return np.frombuffer(binary, dtype, a["count"] * comps, start).reshape(a["count"], comps)

    prim = gltf["meshes"][0]["primitives"][0]
    return {k: accessor(i).astype(np.float32) for k, i in prim["attributes"].items()}, accessor(prim["indices"]).astype(np.uint32)


def _set_uniforms(prog, values):
    for name in prog:
        u = prog[name]
        if not isinstance(u, moderngl.Uniform) or name not in values:
            continue
        v = np.asarray(values[name], np.float64)
        v = v.T if v.ndim == 2 else v  # row-major in uniforms.json
        u.write(np.ascontiguousarray(v, np.int32 if u.fmt.endswith("i") else np.float32).tobytes())


def _input_texture(ctx, folder, spec):
    levels = [np.load(folder / f) for f in spec["files"]]
    a = levels[0]
    if spec["kind"] == "3d":
        tex = ctx.texture3d(a.shape[2::-1], a.shape[3], a.tobytes(), dtype="f4")
    else:
        tex = ctx.texture(a.shape[1::-1], a.shape[2], a.tobytes(), dtype="f4")
        if len(levels) > 1:
            tex.build_mipmaps(0, len(levels) - 1)
            for k, level in enumerate(levels[1:], start=1):
                tex.write(level.tobytes(), level=k)
    tex.filter = {"nearest": (moderngl.NEAREST,) * 2, "linear": (moderngl.LINEAR,) * 2,
                  "linear_mipmap_linear": (moderngl.LINEAR_MIPMAP_LINEAR, moderngl.LINEAR)}[spec["filter"]]  # fmt: skip
    tex.repeat_x = tex.repeat_y = spec["wrap"] == "repeat"
    return tex


def _render_target(ctx, spec):
    tex = ctx.texture(spec["size"], 4 if spec["format"].startswith("RGBA") else 1, dtype="f4" if "F" in spec["format"] else "f1")
    tex.filter = (moderngl.LINEAR,) * 2 if spec["filter"] == "linear" else (moderngl.NEAREST,) * 2
    tex.repeat_x = tex.repeat_y = False
    return tex, ctx.framebuffer([tex], ctx.depth_renderbuffer(spec["size"]) if spec["depth"] else None)


def _draw_from_files(ctx, export_folder):
    """Run look/passes.json as a host program would, from the exported files only; the final frame, row 0 on top."""
    folder = export_folder / "look"
    graph, uniforms = json.loads((folder / "passes.json").read_text()), json.loads((folder / "uniforms.json").read_text())
    textures = {n: _input_texture(ctx, folder, s) for n, s in graph["textures"].items()}
    targets = {n: _render_target(ctx, s) for n, s in graph["render_targets"].items()}
    W, H = graph["size"]
    targets["screen"] = _render_target(ctx, {"size": [W, H], "format": "RGBA8", "filter": "nearest", "depth": False})
    textures.update({n: t for n, (t, _) in targets.items()})
    attributes, indices = _glb(export_folder / "mesh.glb")
    names = sorted(graph["attributes"], key=lambda n: graph["attributes"][n]["location"])
    vbo = ctx.buffer(np.concatenate([attributes[graph["attributes"][n]["glb"]] for n in names], axis=1).tobytes())
    ibo = ctx.buffer(indices.tobytes())
    for p in graph["passes"]:
        prog = ctx.program(vertex_shader=(folder / p.get("vertex", "fullscreen.vert")).read_text(), fragment_shader=(folder / p["fragment"]).read_text())
        _set_uniforms(prog, uniforms)
        used = [n for n in names if n in prog]
        layout = " ".join(f"{3 if n in ('position', 'normal') else 1}f" if n in used else f"{12 if n in ('position', 'normal') else 4}x" for n in names)
        vao = ctx.vertex_array(prog, [(vbo, layout, *used)], ibo) if p["draw"] == "mesh" else ctx.vertex_array(prog, [])
        tex, fbo = targets[p["target"]]
        fbo.use()
        ctx.viewport = (0, 0, *tex.size)
        if p["clear"]:
            fbo.clear(*p["clear"]["colour"], depth=p["clear"]["depth"])
        ctx.enable(moderngl.DEPTH_TEST) if p["depth_test"] else ctx.disable(moderngl.DEPTH_TEST)
        ctx.enable(moderngl.CULL_FACE) if p["cull"] else ctx.disable(moderngl.CULL_FACE)
        for unit, (uniform, name) in enumerate(p["inputs"].items()):
            textures[name].use(location=unit)
            if uniform in prog:
                prog[uniform].value = unit
        vao.render(moderngl.TRIANGLES) if p["draw"] == "mesh" else vao.render(vertices=3)
    frame = np.frombuffer(targets["screen"][1].read(components=3, dtype="f1"), np.uint8).reshape(H, W, 3)
    return frame[::-1] / 255.0


def test_glsl330_files_draw_the_look(exported, reference):
    ctx = moderngl.create_context(standalone=True, backend="egl")
    try:
        frame = _draw_from_files(ctx, exported["glsl330"])
    finally:
        ctx.release()
    value = psnr(frame, reference)
    print(f"exported glsl330 passes (moderngl, llvmpipe) against diffwash render: {value:.1f} dB")
    assert value >= 38


# ---- (c) the window ---------------------------------------------------------------------------------


def test_preview_window_draws_the_look(tmp_path):
    """`diffwash preview --window` in a virtual X display shows the look's frame (as headless)."""
    xvfb = shutil.which("xvfb-run")
    assert xvfb, "xvfb-run is missing: run scripts/install-system-deps"
    scene = _showcase(tmp_path, size=96)
    env = {**os.environ, "PYTHONPATH": str(ROOT), "DIFFWASH_CACHE_DIR": "off"}
    env.pop("DISPLAY", None)
    cmd = [xvfb, "-a", "-s", "-screen 0 640x480x24", sys.executable, "-m", "diffwash", "preview", str(scene)]
    r = subprocess.run([*cmd, "--window", "--frames", "3", "-o", str(tmp_path / "win.png")], env=env, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    img, _ = read_image(tmp_path / "win.png")
    frame = preview.render(diffwash.load_scene(scene))
    assert img.shape == frame.shape
    assert np.abs(img - frame).max() <= 1.5 / 255


def test_window_look_follows_the_orbit_and_the_light(tmp_path):
    """The window's look (headless here): the orbit moves the picture, the light redraws the shadow map."""
    scene = diffwash.load_scene(_showcase(tmp_path, size=96))
    ctx = preview.create_context()
    try:
        view = _LookView(ctx, scene)
        orbit = _Orbit(scene, view.frame.uniforms["light_direction"])

        def frame():
            fbo = view.draw(orbit.uniforms(view.frame.uniforms, scene.width, scene.height))
            return np.frombuffer(fbo.read(components=3, dtype="f1"), np.uint8).reshape(96, 96, 3)[::-1] / 255.0

        first = frame()
        np.testing.assert_allclose(first, preview.render(scene, ctx=ctx), atol=1e-6)  # the headless frame
        orbit.press(0, 0, light=False)
        orbit.move(30, 10)
        assert psnr(frame(), first) < 25
        orbit.reset()
        np.testing.assert_array_equal(frame(), first)
        shadow = np.frombuffer(view.frame.shadow_map.read(), np.float32).copy()
        orbit.press(0, 0, light=True)
        orbit.move(80, 0)
        moved = frame()
        assert psnr(moved, first) < 35
        assert not np.array_equal(np.frombuffer(view.frame.shadow_map.read(), np.float32), shadow)
    finally:
        ctx.release()
