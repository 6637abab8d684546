"""diffwash.widget: the Python side (what re-bakes, the LUT it sends, export, bad values) and its front end in real
headless Chromium (Debian's /usr/bin/chromium, SwiftShader WebGL2), in a small host page that plays anywidget's model
(get, set, on/off "change:...", save_changes, send), so no Jupyter server is needed: frame rate and slider latency on
the 100k-triangle knot at 512^2, and the pixels against `diffwash render` before and after sliders move."""

import base64
import json
import os
import time
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

import diffwash
from diffwash import lut as dlut
from diffwash._export import EXPORT_FILES
from diffwash._widget import RANGE_CONSTANTS, lut_bytes

from conftest import DATA, ROOT
from test_threejs import Server, inside, rendered
from test_viewer import CHROMIUM, CHROMIUM_ARGS, psnr, small_scene

pytest.importorskip("anywidget", reason="needs anywidget (pip install 'diffwash[widget]')")

KNOT = DATA / "scenes" / "knot.json"
SHOT = ROOT / "docs" / "images" / "widget.png"
BINARY = ("mesh", "lut", "look_mesh", "mix_lut")


_BAKE = dlut.bake  # the real one, where a test counts the widget's calls of `lut.bake`


def bake_bytes(params, size=256):
    return lut_bytes(_BAKE(params, size))


# ---- the Python side ---------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def sphere(tmp_path_factory):
    return diffwash.load_scene(small_scene(tmp_path_factory.mktemp("widget")))


def test_widget_sends_the_baked_lut_and_rebakes_only_for_the_table(sphere, monkeypatch):
    w = diffwash.widget(sphere)
    assert w.lut == bake_bytes(sphere.params)
    assert w.lut_range == [pytest.approx(float(sphere.params.wash_max)), pytest.approx(float(sphere.params.unlit_max))]
    assert w.config["shaders"]["per-pixel"]["frag"] == diffwash.shader_sources("webgl2", "per-pixel")[1]
    bakes = []
    original = dlut.bake
    monkeypatch.setattr(dlut, "bake", lambda *a, **k: bakes.append(1) or original(*a, **k))
    # A uniform costs nothing in Python.
    for name, value in [("gain", 0.7), ("bias", 0.3), ("shininess", 40.0), ("wash_reduction", 0.5)]:
        w.constants = {**w.constants, name: value}
    w.light = [0.0, 1.0, 1.0]
    w.shading = "per-vertex"
    assert bakes == []
    # A pigment re-bakes: the bytes are the bake of the new values.
    K = [k * 1.7 for k in w.wash["K"]]
    w.wash = {**w.wash, "K": K}
    assert len(bakes) == 1
    assert np.allclose(np.asarray(w.params.wash.K), K) and float(w.params.gain) == 0.7
    assert w.lut == bake_bytes(w.params) != bake_bytes(sphere.params)
    w.unlit = {**w.unlit, "S": [0.5, 0.1, 0.2]}
    assert len(bakes) == 2 and w.lut == bake_bytes(w.params)
    # A range constant re-bakes over the new range.
    for i, name in enumerate(RANGE_CONSTANTS):
        w.constants = {**w.constants, name: 1.5 + i}
    assert len(bakes) == 5
    assert w.lut_range == [pytest.approx(1.5 * 2.5), pytest.approx(3.5)]
    assert w.lut == bake_bytes(w.params)
    assert w.scene.shading == "per-vertex" and float(w.scene.params.bias) == 0.3


def test_rebake_time():
    """The issue's figure: a pigment change re-bakes the 256^2 LUT in <= 200 ms warm (goal 50 ms)."""
    w = diffwash.widget(KNOT)
    times = []
    for i in range(8):
        w.wash = {**w.wash, "K": [k * (1.01 + 0.01 * i) for k in w.wash["K"]]}
        times.append(w.bake_ms)
    warm = sorted(times[2:])
    print(f"widget re-bake of the 256^2 LUT after a pigment change: median {np.median(warm):.1f} ms, "
          f"max {max(warm):.1f} ms (warm, 6 changes)")  # fmt: skip
    assert np.median(warm) <= 200


