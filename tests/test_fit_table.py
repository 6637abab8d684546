"""Pigments from measurement tables: the CSV format, the fitting core, and real measured watercolours (NTU)."""

import math

import hypothesis.strategies as st
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import ROOT
from hypothesis import given

from diffwash import DiffwashError, colorimetry, km, pigments
from diffwash.fit import PLAIN, FitModel, fit_table, read_ntu_wpsm, read_table
from diffwash.fit._kmfit import effective, ground_pair_start, log_sd, residuals, Rows
from diffwash.fit._kmfit import delta_e_displayed
from diffwash.fit.tables._table import CLIP_LO


NTU = ROOT / "data" / "ntu-wpsm" / "primaries-P1-P7.csv"  # shipped with the repository (data/ntu-wpsm/README.md)


# --- the CIEDE2000 residuals the fits use -------------------------------------------------------------------


@given(
    st.tuples(st.floats(0, 100), st.floats(-100, 100), st.floats(-100, 100)),
    st.tuples(st.floats(0, 100), st.floats(-100, 100), st.floats(-100, 100)),
)
def test_delta_e_residuals_square_to_ciede2000(lab1, lab2):
    r = colorimetry.delta_e_2000_residuals(jnp.asarray(lab1), jnp.asarray(lab2))
    de = colorimetry.delta_e_2000(jnp.asarray(lab1), jnp.asarray(lab2))
    assert float(jnp.sum(r * r)) == pytest.approx(float(de) ** 2, rel=1e-9, abs=1e-9)


@pytest.mark.parametrize("textiles", [False, True])
def test_cie94_residuals_match_colour_science(textiles):
    import colour

    rng = np.random.default_rng(7)
    a = np.c_[rng.uniform(0, 100, 2000), rng.uniform(-100, 100, (2000, 2))]
    for b in (a + rng.normal(0, 4, a.shape), np.c_[rng.uniform(0, 100, 2000), rng.uniform(-100, 100, (2000, 2))]):
        r = np.asarray(colorimetry.delta_e_1994_residuals(a, b, textiles=textiles))
        want = colour.delta_E(a, b, method="CIE 1994", textiles=textiles)
        np.testing.assert_allclose(np.sqrt(np.sum(r * r, axis=-1)), want, rtol=1e-10, atol=1e-10)
    lab = jnp.asarray([50.0, 20.0, -10.0])
    J = jax.jacfwd(lambda x: colorimetry.delta_e_1994_residuals(lab, x))(lab)
    assert np.all(np.isfinite(J)) and np.linalg.matrix_rank(np.asarray(J)) == 3


def test_delta_e_residuals_are_smooth_where_colours_meet():
    # At equal colours CIEDE2000 itself has a kink (a square root); its residuals have a finite, non-zero Jacobian.
    lab = jnp.asarray([50.0, 20.0, -10.0])
    J = jax.jacfwd(lambda x: colorimetry.delta_e_2000_residuals(x, lab))(lab)
    assert np.all(np.isfinite(J)) and np.linalg.matrix_rank(np.asarray(J)) == 3


# --- the fitting core ----------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", ["Quinacridone Rose", "Indian Red", "Cadmium Yellow", "Interference Lilac"])
def test_curtis_inversion_over_real_grounds(name):
    # Over paper (not white) and a black ink (not black), two grounds still give K and S exactly.
    p = pigments.load(name)
    paper, ink = np.array([0.92, 0.9, 0.84]), np.array([0.035, 0.035, 0.04])
    R, T = km.layer(p.K, p.S, 2.0)
    K, S = ground_pair_start(np.asarray(km.over(R, T, paper)), paper, np.asarray(km.over(R, T, ink)), ink, 2.0)
    np.testing.assert_allclose(K, p.K, rtol=1e-6)
    np.testing.assert_allclose(S, p.S, rtol=1e-6)


