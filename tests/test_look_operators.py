"""The look's operators, one behaviour each: textures, paper effects, edges, strokes, hatching, shadows, mixes."""

import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from diffwash import shading
from diffwash._errors import DiffwashError
from diffwash.look import _edges, _hatching, _mix, _paper, _shadow, _strokes, _textures
from diffwash.pigments import Pigment

from conftest import DATA

ROSE = Pigment(K=np.array([0.22, 1.47, 0.57]), S=np.array([0.05, 0.003, 0.03]), density=0.02, staining=5.5, granularity=0.81)
ULTRAMARINE = Pigment(K=np.array([0.86, 0.86, 0.06]), S=np.array([0.005, 0.005, 0.09]), density=0.01, staining=3.1, granularity=0.91)


# --- textures ------------------------------------------------------------------------------------


def test_screen_textures_are_seeded_tileable_and_normalised():
    a = _textures.screen_textures(shape=(48, 40), seed=3)
    b = _textures.screen_textures(shape=(48, 40), seed=3)
    c = _textures.screen_textures(shape=(48, 40), seed=4)
    np.testing.assert_array_equal(a.channels, b.channels)
    assert not np.allclose(a.channels, c.channels)
    assert a.channels.shape == (48, 40, 6) and a.channels.dtype == np.float32
    h = a.paper
    assert h.min() >= 0 and h.max() <= 1 and 0.2 < h.mean() < 0.8
    for k in range(2, 6):  # the noises: zero mean, unit deviation
        assert abs(float(a.channels[..., k].mean())) < 1e-5 and abs(float(a.channels[..., k].std()) - 1) < 1e-4
    # Periodic: the step across the tile's seam is no larger than steps inside it.
    for k in (0, 2):
        x = a.channels[..., k].astype(np.float64)
        inner = np.abs(np.diff(x, axis=1)).mean()
        seam = np.abs(x[:, 0] - x[:, -1]).mean()
        assert seam < 2.5 * inner


def test_tile_repeats_the_tile_over_the_image():
    t = _textures.screen_textures(shape=(16, 12), seed=1)
    img = np.asarray(_textures.tile(t, 40, 30))
    assert img.shape == (40, 30, 6)
    np.testing.assert_array_equal(img[17, 25], t.channels[17 % 16, 25 % 12])
    np.testing.assert_array_equal(img[:16, :12], t.channels)


def test_paper_from_image(tmp_path):
    from diffwash._io import write_png

    g = np.linspace(0, 1, 20 * 24).reshape(20, 24)
    write_png(tmp_path / "paper.png", np.repeat(g[..., None], 3, axis=2))
    h = _textures.paper_from_image(tmp_path / "paper.png")
    assert h.shape == (20, 24) and h.min() == 0 and h.max() == 1
    assert np.all(np.diff(h, axis=1) >= 0)  # brighter is higher
    t = _textures.screen_textures(tmp_path / "paper.png")
    assert t.shape == (20, 24)


@pytest.mark.parametrize("case", ["missing", "not-an-image", "too-small"])
def test_a_bad_paper_image_is_one_line_naming_the_file(tmp_path, case):
    from diffwash._io import write_png

    path = tmp_path / "paper.png"
    if case == "not-an-image":
        path.write_bytes(b"this is not a picture")
    elif case == "too-small":
        write_png(path, np.zeros((4, 5, 3)))
    with pytest.raises(DiffwashError) as e:
        _textures.paper_from_image(path, field="watercolour.paper")
    msg = str(e.value)
    assert "\n" not in msg and str(path) in msg and "watercolour.paper" in msg


# --- paper effects ---------------------------------------------------------------------------------


@given(st.floats(0.0, 1.0), st.floats(0.05, 20.0))
def test_deposit_law(gamma, omega):
    """Curtis et al.'s equilibrium: in (0, 1], never more on the peaks than in the valleys, even without granularity."""
    h = np.linspace(0, 1, 11)
    phi = np.asarray(_paper.deposit(h, gamma, omega))
    assert np.all(phi >= 0) and np.all(phi <= 1 + 1e-12)
    assert np.all(np.diff(phi) <= 1e-12)
    if gamma == 0:
        np.testing.assert_allclose(phi, omega / (1 + omega))


