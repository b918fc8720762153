"""The twin end to end: files, truth, determinism, stability, FRFs against the model."""

from __future__ import annotations

from pathlib import Path

import control as ct
import numpy as np
import pytest
import scipy.io

from fsmbench.bench.esrf import esrf_decentralised_controller
from fsmbench.bench.params import Bench
from fsmbench.ident import hanning, spectral_matrix
from fsmbench.io.signals import EXPERIMENTS
from fsmbench.sim.controller import closed_loop_spectral_radius
from fsmbench.sim.plant import ADC_CHANNELS, twin_discrete
from fsmbench.twin import TwinRun, feedback_controller, simulate_bench, write_twin
from fsmbench.twin.experiments import esrf_experiments, with_duration
from fsmbench.twin.simulate import simulate_experiment

REQUIRED_TRUTH_KEYS = [
    "fs_hz", "qd_gain_v_per_rad.h", "qd_gain_v_per_rad.v",
    "current_amp_gain_a_per_v.h", "current_amp_gain_a_per_v.v",
    *[f"sercalo.{a}.{k}" for a in "hv" for k in ("resonance_hz", "damping_ratio",
                                                  "dc_gain_v_per_a")],
    "newport_gain_v_per_v.h", "newport_gain_v_per_v.v", "delay_s.sercalo", "delay_s.newport",
    "noise_rms.qd_noise_v.h", "noise_rms.newport_angle_noise_rad",
    "noise_rms.attocube_noise_m", "noise_rms.adc_quantisation_v",
]


def _get(tree: dict, dotted: str) -> object:
    node: object = tree
    for part in dotted.split("."):
        assert isinstance(node, dict) and part in node, f"missing key {dotted}"
        node = node[part]
    return node


def test_writes_the_seeds_thirteen_files_with_its_variables(short_twin: TwinRun,
                                                            tmp_path: Path) -> None:
    paths = write_twin(short_twin, tmp_path)
    assert sorted(p.name for p in paths) == sorted([f"{n}.mat" for n in EXPERIMENTS]
                                                   + ["twin_truth.json"])
    for name, info in EXPERIMENTS.items():
        # Read with scipy, as a MATLAB `load` would see the file.
        data = scipy.io.loadmat(tmp_path / f"{name}.mat")
        variables = sorted(k for k in data if not k.startswith("__"))
        assert variables == sorted(info.required), name
        n = data["t"].shape[0]
        for var in info.required:
            assert data[var].shape == (n, 1), (name, var)  # column vectors, as the seed loads
        np.testing.assert_allclose(np.diff(data["t"][:, 0]), 1e-4, rtol=1e-9)  # 10 kHz grid


def test_same_seed_gives_identical_files_other_seed_differs(tmp_path: Path) -> None:
    names = ["data_uch", "data_huddle_test_3"]
    a = write_twin(simulate_bench(seed=7, duration_s=3.0, experiments=names), tmp_path / "a")
    b = write_twin(simulate_bench(seed=7, duration_s=3.0, experiments=names), tmp_path / "b")
    c = write_twin(simulate_bench(seed=8, duration_s=3.0, experiments=names), tmp_path / "c")
    for pa, pb, pc in zip(a, b, c, strict=True):
        assert pa.read_bytes() == pb.read_bytes(), pa.name
        if pa.suffix == ".mat":
            assert pa.read_bytes() != pc.read_bytes(), pa.name


@pytest.mark.parametrize("fmt", ["mat5", "nexus"])
def test_records_written_as_simulated_are_write_twins_files(tmp_path: Path, fmt: str) -> None:
    # Written by the simulating threads as each record is done, or after by write_twin:
    # the same files, byte for byte (a fixed creation time makes a file a function of it).
    names = ["data_uch", "data_huddle_test_3", "data_cal_pd_h"]
    run = simulate_bench(seed=3, duration_s=3.0, experiments=names,
                         write_dir=tmp_path / "as-simulated", format=fmt)  # type: ignore[arg-type]
    after = write_twin(run, tmp_path / "after", format=fmt)  # type: ignore[arg-type]
    assert [p.name for p in run.files] == [p.name for p in after]
    for written, reference in zip(run.files, after, strict=True):
        assert written.parent == tmp_path / "as-simulated"
        assert written.read_bytes() == reference.read_bytes(), written.name
    assert simulate_bench(seed=3, duration_s=3.0, experiments=names).files == ()


