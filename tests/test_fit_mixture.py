"""fit-image fits a library mixture's proportions and amount (`wash.mix`, `wash.amount`, `unlit.mix`,
`unlit.amount`): a small spectral scene is rendered with known mixtures, fitted back from other ones (one of them
with a proportion at 0) through the Python API and the command line's entry point, the fitted scene file carries
the fitted "mix" and "amount"; the residuals' gradients in the new variables match float64 finite differences
(and stay finite where a proportion is exactly 0); and asking for them of a glaze that is not a library mixture
is one line naming the parameter, exit 2."""

import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import DATA, write_fit_target

import diffwash
from diffwash.cli import main
from diffwash.fit import FITTABLE, fit_image
from diffwash.fit.images._image import _decode, _encode, _gauges, _prepare_view, _Problem, _residuals, _varying

LIBRARY = DATA / "libraries" / "ntu-four.json"
SIZE = 48
NAMES = ("wash.mix", "wash.amount", "unlit.mix", "unlit.amount")
#: The mixtures of the target, and those the fits start from (the wash's P1 at 0).
TRUTH = {"wash": ({"P4": 0.75, "P1": 0.25}, 0.02), "unlit": ({"P8": 0.7, "P4": 0.3}, 0.01)}
START = {"wash": ({"P4": 1.0, "P1": 0.0}, 0.035), "unlit": ({"P8": 0.4, "P4": 0.6}, 0.02)}


def _scene_dict(glazes) -> dict:
    """A sphere with a wash and an unlit glaze of the shipped NTU library: `{glaze: (mix, amount)}`."""
    return {
        "mesh": str(DATA / "meshes" / "sphere.ply"), "image": {"width": SIZE, "height": SIZE},
        "camera": {"eye": [0, 0, 3.5], "target": [0, 0, 0]}, "light": {"direction": [-1, 1, 1]},
        **{g: {"library": str(LIBRARY), "mix": mix, "amount": a} for g, (mix, a) in glazes.items()},
        "shininess": 12, "k_unlit": 1.2, "gain": 0.6, "bias": 0.45, "wash_reduction": 0.3,
    }  # fmt: skip


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """truth.json, its render (linear, and a 16-bit sRGB PNG), and start.json with other mixtures."""
    d = tmp_path_factory.mktemp("mixture")
    return d, write_fit_target(d, _scene_dict(TRUTH), _scene_dict(START))


def _check_written(path, rel):
    """The scene file at `path` has the true mixtures and amounts, pigment names kept, and loads again."""
    data = json.loads(path.read_text())
    for glaze, (mix, amount) in TRUTH.items():
        written = data[glaze]
        assert list(written["mix"]) == list(mix), glaze  # the library's names, in the scene's order
        np.testing.assert_allclose(list(written["mix"].values()), list(mix.values()), rtol=rel, atol=rel)
        assert sum(written["mix"].values()) == pytest.approx(1, abs=1e-12)
        assert written["amount"] == pytest.approx(amount, rel=rel)
        assert (path.parent / written["library"]).resolve() == LIBRARY.resolve()
    again = diffwash.load_scene(path)
    np.testing.assert_allclose(np.asarray(again.params.wash.proportions), list(TRUTH["wash"][0].values()), atol=rel)


def test_the_new_names_are_fittable_and_amount_holds_the_thickness_scale():
    for name in NAMES:
        assert name in FITTABLE, name
    free, notes = _gauges(("wash.amount", "k_wash", "k_specular", "unlit.mix", "k_unlit"))
    assert free == ("wash.amount", "unlit.mix", "k_unlit")  # the amount trades off with k_wash, not the mix with k_unlit
    assert any("k_wash is held" in n and "wash.amount" in n for n in notes), notes


def test_the_python_api_recovers_proportions_and_amounts(files):
    d, linear = files
    fit = fit_image(linear, d / "start.json", NAMES, max_steps=50)
    assert fit.converged, fit.message
    for glaze, (mix, amount) in TRUTH.items():
        np.testing.assert_allclose(fit.fitted[f"{glaze}.mix"], list(mix.values()), atol=1e-6)
        assert float(fit.fitted[f"{glaze}.amount"]) == pytest.approx(amount, rel=1e-6)
        np.testing.assert_array_equal(fit.start[f"{glaze}.mix"], list(START[glaze][0].values()))  # the 0 as it was
        assert float(fit.start[f"{glaze}.amount"]) == START[glaze][1]
    assert fit.rms[0] < 1e-8
    fit.save(d / "api.json")
    _check_written(d / "api.json", 1e-6)


