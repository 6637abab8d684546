"""References must span colour space before a camera model is fitted to them; a model that reads the card as no
card could be is refused; the noise of a patch mean never overflows (docs/fitting.md, "Patches of known colour").

Through the command line's entry point (`diffwash.cli.main` in this process): refused layouts exit 2 with one line
naming the layout and `references`, and write nothing."""

import json
from dataclasses import replace

import numpy as np
import pytest
from conftest import DATA
from test_photo_calibration import card_with_references

from diffwash import DiffwashError, colorimetry, pigments
from diffwash.fit.photos._camera import checker_references, fit_camera, lab_to_linear
from diffwash.fit.photos._noise import RGB_TO_YCC, JpegSteps, _row_norms, pixel_noise
from diffwash.fit.photos._photo import calibrate, check_readings, linearise, parse_layout, reference_readings

CARD = DATA / "examples" / "card.jpg"
PAPER, BLACK = [93, 0, 3], [12, 0, 0]


def _example_layout(tmp_path, refs):
    """data/examples/card.json with `refs` [(box, lab), ...] as its references, written to tmp_path/card.json."""
    layout = json.loads((DATA / "examples" / "card.json").read_text())
    layout["references"] = [{"box": box, "lab": lab} for box, lab in refs]
    (tmp_path / "card.json").write_text(json.dumps(layout))


ON_PAPER = [[60, 24, 90, 56], [250, 24, 290, 56], [130, 24, 160, 56], [190, 24, 220, 56]]
ON_BLACK = [[14, 152, 40, 180], [14, 200, 40, 230]]


@pytest.mark.parametrize("refs", [
    [(ON_PAPER[0], PAPER), (ON_PAPER[1], PAPER), (ON_BLACK[0], BLACK), (ON_BLACK[1], BLACK)],  # white and black
    [(ON_PAPER[0], PAPER)] * 4,  # one reference four times
    [(box, PAPER) for box in ON_PAPER] + [(box, BLACK) for box in ON_BLACK],  # greys only
], ids=["paper-and-black", "identical", "greys"])  # fmt: skip
def test_references_of_too_few_colours_are_refused(cli, tmp_path, refs):
    _example_layout(tmp_path, refs)
    before = sorted(p.name for p in tmp_path.iterdir())
    code, out, err = cli("fit-swatch", CARD, "--layout", "card.json", "-o", "out.json")
    assert code == 2, err
    assert err.startswith("diffwash") and err.count("\n") == 1 and "Traceback" not in err, err
    assert "card.json: references: " in err and "span too few colours for a colour matrix" in err, err
    assert "near-neutral" in err and "calibrate from the paper" in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == before and "calibrated from" not in out


def test_coloured_references_on_one_colour_of_the_photo_are_refused(cli, tmp_path):
    # Known colours that span colour space, but every box on the bare paper: the photo shows one colour.
    _example_layout(tmp_path, [(box, lab.tolist()) for box, lab in zip(ON_PAPER, checker_references()[::6])])
    code, out, err = cli("fit-swatch", CARD, "--layout", "card.json", "-o", "out.json")
    assert code == 2 and err.count("\n") == 1, err
    assert "card.json: references: the photo shows the 4 references as too few colours" in err, err
    assert not (tmp_path / "out.json").exists()


def test_coloured_references_still_calibrate_a_jpeg_without_warnings(cli, tmp_path):
    # Eight ColorChecker patches: the references span colour space. A JPEG goes through the noise model's JPEG
    # branch, where the overflow was; warnings are errors here.
    card_with_references(tmp_path, checker_references()[::3][:8], jpeg=True)
    code, out, err = cli("fit-swatch", "card.jpg", "--layout", "card.json", "-o", "rose.json")
    assert code == 0, err
    assert "calibrated from 8 references of known colour" in out and "Warning" not in err, err
    cal = json.loads((tmp_path / "rose.json").read_text())["fit"]["calibration"][0]["camera"]
    assert cal["references"] == 8 and cal["leave_one_out_mean_delta_e_2000"] < 3
    # The patches are read as colours, not black (references of too few colours gave K of 10^4).
    np.testing.assert_allclose(pigments.load(tmp_path / "rose.json").K, pigments.load("Quinacridone Rose").K,
                               rtol=0.5)  # fmt: skip


