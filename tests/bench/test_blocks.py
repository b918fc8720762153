"""Physics blocks and the assembled plant against closed-form derivations."""

from __future__ import annotations

import math

import control as ct
import numpy as np
import pytest
import scipy.linalg
from hypothesis import given, settings
from hypothesis import strategies as st

from fsmbench.bench.blocks import (
    PLANT_INPUTS,
    PLANT_OUTPUTS,
    PlantModel,
    current_amplifier,
    input_delays_s,
    mode_block,
    newport,
    physical_plant,
    sercalo,
    ss_frequency_response,
    ss_response,
    voltage_amplifier,
)
from fsmbench.bench.params import Bench

AXES = ("h", "v")


@pytest.mark.parametrize("which", ["nominal", "true"])
def test_signal_names_match_the_seed(bench: Bench, which: str) -> None:
    plant = physical_plant(getattr(bench, which))
    assert tuple(plant.sys.input_labels) == PLANT_INPUTS
    assert tuple(plant.sys.output_labels) == PLANT_OUTPUTS
    assert list(plant.blocks["Gi"].input_labels) == ["Uch", "Ucv"]
    assert list(plant.blocks["Gc"].output_labels) == ["Vpch", "Vpcv"]
    assert list(plant.blocks["Gn"].output_labels) == ["Vpnh", "Vpnv"]
    assert list(plant.blocks["Gd"].input_labels) == ["Rh", "Rv"]


@pytest.mark.parametrize("axis", AXES)
def test_block_dc_gains_from_physics(bench: Bench, axis: str) -> None:
    p = bench.true
    i = AXES.index(axis)
    r_tot = (p.current_amplifier.r_ohm[axis] + p.current_amplifier.r_buffer_ohm[axis]
             + p.sercalo.r_coil_ohm[axis])
    # Exact closed forms; only float rounding separates them.
    assert current_amplifier(p).dcgain()[i, i] == pytest.approx(1 / r_tot, rel=1e-12)
    assert voltage_amplifier(p).dcgain()[i, i] == pytest.approx(1000.0, rel=1e-12)
    # Gc(0) = Gd R(phi) B g0 T: with coupling and rotation of the true bench.
    c, s = math.cos(p.quad_diode.rotation_rad), math.sin(p.quad_diode.rotation_rad)
    rot = np.array([[c, s], [-s, c]])
    torque = np.array([[1.0, p.sercalo.coupling_v_to_h], [p.sercalo.coupling_h_to_v, 1.0]])
    g0 = np.diag(p.sercalo.dc_gain_rad_per_a.as_array())
    beam = np.diag(p.sercalo.beam_angle_per_mirror_angle.as_array())
    gd = np.diag(p.quad_diode.gain_v_per_rad.as_array())
    expected = gd @ rot @ beam @ g0 @ torque
    np.testing.assert_allclose(sercalo(p).dcgain(), expected, rtol=1e-12, atol=1e-14)
    expected_n = gd @ rot * 2.0 @ np.diag(p.newport.gain_rad_per_v.as_array())
    np.testing.assert_allclose(newport(p).dcgain(), expected_n, rtol=1e-12, atol=1e-14)


@pytest.mark.parametrize("axis", AXES)
def test_sercalo_poles_are_the_modes(bench: Bench, axis: str) -> None:
    s = bench.true.sercalo
    w0 = 2 * np.pi * s.resonance_hz[axis]
    xi = s.damping_ratio[axis]
    expected = w0 * (-xi + 1j * math.sqrt(1 - xi**2))
    poles = sercalo(bench.true).poles()
    # Eigenvalues of a 2x2 block: relative accuracy near machine precision.
    assert np.min(np.abs(poles - expected)) / w0 < 1e-12


def test_mode_block_is_well_conditioned() -> None:
    """Modal form: entries O(w0) and an eigenvector matrix of modest condition."""
    m = mode_block(freq_hz=411.5, damping_ratio=1e-3)
    assert np.max(np.abs(m.A)) <= 2 * np.pi * 411.5 * (1 + 1e-12)
    _, vecs = np.linalg.eig(m.A)
    assert np.linalg.cond(vecs) < 1.01  # nearly orthogonal eigenvectors for a light mode
    w0 = 2 * np.pi * 411.5
    companion = ct.tf2ss(ct.tf([1.0], [1 / w0**2, 2e-3 / w0, 1]))
    _, vecs_c = np.linalg.eig(companion.A)
    # The companion form's eigenvector condition grows like w0 (2585 rad/s here).
    assert np.linalg.cond(vecs_c) > 1e3 * np.linalg.cond(vecs)


