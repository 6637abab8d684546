"""The package's shape: a one-way import graph, a command line over the public API, one model.

These hold the structure issue 14 asks for: no import cycles inside `diffwash/`, imports inside
functions only for optional dependencies, the CLI importing nothing private, and the exported
shaders generated from the model's own functions and constants; and issue 22's start-up: the
packages load their submodules on first use, so `import diffwash` and `diffwash --help` load none of
the heavy dependencies, and `diffwash.fit` split by family into subpackages that meet only at their
public faces.
"""

from __future__ import annotations

import ast
import collections
import importlib
import os
import re
import subprocess
import sys
import time
from pathlib import Path

import pytest
from conftest import ROOT

from diffwash.cli import COMMANDS

PACKAGE = ROOT / "diffwash"
#: Optional dependencies, imported where they are used (extras, or only some platforms have them).
OPTIONAL = {"glfw", "mitsuba", "drjit", "nvdiffrast", "torch", "playwright", "mixbox", "pymixbox", "rawpy",
            "colour_checker_detection", "bpy", "mathutils"}


def _module_name(path: Path) -> str:
    rel = path.relative_to(ROOT).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def _resolve(module: str, is_package: bool, node: ast.ImportFrom) -> str:
    if node.level == 0:
        return node.module or ""
    base = module.split(".")
    if not is_package:
        base = base[:-1]
    base = base[: len(base) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def _imports() -> dict[str, list[tuple[str, bool, int]]]:
    """Per module: (imported module, inside a function?, line) for every import."""
    out = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        module = _module_name(path)
        tree = ast.parse(path.read_text(encoding="utf-8"))
        found = []
        functions = [n for n in ast.walk(tree) if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef))]
        inside = {id(n) for f in functions for n in ast.walk(f) if n is not f}
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                for alias in node.names:
                    found.append((alias.name, id(node) in inside, node.lineno))
            elif isinstance(node, ast.ImportFrom):
                target = _resolve(module, path.name == "__init__.py", node)
                found.append((target, id(node) in inside, node.lineno))
                if node.level or target.startswith("diffwash"):
                    for alias in node.names:  # `from . import km` imports the module diffwash.km
                        found.append((f"{target}.{alias.name}", id(node) in inside, node.lineno))
        out[module] = found
    return out


def _internal_graph() -> dict[str, set[str]]:
    modules = set(_imports())
    graph = {m: set() for m in modules}
    for m, found in _imports().items():
        for target, _, _ in found:
            if target in modules and target != m and not m.startswith(target + "."):
                graph[m].add(target)
    return graph


def test_no_import_cycles_inside_the_package():
    graph = _internal_graph()
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(m: str) -> None:
        state[m] = 1
        stack.append(m)
        for t in sorted(graph[m]):
            if state.get(t) == 1:
                cycle = stack[stack.index(t):] + [t]
                pytest.fail("import cycle: " + " -> ".join(cycle))
            if t not in state:
                visit(t)
        stack.pop()
        state[m] = 2

    for m in sorted(graph):
        if m not in state:
            visit(m)


def test_imports_inside_functions_are_only_for_optional_dependencies():
    offenders = []
    for module, found in _imports().items():
        for target, inside, line in found:
            if inside and target.split(".")[0] not in OPTIONAL:
                offenders.append(f"{module}:{line} imports {target}")
    assert not offenders, "\n".join(sorted(set(offenders)))


def _private(dotted: str) -> bool:
    return any(part.startswith("_") and not part.endswith("__") for part in dotted.split("."))


def _attribute_chain(node: ast.Attribute) -> str | None:
    """`diffwash.fit.fit_table` for that expression; None unless it is a chain of names."""
    parts = []
    while isinstance(node, ast.Attribute):
        parts.append(node.attr)
        node = node.value
    return ".".join([node.id, *reversed(parts)]) if isinstance(node, ast.Name) else None


