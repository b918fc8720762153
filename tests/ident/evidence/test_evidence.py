"""The evidence the records carry about the bench (fsmbench.ident.evidence, issue 30).

Each module is checked against something it does not compute itself: the sign
explanations against a brute-force parity check of every assignment, the
recorded controller against the twin's own loop (python-control's Tustin
realisation, not the fitted second-order sections), the rate witness against
records whose ``t`` is rescaled, and the bench file that matches the records
against a rerun of the identification.
"""

from __future__ import annotations

import itertools
from collections.abc import Mapping

import numpy as np
import pytest
import xarray as xr
from hypothesis import given, settings
from hypothesis import strategies as st

from fsmbench.bench.params import default_bench
from fsmbench.ident.evidence.bench_signs import diagnose_signs, with_signs
from fsmbench.ident.evidence.departures import (
    departures,
    get_key,
    matching_params,
    measured_keys,
    set_key,
)
from fsmbench.ident.evidence.rate import records_rate
from fsmbench.ident.evidence.recorded_loop import rate_witness, recorded_controllers
from fsmbench.ident.evidence.signs import SignCause, SignObservation, explain_signs
from fsmbench.twin import TwinRun, simulate_bench

LOOP = ["data_huddle_test_3", "data_rep_h", "data_rep_v"]
STEP_V = 20.0 / 2**16


# --------------------------------------------------------------------------- signs
#: The observation structure of one axis with every record (ident.consistency's letters).
def _structure(axis: str) -> list[tuple[str, str, str, tuple[str, ...]]]:
    return [(f"data_cal_pd_{axis}", f"Vn{axis}", f"Vp{axis}", ("q", "r")),
            (f"data_uc{axis}", f"Uc{axis}", f"Vp{axis}", ("q", "m", "i")),
            (f"data_uc{axis}", f"Uc{axis}", f"Vc{axis}", ("c", "i")),
            (f"data_un{axis}", f"Un{axis}", f"Vp{axis}", ("q", "n")),
            (f"data_rep_{axis}", f"Un{axis}", f"Vn{axis}", ("n", "r")),
            ("data_huddle_test_3", f"Vp{axis}", f"Uc{axis}", ("q", "m", "i")),
            ("data_rep_h", f"Vp{axis}", f"Uc{axis}", ("q", "m", "i"))]


def _observe(axis: str, bench: set[str], flips: set[tuple[str, str]]
             ) -> list[SignObservation]:
    out = []
    for record, inp, outp, letters in _structure(axis):
        n = sum(b in bench for b in letters) + sum(
            (record, s) in flips for s in (inp, outp))
        out.append(SignObservation(record, inp, outp, letters, -1 if n % 2 else 1))
    return out


def _explains(causes: tuple[SignCause, ...], obs: list[SignObservation]) -> bool:
    """Parity of each observation under the causes, computed directly."""
    for o in obs:
        n = sum(1 for c in causes if (c.kind == "bench" and c.name in o.bench)
                or (c.kind == "record" and c.record == o.record
                    and c.name in (o.input, o.output)))
        if (-1 if n % 2 else 1) != o.sign:
            return False
    return True


@settings(max_examples=60, deadline=None, derandomize=True)
@given(bench=st.sets(st.sampled_from("qminrc"), max_size=2),
       flip=st.one_of(st.none(), st.sampled_from(
           [(r, s) for r, i, o, _ in _structure("h") for s in (i, o)])))
def test_every_explanation_explains_and_none_is_smaller(bench: set[str],
                                                        flip: tuple[str, str] | None) -> None:
    obs = _observe("h", bench, {flip} if flip else set())
    d = explain_signs(obs, axis="h")
    assert d.explained
    size = len(d.explanations[0])
    assert all(len(e) == size and _explains(e, obs) for e in d.explanations)
    # Brute force over every set of fewer causes: none explains (minimality).
    variables = [SignCause("bench", "h", b) for b in "qminrc"] + [
        SignCause("record", "h", s, r) for r, i, o, _ in _structure("h") for s in (i, o)]
    variables = list(dict.fromkeys(variables))
    for k in range(size):
        assert not any(_explains(c, obs) for c in itertools.combinations(variables, k))
    # The truth is among the explanations whenever it is one of the smallest.
    true = {SignCause("bench", "h", b) for b in bench} | (
        {SignCause("record", "h", flip[1], flip[0])} if flip else set())
    if len(true) == size:
        assert any(set(e) == true for e in d.explanations)


