"""The engine's loop as one linear system, checked against the compiled loop itself."""

from __future__ import annotations

import numpy as np
import pytest

from fsmbench.bench.params import Bench
from fsmbench.control.loaded import running_controller
from fsmbench.sim.closed_loop import (
    closed_loop_plant,
    feedback_name,
    reference_feedthrough,
    reference_name,
)
from fsmbench.sim.controller import closed_loop_spectral_radius
from fsmbench.sim.engine import Quantiser, run_loop
from fsmbench.sim.plant import ADC_CHANNELS, DAC_CHANNELS, bench_discrete

# Both sides are float64 state recursions of one linear system (ideal converters): they
# differ by round-off accumulated over a few thousand samples of a 0.1 %-damped mode.
_RTOL = 1e-8


def _state_space_run(plant, u: np.ndarray) -> np.ndarray:
    """``x+ = a x + b u``, ``y = c x`` from rest, (n, n_out)."""
    x = np.zeros(plant.a.shape[0])
    out = np.empty((u.shape[0], plant.c.shape[0]))
    for k in range(u.shape[0]):
        out[k] = plant.c @ x
        x = plant.a @ x + plant.b @ u[k]
    return out


@pytest.fixture(scope="module")
def loop_parts(bench: Bench):
    plant = bench_discrete(bench)
    ctrl = running_controller(None, bench=bench)
    return plant, ctrl, closed_loop_plant(plant, ctrl.feedback)


def test_names_and_stability(loop_parts) -> None:
    plant, ctrl, loop = loop_parts
    assert loop.input_names[:4] == DAC_CHANNELS
    assert loop.input_names[4:] == (reference_name("Vph"), reference_name("Vpv"))
    assert loop.output_names[-2:] == (feedback_name("Uch"), feedback_name("Ucv"))
    rho = float(np.max(np.abs(np.linalg.eigvals(loop.a))))
    # The same matrix the engine's stability check builds, assembled independently.
    assert rho == pytest.approx(closed_loop_spectral_radius(plant, ctrl.feedback,
                                                            n_adc=len(ADC_CHANNELS)), rel=1e-12)
    assert rho < 1.0


def test_excitation_at_the_output_matches_the_compiled_loop(loop_parts) -> None:
    plant, ctrl, loop = loop_parts
    n = 3000
    rng = np.random.default_rng(3)
    w = np.zeros((n, len(DAC_CHANNELS)))
    w[:, 0] = 1e-3 * rng.standard_normal(n)
    w[:, 1] = 5e-4 * rng.standard_normal(n)
    ideal = Quantiser(range_v=20.0, bits=0)
    run = run_loop(plant, u_ext=w, adc_noise=np.zeros((n, len(ADC_CHANNELS))), adc=ideal,
                   dac=ideal, controller=ctrl.feedback, n_adc=len(ADC_CHANNELS))
    u = np.hstack([w, np.zeros((n, 2))])
    y = _state_space_run(loop, u)
    n_adc = len(ADC_CHANNELS)
    scale = np.max(np.abs(run.adc), axis=0)
    np.testing.assert_allclose(y[:, :n_adc], run.adc, atol=_RTOL * scale.max())
    # The DAC command is the controller's part plus the excitation on the channel.
    for i, ch in enumerate(("Uch", "Ucv")):
        j = DAC_CHANNELS.index(ch)
        fb = y[:, loop.output_names.index(feedback_name(ch))]
        np.testing.assert_allclose(fb + w[:, j], run.dac[:, j],
                                   atol=_RTOL * np.max(np.abs(run.dac[:, j])))
        assert np.max(np.abs(fb)) > 1e-3 * np.max(np.abs(w[:, i]))  # the loop did act


def test_reference_matches_the_compiled_loop(loop_parts) -> None:
    """A reference r: the controller reads reading - r (the engine's ADC noise of -r)."""
    plant, ctrl, loop = loop_parts
    n = 3000
    r = np.zeros((n, len(ADC_CHANNELS)))
    i_ph = ADC_CHANNELS.index("Vph")
    r[200:, i_ph] = 1e-3  # a step of the 4QD reading the loop makes the beam follow
    ideal = Quantiser(range_v=20.0, bits=0)
    run = run_loop(plant, u_ext=np.zeros((n, len(DAC_CHANNELS))), adc_noise=-r, adc=ideal,
                   dac=ideal, controller=ctrl.feedback, n_adc=len(ADC_CHANNELS))
    u = np.zeros((n, len(loop.input_names)))
    u[:, loop.input_names.index(reference_name("Vph"))] = r[:, i_ph]
    y = _state_space_run(loop, u)
    n_adc = len(ADC_CHANNELS)
    sensor = run.adc + r  # what the sensor read
    np.testing.assert_allclose(y[:, :n_adc], sensor, atol=_RTOL * np.max(np.abs(sensor)))
    direct = reference_feedthrough(ctrl.feedback)
    refs = np.column_stack([r[:, ADC_CHANNELS.index(c)] for c in ("Vph", "Vpv")])
    for i, ch in enumerate(("Uch", "Ucv")):
        fb = y[:, loop.output_names.index(feedback_name(ch))] + refs @ direct[i]
        j = DAC_CHANNELS.index(ch)
        np.testing.assert_allclose(fb, run.dac[:, j], atol=_RTOL * np.max(np.abs(run.dac[:, j])))
    # The loop follows the reference: the 4QD reading ends at the step (integral action).
    assert sensor[-1, i_ph] == pytest.approx(1e-3, rel=1e-3)