def test_residual_gradients_of_mixtures_match_finite_differences(files):
    """The solver's Jacobian in the mixtures' log-ratio and log-amount variables, against float64 central
    differences: at the start (the wash's P1 raised from 0 to the floor), and where a proportion is exactly 0."""
    d, linear = files
    scene = diffwash.load_scene(d / "start.json")
    view = _prepare_view(scene, diffwash.rasterize(scene), linear, np.float64)
    to64 = lambda a: jnp.asarray(a, jnp.float64) if np.asarray(a).dtype.kind == "f" else a  # noqa: E731
    problem = _Problem(views=(view,), base=jax.tree.map(to64, scene.params), light_length=jnp.float64(1.0),
                       loss="linear", varying=_varying(NAMES))  # fmt: skip
    y0 = {k: jnp.asarray(v) for k, v in _encode(scene.params, NAMES).items()}
    assert y0["wash.mix"].shape == (1,) and y0["wash.amount"].shape == ()  # P - 1 log-ratios; one log-amount
    p0 = _decode(y0, problem.base, 1.0)
    assert 0 < float(p0.wash.proportions[1]) < 2e-3 and float(jnp.sum(p0.wash.proportions)) == pytest.approx(1)
    assert float(p0.unlit.amount) == pytest.approx(0.02, rel=1e-12)  # encode and decode agree
    np.testing.assert_allclose(p0.unlit.proportions, [0.4, 0.6], rtol=1e-12)
    w = jnp.asarray(np.random.default_rng(0).normal(size=view.target.size))
    f = jax.jit(lambda y: jnp.vdot(w, _residuals(y, problem)))
    grad = jax.jit(jax.grad(f))
    h = 1e-5
    # At the start, and with the wash's P1 exactly 0 (the log-ratio far out: the softmax underflows to 0).
    for y in (y0, {**y0, "wash.mix": jnp.asarray([800.0])}):
        g = grad(y)
        assert all(bool(jnp.all(jnp.isfinite(v))) for v in jax.tree.leaves(g))
        for n in NAMES:
            for i in np.ndindex(y[n].shape):
                e = jnp.zeros_like(y[n]).at[i].set(h)
                fd = float((f({**y, n: y[n] + e}) - f({**y, n: y[n] - e})) / (2 * h))
                ad = float(g[n][i])
                assert abs(ad - fd) <= 1e-4 * max(abs(fd), 1e-3), (n, i, ad, fd)
    at_zero = _decode({**y0, "wash.mix": jnp.asarray([800.0])}, problem.base, 1.0).wash.proportions
    assert float(at_zero[1]) == 0.0 and float(at_zero[0]) == 1.0
    assert float(jnp.abs(grad({**y0, "wash.mix": jnp.asarray([800.0])})["wash.mix"][0])) == 0.0


def _cli(d, monkeypatch, capsys, *args):
    monkeypatch.chdir(d)
    monkeypatch.setenv("MPLBACKEND", "Agg")
    status = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return status, out, err


def test_the_command_line_fits_the_mixtures_and_writes_them(files, capsys, monkeypatch):
    d, _ = files
    status, out, err = _cli(d, monkeypatch, capsys, "fit-image", "target.png", "--scene", "start.json", "--fit",
                            ",".join(NAMES), "-o", "cli.json", "--quiet", "--max-steps", "50")  # fmt: skip
    assert status == 0, err
    assert "converged after" in out and "wash.mix" in out and "unlit.amount" in out, out
    _check_written(d / "cli.json", 1e-3)  # from a 16-bit PNG


PLAIN = {"wash": {"pigment": "Quinacridone Rose"}, "unlit": {"pigment": "French Ultramarine"}}
ONE = {"wash": {"library": str(LIBRARY), "pigment": "P4", "amount": 0.02}}


@pytest.mark.parametrize(
    "changes, fit, needle",
    [(PLAIN, "gain,wash.mix", "cannot fit 'wash.mix': the scene's wash is the pigment 'Quinacridone Rose', not a mixture"),
     (PLAIN, "unlit.amount", "cannot fit 'unlit.amount': the scene's unlit is the pigment 'French Ultramarine'"),
     (ONE, "wash.mix", "cannot fit 'wash.mix': the scene's wash is one library pigment (P4)"),
     ({}, "wash.mix,wash.K", "cannot fit 'wash.K' of a scene whose glazes are spectral"),
     ({}, "unlit.amount,unlit.S", "cannot fit 'unlit.S' of a scene whose glazes are spectral")],
    ids=["plain-mix", "plain-amount", "one-pigment", "spectral-K", "spectral-S"],
)  # fmt: skip
def test_a_mixture_parameter_the_scene_lacks_is_one_line_exit_2(files, tmp_path, monkeypatch, capsys, changes, fit, needle):
    d, _ = files
    (tmp_path / "bad.json").write_text(json.dumps({**_scene_dict(START), **changes}))
    status, _, err = _cli(tmp_path, monkeypatch, capsys, "fit-image", d / "target.png", "--scene", "bad.json",
                          "--fit", fit, "-o", "out.json")  # fmt: skip
    assert status == 2, err
    assert err.count("\n") == 1 and "Traceback" not in err and "--fit: " in err and needle in err, err
    assert not (tmp_path / "out.json").exists()
    with pytest.raises(diffwash.DiffwashError, match=needle.split(":")[0]):
        fit_image(np.zeros((SIZE, SIZE, 3)), tmp_path / "bad.json", fit)
