"""data/kimera-paintmixing/convert.py and benchmarks/bench_real.py's baselines, on a small made-up upstream file.

The upstream measurements themselves are not in the repository (see data/kimera-paintmixing/README.md), so
these tests write files of the upstream's shape and check what the conversion makes of them.
"""

import json
import sys

import numpy as np
import pytest
from conftest import ROOT

from diffwash import measurements

sys.path.insert(0, str(ROOT / "benchmarks"))
sys.path.insert(0, str(ROOT / "data" / "kimera-paintmixing"))
import bench_real  # noqa: E402
import convert  # noqa: E402

WL = np.linspace(381.2, 719.9, 170)  # the upstream grid's span and count (its steps shrink a little to the red)


def _flat(level: float, rng) -> list[float]:
    return (100 * level + rng.normal(0, 0.2, WL.size)).tolist()  # percent, with a little noise


def _upstream(tmp_path):
    rng = np.random.default_rng(0)
    paints = ["white", "cold yellow", "yellow oxide", "red", "red oxide", "blue red shade", "green", "black"]
    level = dict(zip(paints, [0.9, 0.6, 0.4, 0.3, 0.2, 0.1, 0.15, 0.03]))
    masstone = [{"type": "wavelengths", "values": WL.tolist()}]
    masstone += [{"type": "masstone", "name": p, "reflectance": _flat(level[p], rng)} for p in paints for _ in range(3)]
    mixes = [{"type": "wavelengths", "values": WL.tolist()}]
    for p in paints[1:]:
        comp = {p: 0.2, "white": 0.3}
        mixes += [{"type": "mix", "name": f"{p}+white", "components": comp, "reflectance": _flat(0.5, rng)}
                  for _ in range(3)]  # fmt: skip
    (tmp_path / "masstone.json").write_text(json.dumps(masstone))
    (tmp_path / "mix1.json").write_text(json.dumps(mixes))
    return level


def test_convert_averages_repeats_into_10nm_bands_and_weighs_fractions(tmp_path):
    level = _upstream(tmp_path)
    rows = {(p, a): v for p, a, v in convert.rows(tmp_path)}
    assert ("blue-red-shade", "1") in rows  # names: spaces to hyphens; a masstone is one layer
    assert np.allclose(rows[("red", "1")], level["red"], atol=0.01)  # percent to 0..1, three readings averaged
    assert ("red+white", "0.4000+0.6000") in rows  # 0.2 g + 0.3 g: fractions of the layer, paint first
    assert rows[("red", "1")].shape == (convert.BANDS.size,)


def test_convert_writes_tables_the_reader_takes_with_the_fixed_split(tmp_path, monkeypatch):
    _upstream(tmp_path)
    out = tmp_path / "out"
    monkeypatch.setattr(sys, "argv", ["convert.py", str(tmp_path), "-o", str(out)])
    convert.main()
    train = measurements.read_measurements(out / "kimera-train.csv")
    held = measurements.read_measurements(out / "kimera-heldout.csv")
    every = measurements.read_measurements(out / "kimera-all.csv")
    assert len(train.pigments) + len(held.pigments) == len(every.pigments)
    assert {p[0] for p in held.pigments} == {"yellow-oxide", "red-oxide", "blue-red-shade", "black"}
    assert all(p[1] == "white" for p in held.pigments)
    assert {"yellow-oxide", "red-oxide", "blue-red-shade", "black"} <= {p[0] for p in train.pigments if len(p) == 1}
    assert set(train.grounds) == {"primer"}
    assert np.allclose(train.grounds["primer"], every.values[[p == ("black",) for p in every.pigments]][0])
    assert tuple(train.wavelengths) == tuple(float(b) for b in convert.BANDS)


@pytest.mark.parametrize("baseline", [bench_real.geometric_mean, bench_real.one_constant])
def test_baselines_give_a_paint_alone_back_and_lie_between_two_paints(baseline):
    dark, light = np.array([0.05, 0.2, 0.6]), np.array([0.9, 0.85, 0.8])
    single = {"a": dark, "w": light}
    assert np.allclose(baseline(single, ("a",), (1.0,)), dark, atol=1e-9)
    mixed = baseline(single, ("a", "w"), (0.3, 0.7))
    assert np.all(mixed > np.minimum(dark, light)) and np.all(mixed < np.maximum(dark, light))
    # more of the dark paint, darker
    assert np.all(baseline(single, ("a", "w"), (0.6, 0.4)) < mixed)
