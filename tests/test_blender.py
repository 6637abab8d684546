"""The Blender target: the node program against the model (no Blender needed), the export's files and bad
input, and the exported knot rendered headless by Blender (`bpy`, Cycles on the CPU) against `diffwash render`."""

import json
import os
import subprocess
import sys

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from PIL import Image

import diffwash
from diffwash import shading
from diffwash._blender import (BLENDER_FILES, blender_config, bpy_available, evaluate_program,
                               look_programs, thickness_program)
from diffwash._export import EXPORT_FILES, export

from conftest import DATA, ROOT
from test_viewer import psnr

KNOT = DATA / "scenes" / "knot.json"
SHOT = ROOT / "docs" / "images" / "blender.png"
needs_bpy = pytest.mark.skipif(not bpy_available(), reason="needs Blender's bpy module (pip install 'diffwash[blender]', bpy 4.2)")


def scene_file(folder, name="knot.json", **overrides):
    """The knot scene as a file `folder/name` (its mesh by absolute path), with `overrides`."""
    data = json.loads(KNOT.read_text())
    data["mesh"] = str((KNOT.parent / data["mesh"]).resolve())
    data.update(overrides)
    path = folder / name
    path.write_text(json.dumps(data))
    return path


def thickness_inputs(params, N, V, L):
    return {"normal": N, "view": V, "light_direction": L, **{k: np.asarray(getattr(params, k), np.float64) for k in shading.CONSTANTS}}


def model_thicknesses(params, N, V, L):
    """What the shaders' `main`s compute: N, L and V normalised, then `shading.thicknesses`."""
    n, l_, v = (shading.safe_normalize(np.asarray(x, np.float64)) for x in (N, L, V))
    return [np.asarray(t) for t in shading.thicknesses(n, l_, v, params)]


def test_thickness_program_is_the_model():
    """The node program, run as Blender's nodes compute, is `shading.thicknesses`: at random points, on the
    highlight (H = N), opposite the light, at L = -V (H = 0) and with zero vectors (safe normalise)."""
    params = diffwash.load_scene(KNOT).params
    rng = np.random.default_rng(0)
    N, V = rng.normal(size=(2000, 3)), rng.normal(size=(2000, 3)) * 3
    L = np.array([1.0, 1.2, 0.8])
    edges = np.array([[L, L, L], [-L, L, L], [L, -L, L], [L, np.zeros(3), L], [np.zeros(3), L, L]])
    N, V = np.concatenate([N, edges[:, 0]]), np.concatenate([V, edges[:, 1]])
    got = evaluate_program(thickness_program(), thickness_inputs(params, N, V, L))
    want = model_thicknesses(params, N, V, L)
    np.testing.assert_allclose(got["wash"], want[0], rtol=0, atol=1e-12)
    np.testing.assert_allclose(got["unlit"], want[1], rtol=0, atol=1e-12)


