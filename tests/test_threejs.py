"""The three.js target: the exported page in real headless Chromium (Debian's /usr/bin/chromium, SwiftShader)
against `diffwash render`, the module's material, `mesh.glb`'s material read back, and bad input."""

import functools
import http.server
import io
import json
import os
import threading
from pathlib import Path

import numpy as np
import pytest
import trimesh
from PIL import Image

import diffwash
from diffwash import lut as dlut
from diffwash._export import EXPORT_FILES, export
from diffwash._gltf import read_glb
from diffwash._threejs import THREE_VERSION, THREEJS_FILES

from conftest import DATA, ROOT
from test_look_preview import _showcase
from test_viewer import CHROMIUM, CHROMIUM_ARGS, psnr, small_scene

KNOT = DATA / "scenes" / "knot.json"
SHOT = ROOT / "docs" / "images" / "threejs.png"

needs_chromium = pytest.mark.skipif(not Path(CHROMIUM).exists(), reason=f"needs Chromium at {CHROMIUM} (Debian package chromium)")


def inside(shot, reference):
    """PSNR without the pixels more than 2 levels off (silhouette pixels SwiftShader covers differently), and their count."""
    off = np.abs(shot - reference).max(axis=-1) > 2 / 255
    return psnr(shot[~off], reference[~off]), int(off.sum())


def rendered(scene, mode=None):
    """`diffwash render` of the scene, as 8-bit sRGB."""
    if mode is not None:
        scene = diffwash.load_scene(scene.path, shading=mode)
    return np.round(diffwash.colorimetry.to_display(np.asarray(diffwash.render(scene))) * 255) / 255


@pytest.fixture(scope="module")
def knot_export(tmp_path_factory):
    """The knot scene as it is (512x512, 100k triangles, per-pixel), exported for three.js."""
    folder = tmp_path_factory.mktemp("threejs") / "knot"
    export(KNOT, folder, target="threejs")
    return diffwash.load_scene(KNOT), folder


class Server:
    """The folder as static files on 127.0.0.1 (ES modules do not load from file://)."""

    def __init__(self, folder):
        class Quiet(http.server.SimpleHTTPRequestHandler):
            def log_message(self, *args):
                pass

        self.httpd = http.server.ThreadingHTTPServer(("127.0.0.1", 0), functools.partial(Quiet, directory=str(folder)))
        self.thread = threading.Thread(target=self.httpd.serve_forever, daemon=True)
        self.thread.start()
        self.url = f"http://127.0.0.1:{self.httpd.server_address[1]}/"

    def close(self):
        self.httpd.shutdown()
        self.httpd.server_close()


@pytest.fixture(scope="module")
def browser():
    playwright = pytest.importorskip("playwright.sync_api", reason="needs playwright (pip install playwright)")
    if not Path(CHROMIUM).exists():
        pytest.skip(f"needs Chromium at {CHROMIUM} (Debian package chromium)")
    with playwright.sync_playwright() as p:
        b = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        yield b
        b.close()


class Page:
    """index.html of an export, served, with its console messages and requests recorded."""

    def __init__(self, browser, folder):
        self.server = Server(folder)
        self.page = browser.new_page(viewport={"width": 800, "height": 800}, device_scale_factor=1)
        self.messages, self.requests = [], []
        self.page.on("console", lambda m: self.messages.append((m.type, m.text)))
        self.page.on("pageerror", lambda e: self.messages.append(("pageerror", str(e))))
        self.page.on("request", lambda r: self.requests.append(r.url))
        self.page.goto(self.server.url + "index.html")
        self.page.wait_for_function("document.body.dataset.ready === '1' || document.body.dataset.error", timeout=120000)
        assert self.page.evaluate("document.body.dataset.error") is None, self.page.inner_text("#error")

    def canvas(self):
        png = self.page.locator("#view").screenshot()
        return np.asarray(Image.open(io.BytesIO(png)).convert("RGB"), np.float64) / 255

    def errors(self):
        return [m for m in self.messages if m[0] in ("error", "pageerror", "warning")]

    def close(self):
        self.page.close()
        self.server.close()


