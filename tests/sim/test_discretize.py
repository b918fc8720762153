"""Zero-order hold with fractional delays against independent references."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.signal as sig

from fsmbench.sim.discretize import zoh_with_delays

A = np.array([[0.0, 2 * np.pi * 300], [-2 * np.pi * 300, -2 * 0.05 * 2 * np.pi * 300]])
B = np.array([[0.0], [2 * np.pi * 300]])
C = np.array([[1.0, 0.0]])
TS = 1e-4


def test_no_delay_is_scipy_zoh() -> None:
    d = zoh_with_delays(A, B, C, ts_s=TS, input_delay_samples=[0.0], input_names=["u"],
                        output_names=["y"])
    ad, bd, *_ = sig.cont2discrete((A, B, C, np.zeros((1, 1))), TS, method="zoh")
    np.testing.assert_allclose(d.a, ad, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(d.b, bd, rtol=1e-12, atol=1e-15)


@pytest.mark.parametrize("delay", [1.0, 3.0, 0.35, 3.5, 2.25])
def test_delayed_zoh_matches_fine_grid_simulation(delay: float) -> None:
    """A 100x finer exact-ZOH simulation with the input shifted by the delay (on its grid)."""
    d = zoh_with_delays(A, B, C, ts_s=TS, input_delay_samples=[delay], input_names=["u"],
                        output_names=["y"])
    rng = np.random.default_rng(3)
    n, fine = 400, 100
    u = rng.standard_normal(n)
    _, y, _ = sig.dlsim((d.a, d.b, d.c, np.zeros((1, 1)), TS), u)
    # Reference: continuous plant on a grid T/100, input held per coarse sample then delayed.
    u_fine = np.repeat(u, fine)
    shift = round(delay * fine)
    u_fine = np.concatenate([np.zeros(shift), u_fine])[: n * fine]
    ad, bd, *_ = sig.cont2discrete((A, B, C, np.zeros((1, 1))), TS / fine, method="zoh")
    _, y_fine, _ = sig.dlsim((ad, bd, C, np.zeros((1, 1)), TS / fine), u_fine)
    ref = y_fine[::fine, 0]
    # Both are exact for these piecewise-constant inputs; differences are rounding
    # accumulated over 40 000 fine steps of a lightly damped mode.
    np.testing.assert_allclose(y[:, 0], ref, atol=1e-10 * np.max(np.abs(ref)))


def test_frequency_response_shows_delay_and_hold() -> None:
    """Below Nyquist the discrete response is G(jw) e^{-jw(d + 1/2)T} sinc(fT) to O((wT)^2)."""
    d = zoh_with_delays(A, B, C, ts_s=TS, input_delay_samples=[2.0], input_names=["u"],
                        output_names=["y"])
    f = np.array([5.0, 50.0, 200.0])
    h = d.frequency_response(f)[:, 0, 0]
    s = 2j * np.pi * f
    g = np.array([(C @ np.linalg.solve(si * np.eye(2) - A, B))[0, 0] for si in s])
    expected = g * np.exp(-s * 2.5 * TS) * np.sinc(f * TS)
    # The hold-as-delay picture is exact only to second order in w T (0.13 at 200 Hz).
    np.testing.assert_allclose(h, expected, rtol=(2 * np.pi * 200 * TS) ** 2)


def test_bad_delays() -> None:
    with pytest.raises(ValueError, match=">= 0"):
        zoh_with_delays(A, B, C, ts_s=TS, input_delay_samples=[-1.0], input_names=["u"],
                        output_names=["y"])
    with pytest.raises(ValueError, match="1 inputs"):
        zoh_with_delays(A, B, C, ts_s=TS, input_delay_samples=[1.0, 2.0], input_names=["u"],
                        output_names=["y"])
