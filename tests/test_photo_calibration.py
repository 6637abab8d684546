"""Photos calibrated from patches of known colour: the camera model, the layout's references, --checker, raw."""

import json
import sys

import numpy as np
import pytest
from PIL import Image
from hypothesis import given, settings
from hypothesis import strategies as st

from diffwash import DiffwashError, colorimetry
from diffwash._io import write_png
from diffwash.fit.photos._camera import _fit_curve, checker_references, find_checker, fit_camera, lab_to_linear, read_raw
from diffwash.fit import fit_swatches
from diffwash.fit.photos._photo import parse_layout
from diffwash.swatchcard import make_swatch_card
from diffwash import pigments


def _s_curve(x):
    """A phone-like tone curve: sRGB, steeper mid-tones, lifted blacks."""
    e = colorimetry.to_display(np.clip(x, 0, 1))
    return 0.05 + 0.93 * np.clip(e + 0.3 * (e - 0.5) * (1 - np.abs(2 * e - 1)), 0, 1)


CROSSTALK = np.array([[0.82, 0.15, 0.03], [0.10, 0.80, 0.10], [0.02, 0.18, 0.80]]) * [1.08, 1.0, 0.9]


def test_camera_model_undoes_a_tone_curve_and_crosstalk():
    lab = checker_references()
    enc = _s_curve(np.clip(lab_to_linear(lab), 0, None) @ CROSSTALK.T)
    model = fit_camera(enc, np.ones(24), lab)
    assert model.curve.kind == "fitted" and model.accuracy < 1.5, model.scores
    # The sRGB curve and a 3x3 matrix (colour-science's default correction after sRGB linearisation) is far off.
    assert model.scores["sRGB curve + Cheung 2004 (3 terms)"] > model.accuracy
    pred = model.correct(model.signal(enc))
    assert np.mean(np.asarray(colorimetry.delta_e_2000(colorimetry.linear_srgb_to_lab(np.clip(pred, 0, None)),
                                                       lab))) < 1.0  # fmt: skip


def _layout(**extra):
    return {"paper": {"box": [0, 0, 10, 10]}, "patches": [{"box": [20, 20, 30, 30], "coats": 1, "ground": "paper"}],
            **extra}  # fmt: skip


@pytest.mark.parametrize("ref, field, words", [
    ({"box": [40, 0, 50, 10], "lab": [120, 0, 0]}, "references[0].lab[0]", "must be <= 100, got 120"),
    ({"box": [40, 0, 50, 10], "lab": [50, 300, 0]}, "references[0].lab[1]", "must be <= 200, got 300"),
    ({"box": [90, 0, 150, 10], "lab": [50, 0, 0]}, "references[0].box", "outside the 100x80 photo"),
    ({"box": [40, 0, 50, 10], "reflectance": [0.5, 1.2, 0.1]}, "references[0].reflectance[1]", "must be <= 1, got 1.2"),
    ({"box": [40, 0, 50, 10], "lab": [50, 0, 0], "reflectance": [0.5, 0.5, 0.5]}, "references[0]", "exactly one"),
    ({"box": [40, 0, 50, 10], "spectrum": [0.5, 0.5]}, "references[0].wavelengths", "missing"),
    ({"box": [40, 0, 50, 10], "spectrum": [0.5, 0.5], "wavelengths": [450, 650]}, "references[0].wavelengths",
     "400-700"),
])  # fmt: skip
def test_bad_references_name_the_field(ref, field, words):
    with pytest.raises(DiffwashError) as e:
        parse_layout(_layout(references=[ref]), file="card.json", size=(100, 80))
    assert f"card.json: {field}:" in str(e.value) and words in str(e.value)


def test_the_paper_may_be_given_as_lab_and_its_default_is_said():
    lab = [95.0, -0.5, 1.0]
    L = parse_layout(_layout(paper={"box": [0, 0, 10, 10], "lab": lab}), size=(100, 80))
    np.testing.assert_allclose(L.paper_reflectance, lab_to_linear(np.array(lab)), rtol=1e-9)
    assert not L.paper_default and parse_layout(_layout(), size=(100, 80)).paper_default
    with pytest.raises(DiffwashError, match="card.json: paper.lab: give the paper's reflectance or its lab"):
        parse_layout(_layout(paper={"box": [0, 0, 10, 10], "lab": lab, "reflectance": [0.9] * 3}), file="card.json",
                     size=(100, 80))  # fmt: skip
    with pytest.raises(DiffwashError, match="card.json: paper.lab: is outside the sRGB gamut"):
        parse_layout(_layout(paper={"box": [0, 0, 10, 10], "lab": [60, 120, 0]}), file="card.json", size=(100, 80))


