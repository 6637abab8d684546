"""Scene files: loading, defaults, normals, and clear errors for bad input."""

import json

import numpy as np
import pytest
import trimesh
from conftest import DATA

from diffwash import DiffwashError, load_scene, save_scene
from diffwash._meshes import torus_knot
from diffwash._scene import load_mesh

BASE = {
    "mesh": "sphere.ply",
    "camera": {"eye": [0, 0, 3], "target": [0, 0, 0]},
    "light": {"direction": [1, 1, 1]},
    "wash": {"pigment": "Quinacridone Rose"},
    "unlit": {"pigment": "French Ultramarine"},
}


@pytest.fixture
def folder(tmp_path):
    trimesh.creation.icosphere(2).export(tmp_path / "sphere.ply")
    return tmp_path


def write_scene(folder, **changes):
    data = json.loads(json.dumps(BASE))
    for key, value in changes.items():
        target = data
        *path, last = key.split("__")
        for p in path:
            target = target[p]
        if value is DELETE:
            del target[last]
        else:
            target[last] = value
    path = folder / "scene.json"
    path.write_text(json.dumps(data))
    return path


DELETE = object()


def test_shipped_scenes_load():
    scene = load_scene(DATA / "scenes" / "knot.json")
    assert scene.mesh.faces.shape == (100000, 3) and scene.mesh.closed
    assert (scene.width, scene.height, scene.shading) == (512, 512, "per-pixel")
    assert scene.params.wash.name == "Quinacridone Rose"
    assert 0 < scene.camera.near < scene.camera.far
    # Every vertex lies between the near and far planes.
    view = scene.camera.target - scene.camera.eye
    depth = (scene.mesh.vertices - scene.camera.eye) @ (view / np.linalg.norm(view))
    assert depth.min() > scene.camera.near and depth.max() < scene.camera.far


def test_defaults(folder):
    scene = load_scene(write_scene(folder))
    assert (scene.width, scene.height) == (512, 512)
    assert scene.shading == "per-pixel" and scene.backfaces == "auto"
    np.testing.assert_array_equal(scene.camera.up, [0, 1, 0])
    assert float(scene.camera.fov_y) == 40
    p = scene.params
    assert (p.k_wash, p.k_specular, p.shininess, p.k_unlit, p.gain, p.bias, p.wash_reduction) == (1, 1, 20, 1, 0.5, 0.5, 0)
    np.testing.assert_array_equal(p.paper, [0.92, 0.90, 0.84])


def test_overrides(folder):
    scene = load_scene(write_scene(folder), shading="per-vertex", size=(64, 32))
    assert scene.shading == "per-vertex" and (scene.width, scene.height) == (64, 32)


def test_the_files_own_normals_are_kept(tmp_path):
    v, f, n = torus_knot(40, 8)
    flipped = -n  # unusual normals a file might carry on purpose
    trimesh.Trimesh(v, f, vertex_normals=flipped, process=False).export(tmp_path / "k.ply", vertex_normal=True)
    mesh = load_mesh(tmp_path / "k.ply")
    np.testing.assert_allclose(mesh.normals, flipped, atol=1e-6)
    trimesh.Trimesh(v, f, process=False).export(tmp_path / "plain.ply")
    mesh = load_mesh(tmp_path / "plain.ply")
    np.testing.assert_allclose(np.linalg.norm(mesh.normals, axis=1), 1, atol=1e-9)
    assert np.mean(np.sum(mesh.normals * n, axis=1)) > 0.99  # trimesh's outward normals


def test_obj_and_open_meshes(tmp_path):
    plane = trimesh.Trimesh([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], [[0, 1, 2], [1, 3, 2]], process=False)
    plane.export(tmp_path / "plane.obj")
    mesh = load_mesh(tmp_path / "plane.obj")
    assert mesh.faces.shape == (2, 3) and not mesh.closed


def test_pigment_by_file_and_by_coefficients(folder):
    (folder / "mine.json").write_text(json.dumps({"name": "Mine", "K": [1, 2, 3], "S": [0.1, 0.2, 0.3]}))
    scene = load_scene(write_scene(folder, wash={"pigment": "mine.json"}, unlit={"K": [0.5, 0.5, 0.5], "S": [0, 0, 0]}))
    assert scene.params.wash.name == "Mine" and scene.params.wash.K.tolist() == [1, 2, 3]
    assert scene.params.unlit.S.tolist() == [0, 0, 0]


