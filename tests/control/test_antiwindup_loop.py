"""Back-calculation anti-windup: the reordered sections, the loop, the saturating step."""

from __future__ import annotations

import control as ct
import numpy as np
import pytest
from scipy import signal

from fsmbench.bench.blocks import physical_plant
from fsmbench.bench.esrf import esrf_decentralised_controller
from fsmbench.bench.params import Bench
from fsmbench.control.analysis import control_objective
from fsmbench.control.antiwindup import (
    DEFAULT_TRACKING_TIME_S,
    antiwindup_channel,
    df2t_cascade,
    is_integrator_section,
)
from fsmbench.control.antiwindup_loop import (
    antiwindup_feedback,
    recovery_time_s,
    run_loop_antiwindup,
    saturating_step,
)
from fsmbench.control.design import design_controller
from fsmbench.control.export import discretise_channel
from fsmbench.sim.engine import Quantiser, run_loop
from fsmbench.sim.plant import ADC_CHANNELS, DAC_CHANNELS, bench_discrete

TS = 1e-4


@pytest.fixture(scope="module")
def fsm_controller(bench: Bench) -> ct.StateSpace:
    """fsmbench's controller (four integrators per axis) designed on the nominal plant."""
    plant = physical_plant(bench.nominal, source="physical (nominal)")
    return design_controller(plant, objective=control_objective(bench.nominal)).controller


def _sos(k: ct.StateSpace, i: int) -> np.ndarray:
    return np.array([s.sos for s in discretise_channel(k, ts_s=TS, output=i, input=i)])


def _response(a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray,
              f: np.ndarray) -> np.ndarray:
    z = np.exp(2j * np.pi * f * TS)
    n = a.shape[0]
    return np.array([(c @ np.linalg.solve(x * np.eye(n) - a, b))[0, 0] + d[0, 0] for x in z])


def test_df2t_realisation_runs_like_sosfilt() -> None:
    # scipy's sosfilt is direct form II transposed: same recursion, independent code.
    rng = np.random.default_rng(1)
    sos = np.array([[0.4, -0.1, 0.3, 1.0, -1.1, 0.5], [1.0, 0.2, 0.0, 1.0, -0.3, 0.0]])
    a, b, c, d = df2t_cascade(sos)
    x = rng.standard_normal(300)
    state = np.zeros(a.shape[0])
    y = np.empty_like(x)
    for k, e in enumerate(x):
        y[k] = (c @ state)[0] + d[0, 0] * e
        state = a @ state + b[:, 0] * e
    # Two orders of the same float64 sums over 300 samples of a stable filter.
    np.testing.assert_allclose(y, signal.sosfilt(sos, x), rtol=0, atol=1e-12)


def test_reordered_channel_keeps_the_response_and_places_the_saturated_poles(
        fsm_controller: ct.StateSpace) -> None:
    f = np.logspace(0, 3.6, 60)
    for i in range(2):
        sos = _sos(fsm_controller, i)
        ch = antiwindup_channel(sos, ts_s=TS)
        assert all(is_integrator_section(r) for r in ch.sos[-2:])
        assert ch.n_integrators == 4
        _, want = signal.sosfreqz(sos, worN=f, fs=1 / TS)
        # DF2T near four poles at z = 1 loses ~1/|z - 1|^2 of float64's eps (1e-8 at 1 Hz).
        np.testing.assert_allclose(_response(ch.a, ch.b, ch.c, ch.d, f), want, rtol=1e-6)
        placed = np.sort(np.abs(ch.saturated_poles))
        target = np.sort(np.exp(-TS * np.arange(1, 5) / DEFAULT_TRACKING_TIME_S))
        # Placement is checked in the module to 1e-3 of the poles' distance from 1.
        np.testing.assert_allclose(placed, target, atol=1e-3 * (1 - target.min()))
        outside = np.setdiff1d(np.arange(ch.a.shape[0]), ch.integrator_states)
        assert np.all(ch.gain[outside] == 0.0)


def _loop_inputs(bench: Bench, n: int, step_rad: float) -> tuple[np.ndarray, np.ndarray]:
    noise = np.zeros((n, len(ADC_CHANNELS)))
    noise[:, ADC_CHANNELS.index("Vph")] = -bench.nominal.quad_diode.gain_v_per_rad.h * step_rad
    return np.zeros((n, len(DAC_CHANNELS))), noise


@pytest.mark.machine_sensitive
def test_without_antiwindup_the_loop_is_the_engines_bit_for_bit(
        bench: Bench, fsm_controller: ct.StateSpace) -> None:
    gd = (bench.nominal.quad_diode.gain_v_per_rad.h, bench.nominal.quad_diode.gain_v_per_rad.v)
    aw = antiwindup_feedback(fsm_controller, gd_v_per_rad=gd, ts_s=TS)
    plant = bench_discrete(bench)
    conv = Quantiser(range_v=bench.true.converter.range_v, bits=bench.true.converter.bits)
    u_ext, noise = _loop_inputs(bench, 1500, 0.5)  # saturates: the rails are reached
    mine = run_loop_antiwindup(plant, u_ext=u_ext, adc_noise=noise, adc=conv, dac=conv,
                               controller=aw, n_adc=len(ADC_CHANNELS), enabled=False)
    ref = run_loop(plant, u_ext=u_ext, adc_noise=noise, adc=conv, dac=conv,
                   controller=aw.feedback, n_adc=len(ADC_CHANNELS))
    assert np.max(np.abs(ref.dac[:, 0])) >= 10.0 - 2 * conv.lsb_v
    for x, y in ((mine.adc, ref.adc), (mine.dac, ref.dac), (mine.internal, ref.internal),
                 (mine.controller_state, ref.controller_state)):
        np.testing.assert_array_equal(x, y)