def test_the_default_paper_is_said_in_a_note(tmp_path):
    card = make_swatch_card(pigments.load("Quinacridone Rose"), coats=(1, 2), patch=40, seed=3)
    layout = {**card.layout, "paper": {"box": card.layout["paper"]["box"]}}
    notes = " ".join(fit_swatches(card.photo, layout).calibrations[0].notes)
    assert "the paper box's colour was not given" in notes
    given = {**card.layout, "paper": {"box": card.layout["paper"]["box"], "reflectance": [0.9, 0.9, 0.88]}}
    assert "was not given" not in " ".join(fit_swatches(card.photo, given).calibrations[0].notes)


def test_reference_forms_agree():
    lab = [52.0, 18.0, -20.0]
    rgb = lab_to_linear(np.array(lab)).tolist()
    wl = list(range(380, 790, 10))
    L = parse_layout(_layout(references=[{"box": [40, 0, 50, 10], "lab": lab},
                                         {"box": [40, 0, 50, 10], "reflectance": rgb},
                                         {"box": [40, 0, 50, 10], "spectrum": [0.5] * len(wl), "wavelengths": wl}]),
                     size=(100, 80))  # fmt: skip
    np.testing.assert_allclose(L.references[1].lab, lab, atol=0.01)
    np.testing.assert_allclose(L.references[2].lab, [76.07, 0, 0], atol=0.2)  # a flat 50% grey
    assert parse_layout(L.to_dict(), size=(100, 80)).references[0].box == L.references[0].box


