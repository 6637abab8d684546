"""Swatch cards of several pigments, alone and mixed: the layout's `pigment`/`coats`, the generator's mixture
cards, the joint fit (`fit_swatch_mixtures`, `diffwash fit-swatch`) into a library `diffwash predict` reads,
and bad layouts refused in one line."""

import copy
import csv
import json

import jax.numpy as jnp
import numpy as np
import pytest
from conftest import DATA

from diffwash import DiffwashError, colorimetry, library
from diffwash.cli import main
from diffwash.fit import fit_swatch_mixtures, fit_swatches, parse_layout, swatch_pigments
from diffwash.swatchcard import make_mixture_card, save_swatch_card

#: One coat of the NTU paints (mL on the sample's area): their measured amounts run 0.01-0.12.
COAT = 0.02
#: The card: three pigments alone (1 and 3 coats), their three pairs and all three mixed; the last column is
#: held out of the fit (a pair the fit saw mixed 1:1, here 1:2).
PATCHES = [("P1", 1), ("P1", 3), ("P4", 1), ("P4", 3), ("P10", 1), ("P10", 3), ("P1+P4", "1+1"),
           ("P1+P10", "1+1"), ("P4+P10", "1+1"), ("P1+P4+P10", "1+1+1"), ("P1+P4", "1+2")]  # fmt: skip
HELD = ("P1+P4", "1+2")


def de2000(a, b):
    """CIEDE2000 between linear sRGB colours, row by row."""
    lab = lambda x: colorimetry.linear_srgb_to_lab(jnp.asarray(x, jnp.float64))  # noqa: E731
    return np.asarray(colorimetry.delta_e_2000(lab(a), lab(b)), np.float64)


@pytest.fixture(scope="module")
def card():
    truth = library.load_library(DATA / "libraries" / "ntu-four.json")
    return make_mixture_card(truth, PATCHES, amount_per_coat=COAT, patch=24, seed=2)


def held_out(layout):
    """Which of the layout's patches are the held-out mixture."""
    return np.array([(p["pigment"], p["coats"]) == HELD for p in layout["patches"]])


@pytest.fixture(scope="module")
def fitted(card):
    """The joint fit of the card's photo without the held-out column."""
    layout = copy.deepcopy(card.layout)
    layout["patches"] = [p for p, h in zip(layout["patches"], held_out(layout)) if not h]
    return fit_swatch_mixtures(card.photo, layout)


def test_the_generator_paints_the_library_and_names_each_patch(card):
    truth = card.library
    assert card.pigment is None and card.photo.shape == (132, 432, 3) and np.all(np.isfinite(card.photo))
    L = parse_layout(card.layout, size=card.photo.shape[1::-1])
    assert len(L.patches) == 2 * len(PATCHES) and {p.ground for p in L.patches} == {"paper", "black"}
    mixed = L.patches[-1]
    assert mixed.pigments == ("P1", "P4") and mixed.amounts == (1.0, 2.0) and mixed.coats == 3.0
    assert parse_layout(L.to_dict()).patches == L.patches  # the layout round-trips
    # Over paper, each patch's true colour is the library's prediction at its amounts (a coat = COAT).
    paper = [i for i, p in enumerate(card.layout["patches"]) if p["ground"] == "paper"]
    pred = truth.predict([card.layout["patches"][i]["pigment"] for i in paper],
                         [[COAT * float(a) for a in str(card.layout["patches"][i]["coats"]).split("+")] for i in paper])
    np.testing.assert_allclose(card.patch_colours[paper], pred.linear_srgb, atol=1e-5)
    assert swatch_pigments(card.layout) == ["P1", "P4", "P10"]


def test_the_joint_fit_reproduces_the_card(fitted, card):
    keep = ~held_out(card.layout)
    assert fitted.converged and fitted.names == ("P1", "P4", "P10")
    assert set(fitted.library.grounds) == {"paper", "black"} and not fitted.library.palette.pairs
    assert fitted.library.palette.law.reference == 1.0  # amounts are coats
    observed = np.array([p.observed for p in fitted.patches])
    predicted = fitted.library.predict(fitted.measurements.pigments, fitted.measurements.amounts,
                                       fitted.measurements.ground).linear_srgb  # fmt: skip
    np.testing.assert_allclose(predicted, [p.fitted for p in fitted.patches], atol=1e-6)
    to_photo = de2000(observed, predicted)  # measured: mean 0.52, max 2.1 (P1+P4 over black)
    to_truth = de2000(card.patch_colours[keep], predicted)  # measured: mean 0.54, max 2.1
    assert to_photo.mean() < 1.0 and to_photo.max() < 3.0, to_photo
    assert to_truth.mean() < 1.0 and to_truth.max() < 3.0, to_truth
    assert np.all(np.isfinite(np.asarray(fitted.library.palette.K))) and np.all(np.asarray(fitted.library.palette.S) > 0)
    record = fitted.library.fit
    assert len(record["patches"]) == keep.sum() and record["patches"][-1]["pigment"] == "P1+P4+P10"