def test_granulation_keeps_the_mean_and_follows_granularity_and_staining():
    paper = _textures.procedural_paper((64, 64), seed=2)
    h = jnp.asarray(paper)

    def spread(p):
        f = np.asarray(_paper.pigment_factor(h, _paper.pigment_look(p, paper), 1.0, 0.0))
        np.testing.assert_allclose(f.mean(), 1.0, rtol=1e-10)  # the pigment's amount is kept
        return f.std()

    granular = Pigment(K=ROSE.K, S=ROSE.S, granularity=0.9, staining=1.0)
    smooth = Pigment(K=ROSE.K, S=ROSE.S, granularity=0.1, staining=1.0)
    staining = Pigment(K=ROSE.K, S=ROSE.S, granularity=0.9, staining=9.0)
    assert spread(granular) > 3 * spread(smooth)
    assert spread(granular) > 2 * spread(staining)  # staining pigments stay where they were laid
    f = np.asarray(_paper.pigment_factor(h, _paper.pigment_look(granular, paper), 1.0, 0.0))
    assert f[paper < 0.2].mean() > f[paper > 0.8].mean()  # settled in the valleys


def test_density_scales_relative_to_the_reference():
    paper = np.full((8, 8), 0.5)
    ref = Pigment(K=ROSE.K, S=ROSE.S, density=_paper.DENSITY_REFERENCE)
    dense = Pigment(K=ROSE.K, S=ROSE.S, density=4 * _paper.DENSITY_REFERENCE)
    h = jnp.asarray(paper)
    np.testing.assert_allclose(_paper.pigment_factor(h, _paper.pigment_look(ref, paper), 0.0, 0.7), 1.0)
    np.testing.assert_allclose(_paper.pigment_factor(h, _paper.pigment_look(dense, paper), 0.0, 0.5), 2.0)


def test_unevenness_and_paper_shading_are_identities_at_zero():
    n = jnp.asarray(np.random.default_rng(0).normal(size=(5, 6)))
    np.testing.assert_array_equal(_paper.unevenness_factor(n, n, 0.0, 0.0), 1.0)
    rgb = jnp.ones((5, 6, 3)) * 0.5
    np.testing.assert_array_equal(_paper.paper_shading(rgb, n, 0.0), rgb)


# --- edges -----------------------------------------------------------------------------------------


def test_resampling_and_blur_conventions():
    x = np.arange(7 * 9, dtype=np.float64).reshape(7, 9)
    low = np.asarray(_edges.downsample(x, 2))
    assert low.shape == (4, 5)
    assert low[0, 0] == x[:2, :2].mean() and low[3, 4] == x[6, 8]  # the last block repeats the edge
    const = np.full((6, 5, 2), 0.7)
    np.testing.assert_allclose(_edges.blur(const, 1.3), const)
    np.testing.assert_allclose(_edges.upsample(const, 11, 9, 2), np.full((11, 9, 2), 0.7))
    np.testing.assert_allclose(np.sum(_edges.gaussian_weights(2.0)), 1.0)
    # Upsampling a linear ramp at the pixel centres is exact away from the clamped border.
    ramp = np.arange(8.0)[None, :].repeat(3, 0)
    up = np.asarray(_edges.upsample(ramp, 6, 16, 2))
    np.testing.assert_allclose(up[0, 1:15], (np.arange(1, 15) + 0.5) / 2 - 0.5)
    assert [_edges.edge_downsample(n) for n in (128, 256, 512, 1024, 2048)] == [1, 1, 2, 4, 8]


def test_edge_darkening_gathers_pigment_at_the_edge_of_a_wash():
    t = np.zeros((40, 40))
    t[10:30, 10:30] = 0.5
    out = np.asarray(_edges.edge_darkening(t, 2.0, 2.0))
    assert out[20, 10] > 0.6  # on the edge
    np.testing.assert_allclose(out[20, 20], 0.5, atol=1e-9)  # the interior is untouched
    assert np.all(out[t == 0] == 0)  # no pigment outside the wash
    np.testing.assert_array_equal(_edges.edge_darkening(t, 0.0, 2.0), t)  # strength 0: off
    np.testing.assert_array_equal(_edges.edge_darkening(t, 2.0, 0.0, factor=1), t)  # width 0 at full resolution: off
    narrow = np.asarray(_edges.edge_darkening(t, 2.0, 0.0, factor=2))  # on a coarser grid: the grid's own edge
    assert np.all(np.isfinite(narrow)) and narrow[20, 10] > 0.5 and narrow[20, 13] == 0.5


