"""The written records: layout, ranges, reproducibility, and the truth's static gains."""

from __future__ import annotations

import importlib.util
import json
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.io import loadmat
from scipy.signal import butter, sosfiltfilt

from indsim import simulate_bench, write_bench
from indsim.truth import GN0

REPO = Path(__file__).resolve().parents[2]
DAC_ADC = ("Uch", "Ucv", "Unh", "Unv", "Vph", "Vpv", "Vch", "Vcv", "Vnh", "Vnv")


def _fsmbench_layout() -> dict[str, tuple[str, ...]]:
    """fsmbench's declared file layout, read from its signals module alone (no package import)."""
    path = REPO / "src" / "fsmbench" / "io" / "signals.py"
    spec = importlib.util.spec_from_file_location("_fsm_signals", path)
    mod = importlib.util.module_from_spec(spec)
    assert spec.loader is not None
    sys.modules["_fsm_signals"] = mod  # its dataclasses look their module up
    try:
        spec.loader.exec_module(mod)
    finally:
        del sys.modules["_fsm_signals"]
    return {k: tuple(v.required) for k, v in mod.EXPERIMENTS.items()}


def test_files_hold_exactly_the_layout(plain_run, tmp_path):
    """Each file holds exactly fsmbench's variables for it; t uniform at fs from 0, columns."""
    write_bench(plain_run, tmp_path)
    layout = _fsmbench_layout()
    assert sorted(p.stem for p in tmp_path.glob("*.mat")) == sorted(layout)
    fs = plain_run.truth["fs_hz"]
    for name, variables in layout.items():
        m = loadmat(tmp_path / f"{name}.mat")
        assert sorted(k for k in m if not k.startswith("__")) == sorted(variables), name
        t = m["t"]
        assert t.dtype == np.float64 and t.ndim == 2 and t.shape[1] == 1
        assert t[0, 0] == 0.0
        # Uniform within rounding of k / fs.
        np.testing.assert_allclose(np.diff(t[:, 0]), 1.0 / fs, rtol=1e-9)
        for v in variables:
            assert m[v].shape == t.shape and m[v].dtype == np.float64, (name, v)
    truth = json.loads((tmp_path / "truth.json").read_text())
    assert (truth["format"], truth["format_version"]) == ("indsim.truth", 1)


def test_signals_within_the_converters_range(runs):
    """Every ADC/DAC signal stays within ±10 V with the experimenter's margin (8 V)."""
    for name, run in runs.items():
        for exp, rec in run.records.items():
            for v, x in rec.signals.items():
                if v in DAC_ADC:
                    assert np.abs(x).max() < 8.5, (name, exp, v)
                    assert np.isfinite(x).all()


def test_seeds_are_reproducible(benches):
    """Same seed, same samples; another seed, other noise."""
    b = benches["qd_amp2_5k"]
    exps = ["data_uch", "data_huddle_test_3"]
    a = simulate_bench(b, seed=11, duration_scale=0.03, experiments=exps)
    c = simulate_bench(b, seed=11, duration_scale=0.03, experiments=exps)
    d = simulate_bench(b, seed=12, duration_scale=0.03, experiments=exps)
    for e in exps:
        for v in a.records[e].signals:
            np.testing.assert_array_equal(a.records[e].signals[v], c.records[e].signals[v])
        assert not np.array_equal(a.records[e].signals["Vph"], d.records[e].signals["Vph"])


CONTRACT = [
    "fs_hz", "qd_gain_v_per_rad.h", "qd_gain_v_per_rad.v", "current_amp_gain_a_per_v.h",
    "current_amp_gain_a_per_v.v", "newport_gain_v_per_v.h", "newport_gain_v_per_v.v",
    "delay_s.sercalo", "delay_s.newport", "effective_delay_s.sercalo",
    "effective_delay_s.newport",
    *[f"sercalo.{a}.{k}" for a in "hv" for k in ("resonance_hz", "damping_ratio",
                                                  "dc_gain_v_per_a")],
    *[f"newport.{a}.{k}" for a in "hv" for k in ("natural_freq_hz", "damping_ratio",
                                                  "internal_delay_s")],
    *[f"observable_signs.{k}" for k in ("Ich_to_Vph", "Icv_to_Vpv", "Unh_to_Vph",
                                         "Unv_to_Vpv", "Vnh_to_Vph", "Vnv_to_Vpv",
                                         "Uch_to_Vch", "Ucv_to_Vcv")],
    "controller.multiplier.h", "controller.multiplier.v", "qd_amplifier.order",
    "bench_file.values", "bench_file.departures", "name", "description", "parameters",
]


def _get(d, dotted):
    for k in dotted.split("."):
        d = d[k]
    return d


def test_truth_has_the_contracted_keys(runs):
    for run in runs.values():
        for key in CONTRACT:
            _get(run.truth, key)
        json.dumps(run.truth, allow_nan=False)  # strict JSON


