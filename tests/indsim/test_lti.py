"""Exact sampling with fractional delays and the fast simulator, against independent references."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.signal import dlsim

from indsim.lti import DiscreteSS, delayed_inputs, sample_with_delay, simulate


def _continuous_reference(A, B, C, T, delay, u):
    """Samples of C x(kT) for the held input u delayed by ``delay``, by an ODE solver."""
    n_samp = len(u)

    def u_of(t):
        k = int(np.floor((t - delay) / T + 1e-12))
        return u[k] if 0 <= k < n_samp else 0.0

    x = np.zeros(A.shape[0])
    out = [C @ x]
    # Integrate piece by piece between the input's switching instants.
    edges = sorted({k * T for k in range(n_samp + 1)} | {k * T + delay for k in range(n_samp)})
    t = 0.0
    for e in edges[1:]:
        if e <= t:
            continue
        held = u_of(0.5 * (t + e))
        sol = solve_ivp(lambda _t, x, v=held: A @ x + B[:, 0] * v, (t, e), x,
                        rtol=1e-11, atol=1e-14, method="DOP853")
        x = sol.y[:, -1]
        t = e
        k = round(t / T)
        if abs(t - k * T) < 1e-12 and len(out) <= k:
            out.append(C @ x)
    return np.array(out[:n_samp])


@pytest.mark.parametrize("delay_samples", [0.0, 0.35, 1.0, 1.7, 4.5])
def test_fractional_delay_sampling_matches_direct_integration(delay_samples):
    """x[k+1] = Phi x + Gb u[k-n] + Ga u[k-n-1] against an ODE solver on the held, delayed input."""
    T = 1e-3
    w0, z = 2 * np.pi * 150.0, 0.05
    A = np.array([[0.0, 1.0], [-w0 * w0, -2 * z * w0]])
    B = np.array([[0.0], [w0 * w0]])
    C = np.array([1.0, 0.0])
    u = np.random.default_rng(0).standard_normal(40)
    delay = delay_samples * T
    Phi, Gb, Ga, n = sample_with_delay(A, B, T, np.array([delay]))
    W = delayed_inputs(u[:, None], n, np.array([Ga[:, 0].any()]))
    sys = DiscreteSS(Phi, np.hstack([Gb, Ga]), C[None, :], np.zeros((1, 2)), T)
    y = simulate(sys, W)[:, 0]
    ref = _continuous_reference(A, B, C, T, delay, u)
    # The ODE solver's tolerance (rtol 1e-11) bounds the reference's error.
    np.testing.assert_allclose(y, ref, rtol=0, atol=1e-8 * np.abs(ref).max())


def test_integrator_split_is_the_delay_fraction():
    """For 1/s the two held-input weights are exactly T - delta and delta."""
    T, delta = 1e-4, 0.37e-4
    Phi, Gb, Ga, n = sample_with_delay(np.zeros((1, 1)), np.ones((1, 1)), T,
                                       np.array([2 * T + delta]))
    assert n[0] == 2
    # Exact arithmetic of the formula; rounding only.
    assert Phi[0, 0] == 1.0
    assert Gb[0, 0] == pytest.approx(T - delta, rel=1e-12)
    assert Ga[0, 0] == pytest.approx(delta, rel=1e-12)


def test_fractional_delay_phase():
    """Behind the hold and a delay D = n T + delta, the sampled 1/s lags by w (D + T/2) at low f."""
    T = 1e-4
    f = np.array([1.0, 5.0, 20.0])
    z = np.exp(2j * np.pi * f * T)
    for D in (1.0 * T, 1.35 * T, 4.5 * T, 2.93 * T):
        Phi, Gb, Ga, n = sample_with_delay(np.zeros((1, 1)), np.ones((1, 1)), T, np.array([D]))
        H = (Gb[0, 0] * z ** -int(n[0]) + Ga[0, 0] * z ** (-int(n[0]) - 1)) / (z - Phi[0, 0])
        lag = -(np.angle(H) + np.pi / 2) / (2 * np.pi * f)
        # The hold's and the split's phases are linear in f up to O((wT)^2) = 2e-4 relative.
        np.testing.assert_allclose(lag, D + T / 2, rtol=2e-4)


def _random_system(rng, n, m, p, defective=False):
    A = rng.standard_normal((n, n))
    A *= 0.95 / np.abs(np.linalg.eigvals(A)).max()
    if defective:  # a Jordan block at 0.5 and another at ~0 (shift registers)
        A = np.zeros((n, n))
        A[0, 0] = A[1, 1] = 0.5
        A[0, 1] = 1.0
        for i in range(2, n - 1):
            A[i + 1, i] = 1.0
    return DiscreteSS(A, rng.standard_normal((n, m)), rng.standard_normal((p, n)),
                      rng.standard_normal((p, m)), 1.0)


@pytest.mark.parametrize("defective", [False, True])
def test_simulate_matches_scipy_dlsim(defective):
    """The lifted recursion against scipy.signal.dlsim (a plain state loop)."""
    rng = np.random.default_rng(1)
    sys = _random_system(rng, 7, 3, 4, defective)
    w = rng.standard_normal((3001, 3))
    _, ref, _ = dlsim((sys.A, sys.B, sys.C, sys.D, 1.0), w)
    for block in (None, 16, 1000):
        y = simulate(sys, w, block=block)
        # Same arithmetic as the recursion, summed in another order: rounding only.
        np.testing.assert_allclose(y, ref, rtol=0, atol=1e-11 * np.abs(ref).max())
