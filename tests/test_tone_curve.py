"""Photos without references: read through a typical camera's tone curve when the file names a camera."""

import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from PIL import Image

from diffwash import DiffwashError, colorimetry, pigments
from diffwash.fit.photos._camera import CAMERA_CURVE, camera_curve, default_curve, fit_camera, lab_to_linear
from diffwash.fit.photos._camera import checker_references
from diffwash.fit.photos._swatch import _measure
from diffwash.swatchcard import make_swatch_card


def _camera_jpeg_engine(x):
    """The tone curve `camera_curve` undoes: Naka-Rushton of the raw signal, then the sRGB encoding."""
    a, c = CAMERA_CURVE
    xa = np.clip(x, 0, 1) ** a
    return colorimetry.to_display((1 + c) * xa / (xa + c))


@settings(max_examples=50, deadline=None)
@given(st.lists(st.floats(0, 1), min_size=2, max_size=20))
def test_the_camera_curve_is_monotone_from_0_to_1_and_undoes_the_engine(xs):
    x = np.sort(np.asarray(xs))
    g = camera_curve(_camera_jpeg_engine(x))
    np.testing.assert_allclose(g, x, atol=1e-6)
    assert camera_curve(0.0) == 0 and abs(camera_curve(1.0) - 1) < 1e-12
    assert np.all(np.isfinite(camera_curve(np.linspace(0, 1, 101))))


def _photos(tmp_path):
    """A generated card (sRGB-encoded) and the same scene through a camera's JPEG engine, with EXIF naming a camera
    and without."""
    card = make_swatch_card(pigments.load("Quinacridone Rose"), coats=(1, 2, 4), patch=40, seed=5)
    (tmp_path / "card.json").write_text(json.dumps(card.layout))
    linear = colorimetry.from_display(card.photo) * 0.9  # the paper at about 80% of the sensor's clipping
    engine = np.round(255 * np.clip(_camera_jpeg_engine(linear), 0, 1)).astype(np.uint8)
    exif = Image.Exif()
    exif[0x010F], exif[0x0110] = "Phone Maker", "Model 7"
    Image.fromarray(engine).save(tmp_path / "phone.png", exif=exif)
    Image.fromarray(engine).save(tmp_path / "stripped.png")
    Image.fromarray(np.round(255 * card.photo).astype(np.uint8)).save(tmp_path / "srgb.png")
    return tmp_path / "card.json"


def _de(a, b):
    lab = lambda m: colorimetry.linear_srgb_to_lab(np.clip([s.rgb for s in m.patches], 1e-6, None))  # noqa: E731
    return float(np.mean(np.asarray(colorimetry.delta_e_2000(lab(a), lab(b)))))


def test_a_phone_photo_is_read_through_the_camera_curve_when_its_exif_names_a_camera(tmp_path):
    layout = _photos(tmp_path)
    truth = _measure(tmp_path / "srgb.png", layout)
    phone = _measure(tmp_path / "phone.png", layout)
    assert _de(phone, truth) < 1.0
    assert "EXIF names a camera, Phone Maker Model 7" in " ".join(phone.calibration.notes)
    # The same pixels with the metadata removed are read as sRGB, and come out too light in the mid-tones.
    stripped = _measure(tmp_path / "stripped.png", layout)
    assert _de(stripped, truth) > 3.0 and "no camera named" in " ".join(stripped.calibration.notes)
    assert _de(_measure(tmp_path / "stripped.png", layout, tone_curve="camera"), truth) < 1.0
    assert _de(_measure(tmp_path / "phone.png", layout, tone_curve="srgb"), truth) > 3.0
    # The assumed curve's typical error widens each patch's noise (a colour floor).
    assert np.all(np.diag(phone.patches[0].cov) > np.diag(_measure(tmp_path / "phone.png", layout,
                                                                    tone_curve="srgb").patches[0].cov))  # fmt: skip


def test_a_plain_srgb_file_is_read_through_the_srgb_curve(tmp_path):
    layout = _photos(tmp_path)
    truth = _measure(tmp_path / "srgb.png", layout)
    assert truth.calibration.curve.kind == "srgb" and truth.calibration.curve_accuracy == 0


def test_the_cli_takes_the_tone_curve_and_says_which(run_cli, tmp_path):
    _photos(tmp_path)
    r = run_cli("fit-swatch", "stripped.png", "--layout", "card.json", "-o", "rose.json", "--tone-curve", "camera")
    assert r.returncode == 0, r.stderr
    assert "note: read through a typical camera's tone curve (as asked)" in r.stdout
    r = run_cli("fit-swatch", "--table", "t.csv", "-o", "x.json", "--tone-curve", "srgb")
    assert r.returncode == 2 and "--tone-curve: only applies to photos" in r.stderr
    r = run_cli("fit-swatch", "phone.png", "--layout", "card.json", "-o", "x.json", "--tone-curve", "film")
    assert r.returncode == 2 and "--tone-curve" in r.stderr and not (tmp_path / "x.json").exists()


def test_an_unknown_tone_curve_is_refused():
    with pytest.raises(DiffwashError, match="unknown tone curve 'film'"):
        default_curve(None, "film")


def test_references_choose_the_camera_curve_when_the_photo_was_made_through_one():
    lab = checker_references()
    enc = np.round(255 * _camera_jpeg_engine(0.7 * np.clip(lab_to_linear(lab), 0, None))) / 255
    model = fit_camera(enc[::3], np.ones(8), lab[::3])
    assert model.curve.kind in ("camera", "fitted"), model.scores
    assert model.scores["typical camera curve + Cheung 2004 (3 terms)"] < model.scores[
        "sRGB curve + Cheung 2004 (3 terms)"]  # fmt: skip
