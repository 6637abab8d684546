"""fit-image fits the watercolour look's continuous parameters: a small watercolour scene is rendered, three look
parameters are perturbed in its scene file and fitted back (Python API and the command line's entry point), and
asking for a look parameter the scene does not have is one line naming the file and the key, exit 2."""

import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import DATA, write_fit_target

import diffwash
from diffwash.cli import main
from diffwash.fit import FITTABLE, fit_image
from diffwash.fit.images._image import _decode_look, _encode, _Problem, _prepare_look_view, _residuals

SIZE = 48
#: The look's values in the target, and the perturbed starting values.
TRUTH = {"watercolour.edges.darkening": 2.5, "watercolour.paper.granulation": 0.45, "watercolour.unevenness.turbulence": 0.25}
START = {"watercolour.edges.darkening": 1.8, "watercolour.paper.granulation": 0.6, "watercolour.unevenness.turbulence": 0.15}


def _scene_dict(values, watercolour=None):
    wc = {"edges": {"width": 2.0}, "strokes": {"amplitude": 0.15}, "shadow": False} if watercolour is None else watercolour
    wc = json.loads(json.dumps(wc))
    for name, v in values.items():
        _, effect, key = name.split(".")
        wc.setdefault(effect, {})[key] = v
    return {
        "mesh": str(DATA / "meshes" / "knot-1k.ply"),
        "image": {"width": SIZE, "height": SIZE},
        "camera": {"eye": [0.4, 0.6, 3.0], "target": [0, 0, 0], "fov_y": 45},
        "light": {"direction": [1.0, 1.2, 0.8]},
        "wash": {"pigment": "Quinacridone Rose"},
        "unlit": {"pigment": "French Ultramarine"},
        "k_wash": 0.45, "k_unlit": 0.55, "gain": 0.65, "bias": 0.4,
        "watercolour": wc,
    }  # fmt: skip


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """truth.json, its render (linear, and a 16-bit sRGB PNG), and start.json with the perturbed look."""
    d = tmp_path_factory.mktemp("look")
    return d, write_fit_target(d, _scene_dict(TRUTH), _scene_dict(START))


def test_look_parameters_are_fittable_by_their_scene_keys():
    for name in ("watercolour.edges.width", "watercolour.paper.density", "watercolour.paper.shading",
                 "watercolour.unevenness.dispersion", "watercolour.strokes.amplitude", "watercolour.shadow.strength",
                 "watercolour.hatching.amount", *TRUTH):  # fmt: skip
        assert name in FITTABLE, name
    assert "watercolour.shadow.bias" not in FITTABLE  # a step: nothing to fit


def test_the_python_api_recovers_the_look(files):
    d, linear = files
    fit = fit_image(linear, d / "start.json", list(TRUTH), max_steps=40)
    assert fit.converged, fit.message
    for name, v in TRUTH.items():
        assert float(fit.fitted[name]) == pytest.approx(v, rel=0.01), name
        assert float(fit.start[name]) == pytest.approx(START[name])
    assert fit.rms[0] < 1e-4
    # The fitted scene carries the fitted look, and saving writes it back into the scene file's object.
    assert float(fit.scene.watercolour.look.edge_darkening) == pytest.approx(TRUTH["watercolour.edges.darkening"], rel=0.01)
    fit.save(d / "api.json")
    written = json.loads((d / "api.json").read_text())["watercolour"]
    assert written["edges"]["darkening"] == pytest.approx(TRUTH["watercolour.edges.darkening"], rel=0.01)
    assert written["edges"]["width"] == 2.0 and written["shadow"] is False  # the rest as written


def test_the_command_line_recovers_the_look_and_writes_it(files, capsys, monkeypatch):
    d, _ = files
    monkeypatch.chdir(d)
    monkeypatch.setenv("MPLBACKEND", "Agg")
    status = main(["fit-image", "target.png", "--scene", "start.json", "--fit", ",".join(TRUTH), "-o", "cli.json",
                   "--quiet", "--max-steps", "40"])  # fmt: skip
    out, err = capsys.readouterr()
    assert status == 0, err
    assert "converged after" in out
    fitted = diffwash.load_scene(d / "cli.json")
    look = fitted.watercolour.look
    got = {"watercolour.edges.darkening": look.edge_darkening, "watercolour.paper.granulation": look.granulation,
           "watercolour.unevenness.turbulence": look.turbulence}  # fmt: skip
    for name, v in TRUTH.items():
        assert float(got[name]) == pytest.approx(v, rel=0.01), name
    wc = json.loads((d / "cli.json").read_text())["watercolour"]
    assert wc["unevenness"]["turbulence"] == pytest.approx(0.25, rel=0.01)