def test_clipped_channel_is_a_bound():
    obs = jnp.asarray([[0.3, 0.2, CLIP_LO]])
    lo = jnp.asarray([[False, False, True]])
    hi = jnp.zeros((1, 3), bool)
    # Below the bound: counts as equal. Above: the excess counts.
    below = effective(jnp.asarray([[0.3, 0.2, 1e-6]]), obs, lo, hi)
    above = effective(jnp.asarray([[0.3, 0.2, 0.1]]), obs, lo, hi)
    np.testing.assert_allclose(below, obs)
    assert float(above[0, 2]) == pytest.approx(0.1)
    model = FitModel(thickness="linear", prior=0.0)
    rows = Rows(amount=jnp.ones(1), ground=jnp.full((1, 3), 0.9), rgb=obs, lo=lo, hi=hi, weight=jnp.ones(1))
    # A pigment so absorbing in blue that the prediction is far below the bound: no residual from blue.
    theta = {"log_K": jnp.log(jnp.asarray([0.5, 0.8, 5000.0])), "log_S": jnp.log(jnp.asarray([0.2, 0.2, 0.01]))}
    # While the prediction stays below the bound, blue's K does not matter; as a value it would.
    jac = jax.jit(lambda th, rw: jax.jacfwd(residuals)(th, (model, rw))["log_K"])
    J = jac(theta, rows)
    assert np.all(J[:, 2] == 0) and np.any(J[:, :2] != 0)
    as_value = Rows(rows.amount, rows.ground, obs.at[0, 2].set(1e-6), jnp.zeros_like(lo), hi, rows.weight)
    assert np.any(jac(theta, as_value)[:, 2] != 0)


def test_log_sd_flags_what_the_data_cannot_tell():
    J = np.array([[1.0, 0.0, 1.0], [0.0, 2.0, 0.0]])  # the first and third parameters only enter as a sum
    sd = log_sd(J, {"a": 1, "b": 1, "c": 1}, 0.0)
    assert np.isinf(sd["a"][0]) and np.isinf(sd["c"][0])
    assert sd["b"][0] == pytest.approx(0.5)


# --- the CSV format --------------------------------------------------------------------------------------------


def write(tmp_path, text, name="m.csv"):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_read_table_scales_grounds_and_clips(tmp_path):
    t = read_table(write(tmp_path, "pigment,amount,ground,r,g,b\npaper,0,paper,240,240,235\nblack,0,black,20,20,22\n"
                                   "Cobalt Blue,0.01,paper,0,124,198\nCobalt Blue,0.01,black,18,40,70\n"))  # fmt: skip
    assert t.names == ["Cobalt Blue"] and len(t) == 2
    np.testing.assert_allclose(t.paper, colorimetry.srgb_decode(np.array([240, 240, 235]) / 255))
    np.testing.assert_allclose(t.black, colorimetry.srgb_decode(np.array([20, 20, 22]) / 255))
    assert t.lo.tolist() == [[True, False, False], [False, False, False]] and not t.hi.any()
    # 0-1 floats: the same table.
    f = read_table(write(tmp_path, "pigment,amount,ground,r,g,b\npaper,0,paper,0.941,0.941,0.922\n"
                                   "x,1,paper,0.5,0.25,1.0\n", "f.csv"))  # fmt: skip
    np.testing.assert_allclose(f.rgb[0], colorimetry.srgb_decode(np.array([0.5, 0.25, 1.0])))
    assert f.hi.tolist() == [[False, False, True]]
    # Linear values are taken as they are; extra columns and column order do not matter.
    lin = read_table(write(tmp_path, "note,b,g,r,ground,amount,pigment\n,0.8,0.8,0.8,paper,0,paper\n"
                                     "hi,0.1,0.2,0.3,paper,2,y\n", "l.csv"), linear=True)  # fmt: skip
    np.testing.assert_allclose(lin.rgb[0], [0.3, 0.2, 0.1])
    np.testing.assert_allclose(lin.paper, [0.8, 0.8, 0.8])