@settings(max_examples=40, deadline=None)
@given(
    gain=st.floats(0, 1), bias=st.floats(0, 1), shininess=st.floats(0, 200), wash_reduction=st.floats(0, 1),
    k_unlit=st.floats(0, 5), k_specular=st.floats(0, 3), seed=st.integers(0, 2**16),
)  # fmt: skip
def test_thickness_program_follows_the_constants(gain, bias, shininess, wash_reduction, k_unlit, k_specular, seed):
    """For any constants (gain and bias at 0 and 1 included: the model clamps them), program = model."""
    base = diffwash.load_scene(KNOT).params
    params = diffwash.Params(wash=base.wash, unlit=base.unlit, gain=gain, bias=bias, shininess=shininess,
                             wash_reduction=wash_reduction, k_unlit=k_unlit, k_specular=k_specular)  # fmt: skip
    rng = np.random.default_rng(seed)
    N, V, L = rng.normal(size=(64, 3)), rng.normal(size=(64, 3)), rng.normal(size=3)
    got = evaluate_program(thickness_program(), thickness_inputs(params, N, V, L))
    want = model_thicknesses(params, N, V, L)
    assert np.all(np.isfinite(got["wash"])) and np.all(np.isfinite(got["unlit"]))
    np.testing.assert_allclose(got["wash"], want[0], rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(got["unlit"], want[1], rtol=1e-9, atol=1e-9)


def test_config_camera_and_constants_come_from_the_scene():
    scene = diffwash.load_scene(KNOT)
    table = diffwash.lut.bake(scene, 8)
    config = blender_config(scene, table)
    cam = np.asarray(config["camera"]["matrix_world"])
    # Blender's camera object matrix is the inverse of diffwash's view: it sits at the eye, looks down its -z.
    np.testing.assert_allclose(cam[:3, 3], scene.camera.eye, atol=1e-12)
    look = -cam[:3, 2]
    towards = np.asarray(scene.camera.target) - np.asarray(scene.camera.eye)
    np.testing.assert_allclose(look, towards / np.linalg.norm(towards), atol=1e-12)
    assert config["camera"]["fov_y"] == 40 and (config["width"], config["height"]) == (512, 512)
    assert config["constants"]["shininess"] == 20 and config["light_direction"] == [1.0, 1.2, 0.8]
    assert config["lut"] == {"size": [8, 8], "wash_max": 1.0, "unlit_max": 1.0}
    assert config["cull_backfaces"] and config["shading"] == "per-pixel"
    json.dumps(config)  # embedded in the script as JSON


def test_export_writes_the_script_and_its_data(tmp_path):
    """Without `bpy` too: the script and its data (the .blend is written only where `bpy` is importable)."""
    folder = tmp_path / "knot"
    written = export(scene_file(tmp_path, backfaces="both"), folder, target="blender", size=16)
    names = {p.name for p in folder.iterdir()}
    assert names == {*EXPORT_FILES, *BLENDER_FILES[: 3 if bpy_available() else 2]}
    assert {p.name for p in written} == names
    script = (folder / "blender_scene.py").read_text()
    assert "__CONFIG__" not in script and "diffwash thickness" in script and "import bpy" in script
    compile(script, "blender_scene.py", "exec")
    data = np.load(folder / "blender_data.npz")
    scene = diffwash.load_scene(KNOT)
    assert data["lut"].shape == (16, 16, 3) and data["faces"].shape == scene.mesh.faces.shape
    np.testing.assert_allclose(data["lut"], diffwash.lut.bake(scene, 16).values, atol=1e-6)
    # The shader files of the Blender target are GLSL 3.30.
    assert (folder / "watercolour_per_pixel.frag").read_text().startswith("#version 330 core")


def one_line(r, *needles):
    assert r.returncode == 2, r.stderr
    err = r.stderr.strip()
    assert "\n" not in err and "Traceback" not in err and err.startswith("diffwash") and "error:" in err, err
    for n in needles:
        assert n in err, err


def test_bad_input(run_cli, tmp_path):
    """An unknown target, an output folder holding the scene, an R/T LUT: one line, exit 2."""
    scene = scene_file(tmp_path)
    one_line(run_cli("export", scene, "-o", tmp_path / "out", "--target", "maya"), "maya")
    one_line(run_cli("export", scene, "-o", tmp_path, "--target", "blender"), "--output")
    one_line(run_cli("export", scene, "-o", tmp_path / "out", "--target", "blender", "--rt"), "rt")
    # A look with effects beyond shader nodes: refused unless --partial, which only the Blender target takes.
    look = scene_file(tmp_path, "look.json", watercolour={"shadow": True, "hatching": False})
    one_line(run_cli("export", look, "-o", tmp_path / "out", "--target", "blender"), "look.json", "watercolour", "edges, shadow",
             "--partial")
    one_line(run_cli("export", scene, "-o", tmp_path / "out", "--partial"), "--partial", "blender")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["knot.json", "look.json"]


def showcase(folder, size, drop=()):
    """The watercolour showcase on the 10k-triangle knot at `size`^2, the effects in `drop` turned off."""
    data = json.loads((DATA / "scenes" / "watercolour.json").read_text())
    data["mesh"] = str((ROOT / "data" / "meshes" / "knot-10k.ply").resolve())
    data["image"] = {"width": size, "height": size}
    for k in drop:
        data["watercolour"][k] = False
    path = folder / ("showcase.json" if not drop else "carried.json")
    path.write_text(json.dumps(data))
    return path


def test_look_programs_are_the_looks_pixel_terms(tmp_path):
    """The look's node programs are `diffwash.look.pixel_terms` (with the pixel's own local mean) and
    `paper_shading`, evaluated without Blender."""
    from diffwash import look as wl

    scene = diffwash.load_scene(showcase(tmp_path, 32))
    wc = scene.watercolour
    programs = look_programs(scene)
    rng = np.random.default_rng(1)
    names = [n for n, _ in programs["terms"]["inputs"]]
    values = {n: rng.uniform(0, 1.5, 64) for n in names}
    for n in ("turbulence_wash", "dispersion_wash", "turbulence_unlit", "dispersion_unlit"):
        values[n] = rng.normal(0, 1, 64)
    got = evaluate_program(programs["terms"], values)
    v = values
    want = wl.pixel_terms(v["wash"], v["unlit"], v["wash"], v["unlit"], v["mix"], v["stroke"], v["paper"], v["turbulence_wash"],
                          v["dispersion_wash"], v["turbulence_unlit"], v["dispersion_unlit"], wc.look, wc.pigments)  # fmt: skip
    assert np.allclose(got["wash"], np.asarray(want[0]), rtol=1e-6, atol=1e-9)
    assert np.allclose(got["unlit"], np.asarray(want[1]), rtol=1e-6, atol=1e-9)
    rgb, shade = rng.uniform(0, 1, (64, 3)), rng.normal(0, 1, 64)
    relief = evaluate_program(programs["relief"], {"rgb": rgb, "shade": shade})["rgb"]
    assert np.allclose(relief, np.asarray(wl.paper_shading(rgb, shade, wc.look.paper_shading)), rtol=1e-6, atol=1e-9)
    config = blender_config(scene, diffwash.lut.bake(scene.params, 16))
    assert config["look"]["not_carried"] == list(diffwash.BLENDER_LEAVES_OUT) and config["look"]["tile"] == list(np.asarray(wc.screen).shape[:2])


def run_script(folder, *args):
    """`python DIR/blender_scene.py ARGS` in a fresh process, as a user runs it where bpy is installed."""
    r = subprocess.run([sys.executable, str(folder / "blender_scene.py"), *map(str, args)],
                       capture_output=True, text=True, timeout=600, check=False)  # fmt: skip
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-2000:]
    return r


