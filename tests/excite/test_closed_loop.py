"""Limits of an excitation played with the loop closed."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from fsmbench.bench.params import Bench
from fsmbench.control.loaded import running_controller
from fsmbench.excite.closed_loop import check_closed_loop_limits, closed_loop_peaks
from fsmbench.excite.design import design_multisine
from fsmbench.excite.limits import ExcitationLimitError, converter_peaks
from fsmbench.sim.engine import Quantiser, run_loop
from fsmbench.sim.plant import ADC_CHANNELS, DAC_CHANNELS, bench_discrete


@pytest.fixture(scope="module")
def design(bench: Bench):
    return design_multisine(input="Uch", band_hz=(2.0, 1000.0), resolution_hz=2.0,
                            amplitude_rms_v=0.01, fs_hz=bench.nominal.converter.fs_hz,
                            phase_method="schroeder", periods=2)


def test_a_zero_controller_gives_the_open_loop_peaks(bench: Bench, design) -> None:
    """Property: with K = 0 the closed loop is the open loop, so the open-loop tool's peaks."""
    ctrl = running_controller(None, bench=bench).feedback
    zero = dataclasses.replace(ctrl, a=0 * ctrl.a, b=0 * ctrl.b, c=0 * ctrl.c, d=0 * ctrl.d)
    plant = bench_discrete(bench)
    closed = closed_loop_peaks(design, params=bench.true, plant=plant, controller=zero)
    open_ = converter_peaks(design, params=bench.true, plant=plant)
    want = {(c.converter, c.signal): c.peak_v for c in open_.peaks}
    got = {(c.converter, c.signal): c.peak_v for c in closed.limits.peaks}
    for key, peak in want.items():
        if peak > 1e-6:
            # Both are FFT responses of one sampled bench: equal to round-off of the FFTs.
            assert got[key] == pytest.approx(peak, rel=1e-6), key


def test_beam_error_matches_the_compiled_loop(bench: Bench, design) -> None:
    """The added beam error is what the engine's loop (ideal converters, no noise) gives."""
    fb = running_controller(None, bench=bench).feedback
    plant = bench_discrete(bench)
    report = closed_loop_peaks(design, params=bench.true, plant=plant, controller=fb,
                               max_error_rad=1e-3)
    n = design.samples_v.size
    reps = 6  # play it repeated: the last period is the periodic steady state
    w = np.zeros((reps * n, len(DAC_CHANNELS)))
    w[:, 0] = np.tile(design.samples_v, reps)
    ideal = Quantiser(range_v=20.0, bits=0)
    run = run_loop(plant, u_ext=w, adc_noise=np.zeros((reps * n, len(ADC_CHANNELS))),
                   adc=ideal, dac=ideal, controller=fb, n_adc=len(ADC_CHANNELS))
    from fsmbench.sim.plant import INTERNAL_SIGNALS

    rh = run.internal[-n:, INTERNAL_SIGNALS.index("Rh")]
    beam = {b.signal: b for b in report.beam}
    # The steady state after 5 repetitions of 1 s leaves exp(-5 / 0.76) ~ 1e-3 of the
    # slowest closed-loop mode's transient.
    assert beam["Rh"].rms_rad == pytest.approx(float(np.sqrt(np.mean(rh**2))), rel=1e-2)


def test_the_beam_bound_limits_the_amplitude(bench: Bench, design) -> None:
    fb = running_controller(None, bench=bench).feedback
    plant = bench_discrete(bench)
    free = closed_loop_peaks(design, params=bench.true, plant=plant, controller=fb)
    rms = max(b.rms_rad for b in free.beam)
    bound = rms / 4
    with pytest.raises(ExcitationLimitError, match="tolerated during the measurement"):
        check_closed_loop_limits(design, params=bench.true, plant=plant, controller=fb,
                                 max_error_rad=bound)
    report = closed_loop_peaks(design, params=bench.true, plant=plant, controller=fb,
                               max_error_rad=bound)
    # Linear in the amplitude: a quarter of the rms fits (rounded down to 3 digits).
    assert report.fitting_amplitude_rms_v() == pytest.approx(design.amplitude_rms_v / 4,
                                                             rel=1e-2)
    assert report.fitting_amplitude_rms_v() <= design.amplitude_rms_v / 4