# --- strokes ---------------------------------------------------------------------------------------


def _cylinder(n_around=48, n_along=40, radius=0.3, length=2.0):
    a = np.linspace(0, 2 * np.pi, n_around, endpoint=False)
    z = np.linspace(-length / 2, length / 2, n_along)
    A, Z = np.meshgrid(a, z, indexing="ij")
    v = np.stack([radius * np.cos(A), radius * np.sin(A), Z], -1).reshape(-1, 3)
    n = np.stack([np.cos(A), np.sin(A), 0 * A], -1).reshape(-1, 3)
    idx = np.arange(n_around * n_along).reshape(n_around, n_along)
    f = []
    for i in range(n_around):
        j = (i + 1) % n_around
        for k in range(n_along - 1):
            f += [[idx[i, k], idx[j, k], idx[j, k + 1]], [idx[i, k], idx[j, k + 1], idx[i, k + 1]]]
    return v, np.asarray(f), n


def test_principal_directions_of_a_cylinder():
    v, f, n = _cylinder()
    d_max, d_min, k_max, k_min = _strokes.principal_directions(v, f, n)
    inner = (np.abs(v[:, 2]) < 0.8)  # away from the open ends
    assert np.median(np.abs(d_min[inner, 2])) > 0.99  # least curvature along the axis
    assert np.median(np.abs(d_max[inner, 2])) < 0.05  # most curvature around it
    np.testing.assert_allclose(np.median(k_max[inner]), 1 / 0.3, rtol=0.05)
    assert abs(np.median(k_min[inner])) < 0.1


def test_stroke_field_is_standardised_deterministic_and_streaked_along_its_direction():
    v, f, n = _cylinder(64, 60)
    s = _strokes.stroke_field(v, f, n, direction="min", length=0.6, width=0.05, seed=1)
    np.testing.assert_array_equal(s, _strokes.stroke_field(v, f, n, direction="min", length=0.6, width=0.05, seed=1))
    assert abs(float(s.mean())) < 1e-5 and abs(float(s.std()) - 1) < 1e-4
    grid = s.reshape(64, 60)  # (around, along)
    along = np.corrcoef(grid[:, :-1].ravel(), grid[:, 1:].ravel())[0, 1]
    around = np.corrcoef(grid[:-1].ravel(), grid[1:].ravel())[0, 1]
    assert along > around + 0.2  # strokes run along the least-curved direction


def test_subdivision_keeps_the_shape():
    v, f, n = _cylinder(12, 6)
    v2, f2, n2 = _strokes.subdivide(v, f, n, max_edge=0.51 * _strokes.mean_edge_length(v, f))
    assert len(f2) == 4 * len(f)
    np.testing.assert_allclose(np.hypot(v2[:, 0], v2[:, 1]).max(), 0.3, rtol=1e-12)  # no vertex leaves the hull


# --- hatching --------------------------------------------------------------------------------------


def test_tonal_art_map_nests_in_tone_and_resolution():
    tam = _hatching.tonal_art_map(size=64, levels=3, seed=1)
    assert [t.shape for t in tam] == [(64, 64, 8), (32, 32, 8), (16, 16, 8)]
    for level in tam:
        assert np.all(np.diff(level, axis=-1) >= -1e-6)  # darker tones only add strokes
        np.testing.assert_allclose(level.mean(axis=(0, 1)), np.arange(1, 9) / 8 * 0.8, atol=0.03)
    # Every stroke of a coarse level is in the finer one: where a coarse texel is fully inked, the
    # finer level has ink in the same 2x2 block.
    for coarse, fine in zip(tam[1:], tam[:-1]):
        n = coarse.shape[0]
        block_max = fine.reshape(n, 2, n, 2, 8).max(axis=(1, 3))
        assert np.all(block_max[coarse > 0.99] > 0)