def test_truth_has_the_contracted_keys_and_derived_values(short_twin: TwinRun,
                                                          bench: Bench) -> None:
    truth = short_twin.truth
    for key in REQUIRED_TRUTH_KEYS:
        value = _get(truth, key)
        assert isinstance(value, float) and np.isfinite(value), key
    p = bench.true
    assert truth["fs_hz"] == 1e4
    for axis in "hv":
        s = truth["sercalo"][axis]
        assert s["resonance_hz"] == p.sercalo.resonance_hz[axis]
        # Ich -> Vph at DC = Gd · beam factor · Sercalo gain; the 4QD rotation
        # (cos 0.015) and the axes' coupling product (3e-4) move it < 1e-3.
        expected = (p.quad_diode.gain_v_per_rad[axis]
                    * p.sercalo.beam_angle_per_mirror_angle[axis]
                    * p.sercalo.dc_gain_rad_per_a[axis])
        assert s["dc_gain_v_per_a"] == pytest.approx(expected, rel=1e-3)
        newport = (p.quad_diode.gain_v_per_rad[axis] * p.newport.beam_angle_per_mirror_angle
                   * p.newport.gain_rad_per_v[axis])
        assert truth["newport_gain_v_per_v"][axis] == pytest.approx(newport, rel=1e-3)
        # Current amplifier: Ic = Uc / (R + R_buffer + Rc) at DC.
        r_total = (p.current_amplifier.r_ohm[axis] + p.current_amplifier.r_buffer_ohm[axis]
                   + p.sercalo.r_coil_ohm[axis])
        assert truth["current_amp_gain_a_per_v"][axis] == pytest.approx(1 / r_total, rel=1e-3)
    # DAC transport (1 sample) + ZOH (half a sample); Newport adds its internal lag.
    assert truth["delay_s"]["sercalo"] == pytest.approx(1.5e-4, rel=1e-12)
    assert truth["delay_s"]["newport"] == pytest.approx(1.5e-4 + p.newport.internal_delay_s,
                                                        rel=1e-12)
    # The realised noise of each record is the injected rms to sampling error
    # (5 s = 5e4 samples: relative std of a std estimate 1/sqrt(2N) = 0.3 %).
    for name, realized in truth["realized"].items():
        assert realized["qd_noise_v"]["h"] == pytest.approx(p.quad_diode.noise_rms_v.h,
                                                            rel=0.02), name
        # The Attocube's parts are realised where the record holds Va, and only there.
        assert ("va_total" in realized) == ("Va" in EXPERIMENTS[name].required), name


def test_too_short_duration_is_refused_with_the_experiments_named() -> None:
    with pytest.raises(ValueError, match=r"too short for .*data_rep_h"):
        simulate_bench(duration_s=2.0)


def test_unknown_experiment_is_refused() -> None:
    with pytest.raises(ValueError, match="unknown experiment"):
        simulate_bench(experiments=["data_foo"])


def test_seed_controller_stabilises_the_twin_and_a_bad_one_is_refused(bench: Bench) -> None:
    p = bench.true
    plant = twin_discrete(p)
    k = esrf_decentralised_controller()
    good = feedback_controller(k, gd_v_per_rad=bench.nominal.quad_diode.gain_v_per_rad,
                               ts_s=p.converter.ts_s)
    assert closed_loop_spectral_radius(plant, good, n_adc=len(ADC_CHANNELS)) < 1.0
    # Positive feedback of the same controller (the sign the seed's -K avoids).
    bad_k = ct.ss(k.A, k.B, -k.C, -k.D, inputs=k.input_labels, outputs=k.output_labels)
    bad = feedback_controller(bad_k, gd_v_per_rad=bench.nominal.quad_diode.gain_v_per_rad,
                              ts_s=p.converter.ts_s, name="positive feedback")
    assert closed_loop_spectral_radius(plant, bad, n_adc=len(ADC_CHANNELS)) > 1.0
    with pytest.raises(ValueError, match="does not stabilise"):
        simulate_bench(experiments=["data_huddle_test_3"], duration_s=3.0, controller=bad)


def test_adc_samples_sit_on_the_16_bit_grid(short_twin: TwinRun, bench: Bench) -> None:
    lsb = bench.true.converter.lsb_v
    assert lsb == pytest.approx(20.0 / 2**16, rel=1e-15)  # ±10 V over 16 bits
    ds = short_twin.recordings["data_uch"]
    for name in ("Uch", "Vch", "Vph", "Vpv"):
        codes = ds[name].values / lsb
        np.testing.assert_allclose(codes, np.round(codes), atol=1e-6, err_msg=name)