def test_signs_and_multiplier_are_consistent(runs):
    """The controller's multiplier flips with the Sercalo path's sign over the calibration's."""
    for run in runs.values():
        t = run.truth
        s, mu = t["observable_signs"], t["controller"]["multiplier"]
        for ax, path, cal in (("h", "Ich_to_Vph", "Vnh_to_Vph"), ("v", "Icv_to_Vpv",
                                                                 "Vnv_to_Vpv")):
            seed_sign = -1.0 if ax == "h" else 1.0  # the seed's Kh < 0 on a plant of sign -
            assert np.sign(mu[ax]) == s[path] * s[cal] * seed_sign
            assert np.sign(t["qd_gain_v_per_rad"][ax]) == s[cal]


def _regress(x, y):
    """Least squares y = a + b x; returns b."""
    A = np.column_stack([np.ones_like(x), x])
    return np.linalg.lstsq(A, y, rcond=None)[0][1]


def test_calibration_regression_finds_the_4qd_gain(runs):
    """Seed 2.1's regression Vph on 2 gn0 Vnh against the truth's g cos θ."""
    for name, run in runs.items():
        for exp, out, met, ax in (("data_cal_pd_h", "Vph", "Vnh", "h"),
                                  ("data_cal_pd_v", "Vpv", "Vnv", "v")):
            s = run.records[exp].signals
            k0 = int(run.truth["fs_hz"])  # drop the first second (seed 2.1, t0 = 1)
            slope = _regress(2 * GN0 * s[met][k0:], s[out][k0:])
            truth = run.truth["qd_gain_v_per_rad"][ax]
            comp = run.bench.qd_compression
            # Noise: 1 mV over >2e4 samples of a >=3 mrad sweep, ~1e-3 relative; a
            # compressed 4QD reads up to ~1.3 x compression less over the sweep.
            assert slope == pytest.approx(truth, rel=3e-3 + 1.3 * comp), (name, ax)


def _static_by_regression(u, y, fs, delay, band_hz=20.0, edge_s=0.5):
    """Static gain y/u by least squares on both low-passed (zero-phase) below ``band_hz``.

    Below 20 Hz every path is flat to (f/f0)^2 < 0.7 % (modes >= 250 Hz, Newport and
    the Vc low-pass >= 450 Hz); the delay is removed by a whole-sample shift.
    Returns the slope and its standard error (effective dof 2 B T of the band).
    """
    sos = butter(4, band_hz, fs=fs, output="sos")
    ul, yl = sosfiltfilt(sos, u), sosfiltfilt(sos, y)
    d = round(delay * fs)
    ul, yl = ul[: len(ul) - d], yl[d:]
    e = int(edge_s * fs)
    ul, yl = ul[e:-e] - ul[e:-e].mean(), yl[e:-e] - yl[e:-e].mean()
    slope = (ul @ yl) / (ul @ ul)
    dof = 2.0 * band_hz * len(ul) / fs
    stderr = np.std(yl - slope * ul) / (np.std(ul) * np.sqrt(dof))
    return slope, stderr


@pytest.mark.parametrize("name", ["plain", "sercalo_h_flipped", "weak", "hot", "fs20k",
                                  "back_emf"])
def test_static_gains_match_regressions_on_the_records(runs, name):
    """Truth's static Ich -> Vph, Unh -> Vph, Uc -> Vc against least squares on the noise runs."""
    run = runs[name]
    t = run.truth
    fs = t["fs_hz"]
    for exp, u, y, expected, delay in (
        ("data_uch", "Uch", "Vph", t["sercalo"]["h"]["dc_gain_v_per_a"]
         * t["current_amp_gain_a_per_v"]["h"], t["delay_s"]["sercalo"]),
        ("data_ucv", "Ucv", "Vpv", t["sercalo"]["v"]["dc_gain_v_per_a"]
         * t["current_amp_gain_a_per_v"]["v"], t["delay_s"]["sercalo"]),
        ("data_uch", "Uch", "Vch", t["vc_gain_v_per_v"]["h"], t["delay_s"]["sercalo"]),
        ("data_unh", "Unh", "Vph", t["newport_gain_v_per_v"]["h"], t["delay_s"]["newport"]),
        ("data_unv", "Unv", "Vpv", t["newport_gain_v_per_v"]["v"], t["delay_s"]["newport"]),
    ):
        s = run.records[exp].signals
        k0 = int(fs)  # after the lead-in
        got, se = _static_by_regression(s[u][k0:], s[y][k0:], fs, delay)
        # 5 standard errors of the regression, plus 1 % for the paths' (f/f0)^2 and the
        # filter's edges.
        assert abs(got - expected) < 5 * se + 0.01 * abs(expected), (name, exp, y, got, se)