def test_tone_weights_blend_the_two_nearest_tones():
    w = np.asarray(_hatching.tone_weights(jnp.asarray([0.0, 0.3125, 1.0])))
    np.testing.assert_allclose(w.sum(axis=-1), [0, 1, 1])
    np.testing.assert_allclose(w[1, [1, 2]], [0.5, 0.5])  # tau = 2.5 / 8


# --- shadows ---------------------------------------------------------------------------------------


def _quads():
    """Two horizontal squares, the upper one half over the lower one, lit from straight above."""
    def quad(x0, x1, y, z0, z1):
        return np.array([[x0, y, z0], [x1, y, z0], [x1, y, z1], [x0, y, z1]], float)

    v = np.concatenate([quad(-1, 1, 0.0, -1, 1), quad(0, 1, 0.5, -1, 1)])
    f = np.array([[0, 2, 1], [0, 3, 2], [4, 6, 5], [4, 7, 6]])
    return v, f


def _raster_tri(clip, faces, size):
    """A brute-force rasterizer ordering by w, as diffwash's does (for the test only)."""
    ndc = clip[:, :3] / clip[:, 3:]
    c = (np.arange(size) + 0.5) / size * 2 - 1
    X, Y = np.meshgrid(c, -c)
    tri = np.full((size, size), -1)
    best = np.full((size, size), np.inf)
    for t, (a, b, d) in enumerate(faces):
        pa, pb, pd = ndc[a], ndc[b], ndc[d]
        area = (pb[0] - pa[0]) * (pd[1] - pa[1]) - (pd[0] - pa[0]) * (pb[1] - pa[1])
        w1 = ((X - pa[0]) * (pd[1] - pa[1]) - (pd[0] - pa[0]) * (Y - pa[1])) / area
        w2 = ((pb[0] - pa[0]) * (Y - pa[1]) - (X - pa[0]) * (pb[1] - pa[1])) / area
        inside = (w1 >= 0) & (w2 >= 0) & (w1 + w2 <= 1)
        w = clip[a, 3] + w1 * (clip[b, 3] - clip[a, 3]) + w2 * (clip[d, 3] - clip[a, 3])
        hit = inside & (w < best)
        tri[hit], best[hit] = t, w[hit]
    return tri


def test_light_view_projection_fits_the_mesh():
    v = np.random.default_rng(0).normal(size=(50, 3))
    for d in ([0, 1, 0], [1, 1.2, 0.8], [0, 0, -1]):
        ndc = np.asarray(_shadow._project(jnp.asarray(v), _shadow.light_view_projection(v, d)))
        assert np.all(np.abs(ndc) <= 1)
        # Nearer the light is smaller depth.
        dn = np.asarray(d, float) / np.linalg.norm(d)
        assert np.corrcoef(v @ dn, ndc[:, 2])[0, 1] < -0.99


def test_shadow_of_one_square_on_another():
    v, f = _quads()
    vp = np.asarray(_shadow.light_view_projection(v, [0.0, 1.0, 0.0]))
    tri = _raster_tri(np.asarray(_shadow.light_clip(v, vp)), f, 64)
    depth = np.asarray(_shadow.light_depth(v, f, vp, tri))
    assert np.all(depth[tri < 0] == 1) and np.all(depth[tri >= 0] < 1)
    pts = np.array([[-0.5, 0.0, 0.0], [0.5, 0.0, 0.0], [0.5, 0.5, 0.0]])  # lower left, lower under the upper, upper
    s = np.asarray(_shadow.shadow(depth, vp, pts, 0.01))
    np.testing.assert_allclose(s, [0, 1, 0], atol=1e-12)
    s2 = np.asarray(_shadow.shadow(depth, vp, pts, 0.01, taps=2))
    np.testing.assert_allclose(s2, [0, 1, 0], atol=1e-12)


# --- mixes -----------------------------------------------------------------------------------------