def test_save_scene_round_trip(folder, tmp_path):
    scene = load_scene(write_scene(folder, shininess=7, gain=0.3))
    out = tmp_path / "sub"
    out.mkdir()
    save_scene(out / "fitted.json", scene)
    data = json.loads((out / "fitted.json").read_text())
    assert data["mesh"] == "../sphere.ply"
    again = load_scene(out / "fitted.json")
    assert float(again.params.shininess) == 7 and float(again.params.gain) == 0.3
    np.testing.assert_array_equal(again.params.wash.K, scene.params.wash.K)
    np.testing.assert_array_equal(again.mesh.vertices, scene.mesh.vertices)


BAD = [
    (dict(mesh=DELETE), r"scene\.json: mesh: missing key"),
    (dict(mesh="nope.ply"), r"scene\.json: mesh: mesh file not found"),
    (dict(camera=DELETE), r"scene\.json: camera: missing key"),
    (dict(camera__eye=DELETE), r"scene\.json: camera\.eye: missing key"),
    (dict(camera__eye=[0, 0]), r"camera\.eye: must be a list of 3 finite numbers"),
    (dict(camera__eye=[0, 0, 0]), r"camera\.target: camera\.eye and camera\.target are the same point"),
    (dict(camera__up=[0, 0, 2]), r"camera\.up: is parallel to the view direction"),
    (dict(camera__fov_y=0), r"camera\.fov_y: must be > 0"),
    (dict(camera__fov_y=180), r"camera\.fov_y: must be < 180"),
    (dict(camera__near=2, camera__far=1), r"camera\.far: must be greater than camera\.near"),
    (dict(image={"width": 0, "height": 10}), r"image\.width: must be >= 1, got 0"),
    (dict(image={"width": 10, "height": 100000}), r"image\.height: must be <= 8192, got 100000"),
    (dict(image={"width": 10.5, "height": 10}), r"image\.width: must be a whole number"),
    (dict(light=DELETE), r"light: missing key"),
    (dict(light={"direction": [0, 0, 0]}), r"light\.direction: must be a non-zero vector"),
    (dict(wash={"pigment": "Quinacridone Roze"}), r"wash\.pigment: unknown pigment 'Quinacridone Roze'.*did you mean"),
    (dict(unlit={"K": [1, 1, 1]}), r"unlit\.S: missing key"),
    (dict(unlit={"K": [1, 1, -1], "S": [1, 1, 1]}), r"unlit\.K\[2\]: must be >= 0"),
    (dict(shininess="20"), r"shininess: must be a number, got '20'"),
    (dict(gain=1.0), r"gain: must be < 1, got 1\.0"),
    (dict(k_wash=-1), r"k_wash: must be >= 0"),
    (dict(paper=[1.2, 0.9, 0.8]), r"paper: is a reflectance and must be within \[0, 1\]"),
    (dict(shading="flat"), r"shading: must be one of per-pixel, per-vertex"),
    (dict(shinyness=3), r"shinyness: unknown key; did you mean 'shininess'"),
    (dict(camera__fovy=3), r"camera\.fovy: unknown key; did you mean 'fov_y'"),
]


@pytest.mark.parametrize("changes, message", BAD)
def test_bad_scenes_name_the_field(folder, changes, message):
    with pytest.raises(DiffwashError, match=message) as info:
        load_scene(write_scene(folder, **changes))
    assert "\n" not in str(info.value)


def test_bad_meshes(folder):
    (folder / "empty.ply").write_text("ply\nformat ascii 1.0\nelement vertex 0\nelement face 0\nend_header\n")
    with pytest.raises(DiffwashError, match=r"mesh: .*(empty|no triangles)"):
        load_scene(write_scene(folder, mesh="empty.ply"))
    (folder / "garbage.ply").write_bytes(b"\x00\x01garbage")
    with pytest.raises(DiffwashError, match=r"scene\.json: mesh: "):
        load_scene(write_scene(folder, mesh="garbage.ply"))
    (folder / "nan.obj").write_text("v 0 0 0\nv 1 0 nan\nv 0 1 0\nf 1 2 3\n")
    with pytest.raises(DiffwashError, match=r"mesh: mesh .*nan\.obj has non-finite vertex coordinates"):
        load_scene(write_scene(folder, mesh="nan.obj"))


def test_scene_that_is_not_an_object(folder):
    (folder / "list.json").write_text("[]")
    with pytest.raises(DiffwashError, match=r"list\.json: a scene must be a JSON object"):
        load_scene(folder / "list.json")
