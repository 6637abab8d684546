"""Bad measurement and query tables, libraries and outputs for fit-swatch --table and predict: one line naming
the file, the line and the column, exit status 2, nothing written (through the CLI's entry point)."""

import json

import pytest
from conftest import ROOT

from diffwash.cli import main

HEAD = "pigment,amount,ground,400,500,600,700\n"
PAPER = "paper,0,paper,0.8,0.82,0.85,0.86\n"
GOOD = HEAD + PAPER + "P1,0.02,paper,0.2,0.1,0.5,0.6\nP2,0.02,paper,0.1,0.5,0.3,0.2\nP1+P2,0.01+0.01,paper,0.1,0.1,0.3,0.3\n"


@pytest.fixture
def cli(capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("MPLBACKEND", "Agg")

    def run(*args):
        try:
            status = main([str(a) for a in args])
        except SystemExit as e:
            status = e.code
        _, err = capsys.readouterr()
        return status, err

    return run


def _refused(result, *needles):
    status, err = result
    assert status == 2, err
    assert err.startswith("diffwash") and err.count("\n") == 1 and "Traceback" not in err, err
    for n in needles:
        assert n in err, err


@pytest.mark.parametrize(
    "body, needles",
    [
        (PAPER + "P1+P2,0.01,paper,0.1,0.1,0.3,0.3\n", ("line 3", "amount", "2 pigments")),
        (PAPER + "P1,0.02,paper,0.2,0.1,0.5\n", ("line 3", "has 6 values")),
        (PAPER + "P1,0.02,paper,0.2,-0.1,0.5,0.6\n", ("line 3", "500", ">= 0")),
        (PAPER + "P1,0.02,paper,0.2,nan,0.5,0.6\n", ("line 3", "500", "finite")),
        (PAPER + "P1,nan,paper,0.2,0.1,0.5,0.6\n", ("line 3", "amount", "finite")),
        (PAPER + "P1,-0.01,paper,0.2,0.1,0.5,0.6\n", ("line 3", "amount", ">= 0")),
        (PAPER + "P1,0.02,board,0.2,0.1,0.5,0.6\n", ("line 3", "ground", "board")),
        (PAPER.replace("0.8,", "80,") + "P1,0.02,paper,0.2,0.1,0.5,0.6\n", ("line 2", "400", "percent")),
    ],
)  # fmt: skip
def test_bad_tables_are_refused_and_nothing_is_written(cli, tmp_path, body, needles):
    (tmp_path / "t.csv").write_text(HEAD + body)
    _refused(cli("fit-swatch", "--table", "t.csv", "-o", "lib.json"), "t.csv", *needles)
    assert not (tmp_path / "lib.json").exists()


def test_reflectance_a_little_above_one_is_data(cli, tmp_path):
    from diffwash import measurements

    (tmp_path / "t.csv").write_text(HEAD + "paper,0,paper,1.02,1.01,0.99,0.98\nP1,0.02,paper,0.2,0.1,0.5,1.01\n")
    m = measurements.read_measurements(tmp_path / "t.csv")
    assert m.values.max() == pytest.approx(1.01) and m.grounds["paper"].max() == pytest.approx(1.02)


def _library(tmp_path, wavelengths=(400, 500, 600, 700)):
    n = len(wavelengths)
    lib = {"format": "diffwash-library", "version": 1, "observation": {"wavelengths": list(wavelengths)},
           "pigments": [{"name": "P1", "K": [1.0] * n, "S": [0.5] * n, "amount_law": {"kind": "power",
                         "reference": 0.05, "gamma": 0.8}, "mixing_weight": 1.0}],
           "grounds": {"paper": [0.8] * n}, "surface": {"k2": 0.0}}  # fmt: skip
    (tmp_path / "lib.json").write_text(json.dumps(lib))


@pytest.mark.parametrize(
    "queries, needles",
    [
        ("pigment,amount,ground\nP1,0.01,paper\nP9,0.02,paper\n", ("q.csv", "line 3", "pigment", "P9")),
        ("pigment,amount,ground\nP1+P1,0.01,paper\n", ("q.csv", "line 2", "amount")),
        ("pigment,amount,ground\nP1,0.01,board\n", ("q.csv", "line 2", "ground", "board")),
        ("pigment,amount\nP1,0.01\n", ("q.csv", "ground")),
    ],
)  # fmt: skip
def test_bad_queries_are_refused(cli, tmp_path, queries, needles):
    _library(tmp_path)
    (tmp_path / "q.csv").write_text(queries)
    _refused(cli("predict", "lib.json", "--table", "q.csv", "-o", "p.csv"), *needles)
    assert not (tmp_path / "p.csv").exists()


def test_a_library_on_a_grid_no_observer_sees_is_refused(cli, tmp_path):
    _library(tmp_path, wavelengths=(900, 950, 1000))
    (tmp_path / "q.csv").write_text("pigment,amount,ground\nP1,0.01,paper\n")
    _refused(cli("predict", "lib.json", "--table", "q.csv", "-o", "p.csv"), "lib.json", "wavelengths", "cannot be seen")
    assert not (tmp_path / "p.csv").exists()


def test_outputs_naming_inputs_are_refused(cli, tmp_path):
    _library(tmp_path)
    (tmp_path / "q.csv").write_text("pigment,amount,ground\nP1,0.01,paper\n")
    before = (tmp_path / "q.csv").read_bytes()
    _refused(cli("predict", "lib.json", "--table", "q.csv", "-o", "q.csv"), "q.csv")
    assert (tmp_path / "q.csv").read_bytes() == before
    (tmp_path / "t.csv").write_text(GOOD)
    _refused(cli("fit-swatch", "--table", "t.csv", "-o", "t.csv"), "t.csv")
    assert (tmp_path / "t.csv").read_text() == GOOD


def test_tables_with_mixtures_or_bands_take_the_joint_fit_and_single_rgb_tables_keep_theirs(tmp_path):
    from diffwash.cli import _library_fit

    assert _library_fit.wants_library(str(ROOT / "data" / "ntu-wpsm" / "ntu-rgb-train.csv"), False) is not None
    (tmp_path / "t.csv").write_text(GOOD)
    assert _library_fit.wants_library(str(tmp_path / "t.csv"), False).spectral
    (tmp_path / "s.csv").write_text("pigment,amount,ground,r,g,b\npaper,0,paper,240,240,235\nP1,0.02,paper,200,40,40\n")
    assert _library_fit.wants_library(str(tmp_path / "s.csv"), False) is None