def test_newport_meets_its_datasheet(bench: Bench) -> None:
    """Fig. 4: -3 dB at 600 Hz, 60 deg lag at 250 Hz (internal lag included), <= 3 dB peaking."""
    p = bench.nominal
    ds = bench.datasheet.newport
    gn = newport(p)
    f = np.array([ds.amplitude_bandwidth_hz, ds.phase_bandwidth_hz])
    h = ss_frequency_response(gn, f)[:, 0, 0] / gn.dcgain()[0, 0]
    mag_db = 20 * np.log10(np.abs(h[0]))
    lag_deg = -np.degrees(np.angle(h[1])) + 360 * ds.phase_bandwidth_hz * p.newport.internal_delay_s
    assert mag_db == pytest.approx(-3.0, abs=0.01)  # parameters rounded to 10 digits
    assert lag_deg == pytest.approx(ds.phase_bandwidth_lag_deg, abs=0.01)
    grid = np.linspace(1, 5000, 5000)
    peak = 20 * np.log10(np.max(np.abs(ss_frequency_response(gn, grid)[:, 0, 0]))
                         / abs(gn.dcgain()[0, 0]))
    assert peak <= ds.peaking_max_db


def test_full_system_is_the_seed_connect(true_plant: PlantModel) -> None:
    """Vph = Gc Gi Uc + Gn Un, R = Gd^-1 Vp, Vch = Ga Zc Gi Uc (ESRF study 2.5), at 4 points."""
    f = np.array([3.0, 100.0, 411.0, 900.0])
    b = true_plant.blocks
    gi, zc, ga = (ss_frequency_response(b[k], f) for k in ("Gi", "Zc", "Ga"))
    gc, gn = ss_frequency_response(b["Gc"], f), ss_frequency_response(b["Gn"], f)
    gd = np.asarray(b["Gd"].D)
    full = true_plant.frequency_response(f, with_delay=False)
    sel = full.sel(output=["Vph", "Vpv"], input=["Uch", "Ucv"]).values
    np.testing.assert_allclose(sel, gc @ gi, rtol=1e-10)
    sel = full.sel(output=["Vph", "Vpv"], input=["Unh", "Unv"]).values
    np.testing.assert_allclose(sel, gn, rtol=1e-10)
    sel = full.sel(output=["Rh", "Rv"], input=["Uch", "Ucv"]).values
    np.testing.assert_allclose(sel, np.linalg.inv(gd) @ gc @ gi, rtol=1e-10)
    sel = full.sel(output=["Vch", "Vcv"], input=["Uch", "Ucv"]).values
    np.testing.assert_allclose(sel, ga @ zc @ gi, rtol=1e-10)


def test_frequency_response_against_python_control(true_plant: PlantModel) -> None:
    f = np.logspace(0, 3.5, 40)
    ours = true_plant.frequency_response(f, with_delay=False).values
    theirs = ct.frequency_response(true_plant.sys, 2 * np.pi * f)
    ref = np.moveaxis(np.asarray(theirs.complex), -1, 0)
    scale = np.max(np.abs(ref), axis=0, keepdims=True) + 1e-300
    # Two independent solvers; the solve is ill-posed only right at the poles.
    assert np.max(np.abs(ours - ref) / scale) < 1e-9


def test_delays_are_pure_phase(bench: Bench, true_plant: PlantModel) -> None:
    delays = input_delays_s(bench.true)
    ts = bench.true.converter.ts_s
    assert delays["Uch"] == pytest.approx(1.5 * ts)  # 1 sample DAC + half-sample hold
    assert delays["Unh"] == pytest.approx(5e-4)  # seed 2.4
    f = np.array([50.0, 700.0])
    with_d = true_plant.frequency_response(f, outputs=["Vph"], inputs=["Unh"]).values[:, 0, 0]
    without = true_plant.frequency_response(f, outputs=["Vph"], inputs=["Unh"],
                                            with_delay=False).values[:, 0, 0]
    np.testing.assert_allclose(with_d / without, np.exp(-2j * np.pi * f * 5e-4), rtol=1e-12)


def test_pade_model_follows_the_delay(true_plant: PlantModel) -> None:
    sys = true_plant.with_pade(order=6)
    f = np.array([10.0, 200.0, 1000.0])
    exact = true_plant.frequency_response(f, outputs=["Vph"], inputs=["Unh"]).values[:, 0, 0]
    approx = ss_frequency_response(sys, f)[:, list(sys.output_labels).index("Vph"),
                                          list(sys.input_labels).index("Unh")]
    # A 6th-order Pade of a 0.5 ms delay is accurate to ~1e-6 below 1 kHz (w tau = 3.1).
    np.testing.assert_allclose(approx, exact, rtol=1e-5)