def test_the_command_line_uses_only_the_public_api():
    """Neither what the CLI imports nor what it reaches as `diffwash.NAME...` (the commands' run time) is private."""
    offenders = []
    for module, found in _imports().items():
        if not module.startswith("diffwash.cli"):
            continue
        for target, _, line in found:
            if not target.startswith("diffwash") or target.startswith("diffwash.cli"):
                continue
            if _private(target):
                offenders.append(f"{module}:{line} imports {target}")
    for path in sorted((PACKAGE / "cli").glob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            chain = _attribute_chain(node) if isinstance(node, ast.Attribute) else None
            if chain and chain.startswith("diffwash.") and _private(chain):
                offenders.append(f"{path.relative_to(ROOT)}:{node.lineno} uses {chain}")
            elif chain and chain.startswith("diffwash.") and chain.split(".")[1] not in _stub_names("diffwash"):
                offenders.append(f"{path.relative_to(ROOT)}:{node.lineno} uses {chain}, which diffwash does not name")
    assert not offenders, "\n".join(sorted(set(offenders)))


#: Lazily loaded packages: their public API is their `__init__.pyi` (what `lazy_loader.attach_stub` reads).
LAZY_PACKAGES = ("diffwash", "diffwash.fit", "diffwash.fit.photos", "diffwash.fit.tables", "diffwash.fit.images",
                 "diffwash.look")


def _stub_names(package: str) -> dict[str, tuple[str, str | None]]:
    """Public name -> (module, attribute; None for a submodule), from the package's `__init__.pyi`."""
    stub = PACKAGE.parent.joinpath(*package.split("."), "__init__.pyi")
    names = {}
    for node in ast.parse(stub.read_text(encoding="utf-8")).body:
        if isinstance(node, ast.ImportFrom):
            assert node.level == 1, f"{stub}: only `from .module import name as name`"
            for alias in node.names:
                assert alias.asname in (None, alias.name), f"{stub}: {alias.name} as {alias.asname} (attach_stub renames nothing)"
                module = f"{package}.{node.module}" if node.module else f"{package}.{alias.name}"
                names[alias.name] = (module, alias.name if node.module else None)
    return names


@pytest.mark.parametrize("package", LAZY_PACKAGES)
def test_lazy_packages_offer_their_stubs_names(package):
    """Every name of the stub is in `__all__` and `dir()`, and is the object its module defines."""
    pkg = importlib.import_module(package)
    names = _stub_names(package)
    assert sorted(pkg.__all__) == sorted(names)
    assert set(names) <= set(dir(pkg))
    for name, (module, attr) in names.items():
        target = importlib.import_module(module)
        assert getattr(pkg, name) is (target if attr is None else getattr(target, attr)), name



#: The fit families (issue 22): each a subpackage of `diffwash.fit` with a public face.
FIT_FAMILIES = ("photos", "tables", "images")
#: The private modules directly in `diffwash/fit/`: what several families use, and why it is shared.
FIT_SHARED = {
    "_kmfit": "the single-pigment Kubelka-Munk fit: swatch photos and tables both run it",
    "_bandlsq": "Levenberg-Marquardt for band-structured problems: _kmfit and the mixture fit",
    "_report": "the report figures of every family's results",
}


def _fit_family(module: str) -> str | None:
    """`photos` for `diffwash.fit.photos` and its modules; `shared` for `diffwash.fit._kmfit`; None otherwise."""
    parts = module.split(".")
    if parts[:2] != ["diffwash", "fit"] or len(parts) < 3:
        return None
    return "shared" if parts[2].startswith("_") else parts[2]


def test_fit_families_are_subpackages_with_a_public_face():
    """Each family has a docstring and a non-empty `__all__`, all of which `diffwash.fit` offers too (as the
    same objects), beside the family itself; `diffwash.fit`'s other names come from its shared modules."""
    fit_names = _stub_names("diffwash.fit")
    for family in FIT_FAMILIES:
        package = f"diffwash.fit.{family}"
        pkg = importlib.import_module(package)
        assert (pkg.__doc__ or "").strip() and pkg.__all__, f"{package} has no public face"
        assert fit_names.get(family) == (package, None), f"diffwash.fit does not name {family}"
        missing = [n for n in pkg.__all__ if fit_names.get(n) != (package, n)]
        assert not missing, f"diffwash.fit does not re-export {package}'s " + ", ".join(missing)
    for name, (module, _) in fit_names.items():
        assert module in {f"diffwash.fit.{f}" for f in FIT_FAMILIES} | {f"diffwash.fit.{m}" for m in FIT_SHARED}, (
            f"diffwash.fit.{name} comes from {module}, neither a family's face nor a shared module")


def test_fit_modules_sit_in_their_family():
    """Directly in `diffwash/fit/` only the shared modules (each used by more than one family), no other
    subpackage than the families, and no module imports another family's private modules (a shared module
    imports no family at all): the families meet only at their public faces."""
    fit = PACKAGE / "fit"
    stray = sorted({p.stem for p in fit.glob("*.py") if p.name != "__init__.py"} - set(FIT_SHARED))
    assert not stray, f"diffwash/fit/ holds {', '.join(stray)}: move each into its family, or list it in FIT_SHARED"
    others = sorted(p.name for p in fit.iterdir() if (p / "__init__.py").exists() and p.name not in FIT_FAMILIES)
    assert not others, f"diffwash/fit/ has subpackages {', '.join(others)} that are not fit families"
    offenders, users = [], collections.defaultdict(set)
    for module, found in _imports().items():
        family = _fit_family(module)
        if family is None:
            continue
        for target, _, line in found:
            to, parts = _fit_family(target), target.split(".")
            if to == "shared" and parts[2] != module.split(".")[2]:
                users[parts[2]].add(family if family != "shared" else module)
            if to is None or to == family or to == "shared":
                continue
            if family == "shared":
                offenders.append(f"{module}:{line} imports {target}: a shared module imports no family")
            elif len(parts) > 3 and _private(".".join(parts[3:])):
                offenders.append(f"{module}:{line} imports {target}, private to diffwash.fit.{to}")
    for name in FIT_SHARED:
        if len(users[name]) == 1 and next(iter(users[name])) in FIT_FAMILIES:
            offenders.append(f"diffwash.fit.{name} is used by {next(iter(users[name]))} alone: move it there")
    assert not offenders, "\n".join(sorted(set(offenders)))

#: What a command that neither renders nor fits must not import (seconds each, on 2 cores).
HEAVY = ("jax", "colour", "matplotlib", "moderngl", "OpenEXR", "scipy", "trimesh", "PIL.Image")

_PROBE = """
import runpy, sys, time
start = time.perf_counter()
if sys.argv[1:] == ["--import"]:
    import diffwash
else:
    sys.argv = ["diffwash", *sys.argv[1:]]
    try:
        runpy.run_module("diffwash", run_name="__main__")
    except SystemExit:
        pass
print("LOADED", *[m for m in {heavy!r} if m in sys.modules], file=sys.stderr)
"""


def _probe(*args: str) -> tuple[list[str], float]:
    """The heavy modules a fresh `python -m diffwash ARGS` (`--import`: `import diffwash`) loaded, and its wall time."""
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""), "DIFFWASH_CACHE_DIR": "off"}
    start = time.perf_counter()
    run = subprocess.run([sys.executable, "-c", _PROBE.format(heavy=HEAVY), *args], env=env, cwd=ROOT,
                         capture_output=True, text=True, timeout=300)  # fmt: skip
    elapsed = time.perf_counter() - start
    assert run.returncode == 0, run.stderr
    line = [l for l in run.stderr.splitlines() if l.startswith("LOADED")][-1]
    return line.split()[1:], elapsed


