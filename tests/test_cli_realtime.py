"""`diffwash bake`, `export` and `preview` through the real entry point."""

import json
import os
import shutil
import subprocess

import numpy as np
import pytest

import diffwash
from diffwash import lut
from diffwash._io import read_image
from diffwash._export import EXPORT_FILES

from conftest import DATA

SPHERE = DATA / "scenes" / "sphere.json"


def one_line_error(result, *needles):
    assert result.returncode == 2, result.stderr
    err = result.stderr.strip()
    assert err.startswith("diffwash: error:") and "\n" not in err, err
    assert "Traceback" not in result.stderr
    for n in needles:
        assert n in err, err


def small_scene(folder, **overrides):
    data = json.loads(SPHERE.read_text())
    data["mesh"] = str((DATA / "scenes" / data["mesh"]).resolve())
    data["image"] = {"width": 96, "height": 64}
    data.update(overrides)
    path = folder / "scene.json"
    path.write_text(json.dumps(data))
    return path


def test_bake_png16_default(run_cli, tmp_path):
    r = run_cli("bake", SPHERE, "-o", tmp_path / "lut.png", "--size", "16x8")
    assert r.returncode == 0, r.stderr
    assert "lut.json" in r.stdout
    table = lut.load(tmp_path / "lut.json")
    assert table.size == (16, 8) and table.kind == "colour"
    side = json.loads((tmp_path / "lut.json").read_text())
    assert side["storage"] == "png16" and side["encoding"] == "srgb"
    # The values are the library's bake, to the 16-bit encoding (the CLI bakes in float32, the tests in float64).
    expected = lut.bake(diffwash.load_scene(SPHERE), (16, 8))
    diff = lut.encoded(table, "png16").astype(int) - lut.encoded(expected, "png16")
    assert np.abs(diff).max() <= 1


def test_bake_exr_rt_and_npy(run_cli, tmp_path):
    r = run_cli("bake", SPHERE, "-o", tmp_path / "rt.exr", "--size", "8", "--rt")
    assert r.returncode == 0, r.stderr
    table = lut.load(tmp_path / "rt.json")
    assert table.kind == "rt" and table.values.shape == (8, 8, 6)
    r = run_cli("bake", SPHERE, "-o", tmp_path / "c.npy", "--size", "8", "--format", "npy")
    assert r.returncode == 0, r.stderr
    assert np.load(tmp_path / "c.npy").shape == (8, 8, 3)


@pytest.mark.parametrize("size", ["1", "4097", "abc", "8x1"])
def test_bake_bad_size(run_cli, tmp_path, size):
    r = run_cli("bake", SPHERE, "-o", tmp_path / "lut.png", "--size", size)
    one_line_error(r, "--size")
    assert list(tmp_path.iterdir()) == []


def test_bake_bad_output_and_scene(run_cli, tmp_path):
    r = run_cli("bake", SPHERE, "-o", tmp_path / "missing" / "lut.png", "--size", "4")
    one_line_error(r, "does not exist")
    r = run_cli("bake", SPHERE, "-o", tmp_path / "lut.tiff")
    one_line_error(r, "extension")
    data = json.loads(SPHERE.read_text())
    del data["wash"]
    data["mesh"] = str((DATA / "scenes" / data["mesh"]).resolve())
    (tmp_path / "bad.json").write_text(json.dumps(data))
    r = run_cli("bake", tmp_path / "bad.json", "-o", tmp_path / "lut.png")
    one_line_error(r, "bad.json", "wash: missing key")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.json"]


def test_export(run_cli, tmp_path):
    scene = small_scene(tmp_path)
    out = tmp_path / "out"
    r = run_cli("export", scene, "-o", out, "--size", "32", "--target", "glsl330")
    assert r.returncode == 0, r.stderr
    assert sorted(p.name for p in out.iterdir()) == sorted(EXPORT_FILES)
    assert (out / "watercolour_per_vertex.vert").read_text().startswith("#version 330 core")
    assert lut.load(out / "lut.json").size == (32, 32)
    # The exported scene loads as it is (with the GLB mesh) and renders the same picture.
    again = diffwash.load_scene(out / "scene.json")
    original = diffwash.load_scene(scene)
    np.testing.assert_allclose(again.mesh.vertices, original.mesh.vertices, atol=1e-6)
    np.testing.assert_allclose(again.mesh.normals, original.mesh.normals, atol=1e-6)
    uniforms = json.loads((out / "uniforms.json").read_text())
    assert uniforms["k_unlit"] == 1.5 and uniforms["lut_unlit_max"] == 1.5
    html = (out / "viewer.html").read_text()
    assert "http://" not in html.replace("http://www.w3.org", "") and "https://" not in html
    # A second export into the same folder needs --overwrite, and then replaces it whole.
    r = run_cli("export", scene, "-o", out, "--size", "32")
    one_line_error(r, "not empty", "--overwrite")
    r = run_cli("export", scene, "-o", out, "--size", "16", "--overwrite")
    assert r.returncode == 0, r.stderr
    assert lut.load(out / "lut.json").size == (16, 16)
    assert (out / "watercolour_per_vertex.vert").read_text().startswith("#version 300 es")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out", "scene.json"]  # no temporary folders left