def test_paper_sliders_rebake_and_repaint_the_background(sphere, monkeypatch):
    w = diffwash.widget(sphere)
    assert [s["key"] for s in w.config["paper"]] == ["paper.0", "paper.1", "paper.2"]
    assert w.paper == pytest.approx(np.asarray(sphere.params.paper).tolist())
    w.paper = [0.6, 0.5, 0.3]
    assert np.allclose(np.asarray(w.params.paper), [0.6, 0.5, 0.3]) and w.lut == bake_bytes(w.params)
    assert w.background == pytest.approx(diffwash.colorimetry.to_display(np.asarray(diffwash.shading.paper_colour(w.params))).tolist())
    assert np.allclose(np.asarray(w.scene.params.paper), [0.6, 0.5, 0.3])


def test_library_mixture_proportions_rebake():
    w = diffwash.widget(DATA / "scenes" / "mixture.json")
    assert w.config["paper"] is None and w.paper == []  # a spectral glaze's paper is per band: no slider
    with pytest.raises(diffwash.DiffwashError, match="paper"):
        w.paper = [0.5, 0.5, 0.5]
    keys = [s["key"] for s in w.config["pigments"]["wash"]["sliders"]]
    assert keys == ["mix.P4", "mix.P1", "amount"]
    w.wash = {"mix": {"P4": 0.4, "P1": 0.6}, "amount": 0.03}
    p = w.params.wash
    assert np.allclose(np.asarray(p.proportions), [0.4, 0.6]) and float(p.amount) == 0.03
    assert w.lut == bake_bytes(w.params)
    assert w.scene.params.wash.describe()["mix"] == {"P4": pytest.approx(0.4), "P1": pytest.approx(0.6)}


@pytest.mark.parametrize(
    "trait, value, field",
    [("wash", {"K": [1.0, -1.0, 1.0], "S": [0.1, 0.1, 0.1]}, "wash.K"), ("unlit", {"K": [1.0, 1.0], "S": [0.1] * 3}, "unlit.K"),
     ("wash", {"K": [float("nan")] * 3, "S": [0.1] * 3}, "wash.K"), ("wash", {"K": [0.1] * 3, "S": ["a", 1, 2]}, "wash.S"), ("constants", {"gain": "x"}, "constants.gain"),
     ("constants", {"k_wash": -1.0}, "constants.k_wash"),
     ("light", [0.0, 0.0, 0.0], "light"), ("shading", "flat", "shading"), ("paper", [1.5, 0.5, 0.5], "paper"),
     ("paper", [0.5, float("nan"), 0.5], "paper"), ("paper", [0.5, 0.5], "paper")],  # fmt: skip
)
def test_bad_values_are_refused_naming_the_field(sphere, trait, value, field):
    w = diffwash.widget(sphere)
    before, lut = getattr(w, trait), w.lut
    if trait == "constants":
        value = {**w.constants, **value}
    with pytest.raises(diffwash.DiffwashError, match=field.replace(".", r"\.")):
        setattr(w, trait, value)
    assert getattr(w, trait) == before and w.lut == lut


@pytest.mark.parametrize(
    "value, field",
    [({"granulation": 2.0}, "look.granulation"), ({"edge_width": float("nan")}, "look.edge_width"),
     ({"edge_width": -1.0}, "look.edge_width"), ({"shadow_bias": 0.1}, "look.shadow_bias"), ({"edges": 1.0}, "look.edges"),
     ({"edge_width": "wide"}, "look.edge_width")],  # fmt: skip
)
def test_bad_look_values_are_refused_naming_the_leaf(look_widget, value, field):
    w = look_widget
    before, uniforms = dict(w.look), dict(w.look_uniforms)
    with pytest.raises(diffwash.DiffwashError, match=field.replace(".", r"\.")):
        w.look = {**w.look, **value} if isinstance(value, dict) else value
    assert w.look == before and w.look_uniforms == uniforms


def test_a_plain_scene_has_no_look_to_set(sphere):
    w = diffwash.widget(sphere)
    assert w.config["look"] is None and w.look == {} and w.mix_lut == b""
    with pytest.raises(diffwash.DiffwashError, match="no watercolour look"):
        w.look = {"edge_width": 1.0}


@pytest.fixture(scope="module")
def look_widget(tmp_path_factory):
    from test_look_preview import _showcase

    return diffwash.widget(_showcase(tmp_path_factory.mktemp("look"), size=64))