@pytest.mark.parametrize("lab, ok", [
    (checker_references()[18:], False),  # the ColorChecker's six greys
    (np.array([PAPER, PAPER, BLACK, BLACK], float), False),
    (np.array([[50, 60, 40]] * 4, float), False),  # one red, four times
    (checker_references()[::6], True),  # four of its colours
    (np.array([[95, 0, 0], [50, 60, 40], [60, -50, 40], [40, 10, -50]], float), True),
])  # fmt: skip
def test_fit_camera_needs_references_that_span_colour_space(lab, ok):
    enc = colorimetry.to_display(np.clip(lab_to_linear(lab), 0, 1) * [0.95, 1.0, 0.9])
    if ok:
        model = fit_camera(enc, np.ones(len(lab)), lab, file="card.json")
        assert np.isfinite(model.accuracy) and np.all(model.gain() > 0)
    else:
        with pytest.raises(DiffwashError, match=r"^card\.json: references: the \d references span too few colours"):
            fit_camera(enc, np.ones(len(lab)), lab, file="card.json")


def _synthetic_card():
    """A 16-bit grey card (paper at 0.85, a black band, one patch) as display values, its layout and calibration."""
    display = np.full((80, 120, 3), colorimetry.to_display(0.85))
    display[50:75, 5:25] = colorimetry.to_display(0.01)
    display[10:30, 40:60] = colorimetry.to_display(np.array([0.6, 0.2, 0.3]))
    L = parse_layout({"paper": {"box": [70, 5, 115, 45]}, "black": {"box": [5, 50, 25, 75]},
                      "patches": [{"box": [40, 10, 60, 30], "coats": 1, "ground": "paper"}]}, size=(120, 80))  # fmt: skip
    cal = calibrate(linearise(display), display, 16, L)
    return display, L, cal


@pytest.mark.parametrize("change, words", [
    (lambda M: 0.02 * M, "reads the paper box as"),  # the paper read as near black
    (lambda M: np.full_like(M, np.nan), "not a number"),
    (lambda M: -M, "reads more light as less"),
])  # fmt: skip
def test_a_model_that_reads_the_card_as_no_card_is_refused(change, words):
    display, L, cal = _synthetic_card()
    lab = checker_references()
    model = fit_camera(colorimetry.to_display(np.clip(lab_to_linear(lab), 0, 1)), np.ones(24), lab)
    check_readings(model, display, cal, L, "card.json")  # a sound model reads the card as it is
    enc, light = reference_readings(display, cal, [L.paper])
    np.testing.assert_allclose(model.correct(model.signal(enc) / light[:, None])[0], 0.85, atol=0.03)
    with pytest.raises(DiffwashError, match="^card.json: references: the camera model fitted") as e:
        check_readings(replace(model, matrix=change(model.matrix)), display, cal, L, "card.json")
    assert words in str(e.value) and "\n" not in str(e.value)


@pytest.mark.parametrize("scale", [-1.0, 0.0, 1e-300, 5e-324, 1e6])
@pytest.mark.parametrize("jpeg", [JpegSteps(luma=1.0, chroma=2.0), None])
def test_patch_noise_never_overflows(scale, jpeg):
    # A scale (values per unit of camera signal) that is tiny, zero or negative (as a camera model that read more
    # light as less gave) makes the pixels' spread in code values huge: the old sqrt(RGB_TO_YCC**2 @ sd**2)
    # overflowed. Now a finite covariance, with no warning (warnings are errors here).
    rng = np.random.default_rng(0)
    values = 0.5 + 0.01 * rng.standard_normal((12, 12, 3))
    display = colorimetry.to_display(np.clip(values, 0, 1))
    noise = pixel_noise(values, display, np.full(3, scale), 8, np.zeros(3), np.zeros(3), jpeg)
    assert np.all(np.isfinite(noise.cov)) and np.all(np.isfinite(noise.value))


def test_row_norms_is_the_plain_formula_where_that_does_not_overflow():
    sd = np.array([0.3, 2.0, 7.5])
    np.testing.assert_allclose(_row_norms(RGB_TO_YCC * sd), np.sqrt((RGB_TO_YCC**2) @ sd**2), rtol=1e-14)
    big = _row_norms(RGB_TO_YCC * (sd * 1e300))
    assert np.all(np.isfinite(big))
    np.testing.assert_allclose(big / 1e300, np.sqrt((RGB_TO_YCC**2) @ sd**2), rtol=1e-14)
    assert np.all(_row_norms(np.zeros((3, 3))) == 0)
