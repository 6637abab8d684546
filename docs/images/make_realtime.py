"""Make docs/images/realtime.png (the knot scene's LUT beside its OpenGL preview) and
docs/images/viewer.png (the exported viewer.html in headless Chromium).

    python docs/images/make_realtime.py
"""

import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

import matplotlib  # noqa: E402

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

import diffwash  # noqa: E402
from diffwash import lut, preview  # noqa: E402

scene = diffwash.load_scene(ROOT / "data" / "scenes" / "knot.json")
table = lut.bake(scene, 256)
frame = preview.render(scene, lut=table)

fig, (a, b) = plt.subplots(1, 2, figsize=(10, 4.6), gridspec_kw={"width_ratios": [1, 1]})
a.imshow(lut.srgb_encode(table.values), extent=(0, table.wash_max, table.unlit_max, 0), aspect="auto", interpolation="nearest")
a.set_xlabel("wash thickness (column i: i/(N-1) * wash_max)")
a.set_ylabel("unlit thickness (row j from the top: j/(M-1) * unlit_max)")
a.set_title(f"256x256 LUT: {table.meta['pigments']['wash']['name']} wash,\n{table.meta['pigments']['unlit']['name']} unlit, over paper", fontsize=10)
b.imshow(frame)
b.set_axis_off()
b.set_title("OpenGL preview through the exported shader\n(per-pixel thickness, 100k triangles, Mesa llvmpipe)", fontsize=10)
fig.tight_layout()
fig.savefig(ROOT / "docs" / "images" / "realtime.png", dpi=90)
print("wrote docs/images/realtime.png")

from playwright.sync_api import sync_playwright  # noqa: E402

with tempfile.TemporaryDirectory() as tmp:
    diffwash.export(scene, Path(tmp) / "out")
    with sync_playwright() as p:
        browser = p.chromium.launch(
            executable_path="/usr/bin/chromium",
            args=["--headless=new", "--no-sandbox", "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
                  "--disable-background-networking", "--disable-component-update", "--disable-sync", "--no-first-run"],
        )
        page = browser.new_page(viewport={"width": 900, "height": 540}, device_scale_factor=1)
        page.goto((Path(tmp) / "out" / "viewer.html").as_uri())
        page.wait_for_function("window.diffwashViewer && window.diffwashViewer.frames > 0", timeout=60000)
        page.screenshot(path=str(ROOT / "docs" / "images" / "viewer.png"))
        browser.close()
print("wrote docs/images/viewer.png")
