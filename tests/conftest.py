"""Tests run in float64 (the library's default is float32) with warnings as errors.

Each test process (each pytest-xdist worker) gives the `diffwash` commands its tests run as subprocesses a
folder of its own for JAX's compiled programs (one worker runs one test at a time, so no two processes write
it at once); it is removed when the process's test session ends. Tests of a first run (the demo's, in a new
folder) and the notebooks (the cache off, as a cold start) pass their own `DIFFWASH_CACHE_DIR`. The documents' code
examples (tests/test_doc_examples.py) use the shared folder below instead, under its lock, commands and Python
blocks alike (in float32: their programs never share a key with the tests').

The test processes themselves (the controller and every xdist worker of one run) share another folder for the
programs they compile in float64 (those that took 0.2 s or more): a fit one worker compiled is read, not
compiled again, by the other, and programs dropped by `_relieve_compiled_programs` come back from disk. The
whole suite's tests took 3,312 s of the two workers' time with it, against 3,555 s without (a run of the day
before); the mixture modules gain most. JAX writes a cache entry in place, so two processes on one folder need
its lock: a size bound turns on JAX's `filelock`-based locking of every read and write (a torn entry would
otherwise be read as corrupt). Twice, in CI runs under JAX 0.10.2, a worker that had run several hundred tests
died of a segmentation fault in the cache writer, before the one cause of such late deaths was found: the
worker's memory maps (XLA's CPU backend maps each compiled program's code in regions of its own; a process may
hold 65530). Five mixture test modules alone left 36,000; `_relieve_compiled_programs` keeps them under half.
"""

import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

# A worker inherits its parent's environment: the marker tells a folder made here from one the user chose.
_OWN = "DIFFWASH_TESTS_OWN_CACHE"
if os.environ.get("DIFFWASH_CACHE_DIR", os.environ.get(_OWN)) == os.environ.get(_OWN):
    os.environ["DIFFWASH_CACHE_DIR"] = os.environ[_OWN] = tempfile.mkdtemp(prefix="diffwash-tests-jax-")

# One folder for the test processes' own programs, made by the first (the controller) and inherited by the workers.
SHARED_CACHE = "DIFFWASH_TESTS_SHARED_CACHE"
_MADE_SHARED = not os.environ.get(SHARED_CACHE)  # the process that makes the folder removes it
if _MADE_SHARED:
    os.environ[SHARED_CACHE] = tempfile.mkdtemp(prefix="diffwash-tests-xla-")

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)
jax.config.update("jax_compilation_cache_dir", os.environ[SHARED_CACHE])
jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.2)
jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
jax.config.update("jax_compilation_cache_max_size", 8 << 30)  # a bound turns on the cross-process lock

import diffwash._cache  # noqa: E402

diffwash._cache.enable_compilation_cache = lambda: None  # in-process commands keep the folder above

from diffwash.cli import main  # noqa: E402

import hypothesis  # noqa: E402
import pytest  # noqa: E402

hypothesis.settings.register_profile("diffwash", deadline=None, max_examples=200, derandomize=True)
hypothesis.settings.load_profile("diffwash")


def pytest_unconfigure(config):
    """Remove this process's compilation cache for commands, if this file made it (every xdist worker and the
    controller), and the test processes' shared one in the process that made it (the controller)."""
    if os.environ.get("DIFFWASH_CACHE_DIR") == os.environ.get(_OWN):
        shutil.rmtree(os.environ[_OWN], ignore_errors=True)
    if _MADE_SHARED:
        shutil.rmtree(os.environ[SHARED_CACHE], ignore_errors=True)


#: Modules whose tests take longest (`--durations=0` of a whole run, 2026-11-28: the doc examples 512 s of the two
#: workers' 3,547, the notebooks 223 s, then 100-130 s each). They are collected first, so that pytest-xdist hands
#: them out while the other worker is busy too; the run then ends on short tests instead of one worker finishing a
#: notebook alone. Each module's tests stay together, in their own order (its module fixtures are set up once).
HEAVY_FIRST = ("test_doc_examples.py", "test_notebooks.py", "test_fit_cli.py", "test_blender.py", "test_mix_pairs.py",
               "test_stacks.py", "test_swatch_mixtures.py", "test_render_core.py", "test_mix_seen.py",
               "test_look_scene.py", "test_fit_image.py", "test_mix_inferred_pairs.py")  # fmt: skip


