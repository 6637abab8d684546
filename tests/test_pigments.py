"""The pigment library: exact to the seed paper, robust loading, clear errors."""

import json
import math
import re
import subprocess
import sys
import zipfile

import jsonschema
import numpy as np
import pytest
from conftest import ROOT

from diffwash import DiffwashError, pigments

SEED = ROOT / "data" / "seed"  # the seed paper's table, copied (data/seed/README.md)


def seed_table():
    """The pigment table, read from the seed paper's own text."""
    rows = {}
    for path in [SEED / "pigment-table.txt"]:
        for line in path.read_text(encoding="utf-8").splitlines():
            m = re.match(r'^\s*[a-l]\s+"([^"]+)"\s+(.*)$', line)
            if m:
                rows[m.group(1)] = [float(v) for v in m.group(2).split()]
    return rows


def test_library_is_exactly_the_seed_table():
    table = seed_table()
    assert len(table) == 12
    lib = pigments.library()
    assert list(lib) == list(table)  # same names, same order
    for name, v in table.items():
        p = lib[name]
        assert p.K.tolist() == v[0:3] and p.S.tolist() == v[3:6], name
        assert (p.density, p.staining, p.granularity) == tuple(v[6:9]), name


def test_library_file_validates_against_the_shipped_schema():
    folder = ROOT / "diffwash" / "data" / "pigments"
    schema = json.loads((folder / "schema.json").read_text())
    jsonschema.Draft202012Validator.check_schema(schema)
    jsonschema.validate(json.loads((folder / "seed.json").read_text()), schema)
    jsonschema.validate(pigments.load("Indian Red").to_dict(), schema)
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate({"name": "x", "K": [1, 2], "S": [1, 2, 3]}, schema)


@pytest.mark.parametrize("name", ["french ultramarine", "FRENCH ULTRAMARINE", "  French   Ultramarine "])
def test_names_match_case_insensitively(name):
    p = pigments.load(name)
    assert p.name == "French Ultramarine"
    assert p.K.shape == (3,) and p.S.shape == (3,)


def test_unknown_pigment_suggests_close_names():
    with pytest.raises(DiffwashError, match=r"unknown pigment 'Ultramarine Blu'.*did you mean 'French Ultramarine'"):
        pigments.load("Ultramarine Blu")


def test_single_pigment_file_and_library_file(tmp_path):
    one = tmp_path / "one.json"
    one.write_text(json.dumps({"name": "Mine", "K": [0.1, 0.2, 0.3], "S": [0.3, 0.2, 0.1]}))
    p = pigments.load(one)
    assert p.name == "Mine" and p.density == pigments.DEFAULTS["density"]
    lib = tmp_path / "lib.json"
    pigments.save(lib, [p, pigments.load("Hansa Yellow")])
    assert pigments.load(lib, name="hansa yellow").K.tolist() == [0.06, 0.21, 1.78]
    with pytest.raises(DiffwashError, match="holds 2 pigments.*say which"):
        pigments.load(lib)
    assert list(pigments.library(lib)) == ["Mine", "Hansa Yellow"]


BAD = [
    ("{not json", r"bad\.json: malformed JSON at line 1 column 2"),
    ('{"pigments": []}', r"bad\.json: pigments: must not be empty"),
    ('{"name": "x", "S": [1, 1, 1]}', r"bad\.json: K: missing key"),
    ('{"pigments": [{"name": "a", "K": [1, 1, 1], "S": [1, 1, 1]}, {"name": "b", "K": [1, 1], "S": [1, 1, 1]}]}',
     r"bad\.json: pigments\[1\]\.K: must be a list of 3 numbers .*got \[1, 1\]"),
    ('{"name": "x", "K": [1, -1, 1], "S": [1, 1, 1]}', r"bad\.json: K\[1\]: must be >= 0, got -1"),
    ('{"name": "x", "K": [1, 1, 1], "S": [1, NaN, 1]}', r"bad\.json: S\[1\]: must be a finite number, got nan"),
    ('{"name": "x", "K": [1, 1, 1], "S": [1, "1", 1]}', r"bad\.json: S\[1\]: must be a number, got '1'"),
    ('{"name": "", "K": [1, 1, 1], "S": [1, 1, 1]}', r"bad\.json: name: must not be empty"),
    ('{"name": "x", "K": [1, 1, 1], "S": [1, 1, 1], "density": -2}', r"bad\.json: density: must be >= 0, got -2"),
    ('[1, 2]', r"bad\.json: a pigment must be a JSON object, got list"),
    ('{"name": "x", "K": [1, 1, 1], "S": [1, 1, 1], "density": true}', r"bad\.json: density: must be a number, got True"),
    ('{"name": "x", "K": [1e13, 1, 1], "S": [1, 1, 1]}', r"bad\.json: K\[0\]: must be <= 1e\+12"),
    ('{"name": "  ", "K": [1, 1, 1], "S": [1, 1, 1]}', r"bad\.json: name: must not be blank"),
]


