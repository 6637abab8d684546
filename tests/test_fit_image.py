"""Shading parameters from target images: render -> perturb -> fit round trips, gauges, losses, solvers, views."""

import json

import equinox as eqx
import jax
import numpy as np
import pytest
from conftest import DATA

import diffwash
from diffwash import DiffwashError
from diffwash.fit import fit_image
from diffwash.fit.images._image import _GLAZE_INPUTS, _get, _glaze, _glaze_terms, _prepare_view, _shade, load_cameras
from diffwash.fit.images._image import parse_fit_list


def scene_file(tmp_path, name, mesh, size=64, camera=None, **extra):
    data = {
        "mesh": str(DATA / "meshes" / mesh),
        "image": {"width": size, "height": size},
        "camera": camera or {"eye": [0.3, 0.4, 3.2], "target": [0, 0, 0], "fov_y": 40},
        "light": {"direction": [-1.0, 1.0, 1.0]},
        "wash": {"pigment": "Cadmium Yellow"},
        "unlit": {"pigment": "Phthalo Green"},
        "shininess": 12, "k_unlit": 1.5, "gain": 0.6, "bias": 0.45, "wash_reduction": 0.3,
        **extra,
    }  # fmt: skip
    path = tmp_path / f"{name}.json"
    path.write_text(json.dumps(data))
    return path


