"""`diffwash swatch-card`, `fit-swatch` and `fit-image` through the real entry point: results, reports and bad input."""

import json

import numpy as np
import pytest
from conftest import DATA
from PIL import Image

import diffwash
from diffwash import colorimetry, pigments
from diffwash._io import write_png
from diffwash.swatchcard import CameraEffects, make_swatch_card, save_swatch_card
from test_fit_table import NTU, ntu_split


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    """One JAX compilation cache for this module's successful runs (bad input fails before compiling)."""
    return {"DIFFWASH_CACHE_DIR": str(tmp_path_factory.mktemp("jax-cache"))}


def leftovers(folder, *names):
    """Files a failed command must not have written: the outputs and any temporary parts."""
    return [p.name for p in folder.iterdir() if p.name in names or p.name.endswith(".part")]


def test_swatch_card_then_fit_swatch(run_cli, tmp_path, cache):
    r = run_cli("swatch-card", "Quinacridone Rose", "-o", "card.jpg", "--coats", "1,2,3", env=cache)
    assert r.returncode == 0, r.stderr
    assert "wrote card.jpg" in r.stdout and json.loads((tmp_path / "card.json").read_text())["name"] == "Quinacridone Rose"
    r = run_cli("fit-swatch", "card.jpg", "--layout", "card.json", "-o", "rose.json", "--report", "report.png", env=cache)
    assert r.returncode == 0, r.stderr
    assert "mean CIEDE2000" in r.stdout and "both identifiable" in r.stdout and "wrote rose.json" in r.stdout
    assert "90% regions of predict: the posterior above and a model error (CIELAB units per axis) single" in r.stdout
    (tmp_path / "q.csv").write_text("pigment,amount,ground\nQuinacridone Rose,4,paper\n")
    r = run_cli("predict", "rose.json", "--table", "q.csv", "-o", "p.csv", env=cache)
    assert r.returncode == 0, r.stderr
    row = (tmp_path / "p.csv").read_text().splitlines()
    assert 0 < float(row[1].split(",")[row[0].split(",").index("de2000_90")]) < 2
    fitted = pigments.load(tmp_path / "rose.json")
    assert fitted.name == "Quinacridone Rose"
    np.testing.assert_allclose(fitted.K, pigments.load("Quinacridone Rose").K, rtol=0.1)
    diag = json.loads((tmp_path / "rose.json").read_text())["fit"]
    assert diag["converged"] and len(diag["patches"]) == 6 and diag["mean_delta_e_2000"] < 1
    with Image.open(tmp_path / "report.png") as im:
        assert im.format == "PNG" and im.width > 600


def ntu_csv(path, table):
    """Write a measurement table in the documented CSV format (8-bit sRGB, the paper as a row)."""
    enc = lambda lin: np.round(255 * np.asarray(colorimetry.srgb_encode(lin))).astype(int)  # noqa: E731
    lines = ["pigment,amount,ground,r,g,b", "paper,0,paper," + ",".join(map(str, enc(table.paper)))]
    for n, a, g, c in zip(table.pigment, table.amount, table.ground, table.rgb):
        lines.append(f"{n},{a:g},{g}," + ",".join(map(str, enc(c))))
    path.write_text("\n".join(lines) + "\n")


def test_fit_swatch_table(run_cli, tmp_path, cache):
    table, train, test = ntu_split()
    ntu_csv(tmp_path / "train.csv", train)
    assert (tmp_path / "train.csv").read_text().splitlines()[1] == "paper,0,paper,240,240,235"
    r = run_cli("fit-swatch", "--table", "train.csv", "-o", "lib.json", "--report", "table.png", env=cache)
    assert r.returncode == 0, r.stderr
    assert "7 pigments from 42 measurements" in r.stdout and "Sap Green" in r.stdout
    lib = pigments.library(tmp_path / "lib.json")
    assert list(lib) == table.names
    fit = json.loads((tmp_path / "lib.json").read_text())["fit"]
    assert fit["model"]["thickness"] == "power" and all(d["converged"] for d in fit["pigments"].values())
    assert (tmp_path / "table.png").stat().st_size > 10_000
    # What it wrote is a library that `predict` reads: the held-out amounts through the command line, as a user
    # would (the figure of docs/fitting.md, 1.48 mean CIEDE2000, there clipped to the sRGB cube as measured).
    assert json.loads((tmp_path / "lib.json").read_text())["format"] == "diffwash-library"
    queries = ["pigment,amount,ground"] + [f"{n},{a:g},{g}" for n, a, g in zip(test.pigment, test.amount, test.ground)]
    (tmp_path / "q.csv").write_text("\n".join(queries) + "\n")
    r = run_cli("predict", "lib.json", "--table", "q.csv", "-o", "pred.csv", env=cache)
    assert r.returncode == 0, r.stderr
    rows = (tmp_path / "pred.csv").read_text().splitlines()
    assert rows[0].split(",")[:9] == ["pigment", "amount", "ground", "r", "g", "b", "L*", "a*", "b*"]
    lab = np.array([[float(v) for v in row.split(",")[6:9]] for row in rows[1:]])
    de = np.asarray(colorimetry.delta_e_2000(lab, colorimetry.linear_srgb_to_lab(test.rgb)))
    assert len(de) == len(test) and float(np.mean(de)) <= 1.8