def test_closed_loop_records_are_bounded_and_track(runs):
    """Huddle 3/5 and the repeatability runs: bounded, stationary, the Sercalo cancels the
    Newport (Uc against Un in the 1 Hz line has the ratio the plant's statics say)."""
    for name, run in runs.items():
        t = run.truth
        gd = t["qd_gain_v_per_rad"]
        fs = t["fs_hz"]
        for exp in ("data_huddle_test_3", "data_huddle_test_5", "data_rep_h", "data_rep_v"):
            s = run.records[exp].signals
            for ax, vp in (("h", "Vph"), ("v", "Vpv")):
                angle = s[vp][int(fs):] / gd[ax]
                half = len(angle) // 2
                r1, r2 = np.std(angle[:half]), np.std(angle[half:])
                # Not growing: the noise excites modes ~0.3 Hz wide in closed loop, so a 2 s
                # half holds few independent values; a factor 3 tells growth from scatter.
                assert r2 < 3.0 * r1, (name, exp, ax)
                assert np.abs(angle - angle.mean()).max() < 8.0 * np.std(angle), (name, exp, ax)
                # The loop holds the beam: 1 mrad is 50x the plain bench's noise; a DAC
                # that rounds limit-cycles by a few of its steps, and the "hot" bench's
                # step is 110 urad of beam: 15 steps bound it there.
                step = (20.0 / 2**16) * abs(t["controller"]["bench_uc_to_beam_rad_per_v"][ax])
                assert np.std(angle) < max(1e-3, 15 * step), (name, exp, ax)
        for exp, un, uc, ax in (("data_rep_h", "Unh", "Uch", "h"), ("data_rep_v", "Unv", "Ucv",
                                                                     "v")):
            s = run.records[exp].signals
            k0 = int(fs) * 2
            ratio = _regress(s[un][k0:], s[uc][k0:])
            mult = t["controller"]["multiplier"][ax]
            ref = t["controller"]["reference_uc_to_beam_rad_per_v"][ax]
            newport_beam = t["newport_gain_v_per_v"][ax] / gd[ax]
            bench_beam = ref / mult  # the bench's static Uc -> beam seen through Gd
            # Uc = -Un * (Newport beam) / (Sercalo beam); the loop gain at 1 Hz (>1e3)
            # and the Newport's lag leave < 1 % of error.
            assert ratio == pytest.approx(-newport_beam / bench_beam, rel=0.01), (name, exp)


def test_corpus_covers_the_variations(benches):
    """Signs both ways, gains x0.2-x5, amplifier orders, Newport damping, rates, modes."""
    assert len(benches) >= 12
    bs = list(benches.values())
    for ax in ("h", "v"):
        assert {getattr(b.sercalo_mount_sign, ax) for b in bs} == {-1.0, 1.0}
        assert {getattr(b.qd_polarity, ax) for b in bs} == {-1.0, 1.0}
    assert {b.qd_amp_order for b in bs} == {0, 1, 2}
    assert any(min(b.newport_damping_ratio) < 1 for b in bs)
    assert any(min(b.newport_damping_ratio) > 1 for b in bs)
    assert {b.fs_hz for b in bs} >= {5000.0, 10000.0, 20000.0}
    assert any(max(b.sercalo_second_mode_hz) > 0 for b in bs)
    assert any(max(map(abs, b.sercalo_mode_angle_rad)) > 0 for b in bs)
    assert any(max(b.back_emf_v_s_per_rad) > 0 for b in bs)
    assert any(b.dac_latency_s > 0 for b in bs)
    p = benches["plain"]
    qd = [b.qd_gain_v_per_rad.h / p.qd_gain_v_per_rad.h for b in bs]
    assert min(qd) <= 0.2 + 1e-9 and max(qd) >= 5 - 1e-9


def test_every_corpus_bench_closes_a_stable_loop(benches):
    """bench_model refuses an unstable loop; check the poles again here."""
    from indsim import bench_model

    for b in benches.values():
        m = bench_model(b)
        assert m.closed.max_pole_abs < 1.0


def test_plain_bench_departs_from_nothing(plain_run):
    """The plain bench is the bench file's nominal one, signs included."""
    assert plain_run.truth["bench_file"]["departures"] == []


def test_nominal_copy_matches_the_bench_file():
    """indsim's copy of default_bench.toml's nominal values is the file's."""
    import tomllib

    from indsim.truth import NOMINAL_BENCH_FILE

    data = tomllib.loads((REPO / "src/fsmbench/bench/default_bench.toml").read_text())
    for key, value in NOMINAL_BENCH_FILE.items():
        assert _get(data, key) == value, key


def test_cli_writes_the_named_benches(tmp_path, capsys):
    from indsim.__main__ import main

    assert main([str(tmp_path), "--bench", "fs5k", "--duration-scale", "0.01"]) == 0
    out = capsys.readouterr().out.strip().splitlines()
    assert len(out) == 1 and out[0].startswith("fs5k:")
    assert len(list((tmp_path / "fs5k").glob("*.mat"))) == 13
    assert (tmp_path / "fs5k" / "truth.json").exists()


def test_bench_file_toml_round_trips(runs):
    """The TOML bench file parses and holds the truth's bench-file values."""
    import tomllib

    from indsim.truth import bench_file_toml

    for run in runs.values():
        data = tomllib.loads(bench_file_toml(run.truth))
        assert data["base"] == "default"
        for key, value in run.truth["bench_file"]["values"].items():
            assert _get(data, key) == value, key