def test_closed_loop_rejects_the_newport_motion(short_twin: TwinRun) -> None:
    """data_rep_h: the 1 Hz Newport motion reaches the 4QD attenuated by the loop."""
    ds = short_twin.recordings["data_rep_h"]
    t = ds["t"].values
    keep = t >= 2.0  # one second after the motion starts: transients gone
    tone = np.exp(-2j * np.pi * 1.0 * t[keep])
    # Lock-in amplitude of the 1 Hz component over whole periods.
    amp_cmd = 2 * abs(np.mean(ds["Unh"].values[keep] * tone))
    amp_vph = 2 * abs(np.mean(ds["Vph"].values[keep] * tone))
    open_loop = abs(short_twin.truth["newport_gain_v_per_v"]["h"]) * amp_cmd
    assert amp_cmd == pytest.approx(1.0, rel=1e-3)  # the 1 V command, DAC-quantised
    # The seed's loop has its crossover far above 1 Hz: > 20 dB rejection.
    assert amp_vph < 0.1 * open_loop


def _measured(run: TwinRun, experiment: str, inp: str, out: str):
    ds = run.recordings[experiment]
    fs = float(ds.attrs["fs_hz"])
    start = int(3.0 * fs) if experiment == "data_unh" else int(1.0 * fs)  # the seed's trims
    return spectral_matrix(ds[inp].values[start:], ds[out].values[start:], input_names=[inp],
                           output_names=[out], window=hanning(int(np.ceil(fs))), fs_hz=fs)


@pytest.mark.parametrize(("experiment", "inp", "out"), [
    ("data_uch", "Uch", "Vph"), ("data_uch", "Uch", "Vch"), ("data_ucv", "Ucv", "Vpv"),
    ("data_ucv", "Ucv", "Vcv"), ("data_unh", "Unh", "Vph"), ("data_unv", "Unv", "Vpv"),
])
def test_twin_records_match_its_discrete_plant(ident_twin: TwinRun, bench: Bench,
                                               experiment: str, inp: str, out: str) -> None:
    """The engine (noise, quantisation, delays) reproduces the discretised plant's FRF."""
    est = _measured(ident_twin, experiment, inp, out)
    f = est.frequency_hz
    plant = twin_discrete(bench.true)
    exact = plant.frequency_response(f)[:, plant.output_names.index(out),
                                        plant.input_names.index(inp)]
    h = est.frf.values[:, 0, 0]
    resonances = np.array([411.5, 251.2])
    # 10 Hz–1 kHz where coherence is high, > 15 Hz from the ~1 Hz-wide
    # resonances (the 1 s Hann window smears them: a bias, not noise).
    band = ((f >= 10) & (f <= 1000) & (est.coherence.values[:, 0, 0] > 0.9)
            & (np.min(np.abs(f[:, None] - resonances[None, :]), axis=1) > 15))
    assert band.sum() > 500
    rel = np.abs(h[band] / exact[band] - 1)
    eps = est.random_error.values[band, 0, 0]
    # Bendat & Piersol: eps is the std of |H1|'s relative error and of its
    # phase, so the complex relative error is Rayleigh(eps) if the twin is the
    # plant plus noise: median sqrt(2 ln 2) eps = 1.18 eps, P(> 4 eps) = 3e-4.
    # [0.85, 1.5] allows for eps itself being estimated from the coherence.
    assert 0.85 < np.median(rel / eps) < 1.5
    assert np.mean(rel > 4 * eps) < 0.01


@pytest.mark.parametrize(("inp", "out"), [("Uch", "Vph"), ("Ucv", "Vpv"), ("Unh", "Vph"),
                                          ("Unv", "Vpv"), ("Uch", "Vpv"), ("Unh", "Vpv")])
def test_discrete_plant_matches_the_continuous_model(bench: Bench, true_plant, inp: str,
                                                     out: str) -> None:
    """ZOH discretisation with delays equals the model (with its exact delays) below 500 Hz."""
    f = np.linspace(1.0, 500.0, 500)
    plant = twin_discrete(bench.true)
    disc = plant.frequency_response(f)[:, plant.output_names.index(out),
                                       plant.input_names.index(inp)]
    model = true_plant.frequency_response(f).sel(output=out, input=inp).values
    ts = bench.true.converter.ts_s
    # The hold's sinc(f Ts) droop (its half-sample delay is in the model's
    # delay); what remains is aliasing of the hold's images, < 1 % here.
    hold = np.sinc(f * ts)
    np.testing.assert_allclose(disc, model * hold, rtol=0.01)


def test_experiments_run_in_threads_give_the_serial_records(bench: Bench) -> None:
    # Threads only change the order of work: every noise stream is keyed by experiment
    # and source, so each record must equal its serial run bit for bit.
    names = ["data_uch", "data_huddle_test_3", "data_rep_h"]
    run = simulate_bench(bench, seed=3, duration_s=5.0, experiments=names)
    for spec in with_duration(tuple(s for s in esrf_experiments() if s.name in names),
                              duration_s=5.0):
        serial = simulate_experiment(bench, spec, seed=3).recording
        for var in serial.data_vars:
            np.testing.assert_array_equal(run.recordings[spec.name][var].values,
                                          serial[var].values)