def render_target(tmp_path, name="target.png", size=64, **changes):
    scene = {
        "mesh": str(DATA / "meshes" / "sphere.ply"), "image": {"width": size, "height": size},
        "camera": {"eye": [0, 0, 3.5], "target": [0, 0, 0]}, "light": {"direction": [-1, 1, 1]},
        "wash": {"pigment": "Cadmium Yellow"}, "unlit": {"pigment": "Phthalo Green"},
        "shininess": 12, "k_unlit": 1.5, "gain": 0.6, "bias": 0.45,
    }  # fmt: skip
    (tmp_path / "truth.json").write_text(json.dumps(scene))
    img = np.asarray(diffwash.render(diffwash.load_scene(tmp_path / "truth.json")))
    write_png(tmp_path / name, np.asarray(colorimetry.srgb_encode(np.clip(img, 0, 1))), bits=16)
    (tmp_path / "start.json").write_text(json.dumps({**scene, **changes}))


def test_fit_image_cli(run_cli, tmp_path, cache):
    render_target(tmp_path, gain=0.5, k_unlit=1.2, shininess=15)
    r = run_cli("fit-image", "target.png", "--scene", "start.json", "--fit", "gain,k_unlit,shininess", "-o", "fitted.json",
                "--report", "fit.png", env=cache)  # fmt: skip
    assert r.returncode == 0, r.stderr
    assert "step   1  loss (rms)" in r.stdout and "converged after" in r.stdout
    fitted = diffwash.load_scene(tmp_path / "fitted.json")
    assert fitted.params.gain == pytest.approx(0.6, rel=0.01)
    assert fitted.params.k_unlit == pytest.approx(1.5, rel=0.01)
    assert fitted.params.shininess == pytest.approx(12, rel=0.01)
    assert (tmp_path / "fit.png").stat().st_size > 10_000
    # The fitted scene is what the rest of the product reads: bake and export take it directly.
    r = run_cli("bake", "fitted.json", "-o", "lut.png", "--size", "16", env=cache)
    assert r.returncode == 0, r.stderr
    r = run_cli("export", "fitted.json", "-o", "rt", env=cache)
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "rt" / "viewer.html").is_file()


def test_fit_image_not_converged_exits_1_and_writes_nothing(run_cli, tmp_path, cache):
    render_target(tmp_path, gain=0.3, k_unlit=0.7, shininess=30)
    args = ("fit-image", "target.png", "--scene", "start.json", "--fit", "gain,k_unlit,shininess", "-o", "fitted.json",
            "--max-steps", "1", "--quiet")  # fmt: skip
    r = run_cli(*args, env=cache)
    assert r.returncode == 1
    assert r.stderr.count("\n") == 1 and "did not converge" in r.stderr and "nothing was written" in r.stderr
    assert leftovers(tmp_path, "fitted.json") == []
    r = run_cli(*args, "--allow-unconverged", env=cache)
    assert r.returncode == 0 and "NOT converged" in r.stdout and (tmp_path / "fitted.json").is_file()


@pytest.fixture
def card(tmp_path):
    c = make_swatch_card(pigments.load("Cadmium Red"), coats=(1, 2))
    save_swatch_card(c, tmp_path / "card.png")
    return json.loads((tmp_path / "card.json").read_text())


def bad_layout(tmp_path, layout, change):
    change(layout)
    (tmp_path / "bad.json").write_text(json.dumps(layout))
    return "bad.json"


@pytest.mark.parametrize(
    "change, message",
    [
        (lambda L: L["patches"][1].update(box=[300, 200, 999, 300]), "bad.json: patches[1].box: [300, 200, 999, 300] lies outside the 216x264 photo"),
        (lambda L: L["patches"][0].update(box=[50, 50, 40, 80]), "bad.json: patches[0].box: is empty"),
        (lambda L: L["patches"][0].update(ground="white"), "bad.json: patches[0].ground: must be one of paper, black, got 'white'"),
        (lambda L: L.pop("paper"), "bad.json: paper: missing key"),
        (lambda L: L["paper"].update(box="all"), "bad.json: paper.box: must be [x0, y0, x1, y1]"),
    ],
)
def test_fit_swatch_bad_layout(run_cli, tmp_path, card, change, message):
    r = run_cli("fit-swatch", "card.png", "--layout", bad_layout(tmp_path, card, change), "-o", "out.json",
                "--report", "r.png")  # fmt: skip
    assert r.returncode == 2
    assert r.stderr == f"diffwash: error: {message}" + r.stderr.split(message, 1)[1] and r.stderr.count("\n") == 1
    assert leftovers(tmp_path, "out.json", "r.png") == []


