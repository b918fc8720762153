"""Randomly malformed recordings: a verdict or a bounded result, never a crash (issue 10).

Hypothesis breaks one or two signals of one twin recording (scales them to
nm or 1e300, makes them constant, integer counts, single precision, cuts,
drops or reverses them, puts NaN or spikes in) and writes the folder. Then
:func:`load_recordings` either raises a :class:`RecordingError` or returns
recordings on which :func:`identify` and :func:`budget_study` must run with
no Python warning, no other exception, and no absurd number: every rms they
report is within what the bench can produce, or its part was skipped.
"""

from __future__ import annotations

import json
import math
import shutil
import tempfile
import warnings
from datetime import timedelta
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from fsmbench.bench.params import Bench
from fsmbench.budget.study import budget_study
from fsmbench.checks import failed
from fsmbench.ident.calibration import MAX_GAIN_FACTOR, MIN_CALIBRATION_R2
from fsmbench.ident.pipeline import identify
from fsmbench.io import write_recording
from fsmbench.io.errors import RecordingError
from fsmbench.io.folder import MAX_VA_RMS_M, load_recordings
from fsmbench.io.matwrite import save_mat
from fsmbench.jsonutil import plain_json
from fsmbench.twin import simulate_bench

FS_HZ = 10_000.0  # the packaged bench's converter rate
ADC_HALF_SPAN_V = 10.0  # ±10 V converter: no 4QD reading can exceed it
# 3 s records: the huddle analysis needs 2 s after its 1 s trim, the 4QD
# calibration 1 s after it; shorter keeps 30 examples within ~1 s each.
RECORD_S = 3.0
NAMES = ("data_cal_pd_h", "data_cal_pd_v", "data_huddle_test_1", "data_huddle_test_2",
         "data_huddle_test_3")


@pytest.fixture(scope="module")
def template(bench: Bench, tmp_path_factory: pytest.TempPathFactory
             ) -> tuple[Path, dict[str, dict[str, np.ndarray]]]:
    """A folder of good 3 s twin records and their variables."""
    run = simulate_bench(bench, seed=4, duration_s=5.0, experiments=list(NAMES))
    folder = tmp_path_factory.mktemp("template")
    arrays: dict[str, dict[str, np.ndarray]] = {}
    for name in NAMES:
        ds = run.recordings[name].isel(t=slice(0, round(RECORD_S * FS_HZ)))
        write_recording(ds, folder / f"{name}.mat", created=0.0)
        arrays[name] = {"t": np.array(ds["t"].values)}
        arrays[name].update({str(k): np.array(v.values) for k, v in ds.data_vars.items()})
    return folder, arrays


MUTATIONS = st.one_of(
    st.tuples(st.just("scale"), st.sampled_from([0.0, -1.0, 1e-9, 1e-3, 1e3, 1e9, 1e300])),
    st.tuples(st.just("constant"), st.floats(-20.0, 20.0)),
    st.tuples(st.just("offset"), st.sampled_from([-1e6, -5.0, 3.0, 1e6])),
    st.tuples(st.just("int16"), st.just(0.0)),
    st.tuples(st.just("float32"), st.just(0.0)),
    st.tuples(st.just("truncate"), st.floats(0.0, 1.0)),
    st.tuples(st.just("nan"), st.floats(0.0, 1.0)),
    st.tuples(st.just("spike"), st.sampled_from([1e300, -1e300, 1e20, 11.0])),
    st.tuples(st.just("noise"), st.sampled_from([1e-6, 1e-3, 1.0, 100.0])),
    st.tuples(st.just("drop"), st.just(0.0)),
    st.tuples(st.just("reverse"), st.just(0.0)),
)


def _mutate(values: dict[str, Any], signal: str, kind: str, x: float,
            rng: np.random.Generator) -> None:
    v = np.asarray(values[signal], dtype=np.float64)
    n = v.size
    if kind == "scale":
        with np.errstate(over="ignore"):
            values[signal] = v * x
    elif kind == "constant":
        values[signal] = np.full(n, x)
    elif kind == "offset":
        values[signal] = v + x
    elif kind == "int16":
        values[signal] = np.clip(np.round(v / (20.0 / 2**16)), -32768, 32767).astype(np.int16)
    elif kind == "float32":
        values[signal] = v.astype(np.float32)
    elif kind == "truncate":
        values[signal] = v[: int(x * n)]
    elif kind in ("nan", "spike"):
        v = v.copy()
        v[min(int(x * n), n - 1) if kind == "nan" else rng.integers(n)] = (
            math.nan if kind == "nan" else x)
        values[signal] = v
    elif kind == "noise":
        values[signal] = v + x * rng.standard_normal(n)
    elif kind == "drop":
        del values[signal]
    elif kind == "reverse":
        values[signal] = v[::-1].copy()


def _check_budget(result: Any, skipped_checks: set[str]) -> None:
    tree = json.loads(json.dumps(result.to_json(), allow_nan=False))
    # 1 mm: the Attocube plausibility bound; no budget of this bench comes near it.
    assert math.isfinite(result.total_rms_m) and 0 < result.total_rms_m <= MAX_VA_RMS_M
    if result.huddle is not None:
        for rec in result.huddle.records.values():
            assert rec.name not in skipped_checks
            assert 0 < rec.va_rms_m <= MAX_VA_RMS_M
            assert rec.vph_rms_v <= ADC_HALF_SPAN_V and rec.vpv_rms_v <= ADC_HALF_SPAN_V
        for comp in result.huddle.comparisons:
            assert all(math.isnan(r) or (math.isfinite(r) and r > 0)
                       for r in comp.ratios.values())
            assert "inf" not in comp.sentence and "nan" not in comp.sentence
    assert isinstance(tree["checks"], list) and isinstance(tree["notices"], list)