def test_antiwindup_changes_nothing_below_the_rails(bench: Bench,
                                                     fsm_controller: ct.StateSpace) -> None:
    gd = (bench.nominal.quad_diode.gain_v_per_rad.h, bench.nominal.quad_diode.gain_v_per_rad.v)
    aw = antiwindup_feedback(fsm_controller, gd_v_per_rad=gd, ts_s=TS)
    plant = bench_discrete(bench)
    conv = Quantiser(range_v=bench.true.converter.range_v, bits=bench.true.converter.bits)
    u_ext, noise = _loop_inputs(bench, 1500, 0.01)
    runs = [run_loop_antiwindup(plant, u_ext=u_ext, adc_noise=noise, adc=conv, dac=conv,
                                controller=aw, n_adc=len(ADC_CHANNELS), enabled=on)
            for on in (False, True)]
    assert np.max(np.abs(runs[0].dac)) < 5.0  # well inside the ±10 V rails
    np.testing.assert_array_equal(runs[0].dac, runs[1].dac)
    np.testing.assert_array_equal(runs[0].internal, runs[1].internal)


def test_recovery_time_reads_the_last_excursion() -> None:
    t = np.arange(10) * 0.1
    err = np.array([5, 3, 0, 2, 0.5, 0.1, 0, 0, 0, 0])
    assert recovery_time_s(t, err, band=1.0) == pytest.approx(0.4)
    assert recovery_time_s(t, np.r_[err[:-1], 2.0], band=1.0) == np.inf
    assert recovery_time_s(t, np.zeros(10), band=1.0) == 0.0


@pytest.mark.parametrize("axis", ["h", "v"])
def test_saturating_step_recovers_with_antiwindup_and_not_without(
        bench: Bench, fsm_controller: ct.StateSpace, axis: str) -> None:
    step = saturating_step(bench, fsm_controller, name="fsmbench's controller", axis=axis)
    # The step was unreachable: the command sat on the rail for most of the hold.
    assert step.saturated_s["without"] > 0.5 * step.hold_s
    # Without anti-windup four wound integrators leave the loop on the rails to the end.
    assert step.recovery_s["without"] == np.inf
    # With it, the integrators are unwound within about Tt of the step back: the loop then
    # settles as the unsaturated one does, so recovery stays within its settling plus Tt.
    assert step.recovery_s["with"] <= step.recovery_s["linear"] + step.tracking_time_s
    assert step.to_json()["recovery_after_step_back_s"]["without"] is None


def test_seed_controller_has_two_integrators_per_axis() -> None:
    k = esrf_decentralised_controller()
    assert [antiwindup_channel(_sos(k, i), ts_s=TS).n_integrators for i in range(2)] == [2, 2]


def test_the_exports_recipe_runs_like_the_twins_controller(fsm_controller: ct.StateSpace) -> None:
    """A target written from controllers_sos.json's words alone gives the twin's commands."""
    from fsmbench.control.export import InputScaling, sos_document

    doc = sos_document({"k": fsm_controller}, ts_s=TS,
                       scaling=InputScaling(qd_gain_v_per_rad=(-31.0, 36.3), plant_source="x"))
    lo, hi = doc["dac_rails_v"]["min"], doc["dac_rails_v"]["max"]
    aw = doc["controllers"]["k"]["h"]["antiwindup"]
    rows = np.array(aw["sos_integrators_last"])
    regs = np.zeros((len(rows), 2))  # (s1, s2) of each section
    gains = {(r["section"], int(r["register"][1]) - 1): r["gain"]
             for r in aw["integrator_registers"]}
    ch = antiwindup_channel(_sos(fsm_controller, 0), ts_s=TS)
    x = np.zeros(ch.a.shape[0])
    e = np.r_[np.full(300, 0.4), np.zeros(300)]  # beam error [rad]: drives u past the rails
    clipped = 0
    for ek in e:
        # The recipe: DF2T sections in order, u = -v, clip, feed u - u_applied back.
        w = ek
        for i, (b0, b1, b2, _a0, a1, a2) in enumerate(rows):
            y = b0 * w + regs[i, 0]
            regs[i, 0] = regs[i, 1] + b1 * w - a1 * y
            regs[i, 1] = b2 * w - a2 * y
            w = y
        u = -w
        u_applied = min(max(u, lo), hi)
        clipped += u != u_applied
        for (i, j), g in gains.items():
            regs[i, j] += g * (u - u_applied)
        # The twin's form: the same controller as one state space, L on its integrators.
        v = (ch.c @ x)[0] + ch.d[0, 0] * ek
        x = ch.a @ x + ch.b[:, 0] * ek
        x = x + ch.gain * (-v - min(max(-v, lo), hi))
        # Same products in another order; the registers are O(1e6) V-scaled sums near the rails.
        assert u == pytest.approx(-v, rel=1e-9, abs=1e-6)
    assert clipped > 100  # the run spent most of its first half on a rail