def test_export_bad_input(run_cli, tmp_path):
    scene = small_scene(tmp_path)
    (tmp_path / "afile").write_text("x")
    r = run_cli("export", scene, "-o", tmp_path / "afile" / "out")
    one_line_error(r, "does not exist")
    r = run_cli("export", scene, "-o", tmp_path / "afile")
    one_line_error(r, "not a folder")
    r = run_cli("export", scene, "-o", tmp_path / "out", "--size", "5000")
    one_line_error(r, "--size", "4096")
    bad = small_scene(tmp_path, camera={"target": [0, 0, 0]})
    r = run_cli("export", bad, "-o", tmp_path / "out")
    one_line_error(r, "camera.eye: missing key")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["afile", "scene.json"]


def test_unwritable_folder(run_cli, tmp_path):
    """A folder nobody may write into (/proc, even for root): one-line errors, nothing left behind."""
    scene = small_scene(tmp_path)
    r = run_cli("export", scene, "-o", "/proc/diffwash-export", "--size", "8")
    one_line_error(r, "/proc", "cannot write")
    r = run_cli("bake", scene, "-o", "/proc/lut.png", "--size", "8")
    one_line_error(r, "/proc", "cannot write")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["scene.json"]


def test_preview_headless(run_cli, tmp_path):
    scene = small_scene(tmp_path)
    r = run_cli("preview", scene, "-o", tmp_path / "frame.png", "--shading", "per-vertex")
    assert r.returncode == 0, r.stderr
    img, bits = read_image(tmp_path / "frame.png")
    assert img.shape == (64, 96, 3) and bits == 8
    frame = diffwash.preview.render(diffwash.load_scene(scene, shading="per-vertex"))
    # The same frame, up to a level where float32 (CLI) and float64 (tests) bakes round apart.
    assert np.abs(img - frame).max() <= 1.01 / 255 and np.mean(np.abs(img - frame) > 0.5 / 255) < 1e-3
    # Through a baked LUT file.
    run_cli("bake", scene, "-o", tmp_path / "lut.png", "--format", "png8")
    r = run_cli("preview", scene, "-o", tmp_path / "frame2.png", "--lut", tmp_path / "lut.json")
    assert r.returncode == 0, r.stderr
    r = run_cli("preview", scene, "-o", tmp_path / "frame3.png", "--lut", tmp_path / "nope.json")
    one_line_error(r, "no sidecar")


def test_preview_window_needs_a_display(run_cli, tmp_path):
    r = run_cli("preview", SPHERE, "--window", env={"DISPLAY": "", "WAYLAND_DISPLAY": ""})
    one_line_error(r, "--window", "display")


def test_preview_window_under_xvfb(tmp_path):
    """A real window (glfw, GLX on Mesa) in a virtual X display shows the headless frame."""
    import sys

    from conftest import ROOT

    xvfb = shutil.which("xvfb-run")
    assert xvfb, "xvfb-run is missing: run scripts/install-system-deps"
    scene = small_scene(tmp_path)
    env = {**os.environ, "PYTHONPATH": str(ROOT), "DIFFWASH_CACHE_DIR": "off"}
    env.pop("DISPLAY", None)
    cmd = [xvfb, "-a", "-s", "-screen 0 640x480x24", sys.executable, "-m", "diffwash", "preview", str(scene)]
    r = subprocess.run([*cmd, "--window", "--frames", "3", "-o", str(tmp_path / "win.png")], env=env, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    img, _ = read_image(tmp_path / "win.png")
    frame = diffwash.preview.render(diffwash.load_scene(scene))
    assert img.shape == frame.shape
    assert np.abs(img - frame).max() <= 1.5 / 255