def test_export_writes_the_module_page_and_three(knot_export):
    _, folder = knot_export
    assert {p.name for p in folder.iterdir()} == {*EXPORT_FILES, *THREEJS_FILES}
    three = folder / "three"
    for name in ("three.module.min.js", "three.core.min.js", "LICENSE", "addons/loaders/GLTFLoader.js", "addons/controls/OrbitControls.js"):
        assert (three / name).is_file(), name
    assert "MIT License" in (three / "LICENSE").read_text()
    assert THREE_VERSION in (three / "README.md").read_text()
    module = (folder / "diffwash-material.js").read_text()
    assert '\nimport * as THREE from "three";\n' in module and "export function createWatercolourMaterial" in module
    # The shaders are the generator's, for three.js: no #version and no declarations three.js makes itself.
    frag = (folder / "watercolour_per_pixel.frag").read_text()
    vert = (folder / "watercolour_per_pixel.vert").read_text()
    assert "#version" not in vert + frag and "in vec3 position;" not in vert and "#define model modelMatrix" in vert
    html = (folder / "index.html").read_text()
    assert '"three": "./three/three.module.min.js"' in html and "http" not in html.split("<script type=\"module\">")[1]


@needs_chromium
def test_page_draws_the_rendered_knot(browser, knot_export):
    scene, folder = knot_export
    page = Page(browser, folder)
    try:
        shot = page.canvas()
        assert shot.shape == (scene.height, scene.width, 3)
        reference = rendered(scene)
        db, (db_inside, off) = psnr(shot, reference), inside(shot, reference)
        print(f"three.js page, knot {scene.width}x{scene.height} per-pixel: {db:.1f} dB against diffwash render ({db_inside:.1f} dB without {off} silhouette pixels)")
        assert db >= 38 and db_inside >= 55
        assert page.errors() == []
        # Served as static files, it needs nothing but the folder.
        assert page.requests and all(r.startswith(page.server.url) for r in page.requests)
        # GLTFLoader hands the GLB material's extras to the page: the same uniforms the module sets.
        extras = page.page.evaluate("window.diffwashThree.extras")
        module_uniforms = page.page.evaluate("window.diffwashThree.config.uniforms")
        assert extras["format"] == "diffwash-material"
        for name, value in extras["uniforms"].items():
            assert module_uniforms[name] == pytest.approx(value), name
        if os.environ.get("DIFFWASH_DOCS_IMAGES"):  # docs/threejs.md's picture is this screenshot
            Image.fromarray(np.round(shot * 255).astype(np.uint8)).save(SHOT, optimize=True)
    finally:
        page.close()


@needs_chromium
def test_module_material_per_vertex_and_rt(browser, tmp_path):
    """The module's other paths: an R/T LUT (two textures over the paper) and per-vertex thickness."""
    scene_path = small_scene(tmp_path)
    export(scene_path, tmp_path / "rt", kind="rt", target="threejs")
    page = Page(browser, tmp_path / "rt")
    try:
        # The sphere's silhouette weighs more than the knot's: SwiftShader covers a few of its pixels
        # differently (as for viewer.html, tests/test_viewer.py); inside it the pictures agree.
        scene = diffwash.load_scene(scene_path)
        shot, reference = page.canvas(), rendered(scene)
        db, (db_inside, off) = psnr(shot, reference), inside(shot, reference)
        print(f"three.js page, sphere 256x256 R/T LUT per-pixel: {db:.1f} dB ({db_inside:.1f} dB without {off} silhouette pixels)")
        assert db >= 35 and db_inside >= 55 and off < 60
        frames = page.page.evaluate("window.diffwashThree.frames")
        page.page.evaluate("""async () => { const m = await import("./diffwash-material.js"), t = window.diffwashThree;
            const material = m.createWatercolourMaterial({shading: "per-vertex"});
            t.scene.traverse((o) => { if (o.isMesh) o.material = material; }); t.draw(); }""")
        assert page.page.evaluate("window.diffwashThree.frames") == frames + 1
        names = page.page.evaluate("() => { const n = []; window.diffwashThree.scene.traverse((o) => { if (o.isMesh) n.push(o.material.name); }); return n; }")
        assert names == ["diffwash watercolour (per-vertex)"]
        per_pixel, shot, reference = shot, page.canvas(), rendered(scene, "per-vertex")
        assert 40 < psnr(shot, per_pixel) < 80  # interpolated thicknesses differ a little from per-pixel ones
        db, (db_inside, off) = psnr(shot, reference), inside(shot, reference)
        print(f"three.js page, sphere 256x256 R/T LUT per-vertex: {db:.1f} dB ({db_inside:.1f} dB without {off} silhouette pixels)")
        assert db >= 35 and db_inside >= 55 and off < 60
        assert page.errors() == []
    finally:
        page.close()