def test_a_mount_flipped_with_its_loop_is_a_finding_and_a_flip_alone_a_contradiction() -> None:
    params = default_bench().nominal
    mount = diagnose_signs(_observe("h", {"m"}, set()), params=params)
    assert mount.checks[0].passed and [f.key for f in mount.findings] == [
        "nominal.sercalo.beam_angle_per_mirror_angle.h"]
    assert mount.params.sercalo.beam_angle_per_mirror_angle.h == \
        -params.sercalo.beam_angle_per_mirror_angle.h
    flip = diagnose_signs(_observe("h", set(), {("data_uch", "Vph")}), params=params)
    assert not flip.checks[0].passed and flip.findings == ()
    assert "Vph in data_uch.mat is recorded with its sign flipped" in flip.checks[0].advice
    assert "negate" in flip.checks[0].advice  # one cause left: advice may change data
    assert list(flip.by_experiment) == ["data_uch"]
    assert flip.params == params


def test_with_signs_reverses_exactly_the_named_keys() -> None:
    params = default_bench().nominal
    causes = [SignCause("bench", "v", "q"), SignCause("bench", "h", "r"),
              SignCause("record", "h", "Vph", "data_uch")]
    out = with_signs(params, causes)
    assert out.quad_diode.gain_v_per_rad.v == -params.quad_diode.gain_v_per_rad.v
    assert out.quad_diode.gain_v_per_rad.h == params.quad_diode.gain_v_per_rad.h
    assert out.newport.metrology_sign.h == -1.0 and out.newport.metrology_sign.v == 1.0
    assert with_signs(out, causes) == params  # reversing twice is the identity


# --------------------------------------------------------------------------- recorded loop
@pytest.fixture(scope="module")
def loop_run() -> TwinRun:
    return simulate_bench(seed=3, duration_s=5.0, experiments=LOOP)


def test_the_recorded_controller_is_the_twin_s(loop_run: TwinRun) -> None:
    # The twin divides by the bench file's 4QD gains (its esrf_feedback): the fit must
    # find them. 1e-3 relative: the command's rounding to the DAC's step is the residual.
    found = recorded_controllers(loop_run.recordings, fs_hz=1e4, step_v=STEP_V)
    gd = default_bench().nominal.quad_diode.gain_v_per_rad
    for axis in "hv":
        r = found[axis]
        assert r.verdict == "seed"
        assert r.gd_used_v_per_rad == pytest.approx(gd[axis], rel=1e-3)
        assert abs(r.gd_used_v_per_rad - gd[axis]) < 5 * r.gd_used_std_v_per_rad + 1e-9


def _replaced(recs: Mapping[str, xr.Dataset], signal: str, value: np.ndarray | float
              ) -> dict[str, xr.Dataset]:
    out = {}
    for name, ds in recs.items():
        ds = ds.copy(deep=True)
        if signal in ds:
            ds[signal] = (("t",), np.broadcast_to(value, ds[signal].shape).copy())
        out[name] = ds
    return out


def test_a_zero_command_is_no_closed_loop_and_noise_is_another_controller(
        loop_run: TwinRun) -> None:
    zero = recorded_controllers(_replaced(loop_run.recordings, "Uch", 0.0), fs_hz=1e4,
                                step_v=STEP_V)
    assert zero["h"].verdict == "zero" and "not closed" in zero["h"].words()
    n = loop_run.recordings["data_rep_h"]["Uch"].size
    noise = np.random.default_rng(0).normal(0.0, 0.1, n)
    other = recorded_controllers(_replaced(loop_run.recordings, "Uch", noise), fs_hz=1e4,
                                 step_v=STEP_V)
    assert other["h"].verdict == "other"


@pytest.mark.parametrize("factor", [2.0, 0.5])
def test_a_t_off_by_an_octave_is_witnessed_by_the_controller(loop_run: TwinRun,
                                                             factor: float) -> None:
    # The samples are the twin's at 10 kHz; t read with another step puts the rate at
    # 10 kHz / factor, and the controller explains the commands only at 10 kHz.
    assert not rate_witness(loop_run.recordings, fs_hz=1e4, step_v=STEP_V).contradicts
    w = rate_witness(loop_run.recordings, fs_hz=1e4 / factor, step_v=STEP_V)
    assert w is not None and w.contradicts and w.fs_hz == 1e4


def test_the_records_rate_decides_and_an_odd_record_is_named(loop_run: TwinRun) -> None:
    recs = {n: ds.assign_attrs(fs_hz=2e4) for n, ds in loop_run.recordings.items()}
    found = records_rate(recs, bench_fs_hz=1e4)
    assert found.fs_hz == 2e4 and found.checks == ()
    assert [f.key for f in found.findings] == ["nominal.converter.fs_hz"]
    odd = dict(recs)
    odd["data_rep_v"] = odd["data_rep_v"].assign_attrs(fs_hz=1e4)
    found = records_rate(odd, bench_fs_hz=1e4)
    assert found.fs_hz == 2e4 and list(found.by_experiment) == ["data_rep_v"]
    assert "either this record was made at another rate" in found.checks[0].advice


