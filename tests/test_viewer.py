"""viewer.html in real headless Chromium (Debian's /usr/bin/chromium, SwiftShader WebGL2) against the
renderer and the OpenGL preview: the same picture, no console errors, no network, working controls."""

import io
import json

import numpy as np
import pytest
from PIL import Image
from playwright.sync_api import sync_playwright

import diffwash
from diffwash import preview
from diffwash._export import export

from conftest import DATA

CHROMIUM = "/usr/bin/chromium"
CHROMIUM_ARGS = [
    "--headless=new",
    "--no-sandbox",
    "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
]
SIZE = 256  # silhouette pixels (where SwiftShader and llvmpipe rasterize edges differently) weigh less here than at 128


def psnr(a, b):
    mse = float(np.mean((np.asarray(a, np.float64) - np.asarray(b, np.float64)) ** 2))
    return float("inf") if mse == 0 else 10 * np.log10(1 / mse)


def small_scene(folder, name="sphere"):
    """The bundled scene at SIZE^2, as a file (the viewer's title and mesh come from it)."""
    data = json.loads((DATA / "scenes" / f"{name}.json").read_text())
    data["mesh"] = str((DATA / "scenes" / data["mesh"]).resolve())
    data["image"] = {"width": SIZE, "height": SIZE}
    path = folder / f"{name}.json"
    path.write_text(json.dumps(data))
    return path


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    folder = tmp_path_factory.mktemp("viewer")
    scene_path = small_scene(folder)
    export(scene_path, folder / "out")
    return diffwash.load_scene(scene_path), folder / "out"


@pytest.fixture(scope="module")
def browser():
    with sync_playwright() as p:
        b = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        yield b
        b.close()


class Page:
    """A viewer page with its console messages and network requests recorded."""

    def __init__(self, browser, url):
        self.page = browser.new_page(viewport={"width": 700, "height": 500}, device_scale_factor=1)
        self.messages, self.requests = [], []
        self.page.on("console", lambda m: self.messages.append((m.type, m.text)))
        self.page.on("pageerror", lambda e: self.messages.append(("pageerror", str(e))))
        self.page.on("request", lambda r: self.requests.append(r.url))
        self.page.goto(url)
        self.page.wait_for_function("window.diffwashViewer && window.diffwashViewer.frames > 0", timeout=60000)

    def frames(self):
        return self.page.evaluate("window.diffwashViewer.frames")

    def wait_frame(self, before):
        self.page.wait_for_function(f"window.diffwashViewer.frames > {before}", timeout=30000)

    def canvas(self):
        png = self.page.locator("#view").screenshot()
        return np.asarray(Image.open(io.BytesIO(png)).convert("RGB"), np.float64) / 255

    def errors(self):
        return [m for m in self.messages if m[0] in ("error", "pageerror", "warning")]

    def close(self):
        self.page.close()


@pytest.fixture
def page(browser, exported):
    p = Page(browser, (exported[1] / "viewer.html").as_uri())
    yield p
    p.close()


def rendered(scene, mode):
    """`diffwash render` of the scene, as 8-bit sRGB."""
    from diffwash.colorimetry import to_display as srgb_encode

    scene = diffwash.load_scene(scene.path, shading=mode)
    return np.round(srgb_encode(np.asarray(diffwash.render(scene))) * 255) / 255


def test_viewer_shows_the_rendered_image(page, exported):
    scene, _ = exported
    shot = page.canvas()
    assert shot.shape == (SIZE, SIZE, 3)
    vs_render, vs_preview = psnr(shot, rendered(scene, "per-pixel")), psnr(shot, preview.render(scene, shading="per-pixel"))
    print(f"viewer in Chromium: {vs_render:.1f} dB against diffwash render, {vs_preview:.1f} dB against the OpenGL preview")
    assert vs_render >= 35
    assert vs_preview >= 35
    assert page.errors() == []
    # Self-contained: nothing but the page itself was requested.
    assert len(page.requests) == 1 and page.requests[0].startswith("file://")


def test_viewer_toggles_per_vertex(page, exported):
    scene, _ = exported
    before = page.frames()
    page.page.check("#shading-per-vertex")
    page.wait_frame(before)
    assert page.page.evaluate("window.diffwashViewer.state.shading") == "per-vertex"
    assert psnr(page.canvas(), rendered(scene, "per-vertex")) >= 35
    assert page.errors() == []


def test_viewer_orbits_and_moves_the_light(page):
    first = page.canvas()
    box = page.page.locator("#view").bounding_box()
    cx, cy = box["x"] + box["width"] / 2, box["y"] + box["height"] / 2
    before = page.frames()
    page.page.mouse.move(cx, cy)
    page.page.mouse.down()
    page.page.mouse.move(cx + 40, cy + 10, steps=4)
    page.page.mouse.up()
    page.wait_frame(before)
    orbited = page.canvas()
    assert psnr(orbited, first) < 30  # the view moved (a sphere lit from the side looks different)
    eye = page.page.evaluate("window.diffwashViewer.state.eye")
    assert not np.allclose(eye, [0.0, 0.0, 3.5])
    assert np.linalg.norm(eye) == pytest.approx(3.5)  # orbiting keeps the distance to the target
    # Reset, then move the light with its slider.
    before = page.frames()
    page.page.click("#reset")
    page.wait_frame(before)
    assert psnr(page.canvas(), first) > 60
    before = page.frames()
    page.page.locator("#light-azimuth").fill("120")
    page.wait_frame(before)
    assert psnr(page.canvas(), first) < 30
    light = page.page.evaluate("window.diffwashViewer.state.light")
    assert np.linalg.norm(light) == pytest.approx(1.0)
    # The wheel zooms out.
    before = page.frames()
    page.page.mouse.move(cx, cy)
    page.page.mouse.wheel(0, 300)
    page.wait_frame(before)
    assert np.linalg.norm(page.page.evaluate("window.diffwashViewer.state.eye")) > 3.5 * 1.2
    assert page.errors() == []


def test_viewer_of_an_rt_export_and_glsl330_target(browser, tmp_path):
    scene_path = small_scene(tmp_path)
    export(scene_path, tmp_path / "rt", kind="rt", target="glsl330")
    assert (tmp_path / "rt" / "watercolour_per_pixel.frag").read_text().startswith("#version 330 core")
    p = Page(browser, (tmp_path / "rt" / "viewer.html").as_uri())
    try:
        scene = diffwash.load_scene(scene_path)
        assert psnr(p.canvas(), preview.render(scene)) >= 35
        assert p.errors() == []
    finally:
        p.close()