def pytest_collection_modifyitems(items):
    """Collect `HEAVY_FIRST`'s modules first (a stable sort: every module's tests keep their order)."""
    rank = {name: i for i, name in enumerate(HEAVY_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))


ROOT = Path(__file__).resolve().parent.parent
DATA = ROOT / "data"


def write_spectral_table(path: Path, m) -> Path:
    """Write `diffwash.measurements.Measurements` on paper as a spectral table CSV (the shared tables' format)."""
    rows = ["pigment,amount,ground," + ",".join(f"{w:g}" for w in m.wavelengths)]
    rows.append("paper,0,paper," + ",".join(f"{float(v)!r}" for v in m.grounds["paper"]))
    for p, a, v in zip(m.pigments, m.amounts, m.values):
        rows.append(f"{'+'.join(p)},{'+'.join(f'{x:g}' for x in a)},paper," + ",".join(f"{float(x)!r}" for x in v))
    path.write_text("\n".join(rows) + "\n")
    return path


def write_fit_target(d: Path, truth: dict, start: dict):
    """For fit-image tests: truth.json and start.json in `d`, and truth's render as target.png (16-bit sRGB).

    Returns the render in linear RGB."""
    import json

    import numpy as np

    import diffwash
    from diffwash import colorimetry
    from diffwash._io import write_png

    (d / "truth.json").write_text(json.dumps(truth))
    (d / "start.json").write_text(json.dumps(start))
    linear = np.asarray(diffwash.render(diffwash.load_scene(d / "truth.json")))
    write_png(d / "target.png", np.asarray(colorimetry.srgb_encode(np.clip(linear, 0, 1))), bits=16)
    return linear


def knot_scene(mesh: str, width: int, height: int, shading: str = "per-pixel", **extra):
    """The tests' knot scene: a torus knot of `data/meshes/`, rose wash, ultramarine unlit glaze,
    constants away from their defaults (so every term of the model shows)."""
    from diffwash._scene import parse_scene

    data = {
        "mesh": mesh,
        "image": {"width": width, "height": height},
        "camera": {"eye": [0.4, 0.6, 3.0], "target": [0.0, 0.0, 0.0], "up": [0.0, 1.0, 0.0], "fov_y": 45},
        "light": {"direction": [1.0, 1.2, 0.8]},
        "shading": shading,
        "wash": {"pigment": "Quinacridone Rose"},
        "unlit": {"pigment": "French Ultramarine"},
        "shininess": 15,
        "k_unlit": 1.3,
        "gain": 0.65,
        "bias": 0.4,
        "wash_reduction": 0.35,
        **extra,
    }
    return parse_scene(data, base=DATA / "meshes")


@pytest.fixture(autouse=True, scope="module")
def _relieve_compiled_programs():
    """After each test module, drop JAX's compiled programs if the worker holds half the memory maps the system
    allows (`diffwash._cache.relieve_compiled_programs`). A worker that had run several hundred tests used to
    die inside XLA's compiler (a segmentation fault, or an abort) when its maps ran out."""
    yield
    diffwash._cache.relieve_compiled_programs()


@pytest.fixture
def cli(capsys, tmp_path, monkeypatch):
    """`diffwash ARGS...` in this process (`diffwash.cli.main`), from `tmp_path`: returns (status, stdout, stderr)."""
    monkeypatch.chdir(tmp_path)
    # main() sets MPLBACKEND for its figures; undone after the test (a notebook kernel started later inherits it).
    monkeypatch.setenv("MPLBACKEND", "Agg")

    def run(*args):
        try:
            status = main([str(a) for a in args])
        except SystemExit as e:  # argparse's usage errors
            status = e.code
        out, err = capsys.readouterr()
        return status, out, err

    return run


@pytest.fixture
def run_cli(tmp_path):
    """Run the real `diffwash` entry point (`python -m diffwash`) in a subprocess.

    Returns a function `(*args, cwd=tmp_path) -> CompletedProcess` with text output.
    """

    def run(*args, cwd=None, env=None, timeout=600):
        e = dict(os.environ)
        e["PYTHONPATH"] = str(ROOT) + os.pathsep + e.get("PYTHONPATH", "")
        if env:
            e.update(env)
        return subprocess.run(
            [sys.executable, "-m", "diffwash", *map(str, args)],
            cwd=cwd or tmp_path,
            env=e,
            capture_output=True,
            text=True,
            timeout=timeout,
        )

    return run
