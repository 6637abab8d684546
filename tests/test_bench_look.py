"""benchmarks/bench_look.py's lower bound (section 2c) keeps compiling and drawing as the look's GLSL changes."""

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "benchmarks"))

import bench_look  # noqa: E402


def test_every_bound_variant_compiles_and_draws():
    res = bench_look.gl_bound(64, seconds=0.2, rounds=1)
    names = ["plain LUT shader", "look (LookFrame, every effect)", *(name for name, _ in bench_look.BOUND_VARIANTS)]
    for name in names:
        assert res[name] > 0, name
    assert all(v > 0 for v in res.values())


def test_the_bound_shader_reads_what_each_variant_keeps():
    full = bench_look._bound_fragment()
    assert "look_hatch_ink" in full and "look_mix_colour(w, u, m)" in full and "texelFetch(look_screen1" in full
    bare = bench_look._bound_fragment(hatching=False, lut=False, screen=False)
    assert "#define LOOK_HATCHING 0" in bare and "look_mix_colour(w, u, m)" not in bare and "texelFetch(look_screen" not in bare
    assert "watercolour_thickness" not in bench_look._bound_fragment(model=False)
