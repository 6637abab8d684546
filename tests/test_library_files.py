"""One library everywhere: what the three-channel fits write is a library that `predict`, scenes and `fit-image`
read, and pigment files of the older kind load wherever a library is read (converted on load)."""

import json

import numpy as np
import pytest
from conftest import DATA

import diffwash
from diffwash import DiffwashError, km, pigments
from diffwash.library import library_from_dict, library_from_pigments, load_library

RED = pigments.Pigment(K=np.array([0.2, 2.0, 3.0]), S=np.array([1.5, 0.4, 0.3]), name="Red", density=0.1,
                       staining=2.0, granularity=0.7)  # fmt: skip
GREEN = pigments.Pigment(K=np.array([2.5, 0.3, 1.8]), S=np.array([0.2, 0.6, 0.1]), name="Green")
PAPER, BLACK = [0.85, 0.84, 0.80], [0.03, 0.03, 0.035]


def _km(p, thickness, ground):
    return np.asarray(km.over(*km.layer(np.asarray(p.K), np.asarray(p.S), np.asarray(thickness)[:, None]),
                              np.asarray(ground)))  # fmt: skip


def test_an_old_table_fit_loads_as_a_library_with_its_amount_law_and_grounds(tmp_path):
    """`fit-swatch --table` wrote pigment files with each pigment's exponent and the grounds in its record."""
    fit = {"model": {"thickness": "power", "surface": "none"}, "paper": PAPER, "black": BLACK,
           "pigments": {"Red": {"thickness_exponent": 0.7}, "Green": {"thickness_exponent": 1.2}}}  # fmt: skip
    pigments.save(tmp_path / "old.json", [RED, GREEN], fit=fit)
    lib = load_library(tmp_path / "old.json")
    assert lib.names == ("Red", "Green") and not lib.spectral and sorted(lib.grounds) == ["black", "paper"]
    pred = lib.predict(["Red", "Green", "Red"], [[0.05], [0.5], [2.0]], ["paper", "black", "black"])
    want = [_km(RED, [0.05**0.7], PAPER)[0], _km(GREEN, [0.5**1.2], BLACK)[0], _km(RED, [2.0**0.7], BLACK)[0]]
    np.testing.assert_allclose(pred.linear_srgb, want, rtol=1e-5, atol=1e-7)


def test_an_old_single_pigment_file_and_the_seed_library_load_as_libraries(tmp_path):
    pigments.save(tmp_path / "one.json", RED, fit={"paper": PAPER})  # what fit-swatch PHOTO wrote
    lib = load_library(tmp_path / "one.json")
    assert lib.names == ("Red",) and list(lib.grounds) == ["paper"]
    np.testing.assert_allclose(lib.predict(["Red"], [[2.0]]).linear_srgb[0], _km(RED, [2.0], PAPER)[0], rtol=1e-5)
    seed = load_library(DATA.parent / "diffwash" / "data" / "pigments" / "seed.json")  # no record: the shading model's paper
    assert len(seed.names) == 12 and np.allclose(seed.grounds["paper"], diffwash.shading.DEFAULT_PAPER)


def test_a_three_channel_library_is_a_pigment_file_too(tmp_path):
    lib = library_from_pigments([RED, GREEN], gamma=[0.7, 1.0], grounds={"paper": PAPER, "black": BLACK})
    lib.save(tmp_path / "lib.json")
    d = json.loads((tmp_path / "lib.json").read_text())
    assert d["format"] == "diffwash-library" and d["observation"] == {"bands": "sRGB"}
    red = pigments.load(tmp_path / "lib.json", name="red")
    assert red == RED  # K, S, density, staining, granularity and name, as the renderer reads them
    again = library_from_dict(d)
    np.testing.assert_allclose(again.predict(["Red+Green"], ["0.5+0.5"]).linear_srgb,
                               lib.predict(["Red+Green"], ["0.5+0.5"]).linear_srgb)  # fmt: skip
    assert again.extras[0] == {"density": 0.1, "staining": 2.0, "granularity": 0.7}


