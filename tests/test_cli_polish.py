"""The command line's small print: help text argparse must not garble, suggest's progress in a log file, plain
names in error messages, and help and docs that say what the commands take. (fit-swatch's table of a card's glaze
stacks, and suggest on that card's library, are tested with the card's fit, in tests/test_stacks.py.)"""

import json
import sys

import jax.numpy as jnp
import numpy as np
import pytest
from conftest import DATA, ROOT

from diffwash import _regions, library, mixing, spectral
from diffwash.cli import COMMANDS, main


def _help(capsys, *args) -> str:
    """`diffwash ARGS --help`'s output, its whitespace collapsed (argparse wraps at the terminal's width)."""
    with pytest.raises(SystemExit) as e:
        main([*args, "--help"])
    assert e.value.code == 0
    return " ".join(capsys.readouterr().out.split())


def test_help_lists_suggest_with_its_90_percent_regions_not_argparses_internals(capsys):
    out = _help(capsys)
    assert "90% regions" in out and "{'option_strings'" not in out and "%%" not in out


@pytest.mark.parametrize("command", list(COMMANDS))
def test_every_commands_help_formats(capsys, command):
    out = _help(capsys, command)
    assert "{'option_strings'" not in out and f"diffwash {command}" in out


# suggest's progress: a line per pick where standard error is not a terminal.


def _library_with_posterior():
    """A library of A, B, C with a given posterior (no fit: the progress lines are what is tested)."""
    grid = (400.0, 500.0, 600.0, 700.0)
    rng = np.random.default_rng(3)
    palette = mixing.Palette(K=jnp.asarray(rng.uniform(0.2, 6.0, (3, 4))), S=jnp.asarray(rng.uniform(0.3, 2.0, (3, 4))),
                             law=mixing.AmountLaw(gamma=jnp.asarray([0.7, 0.9, 0.6])), weights=jnp.ones(3),
                             names=("A", "B", "C"), wavelengths=grid)  # fmt: skip
    n = 3 * (2 * len(grid) + 1)
    post = _regions.Posterior(0.1 * rng.standard_normal((n, 5)), np.full(n, 0.01),
                              {"single": 0.3, "seen": 0.6, "unseen": 2.0, "unmixed": 2.0}, (("A", "B"),))  # fmt: skip
    paper = np.linspace(0.80, 0.88, len(grid))
    return library.Library(palette, {"paper": paper}, spectral.observation(grid), posterior=post)


@pytest.fixture
def ranked(tmp_path):
    _library_with_posterior().save(tmp_path / "lib.json")
    (tmp_path / "cand.csv").write_text("pigment,amount,ground\nA+C,0.01+0.02,paper\nB/C,0.02/0.02,paper\n"
                                       "C,0.05,paper\n")  # fmt: skip
    return ["suggest", str(tmp_path / "lib.json"), "--table", str(tmp_path / "cand.csv"), "-n", "3",
            "-o", str(tmp_path / "ranked.csv")]  # fmt: skip


def test_suggest_writes_a_progress_line_per_pick_to_a_log(ranked, capsys):
    assert main(ranked) == 0
    err = capsys.readouterr().err
    assert "\r" not in err and err.splitlines() == [f"suggest: picked {i}/3" for i in (1, 2, 3)]


def test_suggest_rewrites_one_progress_line_on_a_terminal(ranked, capsys, monkeypatch):
    monkeypatch.setattr(sys.stderr, "isatty", lambda: True)
    assert main(ranked) == 0
    assert capsys.readouterr().err == "\rsuggest: picked 1/3\rsuggest: picked 2/3\rsuggest: picked 3/3\n"


# Errors name a ground as the table wrote it, not as numpy's repr of it. colour-science, once imported, turns on
# numpy's legacy printing (1.13) process-wide, which hides that repr; a command that never imports it showed it.


def test_predict_names_a_ground_the_library_lacks_plainly(tmp_path, capsys):
    (tmp_path / "my-pigments.json").write_text(json.dumps({"pigments": [{"name": "P1", "K": [0.5, 1, 2],
                                                                         "S": [0.3, 0.3, 0.3]}]}))  # fmt: skip
    (tmp_path / "q.csv").write_text("pigment,amount,ground\nP1,0.5,black\n")
    out = tmp_path / "p.csv"
    with np.printoptions(legacy=False):
        assert main(["predict", str(tmp_path / "my-pigments.json"), "--table", str(tmp_path / "q.csv"),
                     "-o", str(out)]) == 2  # fmt: skip
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "q.csv: line 2: ground: no ground 'black' in the library" in err[0], err
    assert "np.str_" not in err[0] and not out.exists()


def test_fit_swatch_names_a_ground_no_row_measures_plainly(tmp_path, capsys):
    (tmp_path / "t.csv").write_text("pigment,amount,ground,400,500,600,700\nP1,0.05,paper,0.1,0.2,0.3,0.4\n")
    with np.printoptions(legacy=False):
        assert main(["fit-swatch", "--table", str(tmp_path / "t.csv"), "-o", str(tmp_path / "lib.json")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "t.csv: line 2: ground: no row measures the ground 'paper'" in err[0], err
    assert "np.str_" not in err[0]


# Help and docs say what the commands take.


def test_predict_help_names_stacks_regions_and_every_library(capsys):
    out = _help(capsys, "predict")
    assert "single or mixed" not in out and "written by diffwash fit-swatch --table" not in out
    for words in ("mixture", "glaze stack", "`P1/P3,0.02/0.03,paper`", "bottom first", "de2000_90",
                  "90% region", "swatch-card photos", "older pigment file"):  # fmt: skip
        assert words in out, words


def test_suggest_help_says_which_libraries_have_a_posterior(capsys):
    out = _help(capsys, "suggest")
    assert "fit-swatch --table of a spectral table)" not in out
    for words in ("swatch-card photos", "RGB ones with mixtures or glaze stacks", "--refine none"):
        assert words in out, words


def test_suggest_refuses_a_pigment_file_saying_which_fits_have_a_posterior(tmp_path, capsys):
    (tmp_path / "old.json").write_text(json.dumps({"pigments": [{"name": "P1", "K": [0.5, 1, 2],
                                                                  "S": [0.3, 0.3, 0.3]}]}))  # fmt: skip
    (tmp_path / "cand.csv").write_text("pigment,amount,ground\nP1,0.5,paper\n")
    assert main(["suggest", str(tmp_path / "old.json"), "--table", str(tmp_path / "cand.csv")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "old.json: uncertainty: has no posterior" in err[0]
    for words in ("spectral table", "RGB table with mixtures or glaze stacks", "swatch-card photos",
                  "older pigment files"):  # fmt: skip
        assert words in err[0], words


def test_pigments_doc_says_what_takes_spectral_pigments(tmp_path, capsys):
    text = " ".join((ROOT / "docs" / "pigments.md").read_text().split())
    assert "do not take spectral pigments yet" not in text
    assert "data/scenes/mixture.json" in text and "swatch-card --library" in text and "bake --rt" in text
    # What it says of the LUT: a spectral scene bakes its colour table; its R/T table is refused.
    scene = str(DATA / "scenes" / "mixture.json")
    assert main(["bake", scene, "-o", str(tmp_path / "lut.png"), "--size", "8"]) == 0
    assert main(["bake", scene, "-o", str(tmp_path / "rt.png"), "--size", "8", "--rt"]) == 2
    assert "kind (--rt)" in capsys.readouterr().err