@pytest.mark.parametrize(
    "text, where, what",
    [
        ("pigment,amount,r,g\npaper,0,1,1\n", None, "missing columns 'ground', 'b'"),
        ("pigment,amount,ground,r,g,b\npaper,0,paper,240,240,235\nx,1,white,1,2,3\n", "line 3: ground", "unknown ground 'white'"),
        ("pigment,amount,ground,r,g,b\npaper,0,paper,240,240,235\nx,1,paper,nan,2,3\n", "line 3: r", "finite"),
        ("pigment,amount,ground,r,g,b\npaper,0,paper,240,240,235\nx,-1,paper,1,2,3\n", "line 3: amount", ">= 0"),
        ("pigment,amount,ground,r,g,b\nx,1,paper,1,2,3\n", "line 2: ground", "no 'paper' row"),
        ("pigment,amount,ground,r,g,b\npaper,0,paper,240,240,235\nx,1,black,1,2,3\n", "line 3: ground", "no 'black' row"),
        ("pigment,amount,ground,r,g,b\npaper,0,paper,255,240,235\nx,1,paper,1,2,3\n", "line 2", "clipped"),
        ("pigment,amount,ground,r,g,b\npaper,0,paper,240,240,235\nx,1,paper,1,2,300\n", "line 3: b", "0-255"),
        ("pigment,amount,ground,r,g,b\npaper,0,paper,240,240,235\nx,1,paper,1,two,3\n", "line 3: g", "not a number"),
    ],
)
def test_read_table_errors_name_file_line_and_column(tmp_path, text, where, what):
    path = write(tmp_path, text)
    with pytest.raises(DiffwashError) as e:
        read_table(path)
    assert e.value.file == str(path) and e.value.field == where
    assert what in str(e.value)
    assert "\n" not in str(e.value)


# --- fitting tables --------------------------------------------------------------------------------------------


def synthetic_table(tmp_path, names, amounts, grounds=("paper", "black")):
    paper, ink = np.array([0.92, 0.9, 0.84]), np.array([0.035, 0.035, 0.04])
    lines = ["pigment,amount,ground,r,g,b", "paper,0,paper," + ",".join(f"{v:.9f}" for v in paper),
             "black,0,black," + ",".join(f"{v:.9f}" for v in ink)]  # fmt: skip
    for n in names:
        p = pigments.load(n)
        for a in amounts:
            for g, Rg in (("paper", paper), ("black", ink)):
                if g in grounds:
                    R, T = km.layer(p.K, p.S, a)
                    c = np.asarray(km.over(R, T, Rg))
                    lines.append(f"{n},{a},{g}," + ",".join(f"{v:.12f}" for v in c))
    return write(tmp_path, "\n".join(lines) + "\n")


@pytest.mark.parametrize("batch", ["vmap", "loop"])
def test_fit_table_recovers_every_pigment_at_once(tmp_path, batch):
    names = ["Quinacridone Rose", "Cadmium Yellow", "French Ultramarine", "Indian Red"]
    path = synthetic_table(tmp_path, names, (0.5, 1, 2, 4))
    fit = fit_table(path, linear=True, batch=batch)
    assert fit.names == names and all(fit.converged)
    for p, n, g in zip(fit.pigments, names, fit.gamma):
        truth = pigments.load(n)
        # Within 1% (the weak prior nudges the least determined coefficients, e.g. Cadmium Yellow's tiny blue S).
        np.testing.assert_allclose(p.K, truth.K, rtol=1e-2, err_msg=n)
        np.testing.assert_allclose(p.S, truth.S, rtol=1e-2, err_msg=n)
        assert g == pytest.approx(1, abs=1e-3)
    assert max(float(np.max(d)) for d in fit.delta_e) < 0.02
    # Fitting one pigment alone gives the same as fitting it in the batch.
    alone = fit_table(read_table(path, linear=True).select(read_table(path, linear=True).pigment == names[1]))
    np.testing.assert_allclose(alone.pigments[0].K, fit.pigments[1].K, rtol=1e-5)