def test_look_sliders_set_the_tuned_scene_and_rebake_the_mix_lut(look_widget, tmp_path):
    from diffwash._look_glsl import mix_lut

    w = look_widget
    assert w.mix_lut == np.ascontiguousarray(mix_lut(w.scene, w.params)[0]).astype("<f2").tobytes()
    weights = w.look_uniforms["look_edge_weights"]
    w.look = {**w.look, "edge_width": 6.0, "granulation": 0.2}
    assert w.look_uniforms["look_edge_weights"] != weights and w.look_uniforms["look_granulation"] == pytest.approx(0.2)
    look = w.scene.watercolour.look
    assert float(look.edge_width) == 6.0 and float(look.granulation) == pytest.approx(0.2)
    table = w.mix_lut
    w.wash = {**w.wash, "K": [k * 2 for k in w.wash["K"]]}
    assert w.mix_lut != table and w.mix_lut == np.ascontiguousarray(mix_lut(w.scene, w.params)[0]).astype("<f2").tobytes()
    w.export(tmp_path / "out")
    saved = diffwash.load_scene(tmp_path / "out" / "scene.json")
    assert float(saved.watercolour.look.edge_width) == pytest.approx(6.0)


def test_export_writes_the_tuned_scene(sphere, tmp_path):
    w = diffwash.widget(sphere)
    w.constants = {**w.constants, "gain": 0.8, "k_unlit": 2.0}
    w.wash = {**w.wash, "S": [0.3, 0.2, 0.1]}
    w.export_folder = str(tmp_path / "out")
    w._on_message(w, {"type": "export"}, [])  # what the panel's button sends
    assert w.status.startswith("exported") and sorted(p.name for p in (tmp_path / "out").iterdir()) == sorted(EXPORT_FILES)
    saved = diffwash.load_scene(tmp_path / "out" / "scene.json")
    assert float(saved.params.gain) == pytest.approx(0.8) and float(saved.params.k_unlit) == pytest.approx(2.0)
    assert np.allclose(np.asarray(saved.params.wash.S), [0.3, 0.2, 0.1])
    table = dlut.load(tmp_path / "out" / "lut.png")
    assert np.abs(np.asarray(table.values) - np.asarray(w.table.values)).max() < 1e-4
    # Again into the same folder: the previous export is replaced; into a folder of other files: refused in the status.
    w.export()
    (tmp_path / "other").mkdir()
    (tmp_path / "other" / "notes.txt").write_text("mine")
    w.export_folder = str(tmp_path / "other")
    w._on_message(w, {"type": "export"}, [])
    assert w.status.startswith("error:") and "not a diffwash export" in w.status
    assert [p.name for p in (tmp_path / "other").iterdir()] == ["notes.txt"]


# ---- the front end in Chromium -----------------------------------------------------------------------

HOST = """<!DOCTYPE html>
<html><head><meta charset="utf-8"><title>diffwash widget host</title><link rel="icon" href="data:,"><style id="css"></style></head>
<body style="margin:0; padding:8px; background:#fff"><div id="out"></div>
<script type="module">
// anywidget's model, played by the page: what the widget's render() uses of it.
const bytes = (b64) => { const s = atob(b64), out = new Uint8Array(s.length);
  for (let i = 0; i < s.length; i++) out[i] = s.charCodeAt(i); return new DataView(out.buffer); };
class Model {
  constructor(state, binary) { this.state = state; this.binary = binary; this.handlers = {}; this.pending = {}; this.saved = []; this.sent = []; }
  get(k) { return this.state[k]; }
  set(k, v) { this.state[k] = v; this.pending[k] = v; this.emit(k); }
  emit(k) { (this.handlers["change:" + k] || []).slice().forEach((f) => f()); }
  on(e, f) { (this.handlers[e] = this.handlers[e] || []).push(f); }
  off(e, f) { const h = this.handlers[e] || [], i = h.indexOf(f); if (i >= 0) h.splice(i, 1); }
  save_changes() { if (Object.keys(this.pending).length) this.saved.push(this.pending); this.pending = {}; }
  send(content) { this.sent.push(content); }
  // What the kernel sends: a state update (bytes in base64), applied first, then its change events.
  receive(update) {
    for (const k in update) this.state[k] = this.binary.includes(k) ? bytes(update[k]) : update[k];
    for (const k in update) this.emit(k);
  }
  drain() { const out = this.saved; this.saved = []; return out; }
}
const state = await (await fetch("state.json")).json();
for (const k of state.__binary__) state[k] = bytes(state[k]);
window.host = new Model(state, state.__binary__);
document.getElementById("css").textContent = state._css;
const widget = (await import("./widget.js")).default;
await widget.render({model: window.host, el: document.getElementById("out")});
document.body.dataset.ready = "1";
</script></body></html>
"""


