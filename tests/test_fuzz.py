"""Every file reader, fuzzed (a small CI run of scripts/fuzz.py): each input loads or raises DiffwashError, nothing
else, quietly and in time; and the regressions the full run found."""

import importlib.util
import json
import struct
import sys
import zlib

import hypothesis
import numpy as np
import pytest
from conftest import ROOT

import diffwash
from diffwash import DiffwashError
from diffwash._io import read_image

_spec = importlib.util.spec_from_file_location("fuzz", ROOT / "scripts" / "fuzz.py")
fuzz = sys.modules["fuzz"] = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(fuzz)

EXAMPLES = 150


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    d = tmp_path_factory.mktemp("fuzz")
    fuzz.prepare(d)
    return d


@pytest.mark.parametrize("name", list(fuzz.READERS))
def test_reader_loads_or_refuses_every_input(name, folder):
    reader = fuzz.READERS[name]

    @hypothesis.settings(max_examples=EXAMPLES, database=None, suppress_health_check=list(hypothesis.HealthCheck))
    @hypothesis.given(drawn=reader.files, option=reader.options)
    def check(drawn, option):
        outcome = fuzz.run_one(reader, drawn, option, folder, limit=20.0)
        assert outcome.ok, f"{outcome.kind}: {outcome.detail}"

    check()