def test_vmapped_and_looped_batches_agree(tmp_path):
    """`batch` changes how the pigments' independent problems run, not their answers."""
    path = synthetic_table(tmp_path, ["Burnt Umber", "Hansa Yellow", "Cerulean Blue"], (0.5, 1, 3))
    table = read_table(path, linear=True)
    fits = {b: fit_table(table, batch=b) for b in ("vmap", "loop", "auto")}
    for b in ("loop", "auto"):
        for p, q in zip(fits[b].pigments, fits["vmap"].pigments):
            np.testing.assert_allclose(p.K, q.K, rtol=1e-7, err_msg=b)
            np.testing.assert_allclose(p.S, q.S, rtol=1e-7, err_msg=b)
        assert all(fits[b].converged)
    with pytest.raises(DiffwashError, match="batch"):
        fit_table(table, batch="threads")


def test_fitted_library_loads_and_predicts(tmp_path):
    path = synthetic_table(tmp_path, ["Hookers Green"], (1, 2, 3))
    fit = fit_table(path, linear=True, model=FitModel(thickness="linear"))
    out = tmp_path / "lib.json"
    fit.save(out)
    lib = pigments.library(out)
    np.testing.assert_allclose(lib["Hookers Green"].K, pigments.load("Hookers Green").K, rtol=2e-3)
    R, T = km.layer(lib["Hookers Green"].K, lib["Hookers Green"].S, 5.0)
    np.testing.assert_allclose(fit.predict("hookers green", [5.0])[0], km.over(R, T, fit.paper), rtol=1e-9)


# --- real measured watercolours ----------------------------------------------------------------------------------


def ntu_split():
    """The fixed split: each paint's amounts in order, the 1st, 3rd, 5th... fit it, the 2nd, 4th... are predicted.

    Train: 0.01, 0.03, 0.05, 0.07, 0.09, 0.12 mL; held out: 0.02, 0.04, 0.06, 0.08, 0.10, 0.16 mL (the last one an
    extrapolation).
    """
    t = read_ntu_wpsm(NTU)
    rank = np.zeros(len(t), int)
    for n in t.names:
        ix = np.flatnonzero(t.pigment == n)
        rank[ix[np.argsort(t.amount[ix])]] = np.arange(len(ix))
    return t, t.select(rank % 2 == 0), t.select(rank % 2 == 1)


def test_ntu_held_out_amounts_within_1_8_ciede2000():
    table, train, test = ntu_split()
    assert len(table.names) == 7 and len(train) == len(test) == 42
    np.testing.assert_allclose(table.amount[:12], [0.01, 0.02, 0.03, 0.04, 0.05, 0.06, 0.07, 0.08, 0.09, 0.1, 0.12, 0.16])
    plain = fit_table(train, model=PLAIN).evaluate(test)
    model = fit_table(train)
    held = model.evaluate(test)
    print(f"\nNTU held-out mean CIEDE2000: plain LM {plain.mean():.3f}, diffwash model {held.mean():.3f}")
    for n in table.names:
        rows = test.pigment == n
        print(f"  {n:18s} plain {plain[rows].mean():.2f}  model {held[rows].mean():.2f}")
    assert held.mean() <= 1.8
    assert plain.mean() > held.mean() + 0.3  # the model's gain is real, not noise
    assert all(model.converged)
    assert np.all(model.gamma < 1.5) and np.all(model.gamma > 0.4)


def test_ntu_paper_colour_and_clipped_values():
    t = read_ntu_wpsm(NTU)
    np.testing.assert_allclose(t.paper, colorimetry.srgb_decode(np.array([240, 240, 235]) / 255))
    yellow = t.pigment == "Lemon Yellow"
    assert t.lo[yellow, 2].sum() == 10  # blue reads 0 from 0.03 mL on: a bound, not a value
    assert math.isclose(float(delta_e_displayed(t.rgb[:1], t.rgb[:1])[0]), 0.0, abs_tol=1e-9)
