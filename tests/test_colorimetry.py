"""Colorimetry against colour-science, with finite gradients at the edges."""

import colour
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from diffwash import colorimetry as cm

TOL = 1e-6
D65 = colour.CCS_ILLUMINANTS["CIE 1931 2 Degree Standard Observer"]["D65"]


@pytest.fixture(scope="module")
def rgb():
    rng = np.random.default_rng(7)
    a = rng.uniform(0, 1, (2000, 3))
    edges = np.array([[0, 0, 0], [1, 1, 1], [0.0031308, 0.04045, 0.5], [1e-9, 0.5, 1], [0.2, 0.2, 0.2]])
    return np.concatenate([a, edges])


def test_srgb_transfer_matches_colour(rgb):
    np.testing.assert_allclose(cm.srgb_encode(rgb), colour.cctf_encoding(rgb, function="sRGB"), atol=TOL, rtol=0)
    np.testing.assert_allclose(cm.srgb_decode(rgb), colour.cctf_decoding(rgb, function="sRGB"), atol=TOL, rtol=0)
    np.testing.assert_allclose(cm.srgb_decode(cm.srgb_encode(rgb)), rgb, atol=1e-12)


def test_xyz_matches_colour(rgb):
    np.testing.assert_allclose(cm.linear_srgb_to_xyz(rgb), colour.RGB_to_XYZ(rgb, "sRGB"), atol=TOL, rtol=0)
    xyz = colour.RGB_to_XYZ(rgb, "sRGB")
    np.testing.assert_allclose(cm.xyz_to_linear_srgb(xyz), colour.XYZ_to_RGB(xyz, "sRGB"), atol=TOL, rtol=0)


def test_lab_matches_colour(rgb):
    xyz = colour.RGB_to_XYZ(rgb, "sRGB")
    lab = colour.XYZ_to_Lab(xyz, D65)
    np.testing.assert_allclose(cm.xyz_to_lab(xyz), lab, atol=TOL, rtol=0)
    np.testing.assert_allclose(cm.lab_to_xyz(lab), colour.Lab_to_XYZ(lab, D65), atol=TOL, rtol=0)
    np.testing.assert_allclose(cm.linear_srgb_to_lab(rgb), lab, atol=TOL, rtol=0)
    np.testing.assert_allclose(
        cm.srgb_to_lab(rgb), colour.XYZ_to_Lab(colour.sRGB_to_XYZ(rgb, apply_cctf_decoding=True), D65), atol=TOL
    )


def test_delta_e_2000_matches_colour(rgb):
    rng = np.random.default_rng(3)
    lab1 = colour.XYZ_to_Lab(colour.RGB_to_XYZ(rgb, "sRGB"), D65)
    lab2 = lab1 + rng.normal(0, 4, lab1.shape)
    # Hue wrap-around, achromatic and identical pairs (Sharma's special cases).
    specials1 = np.array([[50, 2.5, 0], [50, 0, 0], [50, 0, 0], [60, -3, -0.1], [40, 10, 10], [50, 2, -0.01]])
    specials2 = np.array([[50, 0, -2.5], [50, 0, 0], [52, 0, 0], [60, -3, 0.1], [40, 10, 10], [50, -2, 0.01]])
    for a, b in [(lab1, lab2), (specials1, specials2)]:
        for textiles in (False, True):
            np.testing.assert_allclose(
                cm.delta_e_2000(a, b, textiles=textiles),
                colour.delta_E(a, b, method="CIE 2000", textiles=textiles),
                atol=TOL,
                rtol=0,
            )


lab_st = st.tuples(st.floats(0, 100), st.floats(-120, 120), st.floats(-120, 120)).map(np.array)


@given(a=lab_st, b=lab_st)
def test_delta_e_2000_property_matches_colour(a, b):
    assert abs(float(cm.delta_e_2000(a, b)) - float(colour.delta_E(a, b, method="CIE 2000"))) <= TOL


@given(a=lab_st, b=lab_st)
def test_delta_e_2000_is_symmetric_and_zero_on_the_diagonal(a, b):
    np.testing.assert_allclose(cm.delta_e_2000(a, b), cm.delta_e_2000(b, a), atol=1e-9)
    assert float(cm.delta_e_2000(a, a)) == 0.0


@pytest.mark.parametrize(
    "fn",
    [cm.srgb_encode, cm.srgb_decode, cm.linear_srgb_to_lab, cm.srgb_to_lab, lambda x: cm.lab_to_xyz(x * 100)],
)
@pytest.mark.parametrize("point", [[0, 0, 0], [1, 1, 1], [0.0031308, 0.04045, 1e-12], [0.5, 0.5, 0.5]])
def test_gradients_are_finite_at_the_edges(fn, point):
    jac = jax.jacfwd(fn)(jnp.array(point, float))
    assert np.all(np.isfinite(jac))
    jac = jax.jacrev(fn)(jnp.array(point, float))
    assert np.all(np.isfinite(jac))


@pytest.mark.parametrize(
    "a, b",
    [([0, 0, 0], [0, 0, 0]), ([50, 0, 0], [50, 0, 0]), ([50, 1, 0], [50, 0, 0]), ([50, 0, 3], [50, 0, -3]), ([40, 5, 5], [40, 5, 5])],
)
def test_delta_e_gradients_are_finite(a, b):
    g1, g2 = jax.grad(lambda x, y: cm.delta_e_2000(x, y), argnums=(0, 1))(jnp.array(a, float), jnp.array(b, float))
    assert np.all(np.isfinite(g1)) and np.all(np.isfinite(g2))


_de_rgb = jax.jit(lambda x, y: cm.delta_e_2000(cm.linear_srgb_to_lab(x), cm.linear_srgb_to_lab(y)))
_de_rgb_grad = jax.jit(jax.grad(_de_rgb))


@settings(max_examples=60)
@given(
    a=arrays(np.float64, 3, elements=st.floats(0.05, 0.95)),
    d=arrays(np.float64, 3, elements=st.floats(-0.05, 0.05)),
)
def test_delta_e_of_rgb_gradients_match_finite_differences(a, d):
    """The gradient of CIEDE2000 between two sRGB colours, against central differences."""
    b = np.clip(a + d, 0.01, 0.99)
    # Away from where the gradient is undefined (the colours meet) or ill-conditioned
    # (hue near the achromatic axis, where it changes by 1/chroma).
    assume(float(_de_rgb(a, b)) > 1e-3 and np.hypot(*np.asarray(cm.linear_srgb_to_lab(a))[1:]) > 2)
    g = np.asarray(_de_rgb_grad(a, b))
    h = 1e-7
    fd = np.array([(_de_rgb(a + h * e, b) - _de_rgb(a - h * e, b)) / (2 * h) for e in np.eye(3)])
    np.testing.assert_allclose(g, fd, rtol=1e-4, atol=1e-5)


def test_broadcasting_and_float32():
    rgb = np.random.default_rng(0).uniform(0, 1, (4, 5, 3)).astype(np.float32)
    lab = cm.linear_srgb_to_lab(rgb)
    assert lab.shape == (4, 5, 3) and lab.dtype == np.float32
    d = cm.delta_e_2000(lab, lab[:1])
    assert d.shape == (4, 5)


def test_white_is_white():
    lab = cm.linear_srgb_to_lab(np.ones(3))
    np.testing.assert_allclose(lab, [100, 0, 0], atol=0.01)
