"""A scene's "watercolour" object: parsed with defaults, refused in one line naming the file and key, drawn by
diffwash.render (finite, visible, the plain model when absent) and differentiable in every continuous look
parameter (float64 central differences)."""

import json

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import ROOT

import diffwash
from diffwash import look as wl

MESH = ROOT / "data" / "meshes" / "knot-1k.ply"


def _scene_dict(watercolour=None, size=40):
    d = json.loads((ROOT / "data" / "scenes" / "knot.json").read_text())
    d["mesh"] = str(MESH)
    d["image"] = {"width": size, "height": size}
    d["k_wash"], d["k_unlit"] = 0.45, 0.55
    if watercolour is not None:
        d["watercolour"] = watercolour
    return d


def _write(tmp_path, d, name="scene.json"):
    path = tmp_path / name
    path.write_text(json.dumps(d))
    return path


def _load(tmp_path, watercolour=None, size=40):
    return diffwash.load_scene(_write(tmp_path, _scene_dict(watercolour, size)))


def test_absent_or_false_is_the_plain_model(tmp_path):
    plain = _load(tmp_path)
    off = _load(tmp_path, False)
    assert plain.watercolour is None and off.watercolour is None
    np.testing.assert_array_equal(np.asarray(diffwash.render(plain)), np.asarray(diffwash.render(off)))


def test_an_empty_object_turns_on_the_defaults(tmp_path):
    wc = _load(tmp_path, {}).watercolour
    for k, v in wl.DEFAULT_LOOK.items():
        assert float(getattr(wc.look, k)) == pytest.approx(v), k
    assert wc.shadow and wc.strokes is not None and wc.tam is None and wc.mix is None


def test_an_effect_set_to_false_is_off(tmp_path):
    wc = _load(tmp_path, {"edges": False, "strokes": False, "shadow": False, "paper": {"granulation": 0.2}}).watercolour
    assert float(wc.look.edge_darkening) == 0 and float(wc.look.strokes) == 0 and float(wc.look.shadow) == 0
    assert wc.strokes is None and not wc.shadow
    assert float(wc.look.granulation) == pytest.approx(0.2)


def test_the_showcase_scene_turns_every_effect_on():
    scene = diffwash.load_scene(ROOT / "data" / "scenes" / "watercolour.json")
    wc = scene.watercolour
    assert all(float(getattr(wc.look, k)) > 0 for k in wl.DEFAULT_LOOK), wc.look
    assert wc.shadow and wc.tam is not None and wc.mix is not None and wc.strokes is not None


def test_the_look_is_drawn_finite_and_visible(tmp_path):
    wc = {"hatching": {"amount": 0.4}, "mix": {"wash": {"pigment": "Cadmium Yellow"}, "map": {"axis": [0, 1, 0]}}}
    look = np.asarray(diffwash.render(_load(tmp_path, wc)))
    plain = np.asarray(diffwash.render(_load(tmp_path)))
    assert np.all(np.isfinite(look))
    psnr = 10 * np.log10(1 / np.mean((look - plain) ** 2))
    assert psnr < 30, psnr
    rgba = np.asarray(diffwash.render_rgba(_load(tmp_path, wc)))
    np.testing.assert_allclose(rgba[..., :3], look)
    assert set(np.unique(rgba[..., 3])) == {0.0, 1.0}


BAD = [
    ({"edges": {"width": -1}}, "watercolour.edges.width", "must be >= 0"),
    ({"edges": {"darkening": "x"}}, "watercolour.edges.darkening", "must be a number, got 'x'"),
    ({"paper": {"granulation": 1.5}}, "watercolour.paper.granulation", "must be <= 1, got 1.5"),
    ({"paper": {"image": "nowhere.png"}}, "watercolour.paper.image", "no such image file"),
    ({"paper": {"seed": -3}}, "watercolour.paper.seed", "must be >= 0, got -3"),
    ({"paper": {"seed": 1.5}}, "watercolour.paper.seed", "whole number"),
    ({"strokes": {"direction": "diagonal"}}, "watercolour.strokes.direction", "min"),
    ({"strokes": {"length": 0}}, "watercolour.strokes.length", "> 0"),
    ({"mix": {"map": [0.5, 0.5]}}, "watercolour.mix.map", "one value per vertex"),
    ({"mix": {"map": {"axis": [0, 0, 0]}}}, "watercolour.mix.map.axis", "non-zero"),
    ({"mix": {}}, "watercolour.mix.map", "missing key"),
    ({"mix": True}, "watercolour.mix.map", "missing key"),  # `true` is the defaults, and mix has no default map
    ({"mix": {"wash": {"pigment": "No Such Pigment"}, "map": {"axis": [1, 0, 0]}}}, "watercolour.mix.wash.pigment", "unknown pigment"),
    ({"edge": {}}, "watercolour.edge", "unknown key"),
    ({"shadow": {"strength": 2}}, "watercolour.shadow.strength", "must be <= 1, got 2"),
    ({"hatching": 3}, "watercolour.hatching", "JSON object or false"),
    ([1, 2], "watercolour", "JSON object"),
]