def test_glb_carries_the_material(knot_export):
    scene, folder = knot_export
    gltf, binary = read_glb((folder / "mesh.glb").read_bytes())
    (material,) = gltf["materials"]
    assert all(p["material"] == 0 for m in gltf["meshes"] for p in m["primitives"])
    extras = material["extras"]["diffwash"]
    uniforms = json.loads((folder / "uniforms.json").read_text())
    for name, value in extras["uniforms"].items():
        assert value == pytest.approx(uniforms[name]), name
    assert set(extras["uniforms"]) >= {"k_wash", "k_specular", "shininess", "k_unlit", "gain", "bias", "wash_reduction", "light_direction", "lut_wash_max", "lut_unlit_max"}
    assert material["pbrMetallicRoughness"]["baseColorFactor"][:3] == pytest.approx(uniforms["paper"])
    assert material["doubleSided"] is uniforms["two_sided"]
    # The LUT texture: the exported lut.png's values (16-bit sRGB), a linear clamped sampler.
    texture = gltf["textures"][extras["textures"]["lut"]]
    sampler = gltf["samplers"][texture["sampler"]]
    assert (sampler["magFilter"], sampler["minFilter"], sampler["wrapS"], sampler["wrapT"]) == (9729, 9729, 33071, 33071)
    image = gltf["images"][texture["source"]]
    view = gltf["bufferViews"][image["bufferView"]]
    assert image["mimeType"] == "image/png"
    png = binary[view["byteOffset"] : view["byteOffset"] + view["byteLength"]]
    table = dlut.load(folder / "lut.json")
    assert extras["lut"]["size"] == list(table.size) and extras["lut"]["encoding"] == "srgb"
    assert extras["lut"]["wash_max"] == pytest.approx(table.wash_max)
    np.testing.assert_array_equal(read_png16(png), dlut.encoded(table, "png16"))
    # A general glTF reader still sees the same mesh.
    mesh = trimesh.load(folder / "mesh.glb", force="mesh", process=False)
    np.testing.assert_allclose(mesh.vertices, np.asarray(scene.mesh.vertices), atol=1e-6)
    assert len(mesh.faces) == len(np.asarray(scene.mesh.faces))


def read_png16(data):
    import png

    w, h, rows, info = png.Reader(bytes=data).asDirect()
    assert info["bitdepth"] == 16 and info["planes"] == 3
    return np.vstack([np.asarray(r, np.uint16) for r in rows]).reshape(h, w, 3)


@needs_chromium
def test_page_draws_the_watercolour_look(browser, tmp_path):
    """The showcase (every effect of the look on; the 10k knot at 256x256, as tests/test_look_export.py)."""
    scene_path = _showcase(tmp_path, size=256)
    export(scene_path, tmp_path / "look", target="threejs", size=64)
    page = Page(browser, tmp_path / "look")
    try:
        assert page.page.evaluate("window.diffwashThree.look !== null")
        shot, reference = page.canvas(), rendered(diffwash.load_scene(scene_path))
        db, (db_inside, off) = psnr(shot, reference), inside(shot, reference)
        print(f"three.js page, watercolour showcase 256x256: {db:.1f} dB against diffwash render ({db_inside:.1f} dB without {off} pixels off by more than 2 levels)")
        assert db >= 38
        assert page.errors() == []
    finally:
        page.close()


def test_bad_target(run_cli, tmp_path):
    r = run_cli("export", KNOT, "-o", tmp_path / "out", "--target", "hlsl")
    assert r.returncode == 2 and "hlsl" in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert not (tmp_path / "out").exists()
    with pytest.raises(diffwash.DiffwashError, match="target"):
        export(KNOT, tmp_path / "out", target="hlsl")