def test_seed_controller_sign_convention(true_plant: PlantModel) -> None:
    """The study's -K loop needs K(0) G(0) > 0: Kh < 0 needs Uch -> Rh < 0, Kv > 0 needs > 0."""
    assert true_plant.dc_gain(output="Rh", input="Uch") < 0
    assert true_plant.dc_gain(output="Rv", input="Ucv") > 0
    # R is the beam angle the Newport calibrates: positive for a positive Newport command.
    assert true_plant.dc_gain(output="Rh", input="Unh") > 0
    assert true_plant.dc_gain(output="Rv", input="Unv") > 0


def test_summary_is_json_ready(true_plant: PlantModel) -> None:
    import json

    text = json.dumps(true_plant.summary())
    assert "Uch->Vph" in text


# ---------------------------------------------------------------- frequency response paths


def _random_plant(seed: int, *, n_modes: int, n_real: int) -> ct.StateSpace:
    """A stable MIMO system of lightly damped modes (0.1 Hz–3 kHz) and real poles."""
    rng = np.random.default_rng(seed)
    blocks = []
    for _ in range(n_modes):
        w0 = 2 * np.pi * 10 ** rng.uniform(-1, 3.5)
        xi = 10 ** rng.uniform(-4, -0.5)
        blocks.append(np.array([[0.0, w0], [-w0, -2 * xi * w0]]))
    blocks += [np.array([[-2 * np.pi * 10 ** rng.uniform(-1, 4)]]) for _ in range(n_real)]
    a = scipy.linalg.block_diag(*blocks)
    n = a.shape[0]
    return ct.ss(a, rng.standard_normal((n, 2)), rng.standard_normal((3, n)),
                 rng.standard_normal((3, 2)))


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**31), n_modes=st.integers(1, 8), n_real=st.integers(0, 4))
def test_the_modal_sum_equals_the_direct_solve(seed: int, n_modes: int, n_real: int) -> None:
    """Every point of a long grid, not only the points the modal path checks itself on."""
    from fsmbench.bench.blocks import solve_response

    sys = _random_plant(seed, n_modes=n_modes, n_real=n_real)
    s = 2j * np.pi * np.geomspace(1e-3, 5e3, 2000)
    a, b, c, d = (np.asarray(x, dtype=float) for x in (sys.A, sys.B, sys.C, sys.D))
    exact = solve_response(a, b, c, d, s)
    h = ss_response(sys, s)
    # 1e-8: the modal path's own acceptance is 1e-10 at its probes; allow 100x between them,
    # relative to each element's value or 1e-6 of its peak (below that, nothing reads it).
    scale = np.maximum(np.abs(exact), 1e-6 * np.max(np.abs(exact), axis=0, keepdims=True))
    assert np.max(np.abs(h - exact) / scale) < 1e-8


def test_a_defective_system_falls_back_to_the_solve() -> None:
    """A Jordan block (a double integrator in a row) has no eigenvector basis."""
    a = np.array([[-1.0, 1.0, 0.0], [0.0, -1.0, 1.0], [0.0, 0.0, -1.0]])
    sys = ct.ss(a, np.array([[0.0], [0.0], [1.0]]), np.array([[1.0, 0.0, 0.0]]), 0.0)
    s = 2j * np.pi * np.geomspace(1e-3, 1e3, 500)
    # Closed form: 1 / (s + 1)^3.
    assert np.allclose(ss_response(sys, s)[:, 0, 0], 1 / (s + 1) ** 3, rtol=1e-12, atol=0)


@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 2**31), n_modes=st.integers(1, 6), n_real=st.integers(0, 3))
def test_an_evaluator_equals_the_direct_solve_point_by_point(seed: int, n_modes: int,
                                                            n_real: int) -> None:
    """Checked on 24 points, used on others: one at a time, as a root finder asks."""
    from fsmbench.bench.blocks import ResponseEvaluator, solve_response

    sys = _random_plant(seed, n_modes=n_modes, n_real=n_real)
    ev = ResponseEvaluator(sys, check_points=2j * np.pi * np.geomspace(1e-3, 1e4, 24))
    a, b, c, d = (np.asarray(x, dtype=float) for x in (sys.A, sys.B, sys.C, sys.D))
    rng = np.random.default_rng(seed)
    for f in 10 ** rng.uniform(-3, 4, 20):
        s = np.array([2j * np.pi * f])
        exact = solve_response(a, b, c, d, s)
        # As the modal path's acceptance, 100x: relative to each element or 1e-6 of the peak.
        scale = np.maximum(np.abs(exact), 1e-6 * np.max(np.abs(exact)))
        assert np.max(np.abs(ev(s) - exact) / scale) < 1e-8
