"""A sample of scripts/hostile-sweep in CI: bad inputs through the real command line, each in its own process, are
refused with status 2 in one line, in time and memory, writing nothing (the full sweep: several hundred cases)."""

import importlib.machinery
import importlib.util
import subprocess
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


def test_a_sample_of_the_sweep_passes(tmp_path):
    # In its own process, as a user runs it: the sweep forks a process per case, and a test process that has
    # loaded JAX (multithreaded) must not fork.
    run = subprocess.run([sys.executable, str(ROOT / "scripts" / "hostile-sweep"), "--quick", "--sample", "16",
                          "--seed", "23", "--keep", str(tmp_path)], capture_output=True, text=True, timeout=900)  # fmt: skip
    assert run.returncode == 0, run.stdout[-3000:] + run.stderr[-3000:]
    assert "16 cases, 0 failed" in run.stdout