@pytest.mark.parametrize(
    "mesh, shading, backfaces",
    [("sphere.ply", "per-pixel", "auto"), ("knot-1k.ply", "per-vertex", "auto"), ("knot-1k.ply", "per-pixel", "both"),
     ("knot-1k.ply", "per-vertex", "both")],
)
def test_fit_shading_is_the_renderers(tmp_path, mesh, shading, backfaces):
    # The fit shades stored geometry instead of calling render() each step; it must give render()'s pixels.
    scene = diffwash.load_scene(scene_file(tmp_path, "s", mesh, shading=shading, backfaces=backfaces,
                                           camera={"eye": [0.2, 0.3, 1.6], "target": [0, 0, 0], "fov_y": 60}))
    vis = diffwash.rasterize(scene)
    image = np.asarray(diffwash.render(scene, visibility=vis))
    view = _prepare_view(scene, vis, image, np.float64)
    got = np.asarray(jax.jit(_shade)(view, scene.params))[np.asarray(view.valid)]
    px = np.asarray(vis.pixels)[np.asarray(view.valid)]
    np.testing.assert_allclose(got, image.reshape(-1, 3)[px], rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(np.asarray(view.target)[np.asarray(view.valid)], image.reshape(-1, 3)[px])


def test_fit_glaze_has_the_glazes_value_and_derivative():
    rng = np.random.default_rng(0)
    p = diffwash.load_scene(DATA / "scenes" / "sphere.json").params
    inputs = (rng.uniform(0, 2, 50), rng.uniform(0, 2, 50), p.wash.K, p.wash.S, p.unlit.K, p.unlit.S, p.paper)
    argnums = tuple(range(7))
    plain = jax.jit(jax.jacfwd(_glaze_terms, argnums=argnums))(*inputs)
    for varying in ((True,) * 7, (True, True, False, False, False, False, True)):
        np.testing.assert_allclose(_glaze(inputs, varying), _glaze_terms(*inputs), rtol=1e-14)
        ours = jax.jit(jax.jacfwd(lambda *a, v=varying: _glaze(a, v), argnums=argnums))(*inputs)
        for i, name in enumerate(_GLAZE_INPUTS):
            if varying[i]:
                np.testing.assert_allclose(ours[i], plain[i], rtol=1e-10, atol=1e-14, err_msg=name)


def perturbed(params, names, factor, turn):
    p = params
    for n in names:
        v = _get(p, n)
        if n == "light":
            new = v + turn * np.array([0.4, -0.3, 0.2])
        elif n in ("gain", "bias", "wash_reduction", "paper"):
            new = np.clip(v * factor, 0.05, 0.95)
        else:
            new = v * factor
        if "." in n:
            glaze, which = n.split(".")
            p = eqx.tree_at(lambda q: getattr(getattr(q, glaze), which), p, new)
        else:
            p = eqx.tree_at(lambda q: getattr(q, n), p, new)
    return p


def close(fitted, truth, n):
    a, b = np.asarray(fitted, float), np.asarray(truth, float)
    if n == "light":
        a, b = a / np.linalg.norm(a), b / np.linalg.norm(b)
        return np.max(np.abs(a - b)) < 0.01
    return np.all(np.abs(a - b) <= 0.01 * np.abs(b))


@pytest.mark.parametrize(
    "mesh, shading, names",
    [
        ("sphere.ply", "per-pixel", "gain,bias,k_wash,k_unlit,shininess,wash_reduction,light"),
        ("knot-1k.ply", "per-vertex", "gain,bias,k_unlit,shininess,paper,light"),
    ],
)
@pytest.mark.parametrize("factor, turn", [(0.8, 1.0), (1.25, -1.0)])
def test_round_trip_recovers_parameters(tmp_path, mesh, shading, names, factor, turn):
    scene = diffwash.load_scene(scene_file(tmp_path, "s", mesh, shading=shading))
    target = np.asarray(diffwash.render(scene))
    names = parse_fit_list(names)
    start = perturbed(scene.params, names, factor, turn)
    steps = []
    fit = fit_image(target, scene, names, start=start, progress=lambda i, loss: steps.append(loss))
    assert fit.converged, fit.message
    assert steps == fit.history and steps[-1] < 1e-6 * steps[0]
    for n in names:
        assert not close(fit.start[n], _get(scene.params, n), n) or n == "paper", f"{n} did not move"
        assert close(fit.fitted[n], _get(scene.params, n), n), f"{n}: {fit.fitted[n]} vs {_get(scene.params, n)}"


def test_gauge_holds_thickness_when_pigment_is_fitted(tmp_path):
    scene = diffwash.load_scene(scene_file(tmp_path, "s", "sphere.ply"))
    target = np.asarray(diffwash.render(scene))
    names = ("wash.K", "wash.S", "k_wash", "unlit.K", "unlit.S", "k_unlit")
    start = perturbed(scene.params, names, 1.2, 0.0)
    fit = fit_image(target, scene, names, start=start)
    assert fit.converged and set(fit.held) == {"k_wash", "k_unlit"}
    assert any("gauge: k_wash" in n for n in fit.notes)
    # Held at its start; K and S carry the scale: K * thickness is what was recovered.
    assert fit.fitted["k_wash"] == pytest.approx(start.k_wash)
    for glaze, k in (("wash", "k_wash"), ("unlit", "k_unlit")):
        for which in ("K", "S"):
            got = fit.fitted[f"{glaze}.{which}"] * fit.fitted[k]
            want = _get(scene.params, f"{glaze}.{which}") * _get(scene.params, k)
            np.testing.assert_allclose(got, want, rtol=0.01)


@pytest.mark.parametrize("loss, solver", [("lab", "lm"), ("linear", "bfgs")])
def test_losses_and_solvers(tmp_path, loss, solver):
    scene = diffwash.load_scene(scene_file(tmp_path, "s", "sphere.ply", size=48))
    target = np.asarray(diffwash.render(scene))
    names = ("gain", "k_unlit", "shininess")
    fit = fit_image(target, scene, names, start=perturbed(scene.params, names, 1.15, 0), loss=loss, solver=solver,
                    max_steps=300)  # fmt: skip
    assert fit.converged, fit.message
    for n in names:
        assert close(fit.fitted[n], _get(scene.params, n), n), n


def test_several_views_from_a_camera_list(tmp_path):
    path = scene_file(tmp_path, "s", "knot-1k.ply", size=48)
    scene = diffwash.load_scene(path)
    cams = [{"eye": [0.3, 0.4, 3.2], "target": [0, 0, 0]}, {"eye": [3.0, 0.5, -0.8], "target": [0, 0, 0]}]
    (tmp_path / "cams.json").write_text(json.dumps(cams))
    views = load_cameras(tmp_path / "cams.json", scene)
    targets = [np.asarray(diffwash.render(v)) for v in views]
    assert not np.allclose(targets[0], targets[1])
    names = ("gain", "bias", "light")
    fit = fit_image(targets, views, names, start=perturbed(scene.params, names, 0.8, 1.0))
    assert fit.converged and len(fit.rms) == 2 and max(fit.rms) < 1e-6
    for n in names:
        assert close(fit.fitted[n], _get(scene.params, n), n), n


def test_fitted_scene_file_renders_the_target(tmp_path):
    path = scene_file(tmp_path, "s", "sphere.ply", size=48)
    scene = diffwash.load_scene(path)
    target = np.asarray(diffwash.render(scene))
    names = ("gain", "k_unlit", "shininess")
    fit = fit_image(target, scene, names, start=perturbed(scene.params, names, 0.85, 0))
    fit.save(tmp_path / "fitted.json")
    again = diffwash.load_scene(tmp_path / "fitted.json")
    np.testing.assert_allclose(np.asarray(diffwash.render(again)), target, atol=1e-6)
    assert json.loads((tmp_path / "fitted.json").read_text())["gain"] == pytest.approx(0.6, rel=1e-6)


def test_not_converging_is_reported(tmp_path):
    scene = diffwash.load_scene(scene_file(tmp_path, "s", "sphere.ply", size=48))
    target = np.asarray(diffwash.render(scene))
    names = ("gain", "k_unlit", "shininess")
    fit = fit_image(target, scene, names, start=perturbed(scene.params, names, 0.6, 0), max_steps=2)
    assert not fit.converged and fit.iterations == 2 and "did not converge" in fit.message


def test_bad_image_fit_input(tmp_path):
    scene = diffwash.load_scene(scene_file(tmp_path, "s", "sphere.ply", size=48))
    with pytest.raises(DiffwashError, match="did you mean 'k_wash'"):
        parse_fit_list("gain,k_wsh")
    with pytest.raises(DiffwashError, match="twice"):
        parse_fit_list("gain,gain")
    with pytest.raises(DiffwashError, match="is 40x48 pixels but the scene renders 48x48"):
        fit_image(np.zeros((48, 40, 3)), scene, "gain")
    bad = np.zeros((48, 48, 3))
    bad[3, 4, 1] = np.nan
    with pytest.raises(DiffwashError, match="NaN"):
        fit_image(bad, scene, "gain")
    with pytest.raises(DiffwashError, match="unknown solver"):
        fit_image(np.zeros((48, 48, 3)), scene, "gain", solver="newton")
