"""The 4QD's linear range: closed forms, the cubic itself, the twin, and the refusal."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from fsmbench.bench.params import default_bench, load_bench
from fsmbench.excite.design import ExcitationDesign, design_multisine
from fsmbench.excite.files import write_excitation
from fsmbench.excite.limits import (
    ExcitationLimitError,
    check_limits,
    converter_peaks,
    input_response,
    response_from_rest,
)
from fsmbench.sim.plant import ADC_CHANNELS, twin_discrete
from fsmbench.twin.simulate import simulate_excitation

REAL_TOML = Path(__file__).parents[2] / "src" / "fsmbench" / "bench" / "real_bench.toml"
REAL = load_bench(REAL_TOML)
TRUE = REAL.true
FS = TRUE.converter.fs_hz
QD = TRUE.quad_diode
K = QD.nonlinearity_pct / 100  # 0.02
VFS_H = abs(QD.gain_v_per_rad.h) * QD.nonlinearity_full_swing_rad  # 31.4 V/rad * 10.6 mrad
VPH = ADC_CHANNELS.index("Vph")


def _cubic(y: np.ndarray) -> np.ndarray:
    """The twin's 4QD (fsmbench.sim.engine): y + c y**3, c = -k / V_fs**2."""
    return y - K / VFS_H**2 * y**3


def _uch_multisine(rms_v: float) -> ExcitationDesign:
    """The default grid of ``fsmbench excite``: 1-2000 Hz every 1 Hz, minimised phases."""
    return design_multisine(input="Uch", band_hz=(1.0, 2000.0), resolution_hz=1.0,
                            amplitude_rms_v=rms_v, fs_hz=FS)


def test_single_sine_against_the_closed_form() -> None:
    """One 10 Hz line on Unh: peak |H| a, compression k (peak/V_fs)^2, gain 3/4 of it low."""
    d = design_multisine(input="Unh", band_hz=(10.0, 10.5), resolution_hz=1.0,
                         amplitude_rms_v=1.0, fs_hz=FS)
    assert d.lines_hz.tolist() == [10.0]
    q = converter_peaks(d, params=TRUE, model="true").quad_diode[0]
    plant = twin_discrete(TRUE)
    amp = abs(input_response(plant, np.array([10.0]), input="Unh",
                             outputs=("Vph",))[0, 0]) * d.line_amplitude_v
    # 1000 samples per period of 10 Hz: the sampled peak is within cos(pi/1000)-1 = 5e-6.
    assert q.peak_v == pytest.approx(amp, rel=1e-5)
    assert q.angle_rad == pytest.approx(amp / 31.4, rel=1e-5)
    assert q.compression == pytest.approx(K * (amp / VFS_H) ** 2, rel=2e-5)
    assert q.compression == pytest.approx(0.0100, abs=1e-4)  # 1 V rms on Unh: 7.5 mrad, 1 %
    # The cubic applied to the predicted response: the line's gain falls by 3/4 of the
    # compression (cos^3 = 3/4 cos + 1/4 cos 3x); the bound of the report is twice that.
    y = response_from_rest(d.one_period(), input="Unh", plant=plant, periodic=True)[:, VPH]
    fall = 1 - abs(np.fft.rfft(_cubic(y))[10] / np.fft.rfft(y)[10])
    # Exact for the cubic; the compression uses the sampled peak, within 5e-6 of the
    # amplitude, squared: 2e-5.
    assert fall == pytest.approx(0.75 * q.compression, rel=2e-5)
    assert q.gain_bias == pytest.approx(1.5 * q.compression, rel=2e-5)


def test_multisine_gain_fall_is_the_cubics_coherent_part() -> None:
    """Random-phase multisines on Uch: the lines' gain fall is 3 k (rms / V_fs)^2."""
    plant = twin_discrete(TRUE)
    falls, bounds = [], []
    for seed in range(8):
        d = design_multisine(input="Uch", band_hz=(1.0, 500.0), resolution_hz=1.0,
                             amplitude_rms_v=0.004, fs_hz=FS, phase_method="random", seed=seed)
        q = converter_peaks(d, params=TRUE, model="true").quad_diode[0]
        y = response_from_rest(d.one_period(), input="Uch", plant=plant,
                               periodic=True)[:, VPH]
        k = np.rint(d.lines_hz).astype(int)
        falls.append(1 - (np.fft.rfft(_cubic(y))[k] / np.fft.rfft(y)[k]).real)
        bounds.append(q.gain_bias)
        assert q.gain_bias == pytest.approx(3 * K * np.mean(y * y) / VFS_H**2, rel=1e-12)
    # The rms, hence the coherent part, does not depend on the phases (Parseval).
    assert np.ptp(bounds) <= 1e-9 * bounds[0]
    # The phase-dependent rest of the cubic has zero mean over phase draws; averaged over
    # 8 draws, the median line is within 0.5-1.6 % of the coherent part (measured): 5 %.
    assert np.median(np.mean(falls, axis=0)) == pytest.approx(bounds[0], rel=0.05)
    assert bounds[0] == pytest.approx(0.00444, abs=5e-6)  # 4 mV rms: 0.444 % low (3 digits)


