"""The baked LUT against a high-precision Kubelka-Munk written here, its convention, files and sidecar."""

import json
from importlib import resources

import hypothesis.strategies as st
import jsonschema
import mpmath
import numpy as np
import pytest
from hypothesis import given, settings
from PIL import Image

import diffwash
from diffwash import colorimetry, lut
from diffwash.pigments import Pigment
from diffwash.shading import Params

import km_reference
from conftest import DATA

# The reference: the textbook Kubelka-Munk of Curtis et al. (1997, sec. 5), in 50-digit mpmath.
km_layer_ref = km_reference.layer


def glaze_ref(wash_pig, unlit_pig, paper, wash, unlit):
    """(R, T) of the unlit layer on the wash layer, and the colour over the paper, per channel."""
    R_out, T_out, colour = [], [], []
    for c in range(3):
        Rw, Tw = km_layer_ref(wash_pig[0][c], wash_pig[1][c], wash)
        Ru, Tu = km_layer_ref(unlit_pig[0][c], unlit_pig[1][c], unlit)
        d = 1 - Ru * Rw
        R = Ru + Tu * Tu * Rw / d
        T = Tu * Tw / d
        P = mpmath.mpf(paper[c])
        R_out.append(float(R))
        T_out.append(float(T))
        colour.append(float(R + T * T * P / (1 - R * P)))
    return np.array(colour), np.array(R_out), np.array(T_out)


def params_with(**kw):
    rose = diffwash.pigments.load("quinacridone rose")
    blue = diffwash.pigments.load("french ultramarine")
    base = dict(wash=rose, unlit=blue, k_wash=1.3, k_specular=0.8, k_unlit=1.7)
    base.update(kw)
    return Params(**base)


