"""Scenes whose glazes are spectral library pigments and mixtures of them: the JAX render, the baked LUT and
the GLSL preview held together, the render against an independent per-band computation, gradients against
finite differences, and bad input refused in one line."""

from __future__ import annotations

import functools
import json
import warnings

import colour
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import km_reference
import pytest
from conftest import DATA

import diffwash
from diffwash import lut, shading
from diffwash._mixture import Mixture
from diffwash._scene import parse_scene
from diffwash.library import load_library

LIBRARY = DATA / "libraries" / "ntu-four.json"
SPHERE = DATA / "meshes" / "sphere.ply"
SIZE = 64


def scene_dict(size=SIZE, **changes) -> dict:
    """A sphere, orange wash (P4 + P1) and green unlit glaze (P8 + P4) of the shipped NTU library."""
    return {
        "mesh": str(SPHERE), "image": {"width": size, "height": size},
        "camera": {"eye": [0, 0, 3.5], "target": [0, 0, 0]}, "light": {"direction": [-1, 1, 1]},
        "wash": {"library": str(LIBRARY), "mix": {"P4": 0.75, "P1": 0.25}, "amount": 0.02},
        "unlit": {"library": str(LIBRARY), "mix": {"P8": 0.7, "P4": 0.3}, "amount": 0.01},
        "shininess": 12, "k_unlit": 1.2, "gain": 0.6, "bias": 0.45, "wash_reduction": 0.3, **changes,
    }  # fmt: skip


@functools.cache
def mixture_scene(size=SIZE, shading_mode="per-pixel") -> diffwash.Scene:
    return parse_scene(scene_dict(size, shading=shading_mode))


def psnr(a, b) -> float:
    mse = float(np.mean((np.asarray(a, np.float64) - np.asarray(b, np.float64)) ** 2))
    return float("inf") if mse == 0 else 10 * np.log10(1 / mse)


def to_8bit(linear) -> np.ndarray:
    return np.round(diffwash.colorimetry.to_display(np.asarray(linear, np.float64)) * 255) / 255


# --- the scene ------------------------------------------------------------------------------------------------


def test_scene_holds_mixtures_on_the_library_bands():
    scene = mixture_scene()
    p = scene.params
    lib = load_library(LIBRARY)
    assert isinstance(p.wash, Mixture) and p.wash.palette.names == ("P4", "P1")
    assert p.observation.describe() == lib.observation.describe()
    np.testing.assert_array_equal(p.paper, lib.grounds["paper"])  # the library's paper by default
    assert np.asarray(p.wash.K).shape == (41,)