def test_glaze_mix_ends_are_the_two_glazes():
    p = shading.Params(wash=ROSE, unlit=ULTRAMARINE)
    w, u = jnp.asarray([0.0, 0.4, 1.0]), jnp.asarray([0.7, 0.0, 1.0])
    np.testing.assert_allclose(_mix.glaze_mix(p, ULTRAMARINE, ROSE, w, u, 0.0), shading.glaze(p, w, u), rtol=1e-12)
    q = shading.Params(wash=ULTRAMARINE, unlit=ROSE)
    np.testing.assert_allclose(_mix.glaze_mix(p, ULTRAMARINE, ROSE, w, u, 1.0), shading.glaze(q, w, u), rtol=1e-12)


def test_mix_lut_is_exact_on_its_grid_and_converges():
    p = shading.Params(wash=ROSE, unlit=ULTRAMARINE)

    def glaze(q, w, u, m):
        return _mix.glaze_mix(q, ULTRAMARINE, ROSE, w, u, m)

    table = _mix.bake_mix_lut(glaze, p, (5, 4, 3), wash_max=1.0, unlit_max=2.0)
    assert table.shape == (3, 4, 5, 3)
    got = _mix.lookup_mix_lut(table, 0.25, 2.0 / 3, 0.5, wash_max=1.0, unlit_max=2.0)
    np.testing.assert_allclose(got, table[1, 1, 1], rtol=1e-6)
    np.testing.assert_allclose(table[1, 1, 1], glaze(p, 0.25, 2.0 / 3, 0.5), rtol=1e-6)
    coarse = _mix.mix_lut_error(glaze, p, (8, 8, 4), wash_max=1.0, unlit_max=1.0, samples=2000)
    fine = _mix.mix_lut_error(glaze, p, (32, 32, 8), wash_max=1.0, unlit_max=1.0, samples=2000)
    assert fine["max"] < coarse["max"] / 4  # second-order convergence of trilinear interpolation
    assert _mix.blended_pair_error(glaze, p, wash_max=1.0, unlit_max=1.0, samples=2000)["max"] > fine["max"]


def test_mix_maps_are_checked():
    np.testing.assert_array_equal(_mix.check_mix_map([0, 0.5, 1], 3), [0, 0.5, 1])
    for bad, why in (([0, 1], "one value per vertex"), ([0, np.nan, 1], "finite"), ([0, 1.5, 1], "[0, 1]")):
        with pytest.raises(DiffwashError, match="scene.json: watercolour.mix: ") as e:
            _mix.check_mix_map(bad, 3, file="scene.json")
        assert why in str(e.value)
    m = _mix.mix_along_axis(np.random.default_rng(0).normal(size=(100, 3)), [0, 1, 0])
    assert m.min() == 0 and m.max() == 1


def test_data_folder_is_the_tests_source():
    assert (DATA / "meshes" / "knot-1k.ply").is_file()


def test_normal_offset_is_texels_in_world_units():
    v = np.random.default_rng(1).normal(size=(40, 3))
    for d in ([0, 1, 0], [1, 1.2, 0.8], [0.3, -0.2, 1.0]):
        vp = np.asarray(_shadow.light_view_projection(v, d))
        r = 1 / np.linalg.norm(vp[0, :3])  # the frustum's half-size
        np.testing.assert_allclose(_shadow.normal_offset(vp, 512, 1.5), 1.5 * 2 * r / 512)


def test_sample_tam_reads_the_two_levels_around_the_lod():
    """The packed two-level lookup equals blending `sample_level` of every level (the textbook trilinear)."""
    rng = np.random.default_rng(3)
    tam = [rng.uniform(size=(n, n, 8)) for n in (32, 16, 8, 4)]
    uv = rng.uniform(-2, 2, size=(500, 2))
    lod = rng.uniform(-0.5, 4.0, size=500)
    levels = np.stack([np.asarray(_hatching.sample_level(t, uv)) for t in tam])
    c = np.clip(lod, 0, 3)
    l0 = np.floor(c).astype(int)
    l1 = np.minimum(l0 + 1, 3)
    f = (c - l0)[:, None]
    i = np.arange(500)
    ref = levels[l0, i] * (1 - f) + levels[l1, i] * f
    np.testing.assert_allclose(np.asarray(_hatching.sample_tam(tam, uv, lod)), ref, rtol=1e-12, atol=1e-12)
