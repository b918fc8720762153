"""Propagation through the loop (U = −K R) and the quadratic angle-to-distance law."""

from __future__ import annotations

import gc
import math

import control as ct
import numpy as np
import pytest
from scipy.signal import freqz, lfilter

from fsmbench.bench.blocks import physical_plant
from fsmbench.bench.esrf import esrf_decentralised_controller, tustin
from fsmbench.bench.params import default_bench
from fsmbench.budget import (
    NoiseInput,
    budget_grid,
    error_budget,
    esrf_welch,
    loop_response,
    propagate,
    propagation,
    quadratic_distance,
)
from fsmbench.budget.propagation import controller_response


@pytest.fixture(scope="module")
def nominal():
    return default_bench().nominal


@pytest.fixture(scope="module")
def plant(nominal):
    return physical_plant(nominal)


# ---------------------------------------------------------------- quadratic law
def test_white_single_axis_closed_form():
    fs, sigma, c = 1000.0, 3e-6, 0.03125
    f = budget_grid(fs_hz=fs, df_hz=0.5)
    p = np.zeros((f.size, 2, 2), dtype=complex)
    p[:, 0, 0] = 2 * sigma**2 / fs  # one-sided white, variance σ²
    q = quadratic_distance(f, p, coefficients=(c, c), fs_hz=fs)
    assert q.mean_m == pytest.approx(c * sigma**2, rel=1e-12)  # E[cθ²] = cσ²
    assert q.std_m == pytest.approx(math.sqrt(2) * c * sigma**2, rel=1e-12)  # √2·cσ²
    # θ² of white θ is white: one-sided 4c²σ⁴/fs (the lag-0 bin sits at df).
    # FFT convolution rounding: 1e-9.
    np.testing.assert_allclose(q.psd_m2_per_hz[1:-1], 4 * c**2 * sigma**4 / fs, rtol=1e-9)
    assert np.sum(q.psd_m2_per_hz) * 0.5 == pytest.approx(q.std_m**2, rel=1e-9)


@pytest.fixture(scope="module")
def monte_carlo():
    """Two correlated, coloured Gaussian angles: a 100 Hz resonance and a low pass."""
    fs, n = 1000.0, 1_000_000
    rng = np.random.default_rng(7)
    b1, a1 = [1e-6], [1.0, -2 * 0.97 * math.cos(2 * math.pi * 100 / fs), 0.97**2]
    b2, a2 = [2e-6], [1.0, -0.9]
    x1 = lfilter(b1, a1, rng.standard_normal(n))
    x2 = 0.6 * x1 + lfilter(b2, a2, rng.standard_normal(n))
    f = budget_grid(fs_hz=fs, df_hz=0.5)
    h1 = freqz(b1, a1, worN=f, fs=fs)[1]
    h2 = freqz(b2, a2, worN=f, fs=fs)[1]
    p11 = 2 / fs * np.abs(h1) ** 2
    p = np.zeros((f.size, 2, 2), dtype=complex)
    p[:, 0, 0], p[:, 1, 1] = p11, 0.36 * p11 + 2 / fs * np.abs(h2) ** 2
    p[:, 0, 1] = p[:, 1, 0] = 0.6 * p11
    c = (0.03, 0.05)
    y = c[0] * x1**2 + c[1] * x2**2
    return fs, f, p, c, y


def test_quadratic_propagation_against_monte_carlo(monte_carlo):
    fs, f, p, c, y = monte_carlo
    q = quadratic_distance(f, p, coefficients=c, fs_hz=fs)
    # 10⁶ samples, correlation time ~30 samples: mean and std known to ~0.5 %; allow 2 %.
    assert np.mean(y) == pytest.approx(q.mean_m, rel=0.02)
    assert np.std(y) == pytest.approx(q.std_m, rel=0.02)
    s = esrf_welch(y - y.mean(), fs_hz=fs)
    for lo, hi in ((2, 40), (40, 120), (150, 250), (300, 500)):
        sel_mc = (s.f_hz >= lo) & (s.f_hz < hi)
        sel = (f >= lo) & (f < hi)
        # ~2000 Welch averages × ≥ 40 bins per band: < 1 % scatter; allow 4 %.
        assert np.mean(s.values[sel_mc]) == pytest.approx(np.mean(q.psd_m2_per_hz[sel]),
                                                          rel=0.04), (lo, hi)