def reference(path, mode):
    scene = diffwash.load_scene(path, shading=mode)
    return np.round(diffwash.colorimetry.to_display(np.asarray(diffwash.render(scene))) * 255) / 255


@needs_bpy
@pytest.mark.parametrize(("mode", "engine"), [("per-pixel", "auto"), ("per-pixel", "cycles"), ("per-vertex", "cycles")])
def test_blender_draws_the_knot_as_diffwash_does(run_cli, tmp_path, mode, engine):
    """The knot (100k triangles) at 256x256, exported through the command line and rendered by Blender headless
    (`auto`: EEVEE where it draws, here on Mesa's llvmpipe; Cycles on the CPU; one sample at each pixel centre,
    the Standard view transform), against `diffwash render`."""
    scene = scene_file(tmp_path, image={"width": 256, "height": 256}, shading=mode)
    r = run_cli("export", scene, "-o", tmp_path / "out", "--target", "blender")
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "out" / "scene.blend").is_file() and "blender_scene.py --render" in r.stdout
    said = run_script(tmp_path / "out", "--render", tmp_path / "blender.png", "--engine", engine).stdout
    drew = "CYCLES" if "with CYCLES" in said else "EEVEE"
    shot = np.asarray(Image.open(tmp_path / "blender.png").convert("RGB"), np.float64) / 255
    ref = reference(scene, mode)
    assert shot.shape == ref.shape == (256, 256, 3)
    db = psnr(shot, ref)
    off = int((np.abs(shot - ref).max(axis=-1) > 2 / 255).sum())
    print(f"Blender ({engine}: {drew}), knot 256x256 {mode}: {db:.1f} dB against diffwash render, {off} pixels off by more than 2 levels")
    assert db >= 45 and off <= 10
    if engine == "auto" and os.environ.get("DIFFWASH_DOCS_IMAGES"):  # docs/blender.md's picture is this render
        Image.open(tmp_path / "blender.png").save(SHOT, optimize=True)


