"""A sample of scripts/hostile-sweep in CI: bad inputs through the real command line, each in its own process, are
refused with status 2 in one line, in time and memory, writing nothing (the full sweep: several hundred cases)."""

import importlib.machinery
import importlib.util
import sys

from conftest import ROOT

_loader = importlib.machinery.SourceFileLoader("hostile_sweep", str(ROOT / "scripts" / "hostile-sweep"))
_spec = importlib.util.spec_from_loader("hostile_sweep", _loader)
sweep = sys.modules["hostile_sweep"] = importlib.util.module_from_spec(_spec)
_loader.exec_module(sweep)


def test_the_sweep_makes_several_hundred_cases_of_every_surface(tmp_path):
    sweep.prepare(tmp_path)
    cases = sweep.cases(tmp_path)
    assert len(cases) > 300
    names = " ".join(c.name for c in cases)
    for surface in ("library", "query", "table", "suggest", "swatch-card", "pigment file", "watercolour scene",
                    "mixture scene", "fit-image", "bake", "render", "export", "special fifo", "special dev"):
        assert surface in names, surface


def test_a_sample_of_the_sweep_passes(tmp_path, capsys):
    status = sweep.main(["--quick", "--sample", "30", "--seed", "23", "--keep", str(tmp_path)])
    out = capsys.readouterr().out
    assert status == 0, out
    assert "30 cases, 0 failed" in out