def _state(w, keys=None):
    """The widget's synced traits as JSON (bytes as base64), as the kernel would send them."""
    state = w.get_state(keys)
    return {k: base64.b64encode(bytes(v)).decode("ascii") if k in BINARY else v for k, v in state.items()}


class Host:
    """The widget's front end in a page of its own, with the kernel's side played by the test (`sync`)."""

    def __init__(self, browser, w, folder):
        folder.mkdir()
        (folder / "widget.js").write_text(w._esm, encoding="utf-8")
        (folder / "host.html").write_text(HOST, encoding="utf-8")
        (folder / "state.json").write_text(json.dumps({**_state(w), "__binary__": list(BINARY)}), encoding="utf-8")
        self.w, self.server = w, Server(folder)
        self.page = browser.new_page(viewport={"width": 1000, "height": 900}, device_scale_factor=1)
        self.messages = []
        self.page.on("console", lambda m: self.messages.append((m.type, m.text)))
        self.page.on("pageerror", lambda e: self.messages.append(("pageerror", str(e))))
        self.page.goto(self.server.url + "host.html")
        self.page.wait_for_function("document.body.dataset.ready === '1'", timeout=120000)

    def sync(self):
        """The kernel's turn: the changes the page saved go to the Python widget, its answer back to the page."""
        changes = self.page.evaluate("window.host.drain()")
        for change in changes:
            for k, v in change.items():
                setattr(self.w, k, v)
        keys = ["lut", "lut_range", "bake_ms", "status", "background", *(["mix_lut", "look_uniforms"] if self.w.config["look"] else [])]
        self.page.evaluate("(u) => window.host.receive(u)", _state(self.w, keys))
        return changes

    def frames(self):
        return self.page.evaluate("window.diffwashWidgets[0].frames")

    def slide(self, key, value, wait=True):
        """Move a slider (its input's value, as a drag would) and wait for the frame it draws (a uniform's)."""
        before = self.frames()
        self.page.evaluate(
            "([k, v]) => { const i = document.querySelector(`input[data-key='${k}']`); i.value = v; i.dispatchEvent(new Event('input')); }",
            [key, value],
        )
        if wait:
            self.page.wait_for_function(f"window.diffwashWidgets[0].frames > {before}", timeout=30000)

    def canvas(self):
        png = self.page.locator(".dw-canvas").screenshot()
        return np.asarray(Image.open(__import__("io").BytesIO(png)).convert("RGB"), np.float64) / 255

    def errors(self):
        return [m for m in self.messages if m[0] in ("error", "pageerror", "warning")]

    def close(self):
        self.page.close()
        self.server.close()


@pytest.fixture(scope="module")
def browser():
    playwright = pytest.importorskip("playwright.sync_api", reason="needs playwright (pip install playwright)")
    if not Path(CHROMIUM).exists():
        pytest.skip(f"needs Chromium at {CHROMIUM} (Debian package chromium)")
    with playwright.sync_playwright() as p:
        b = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        yield b
        b.close()


def _with(scene, **constants):
    import dataclasses

    return dataclasses.replace(scene, params=dataclasses.replace(scene.params, **constants))