@needs_bpy
@pytest.mark.parametrize("mode", ["per-pixel", "per-vertex"])
def test_blender_draws_the_back_faces_of_an_open_mesh(tmp_path, mode):
    """The sphere with its cap towards the eye cut away: the inside shows, shaded with the normal turned towards
    the eye (two-sided lighting) in both modes, as `diffwash render` draws it (Cycles, 128x128)."""
    import trimesh

    sphere = DATA / "scenes" / "sphere.json"
    mesh = diffwash.load_scene(sphere).mesh
    keep = np.asarray(mesh.vertices)[np.asarray(mesh.faces)][:, :, 2].max(axis=1) < 0.5
    bowl = trimesh.Trimesh(np.asarray(mesh.vertices), np.asarray(mesh.faces)[keep], process=False)
    bowl.export(tmp_path / "bowl.ply")
    data = json.loads(sphere.read_text())
    data.update(mesh=str(tmp_path / "bowl.ply"), image={"width": 128, "height": 128}, shading=mode)
    (tmp_path / "bowl.json").write_text(json.dumps(data))
    scene = diffwash.load_scene(tmp_path / "bowl.json")
    assert not scene.cull_backfaces
    export(scene, tmp_path / "out", target="blender")
    run_script(tmp_path / "out", "--render", tmp_path / "bowl.png", "--engine", "cycles")
    shot = np.asarray(Image.open(tmp_path / "bowl.png").convert("RGB"), np.float64) / 255
    ref = reference(tmp_path / "bowl.json", mode)
    db = psnr(shot, ref)
    print(f"Blender (Cycles), open sphere 128x128 {mode}: {db:.1f} dB against diffwash render")
    assert db >= 40


@needs_bpy
@pytest.mark.parametrize("mode", ["per-pixel", "per-vertex"])
def test_rotating_the_sun_moves_the_models_light(tmp_path, mode):
    """`diffwash light` drives the node groups' Light Direction: turned towards another direction in Blender,
    the render is `diffwash render` with that light (Cycles, 128x128)."""
    scene = scene_file(tmp_path, image={"width": 128, "height": 128}, shading=mode)
    export(scene, tmp_path / "out", target="blender")
    other = [-1.0, 0.5, 0.7]
    code = f"""
import sys
sys.path.insert(0, {str(tmp_path / "out")!r})
import bpy, blender_scene
from mathutils import Vector
blender_scene.build({mode!r})
blender_scene.render_settings((128, 128))
sun = bpy.data.objects["diffwash light"]
sun.rotation_quaternion = Vector({other}).normalized().to_track_quat("Z", "Y")
blender_scene.render({str(tmp_path / "moved.png")!r}, "cycles", (128, 128))
"""
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600, check=False)
    assert r.returncode == 0, r.stderr[-2000:]
    shot = np.asarray(Image.open(tmp_path / "moved.png").convert("RGB"), np.float64) / 255
    moved = scene_file(tmp_path, "moved.json", image={"width": 128, "height": 128}, shading=mode, light={"direction": other})
    db, before = psnr(shot, reference(moved, mode)), psnr(shot, reference(scene, mode))
    print(f"Blender (Cycles), knot 128x128 {mode}, the sun turned: {db:.1f} dB against diffwash render with that light ({before:.1f} dB with the scene's)")
    assert db >= 45 and before < 30


@needs_bpy
def test_blender_draws_the_looks_per_pixel_effects(run_cli, tmp_path):
    """The watercolour showcase exported for Blender and rendered headless (EEVEE where it draws): its paper,
    unevenness, strokes and mix as `diffwash render` draws them with the effects shader nodes cannot carry (edge
    darkening, the own shadow, hatching) turned off; the script names those it leaves out."""
    full = showcase(tmp_path, 256)
    r = run_cli("export", full, "-o", tmp_path / "out", "--target", "blender", "--partial")
    assert r.returncode == 0, r.stderr
    assert "not its edges, shadow, hatching (beyond shader nodes" in r.stdout, r.stdout
    said = run_script(tmp_path / "out", "--render", tmp_path / "blender.png").stdout
    assert "edges, shadow, hatching are not carried" in said, said
    drew = "CYCLES" if "with CYCLES" in said else "EEVEE"
    shot = np.asarray(Image.open(tmp_path / "blender.png").convert("RGB"), np.float64) / 255
    carried = showcase(tmp_path, 256, drop=tuple(diffwash.BLENDER_LEAVES_OUT))
    db, everything = psnr(shot, reference(carried, "per-pixel")), psnr(shot, reference(full, "per-pixel"))
    off = int((np.abs(shot - reference(carried, "per-pixel")).max(axis=-1) > 2 / 255).sum())
    print(f"Blender ({drew}), watercolour showcase 256x256: {db:.1f} dB against diffwash render of the effects it "
          f"carries ({off} pixels off by more than 2 levels), {everything:.1f} dB against the whole look")  # fmt: skip
    assert db >= 40 and off <= 20
    if os.environ.get("DIFFWASH_DOCS_IMAGES"):  # docs/blender.md's picture of the look
        Image.open(tmp_path / "blender.png").save(ROOT / "docs" / "images" / "blender-look.png", optimize=True)
