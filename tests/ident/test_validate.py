"""Time-domain validation: VAF and the held-input simulation."""

from __future__ import annotations

import control as ct
import numpy as np
import pytest

from fsmbench.ident.validate import simulate_fit, variance_accounted_for


def test_vaf_properties() -> None:
    rng = np.random.default_rng(0)
    y = rng.standard_normal(10000)
    assert variance_accounted_for(y, y) == 1.0
    assert variance_accounted_for(y, np.zeros_like(y)) == pytest.approx(0.0)
    assert variance_accounted_for(y, y + 3.0) == pytest.approx(1.0)  # offsets do not count
    noise = 0.1 * rng.standard_normal(10000)
    assert variance_accounted_for(y, y + noise) == pytest.approx(0.99, abs=0.002)
    assert np.isnan(variance_accounted_for(np.ones(5), np.ones(5)))


@pytest.mark.parametrize("delay_samples", [0.5, 1.5, 4.5])
def test_held_simulation_matches_python_control(delay_samples: float) -> None:
    """ZOH discretisation of a lightly damped mode with a delay against control.c2d."""
    ts = 1e-4
    w0, xi = 2 * np.pi * 300.0, 0.01
    sys = ct.ss(ct.tf([w0**2], [1, 2 * xi * w0, w0**2]))
    rng = np.random.default_rng(1)
    u = rng.standard_normal((4000, 1))
    ours = simulate_fit(np.asarray(sys.A), np.asarray(sys.B), np.asarray(sys.C),
                        np.zeros((1, 1)), u=u, delay_s=delay_samples * ts, ts_s=ts)
    # Reference: exact ZOH of the delay-free system, delayed by whole samples.
    # The measured delay includes the hold's half sample: τ = 0.5 sample means none extra.
    k = int(delay_samples - 0.5)
    d = ct.c2d(sys, ts, method="zoh")
    shifted = np.zeros_like(u[:, 0])
    shifted[k:] = u[: u.shape[0] - k, 0]
    ref = ct.forced_response(d, U=shifted).outputs
    # Two exact discretisations of one system: rounding only.
    np.testing.assert_allclose(ours[:, 0], ref, atol=1e-10 * np.max(np.abs(ref)))
