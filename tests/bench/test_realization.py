"""Minimal realisations, Padé delays and exact zero-order-hold sampling with delays."""

from __future__ import annotations

import control as ct
import numpy as np
import pytest
from scipy import linalg

from fsmbench.bench.blocks import PlantModel, ss_response
from fsmbench.bench.realization import (
    minimal_realization,
    pade_delays,
    plant_model,
    select,
    zoh_with_delays,
)

F_HZ = np.geomspace(0.01, 4999.0, 600)


def _hinf_relative(h: np.ndarray, ref: np.ndarray) -> float:
    """``max_f |H - Href| / max_f |Href|`` per channel, worst channel (zero channels skipped)."""
    peak = np.max(np.abs(ref), axis=0)
    err = np.max(np.abs(h - ref), axis=0)
    live = peak > 0
    assert np.all(err[~live] == 0)
    return float(np.max(err[live] / peak[live]))


def _random_stable(rng: np.random.Generator, n: int, m: int, p: int) -> ct.StateSpace:
    """A random stable system with lightly damped modes spread over decades."""
    blocks = []
    for _ in range(n // 2):
        w = 2 * np.pi * 10 ** rng.uniform(0, 3.5)
        z = 10 ** rng.uniform(-3, -0.5)
        blocks.append(np.array([[0.0, w], [-w, -2 * z * w]]))
    if n % 2:
        blocks.append(np.array([[-2 * np.pi * 10 ** rng.uniform(0, 4)]]))
    a = linalg.block_diag(*blocks)
    return ct.ss(a, rng.standard_normal((n, m)), rng.standard_normal((p, n)), np.zeros((p, m)))


def test_minimal_realization_removes_hidden_states_and_keeps_the_response() -> None:
    rng = np.random.default_rng(3)
    for _ in range(20):
        g1, g2 = _random_stable(rng, 4, 1, 1), _random_stable(rng, 5, 1, 1)
        # Parallel copies driven by one input, seen by one output: g2's states are
        # unobservable, g1 is duplicated (a copy is redundant).
        a = linalg.block_diag(g1.A, g1.A, g2.A)
        b = np.vstack([g1.B, g1.B, g2.B])
        c = np.hstack([g1.C, g1.C, np.zeros_like(g2.C)])
        big = ct.ss(a, b, c, np.zeros((1, 1)), inputs=["u"], outputs=["y"])
        # A random orthogonal change of coordinates hides the structure.
        q, _ = np.linalg.qr(rng.standard_normal((13, 13)))
        big = ct.ss(q.T @ a @ q, q.T @ b, c @ q, big.D, inputs=["u"], outputs=["y"])
        small = minimal_realization(big)
        assert small.nstates == 4
        assert list(small.input_labels) == ["u"] and list(small.output_labels) == ["y"]
        s = 2j * np.pi * F_HZ
        assert _hinf_relative(ss_response(small, s), ss_response(big, s)) < 1e-9


def _pade_value(tau: float, s: np.ndarray) -> np.ndarray:
    num, den = ct.pade(tau, 6)
    return np.polyval(num, s) / np.polyval(den, s)


def test_pade_delays_match_control_pade() -> None:
    g = ct.ss([[-100.0]], [[100.0, 50.0]], [[1.0]], [[0.0, 0.0]], inputs=["a", "b"],
              outputs=["y"])
    tau = {"a": 1.5e-4, "b": 5e-4}
    model = pade_delays(g, tau, order=6)
    s = 2j * np.pi * F_HZ
    ref = ss_response(g, s) * np.stack([_pade_value(tau[n], s) for n in "ab"], axis=-1)[:, None]
    assert _hinf_relative(ss_response(model, s), ref) < 1e-10
    assert model.nstates == 1 + 2 * 6


def test_zoh_with_whole_sample_delays_is_z_to_the_minus_n() -> None:
    g = _random_stable(np.random.default_rng(1), 5, 2, 2)
    g = ct.ss(g.A, g.B, g.C, g.D, inputs=["a", "b"], outputs=["x", "y"])
    dt = 1e-4
    model = zoh_with_delays(g, {"a": 2 * dt, "b": 0.0}, dt=dt)
    nyquist_hz = 0.5 / dt
    f = F_HZ
    z = np.exp(2j * np.pi * f[f < nyquist_hz] * dt)
    ref = ss_response(ct.sample_system(g, dt, method="zoh"), z)
    ref[:, :, 0] *= z[:, None] ** -2
    assert _hinf_relative(ss_response(model, z), ref) < 1e-12
    assert model.nstates == 5 + 2


def test_zoh_with_fractional_delays_is_exact_at_the_samples() -> None:
    """A fractional delay sampled at dt equals the same plant sampled ten times faster with
    the delay in whole fine samples and each coarse sample held for ten fine ones."""
    g = _random_stable(np.random.default_rng(2), 6, 2, 2)
    dt, fine = 1e-4, 10
    tau = {g.input_labels[0]: 1.3 * dt, g.input_labels[1]: 0.4 * dt}
    coarse = zoh_with_delays(g, tau, dt=dt)
    dense = zoh_with_delays(g, tau, dt=dt / fine)
    u = np.random.default_rng(0).standard_normal((2, 80))
    y = ct.forced_response(coarse, U=u).outputs
    y_dense = ct.forced_response(dense, U=np.repeat(u, fine, axis=1)).outputs[:, ::fine]
    assert np.max(np.abs(y - y_dense)) < 1e-12 * np.max(np.abs(y_dense))


def test_plant_model_options(true_plant: PlantModel) -> None:
    sub = true_plant.subsystem(outputs=["Rh"], inputs=["Uch"])
    with pytest.raises(ValueError, match="sample time"):
        plant_model(sub, true_plant.input_delay_s, delays="exact")
    with pytest.raises(ValueError, match="continuous"):
        plant_model(sub, true_plant.input_delay_s, delays="pade", dt=1e-4)
    with pytest.raises(ValueError, match="half sample"):
        plant_model(sub, {"Uch": 1e-5}, delays="exact", dt=1e-4)
    with pytest.raises(KeyError, match="no output named 'Rx'"):
        select(sub, outputs=["Rx"])
    # The hold's half sample is the sampling's own: 1.5 samples of delay are z^-1.
    exact = plant_model(sub, true_plant.input_delay_s, delays="exact", dt=1e-4,
                        minimal=False)
    none = plant_model(sub, {}, delays="none", dt=1e-4, minimal=False)
    assert exact.nstates == none.nstates + 1