@pytest.mark.parametrize("watercolour, key, needle", BAD, ids=[b[1] for b in BAD])
def test_bad_values_are_one_line_naming_file_and_key(tmp_path, watercolour, key, needle):
    path = _write(tmp_path, _scene_dict(watercolour))
    with pytest.raises(diffwash.DiffwashError) as e:
        diffwash.load_scene(path)
    msg = str(e.value)
    assert "\n" not in msg and str(path) in msg and f"{key}:" in msg and needle in msg, msg


@pytest.mark.parametrize("watercolour, key", [({"edges": {"width": -2}}, "watercolour.edges.width"),
                                              ({"paper": {"image": "missing.png"}}, "watercolour.paper.image"),
                                              ({"mix": {"map": [0.1, 0.2, 0.3]}}, "watercolour.mix.map")])  # fmt: skip
def test_bad_values_through_the_cli_exit_2(run_cli, tmp_path, watercolour, key):
    path = _write(tmp_path, _scene_dict(watercolour))
    r = run_cli("render", path, "-o", tmp_path / "out.png")
    assert r.returncode == 2, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "scene.json" in lines[0] and key in lines[0], r.stderr
    assert not (tmp_path / "out.png").exists()


def test_a_paper_image_and_a_mix_file(tmp_path):
    from diffwash._io import write_png

    rng = np.random.default_rng(0)
    write_png(tmp_path / "paper.png", np.repeat(rng.uniform(size=(32, 32, 1)), 3, axis=2))
    n = len(diffwash.load_mesh(MESH).vertices)
    np.save(tmp_path / "mix.npy", np.linspace(0, 1, n))
    wc = _load(tmp_path, {"paper": {"image": "paper.png"}, "mix": {"map": "mix.npy"}}).watercolour
    assert wc.screen.shape[:2] == (32, 32)
    np.testing.assert_allclose(wc.mix, np.linspace(0, 1, n), atol=1e-6)


def test_the_cli_renders_the_look(run_cli, tmp_path):
    path = _write(tmp_path, _scene_dict({}, size=32))
    r = run_cli("render", path, "-o", tmp_path / "out.png")
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "out.png").is_file()


def test_a_look_too_big_to_draw_in_one_piece_is_refused_with_a_size_that_fits(run_cli, tmp_path):
    """The look blurs across the whole image, so it cannot go in strips: past its limit the render is refused."""
    path = _write(tmp_path, _scene_dict({}, size=32))
    r = run_cli("render", path, "--size", "4000x2000", "-o", tmp_path / "out.png")
    assert r.returncode == 2 and r.stderr.count("\n") == 1, r.stderr
    assert "4000x2000 = 8,000,000 pixels is over its limit of 2,097,152" in r.stderr and "render at 2048x1024" in r.stderr
    assert not (tmp_path / "out.png").exists()


# --- gradients of the renderer in every continuous look parameter ----------------------------------------

LEAVES = [*wl.DEFAULT_LOOK]


@pytest.fixture(scope="module")
def grad_scene(tmp_path_factory):
    wc = {"hatching": {"amount": 0.4}, "mix": {"wash": {"pigment": "Cadmium Yellow"}, "unlit": {"pigment": "Hookers Green"},
                                               "map": {"axis": [0, 1, 0], "softness": 0.8}}}  # fmt: skip
    scene = _load(tmp_path_factory.mktemp("g"), wc, size=24)
    to64 = lambda x: jnp.asarray(x, jnp.float64) if eqx.is_inexact_array(x) or isinstance(x, (float, np.floating)) else x  # noqa: E731
    return jax.tree.map(to64, scene)


def _loss(scene, weights):
    def f(look, mix):
        s = eqx.tree_at(lambda s: (s.watercolour.look, s.watercolour.mix), scene, (look, mix))
        return jnp.sum(diffwash.render(s) * weights)

    return f


