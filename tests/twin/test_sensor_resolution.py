"""A designed excitation resolves the 4QD amplifier; the bench file then keeps it out of the delays.

The real-bench twin at 20 kHz has a 10 kHz second-order (Butterworth) 4QD
amplifier that its bench model does not know. With the ESRF study's white noise the
Newport's lines stay coherent to ~2 kHz, where the amplifier is a lag like
22.5 us of delay and nothing else. Odd multisines on Unh and Unv up to 8 kHz
keep the lines coherent to 0.4 fs, where the amplifier's droop (16 % at
8 kHz) shows: the joint fit resolves it, and says to put it in the bench file;
with it there, every delay is the pure one.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from fsmbench.bench.blocks import input_delays_s, replace_params
from fsmbench.bench.params import Bench, real_bench
from fsmbench.excite.design import design_multisine
from fsmbench.excite.files import write_excitation
from fsmbench.ident.delay.sampled import SensorLowpass
from fsmbench.ident.pipeline import Identification, identify
from fsmbench.io.folder import load_recordings
from fsmbench.twin.simulate import play_excitation

FS = 20_000.0


def _bench(*, amplifier_known: bool) -> Bench:
    b = real_bench()
    nominal = replace_params(b.nominal, converter={"fs_hz": FS})
    if amplifier_known:
        nominal = replace_params(nominal, converter={"fs_hz": FS}, quad_diode={
            "bandwidth_hz": b.true.quad_diode.bandwidth_hz,
            "bandwidth_order": b.true.quad_diode.bandwidth_order})
    return Bench(datasheet=b.datasheet, nominal=nominal,
                 true=replace_params(b.true, converter={"fs_hz": FS}))


TRUE_DELAYS_S = input_delays_s(_bench(amplifier_known=False).true)


@pytest.fixture(scope="module")
def recordings(tmp_path_factory: pytest.TempPathFactory) -> dict:
    root = tmp_path_factory.mktemp("sensor")
    bench = _bench(amplifier_known=False)
    files = []
    for channel in ("Unh", "Unv"):
        # 1.5 V rms peaks at 1.8 V on the DAC and 0.27 V on the 4QD (checked by excite);
        # 2 Hz lines, 2 transient periods (1 s: the Newport settles in ms).
        design = design_multisine(input=channel, band_hz=(1.0, 8000.0), resolution_hz=2.0,
                                  amplitude_rms_v=1.5, fs_hz=FS, periods=16,
                                  transient_periods=2, grid="odd")
        (root / channel).mkdir()
        files.append(write_excitation(design, root / channel)[1])
    play_excitation(files, bench, out_dir=root / "twin", seed=0,
                    experiments=["data_cal_pd_h", "data_cal_pd_v", "data_uch", "data_ucv"])
    return dict(load_recordings(Path(root / "twin"), fs_hz=FS).recordings)


def _identify(recordings: dict, *, amplifier_known: bool) -> Identification:
    bench = _bench(amplifier_known=amplifier_known)
    return identify(recordings, bench=bench, source="twin")


def test_a_multisine_to_8_khz_resolves_the_4qd_amplifier(recordings: dict) -> None:
    ident = _identify(recordings, amplifier_known=False)
    assert ident.newport is not None and ident.newport.dynamics is not None
    truth = SensorLowpass.from_params(_bench(amplifier_known=False).true)
    for axis, fit in ident.newport.dynamics.axes.items():
        assert fit.sensor is not None and fit.sensor.source == "fitted", axis
        assert fit.sensor.order == truth.order
        # Three standard deviations: one record (h came out 2.3 sigma high once).
        assert abs(fit.sensor.bandwidth_hz - truth.bandwidth_hz) < 3 * fit.sensor.bandwidth_std_hz
        # The Newport's pure delay (DAC 1 sample + 35 us latency + hold + 0.35 ms lag: 460 us);
        # 3 us: the fit's ~1 us scatter.
        assert fit.delay_s == pytest.approx(TRUE_DELAYS_S["Unh"], abs=3e-6)
    # One amplifier feeds both outputs: one finding per bench-file key, with its record.
    keys = [f.key for f in ident.findings if "quad_diode.bandwidth" in f.key]
    assert sorted(keys) == ["nominal.quad_diode.bandwidth_hz",
                            "nominal.quad_diode.bandwidth_order"], keys
    notes = [n.sentence() for n in ident.notices]
    assert sum("second-order (Butterworth) low pass at" in n for n in notes) == 1, notes


def test_the_resolved_amplifier_makes_the_sercalo_delay_pure(recordings: dict) -> None:
    unknown = _identify(recordings, amplifier_known=False)
    known = _identify(recordings, amplifier_known=True)
    assert unknown.sercalo is not None and known.sercalo is not None
    # The truth: 1 sample of DAC transport and half a sample of hold at 20 kHz (75 us)
    # and 35 us of latency, 110 us. 2.5 us: the twin's 125 kHz coil pole (1.3 us) plus the
    # fit's scatter.
    assert known.sercalo.pure_delay_s == pytest.approx(TRUE_DELAYS_S["Uch"], abs=2.5e-6)
    # Unknown to the bench file, the amplifier the Newport's lines resolved is used in the
    # same run: the same pure delay.
    assert unknown.sercalo.pure_delay_s == pytest.approx(TRUE_DELAYS_S["Uch"], abs=2.5e-6)
    assert {j.sensor.source for j in unknown.sercalo.joint_delays} == {"Newport"}
    # The effective delay (the plant's) is the same either way: the amplifier is a lag.
    assert unknown.sercalo.delay_s == pytest.approx(known.sercalo.delay_s, abs=0.5e-6)
    assert not [n for n in known.notices if "quad_diode" in n.message]