def test_scenes_read_libraries_and_old_pigment_files_both_ways(tmp_path):
    pigments.save(tmp_path / "old.json", [RED, GREEN], fit={"paper": PAPER})
    library_from_pigments([RED, GREEN], grounds={"paper": PAPER}).save(tmp_path / "new.json")
    base = {"mesh": str(DATA / "meshes" / "sphere.ply"), "image": {"width": 16, "height": 16},
            "camera": {"eye": [0, 0, 3.5], "target": [0, 0, 0]}, "light": {"direction": [-1, 1, 1]}}  # fmt: skip
    scenes = {
        "pigment-refs.json": {"wash": {"pigment": "new.json", "name": "Red"}, "unlit": {"pigment": "old.json", "name": "Green"}},
        "library-refs.json": {"wash": {"library": "old.json", "pigment": "Red"}, "unlit": {"library": "new.json", "pigment": "Green"}},
    }  # fmt: skip
    images = {}
    for name, glazes in scenes.items():
        (tmp_path / name).write_text(json.dumps({**base, **glazes, "paper": PAPER}))
        images[name] = np.asarray(diffwash.render(diffwash.load_scene(tmp_path / name)))
    # a pigment by reference or the same pigment from its library at its reference amount: the same picture
    np.testing.assert_allclose(images["pigment-refs.json"], images["library-refs.json"], atol=1e-5)


def test_a_spectral_library_is_refused_as_a_three_channel_pigment():
    with pytest.raises(DiffwashError, match="spectral pigment library"):
        pigments.load(DATA / "libraries" / "ntu-four.json", name="P1")


def test_predict_reads_an_old_pigment_file(run_cli, tmp_path):
    pigments.save(tmp_path / "old.json", RED, fit={"paper": PAPER})
    (tmp_path / "q.csv").write_text("pigment,amount,ground\nRed,1,paper\nRed,3,paper\n")
    r = run_cli("predict", "old.json", "--table", "q.csv", "-o", "p.csv")
    assert r.returncode == 0, r.stderr
    rows = (tmp_path / "p.csv").read_text().splitlines()[1:]
    got = np.array([[float(v) for v in row.split(",")[3:6]] for row in rows]) / 255
    want = np.asarray(diffwash.colorimetry.srgb_encode(_km(RED, [1.0, 3.0], PAPER)))
    np.testing.assert_allclose(got, want, atol=2e-4)


def test_queries_match_names_as_tables_do_and_take_a_tables_bare_ground_rows(run_cli, tmp_path):
    """A query names a pigment ignoring case and runs of spaces (as tables and pigment files do), and a
    measurement table's bare-ground row (`paper,0,paper`) predicts that ground: a table is a query table."""
    lib = library_from_pigments([RED, GREEN], grounds={"paper": PAPER, "black": BLACK})
    lib.save(tmp_path / "lib.json")
    (tmp_path / "q.csv").write_text("pigment,amount,ground\npaper,0,paper\n  red ,1,paper\nRed,1,paper\n"
                                    "GREEN+red,0.5+0.5,black\nBlack,0,black\n")  # fmt: skip
    r = run_cli("predict", "lib.json", "--table", "q.csv", "-o", "p.csv")
    assert r.returncode == 0, r.stderr
    rows = [row.split(",") for row in (tmp_path / "p.csv").read_text().splitlines()[1:]]
    rgb = np.array([[float(v) for v in row[3:6]] for row in rows]) / 255
    want = np.asarray(diffwash.colorimetry.srgb_encode(np.array([PAPER, BLACK])))
    np.testing.assert_allclose(rgb[[0, 4]], want, atol=2e-4)
    np.testing.assert_allclose(rgb[1], rgb[2])
    # A ground with paint on it is no pigment: refused as before, naming the file, line and column.
    (tmp_path / "bad.csv").write_text("pigment,amount,ground\npaper,0.1,paper\n")
    r = run_cli("predict", "lib.json", "--table", "bad.csv", "-o", "p2.csv")
    assert r.returncode == 2 and "bad.csv: line 2: pigment: no pigment 'paper'" in r.stderr, r.stderr
    assert not (tmp_path / "p2.csv").exists()


@pytest.mark.parametrize("name, joins", [("Sap+Green", "the names of a mixture"), ("Sap/Green", "the layers of a glaze stack")])
def test_a_library_name_that_no_query_could_name_is_refused(tmp_path, name, joins):
    library_from_pigments([RED], grounds={"paper": PAPER}).save(tmp_path / "lib.json")
    d = json.loads((tmp_path / "lib.json").read_text())
    d["pigments"][0]["name"] = name
    (tmp_path / "bad.json").write_text(json.dumps(d))
    with pytest.raises(DiffwashError) as e:
        load_library(tmp_path / "bad.json")
    assert str(e.value) == f"{tmp_path / 'bad.json'}: pigments[0].name: must not hold '{name[3]}' (it joins {joins}), got {name!r}"