# --------------------------------------------------------------------------- departures
def test_keys_round_trip_and_the_matching_bench_has_no_departure() -> None:
    params = default_bench().nominal
    key = "nominal.sercalo.resonance_hz.v"
    assert get_key(set_key(params, key, 250.0), key) == 250.0
    assert get_key(set_key(params, "nominal.converter.fs_hz", 2e4),
                   "nominal.converter.fs_hz") == 2e4
    js = {"qd_gain_v_per_rad": {"h": -40.0, "v": 36.3},
          "sercalo": {"h": {"resonance_hz": 400.0, "damping_ratio": 1e-3,
                            "dc_gain_v_per_a": -40.0 * -4.0 * 0.7}},
          "current_amp_gain_a_per_v": {"h": 1.0 / 80.0}}
    measured = measured_keys(js, params=params)
    by_key = {m.key: m.value for m in measured}
    # Ich → Vph = Gd · beam · g0 and Gi = 1/(R + Rc + Rbuf), inverted by hand.
    assert by_key["nominal.sercalo.dc_gain_rad_per_a.h"] == pytest.approx(0.7, rel=1e-12)
    assert by_key["nominal.current_amplifier.r_buffer_ohm.h"] == pytest.approx(
        80.0 - params.current_amplifier.r_ohm.h - params.sercalo.r_coil_ohm.h, rel=1e-12)
    found = {f.key for f in departures(measured, bench_file=params, fs_hz=1e4)}
    assert {"nominal.quad_diode.gain_v_per_rad.h", "nominal.sercalo.resonance_hz.h"} <= found
    assert "nominal.quad_diode.gain_v_per_rad.v" not in found  # equal: no departure
    matching = matching_params(params, measured)
    assert departures(measured, bench_file=matching, fs_hz=1e4) == []


@pytest.mark.parametrize("factor", [1.0, 2.0, 0.5])
def test_the_coil_path_s_corners_witness_the_rate(factor: float) -> None:
    # Without a closed-loop record the coil path is the witness: its corners are in Hz.
    from fsmbench.ident.evidence.rate import current_amplifier_rate_check

    run = simulate_bench(seed=2, duration_s=5.0, experiments=["data_uch"])
    ds = run.recordings["data_uch"]
    moved = ds.assign_coords(t=ds["t"].values * factor)
    moved.attrs["fs_hz"] = 1e4 / factor
    check = current_amplifier_rate_check({"data_uch": moved}, params=default_bench().nominal,
                                         trim_s=factor)
    assert check is not None and check.passed == (factor == 1.0)
    if factor != 1.0:
        assert check.value == pytest.approx(1e4) and "sampled at 10000 Hz" in check.advice


@settings(max_examples=20, deadline=None, derandomize=True)
@given(gain=st.floats(min_value=-2.0, max_value=2.0).filter(lambda g: abs(g) > 0.1),
       offset=st.floats(min_value=-1.0, max_value=1.0), seed=st.integers(0, 2**31))
def test_the_recorded_loop_fit_is_the_full_least_squares(gain: float, offset: float,
                                                         seed: int) -> None:
    """The controller's coefficient with the polynomial projected out once equals the
    coefficient of numpy's least squares on the whole design [K y, 1, t, t^2]
    (Frisch-Waugh-Lovell); 1e-9 relative: two well-conditioned 4-column solves of the same
    problem, far above their rounding (~1e-15) and far below any effect on a verdict."""
    import scipy.signal

    from fsmbench.ident.evidence.recorded_loop import SETTLE_S, esrf_sos, fit_record

    rng = np.random.default_rng(seed)
    fs = 10_000.0
    n = 20_000
    y = rng.standard_normal(n)
    k0 = round(SETTLE_S * fs)
    sos = esrf_sos("h", fs)
    w = scipy.signal.sosfilt(sos, y - y.mean())
    t = np.arange(n - k0) / fs
    t = t / t[-1]
    u = np.zeros(n)
    u[k0:] = gain * w[k0:] + offset * (1.0 + t - t * t) + 0.01 * rng.standard_normal(n - k0)
    fit = fit_record("r", u, y, axis="h", fs_hz=fs, step_v=1e-3)
    lag = fit.lag_samples  # the lag the fit kept, 0 here unless noise decides otherwise
    yl = np.concatenate([np.zeros(lag), y[:n - lag]]) - y.mean()
    x = np.column_stack([scipy.signal.sosfilt(sos, yl)[k0:], np.ones_like(t), t, t * t])
    coef, *_ = np.linalg.lstsq(x, u[k0:], rcond=None)
    assert -1.0 / fit.gd_used_v_per_rad == pytest.approx(coef[0], rel=1e-9)
    resid = u[k0:] - x @ coef
    assert fit.explained == pytest.approx(1.0 - np.var(resid) / np.var(u[k0:]), rel=1e-9)
