"""Pigments from swatch-card photos: the generator, calibration, patch statistics and the fit's accuracy."""

import json

import numpy as np
import pytest
from PIL import Image

from diffwash import DiffwashError, km, library, pigments
from diffwash._io import read_image
from diffwash.fit import fit_swatches, parse_layout
from diffwash.fit.photos._photo import calibrate, linearise, patch_stats
from diffwash.fit import save_swatch_report
from diffwash.fit._kmfit import delta_e_displayed
from diffwash.swatchcard import IDEAL, CameraEffects, make_swatch_card, save_swatch_card

SEEN = (1, 2, 4)
UNSEEN = (3, 5)


def held_out_error(card, fit):
    """Mean CIEDE2000 between the fitted pigment and the truth at the coat counts the fit did not see."""
    out = []
    for c in UNSEEN:
        for ground in (card.paper, card.ink):
            R, T = km.layer(card.pigment.K, card.pigment.S, c)
            truth = np.asarray(km.over(R, T, ground))
            out.append(float(delta_e_displayed(fit.predict([c], ground)[0], truth)))
    return float(np.mean(out))


def seen_only(layout):
    return {**layout, "patches": [p for p in layout["patches"] if p["coats"] in SEEN]}


@pytest.mark.parametrize(
    "name, effects, suffix",
    [
        ("Quinacridone Rose", CameraEffects(), ".jpg"),
        ("Cadmium Yellow", CameraEffects(exposure=0.75, white_balance=(0.9, 1.0, 1.15), vignetting=0.4), ".jpg"),
        ("French Ultramarine", CameraEffects(gradient=0.3, blur=1.5, jpeg_quality=75), ".jpg"),
        ("Indian Red", CameraEffects(shot_noise=0.02, grain=0.03), ".png"),
        ("Interference Lilac", CameraEffects(), ".jpg"),
    ],
)
def test_unseen_coats_within_one_ciede2000(tmp_path, name, effects, suffix):
    card = make_swatch_card(pigments.load(name), coats=(1, 2, 3, 4, 5), effects=effects, seed=sum(map(ord, name)) % 1000)
    photo = tmp_path / f"card{suffix}"
    save_swatch_card(card, photo)
    layout = json.loads(photo.with_suffix(".json").read_text())
    fit = fit_swatches(photo, seen_only(layout))
    err = held_out_error(card, fit)
    print(f"\n{name}: unseen-coat CIEDE2000 {err:.2f}, fit {fit.mean_delta_e:.2f}, {fit.iterations} steps")
    assert fit.converged
    assert err <= 1.0
    assert fit.mean_delta_e <= 1.0
    assert "both identifiable" in fit.identifiability
    assert fit.pigment.name == "card"  # the photo's name when neither --name nor the layout gives one
    # The library it writes predicts the unseen coats with 90% regions that hold them (bench_coverage: 91%).
    truth, pred = [], fit.library.predict(["card"] * 4, [c for c in UNSEEN for _ in (0, 1)], ["paper", "black"] * 2)
    for c in UNSEEN:
        for ground in (card.paper, card.ink):
            truth.append(np.asarray(km.over(*km.layer(card.pigment.K, card.pigment.S, c), ground)))
    de = delta_e_displayed(pred.linear_srgb, np.array(truth))
    assert pred.de2000_90 is not None and np.all(de <= pred.de2000_90) and np.all(pred.de2000_90 < 2), (de, pred)


def test_photo_formats_and_exif_orientation_agree(tmp_path):
    card = make_swatch_card(pigments.load("Hookers Green"), coats=(1, 2, 3), effects=CameraEffects(shot_noise=0.0,
                            read_noise=0.0, grain=0.0, unevenness=0.0), seed=3)  # fmt: skip
    results = {}
    for label, name, kw in (("png8", "a.png", {}), ("png16", "b.png", {"bits": 16}), ("jpeg", "c.jpg", {}),
                            ("jpeg-rotated", "d.jpg", {"orientation": 6}), ("png-rotated", "e.png", {"orientation": 8})):
        save_swatch_card(card, tmp_path / name, **kw)
        if kw.get("orientation"):  # stored on its side; shown upright
            with Image.open(tmp_path / name) as im:
                assert im.size == card.photo.shape[:2]
        display, bits = read_image(tmp_path / name)
        assert display.shape == card.photo.shape and bits == (16 if label == "png16" else 8)
        results[label] = fit_swatches(tmp_path / name, card.layout, name="green")
    ref = results["png16"]
    for label, fit in results.items():
        np.testing.assert_allclose(fit.pigment.K, ref.pigment.K, rtol=0.03, err_msg=label)
        assert held_out_error(card, fit) < 0.5, label


