"""Margins and Nyquist counts with exact delays, against python-control and pole counts."""

from __future__ import annotations

import math

import control as ct
import numpy as np
import pytest

from fsmbench.control.freq import (
    evaluate_ss,
    frequency_grid,
    nyquist_count,
    plain_json,
    siso_margins,
)

S = ct.tf("s")

SIMPLE_LOOPS = {
    "third_order": 4.0 / ((S + 1) * (S + 2) * (S + 3)) * 6,
    "integrator_lag": 2.0 / (S * (S + 1) * (0.1 * S + 1)),
    "double_integrator_lead": 40.0 * (S + 2) / (S**2 * (S + 20)),
    "resonant": 2e4 / ((S + 10) * (S**2 + 2 * 0.05 * 100 * S + 100**2)),
    "resonant_unstable": 1.5e5 / ((S + 10) * (S**2 + 2 * 0.05 * 100 * S + 100**2)),
}


def _fn(tf: ct.TransferFunction):
    def loop(f: np.ndarray) -> np.ndarray:
        return np.array([complex(tf(2j * np.pi * x)) for x in np.atleast_1d(f)])
    return loop


@pytest.mark.parametrize("name", list(SIMPLE_LOOPS))
def test_margins_match_python_control(name: str) -> None:
    tf = SIMPLE_LOOPS[name]
    gm, pm, sm, wpc, wgc, _ = ct.stability_margins(tf)
    f = frequency_grid(tf.poles(), f_min_hz=1e-3, f_max_hz=1e3, per_decade=200)
    stable = bool(np.all(ct.feedback(tf, 1).poles().real < 0))
    m = siso_margins(_fn(tf), f, stable=stable)
    # Both refine crossings to solver precision; 1e-6 leaves room for brentq's xtol.
    if np.isfinite(pm):
        assert m.phase_margin_deg == pytest.approx(pm, rel=1e-6)
        # python-control names the crossover of the smallest margin; ours lists them all
        # and reports the first (the bandwidth) as crossover_hz.
        assert min(abs(2 * np.pi * x / wgc - 1) for x in m.crossovers_hz) < 1e-6
    else:  # |L| < 1 everywhere
        assert math.isinf(m.phase_margin_deg) and math.isnan(m.crossover_hz)
    assert m.modulus_margin == pytest.approx(sm, rel=1e-6)
    if np.isfinite(gm) and gm > 1:
        assert m.gain_margin_db == pytest.approx(20 * np.log10(gm), rel=1e-6)
        assert 2 * np.pi * m.phase_crossover_hz == pytest.approx(wpc, rel=1e-6)
    elif np.isfinite(gm):  # python-control's margin is a reduction: ours keeps it apart
        assert m.gain_reduction_margin_db == pytest.approx(-20 * np.log10(gm), rel=1e-6)
    else:
        assert math.isinf(m.gain_margin_db)


def test_modulus_margin_is_inverse_peak_sensitivity() -> None:
    tf = SIMPLE_LOOPS["resonant"]
    f = frequency_grid(tf.poles(), f_min_hz=1e-3, f_max_hz=1e3, per_decade=400)
    m = siso_margins(_fn(tf), f)
    peak = np.max(np.abs(1 / (1 + _fn(tf)(f))))
    # The refined minimum may only be deeper than the grid's; a 400/decade grid is within 1e-4.
    assert 1 / peak == pytest.approx(m.modulus_margin, rel=1e-4)
    assert m.modulus_margin <= 1 / peak + 1e-15


@pytest.mark.parametrize(("gain", "unstable"), [(5.0, 0), (7.9, 0), (8.1, 2), (20.0, 2)])
def test_nyquist_count_agrees_with_poles(gain: float, unstable: int) -> None:
    """k/(s+1)^3: critical gain 8, two poles cross together."""
    tf = gain / (S + 1) ** 3
    count = nyquist_count(lambda s: 1 + np.array([complex(tf(x)) for x in s]),
                          open_loop_poles=tf.poles())
    poles = ct.feedback(tf, 1).poles()
    assert count.closed_loop_unstable == int(np.sum(poles.real > 0)) == unstable


def test_nyquist_open_loop_unstable_plant() -> None:
    """k (s+2)/((s-1)(s+5)): P = 1, stabilised for k > 2.5."""
    for k, expected in ((1.0, 1), (10.0, 0)):
        tf = k * (S + 2) / ((S - 1) * (S + 5))
        count = nyquist_count(lambda s, tf=tf: 1 + np.array([complex(tf(x)) for x in s]),
                              open_loop_poles=tf.poles())
        assert count.open_loop_unstable == 1
        assert count.closed_loop_unstable == expected
        assert count.closed_loop_unstable == int(np.sum(ct.feedback(tf, 1).poles().real > 0))


@pytest.mark.parametrize(("gain", "stable"), [(0.5, True), (3.0, False)])
def test_nyquist_with_exact_delay_agrees_with_pade(gain: float, stable: bool) -> None:
    """k e^{-s} / (s (s+1)): delays exact in the count, Padé(12) for the poles."""
    def one_plus_l(s: np.ndarray) -> np.ndarray:
        return 1 + gain * np.exp(-s) / (s * (s + 1))
    count = nyquist_count(one_plus_l, open_loop_poles=np.array([0.0, -1.0]))
    num, den = ct.pade(1.0, 12)
    loop = gain * ct.tf(num, den) / (S * (S + 1))
    poles = ct.feedback(loop, 1).poles()
    assert count.stable is stable
    assert bool(np.max(poles.real) < 0) is stable


def test_evaluate_ss_and_grid() -> None:
    sys = ct.ss(ct.tf([1.0, 3.0], [1.0, 2.0, 100.0]))
    s = np.array([0.1 + 1j, 2j, -1 + 5j])
    ref = np.array([complex(sys(x)) for x in s])
    # One solve per point, two algorithms: rounding only.
    np.testing.assert_allclose(evaluate_ss(sys, s)[:, 0, 0], ref, rtol=1e-12)
    f = frequency_grid([complex(-0.01, 100.0)], f_min_hz=1.0, f_max_hz=100.0, per_decade=10)
    f0 = 100.0 / (2 * np.pi)
    assert np.sum(np.abs(f - f0) < 0.01 / (2 * np.pi)) >= 20  # dense within one half-bandwidth
    assert np.all(np.diff(f) > 0)


def test_plain_json() -> None:
    out = plain_json({"a": np.float64(np.nan), "b": (1, np.inf), "c": np.array([1.5]),
                      "d": np.bool_(True), "e": np.int64(3)})
    assert out == {"a": None, "b": [1, None], "c": [1.5], "d": True, "e": 3}
