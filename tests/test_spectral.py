"""diffwash.spectral: reflectance on a band grid to XYZ, sRGB and CIELAB, held to colour-science."""

import warnings

import colour
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.test_util import check_grads

from diffwash import colorimetry, spectral
from diffwash._errors import DiffwashError

NTU = np.arange(380.0, 781.0, 10.0)
CMFS = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"]


def _colour_xyz(R, wl, illuminant="D65", cmfs=CMFS, **kwargs):
    ill = colour.SDS_ILLUMINANTS[illuminant]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # colour-science's shape-alignment notes
        return np.array([colour.sd_to_XYZ(colour.SpectralDistribution(r, wl), cmfs, ill, **kwargs) for r in R]) / 100


@pytest.mark.parametrize("illuminant", ["D65", "A", "FL2"])
def test_astm_e308_matrix_is_colour_sciences_sd_to_xyz(illuminant):
    R = np.random.default_rng(0).uniform(0, 1.05, (6, len(NTU)))
    obs = spectral.observation(NTU, illuminant=illuminant)
    assert obs.method == "ASTM E308"
    np.testing.assert_allclose(obs.xyz(R), _colour_xyz(R, NTU, illuminant), rtol=0, atol=1e-12)


def test_integration_matrix_aligns_the_cmfs_to_the_grid():
    wl = np.arange(400.0, 701.0, 5.0)
    R = np.random.default_rng(1).uniform(0, 1, (4, len(wl)))
    obs = spectral.observation(wl, method="Integration")
    shape = colour.SpectralShape(400, 700, 5)
    np.testing.assert_allclose(obs.xyz(R), _colour_xyz(R, wl, method="Integration", shape=shape), atol=1e-12)


def test_any_grid_and_observer_by_name():
    wl = np.array([405.0, 436, 480, 520, 546, 590, 633, 700])  # irregular: Integration
    obs = spectral.observation(wl, observer="CIE 1964 10 Degree Standard Observer")
    assert obs.method == "Integration" and obs.bands == ("405", "436", "480", "520", "546", "590", "633", "700")
    np.testing.assert_allclose(obs.xyz(np.ones(len(wl)))[1], 1.0, atol=1e-12)  # the perfect reflector: Y = 1
    # A flat grey is the white scaled, on any grid, and stays achromatic in CIELAB.
    lab = obs.lab(np.full(len(wl), 0.4))
    assert abs(float(lab[1])) < 1e-9 and abs(float(lab[2])) < 1e-9


def test_srgb_and_lab_follow_colour_science_with_cat02():
    R = np.random.default_rng(2).uniform(0, 1, (5, len(NTU)))
    obs = spectral.observation(NTU, illuminant="A")
    xyz = _colour_xyz(R, NTU, "A")
    white_xy = colour.XYZ_to_xy(np.asarray(obs.white))
    np.testing.assert_allclose(obs.srgb(R), colour.XYZ_to_sRGB(xyz, illuminant=white_xy), atol=1e-10)
    np.testing.assert_allclose(obs.lab(R), colour.XYZ_to_Lab(xyz, white_xy), atol=1e-9)
    # The perfect reflector is sRGB white under any illuminant (adapted), to the published matrices' rounding.
    np.testing.assert_allclose(obs.linear_srgb(np.ones(len(NTU))), np.ones(3), atol=3e-4)


def test_rgb_grid_is_the_identity_observation():
    obs = spectral.observation()
    rgb = np.random.default_rng(3).uniform(0, 1, (7, 3))
    assert not obs.spectral and obs.bands == ("r", "g", "b")
    np.testing.assert_array_equal(obs.linear_srgb(rgb), rgb)
    np.testing.assert_allclose(obs.lab(rgb), colorimetry.linear_srgb_to_lab(rgb), atol=1e-12)
    np.testing.assert_allclose(obs.xyz(rgb), colorimetry.linear_srgb_to_xyz(rgb), atol=1e-12)


def test_observation_is_a_pytree_through_jit_and_float32():
    obs = spectral.observation(NTU)
    f = jax.jit(lambda o, r: o.lab(r))
    R = np.full(len(NTU), 0.5, np.float32)
    out = f(obs, jnp.asarray(R))
    np.testing.assert_allclose(out, obs.lab(R.astype(np.float64)), atol=2e-3)


def test_gradients_match_finite_differences():
    obs = spectral.observation(NTU)
    R = jnp.asarray(np.random.default_rng(4).uniform(0.05, 0.9, len(NTU)))
    check_grads(lambda r: obs.lab(r), (R,), order=1, modes=["fwd", "rev"], atol=1e-6, rtol=1e-6)


@pytest.mark.parametrize(
    "grid, what",
    [([500.0], "at least two"), ([500.0, 500.0], "increase strictly"), ([400.0, float("nan")], "finite"),
     ([-5.0, 400.0], "> 0"), ([100.0, 150.0, 200.0], "cannot be seen"), ([450.0, 500.0, 550.0], "cannot be seen"),
     ([380.0, 700.0, 1000.0], "cannot be seen")],
)  # fmt: skip
def test_bad_grids_are_refused(grid, what):
    with pytest.raises(DiffwashError, match=what):
        spectral.observation(grid)


def test_unknown_names_and_methods_are_refused():
    with pytest.raises(DiffwashError, match="unknown illuminant"):
        spectral.observation(NTU, illuminant="D66")
    with pytest.raises(DiffwashError, match="unknown observer"):
        spectral.observation(NTU, observer="CIE 1931")
    with pytest.raises(DiffwashError, match="ASTM E308 needs"):
        spectral.observation([400.0, 433.0, 466.0], method="ASTM E308")


def test_resample_interpolates_inside_and_refuses_outside():
    v = np.stack([NTU / 100, np.ones(len(NTU))])
    out = spectral.resample(v, NTU, [385.0, 400.0, 777.5])
    np.testing.assert_allclose(out, [[3.85, 4.0, 7.775], [1, 1, 1]], atol=1e-12)
    with pytest.raises(DiffwashError, match="leaves the 380-780 nm"):
        spectral.resample(v, NTU, [370.0, 400.0])