def test_front_end_draws_what_diffwash_renders_and_follows_the_sliders(browser, sphere, tmp_path):
    w = diffwash.widget(sphere)
    host = Host(browser, w, tmp_path / "host")
    try:
        shot = host.canvas()
        assert shot.shape == (sphere.height, sphere.width, 3)
        assert psnr(shot, rendered(sphere)) >= 35
        # A uniform: the page redraws by itself and tells the model; the pixels are the render at the new value.
        host.slide("gain", 0.8)
        assert host.page.evaluate("window.host.get('constants').gain") == pytest.approx(0.8, abs=1e-3)
        changes = host.sync()
        assert [list(c) for c in changes] == [["constants"]] and float(w.params.gain) == pytest.approx(0.8, abs=1e-3)
        moved = host.canvas()
        assert psnr(moved, shot) < 40  # the picture changed ...
        expected = rendered(_with(sphere, gain=float(w.params.gain)))
        assert psnr(moved, expected) >= 35  # ... as the renderer predicts
        # A pigment: the model asks Python, which re-bakes; the page draws the new table.
        before = host.frames()
        host.slide("K.0", np.log10(0.5), wait=False)  # the wash's K red (a log slider): nothing to draw before Python answers
        assert host.frames() == before
        host.sync()
        host.page.wait_for_function(f"window.diffwashWidgets[0].frames > {before}", timeout=30000)
        assert float(np.asarray(w.params.wash.K)[0]) == pytest.approx(0.5, rel=1e-2)
        repainted = host.canvas()
        assert psnr(repainted, moved) < 40
        assert psnr(repainted, rendered(w.scene)) >= 35
        # The shading mode and the light go the same way.
        before = host.frames()
        host.page.check("input[value=per-vertex]")
        host.page.wait_for_function(f"window.diffwashWidgets[0].frames > {before}", timeout=30000)
        host.sync()
        assert w.shading == "per-vertex" and psnr(host.canvas(), rendered(w.scene)) >= 35
        host.slide("azimuth", -60)
        host.sync()
        assert psnr(host.canvas(), rendered(w.scene)) >= 35
        # The paper: Python re-bakes the table over the new paper and sends the bare paper's colour back.
        before = host.frames()
        host.slide("paper.2", 0.35, wait=False)
        host.sync()
        host.page.wait_for_function(f"window.diffwashWidgets[0].frames > {before}", timeout=30000)
        assert float(np.asarray(w.params.paper)[2]) == pytest.approx(0.35, abs=1e-3)
        assert psnr(host.canvas(), rendered(w.scene)) >= 35
        # The export button sends its message; the kernel answers with the status, which the panel shows.
        host.page.click(".dw-export")
        assert host.page.evaluate("window.host.sent") == [{"type": "export"}]
        w.export_folder = str(tmp_path / "export")
        w._on_message(w, {"type": "export"}, [])
        host.sync()
        assert host.page.locator(".dw-status").text_content().startswith("exported")
        assert host.errors() == []
    finally:
        host.close()


def test_front_end_mixture_sliders(browser, tmp_path):
    """A glaze mixed from a library's pigments: its proportion sliders reach Python, whose re-baked table the page draws."""
    scene = diffwash.load_scene(DATA / "scenes" / "mixture.json")
    w = diffwash.widget(scene)
    host = Host(browser, w, tmp_path / "host")
    try:
        first = host.canvas()
        assert psnr(first, rendered(scene)) >= 35
        before = host.frames()
        host.slide("mix.P1", 0.5, wait=False)
        # A drag goes on while Python bakes: the page holds the later values back and sends the last one once.
        host.slide("mix.P1", 0.7, wait=False)
        host.slide("mix.P1", 0.9, wait=False)
        assert host.page.evaluate("window.host.saved.map((c) => c.unlit ? 'unlit' : c.wash.mix.P1)") == [0.5]
        assert host.sync() == [{"wash": {"mix": {"P4": 0.75, "P1": 0.5}, "amount": 0.02}}]
        assert host.page.evaluate("window.host.saved.map((c) => c.wash.mix.P1)") == [0.9]
        host.sync()
        host.page.wait_for_function(f"window.diffwashWidgets[0].frames > {before}", timeout=30000)
        assert w.wash["mix"]["P1"] == pytest.approx(0.9) and w.wash["mix"]["P4"] == pytest.approx(0.75)
        shot = host.canvas()
        assert psnr(shot, first) < 40 and psnr(shot, rendered(w.scene)) >= 35
        assert host.errors() == []
    finally:
        host.close()