def card_with_references(tmp_path, lab, jpeg: bool = False):
    """A generated swatch card (Quinacridone Rose) with a strip of patches of known colour `lab` (at most 8) above
    it, as the camera saw them (its exposure and white balance, sRGB-encoded): tmp_path/card.png (16 bits), or
    card.jpg (quality 90) with `jpeg`; its layout as tmp_path/card.json."""
    card = make_swatch_card(pigments.load("Quinacridone Rose"), coats=(1, 2), patch=40, seed=3)
    H, W, _ = card.photo.shape
    side, strip = 24, 76
    photo = np.concatenate([np.repeat(card.photo[:1], strip, axis=0), card.photo], axis=0)
    gains = card.effects.exposure * np.asarray(card.effects.white_balance)
    refs = []
    for i, c in enumerate(lab):
        x0, y0 = 8 + (i % 4) * (side + 6), 8 + (i // 4) * (side + 6)
        photo[y0 : y0 + side, x0 : x0 + side] = colorimetry.to_display(np.clip(lab_to_linear(c) * gains, 0, 1))
        refs.append({"box": [x0, y0, x0 + side, y0 + side], "lab": np.asarray(c).tolist()})
    assert len(lab) <= 8 and 8 + 4 * (side + 6) < W
    layout = json.loads(json.dumps(card.layout))
    shift = lambda b: [b[0], b[1] + strip, b[2], b[3] + strip]  # noqa: E731
    for part in (layout["paper"], layout["black"], *layout["patches"]):
        part["box"] = shift(part["box"])
    layout["references"] = refs
    if jpeg:
        Image.fromarray(np.round(255 * np.clip(photo, 0, 1)).astype(np.uint8)).save(tmp_path / "card.jpg", quality=90)
    else:
        write_png(tmp_path / "card.png", photo, bits=16)
    (tmp_path / "card.json").write_text(json.dumps(layout))


def _card_with_references(tmp_path, n):
    """`card_with_references` with `n` of the checker's patches."""
    card_with_references(tmp_path, checker_references()[:: max(1, 24 // n)][:n])


def test_fit_swatch_reads_the_photo_through_references(run_cli, tmp_path):
    _card_with_references(tmp_path, 8)
    r = run_cli("fit-swatch", "card.png", "--layout", "card.json", "-o", "rose.json")
    assert r.returncode == 0, r.stderr
    assert "calibrated from 8 references of known colour" in r.stdout
    cal = json.loads((tmp_path / "rose.json").read_text())["fit"]["calibration"][0]["camera"]
    assert cal["references"] == 8 and cal["leave_one_out_mean_delta_e_2000"] < 3


def test_too_few_references_exit_2_and_write_nothing(run_cli, tmp_path):
    _card_with_references(tmp_path, 3)
    r = run_cli("fit-swatch", "card.png", "--layout", "card.json", "-o", "rose.json")
    assert r.returncode == 2 and "card.json: references:" in r.stderr and "at least 4" in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and not (tmp_path / "rose.json").exists()


def test_checker_not_found_exit_2(run_cli, tmp_path):
    _card_with_references(tmp_path, 4)
    r = run_cli("fit-swatch", "card.png", "--layout", "card.json", "-o", "rose.json", "--checker")
    assert r.returncode == 2 and "no X-Rite ColorChecker Classic found" in r.stderr and "--checker" in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and not (tmp_path / "rose.json").exists()


def test_raw_photo_is_read_linear(run_cli, tmp_path):
    # A DNG written here (tests/dng_writer.py: an RGGB mosaic of linear values) comes back linear: no gamma, no
    # brightening; fit-swatch fits a card from it as from the PNG.
    from dng_writer import write_dng

    card = make_swatch_card(pigments.load("Quinacridone Rose"), coats=(1, 2), patch=40, seed=3)
    H, W, _ = card.photo.shape
    linear = colorimetry.from_display(card.photo[: H // 2 * 2, : W // 2 * 2])
    write_dng(tmp_path / "card.dng", linear)
    from diffwash.fit.photos._camera import read_raw

    back = read_raw(tmp_path / "card.dng")
    med = lambda a, b: np.median(a[b[1] + 4 : b[3] - 4, b[0] + 4 : b[2] - 4].reshape(-1, 3), axis=0)  # noqa: E731
    # Linear: one scale for every box and channel (LibRaw may scale the whole range).
    ratios = [med(back, b) / med(linear, b) for b in [card.layout["paper"]["box"]] +
              [p["box"] for p in card.layout["patches"]]]  # fmt: skip
    np.testing.assert_allclose(ratios, ratios[0][0], rtol=0.03)
    (tmp_path / "card.json").write_text(json.dumps(card.layout))
    r = run_cli("fit-swatch", "card.dng", "--layout", "card.json", "-o", "rose.json")
    assert r.returncode == 0, r.stderr
    np.testing.assert_allclose(pigments.load(tmp_path / "rose.json").K, pigments.load("Quinacridone Rose").K,
                               rtol=0.15)  # fmt: skip


def test_a_file_that_is_not_raw_is_one_line(run_cli, tmp_path):
    (tmp_path / "card.dng").write_bytes(b"not a raw photo")
    (tmp_path / "card.json").write_text(json.dumps(_layout()))
    r = run_cli("fit-swatch", "card.dng", "--layout", "card.json", "-o", "rose.json")
    assert r.returncode == 2 and "card.dng: cannot read as a raw photo" in r.stderr, r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and not (tmp_path / "rose.json").exists()


def test_checker_in_the_photo_calibrates_it(run_cli, tmp_path):
    # A ColorChecker beside a generated swatch card, seen by the card's camera (exposure, white balance, sRGB):
    # --checker finds it and reads the photo through a camera model fitted to its 24 patches.
    card = make_swatch_card(pigments.load("Quinacridone Rose"), coats=(1, 2), patch=40, seed=3)
    H, W, _ = card.photo.shape
    s, g = 50, 10
    gains = card.effects.exposure * np.asarray(card.effects.white_balance)
    photo = np.ones((max(H, 4 * (s + g) + 60), W + 6 * (s + g) + 60, 3)) * card.photo[2, 2]
    photo[:H, :W] = card.photo
    x0, y0 = W + 30, 30
    photo[y0 - g : y0 + 4 * (s + g), x0 - g : x0 + 6 * (s + g)] = colorimetry.to_display(0.02 * gains)
    for i, lab in enumerate(checker_references()):
        r, c = divmod(i, 6)
        y, x = y0 + r * (s + g), x0 + c * (s + g)
        photo[y : y + s, x : x + s] = colorimetry.to_display(np.clip(lab_to_linear(lab) * gains, 0, 1))
    write_png(tmp_path / "card.png", photo, bits=16)
    (tmp_path / "card.json").write_text(json.dumps(card.layout))
    r = run_cli("fit-swatch", "card.png", "--layout", "card.json", "-o", "rose.json", "--checker")
    assert r.returncode == 0, r.stderr
    assert "calibrated from 24 references of known colour" in r.stdout
    cam = json.loads((tmp_path / "rose.json").read_text())["fit"]["calibration"][0]["camera"]
    assert cam["references"] == 24 and cam["leave_one_out_mean_delta_e_2000"] < 1.5


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), n=st.integers(6, 12))
def test_fitted_tone_curve_is_monotone_whatever_the_references(seed, n):
    # The curve's Bernstein coefficients are non-decreasing by construction, so the curve is monotone: an encoded
    # value never reads darker than a smaller one, even from noisy or contradictory references.
    rng = np.random.default_rng(seed)
    lab = np.column_stack([rng.uniform(5, 95, n), rng.uniform(-60, 60, n), rng.uniform(-60, 60, n)])
    enc = np.clip(rng.uniform(0, 1, (n, 3)), 0, 1)
    curve, M = _fit_curve(enc, rng.uniform(0.7, 1.1, n), lab_to_linear(lab))
    g = curve(np.linspace(0, 1, 201))
    assert curve.kind == "fitted" and np.all(np.isfinite(g)) and np.all(np.diff(g) >= -1e-12)
    assert np.all(np.isfinite(M))


@pytest.mark.parametrize("module, call", [("rawpy", lambda: read_raw("card.dng")),
                                          ("colour_checker_detection", lambda: find_checker(np.zeros((8, 8, 3))))])
def test_missing_photo_extra_is_one_line_naming_it(monkeypatch, module, call):
    monkeypatch.setitem(sys.modules, module, None)  # as if not installed
    with pytest.raises(DiffwashError) as e:
        call()
    assert "pip install 'diffwash[photo]'" in str(e.value) and "\n" not in str(e.value)