def test_glaze_of_thickness_one_is_the_library_prediction():
    """A glaze of thickness 1 over the paper is the library's own prediction for that amount of the paint."""
    p = mixture_scene().params
    lib = load_library(LIBRARY)
    R = np.asarray(shading.glaze(p, np.ones(1), np.zeros(1)))[0]
    pred = lib.predict(["P4+P1"], ["0.015+0.005"])
    np.testing.assert_allclose(R, pred.reflectance[0], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(np.asarray(shading.colour(p, np.ones(1), np.zeros(1)))[0], pred.linear_srgb[0],
                               rtol=1e-9, atol=1e-12)  # fmt: skip


# --- one model, three implementations -------------------------------------------------------------------------


@pytest.fixture(scope="module")
def ctx():
    c = diffwash.preview.create_context()
    yield c
    c.release()


@pytest.mark.parametrize("mode", ["per-pixel", "per-vertex"])
def test_render_lut_and_preview_agree(ctx, mode):
    """The JAX render, the 256^2 LUT at the render's thicknesses and the GLSL preview: one picture."""
    scene = mixture_scene(96, mode)
    rendered = np.asarray(diffwash.render(scene), np.float64)
    table = lut.bake(scene, 256)
    thick = np.asarray(diffwash.render_thicknesses(scene), np.float64)
    cover = np.asarray(diffwash.rasterize(scene).coverage)
    looked_up = table.lookup(thick[..., 0], thick[..., 1])
    assert np.abs(looked_up - rendered)[cover].max() < 4e-3  # bilinear interpolation between samples (2.2e-3)
    np.testing.assert_allclose(table.values[0, 0], np.asarray(shading.paper_colour(scene.params)), atol=1e-6)
    assert psnr(to_8bit(looked_up), to_8bit(rendered)) >= 45
    frame = diffwash.preview.render(scene, lut=lut.load_encoded(table, "png16"), ctx=ctx)
    assert psnr(frame, to_8bit(rendered)) >= 40
    outside = ~cover & ~np.roll(cover, 1, 0) & ~np.roll(cover, -1, 0) & ~np.roll(cover, 1, 1) & ~np.roll(cover, -1, 1)
    assert np.abs(frame[outside] - to_8bit(rendered)[outside]).max() < 1e-6  # the paper's colour


def test_per_fragment_km_and_rt_tables_are_refused(ctx):
    scene = mixture_scene()
    with pytest.raises(diffwash.DiffwashError, match="per sRGB channel"):
        diffwash.preview.render(scene, colour="km", ctx=ctx)
    with pytest.raises(diffwash.DiffwashError, match="R/T table"):
        lut.bake(scene, 16, kind="rt")
    u = diffwash.uniform_values(scene)
    assert "wash_K" not in u and np.allclose(u["paper"], np.asarray(shading.paper_colour(scene.params)))


# --- an independent computation --------------------------------------------------------------------------------


def km_layer(K, S, x):
    """R, T of a layer per band: the textbook hyperbolic form in mpmath (`km_reference`), with its limits."""
    RT = np.array([[float(v) for v in km_reference.layer(k, s, x)] for k, s in zip(K, S)])
    return RT[:, 0], RT[:, 1]


def test_one_pigment_render_matches_colour_science():
    """Per band KM in NumPy, then colour-science's own `sd_to_XYZ` and `XYZ_to_sRGB`, at some pixels."""
    data = scene_dict(48, wash={"library": str(LIBRARY), "pigment": "P1"},
                      unlit={"library": str(LIBRARY), "pigment": "P8", "amount": 0.03})  # fmt: skip
    scene = parse_scene(data)
    image = np.asarray(diffwash.render(scene), np.float64)
    thick = np.asarray(diffwash.render_thicknesses(scene), np.float64)
    cover = np.asarray(diffwash.rasterize(scene).coverage)
    raw = json.loads(LIBRARY.read_text())
    pig = {p["name"]: p for p in raw["pigments"]}
    wl = np.asarray(raw["observation"]["wavelengths"], np.float64)
    paper = np.asarray(raw["grounds"]["paper"])
    t_unlit = (0.03 / 0.05) ** pig["P8"]["amount_law"]["gamma"]  # the law at the scene's amount
    cmfs = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"]
    d65 = colour.SDS_ILLUMINANTS["D65"]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # colour-science's notes on aligning shapes
        white = colour.sd_to_XYZ(colour.SpectralDistribution(np.ones_like(wl), wl), cmfs, d65) / 100
        ys, xs = np.nonzero(cover)
        for i in np.random.default_rng(0).choice(len(ys), 12, replace=False):
            w, u = thick[ys[i], xs[i]]
            Rw, Tw = km_layer(np.asarray(pig["P1"]["K"]), np.asarray(pig["P1"]["S"]), w)
            Ru, Tu = km_layer(np.asarray(pig["P8"]["K"]) * t_unlit, np.asarray(pig["P8"]["S"]) * t_unlit, u)
            R = Ru + Tu * Tu * Rw / (1 - Ru * Rw)  # unlit on wash
            T = Tu * Tw / (1 - Ru * Rw)
            R = R + T * T * paper / (1 - R * paper)  # over the paper
            xyz = colour.sd_to_XYZ(colour.SpectralDistribution(R, wl), cmfs, d65) / 100
            rgb = colour.XYZ_to_sRGB(xyz, illuminant=colour.XYZ_to_xy(white), chromatic_adaptation_transform="CAT02",
                                     apply_cctf_encoding=False)  # fmt: skip
            np.testing.assert_allclose(image[ys[i], xs[i]], rgb, atol=2e-4)  # IEC's 4-decimal matrices


# --- gradients -------------------------------------------------------------------------------------------------

LEAVES = ["wash.proportions", "unlit.proportions", "wash.amount", "unlit.amount", "wash.palette.K",
          "unlit.palette.S", "paper", "gain", "bias", "k_wash", "k_unlit", "shininess", "wash_reduction"]  # fmt: skip


def _get(p, path):
    for part in path.split("."):
        p = getattr(p, part)
    return p


def _set(p, path, value):
    return eqx.tree_at(lambda q: _get(q, path), p, value)


def _loss(scene):
    weights = jnp.asarray(np.random.default_rng(0).uniform(0.5, 1.5, (scene.height, scene.width, 3)))
    return jax.jit(lambda p: jnp.sum(diffwash.render(scene, p) * weights))


@pytest.mark.parametrize("mix", [{"P4": 0.75, "P1": 0.25}, {"P4": 1.0, "P1": 0.0}])
def test_gradients_match_finite_differences(mix):
    """Mixture proportions, amounts, pigment spectra and shading constants, float64; a zero proportion too."""
    scene = parse_scene(scene_dict(40, wash={"library": str(LIBRARY), "mix": mix, "amount": 0.02}))
    params = jax.tree.map(lambda x: jnp.asarray(x, jnp.float64), scene.params)
    loss = _loss(scene)
    grad = jax.jit(jax.grad(loss))(params)
    rng = np.random.default_rng(1)
    for path in LEAVES:
        x0, g = jnp.asarray(_get(params, path)), jnp.asarray(_get(grad, path))
        assert bool(jnp.all(jnp.isfinite(g))) and float(jnp.max(jnp.abs(g))) > 0, path
        d = jnp.asarray(rng.normal(size=x0.shape)) * (jnp.abs(x0) + 1e-2)  # each entry on its own scale
        h = 1e-6
        fd = (loss(_set(params, path, x0 + h * d)) - loss(_set(params, path, x0 - h * d))) / (2 * h)
        ad = float(jnp.sum(g * d))
        assert abs(ad - float(fd)) <= 1e-4 * max(abs(float(fd)), 1e-3), (path, ad, float(fd))


def test_gradients_are_finite_at_the_edges():
    """Zero thickness everywhere (k_wash = k_unlit = 0) and a pigment with S = 0 in some bands."""
    scene = mixture_scene(32)
    p = jax.tree.map(lambda x: jnp.asarray(x, jnp.float64), scene.params)
    p = eqx.tree_at(lambda q: (q.k_wash, q.k_unlit), p, (jnp.float64(0), jnp.float64(0)))
    p = _set(p, "wash.palette.S", _get(p, "wash.palette.S").at[:, :10].set(0))
    grad = jax.grad(_loss(scene))(p)
    assert all(bool(jnp.all(jnp.isfinite(g))) for g in jax.tree.leaves(grad))
    image = np.asarray(diffwash.render(scene, p))
    np.testing.assert_allclose(image, np.broadcast_to(np.asarray(shading.paper_colour(p)), image.shape), atol=1e-12)


# --- writing back, exporting, fitting --------------------------------------------------------------------------


def test_saved_and_exported_scenes_load_again(tmp_path):
    path = tmp_path / "in" / "scene.json"
    path.parent.mkdir()
    path.write_text(json.dumps(scene_dict(32, wash={"library": str(LIBRARY), "pigment": "P4"})))
    scene = diffwash.load_scene(path)
    diffwash.save_scene(tmp_path / "saved.json", scene)
    again = diffwash.load_scene(tmp_path / "saved.json")
    np.testing.assert_array_equal(np.asarray(diffwash.render(again)), np.asarray(diffwash.render(scene)))
    assert LIBRARY.resolve() in [p.resolve() for p in diffwash.referenced_files(path)]
    written = diffwash.export(scene, tmp_path / "out", size=32)
    exported = diffwash.load_scene(tmp_path / "out" / "scene.json")
    assert isinstance(exported.params.unlit, Mixture) and len(written) >= 10
    side = json.loads((tmp_path / "out" / "lut.json").read_text())
    assert side["pigments"]["wash"]["mix"] == {"P4": 1.0} and side["observation"]["illuminant"] == "D65"


def test_fit_image_finds_the_shading_constants_of_a_mixture_scene():
    scene = mixture_scene(48)
    truth = eqx.tree_at(lambda q: (q.gain, q.bias), scene.params, (np.float64(0.7), np.float64(0.4)))
    target = np.asarray(diffwash.render(scene, truth))
    result = diffwash.fit.fit_image(target, scene, ["gain", "bias"])
    assert result.converged, result.message
    np.testing.assert_allclose([float(result.params.gain), float(result.params.bias)], [0.7, 0.4], atol=1e-4)
    with pytest.raises(diffwash.DiffwashError, match="cannot fit 'wash.K'"):
        diffwash.fit.fit_image(target, scene, ["wash.K"])


# --- bad input -------------------------------------------------------------------------------------------------


def _bad_library(folder):
    data = json.loads(LIBRARY.read_text())
    data["observation"]["wavelengths"] = list(range(500, 610, 10))  # a grid no observer sees whole
    for p in data["pigments"]:
        p["K"], p["S"] = p["K"][:11], p["S"][:11]
    data["grounds"] = {"paper": data["grounds"]["paper"][:11]}
    (folder / "narrow.json").write_text(json.dumps(data))
    return "narrow.json"


BAD = {
    "unknown pigment": ({"wash": {"library": str(LIBRARY), "mix": {"P4": 0.5, "P99": 0.5}}}, "wash.mix.P99", "no pigment 'P99'"),
    "unknown single": ({"unlit": {"library": str(LIBRARY), "pigment": "P2"}}, "unlit.pigment", "no pigment 'P2'"),
    "negative": ({"wash": {"library": str(LIBRARY), "mix": {"P4": 1.5, "P1": -0.5}}}, "wash.mix.P1", ">= 0"),
    "sum": ({"wash": {"library": str(LIBRARY), "mix": {"P4": 0.6, "P1": 0.6}}}, "wash.mix", "sum to 1"),
    "both": ({"wash": {"library": str(LIBRARY), "mix": {"P4": 1}, "pigment": "P4"}}, "wash", "either"),
    "amount": ({"wash": {"library": str(LIBRARY), "pigment": "P4", "amount": 0}}, "wash.amount", "> 0"),
    "missing": ({"wash": {"library": "nowhere.json", "pigment": "P4"}}, "wash.library", "no such library file"),
    "unevaluable": ({"wash": {"library": "narrow.json", "pigment": "P4"}}, "wash.library", "cannot be seen"),
    "mixed kinds": ({"unlit": {"pigment": "Phthalo Green"}}, "unlit", "both glazes must be seen alike"),
    "ground": ({"paper": {"ground": "canvas"}}, "paper.ground", "no ground 'canvas'"),
    "paper list": ({"paper": [0.9, 0.9, 0.9]}, "paper", "41 reflectances"),
    "look": ({"watercolour": {}}, "watercolour", "library paints"),
}


@pytest.mark.parametrize("case", list(BAD))
def test_bad_input_is_one_line_naming_the_scene_and_the_key(cli, tmp_path, case):
    changes, field, message = BAD[case]
    _bad_library(tmp_path)
    (tmp_path / "scene.json").write_text(json.dumps(scene_dict(16, **changes)))
    code, out, err = cli("render", "scene.json", "-o", "out.png")
    assert code == 2, err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    assert f"scene.json: {field}: " in err and message in err, err
    assert not (tmp_path / "out.png").exists()


def test_rt_bake_of_a_spectral_scene_is_refused(cli, tmp_path):
    (tmp_path / "scene.json").write_text(json.dumps(scene_dict(16)))
    code, out, err = cli("bake", "scene.json", "-o", "lut.png", "--rt")
    assert code == 2 and err.count("\n") == 1 and "scene.json: kind (--rt): an R/T table" in err, err
    assert not list(tmp_path.glob("lut*"))
