"""Issue 23: one declared schema per file kind (scene with its watercolour object, layout, measurement and query
tables), checked before anything is computed, with one-line errors naming the file and the key (or line and
column), and the docs' format tables written from the same declarations."""

import importlib.machinery
import importlib.util
import json
import os
import subprocess
import sys

import numpy as np
import pytest
from conftest import ROOT
from hypothesis import given, settings
from hypothesis import strategies as st

from diffwash import _schema, _scene_schema, measurements
from diffwash import look as wl
from diffwash._errors import DiffwashError

_spec = importlib.util.spec_from_loader("format_tables", importlib.machinery.SourceFileLoader(
    "format_tables", str(ROOT / "scripts" / "format-tables")))  # fmt: skip
format_tables = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(format_tables)


@pytest.mark.parametrize("doc", list(format_tables.DOC_MODELS))
def test_the_docs_format_tables_are_the_declarations(doc):
    text = (ROOT / "docs" / doc).read_text()
    for model in format_tables.DOC_MODELS[doc]:
        assert format_tables.block(model) in text, f"docs/{doc}: the table of {model.__name__} differs from its declaration"


def test_the_script_rewrites_a_stale_table_and_check_finds_it(tmp_path, monkeypatch):
    docs = tmp_path / "docs"
    docs.mkdir()
    for doc in format_tables.DOC_MODELS:
        (docs / doc).write_text((ROOT / "docs" / doc).read_text())
    stale = (docs / "pigments.md").read_text().replace("absorption per unit thickness, one per band", "stale words", 1)
    (docs / "pigments.md").write_text(stale)
    monkeypatch.setattr(format_tables, "ROOT", tmp_path)
    monkeypatch.setattr(sys, "argv", ["format-tables", "--check"])
    assert format_tables.main() == 1 and (docs / "pigments.md").read_text() == stale
    monkeypatch.setattr(sys, "argv", ["format-tables"])
    assert format_tables.main() == 0
    assert (docs / "pigments.md").read_text() == (ROOT / "docs" / "pigments.md").read_text()


SCENE = json.loads((ROOT / "data" / "scenes" / "knot.json").read_text())


def _set(data, path, value):
    data = json.loads(json.dumps(data))
    *head, last = path
    obj = data
    for k in head:
        obj = obj.setdefault(k, {}) if isinstance(k, str) else obj[k]
    obj[last] = value
    return data


# (where, a wrong value, the key the error names, words it says)
SCENE_BAD = [
    (("k_wash",), "1", "k_wash", "must be a number"),
    (("k_wash",), True, "k_wash", "must be a number"),
    (("k_wash",), -0.5, "k_wash", "must be >= 0"),
    (("k_wash",), 1e39, "k_wash", "float32"),
    (("bias",), 0, "bias", "must be > 0"),
    (("wash_reduction",), 1.5, "wash_reduction", "must be <= 1"),
    (("camera", "eye"), [0, 0, float("nan")], "camera.eye[2]", "finite"),
    (("camera", "target"), [0, 0], "camera.target", "3 finite numbers"),
    (("camera", "up", 1), -3e38 * 10, "camera.up[1]", "float32"),
    (("camera", "near"), 0, "camera.near", "must be > 0"),
    (("image", "height"), 512.0, "image.height", "whole number"),
    (("image", "width"), 9000, "image.width", "<= 8192"),
    (("light", "direction"), [0, 0, 0], "light.direction", "non-zero"),
    (("backfaces",), "front", "backfaces", "auto, cull, both"),
    (("wash",), {"K": [1, 1, 1], "S": [1, 1, "x"]}, "wash.S[2]", "must be a number"),
    (("unlit",), {"pigment": "Hookers Green", "colour": 1}, "unlit.colour", "unknown key"),
    (("unlit",), {"library": "l.json", "mix": {"P1": 0.5, "p1": 0.5}}, "unlit.mix.p1", "again"),
    (("unlit",), {"library": "l.json", "pigment": "P1", "amount": -1}, "unlit.amount", "must be > 0"),
    (("paper",), {"ground": ""}, "paper.ground", "not be empty"),
    (("watercolour",), {"edges": {"width": 1e40}}, "watercolour.edges.width", "float32"),
    (("watercolour",), {"hatching": {"scale": 0}}, "watercolour.hatching.scale", "must be > 0"),
    (("watercolour",), {"strokes": {"seed": 2**32}}, "watercolour.strokes.seed", "< 4.29497e+09"),
    (("watercolour",), {"mix": {"map": {"axis": [0, 1, 0], "softness": 11}}}, "watercolour.mix.map.softness", "<= 10"),
    (("watercolour",), {"mix": {"map": "m.npy", "wash": 3}}, "watercolour.mix.wash", "must be {"),
    (("watercolour",), {"paper": "rough"}, "watercolour.paper", "JSON object or false"),
]  # fmt: skip