def test_the_script_counts_and_tables(capsys):
    assert fuzz.main(["-n", "14", "--seed", "1"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0].split() == ["reader", "inputs", "crashes", "hangs", "seconds"]
    rows = {line.split()[0]: line.split()[1:] for line in out[1:]}
    assert set(rows) == {*fuzz.READERS, "total"}
    assert int(rows["total"][0]) >= 14 and rows["total"][1:3] == ["0", "0"]


def test_a_crash_is_counted_not_hidden(folder):
    def read(path, option):
        raise IndexError("a reader bug")

    broken = fuzz.Reader("broken", hypothesis.strategies.just(b"{}"), read, ".json")
    tally = fuzz.fuzz(broken, 3, folder)
    assert tally.inputs >= 3 and tally.crashes == tally.inputs and "IndexError" in next(iter(tally.examples))


# Regressions: inputs the fuzzer found that crashed the readers before.


@pytest.mark.parametrize("reader", [diffwash.load_scene, diffwash.fit.read_layout, diffwash.pigments.load,
                                    diffwash.pigments.library])  # fmt: skip
@pytest.mark.parametrize("text", [b"[" * 100_000 + b"]" * 100_000, b"9" * 5000])
def test_json_nested_too_deeply_or_with_huge_integers_is_refused(tmp_path, reader, text):
    (tmp_path / "x.json").write_bytes(text)
    with pytest.raises(DiffwashError, match=r"x\.json: malformed JSON"):  # was RecursionError / ValueError
        reader(tmp_path / "x.json")


def test_a_jpeg_whose_header_claims_a_huge_size_is_refused_not_a_pillow_error(tmp_path):
    from PIL import Image

    Image.fromarray(np.zeros((8, 8, 3), np.uint8)).save(tmp_path / "a.jpg")
    data = (tmp_path / "a.jpg").read_bytes()
    i = data.find(b"\xff\xc0")
    (tmp_path / "a.jpg").write_bytes(data[: i + 5] + struct.pack(">HH", 65535, 65535) + data[i + 9 :])
    with pytest.raises(DiffwashError, match=r"a\.jpg: is 65535x65535 = 4,294,836,225 pixels by its header"):
        read_image(tmp_path / "a.jpg")  # was PIL.Image.DecompressionBombError


def test_a_png_header_that_lies_about_its_size_is_refused_at_once(tmp_path):
    import time

    ihdr = struct.pack(">IIBBBBB", 30000, 2000, 8, 2, 0, 0, 0)
    chunk = lambda k, d: struct.pack(">I", len(d)) + k + d + struct.pack(">I", zlib.crc32(k + d))  # noqa: E731
    data = b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", zlib.compress(b"\0" * 1000)) + chunk(b"IEND", b"")
    (tmp_path / "a.png").write_bytes(data)
    start = time.perf_counter()
    with pytest.raises(DiffwashError, match=r"a\.png: is 30000x2000 .* pixels by its header, over the limit of 1"):
        read_image(tmp_path / "a.png", max_pixels=10_000_000)  # was a decode of 60 M pixels that ran for seconds
    assert time.perf_counter() - start < 1.0
    with pytest.raises(DiffwashError, match=r"a\.png: not a readable PNG"):
        read_image(tmp_path / "a.png")  # within the default limit: the data ends early, said in one line


def test_a_mesh_that_trimesh_cannot_read_is_one_line_through_the_cli(run_cli, tmp_path):
    stl = b"solid \nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex -1.9 1.0 -0.3"
    (tmp_path / "bad.stl").write_bytes(stl)
    scene = {"mesh": "bad.stl", "camera": {"eye": [0, 0, 3], "target": [0, 0, 0]}, "light": {"direction": [0, 0, 1]},
             "wash": {"pigment": "Quinacridone Rose"}, "unlit": {"pigment": "French Ultramarine"}}  # fmt: skip
    (tmp_path / "scene.json").write_text(json.dumps(scene))
    r = run_cli("render", "scene.json", "-o", "out.png")
    assert r.returncode == 2 and r.stderr.startswith("diffwash: error: scene.json: mesh: ") and "bad.stl" in r.stderr
    assert len(r.stderr.splitlines()) == 1, r.stderr  # trimesh logged its tracebacks to stderr before


def test_faces_naming_missing_vertices_are_refused(tmp_path):
    (tmp_path / "m.ply").write_text("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
                                    "property float z\nelement face 2\nproperty list uchar int vertex_indices\n"
                                    "end_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n3 0 1 9\n")  # fmt: skip
    with pytest.raises(DiffwashError, match=r"m\.ply: .*faces that name vertices it does not have"):
        diffwash.load_mesh(tmp_path / "m.ply")  # was IndexError


@pytest.mark.parametrize("text", ["v 0 0\nv 1 0\nv 0 1\nf 1 2 3\n", "v 0\nv 1\nv 2\nf 1 2 3\n"])
def test_vertices_that_are_not_three_coordinates_are_refused(tmp_path, text):
    """Found by `scripts/fuzz.py` (100,000 inputs): trimesh reads an OBJ whose `v` lines hold two numbers as 2-D
    vertices, and the zero-area check then failed inside numpy.cross (ValueError, or a DeprecationWarning)."""
    (tmp_path / "m.obj").write_text(text)
    with pytest.raises(DiffwashError, match=r"m\.obj: .*vertices of [12] coordinates, not 3"):
        diffwash.load_mesh(tmp_path / "m.obj")


def test_json_readers_refuse_rather_than_crash_on_wrong_types(tmp_path):
    (tmp_path / "lib.json").write_text(json.dumps({"pigments": [{"name": "a", "K": [1, 1, 10**400], "S": [0, 0, 0]}]}))
    with pytest.raises(DiffwashError, match=r"pigments\[0\]\.K"):
        diffwash.pigments.library(tmp_path / "lib.json")


@pytest.mark.parametrize("doc, reader", [
    ({"paper": {"box": [0, 0, 1, 1], "x\ny": 1}, "patches": []}, diffwash.fit.read_layout),
    ({"mesh": "m.ply", "came\rra": {}}, diffwash.load_scene),
])  # fmt: skip
def test_an_error_about_a_key_with_a_line_break_is_still_one_line(tmp_path, doc, reader):
    (tmp_path / "x.json").write_text(json.dumps(doc))
    with pytest.raises(DiffwashError) as e:
        reader(tmp_path / "x.json")
    assert "\n" not in str(e.value) and "\r" not in str(e.value) and "\\" in str(e.value)  # was two lines


@pytest.mark.parametrize("path", ["_schema:LibraryFile", "_schema:PigmentFile", "_schema:LayoutFile",
                                  "_scene_schema:SceneFile"])  # fmt: skip
def test_the_declared_formats_give_documents_with_every_key(path):
    """The fuzzer draws documents from the formats' own declarations too: every declared key turns up (a key
    added to a format is fuzzed without anyone writing a generator for it), and some documents are valid."""
    import importlib

    module, name = path.split(":")
    model = getattr(importlib.import_module(f"diffwash.{module}"), name)
    seen, valid = set(), 0

    @hypothesis.settings(max_examples=120, database=None, derandomize=True,
                         suppress_health_check=list(hypothesis.HealthCheck))  # fmt: skip
    @hypothesis.given(fuzz.declared_docs(path))
    def draw(doc):
        nonlocal valid
        seen.update(doc)
        try:
            diffwash._schema.validate(model, doc)
            valid += 1
        except DiffwashError:
            pass

    draw()
    assert seen == {f.alias or k for k, f in model.model_fields.items()}
    assert valid > 0 or name in ("LayoutFile", "LibraryFile")  # cross-field rules (a box's x0 < x1, a library's
    # observation naming wavelengths or sRGB) random documents seldom meet
