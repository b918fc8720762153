"""Tustin sections, prewarped or not, and their state-space cascade."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

from fsmbench.bench.esrf import iff_controller, tustin
from fsmbench.bench.sections import (
    Section,
    section_prewarp_rad_s,
    section_response,
    tustin_cascade,
    tustin_section,
    warped_frequency_rad_s,
)
from fsmbench.control.export import discretise
from fsmbench.control.freq import evaluate_ss

TS = 1e-4  # [s]


def _pair(f_hz: float, zeta: float) -> tuple[complex, complex]:
    w = 2 * np.pi * f_hz
    r = complex(-zeta * w, w * np.sqrt(1 - zeta**2))
    return r, r.conjugate()


RESONANCE = Section(zeros=(-300.0,), poles=_pair(800.0, 0.01), gain=2e6)
NOTCH = Section(zeros=_pair(411.5, 0.003), poles=(-352.5, -12566.4), gain=1.0)
ROLL_OFF = Section(zeros=(), poles=_pair(200.0, 0.8), gain=(2 * np.pi * 200.0) ** 2)
INTEGRATOR = Section(zeros=(-112.0,), poles=(0j, 0j), gain=-3216.7)


def test_what_gets_prewarped() -> None:
    assert section_prewarp_rad_s(NOTCH, ts_s=TS) == pytest.approx(2 * np.pi * 411.5)
    assert section_prewarp_rad_s(RESONANCE, ts_s=TS) == pytest.approx(2 * np.pi * 800.0)
    assert section_prewarp_rad_s(ROLL_OFF, ts_s=TS) is None  # damping 0.8: nothing to pin
    assert section_prewarp_rad_s(INTEGRATOR, ts_s=TS) is None
    above = Section(zeros=(), poles=_pair(6e3, 0.01), gain=1.0)  # above Nyquist (5 kHz)
    assert section_prewarp_rad_s(above, ts_s=TS) is None


@pytest.mark.parametrize("sec", [RESONANCE, NOTCH, ROLL_OFF, INTEGRATOR])
@pytest.mark.parametrize("prewarp", [True, False])
def test_discrete_response_is_the_continuous_one_at_the_warped_frequency(
        sec: Section, prewarp: bool) -> None:
    d = tustin_section(sec, ts_s=TS, prewarp=prewarp)
    f = np.linspace(1.0, 4.9e3, 97)
    w = 2 * np.pi * f
    _, hd = signal.sosfreqz(np.array([d.sos]), worN=f, fs=1 / TS)
    # Closed form of the warp, written out here: w' = w0 tan(w T/2) / tan(w0 T/2).
    w0 = d.prewarp_rad_s
    wp = (2 / TS * np.tan(w * TS / 2) if w0 is None
          else w0 * np.tan(w * TS / 2) / np.tan(w0 * TS / 2))
    np.testing.assert_allclose(warped_frequency_rad_s(w, ts_s=TS, prewarp_rad_s=w0), wp,
                               rtol=1e-14)
    # Rounding of the coefficients, amplified near z = 1 by the double integrator
    # (eps / (w T)^2 = 5.6e-10 at 1 Hz) and at the notch bottom by 1/(2 zeta) = 170.
    np.testing.assert_allclose(hd, section_response(sec, 1j * wp), rtol=1e-8)
    if w0 is not None:
        # The defining property: exact at the prewarp frequency.
        _, h0 = signal.sosfreqz(np.array([d.sos]), worN=[w0 / (2 * np.pi)], fs=1 / TS)
        assert abs(h0[0] / section_response(sec, np.array([1j * w0]))[0] - 1) < 1e-10


def test_resonance_peak_stays_in_place() -> None:
    """A lightly damped pole pair (800 Hz, zeta 0.01): its peak moves 17 Hz with plain
    Tustin ((pi f T)^2/3 = 2.1 %), not when prewarped."""
    f = np.linspace(770.0, 810.0, 40001)  # 1 mHz grid
    peak_c = f[np.argmax(np.abs(section_response(RESONANCE, 2j * np.pi * f)))]
    peaks = {}
    for prewarp in (True, False):
        sos = np.array([tustin_section(RESONANCE, ts_s=TS, prewarp=prewarp).sos])
        peaks[prewarp] = f[np.argmax(np.abs(signal.sosfreqz(sos, worN=f, fs=1 / TS)[1]))]
    # The warp's slope at 800 Hz (1.02) moves the peak by 2 % of its 1.6 mHz offset from
    # 800 Hz: below the 1 mHz grid.
    assert peaks[True] == pytest.approx(peak_c, abs=2e-3)
    assert peak_c - peaks[False] == pytest.approx(800.0 * (np.pi * 800.0 * TS) ** 2 / 3, rel=0.05)


@pytest.mark.parametrize("prewarp", [True, False])
def test_state_space_cascade_equals_the_sections(prewarp: bool) -> None:
    secs = [INTEGRATOR, NOTCH, ROLL_OFF]
    sys = tustin_cascade(secs, ts_s=TS, prewarp=prewarp, input_name="Rh", output_name="Uch")
    assert sys.dt == TS and list(sys.input_labels) == ["Rh"]
    assert sys.nstates == 6
    assert np.max(np.abs(sys.A)) < 10.0  # bilinear of state-scaled sections: O(1) entries
    sos = np.array([tustin_section(s, ts_s=TS, prewarp=prewarp).sos for s in secs])
    f = np.logspace(0, np.log10(4.9e3), 200)
    _, h = signal.sosfreqz(sos, worN=f, fs=1 / TS)
    # Two routes (bilinear of a realisation, bilinear of roots); near z = 1 both lose
    # eps / (w T)^2 to the double integrator (5.6e-10 at 1 Hz).
    np.testing.assert_allclose(evaluate_ss(sys, np.exp(2j * np.pi * f * TS))[:, 0, 0], h,
                               rtol=1e-8)


def test_zero_channel_and_real_roots_only() -> None:
    """IFF (ESRF study 8.2): -1e4/s and a zero channel; no complex roots, so the default equals
    plain Tustin."""
    k = iff_controller()
    kd = discretise(k)
    f = np.logspace(0, np.log10(4.9e3), 50)
    z = np.exp(2j * np.pi * f * TS)
    # Same bilinear map on one integrator, two realisations: rounding.
    np.testing.assert_allclose(evaluate_ss(kd, z), evaluate_ss(tustin(k), z), rtol=1e-12,
                               atol=0)
    assert list(kd.input_labels) == ["Vch", "Vcv"]
    static = tustin_cascade([Section((), (), -2.5)], ts_s=TS)
    assert static.nstates == 0 and static.D[0, 0] == -2.5