@pytest.mark.parametrize("text, message", BAD)
def test_bad_pigment_files_name_the_file_and_field(tmp_path, text, message):
    path = tmp_path / "bad.json"
    path.write_text(text)
    with pytest.raises(DiffwashError, match=message) as info:
        pigments.load(path)
    assert "\n" not in str(info.value)


def test_missing_pigment_file(tmp_path):
    with pytest.raises(DiffwashError, match="nope.json: no such pigment file"):
        pigments.load(tmp_path / "nope.json")


def test_pigment_is_a_pytree_of_its_coefficients_with_a_static_label():
    import jax

    p = pigments.load("Cadmium Red")
    leaves = jax.tree_util.tree_leaves(p)
    # K, S, and Curtis et al.'s density, staining and granularity (differentiable, for the watercolour look).
    assert len(leaves) == 5
    assert np.allclose(leaves[0], p.K) and np.allclose(leaves[1], p.S) and leaves[2:] == [0.02, 1.0, 0.63]
    doubled = jax.tree_util.tree_map(lambda x: 2 * x, p)
    assert doubled.name == "Cadmium Red" and np.allclose(doubled.K, 2 * p.K) and doubled.granularity == 1.26
    # The label is static metadata: compiled kernels take the pigment without it.
    assert pigments.unlabelled({"wash": p})["wash"].name == "pigment"
    assert jax.tree_util.tree_structure(pigments.unlabelled(p)) == jax.tree_util.tree_structure(
        pigments.unlabelled(pigments.load("Cerulean Blue")))


def test_save_round_trip(tmp_path):
    p = pigments.load("Cerulean Blue")
    pigments.save(tmp_path / "p.json", p, fit={"converged": True})
    data = json.loads((tmp_path / "p.json").read_text())
    assert data["fit"] == {"converged": True}
    q = pigments.load(tmp_path / "p.json")
    assert q.to_dict() == p.to_dict()
    assert all(math.isfinite(v) for v in q.K)


def test_the_wheel_ships_the_pigment_data(tmp_path):
    """The installed package carries its data; nothing is read from the source tree."""
    subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q", "-w", str(tmp_path), str(ROOT)],
        check=True,
        capture_output=True,
    )
    (wheel,) = tmp_path.glob("diffwash-*.whl")
    names = zipfile.ZipFile(wheel).namelist()
    assert "diffwash/data/pigments/seed.json" in names
    assert "diffwash/data/pigments/schema.json" in names
    for package in ("diffwash", "diffwash/fit", "diffwash/fit/photos", "diffwash/fit/tables", "diffwash/fit/images",
                    "diffwash/look"):  # the lazily loaded packages' public APIs
        assert f"{package}/__init__.pyi" in names
    # And it loads from an installed copy, outside the source tree.
    target = tmp_path / "site"
    zipfile.ZipFile(wheel).extractall(target)
    code = "import diffwash, sys; assert diffwash.__file__.startswith(sys.argv[1]); print(len(diffwash.pigments.library()))"
    out = subprocess.run([sys.executable, "-c", code, str(target)], cwd=tmp_path, env={"PYTHONPATH": str(target), "PATH": "/usr/bin:/bin"},
                         capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "12"
