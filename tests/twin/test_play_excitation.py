"""The twin plays a designed excitation; the FRF measured from it is the twin's own plant."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from fsmbench.bench.params import default_bench
from fsmbench.excite.design import ExcitationDesign, design_multisine
from fsmbench.excite.files import ExcitationFileError, write_excitation
from fsmbench.sim.excitation import SampledExcitation
from fsmbench.sim.plant import twin_discrete
from fsmbench.twin.experiments import INPUT_EXPERIMENTS, played_experiment
from fsmbench.twin.simulate import TwinRun, simulate_excitation

BENCH = default_bench()
FS = BENCH.true.converter.fs_hz
LSB = BENCH.true.converter.lsb_v
START = 10_000  # data_uch's excitation starts at 1 s, as the seed's


@pytest.fixture(scope="module")
def multisine() -> ExcitationDesign:
    # 3 transient periods of 1 s: the h mode's envelope decays as exp(-xi w0 t), tau 0.32 s,
    # so 3 s leave 1e-4 of the start-up in the first period kept (the v mode, 0.63 s, is
    # seen only through 2 % coupling).
    return design_multisine(input="Uch", band_hz=(1.0, 2000.0), resolution_hz=1.0,
                            amplitude_rms_v=0.015, fs_hz=FS, seed=1, periods=8,
                            transient_periods=3)


@pytest.fixture(scope="module")
def played(multisine: ExcitationDesign, tmp_path_factory: pytest.TempPathFactory) -> TwinRun:
    folder = tmp_path_factory.mktemp("exc")
    write_excitation(multisine, folder)
    return simulate_excitation(folder, BENCH, seed=5)


def test_the_record_is_data_uch_with_the_designed_samples(multisine, played) -> None:
    ds = played.recordings["data_uch"]
    n = multisine.samples_v.size
    assert ds.sizes["t"] == START + n  # every sample once, nothing after
    uch = ds["Uch"].values
    assert np.all(uch[:START] == 0.0)
    # The DAC rounds each command to its 16-bit step: half a step.
    np.testing.assert_allclose(uch[START:], multisine.samples_v, atol=LSB / 2 + 1e-15)
    assert set(ds.data_vars) == {"Uch", "Vch", "Vph", "Vpv"}  # what the seed loads
    assert played.truth["experiments"]["data_uch"]["excitations"][0]["kind"] == "samples"


def _h1(ds, out: str, d: ExcitationDesign) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """H1 at the lines over the steady-state periods, the lines' |U| and their bins."""
    n = d.period_samples
    k0 = START + d.transient_samples
    u = ds["Uch"].values[k0:k0 + d.periods * n].reshape(d.periods, n)
    y = ds[out].values[k0:k0 + d.periods * n].reshape(d.periods, n)
    bins = np.rint(d.lines_hz * n / FS).astype(int)
    uk = np.fft.rfft(u, axis=1)[:, bins]
    yk = np.fft.rfft(y, axis=1)[:, bins]
    return (yk * uk.conj()).sum(0) / (np.abs(uk) ** 2).sum(0), np.abs(uk[0]), bins


def test_h1_at_the_grid_lines_is_the_twins_true_plant(multisine, played) -> None:
    ds = played.recordings["data_uch"]
    truth = played.truth
    plant = twin_discrete(BENCH.true)  # the sampled plant the twin runs: hold and delays
    h_true = plant.frequency_response(multisine.lines_hz)[:, :, 0]
    p = multisine.periods
    n = multisine.period_samples
    realized = truth["realized"]["data_uch"]
    q2 = truth["noise_rms"]["adc_quantisation_v"] ** 2
    gd = abs(truth["qd_gain_v_per_rad"]["h"])
    theta = max(realized["newport_angle_noise_rad"].values())
    # White noise of the ADC channel, bounded from the realised sources (twin_truth): the 4QD
    # noise, the Newport's angle noise seen twice on the beam (|row of 2 R| = 2) and the
    # ADC's rounding; the coil-voltage channel has its amplifier noise and the rounding.
    sigma = {"Vph": np.sqrt(realized["qd_noise_v"]["h"] ** 2 + (gd * 2 * theta) ** 2 + q2),
             "Vch": np.sqrt(realized["vc_noise_v"]["h"] ** 2 + q2)}
    for out in ("Vch", "Vph"):
        h, u_abs, _ = _h1(ds, out, multisine)
        ref = h_true[:, plant.output_names.index(out)]
        # Periodic input: the estimate's error is the mean of P noise DFTs over U_k, of
        # standard deviation sigma sqrt(N / P) / |U_k| per line (complex Gaussian).
        sd = sigma[out] * np.sqrt(n / p) / u_abs
        # |e| > 5 sd has probability exp(-25) = 1e-11 per line: none of 2000 may exceed it.
        z = np.abs(h - ref) / sd
        assert z.max() < 5.0, (out, z.max(), multisine.lines_hz[z.argmax()])
        # and the noise is really there (an estimate equal to the truth would be suspect):
        # the mean of |e|^2 / sd^2 is 1 for the full noise, less as the bound is loose.
        assert 0.3 < np.mean(z**2) <= 1.2, (out, np.mean(z**2))