def test_the_fit_predicts_a_mixture_it_did_not_see(fitted, card):
    held = held_out(card.layout)
    grounds = [p["ground"] for p, h in zip(card.layout["patches"], held) if h]
    pred = fitted.library.predict(["P1+P4"] * len(grounds), ["1+2"] * len(grounds), grounds)
    de = de2000(card.patch_colours[held], pred.linear_srgb)  # measured: 1.0 over paper, 1.7 over black
    assert de.max() < 3.0, de
    # Its 90% regions hold it (measured: radii 2.5 and 2.4), and are no wider than a mixture's colour needs.
    assert pred.de2000_90 is not None and np.all(de <= pred.de2000_90) and np.all(pred.de2000_90 < 8), pred.de2000_90


def test_regions_carry_the_photos_own_measurement_error(card):
    # One patch per paint: the fit reproduces each exactly, so the card alone would say its model error is 0.
    # A photo read through an assumed tone curve (2 CIEDE2000 typical error) is not that sure of its colours.
    layout = copy.deepcopy(card.layout)
    layout["patches"] = [p for p in layout["patches"] if p["coats"] == 1 and p["ground"] == "paper"]
    regions = {}
    for curve in ("srgb", "camera"):
        lib = fit_swatch_mixtures(card.photo, layout, tone_curve=curve).library
        regions[curve] = lib.predict(["P1", "P4"], [1, 1], ["paper", "paper"]).de2000_90
        assert lib.fit["uncertainty"]["measurement"]["per_axis"] > 0
    assert np.all(regions["camera"] > 3.0) and np.all(regions["srgb"] < 1.5), regions


def test_the_card_fit_says_what_its_patches_determined(fitted):
    unc = fitted.library.fit["uncertainty"]
    assert set(unc["model_error"]) == {"single", "seen", "unseen"}  # every pair is on the card: unseen by folds
    assert "leave-pairs-out" in unc["unseen_from"]
    for r in unc["pigments"]:  # every paint is on the card over black: not asked for again; three channels are
        assert "over black" not in r["measure"], r
        assert not {"absorption", "scattering"} & set(r["from_the_prior"]) or "spectrophotometer" in r["measure"], r


def test_fit_swatches_sends_cards_of_several_pigments_to_the_joint_fit(card):
    with pytest.raises(DiffwashError, match="3 pigments .*fit_swatch_mixtures"):
        fit_swatches(card.photo, card.layout)


def test_patches_without_a_pigment_are_the_cards_and_names_match_ignoring_case():
    box = lambda x: [x, 40, x + 10, 50]  # noqa: E731
    layout = {"paper": {"box": [0, 0, 100, 20]}, "name": "Rose",
              "patches": [{"box": box(0), "coats": 1, "ground": "paper"},
                          {"box": box(20), "pigment": "rose", "coats": 2, "ground": "paper"}]}  # fmt: skip
    assert swatch_pigments(layout) == ["Rose"]  # one pigment: the single-pigment fit, as before
    assert swatch_pigments(layout, name="Blue") == ["Blue", "rose"]
    layout["patches"].append({"box": box(40), "pigment": "ROSE + Cobalt  Blue", "coats": "1+0.5", "ground": "paper"})
    assert swatch_pigments(layout) == ["Rose", "Cobalt Blue"]
    assert parse_layout(layout).patches[2].amounts == (1.0, 0.5)