def test_look_and_model_parameters_fit_together(files):
    d, linear = files
    start = _scene_dict({**TRUTH, "watercolour.edges.darkening": 1.8})
    start["gain"] = 0.55
    (d / "start_gain.json").write_text(json.dumps(start))
    fit = fit_image(linear, d / "start_gain.json", ["gain", "watercolour.edges.darkening"], max_steps=40)
    assert fit.converged, fit.message
    assert float(fit.fitted["gain"]) == pytest.approx(0.65, rel=0.01)
    assert float(fit.fitted["watercolour.edges.darkening"]) == pytest.approx(2.5, rel=0.01)


def test_residual_gradients_of_look_parameters_match_finite_differences(files):
    """The solver's Jacobian in the look's variables (log and logit), against float64 central differences."""
    d, linear = files
    scene = diffwash.load_scene(d / "start.json")
    names = ("watercolour.edges.darkening", "watercolour.paper.granulation", "watercolour.edges.width",
             "watercolour.strokes.amplitude", "watercolour.paper.density")  # fmt: skip
    view = _prepare_look_view(scene, diffwash.rasterize(scene), linear, np.asarray(scene.params.light), np.float64)
    to64 = lambda a: jnp.asarray(a, jnp.float64) if np.asarray(a).dtype.kind == "f" else a  # noqa: E731
    problem = _Problem(views=(view,), base=jax.tree.map(to64, scene.params), light_length=jnp.float64(1.0), loss="linear",
                       look=jax.tree.map(to64, scene.watercolour.look))  # fmt: skip
    y = {k: jnp.asarray(v) for k, v in _encode(scene.params, names, scene.watercolour.look).items()}
    w = jnp.asarray(np.random.default_rng(0).normal(size=view.target.size))
    f = jax.jit(lambda y: jnp.vdot(w, _residuals(y, problem)))
    g = jax.grad(f)(y)
    h = 1e-5
    for n in names:
        fd = (f({**y, n: y[n] + h}) - f({**y, n: y[n] - h})) / (2 * h)
        assert np.isfinite(float(g[n]))
        assert abs(float(g[n]) - float(fd)) <= 1e-4 * max(abs(float(fd)), 1e-3), (n, float(g[n]), float(fd))
    look = _decode_look(y, problem.look)
    assert float(look.granulation) == pytest.approx(0.6, rel=1e-6)  # encode and decode agree


def _cli(d, monkeypatch, capsys, *args):
    monkeypatch.chdir(d)
    monkeypatch.setenv("MPLBACKEND", "Agg")
    status = main([str(a) for a in args])
    _, err = capsys.readouterr()
    return status, err


@pytest.mark.parametrize(
    "watercolour, name, needle",
    [(False, "watercolour.edges.darkening", 'no "watercolour" object'),
     ({"edges": False}, "watercolour.edges.width", "edges effect is off"),
     ({}, "watercolour.hatching.amount", "hatching effect is off"),
     ({"strokes": False}, "watercolour.strokes.amplitude", "strokes effect is off")],
    ids=["no-look", "edges-off", "hatching-off", "strokes-off"],
)  # fmt: skip
def test_a_look_parameter_the_scene_lacks_is_one_line_exit_2(files, tmp_path, monkeypatch, capsys, watercolour, name, needle):
    d, _ = files
    scene = _scene_dict({}, watercolour if watercolour is not False else {})
    if watercolour is False:
        del scene["watercolour"]
    (tmp_path / "bad.json").write_text(json.dumps(scene))
    status, err = _cli(tmp_path, monkeypatch, capsys, "fit-image", d / "target.png", "--scene", "bad.json", "--fit",
                       f"gain,{name}", "-o", "out.json")  # fmt: skip
    assert status == 2, err
    assert err.count("\n") == 1 and "bad.json" in err and f"{name}:" in err and needle in err, err
    assert not (tmp_path / "out.json").exists()
    with pytest.raises(diffwash.DiffwashError, match=needle):
        fit_image(np.zeros((SIZE, SIZE, 3)), tmp_path / "bad.json", [name])


def test_an_unknown_look_key_is_refused_with_a_suggestion(files, tmp_path, monkeypatch, capsys):
    d, _ = files
    status, err = _cli(tmp_path, monkeypatch, capsys, "fit-image", d / "target.png", "--scene", d / "start.json", "--fit",
                       "watercolour.edges.widht", "-o", "out.json")  # fmt: skip
    assert status == 2 and err.count("\n") == 1, err
    assert "unknown parameter 'watercolour.edges.widht'" in err and "did you mean 'watercolour.edges.width'" in err, err


def test_a_fit_without_look_parameters_leaves_the_look_as_it_was(files):
    d, linear = files
    fit = fit_image(linear, d / "truth.json", ["gain"], max_steps=10)
    assert float(fit.fitted["gain"]) == pytest.approx(0.65, rel=1e-3)
    before = diffwash.load_scene(d / "truth.json").watercolour.look
    for leaf in ("edge_darkening", "granulation", "turbulence", "strokes"):
        assert float(getattr(fit.scene.watercolour.look, leaf)) == float(getattr(before, leaf)), leaf