@pytest.mark.parametrize("args", [("--import",), ("--version",), ("--help",),
                                  *[(c, "--help") for c in COMMANDS if c != "fit-image"]])  # fmt: skip
def test_starting_loads_no_heavy_dependency(args):
    """`import diffwash`, `diffwash --version`, `--help` and a command's `--help` load none of `HEAVY`."""
    loaded, _ = _probe(*args)
    assert loaded == [], f"{' '.join(args)} imported {', '.join(loaded)}"


def test_listing_pigments_needs_no_jax():
    """`diffwash pigments` (not to a terminal) reads the library as plain data: no JAX, no colour-science."""
    loaded, _ = _probe("pigments")
    assert loaded == [], f"diffwash pigments imported {', '.join(loaded)}"


def test_lazy_module_proxies_import_at_first_use_and_forward_reads_and_writes():
    code = """
import sys
from diffwash._lazy import lazy
wave = lazy("wave")
assert "wave" not in sys.modules
assert wave.WAVE_FORMAT_PCM == 1 and "wave" in sys.modules
wave.answer = 42
import wave as real
assert real.answer == 42 and "answer" in dir(wave)
del wave.answer
assert not hasattr(real, "answer")
"""
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    run = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr


_CONCURRENT_SOLVES = """
import diffwash, jax, jax.numpy as jnp, numpy as np
from jax.scipy.linalg import solve_triangular

@jax.jit
def f(A, b):  # eight independent batched triangular solves: XLA runs them at once
    return sum(solve_triangular(A[i], b[i], lower=True).sum() for i in range(8))

rng = np.random.default_rng(0)
A = jnp.asarray(np.tril(rng.normal(size=(8, 256, 48, 48))) + 5 * np.eye(48), jnp.float32)
b = jnp.asarray(rng.normal(size=(8, 256, 48, 4)), jnp.float32)
for k in range(100):
    f(A + k * 1e-3, b).block_until_ready()
print("finished")
"""