def test_calibration_undoes_exposure_white_balance_and_falloff():
    effects = CameraEffects(exposure=0.7, white_balance=(1.2, 1.0, 0.8), vignetting=0.35, gradient=0.25, grain=0.0,
                            shot_noise=0.0, read_noise=0.0, blur=0.0, unevenness=0.0)  # fmt: skip
    card = make_swatch_card(pigments.load("Burnt Umber"), effects=effects)
    layout = parse_layout(card.layout, size=card.photo.shape[1::-1])
    linear = linearise(card.photo)
    cal = calibrate(linear, card.photo, 8, layout)
    # The gain holds the white balance (and the exposure times the light at the paper box).
    np.testing.assert_allclose(cal.gain / cal.gain[1], np.array(effects.white_balance), rtol=0.01)
    assert cal.degree == 2 and cal.light_range[0] < 0.75
    # Bare paper anywhere on the card now reads the paper's reflectance, within 1.5%.
    H, W = card.photo.shape[:2]
    for box in ([2, 2, 12, 12], [W - 12, H - 12, W - 2, H - 2], [W - 12, 2, W - 2, 12]):
        b = parse_layout({**card.layout, "paper": {"box": box}}, size=(W, H)).paper
        st = patch_stats(linear, card.photo, 8, cal, b)
        np.testing.assert_allclose(st.rgb, card.paper, rtol=0.015)
    # Without the falloff correction the corners are off by far more.
    flat = type(cal)(gain=cal.gain, coefficients=np.zeros(1), degree=0, pixels=0, light_range=(1, 1), size=(W, H))
    st = patch_stats(linear, card.photo, 8, flat, parse_layout({**card.layout, "paper": {"box": [2, 2, 12, 12]}}).paper)
    assert np.max(np.abs(st.rgb / card.paper - 1)) > 0.1