@settings(max_examples=30, derandomize=True, database=None,
          # One example reads five files and runs identify and the budget in
          # about a second on a loaded 2-core machine; a minute is a hang.
          deadline=timedelta(seconds=60))
@given(data=st.data())
def test_malformed_recordings_give_a_verdict_or_a_bounded_result(
        template: tuple[Path, dict[str, dict[str, np.ndarray]]], bench: Bench,
        data: st.DataObject) -> None:
    folder_in, arrays = template
    name = data.draw(st.sampled_from(NAMES), label="record")
    values: dict[str, Any] = {k: v.copy() for k, v in arrays[name].items()}
    rng = np.random.default_rng(data.draw(st.integers(0, 2**16), label="rng"))
    for _ in range(data.draw(st.integers(1, 2), label="faults")):
        present = sorted(values)
        signal = data.draw(st.sampled_from(present), label="signal")
        kind, x = data.draw(MUTATIONS, label="mutation")
        _mutate(values, signal, kind, x, rng)
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp) / "data"
        shutil.copytree(folder_in, folder)
        save_mat(folder / f"{name}.mat", values, created=0.0)
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # every warning must have become a notice
            try:
                loaded = load_recordings(folder, fs_hz=FS_HZ)
            except RecordingError:
                event("rejected by load_recordings")
                return  # a verdict naming the folder: fine
            ident = identify(loaded.recordings, bench=bench)
            # df_hz = 5 Hz: the grid sets the budget's resolution, not which
            # records are used; coarse keeps every example fast.
            budget = budget_study(loaded.recordings, bench=bench, df_hz=5.0)
    bad = {c.subject.split(".mat")[0] for c in failed(loaded.checks)}
    event(f"{name} skipped by load" if name in loaded.skipped else
          f"check failed: {sorted({c.name for c in failed(loaded.checks)})}" if bad
          else "all checks passed")
    # The 4QD gains, when identified, passed their checks: no dead-channel gain.
    nominal = bench.nominal.quad_diode.gain_v_per_rad
    for axis, cal in ident.qd.items():
        assert f"data_cal_pd_{axis}" not in bad
        assert cal.r_squared >= MIN_CALIBRATION_R2
        ratio = cal.gain_v_per_rad / getattr(nominal, axis)
        assert 1 / MAX_GAIN_FACTOR <= ratio <= MAX_GAIN_FACTOR
    json.dumps(plain_json(ident.to_json()), allow_nan=False)
    _check_budget(budget, bad)


@settings(max_examples=3, derandomize=True, database=None,
          # One example is a whole study (design and its twin check ~15 s on 2 cores).
          deadline=timedelta(seconds=240),
          # capsys is read out at the start of every example, so sharing it is safe.
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_the_whole_study_on_malformed_recordings_gives_a_verdict(
        template: tuple[Path, dict[str, dict[str, np.ndarray]]],
        data: st.DataObject, capsys: pytest.CaptureFixture[str]) -> None:
    from fsmbench.cli import main

    folder_in, arrays = template
    name = data.draw(st.sampled_from(NAMES), label="record")
    values: dict[str, Any] = {k: v.copy() for k, v in arrays[name].items()}
    rng = np.random.default_rng(data.draw(st.integers(0, 2**16), label="rng"))
    signal = data.draw(st.sampled_from(sorted(values)), label="signal")
    kind, x = data.draw(MUTATIONS, label="mutation")
    _mutate(values, signal, kind, x, rng)
    with tempfile.TemporaryDirectory() as tmp:
        folder, out = Path(tmp) / "data", Path(tmp) / "out"
        shutil.copytree(folder_in, folder)
        save_mat(folder / f"{name}.mat", values, created=0.0)
        capsys.readouterr()
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            status = main(["study", "--data", str(folder), "--out", str(out)])
        err = capsys.readouterr().err
        assert "Traceback" not in err
        if status == 2:  # a verdict in one line naming the problem
            lines = [ln for ln in err.splitlines() if "error:" in ln]
            assert len(lines) == 1 and "fsmbench study: error:" in lines[0]
            assert not out.exists()
            return
        assert status == 0
        summary = json.loads((out / "summary.json").read_text())
        budget = json.loads((out / "budget.json").read_text())
        total = budget["budget"]["total_rms_m"]
        # The Attocube plausibility bound: no number of this bench comes near 1 mm.
        assert math.isfinite(total) and 0 < total <= MAX_VA_RMS_M
        # Three-valued: data contradicting themselves give "not verified", with the reason.
        assert summary["meets_specifications"] in (True, False, None)
        if summary["meets_specifications"] is None:
            assert summary["verdict_status"] == "not_verified" and (
                summary["failed_checks"] or summary["skipped"]), summary["verdict"]
        # A broken record is named in the first screen when a check or the loader refused it.
        refused = [c["subject"] for c in summary["failed_checks"]] + list(summary["skipped"])
        if signal != "t" and kind in ("scale", "int16") and x in (0.0, 1e300):
            assert any(name in r for r in refused)