def test_concurrent_batched_solves_finish():
    """jaxlib 0.10 hangs this program every time on 2 cores (each solve waits on the pool it runs on:
    diffwash/_jaxlib.py); the supported jaxlib finishes it in about 3 s."""
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    try:
        run = subprocess.run([sys.executable, "-c", _CONCURRENT_SOLVES], env=env, capture_output=True, text=True,
                             timeout=180)  # fmt: skip
    except subprocess.TimeoutExpired:
        pytest.fail("eight concurrent batched triangular solves hung (a deadlocking jaxlib: diffwash/_jaxlib.py)")
    assert run.returncode == 0 and "finished" in run.stdout, run.stderr


@pytest.mark.parametrize("version, bad", [
    ("0.9.2", False), ("0.4.38", False), ("0.10.0", True), ("0.10.2", True), ("0.10.1.dev20260301", True),
    ("0.11.1", True), ("0.11.2", False), ("1.0", False),
])  # fmt: skip
def test_the_deadlocking_jaxlib_releases_are_known(version, bad):
    from diffwash import _jaxlib

    assert _jaxlib.deadlocks(version) is bad


def test_pyproject_excludes_the_deadlocking_jaxlib_and_none_is_installed():
    from importlib import metadata

    from diffwash import _jaxlib

    text = (ROOT / "pyproject.toml").read_text()
    for pkg in ("jax", "jaxlib"):
        assert f'"{pkg}>=0.4.38,!=0.10.*,!=0.11.0,!=0.11.1"' in text
    assert _jaxlib.installed_version() == metadata.version("jaxlib")  # the quick reading is the metadata's
    assert not _jaxlib.deadlocks(metadata.version("jaxlib"))


def test_importing_diffwash_warns_of_a_deadlocking_jaxlib(monkeypatch):
    from diffwash import _jaxlib

    monkeypatch.setattr(_jaxlib, "installed_version", lambda: "0.10.2")
    with pytest.warns(RuntimeWarning, match=r"jaxlib 0\.10\.2 can hang .* pip install 'jax<0\.10' 'jaxlib<0\.10'"):
        _jaxlib.warn_if_deadlocking()


def test_diffwash_version_answers_at_once():
    """A bound that a shared, loaded machine keeps (about 0.1-0.5 s now), but the old 3-14 s start breaks:
    the best of three fresh runs, interpreter start included."""
    best = min(_probe("--version")[1] for _ in range(3))
    assert best < 2.0, f"diffwash --version took {best:.2f} s"


def test_shaders_are_generated_from_the_model():
    """The KM series, the clamps' epsilon and the sRGB breakpoints in the GLSL are the Python ones."""
    from diffwash import colorimetry, km, shading
    from diffwash._glsl import shader_sources
    from diffwash._xp import float_literal

    _, frag = shader_sources("glsl330", "per-pixel", colour="km")
    for c in (*km._CH_COEFFS, *km._SH_COEFFS):
        assert float_literal(c) in frag
    horner = collections.Counter(re.findall(r"\* (t\d+) \+", frag))  # the series' variable: whichever temporary
    assert max(horner.values()) >= 2 * (km.SERIES_TERMS - 1)  # both series, Horner, every term
    assert float_literal(shading.GAIN_BIAS_EPS) in frag
    assert float_literal(colorimetry.SRGB_LINEAR_BREAK) in frag
    assert float_literal(colorimetry.SRGB_ENCODED_BREAK) in frag
    for name in ("km_layer", "km_composite", "km_over", "schlick_bias", "perlin_gain", "watercolour_thicknesses"):
        assert "Generated from diffwash." in frag and f" {name}(" in frag


#: Lines of code (docstrings apart) a function may have before it should be split.
MAX_FUNCTION_LINES = 75


def test_functions_are_short():
    """No function much over 60 lines of code: longer ones are split into named steps."""
    offenders = []
    for path in sorted(PACKAGE.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if not isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                continue
            body = node.body
            doc = body[0] if body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant) else None
            lines = node.end_lineno - node.lineno + 1 - (doc.end_lineno - doc.lineno + 1 if doc else 0)
            if lines > MAX_FUNCTION_LINES:
                offenders.append(f"{path.relative_to(ROOT)}:{node.lineno} {node.name}: {lines} lines")
    assert not offenders, "\n".join(offenders)