def test_a_linear_gain_would_be_wrong(monte_carlo):
    """The quadratic term's std is not (dL/dθ)·σ for any fixed gain: it scales as σ², not σ."""
    fs, f, p, c, _ = monte_carlo
    q1 = quadratic_distance(f, p, coefficients=c, fs_hz=fs)
    q4 = quadratic_distance(f, 4 * p, coefficients=c, fs_hz=fs)  # angle ×2
    assert q4.std_m == pytest.approx(4 * q1.std_m, rel=1e-12)  # exact scaling: rounding
    assert q4.mean_m == pytest.approx(4 * q1.mean_m, rel=1e-12)


# ---------------------------------------------------------------- the loop
def test_loop_matches_python_control_responses(nominal, plant):
    """S·G against (I + G K)⁻¹ G from python-control's own evaluation of the Padé plant and K.

    (A state-space ``ct.feedback`` of this plant is useless as a reference: its
    A matrix has a condition number ~1e44 — the 125 kHz coil pole next to K's
    double integrator — and its frequency response is off by O(1).)
    """
    k = esrf_decentralised_controller()
    f = np.array([1.0, 10.0, 30.0, 100.0])
    loop = loop_response(plant, params=nominal, f_hz=f, controller=k)
    to_r = loop.transfers("sercalo_dac")[0]
    g = plant.with_pade(order=8)
    g_ru = ct.ss(g.A, g.B[:, :2], g.C[4:6, :], g.D[4:6, :2])
    gg = np.stack([g_ru(2j * np.pi * fi) for fi in f])
    kk = np.stack([k(2j * np.pi * fi) for fi in f])
    ref = np.linalg.solve(np.eye(2) + gg @ kk, gg)
    # Padé (order 8) of a 0.15 ms delay is exact to < 1e-12 below 100 Hz.
    np.testing.assert_allclose(to_r, ref, rtol=1e-9, atol=1e-15)
    # The loop rejects at 1 Hz (crossover ~27 Hz). The sign (U = −K R) is checked end to end
    # against the twin's closed loop in test_twin.py.
    assert np.abs(loop.s[0, 0, 0]) < 1e-2


def test_a_loop_asked_again_reuses_its_responses_and_lets_them_go(nominal):
    """The budget asks for the same plant's and controller's responses on the same grid for
    each configuration: computed once per plant and controller (the same values as a fresh
    computation), read-only, and dropped with them."""
    plant = physical_plant(nominal, source="nominal")
    k = tustin(esrf_decentralised_controller(), ts_s=nominal.converter.ts_s)
    f = budget_grid(fs_hz=1e4, df_hz=25.0)
    first = loop_response(plant, params=nominal, f_hz=f, controller=k)
    again = loop_response(plant, params=nominal, f_hz=f, controller=k)
    assert again.g_ru.base is first.g_ru.base and again.k is first.k
    assert not first.k.flags.writeable and not first.g_ru.flags.writeable
    other_grid = loop_response(plant, params=nominal, f_hz=f[::2], controller=k)
    np.testing.assert_array_equal(other_grid.k, first.k[::2])  # a new grid, computed anew
    fresh_plant = physical_plant(nominal, source="nominal")  # equal, but another object
    fresh = loop_response(fresh_plant, params=nominal, f_hz=f,
                          controller=tustin(esrf_decentralised_controller(),
                                            ts_s=nominal.converter.ts_s))
    for name in ("g_ru", "g_rn", "k", "s", "si"):
        np.testing.assert_array_equal(getattr(fresh, name), getattr(first, name))
    held = len(propagation._KEPT)
    del fresh, fresh_plant
    gc.collect()
    assert len(propagation._KEPT) < held  # the other plant's and controller's are gone


