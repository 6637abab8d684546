"""`diffwash render` through its entry point: images written, and bad input refused in one line."""

from __future__ import annotations

import json

import numpy as np
import png
import pytest

import diffwash
from diffwash import colorimetry

from conftest import DATA

SCENE = {
    "mesh": str(DATA / "meshes" / "knot-1k.ply"),
    "image": {"width": 48, "height": 36},
    "camera": {"eye": [0.4, 0.6, 3.0], "target": [0.0, 0.0, 0.0], "up": [0, 1, 0], "fov_y": 45},
    "light": {"direction": [1.0, 1.2, 0.8]},
    "wash": {"pigment": "Quinacridone Rose"},
    "unlit": {"pigment": "French Ultramarine"},
}


def write_scene(folder, **changes):
    data = json.loads(json.dumps(SCENE))
    for key, value in changes.items():
        target = data
        *path, last = key.split(".")
        for p in path:
            target = target[p]
        target[last] = value
    path = folder / "scene.json"
    path.write_text(json.dumps(data))
    return path


def read_png(path):
    with open(path, "rb") as f:
        w, h, rows, info = png.Reader(file=f).asDirect()
        return np.vstack([np.asarray(r) for r in rows]).reshape(h, w, info["planes"]), info


def test_render_writes_the_srgb_image(run_cli, tmp_path):
    scene_path = write_scene(tmp_path)
    out = run_cli("render", scene_path, "-o", "knot.png")
    assert out.returncode == 0, out.stderr
    assert "knot.png" in out.stdout and "48x36" in out.stdout
    img, info = read_png(tmp_path / "knot.png")
    assert img.shape == (36, 48, 3) and info["bitdepth"] == 8 and not info["alpha"]
    expect = np.asarray(colorimetry.srgb_encode(diffwash.render(diffwash.load_scene(scene_path))))
    assert np.abs(img.astype(float) - np.round(expect * 255)).max() <= 1  # float32 in the CLI, float64 here


def test_render_options(run_cli, tmp_path):
    scene_path = write_scene(tmp_path)
    out = run_cli("render", scene_path, "-o", "a.png", "--size", "40x30", "--shading", "per-vertex",
                  "--antialias", "--alpha", "--bits", "16")  # fmt: skip
    assert out.returncode == 0, out.stderr
    assert "per-vertex" in out.stdout and "antialiased" in out.stdout
    img, info = read_png(tmp_path / "a.png")
    assert img.shape == (30, 40, 4) and info["bitdepth"] == 16 and info["alpha"]
    alpha = img[..., 3] / 65535
    assert alpha.min() == 0 and alpha.max() == 1
    assert ((alpha > 0) & (alpha < 1)).sum() > 10  # antialiased edges


def _bad_mesh(folder, kind):
    path = folder / f"bad.{'obj' if kind != 'garbage' else 'ply'}"
    if kind == "garbage":
        path.write_bytes(b"ply\nformat nonsense\n\x00\x01\x02")
    elif kind == "empty":
        path.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\n")
    elif kind == "nan":
        path.write_text("v 0 0 0\nv nan 0 0\nv 0 1 0\nf 1 2 3\n")
    return path


@pytest.mark.parametrize(
    "change, field",
    [
        ({"mesh": "no-such-mesh.ply"}, "mesh"),
        ({"mesh": "garbage"}, "mesh"),
        ({"mesh": "empty"}, "mesh"),
        ({"mesh": "nan"}, "mesh"),
        ({"camera.target": [0.4, 0.6, 3.0]}, "camera.target"),
        ({"camera.up": [0.4, 0.6, 3.0]}, "camera.up"),
        ({"image.width": 0}, "image.width"),
        ({"image.height": 100000}, "image.height"),
        ({"wash.pigment": "Quinacridone Roze"}, "wash.pigment"),
    ],
)
def test_bad_scenes_are_refused_in_one_line(run_cli, tmp_path, change, field):
    change = dict(change)
    if change.get("mesh") in ("garbage", "empty", "nan"):
        change["mesh"] = str(_bad_mesh(tmp_path, change["mesh"]))
    scene_path = write_scene(tmp_path, **change)
    out = run_cli("render", scene_path, "-o", "out.png")
    assert out.returncode == 2, (out.stdout, out.stderr)
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1 and f"{field}:" in lines[0] and "scene.json" in lines[0], out.stderr
    assert not (tmp_path / "out.png").exists()
    assert not list(tmp_path.glob(".out.png*"))  # nothing half-written


@pytest.mark.parametrize(
    "args, field",
    [
        (["--size", "0x10"], "--size"),
        (["--size", "100000x10"], "--size"),
        (["--size", "big"], "--size"),
        (["-o", "out.tif"], "--output"),
        (["-o", "out.jpg", "--bits", "16"], "--output"),
        (["-o", "out.jpg", "--alpha"], "--output"),
    ],
)
def test_bad_options_are_refused_in_one_line(run_cli, tmp_path, args, field):
    scene_path = write_scene(tmp_path)
    if "-o" not in args:
        args = ["-o", "out.png", *args]
    out = run_cli("render", scene_path, *args)
    assert out.returncode == 2, (out.stdout, out.stderr)
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1 and f"{field}:" in lines[0], out.stderr
    assert not list(tmp_path.glob("out.*"))


def test_missing_scene_and_output_folder(run_cli, tmp_path):
    out = run_cli("render", tmp_path / "nope.json", "-o", "out.png")
    assert out.returncode == 2 and "nope.json" in out.stderr and len(out.stderr.strip().splitlines()) == 1
    scene_path = write_scene(tmp_path)
    out = run_cli("render", scene_path, "-o", tmp_path / "no" / "such" / "out.png")
    assert out.returncode == 2 and "does not exist" in out.stderr and len(out.stderr.strip().splitlines()) == 1