def test_identification_grade_numbers(multisine, played) -> None:
    ds = played.recordings["data_uch"]
    truth = played.truth
    h_vch, _, _ = _h1(ds, "Vch", multisine)
    # |Vch/Uch| at 1 Hz is Ga Rc Gi of twin_truth (the 1 kHz pole and the coil's 125 kHz
    # one change it by < 1e-6); the measured noise there is 2e-4 of it.
    ga_rc_gi = (BENCH.true.voltage_amplifier.gain * BENCH.true.sercalo.r_coil_ohm.h
                * truth["current_amp_gain_a_per_v"]["h"])
    assert abs(h_vch[0]) == pytest.approx(ga_rc_gi, rel=1e-3)
    h_vph, _, _ = _h1(ds, "Vph", multisine)
    peak_hz = multisine.lines_hz[np.argmax(np.abs(h_vph))]
    # The resonance of twin_truth (411.5 Hz) lies between the 1 Hz lines 411 and 412.
    assert abs(peak_hz - truth["sercalo"]["h"]["resonance_hz"]) <= 0.5


def test_after_the_end_the_twin_repeats_a_periodic_file(multisine, tmp_path: Path) -> None:
    short = design_multisine(input="Ucv", band_hz=(5.0, 200.0), resolution_hz=5.0,
                             amplitude_rms_v=0.01, fs_hz=FS, periods=2, transient_periods=1,
                             phase_method="schroeder")
    write_excitation(short, tmp_path)
    run = simulate_excitation(tmp_path / "excitation.json", BENCH, seed=0, duration_s=3.0)
    ucv = run.recordings["data_ucv"]["Ucv"].values
    assert ucv.size == 30_000
    x = ucv[START:].reshape(-1, short.period_samples)  # 1 s of file, then 1 s more
    # Identical commands give identical DAC codes: the repeat is exact.
    np.testing.assert_array_equal(x[3:], np.broadcast_to(x[1], x[3:].shape))


def test_played_experiment_and_its_checks(multisine) -> None:
    spec = played_experiment(channel="Unh", samples_v=np.ones(100), fs_hz=FS)
    assert spec.name == INPUT_EXPERIMENTS["Unh"] == "data_unh"
    ex = spec.excitations[0]
    assert isinstance(ex, SampledExcitation) and ex.start_s == 3.0 and ex.loop_from is None
    assert spec.duration_s == 5.0  # data_unh's minimum: longer than 3 s + 100 samples
    with pytest.raises(ValueError, match="too short for data_unh"):
        played_experiment(channel="Unh", samples_v=np.ones(100), fs_hz=FS, duration_s=4.0)
    with pytest.raises(ValueError, match="unknown input 'Vph'"):
        played_experiment(channel="Vph", samples_v=np.ones(100), fs_hz=FS)


def test_a_file_at_another_rate_is_refused(tmp_path: Path) -> None:
    d = design_multisine(input="Uch", band_hz=(5.0, 100.0), resolution_hz=5.0,
                         amplitude_rms_v=0.01, fs_hz=20_000.0, phase_method="schroeder")
    write_excitation(d, tmp_path)
    with pytest.raises(ExcitationFileError, match=r"excitation.json: is sampled at 20000 Hz; "
                                                  r"the twin's bench runs at 10000 Hz"):
        simulate_excitation(tmp_path, BENCH)


def test_a_whole_identification_set_from_designed_excitations(tmp_path: Path) -> None:
    """Uch and Ucv multisines plus the ESRF study's other experiments: one folder, identified."""
    import json

    from fsmbench.ident.pipeline import IdentifyOptions, identify
    from fsmbench.io.folder import load_recordings
    from fsmbench.twin.compare import comparison_rows
    from fsmbench.twin.simulate import play_excitation

    files = []
    for inp in ("Uch", "Ucv"):
        d = design_multisine(input=inp, band_hz=(1.0, 2000.0), resolution_hz=1.0,
                             amplitude_rms_v=0.015, fs_hz=FS, seed=2, periods=6,
                             transient_periods=3)
        folder = tmp_path / inp
        folder.mkdir()
        write_excitation(d, folder)
        files.append(folder)
    out = tmp_path / "set"
    play_excitation(files, BENCH, out_dir=out, seed=4,
                    experiments=["data_cal_pd_h", "data_cal_pd_v", "data_uch", "data_unh",
                                 "data_unv"])
    truth = json.loads((out / "twin_truth.json").read_text())
    assert [f["input"] for f in truth["excitation_files"]] == ["Uch", "Ucv"]
    assert sorted(truth["experiments"]) == sorted(
        ["data_cal_pd_h", "data_cal_pd_v", "data_uch", "data_ucv", "data_unh", "data_unv"])
    with pytest.raises(ValueError, match="two excitation files play data_uch"):
        play_excitation([files[0], files[0]], BENCH, out_dir=tmp_path / "twice")
    recs = load_recordings(out, fs_hz=FS).recordings
    ident = identify(recs, bench=BENCH, options=IdentifyOptions(weights="variance"),
                     source="twin")
    assert ident.to_json()["diagnostics"]["frf_estimator"]["sercalo"] == "periodic"
    rows = comparison_rows(ident.to_json(), reference=truth, bench=BENCH)
    assert len(rows) == 20 and all(r.within_target for r in rows), [str(r) for r in rows]
