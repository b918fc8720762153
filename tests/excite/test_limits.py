"""Converter limits through the bench model: closed forms, a time-domain reference, verdicts."""

from __future__ import annotations

import re

import numpy as np
import pytest
from scipy.signal import dlsim

from fsmbench.bench.params import default_bench
from fsmbench.excite.design import ExcitationDesign, design_multisine, design_noise
from fsmbench.excite.limits import (
    ExcitationLimitError,
    check_limits,
    converter_peaks,
    input_response,
    response_from_rest,
)
from fsmbench.ident.calibration import known_ga_zc
from fsmbench.sim.plant import ADC_CHANNELS, twin_discrete

BENCH = default_bench()
NOM = BENCH.nominal
PLANT = twin_discrete(NOM)
FS = NOM.converter.fs_hz


def test_schur_response_equals_the_plants_own() -> None:
    f = np.linspace(0.0, 4999.0, 301)
    for inp in ("Uch", "Unv"):
        ref = PLANT.frequency_response(f)[:, :len(ADC_CHANNELS), PLANT.input_names.index(inp)]
        # Two factorisations of the same linear systems: rounding only.
        np.testing.assert_allclose(input_response(PLANT, f, input=inp), ref, rtol=1e-9,
                                   atol=1e-9 * np.abs(ref).max())


def test_response_from_rest_equals_the_state_recursion() -> None:
    x = np.random.default_rng(2).standard_normal(4000) * 0.01
    j = PLANT.input_names.index("Uch")
    _, y, _ = dlsim((PLANT.a, PLANT.b[:, [j]], PLANT.c, np.zeros((PLANT.c.shape[0], 1)),
                     PLANT.ts_s), x)
    got = response_from_rest(x, input="Uch", plant=PLANT)
    # Padding leaves 1e-9 of the slowest mode to wrap around; the FFTs round at 1e-15.
    np.testing.assert_allclose(got, y[:, :len(ADC_CHANNELS)], atol=1e-8 * np.abs(y).max())


def test_coil_voltage_gain_is_ga_zc_gi() -> None:
    """A 10 Hz sine on Uch: Vch peaks at |Ga Zc Gi| times its amplitude (ESRF study 2.2)."""
    n = 1000  # one period of 10 Hz
    x = 0.01 * np.cos(2 * np.pi * 10.0 * np.arange(n) / FS)
    y = response_from_rest(x, input="Uch", plant=PLANT, periodic=True)
    r_tot = (NOM.current_amplifier.r_ohm.h + NOM.current_amplifier.r_buffer_ohm.h
             + NOM.sercalo.r_coil_ohm.h)
    gi = 1.0 / abs(r_tot + 2j * np.pi * 10.0 * NOM.sercalo.l_coil_h.h)
    expected = 0.01 * known_ga_zc(NOM, axis="h", f_hz=np.array([10.0]))[0] * gi
    assert expected == pytest.approx(0.01 * 1000 * 9.3 / 50.3, rel=1e-3)  # 1.849 V: 185 V/V
    # The hold's droop at 10 Hz of 10 kHz is 1.6e-6, the sampled peak of a 10 Hz cosine
    # is its amplitude within 5e-6: 1e-5 covers both.
    assert np.abs(y[:, ADC_CHANNELS.index("Vch")]).max() == pytest.approx(expected, rel=1e-5)


#: The one-line refusal of an excitation that leaves a converter's range.
OVER_RANGE = re.compile(r"Uch: an excitation of 0\.05 V rms drives ADC Vch to (?P<peak>\S+) V "
                        r"peak, beyond its ±10 V range \(nominal bench model\); at most "
                        r"(?P<fit>\S+) V rms fits")


@pytest.fixture(scope="module")
def seed_noise() -> ExcitationDesign:
    """The ESRF study's level: 15 mV rms, 1-2000 Hz band noise on Uch, 30 s."""
    return design_noise(input="Uch", band_hz=(1.0, 2000.0), amplitude_rms_v=0.015, fs_hz=FS,
                        duration_s=30.0, seed=0)


def test_the_seeds_noise_level_fits_near_the_limit(seed_noise) -> None:
    report = check_limits(seed_noise, params=NOM)
    assert report.fits
    vch = next(c for c in report.peaks if c.signal == "Vch")
    assert report.worst() is vch  # the coil-voltage channel is the tight one
    # Measured: 9.81 V of 10 V; a Gaussian's 4.6-sigma peak over 3e5 samples on Vch.
    assert 0.9 < vch.fraction <= 1.0
    assert [c.signal for c in report.peaks] == ["Uch", "Vch", "Vph"]  # nominal: no coupling
    assert report.peaks[0].converter == "DAC"


def test_over_range_is_refused_with_the_amplitude_that_fits(seed_noise) -> None:
    loud = design_noise(input="Uch", band_hz=(1.0, 2000.0), amplitude_rms_v=0.05, fs_hz=FS,
                        duration_s=30.0, seed=0)
    with pytest.raises(ExcitationLimitError) as info:
        check_limits(loud, params=NOM)
    msg = str(info.value)
    assert "\n" not in msg
    m = OVER_RANGE.fullmatch(msg)
    assert m is not None, msg
    # The numbers printed are the report's own (Vch at 32.7 V here), to 3 significant digits.
    report = converter_peaks(loud, params=NOM)
    vch = report.worst()
    assert vch.signal == "Vch" and float(m["peak"]) == float(f"{vch.peak_v:.3g}")
    fit = float(m["fit"])
    assert fit == report.fitting_amplitude_rms_v()
    # The rms that brings Vch to 10 V, floored to 3 significant digits (the floor forgives
    # 1e-12 of rounding).
    exact = 0.05 / vch.fraction
    assert fit <= exact * (1 + 1e-12) and exact < fit + 10.0 ** (np.floor(np.log10(fit)) - 2)
    # Linear: the amplitude offered fits (the same noise scaled). rel 1e-9: the same draws
    # scaled by another factor through a linear model, rounding only.
    scaled = design_noise(input="Uch", band_hz=(1.0, 2000.0), amplitude_rms_v=fit, fs_hz=FS,
                          duration_s=30.0, seed=0)
    assert check_limits(scaled, params=NOM).worst().fraction == pytest.approx(
        fit / 0.05 * vch.fraction, rel=1e-9)
    assert check_limits(scaled, params=NOM).fits


def test_dac_range_on_a_newport_input() -> None:
    d = design_multisine(input="Unh", band_hz=(1.0, 50.0), resolution_hz=1.0,
                         amplitude_rms_v=9.0, fs_hz=FS, phase_method="schroeder")
    report = converter_peaks(d, params=NOM)
    assert report.peaks[0].signal == "Unh" and report.peaks[0].peak_v > 10.0
    # Unh reaches the 4QD and the Newport's own metrology (Vnh = angle / gn0).
    assert {c.signal for c in report.peaks} == {"Unh", "Vph", "Vnh"}
    with pytest.raises(ExcitationLimitError, match=r"^Unh: .* drives (DAC Unh|ADC Vnh) to "):
        check_limits(d, params=NOM)


def test_true_model_reaches_the_other_axis_through_coupling(seed_noise) -> None:
    report = converter_peaks(seed_noise, params=BENCH.true, model="true")
    assert "Vpv" in {c.signal for c in report.peaks}  # 2 % torque coupling, 4QD rotation
    assert report.fits and report.verdict().endswith("true bench model)")