def test_compression_against_the_twin(tmp_path: Path) -> None:
    """The twin's Vph with and without its 2 % 4QD, same seed: the peak's compression."""
    d = _uch_multisine(0.015)
    report = check_limits(d, params=TRUE, model="true", max_qd_compression=0.05)
    q = report.quad_diode[0]
    assert q.compression == pytest.approx(0.0405, abs=5e-5)  # 15.1 mrad: 4.05 %
    write_excitation(d, tmp_path, limits=report)
    linear = dataclasses.replace(REAL, true=dataclasses.replace(
        TRUE, quad_diode=dataclasses.replace(QD, nonlinearity_pct=0.0)))
    got = {}
    for name, bench in (("real", REAL), ("linear", linear)):
        run = simulate_excitation(tmp_path, bench, seed=5)
        got[name] = np.asarray(run.recordings["data_uch"]["Vph"].values, dtype=float).ravel()
    played = slice(got["linear"].size - d.samples_v.size, None)
    lin, real = got["linear"][played], got["real"][played]
    i = int(np.argmax(np.abs(lin)))
    # The twin adds its noise (1 mV rms), mains (0.5 mV), drift and 0.3 mV ADC steps to
    # the linear peak of 0.47 V: 1 % covers a few mV (measured 0.1 %).
    assert abs(lin[i]) == pytest.approx(q.peak_v, rel=0.01)
    # Same noise in both runs: the compression read at the peak sample is the cubic's
    # there; twice the peak's 1 % plus two ADC steps of the 19 mV difference: 3 %
    # (measured 0.4 % and 0.2 % with seeds 5 and 6).
    assert (lin[i] - real[i]) / lin[i] == pytest.approx(q.compression, rel=0.03)


def test_real_bench_refuses_what_the_converters_allow() -> None:
    """41 mV rms (converters fine) and 15 mV are refused on the real bench; 7 mV is not."""
    for rms, angle, compression in ((0.041, 41.2, 30.2), (0.015, 15.1, 4.05)):
        d = _uch_multisine(rms)
        report = converter_peaks(d, params=TRUE, model="true")
        assert report.converters_fit and not report.fits
        with pytest.raises(ExcitationLimitError) as info:
            check_limits(d, params=TRUE, model="true")
        msg = str(info.value)
        assert "\n" not in msg
        assert msg.startswith(f"Uch: an excitation of {rms:g} V rms turns the beam on the 4QD "
                              f"(Vph) to {angle:g} mrad peak, compressed {compression:g} %, "
                              "beyond the 1 % limit (true bench model, 2 % at its full swing)")
        # Compression goes with the amplitude squared: 41 * sqrt(1 / 30.2) = 7.46 mV.
        assert msg.endswith("at most 0.00745 V rms keeps it within")
    ok = check_limits(_uch_multisine(0.00745), params=TRUE, model="true")
    assert ok.fits and 0.0099 < ok.worst_qd().compression <= 0.01  # type: ignore[union-attr]
    assert "; 4QD Vph compressed 0.99" in ok.verdict()
    # A looser limit accepts 15 mV.
    assert check_limits(_uch_multisine(0.015), params=TRUE, model="true",
                        max_qd_compression=0.05).fits


def test_linear_4qd_is_said_not_limited() -> None:
    nominal = default_bench().nominal
    report = check_limits(_uch_multisine(0.015), params=nominal)
    assert report.qd_linear and report.quad_diode[0].compression == 0.0
    assert report.qd_line() == ("4QD linear in this model: compression not limited "
                                "(beam 26.4 mrad peak on Vph)")
    assert report.fits and "4QD" not in report.verdict()


def test_limit_must_be_positive() -> None:
    with pytest.raises(ValueError, match="compression limit must be > 0"):
        converter_peaks(_uch_multisine(0.001), params=TRUE, max_qd_compression=0.0)


def test_linear_4qd_needs_no_full_swing_but_a_compressing_one_does() -> None:
    qd0 = dataclasses.replace(QD, nonlinearity_pct=0.0, nonlinearity_full_swing_rad=0.0)
    report = check_limits(_uch_multisine(0.001), params=dataclasses.replace(TRUE, quad_diode=qd0))
    assert report.qd_linear and report.quad_diode[0].gain_bias == 0.0
    bad = dataclasses.replace(QD, nonlinearity_full_swing_rad=0.0)
    with pytest.raises(ValueError, match="compression of 2 % needs a full swing > 0 rad"):
        converter_peaks(_uch_multisine(0.001), params=dataclasses.replace(TRUE, quad_diode=bad))