@pytest.mark.parametrize("path, value, key, words", SCENE_BAD, ids=[c[2] for c in SCENE_BAD])
def test_the_scene_schema_refuses_at_the_named_key(path, value, key, words):
    with pytest.raises(DiffwashError) as e:
        _schema.validate(_scene_schema.SceneFile, _set(SCENE, path, value), "s.json", what="scene")
    msg = str(e.value)
    assert msg.startswith(f"s.json: {key}: ") and words in msg and "\n" not in msg, msg


def test_every_look_leaf_is_a_declared_key_with_its_default_and_bound():
    for spec in wl.leaf_specs().values():
        field = _scene_schema.EFFECT_MODELS[spec.effect].model_fields[spec.key]
        assert field.default == spec.on and field.description == spec.doc
        too_big = (spec.at_most or 1e30) * 2
        with pytest.raises(DiffwashError, match=rf"watercolour\.{spec.effect}\.{spec.key}: must be "):
            _schema.validate(_scene_schema.SceneFile, _set(SCENE, ("watercolour", spec.effect, spec.key), -1.0))
        if spec.at_most is not None:
            with pytest.raises(DiffwashError, match=rf"must be <= {spec.at_most:g}"):
                _schema.validate(_scene_schema.SceneFile, _set(SCENE, ("watercolour", spec.effect, spec.key), too_big))


@settings(max_examples=60, deadline=None)
@given(st.sampled_from(["k_wash", "shininess", ("camera", "fov_y"), ("camera", "far")]),
       st.floats(min_value=3.5e38, max_value=1.7e308))  # fmt: skip
def test_numbers_beyond_float32_are_refused_at_their_key(key, value):
    path = key if isinstance(key, tuple) else (key,)
    with pytest.raises(DiffwashError, match=rf"{'.'.join(path)}: .*float32"):
        _schema.validate(_scene_schema.SceneFile, _set(SCENE, path, value), "s.json")


LAYOUT = {"paper": {"box": [0, 0, 10, 10]}, "patches": [{"box": [20, 20, 30, 30], "coats": 1, "ground": "paper"}]}
LAYOUT_BAD = [
    (("paper", "box"), [0, 0, 10], "paper.box", "4 pixel coordinates"),
    (("paper", "box", 2), 10.5, "paper.box[2]", "whole pixel"),
    (("paper", "box", 3), 1e39, "paper.box[3]", "float32"),
    (("paper", "reflectance"), [0.9, 0, 0.8], "paper.reflectance[1]", "must be > 0"),
    (("patches", 0, "coats"), [1], "patches[0].coats", "coats > 0"),
    (("patches", 0, "coats"), True, "patches[0].coats", "coats > 0"),
    (("patches", 0, "ground"), "Paper", "patches[0].ground", "paper, black"),
    (("patches", 0, "pigment"), " ", "patches[0].pigment", "blank"),
    (("patches", 0, "size"), 3, "patches[0].size", "unknown key"),
    (("black",), {"box": [5, 5, 5, 9]}, "black.box", "is empty"),
    (("references",), [{"box": [0, 0, 1, 1], "lab": [50, 0, -201]}], "references[0].lab[2]", ">= -200"),
    (("references",), [{"box": [0, 0, 1, 1], "spectrum": [0.5, 2.0], "wavelengths": [400, 700]}],
     "references[0].spectrum[1]", "<= 1.5"),
    (("references",), [{"box": [0, 0, 1, 1], "spectrum": [0.5], "wavelengths": [400, 700]}],
     "references[0].spectrum", "2 reflectances"),
    (("name",), 7, "name", "must be text"),
]  # fmt: skip