def _board_card(board: float, light_slope: float):
    """Patches painted on a board (no bare paper around them), under light that falls off across the photo:
    the linear image, its layout (paper box, black box on the bare board, patches) and each patch's truth."""
    rng = np.random.default_rng(2)
    H, W, side = 240, 360, 40
    img = np.full((H, W, 3), board) * (1 + 0.02 * rng.standard_normal((H, W, 1)))
    truth = rng.uniform(0.05, 0.6, (8, 3))
    boxes = [[20 + 85 * (i % 4), 30 + 100 * (i // 4), 20 + 85 * (i % 4) + side, 30 + 100 * (i // 4) + side]
             for i in range(9)]  # fmt: skip
    boxes[8] = [150, 190, 210, 230]  # the paper (a white patch)
    for b, rgb in zip(boxes, [*truth, np.full(3, 0.85)]):
        img[b[1] : b[3], b[0] : b[2]] = rgb
    xx = np.arange(W)[None, :, None] / W
    img = img * (1 + light_slope * (xx - 0.5)) * 0.9
    layout = {"paper": {"box": boxes[8], "reflectance": [0.85] * 3}, "black": {"box": [300, 200, 350, 235]},
              "patches": [{"box": b, "coats": 1, "ground": "paper"} for b in boxes[:8]]}  # fmt: skip
    return img, layout, truth


def test_on_a_board_the_light_is_read_from_the_bare_board():
    from diffwash import colorimetry
    from diffwash.fit.photos._swatch import _measure

    img, layout, truth = _board_card(0.2, 0.6)
    display = colorimetry.to_display(np.clip(img, 0, 1))
    m = _measure(display, layout)
    assert "light falloff read from the bare board" in " ".join(m.calibration.notes) and m.calibration.degree > 0
    de = lambda rgb: np.mean(np.asarray(colorimetry.delta_e_2000(colorimetry.linear_srgb_to_lab(rgb),  # noqa: E731
                                                                  colorimetry.linear_srgb_to_lab(truth))))  # fmt: skip
    read = np.array([s.rgb for s in m.patches])
    # Without the black box there is no board to read: plain scaling to the paper box, off by the light.
    plain = np.array([s.rgb for s in _measure(display, {k: v for k, v in layout.items() if k != "black"}).patches])
    assert de(read) < 0.5 and de(plain) > 2.5, (de(read), de(plain))


def test_trimmed_statistics_ignore_stains_and_edges():
    card = make_swatch_card(pigments.load("Cerulean Blue"), coats=(2,), effects=IDEAL)
    layout = parse_layout(card.layout)
    photo = card.photo.copy()
    b = layout.patches[0].box
    clean = patch_stats(linearise(photo), photo, 8, calibrate(linearise(photo), photo, 8, layout), b).rgb
    # A dark stain on 8% of the patch, and a one-pixel frame of wrong colour along its edges.
    rng = np.random.default_rng(0)
    ys = rng.integers(b.y0, b.y1, 200)
    xs = rng.integers(b.x0, b.x1, 200)
    photo[ys, xs] = 0.05
    photo[b.y0 : b.y1, b.x0] = photo[b.y0, b.x0 : b.x1] = 1.0
    lin = linearise(photo)
    dirty = patch_stats(lin, photo, 8, calibrate(lin, photo, 8, layout), b).rgb
    np.testing.assert_allclose(dirty, clean, rtol=0.01)


def test_clipped_channels_are_bounds():
    # A pale, scattering pigment on grey paper, photographed bright: the paper is fine but thick coats blow out red
    # and blue. Those channels only say "at least this bright".
    effects = CameraEffects(**{**IDEAL.__dict__, "exposure": 1.55})
    card = make_swatch_card(pigments.load("Interference Lilac"), coats=(1, 2, 3, 4), paper=(0.45, 0.45, 0.45),
                            effects=effects)  # fmt: skip
    fit = fit_swatches(card.photo, {**card.layout, "paper": {**card.layout["paper"], "reflectance": [0.45] * 3}})
    bounds = {(q.coats, q.ground): q.bound for q in fit.patches}
    assert bounds[(4, "paper")] == [True, False, True] and bounds[(1, "black")] == [False, False, False]
    assert fit.converged and fit.mean_delta_e < 0.3  # every bound is met
    for q in fit.patches:
        for c in range(3):
            if q.bound[c]:
                assert q.fitted[c] >= q.observed[c] * 0.999
    np.testing.assert_allclose(fit.pigment.K, card.pigment.K, rtol=0.05)
    np.testing.assert_allclose(fit.pigment.S, card.pigment.S, rtol=0.05)


def test_one_ground_identifiability(tmp_path):
    card = make_swatch_card(pigments.load("Phthalo Green"), coats=(1, 2, 3), black=False, effects=IDEAL)
    several = fit_swatches(card.photo, card.layout)
    assert "paper only, 3 coat counts" in several.identifiability.lower()
    assert "not separately identifiable" not in several.identifiability
    one = fit_swatches(card.photo, {**card.layout, "patches": card.layout["patches"][:1]})
    assert "NOT separately identifiable" in one.identifiability
    assert "Poorly determined" in one.identifiability  # the fit's own uncertainty says the same
    # One coat count still reproduces its patch.
    assert one.patches[0].delta_e < 0.1


def test_pigment_file_and_report(tmp_path):
    card = make_swatch_card(pigments.load("Brilliant Orange"), coats=(1, 2), seed=5)
    save_swatch_card(card, tmp_path / "card.png")
    layout = {**card.layout, "name": "Orange from a photo"}
    fit = fit_swatches(tmp_path / "card.png", layout)
    fit.save(tmp_path / "orange.json")
    p = pigments.load(tmp_path / "orange.json")
    assert p.name == "Orange from a photo"
    np.testing.assert_allclose(p.K, fit.pigment.K)
    r90 = library.load_library(tmp_path / "orange.json").predict(["Orange from a photo"], [3], ["paper"]).de2000_90
    assert r90 is not None and 0 < r90[0] < 2  # the posterior travels with the file
    diag = json.loads((tmp_path / "orange.json").read_text())["fit"]
    assert diag["converged"] is True and diag["iterations"] == fit.iterations
    assert len(diag["patches"]) == 4 and all("delta_e_2000" in q for q in diag["patches"])
    save_swatch_report(tmp_path / "report.png", fit, card.photo, parse_layout(layout))
    with Image.open(tmp_path / "report.png") as im:
        assert im.width > 600 and im.height > 300


@pytest.mark.parametrize(
    "change, field, what",
    [
        (lambda L: L.pop("paper"), "paper", "missing key"),
        (lambda L: L["patches"][0].update(box=[10, 10, 10, 20]), "patches[0].box", "empty"),
        (lambda L: L["patches"][1].update(box=[300, 200, 400, 300]), "patches[1].box", "outside"),
        (lambda L: L["patches"][0].update(ground="white"), "patches[0].ground", "must be one of paper, black, got 'white'"),
        (lambda L: L.pop("black"), "patches[1].ground", "no 'black' box"),
        (lambda L: L["patches"][0].update(coats=float("nan")), "patches[0].coats", "coats > 0"),
        (lambda L: L["paper"].update(reflectance=[0.9, 0.9]), "paper.reflectance", "3 linear reflectances"),
    ],
)
def test_layout_errors(change, field, what):
    card = make_swatch_card(pigments.load("Cadmium Red"), coats=(1, 2), effects=IDEAL)
    layout = json.loads(json.dumps(card.layout))
    change(layout)
    with pytest.raises(DiffwashError) as e:
        fit_swatches(card.photo, layout)
    assert e.value.field == field and what in e.value.problem


def test_saturated_paper_box_is_refused():
    card = make_swatch_card(pigments.load("Cadmium Red"), coats=(1, 2), effects=CameraEffects(exposure=1.4))
    with pytest.raises(DiffwashError, match="over-exposed") as e:
        fit_swatches(card.photo, card.layout)
    assert e.value.field == "paper.box"