@pytest.mark.parametrize("leaf", [k for k in LEAVES if k != "shadow_bias"] + ["mix"])
def test_render_gradients_match_finite_differences(grad_scene, leaf):
    wc = grad_scene.watercolour
    weights = jnp.asarray(np.random.default_rng(1).uniform(size=(24, 24, 3)))
    f = _loss(grad_scene, weights)
    g_look, g_mix = jax.grad(f, argnums=(0, 1))(wc.look, jnp.asarray(wc.mix))
    h = 1e-5
    if leaf == "mix":
        d = jnp.asarray(np.random.default_rng(2).normal(size=wc.mix.shape))
        ad = jnp.vdot(g_mix, d)
        fd = (f(wc.look, wc.mix + h * d) - f(wc.look, wc.mix - h * d)) / (2 * h)
    else:
        ad = getattr(g_look, leaf)
        at = lambda x: eqx.tree_at(lambda lk: getattr(lk, leaf), wc.look, x)  # noqa: E731
        v = getattr(wc.look, leaf)
        fd = (f(at(v + h), wc.mix) - f(at(v - h), wc.mix)) / (2 * h)
    assert np.isfinite(float(ad))
    assert abs(float(ad) - float(fd)) <= 1e-4 * max(abs(float(fd)), 1e-3), (leaf, float(ad), float(fd))


def test_gradients_are_finite_with_every_effect_at_zero(grad_scene):
    wc = grad_scene.watercolour
    zero = jax.tree.map(jnp.zeros_like, wc.look)
    weights = jnp.ones((24, 24, 3))
    g = jax.grad(_loss(grad_scene, weights), argnums=(0, 1))(zero, jnp.zeros_like(jnp.asarray(wc.mix)))
    assert all(np.all(np.isfinite(np.asarray(x))) for x in jax.tree.leaves(g))


def test_a_saved_scene_keeps_its_look_with_fitted_values(tmp_path):
    from diffwash._io import write_png

    write_png(tmp_path / "paper.png", np.repeat(np.random.default_rng(0).uniform(size=(16, 16, 1)), 3, axis=2))
    path = _write(tmp_path, _scene_dict({"paper": {"image": "paper.png"}, "edges": {"width": 2.0}, "strokes": False}))
    assert tmp_path / "paper.png" in diffwash.referenced_files(path)  # an output may not overwrite it
    scene = diffwash.load_scene(path)
    fitted = eqx.tree_at(lambda s: s.watercolour.look.edge_darkening, scene, np.float64(1.25))
    (tmp_path / "out").mkdir()
    diffwash.save_scene(tmp_path / "out" / "fitted.json", fitted)
    again = diffwash.load_scene(tmp_path / "out" / "fitted.json")
    assert float(again.watercolour.look.edge_darkening) == 1.25
    assert float(again.watercolour.look.edge_width) == 2.0
    assert again.watercolour.strokes is None  # off stays off
    np.testing.assert_array_equal(again.watercolour.screen, scene.watercolour.screen)  # the paper image, found again


def test_look_parameters_fit_to_a_target_render(grad_scene):
    """Least squares through diffwash.render (optimistix Levenberg-Marquardt) finds the edge darkening,
    granulation and turbulence of a target rendered with other values."""
    import optimistix as optx

    names = ("edge_darkening", "granulation", "turbulence")
    truth = eqx.tree_at(lambda lk: [getattr(lk, n) for n in names], grad_scene.watercolour.look,
                        [jnp.float64(4.0), jnp.float64(0.35), jnp.float64(0.3)])  # fmt: skip

    def image(values):
        look = eqx.tree_at(lambda lk: [getattr(lk, n) for n in names], grad_scene.watercolour.look, list(values))
        return diffwash.render(eqx.tree_at(lambda s: s.watercolour.look, grad_scene, look))

    target = image([getattr(truth, n) for n in names])
    start = jnp.asarray([float(getattr(grad_scene.watercolour.look, n)) for n in names])
    sol = optx.least_squares(lambda y, _: (image(list(y)) - target).reshape(-1), optx.LevenbergMarquardt(rtol=1e-8, atol=1e-10),
                             start, max_steps=50)  # fmt: skip
    np.testing.assert_allclose(np.asarray(sol.value), [4.0, 0.35, 0.3], rtol=1e-4)


def test_the_shadow_map_made_once_outside_is_the_kernels_and_the_light_stays_differentiable(grad_scene):
    # A fixed light and mesh: the map is computed once, outside the kernel; a traced light: inside, differentiable.
    p = grad_scene.params
    render_at = lambda light: diffwash.render(grad_scene, eqx.tree_at(lambda q: q.light, p, light))  # noqa: E731
    outside = render_at(p.light)
    inside, vjp = jax.vjp(render_at, p.light)
    np.testing.assert_allclose(np.asarray(outside), np.asarray(inside), rtol=0, atol=1e-12)
    weights = jnp.asarray(np.random.default_rng(3).uniform(size=(24, 24, 3)))
    (g,) = vjp(weights)
    d, h = jnp.asarray([0.3, -0.2, 0.1]), 1e-5
    fd = (jnp.sum(render_at(p.light + h * d) * weights) - jnp.sum(render_at(p.light - h * d) * weights)) / (2 * h)
    assert abs(float(jnp.vdot(g, d)) - float(fd)) <= 1e-4 * max(abs(float(fd)), 1e-3)