def test_fit_swatch_nan_in_layout(run_cli, tmp_path, card):
    text = json.dumps(card).replace('"coats": 2', '"coats": NaN', 1)
    (tmp_path / "nan.json").write_text(text)
    r = run_cli("fit-swatch", "card.png", "--layout", "nan.json", "-o", "out.json")
    assert r.returncode == 2 and "nan.json: patches[2].coats: must be a number of coats > 0 ('+'-joined numbers for a mixture), got nan" in r.stderr
    assert leftovers(tmp_path, "out.json") == []


def test_fit_swatch_saturated_paper(run_cli, tmp_path):
    c = make_swatch_card(pigments.load("Cadmium Red"), coats=(1, 2), effects=CameraEffects(exposure=1.5))
    save_swatch_card(c, tmp_path / "bright.jpg")
    r = run_cli("fit-swatch", "bright.jpg", "--layout", "bright.json", "-o", "out.json")
    assert r.returncode == 2 and r.stderr.count("\n") == 1
    assert "bright.json: paper.box: the paper box is over-exposed (saturated)" in r.stderr
    assert leftovers(tmp_path, "out.json") == []


@pytest.mark.parametrize(
    "csv, message",
    [
        ("pigment,amount,r,g,b\npaper,0,240,240,235\n", "m.csv: missing column 'ground'"),
        ("pigment,amount,ground,r,g,b\npaper,0,paper,240,240,235\nx,0.1,paper,nan,1,2\n", "m.csv: line 3: r: must be a finite number"),
        ("pigment,amount,ground,r,g,b\npaper,0,paper,240,240,235\nx,0.1,glass,1,1,2\n", "m.csv: line 3: ground: unknown ground 'glass'"),
    ],
)
def test_fit_swatch_bad_table(run_cli, tmp_path, csv, message):
    (tmp_path / "m.csv").write_text(csv)
    r = run_cli("fit-swatch", "--table", "m.csv", "-o", "lib.json")
    assert r.returncode == 2 and r.stderr.startswith(f"diffwash: error: {message}") and r.stderr.count("\n") == 1
    assert leftovers(tmp_path, "lib.json") == []


def test_fit_swatch_usage_errors(run_cli, tmp_path, card):
    r = run_cli("fit-swatch", "-o", "x.json")
    assert r.returncode == 2 and "PHOTO: needs a PHOTO and its --layout, or --table CSV" in r.stderr
    r = run_cli("fit-swatch", "card.png", "--table", "m.csv", "-o", "x.json")
    assert r.returncode == 2 and "--table: give either --table or photos with --layout, not both" in r.stderr
    r = run_cli("fit-swatch", "card.png", "--layout", "card.json", "-o", "x.txt")
    assert r.returncode == 2 and "--output: must be a .json file" in r.stderr
    r = run_cli("fit-swatch", "missing.jpg", "--layout", "card.json", "-o", "x.json")
    assert r.returncode == 2 and "missing.jpg: no such image file" in r.stderr
    r = run_cli("fit-swatch", "card.png", "--layout", "card.json", "-o", "x.json", "--batch", "loop")
    assert r.returncode == 2 and "--batch: only applies to --table fits" in r.stderr
    r = run_cli("fit-swatch", "--table", "m.csv", "-o", "x.json", "--batch", "threads")
    assert r.returncode == 2 and "invalid choice" in r.stderr


def test_fit_image_bad_input(run_cli, tmp_path):
    render_target(tmp_path, size=32)
    Image.new("RGB", (40, 32), (200, 120, 60)).save(tmp_path / "wide.png")  # in colour: a grey one is refused first
    r = run_cli("fit-image", "wide.png", "--scene", "start.json", "--fit", "gain", "-o", "out.json")
    assert r.returncode == 2 and r.stderr.count("\n") == 1
    assert "wide.png: is 40x32 pixels but the scene renders 32x32" in r.stderr
    r = run_cli("fit-image", "target.png", "--scene", "start.json", "--fit", "gain,bais", "-o", "out.json")
    assert r.returncode == 2 and "--fit: unknown parameter 'bais'; did you mean 'bias'?" in r.stderr
    (tmp_path / "nan.json").write_text((tmp_path / "start.json").read_text().replace('"gain": 0.6', '"gain": NaN'))
    r = run_cli("fit-image", "target.png", "--scene", "nan.json", "--fit", "gain", "-o", "out.json")
    assert r.returncode == 2 and "nan.json: gain: must be a finite number" in r.stderr
    r = run_cli("fit-image", "target.png", "target.png", "target.png", "--scene", "start.json", "--scene", "start.json",
                "--fit", "gain", "-o", "out.json")  # fmt: skip
    assert r.returncode == 2 and "--scene: got 3 targets but 2 scenes" in r.stderr
    assert leftovers(tmp_path, "out.json") == []


def test_ntu_data_is_where_the_tests_look():
    assert NTU.is_file() and NTU.parent.name == "ntu-wpsm"