@pytest.mark.parametrize("path, value, key, words", LAYOUT_BAD, ids=[c[2] for c in LAYOUT_BAD])
def test_the_layout_schema_refuses_at_the_named_key(path, value, key, words):
    from diffwash.fit import parse_layout

    with pytest.raises(DiffwashError) as e:
        parse_layout(_set(LAYOUT, path, value), file="card.json")
    msg = str(e.value)
    assert msg.startswith(f"card.json: {key}: ") and words in msg and "\n" not in msg, msg


HEAD = "pigment,amount,ground,400,500,600\npaper,0,paper,0.8,0.8,0.8\n"
TABLE_BAD = [
    (HEAD + "P1,0.01,paper,0.2,abc,0.3\n", "line 3: 500", "not a number: 'abc'"),
    (HEAD + "P1,0.01,paper,0.2,0.3,nan\n", "line 3: 600", "finite"),
    (HEAD + "P1,0.01,paper,0.2,-0.1,0.3\n", "line 3: 500", "must be >= 0, got -0.1"),
    (HEAD + "P1,0.01,paper,1e39,0.1,0.3\n", "line 3: 400", "float32"),
    (HEAD + "P1,0.01, ,0.2,0.1,0.3\n", "line 3: ground", "blank"),
    ("pigment,amount,ground,r,g,b\npaper,0,paper,240,240,x\n", "line 2: b", "not a number"),
]  # fmt: skip


@pytest.mark.parametrize("table, where, words", TABLE_BAD, ids=[c[1] for c in TABLE_BAD])
def test_the_table_schema_refuses_at_the_named_line_and_column(tmp_path, table, where, words):
    (tmp_path / "t.csv").write_text(table)
    with pytest.raises(DiffwashError) as e:
        measurements.read_measurements(tmp_path / "t.csv")
    assert str(e.value).startswith(f"{tmp_path / 't.csv'}: {where}: ") and words in str(e.value), str(e.value)
    (tmp_path / "q.csv").write_text(table.replace(",0.8,0.8,0.8", ",,,").replace("paper,0,paper,240,240,x", "P1,1, ,1,2,3"))
    if "ground" in where:
        with pytest.raises(DiffwashError, match="line 3: ground: must not be blank"):
            measurements.read_queries(tmp_path / "q.csv")


def test_four_thousand_rows_are_checked_in_one_call(tmp_path):
    """Every row of a table at the row limit is checked (its speed: `python benchmarks/bench_schema.py`)."""
    rng = np.random.default_rng(0)
    waves = range(380, 790, 10)
    rows = [f"P{i % 7},{rng.uniform(0.01, 0.05):.4f},paper," + ",".join(f"{v:.4f}" for v in rng.uniform(0, 1, 41))
            for i in range(3999)]  # fmt: skip
    text = "pigment,amount,ground," + ",".join(map(str, waves)) + "\npaper,0,paper," + ",".join(["0.85"] * 41) + "\n"
    (tmp_path / "t.csv").write_text(text + "\n".join(rows) + "\n")
    header, body = measurements._read_csv(tmp_path / "t.csv")
    col = measurements._key_columns(header, tmp_path)
    vcols, _ = measurements._band_columns(header, tmp_path)
    checked = measurements._checked_rows("MeasurementRow", body, header, col, vcols, tmp_path)
    assert len(checked) == 4000


def test_pydantic_loads_only_when_a_file_is_checked():
    code = "import sys, runpy\nimport diffwash\nassert 'pydantic' not in sys.modules\nsys.argv = ['diffwash', '--help']\n" \
           "try:\n    runpy.run_module('diffwash', run_name='__main__')\nexcept SystemExit:\n    pass\n" \
           "print('pydantic' in sys.modules, file=sys.stderr)\n"  # fmt: skip
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    run = subprocess.run([sys.executable, "-c", code], env=env, cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert run.returncode == 0 and run.stderr.strip().splitlines()[-1] == "False", run.stderr