def test_open_loop_transfers(nominal, plant):
    f = budget_grid(fs_hz=1e4, df_hz=50.0)
    loop = loop_response(plant, params=nominal, f_hz=f, controller=None, closed_loop=False)
    np.testing.assert_allclose(loop.s, np.broadcast_to(np.eye(2), loop.s.shape), atol=0)  # K=0
    sensor = loop.transfers("sensor")
    assert np.all(sensor[0] == 0) and np.all(sensor[1] == 0)  # noise on the 4QD moves nothing
    sigma = 3e-6
    src = NoiseInput("n", "newport_angle", np.full((f.size, 2), 2 * sigma**2 / 1e4), "", "")
    out = propagate(src, loop, params=nominal)
    # Open loop: the beam angle is 2θn; the band df..fs/2 of a white 2σ²/fs holds σ².
    # Both exact up to rounding (1e-12).
    np.testing.assert_allclose(out.angle_rms_rad, 2 * sigma, rtol=1e-12)
    # Piston: Newport spot offset × θn on each axis.
    assert out.perpendicular_rms_m == pytest.approx(
        nominal.geometry.newport_spot_offset_m * sigma * math.sqrt(2), rel=1e-12)


def test_propagation_scales_linearly_and_quadratically(nominal, plant):
    f = budget_grid(fs_hz=1e4, df_hz=1.0)
    loop = loop_response(plant, params=nominal, f_hz=f, controller=esrf_decentralised_controller())
    base = np.full((f.size, 2), 1e-12)
    a = propagate(NoiseInput("a", "sercalo_dac", base, "", ""), loop, params=nominal)
    b = propagate(NoiseInput("b", "sercalo_dac", 4 * base, "", ""), loop, params=nominal)
    # Linear in the input PSD, quadratic term in its square: exact up to rounding (1e-12).
    np.testing.assert_allclose(b.angle_rms_rad, 2 * np.asarray(a.angle_rms_rad), rtol=1e-12)
    assert b.perpendicular_rms_m == pytest.approx(2 * a.perpendicular_rms_m, rel=1e-12)
    assert b.quadratic.std_m == pytest.approx(4 * a.quadratic.std_m, rel=1e-12)


def test_discrete_controller_response():
    k = esrf_decentralised_controller()
    kd = tustin(k, ts_s=1e-4)
    f = np.array([10.0, 100.0])
    # Tustin warps frequency by tan(ωT/2)/(ωT/2): < 1e-3 below 100 Hz.
    np.testing.assert_allclose(controller_response(kd, f), controller_response(k, f), rtol=2e-3)


def test_budget_rows_add_up(nominal, plant):
    b = error_budget(nominal, plant=plant, controller=esrf_decentralised_controller(),
                     df_hz=1.0)
    # RSS by construction (the cross-term row closes it): rounding only.
    assert b.total_rms_m == pytest.approx(math.sqrt(sum(r.rms_m**2 for r in b.rows)), rel=1e-12)
    assert b.limiting == max(b.rows, key=lambda r: r.rms_m).name
    assert b.total_bias_m == pytest.approx(sum(r.bias_m for r in b.rows), rel=1e-9)  # means add


@pytest.mark.parametrize(("call", "match"), [
    (lambda n, p: loop_response(p, params=n, f_hz=np.array([0.0, 1.0]), controller=None),
     "> 0"),
    (lambda n, p: loop_response(p, params=n, f_hz=np.array([1.0]), controller=None),
     "needs a controller"),
    (lambda n, p: budget_grid(fs_hz=1e4, df_hz=0.3), "must divide"),
    (lambda n, p: quadratic_distance(np.array([1.0, 2.0, 4.0]), np.zeros((3, 2, 2)),
                                     coefficients=(1.0, 1.0), fs_hz=8.0), "uniform grid"),
])
def test_bad_input(nominal, plant, call, match):
    with pytest.raises(ValueError, match=match):
        call(nominal, plant)


def test_bad_source(nominal, plant):
    f = budget_grid(fs_hz=1e4, df_hz=500.0)
    loop = loop_response(plant, params=nominal, f_hz=f, controller=None, closed_loop=False)
    with pytest.raises(ValueError, match="shape"):
        propagate(NoiseInput("x", "sensor", np.ones((3, 2)), "", ""), loop, params=nominal)
    with pytest.raises(ValueError, match="unknown source kind"):
        propagate(NoiseInput("x", "thermal", np.ones((f.size, 2)), "", ""), loop,
                  params=nominal)