def test_fit_swatch_writes_a_library_that_predict_reads(card, run_cli, tmp_path):
    save_swatch_card(card, tmp_path / "card.png")
    r = run_cli("fit-swatch", "card.png", "--layout", "card.json", "-o", "lib.json", "--report", "report.png")
    assert r.returncode == 0, r.stderr  # float32, as for a user
    assert "3 pigments (P1, P4, P10) from 22 patches (10 mixtures)" in r.stdout and "wrote lib.json" in r.stdout
    assert "P1+P4+P10  1+1+1  black" in r.stdout and (tmp_path / "report.png").stat().st_size > 10_000
    assert "90% regions: model error" in r.stdout and "    P10: log K" in r.stdout, r.stdout
    fit = json.loads((tmp_path / "lib.json").read_text())["fit"]
    assert fit["converged"] and fit["mean_delta_e_2000"] < 1.5 and fit["layouts"] == ["card.json"]
    (tmp_path / "q.csv").write_text("pigment,amount,ground\nP1+P4,1+2,paper\nP10+P4,2+1,black\n")
    assert main(["predict", str(tmp_path / "lib.json"), "--table", str(tmp_path / "q.csv"),
                 "-o", str(tmp_path / "pred.csv")]) == 0  # fmt: skip
    with open(tmp_path / "pred.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    rgb = np.array([[float(row[c]) for c in "rgb"] for row in rows])
    assert rgb.shape == (2, 3) and np.all(np.isfinite(rgb))
    assert all(0 < float(row["de2000_90"]) < 10 for row in rows), rows  # the card's fit carries its regions
    held = held_out(card.layout) & np.array([p["ground"] == "paper" for p in card.layout["patches"]])
    truth = 255 * np.asarray(colorimetry.srgb_encode(card.patch_colours[held][0]))
    assert np.abs(rgb[0] - truth).max() < 12, (rgb[0], truth)


GOOD = {"paper": {"box": [0, 0, 60, 10]}, "black": {"box": [0, 40, 10, 50]},
        "patches": [{"box": [20, 20, 30, 30], "pigment": "P1+P4", "coats": "1+2", "ground": "paper"}]}  # fmt: skip


@pytest.mark.parametrize("change, field, words", [
    ({"coats": "1"}, "patches[0].coats", "1 number of coats for 2 pigments (P1+P4)"),
    ({"coats": "1+2+3"}, "patches[0].coats", "3 numbers of coats for 2 pigments"),
    ({"pigment": "P1+"}, "patches[0].pigment", "empty pigment name"),
    ({"pigment": ""}, "patches[0].pigment", "must not be empty"),
    ({"pigment": 3}, "patches[0].pigment", "must be text, got 3"),
    ({"pigment": "P1+Black"}, "patches[0].pigment", "'Black' names a ground"),
    ({"coats": "1+-2"}, "patches[0].coats", "must be >= 0"),
    ({"coats": "0+0"}, "patches[0].coats", "add up to 0"),
    ({"coats": "1+x"}, "patches[0].coats", "not a number: 'x'"),
    ({"coats": "1+nan"}, "patches[0].coats", "finite"),
    ({"coats": "1+1e39"}, "patches[0].coats", "float32"),
    ({"pigment": None, "coats": "1+2"}, "patches[0].coats", "2 numbers of coats for the card's one pigment"),
    ({"paint": "P1"}, "patches[0].paint", "unknown key"),
])  # fmt: skip
def test_bad_mixture_patches_are_refused_in_one_line(tmp_path, monkeypatch, capsys, change, field, words):
    monkeypatch.chdir(tmp_path)
    layout = copy.deepcopy(GOOD)
    layout["patches"][0].update(change)
    layout["patches"][0] = {k: v for k, v in layout["patches"][0].items() if v is not None}
    (tmp_path / "bad.json").write_text(json.dumps(layout))
    # The photo is read after the layout: any file will do.
    (tmp_path / "card.png").write_bytes(b"")
    assert main(["fit-swatch", "card.png", "--layout", "bad.json", "-o", "lib.json"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    assert err.startswith(f"diffwash: error: bad.json: {field}: ") and words in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.json", "card.png"]  # nothing written


def test_swatch_card_cli_paints_a_librarys_pigments_as_make_mixture_card_does(run_cli, tmp_path):
    lib = DATA / "libraries" / "ntu-four.json"
    r = run_cli("swatch-card", "--library", lib, "--patches", "P1:1, P4:2 ,P1+P4:1+2", "--amount-per-coat", "0.02",
                "--seed", "3", "-o", "cli.png")  # fmt: skip
    assert r.returncode == 0, r.stderr
    card = make_mixture_card(library.load_library(lib), [("P1", 1), ("P4", 2), ("P1+P4", "1+2")], amount_per_coat=0.02, seed=3)
    save_swatch_card(card, tmp_path / "py.png")
    from diffwash._io import read_image

    # The command computes in float32, the tests in float64: a pixel may round to the next 8-bit level.
    np.testing.assert_allclose(read_image(tmp_path / "cli.png")[0], read_image(tmp_path / "py.png")[0], rtol=0, atol=1.01 / 255)
    assert json.loads((tmp_path / "cli.json").read_text()) == json.loads((tmp_path / "py.json").read_text())


@pytest.mark.parametrize("args, field", [
    (["--patches", "P1:1,P9:1"], "--patches"),            # a pigment the library lacks
    (["--patches", "P1+P4:1"], "--patches"),              # a coat count per pigment
    (["--patches", "P1:x"], "--patches"),
    (["--patches", "P1:0"], "--patches"),
    (["--patches", "P1:1", "P1"], "PIGMENT"),             # a pigment and a library
    (["--patches", "P1:1", "--coats", "1,2"], "--coats"),
    (["--patches", "P1:1", "--amount-per-coat", "-1"], "--amount-per-coat"),
])  # fmt: skip
def test_swatch_card_cli_refuses_bad_mixture_cards_in_one_line(run_cli, tmp_path, args, field):
    r = run_cli("swatch-card", "--library", DATA / "libraries" / "ntu-four.json", *args, "-o", "card.png")
    assert r.returncode == 2 and field in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert not (tmp_path / "card.png").exists() and not (tmp_path / "card.json").exists()
