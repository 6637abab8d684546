"""The `diffwash` command through its real entry point (python -m diffwash, and the console script)."""

import json
import os
import tomllib

import numpy as np
from conftest import ROOT
from PIL import Image

import diffwash
from diffwash.cli import main
from diffwash.swatches import swatch_colours


def test_console_script_points_at_main():
    scripts = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["scripts"]
    assert scripts == {"diffwash": "diffwash.cli:main"}
    from diffwash.cli import main

    assert callable(main)


def test_help_and_version(run_cli):
    r = run_cli("--help")
    assert r.returncode == 0
    for cmd in ("pigments", "swatches", "demo"):
        assert cmd in r.stdout
    r = run_cli("--version")
    assert r.returncode == 0 and r.stdout.strip() == f"diffwash {diffwash.__version__}"


def test_usage_errors_exit_2(run_cli):
    r = run_cli("no-such-command")
    assert r.returncode == 2 and "invalid choice" in r.stderr
    r = run_cli("swatches")
    assert r.returncode == 2 and "required" in r.stderr


def test_pigments_table(run_cli):
    r = run_cli("pigments")
    assert r.returncode == 0
    lines = r.stdout.splitlines()
    assert lines[0].split()[:3] == ["pigment", "K", "(r"]
    assert len(lines) == 2 + 12
    assert lines[2].startswith("Quinacridone Rose") and "0.22" in lines[2] and "5.5" in lines[2]
    r = run_cli("pigments", "--json")
    assert [p["name"] for p in json.loads(r.stdout)["pigments"]][-1] == "Interference Lilac"


def test_pigments_with_a_bad_library_file(run_cli, tmp_path):
    (tmp_path / "lib.json").write_text('{"pigments": [{"name": "x", "K": [1, 1], "S": [1, 1, 1]}]}')
    r = run_cli("pigments", "--library", "lib.json")
    assert r.returncode == 2
    assert r.stderr.strip() == "diffwash: error: lib.json: pigments[0].K: must be a list of 3 numbers (red, green, blue), got [1, 1]"


def test_swatches_chart(run_cli, tmp_path):
    r = run_cli("swatches", "cadmium red", "Phthalo Green", "-o", "chart.png")
    assert r.returncode == 0, r.stderr
    img = np.asarray(Image.open(tmp_path / "chart.png").convert("RGB")).astype(int)
    # Every swatch colour (over paper and over black) is painted in the chart.
    for name in ("Cadmium Red", "Phthalo Green"):
        over_paper, over_black = swatch_colours(diffwash.pigments.load(name))
        for c in np.concatenate([over_paper, over_black]):
            target = np.round(c * 255).astype(int)
            assert np.any(np.all(np.abs(img - target) <= 1, axis=-1)), (name, target)
    assert img.shape[0] < img.shape[1] * 2  # two rows, a landscape-ish chart


def test_swatches_errors(run_cli, tmp_path):
    r = run_cli("swatches", "Cadmium Rde", "-o", "chart.png")
    assert r.returncode == 2
    assert r.stderr.strip() == "diffwash: error: unknown pigment 'Cadmium Rde' (not in the pigment library); did you mean 'Cadmium Red', 'Cadmium Yellow'?"
    assert "Traceback" not in r.stderr
    r = run_cli("swatches", "Cadmium Red", "--coats", "1,x", "-o", "chart.png")
    assert r.returncode == 2 and "--coats: must be comma-separated numbers" in r.stderr
    r = run_cli("swatches", "Cadmium Red", "-o", "missing/chart.png")
    assert r.returncode == 2 and "output folder does not exist" in r.stderr
    assert not (tmp_path / "chart.png").exists()


def test_main_leaves_the_environment_as_it_found_it(monkeypatch, capsys):
    # main() picks matplotlib's file backend for its own figures; a caller's later subprocesses (a notebook
    # kernel) must not inherit it, or their inline figures vanish.
    monkeypatch.delenv("MPLBACKEND", raising=False)
    assert main(["pigments"]) == 0
    assert "MPLBACKEND" not in os.environ
    monkeypatch.setenv("MPLBACKEND", "pdf")
    assert main(["pigments"]) == 0
    assert os.environ["MPLBACKEND"] == "pdf"
    for level in (None, "1", "0"):  # unset; what `import jax` sets; the caller's own
        if level is None:
            monkeypatch.delenv("TF_CPP_MIN_LOG_LEVEL", raising=False)
        else:
            monkeypatch.setenv("TF_CPP_MIN_LOG_LEVEL", level)
        seen = []
        monkeypatch.setattr("diffwash.cli._main", lambda argv: seen.append(os.environ.get("TF_CPP_MIN_LOG_LEVEL")) or 0)
        assert main(["pigments"]) == 0
        assert seen == ["0" if level == "0" else "3"] and os.environ.get("TF_CPP_MIN_LOG_LEVEL") == level


def test_a_command_run_from_a_jax_process_writes_only_its_own_line_from_a_warm_cache(run_cli, tmp_path):
    """jaxlib 0.9 logs two lines per program it loads from the compilation cache; a command started from a
    process that imported JAX (which sets TF_CPP_MIN_LOG_LEVEL=1) inherits that level: `main` raises it."""
    env = {"TF_CPP_MIN_LOG_LEVEL": "1", "DIFFWASH_CACHE_DIR": str(tmp_path / "cache")}
    for _ in range(2):  # the second run loads from the cache
        r = run_cli("bake", ROOT / "data" / "scenes" / "sphere.json", "-o", tmp_path / "missing" / "lut.png", "--size",
                    "4", env=env)  # fmt: skip
        assert r.returncode == 2 and r.stderr.count("\n") == 1, r.stderr