def test_front_end_frame_rate_and_latency_on_the_knot(browser, tmp_path):
    """The issue's figures: the 100k-triangle knot at 512^2, >= 15 fps (goal 30), a slider's change on screen in
    <= 150 ms (goal 50)."""
    scene = diffwash.load_scene(KNOT)
    w = diffwash.widget(scene)
    host = Host(browser, w, tmp_path / "host")
    try:
        reference = rendered(scene)
        db, (db_inside, off) = psnr(host.canvas(), reference), inside(host.canvas(), reference)
        fps = host.page.evaluate("""(n) => { const api = window.diffwashWidgets[0]; api.draw(); api.sync();
            const t0 = performance.now(); for (let i = 0; i < n; i++) { api.draw(); api.sync(); }
            return n * 1000 / (performance.now() - t0); }""", 20)  # fmt: skip
        raf = host.page.evaluate("""(ms) => new Promise((resolve) => { const api = window.diffwashWidgets[0];
            let n = 0; const t0 = performance.now();
            const step = () => { api.draw(); n++; if (performance.now() - t0 < ms) requestAnimationFrame(step);
                                 else { api.sync(); resolve(n * 1000 / (performance.now() - t0)); } };
            requestAnimationFrame(step); })""", 3000)  # fmt: skip
        latencies = host.page.evaluate("""async (values) => { const api = window.diffwashWidgets[0], out = [];
            const input = document.querySelector("input[data-key='gain']");
            for (const v of values) { const t0 = performance.now(); const done = api.nextFrame();
                input.value = v; input.dispatchEvent(new Event("input")); out.push(await done - t0); }
            return out; }""", [0.3, 0.4, 0.5, 0.6, 0.7, 0.35, 0.45, 0.55, 0.65, 0.75])  # fmt: skip
        shot = host.canvas()
        host.sync()
        print(f"widget in Chromium (SwiftShader), knot {scene.width}x{scene.height}, {w.config['faces']} triangles: "
              f"{fps:.1f} fps drawn and finished back to back, {raf:.1f} fps on animation frames; slider to screen "
              f"median {np.median(latencies):.1f} ms, max {max(latencies):.1f} ms; first frame {db:.1f} dB against "
              f"diffwash render ({db_inside:.1f} dB without {off} silhouette pixels)")  # fmt: skip
        assert db >= 38
        # The bars hold on two quiet cores; on a machine busy with other work (a load above its cores) the
        # figures are printed and held only to a tenth of a second per frame's worth of slack, to catch breakage.
        load = os.getloadavg()[0] / (os.cpu_count() or 1)
        print(f"(load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores)")
        # Beside another pytest-xdist worker the page shares the cores with it, whatever the load average (a
        # one-minute mean) says yet.
        if load <= 1 and not os.environ.get("PYTEST_XDIST_WORKER"):
            assert fps >= 15 and raf >= 15
            assert np.median(latencies) <= 150
        else:
            assert fps >= 3 and np.median(latencies) <= 500
        assert psnr(shot, rendered(_with(scene, gain=float(w.params.gain)))) >= 38
        if os.environ.get("DIFFWASH_DOCS_IMAGES"):  # docs/widget.md's picture is this screenshot
            png = host.page.locator(".diffwash-widget").screenshot()
            SHOT.write_bytes(png)
            Image.open(SHOT).convert("RGB").save(SHOT, optimize=True)
        assert host.errors() == []
    finally:
        host.close()