def _check_against_reference(table, params, kind, tol):
    n, m = table.size
    wp = (np.asarray(params.wash.K), np.asarray(params.wash.S))
    up = (np.asarray(params.unlit.K), np.asarray(params.unlit.S))
    rows = sorted({0, m - 1, m // 2, 1})
    cols = sorted({0, n - 1, n // 3, 1})
    for j in rows:
        for i in cols:
            # The convention, written out: column i = wash i/(N-1) wash_max, row j = unlit j/(M-1) unlit_max.
            w = i / (n - 1) * float(params.k_specular * params.k_wash)
            u = j / (m - 1) * float(params.k_unlit)
            colour, R, T = glaze_ref(wp, up, np.asarray(params.paper), w, u)
            expected = colour if kind == "colour" else np.concatenate([R, T])
            np.testing.assert_allclose(table.values[j, i], expected, atol=tol, rtol=0, err_msg=f"row {j} column {i}")


@pytest.mark.parametrize("kind", ["colour", "rt"])
def test_bake_matches_high_precision_reference(kind):
    params = params_with()
    # Non-square, so a transposed table cannot pass.
    table = lut.bake(params, (9, 6), kind=kind)
    assert table.size == (9, 6)
    assert table.values.shape == (6, 9, 3 if kind == "colour" else 6)
    assert table.wash_max == pytest.approx(0.8 * 1.3) and table.unlit_max == pytest.approx(1.7)
    np.testing.assert_allclose(table.wash, np.linspace(0, 0.8 * 1.3, 9))
    np.testing.assert_allclose(table.unlit, np.linspace(0, 1.7, 6))
    _check_against_reference(table, params, kind, tol=2e-6)  # float32 storage


pigment_values = st.lists(st.floats(0, 5), min_size=3, max_size=3)


@settings(max_examples=15)
@given(
    wk=pigment_values,
    ws=pigment_values,
    uk=pigment_values,
    us=pigment_values,
    paper=st.lists(st.floats(0, 1), min_size=3, max_size=3),
    k_wash=st.floats(0.01, 4),
    k_unlit=st.floats(0.01, 4),
)
def test_bake_any_pigments_matches_reference(wk, ws, uk, us, paper, k_wash, k_unlit):
    params = Params(
        wash=Pigment(K=np.array(wk), S=np.array(ws), name="w"),
        unlit=Pigment(K=np.array(uk), S=np.array(us), name="u"),
        paper=np.array(paper),
        k_wash=k_wash,
        k_unlit=k_unlit,
    )
    table = lut.bake(params, 5, kind="colour")
    _check_against_reference(table, params, "colour", tol=2e-6)
    rt = lut.bake(params, 5, kind="rt")
    _check_against_reference(rt, params, "rt", tol=2e-6)
    # The R/T table over its paper is the colour table.
    np.testing.assert_allclose(rt.colour, table.values, atol=2e-6)


def test_bake_from_scene_file_and_scene():
    scene = diffwash.load_scene(DATA / "scenes" / "sphere.json")
    a = lut.bake(DATA / "scenes" / "sphere.json", 4)
    b = lut.bake(scene, 4)
    np.testing.assert_array_equal(a.values, b.values)
    assert a.meta["pigments"]["wash"]["name"] == "Cadmium Yellow"
    assert a.meta["constants"]["k_unlit"] == 1.5 and a.unlit_max == 1.5


def test_zero_range_is_finite():
    table = lut.bake(params_with(k_wash=0.0, k_unlit=0.0), 3)
    assert table.wash_max == 0 and table.unlit_max == 0
    # Every sample is bare paper.
    np.testing.assert_allclose(table.values, np.broadcast_to(np.asarray(params_with().paper), (3, 3, 3)), atol=1e-7)
    assert np.all(table.lookup(0.3, 0.2) == table.values[0, 0])


@pytest.mark.parametrize("size", [1, 0, 4097, -3, 2.5, True, (4, 1), (4, 5, 6)])
def test_bad_sizes(size):
    with pytest.raises(diffwash.DiffwashError, match="size"):
        lut.bake(params_with(), size)


def test_lookup_is_bilinear_on_the_grid():
    table = lut.bake(params_with(), (7, 5))
    # At the samples it returns the samples; halfway between, the mean.
    np.testing.assert_allclose(table.lookup(table.wash[3], table.unlit[2]), table.values[2, 3], atol=1e-7)
    mid = table.lookup((table.wash[3] + table.wash[4]) / 2, table.unlit[4])
    np.testing.assert_allclose(mid, (table.values[4, 3].astype(float) + table.values[4, 4]) / 2, atol=1e-7)
    # Outside the range it clamps to the edges.
    np.testing.assert_allclose(table.lookup(99.0, -1.0), table.values[0, -1], atol=1e-7)


# --- files and the sidecar --------------------------------------------------------------------------


@pytest.fixture(scope="module")
def tables():
    params = params_with()
    return {"colour": lut.bake(params, (17, 11)), "rt": lut.bake(params, (17, 11), kind="rt")}


def sidecar_schema():
    return json.loads((resources.files("diffwash") / "data" / "lut.schema.json").read_text())


@pytest.mark.parametrize("fmt", ["png16", "png8", "exr", "npy"])
@pytest.mark.parametrize("kind", ["colour", "rt"])
def test_save_load_round_trip(tmp_path, tables, fmt, kind):
    table = tables[kind]
    path = tmp_path / f"lut{lut.FORMATS[fmt][0]}"
    written = lut.save(path, table, fmt)
    assert written[-1] == tmp_path / "lut.json"
    assert all(p.is_file() for p in written)
    assert not [p for p in tmp_path.iterdir() if p.name.endswith(".part")]
    back = lut.load(path)
    assert back.kind == kind and back.size == table.size
    assert back.wash_max == table.wash_max and back.unlit_max == table.unlit_max
    if fmt in ("exr", "npy"):
        np.testing.assert_array_equal(back.values, table.values)
    else:
        # Exactly the stored integers come back (decode, then encode again).
        np.testing.assert_array_equal(lut.encoded(back, fmt), lut.encoded(table, fmt))
        step = 1 / 65535 if fmt == "png16" else 1 / 255
        # sRGB quantisation: linear error <= half a step times the decoding slope (<= 1/12.92 near 0, <= 2.4/1.055 at 1).
        assert np.abs(back.values - table.values).max() <= 0.5 * step * 2.3 + 1e-7
    # Loading through the sidecar works too, and the sidecar follows the schema and says what the issue asks.
    assert lut.load(tmp_path / "lut.json").size == table.size
    side = json.loads((tmp_path / "lut.json").read_text())
    jsonschema.validate(side, sidecar_schema())
    assert side["size"] == list(table.size)
    assert side["encoding"] == ("srgb" if fmt.startswith("png") else "linear")
    assert side["pigments"]["wash"]["name"] == "Quinacridone Rose"
    assert side["paper"] == pytest.approx(list(diffwash.shading.DEFAULT_PAPER))
    assert set(side["constants"]) == set(diffwash.shading.DEFAULT_CONSTANTS)
    assert side["diffwash_version"] == diffwash.__version__


def test_png_orientation_read_independently(tmp_path, tables):
    """Read the PNG with Pillow: top-right is the thickest wash without unlit, bottom-left the reverse."""
    table = tables["colour"]
    lut.save(tmp_path / "lut.png", table, "png8")
    img = np.asarray(Image.open(tmp_path / "lut.png").convert("RGB"), np.float64) / 255
    assert img.shape == (11, 17, 3)
    params = params_with()
    wp = (np.asarray(params.wash.K), np.asarray(params.wash.S))
    up = (np.asarray(params.unlit.K), np.asarray(params.unlit.S))
    for (row, col), (w, u) in {(0, 16): (table.wash_max, 0), (10, 0): (0, table.unlit_max), (10, 16): (table.wash_max, table.unlit_max)}.items():
        colour, _, _ = glaze_ref(wp, up, np.asarray(params.paper), w, u)
        np.testing.assert_allclose(img[row, col], colorimetry.to_display(colour), atol=0.6 / 255)


def test_nothing_half_written(tmp_path, tables):
    # The sidecar's name is taken by a folder: refused before anything is written.
    (tmp_path / "lut.json").mkdir()
    with pytest.raises(diffwash.DiffwashError, match=r"lut\.json: is a folder"):
        lut.save(tmp_path / "lut.png", tables["colour"])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["lut.json"]
    assert not (tmp_path / "lut.png").exists()


def test_unwritable_folder(tmp_path, tables):
    with pytest.raises(diffwash.DiffwashError, match="does not exist"):
        lut.save(tmp_path / "nope" / "lut.png", tables["colour"])
    # /proc takes no new files, even from root.
    with pytest.raises(diffwash.DiffwashError, match="cannot write"):
        lut.save("/proc/lut.png", tables["colour"])


@pytest.mark.parametrize(
    "path, fmt, message",
    [("lut.jpg", None, "extension"), ("lut.png", "exr", "needs a .exr"), ("lut.npy", "tiff", "must be one of")],
)
def test_bad_format(tmp_path, tables, path, fmt, message):
    with pytest.raises(diffwash.DiffwashError, match=message):
        lut.save(tmp_path / path, tables["colour"], fmt)


def test_load_errors(tmp_path, tables):
    with pytest.raises(diffwash.DiffwashError, match="no sidecar"):
        lut.load(tmp_path / "missing.png")
    lut.save(tmp_path / "lut.png", tables["colour"])
    side = json.loads((tmp_path / "lut.json").read_text())
    (tmp_path / "lut.json").write_text(json.dumps({**side, "size": [17, 12]}))
    with pytest.raises(diffwash.DiffwashError, match="size"):
        lut.load(tmp_path / "lut.png")
    (tmp_path / "lut.json").write_text(json.dumps({k: v for k, v in side.items() if k != "wash_max"}))
    with pytest.raises(diffwash.DiffwashError, match="wash_max: missing key"):
        lut.load(tmp_path / "lut.png")
    (tmp_path / "lut.json").write_text(json.dumps({"hello": 1}))
    with pytest.raises(diffwash.DiffwashError, match="not a diffwash LUT sidecar"):
        lut.load(tmp_path / "lut.json")
