"""Issue 22: each look effect written once, as the model is (`diffwash._xp`), and `diffwash.look` free of OpenGL.

The per-pixel arithmetic of every effect lives in `diffwash/look/` as functions of an array namespace; the
shaders are those functions traced (`diffwash._look_glsl`); each `Look` leaf is declared once, and the scene
reader's key lists and the shaders' uniforms come from that declaration.
"""

import ast
import os
import re
import subprocess
import sys

import numpy as np
import pytest
from conftest import ROOT

from diffwash import _look_glsl, _watercolour
from diffwash import look as wl

LOOK = ROOT / "diffwash" / "look"
#: What only GLSL source says (a string holding any of these is shader code).
_GLSL = re.compile(r"\b(uniform|texelFetch|textureSize|gl_FragCoord|void main|vec[234]\(|#version)\b")


def _glsl_lines(path) -> int:
    """Lines of GLSL in the string constants of a Python file (docstrings, which may name GLSL, apart)."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    holders = [n for n in ast.walk(tree) if isinstance(n, (ast.Module, ast.ClassDef, ast.FunctionDef))]
    docs = {id(h.body[0].value) for h in holders if h.body and isinstance(h.body[0], ast.Expr)}
    strings = [n.value for n in ast.walk(tree) if isinstance(n, ast.Constant) and isinstance(n.value, str) and id(n) not in docs]
    return sum(len(s.splitlines()) for s in strings if _GLSL.search(s) and ";" in s)


def test_no_glsl_is_written_in_the_look_package():
    counts = {p.name: _glsl_lines(p) for p in sorted(LOOK.glob("*.py"))}
    assert sum(counts.values()) == 0, counts
    assert _glsl_lines(ROOT / "diffwash" / "_look_glsl.py") > 0  # the check sees GLSL where there is some


def test_the_look_imports_no_opengl():
    """`diffwash.look` and every module in it load without moderngl (the host code lives outside)."""
    modules = [f"diffwash.look.{p.stem}" for p in sorted(LOOK.glob("_*.py")) if p.stem != "__init__"]
    code = "import importlib, sys\n" + "".join(f"importlib.import_module({m!r})\n" for m in ["diffwash.look", *modules])
    code += "print('moderngl' in sys.modules)\n"
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    run = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    assert run.stdout.strip() == "False"


def test_the_final_pass_and_the_surface_are_the_look_functions_traced():
    final = _look_glsl.glsl_final_pass(height=512)
    for fn in ("pixel_terms", "edge_darken", "stroke_factor", "pigment_factor", "deposit", "unevenness_factor", "paper_shading"):
        assert re.search(rf"// Generated from diffwash\.look\._\w+\.{fn}\.", final), fn
    assert "// Generated from diffwash.colorimetry.srgb_encode." in final
    # The model's constant, as Python has it, in the traced deposit: no retyped formula.
    assert "look_deposit(h, pigment.x, pigment.y) / pigment.z" in final
    surface = _look_glsl.glsl_surface()
    assert surface.count("vec2 look_surface(") == 2  # traced with and without hatching


def test_each_leaf_is_declared_once_and_the_scene_keys_follow():
    specs = wl.leaf_specs()
    assert list(specs) == list(wl.DEFAULT_LOOK) == [f for f in wl.Look.__dataclass_fields__]
    for leaf, spec in specs.items():
        assert _watercolour.WATERCOLOUR_KEYS[spec.effect][spec.key] == spec.on
        name = f"watercolour.{spec.effect}.{spec.key}"
        assert (_watercolour.LOOK_PARAMETERS.get(name) == leaf) == spec.fit
        assert (name in _watercolour.LOOK_FRACTIONS) == (spec.at_most == 1)
        assert f"uniform float look_{leaf};" in _look_glsl.look_declarations()
    uniforms = wl.look_uniforms(wl.Look(), wl.Pigments.single(*(wl.PigmentLook(0.5, 2.0, 0.5, 0.0),) * 2), height=64)
    assert {f"look_{leaf}" for leaf in specs} <= set(uniforms)
    # The defaults as the scene reader applies them: the effects on by default are those whose strengths are.
    assert _watercolour._ON_BY_DEFAULT == ("edges", "paper", "unevenness", "strokes", "shadow")
    assert _watercolour.WATERCOLOUR_KEYS["hatching"]["amount"] == 0.5 and wl.DEFAULT_LOOK["hatching"] == 0.0


@pytest.mark.parametrize("x64", [True])
def test_glaze_mix_is_the_models_glaze_of_the_mixtures(x64):
    from diffwash import shading
    from diffwash.pigments import Pigment

    a = Pigment(K=np.array([0.22, 1.47, 0.57]), S=np.array([0.05, 0.003, 0.03]))
    b = Pigment(K=np.array([0.86, 0.86, 0.06]), S=np.array([0.005, 0.005, 0.09]))
    params = shading.Params(wash=a, unlit=b)
    w, u = np.linspace(0, 1.5, 7), np.linspace(0.2, 0.9, 7)
    np.testing.assert_array_equal(wl.glaze_mix(params, b, a, w, u, 0.0 * w), shading.glaze(params, w, u))
    swapped = shading.Params(wash=b, unlit=a)
    np.testing.assert_allclose(wl.glaze_mix(params, b, a, w, u, 1.0 + 0 * w), shading.glaze(swapped, w, u), rtol=1e-12)