def test_front_end_draws_the_watercolour_look(browser, tmp_path):
    """A scene with the watercolour look is drawn with the look's passes (look-runner.js, the viewer page's own
    source): against `diffwash render` as the viewer is (>= 38 dB); a look slider changes the picture as the
    renderer predicts, the edge width through the blur weights Python sends back; a pigment re-bakes the look's mix
    LUT; the checkbox shows the plain model."""
    from test_look_preview import _showcase

    scene = diffwash.load_scene(_showcase(tmp_path, size=256))
    w = diffwash.widget(scene)
    assert [s["label"] for s in w.config["look"]["sliders"]][:2] == ["edges.darkening", "edges.width"]
    host = Host(browser, w, tmp_path / "host")
    try:
        assert host.page.evaluate("window.diffwashWidgets[0].look")
        first = host.canvas()
        db = psnr(first, rendered(scene))
        assert db >= 38, db
        host.slide("edge_darkening", 0.0)
        assert host.sync() == [{"look": {**w.look, "edge_darkening": 0.0}}]
        moved = host.canvas()
        assert psnr(moved, first) < 40 and psnr(moved, rendered(w.scene)) >= 38
        host.slide("edge_darkening", 6.0)
        host.slide("edge_width", 8.0)
        before = host.frames()
        host.sync()  # Python's blur weights for the new width come back, and the page redraws
        host.page.wait_for_function(f"window.diffwashWidgets[0].frames > {before}", timeout=30000)
        assert float(np.asarray(w.scene.watercolour.look.edge_width)) == pytest.approx(8.0, abs=0.05)
        wide = host.canvas()
        assert psnr(wide, moved) < 40 and psnr(wide, rendered(w.scene)) >= 38
        # A pigment: Python re-bakes the 2D LUT and the look's mix LUT, and the page draws them.
        before = host.frames()
        host.slide("K.2", np.log10(3 * w.wash["K"][2]), wait=False)
        host.sync()
        host.page.wait_for_function(f"window.diffwashWidgets[0].frames > {before}", timeout=30000)
        repainted = host.canvas()
        assert psnr(repainted, wide) < 40 and psnr(repainted, rendered(w.scene)) >= 38
        fps = host.page.evaluate("""(n) => { const api = window.diffwashWidgets[0]; api.draw(); api.sync();
            const t0 = performance.now(); for (let i = 0; i < n; i++) { api.draw(); api.sync(); }
            return n * 1000 / (performance.now() - t0); }""", 10)  # fmt: skip
        print(f"widget with the watercolour look in Chromium (SwiftShader), {scene.width}^2, {w.config['faces']} "
              f"triangles: {fps:.1f} fps; first frame {db:.1f} dB against diffwash render; mix LUT re-bake "
              f"{w.bake_ms:.0f} ms with the 2D LUT")  # fmt: skip
        # The checkbox: the plain model, drawn as `diffwash render` draws the scene without its look.
        before = host.frames()
        host.page.locator(".dw-panel input[type=checkbox]").uncheck()
        host.page.wait_for_function(f"window.diffwashWidgets[0].frames > {before}", timeout=30000)
        import dataclasses

        plain = dataclasses.replace(w.scene, watercolour=None)
        assert psnr(host.canvas(), rendered(plain)) >= 35
        assert host.errors() == []
    finally:
        host.close()


def test_front_end_look_frame_rate_on_the_showcase(browser, tmp_path):
    """The watercolour showcase (`data/scenes/watercolour.json`: every effect, the 100k-triangle knot, 512^2) drawn
    with the look's six passes: frame rate and a look slider's latency, printed (docs/widget.md); held only against
    breakage, SwiftShader rendering the passes on the CPU."""
    scene = diffwash.load_scene(DATA / "scenes" / "watercolour.json")
    w = diffwash.widget(scene)
    host = Host(browser, w, tmp_path / "host")
    try:
        db = psnr(host.canvas(), rendered(scene))
        fps = host.page.evaluate("""(n) => { const api = window.diffwashWidgets[0]; api.draw(); api.sync();
            const t0 = performance.now(); for (let i = 0; i < n; i++) { api.draw(); api.sync(); }
            return n * 1000 / (performance.now() - t0); }""", 10)  # fmt: skip
        latencies = host.page.evaluate("""async (values) => { const api = window.diffwashWidgets[0], out = [];
            const input = document.querySelector("input[data-key='granulation']");
            for (const v of values) { const t0 = performance.now(); const done = api.nextFrame();
                input.value = v; input.dispatchEvent(new Event("input")); out.push(await done - t0); }
            return out; }""", [0.2, 0.3, 0.4, 0.5, 0.7, 0.9])  # fmt: skip
        host.sync()
        print(f"widget with the watercolour look (every effect), knot {scene.width}x{scene.height}, {w.config['faces']} "
              f"triangles, Chromium (SwiftShader): {fps:.1f} fps back to back; look slider to screen median "
              f"{np.median(latencies):.0f} ms; first frame {db:.1f} dB against diffwash render "
              f"(load average {os.getloadavg()[0]:.1f})")  # fmt: skip
        assert db >= 35 and fps >= 0.5
        assert psnr(host.canvas(), rendered(w.scene)) >= 35  # the granulation slider reached the shader
        if os.environ.get("DIFFWASH_DOCS_IMAGES"):  # docs/widget.md's picture of the look
            png = host.page.locator(".diffwash-widget").screenshot()
            path = ROOT / "docs" / "images" / "widget-look.png"
            path.write_bytes(png)
            Image.open(path).convert("RGB").save(path, optimize=True)
        assert host.errors() == []
    finally:
        host.close()
