"""The live bench's state machine, case by case (issue 23, "What was found"), without Tango.

Most cases step :class:`LiveBench` by hand (``advance``: deterministic, no
thread); the watchdog and speed cases run its loop thread and wait with a
wall-clock timeout that fails saying what it waited for (nothing asserts on
wall-clock durations). Each test names the case it covers.
"""

from __future__ import annotations

import datetime
import errno
import json
import math
import shutil
import threading
import time
import tracemalloc
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import pytest

from fsmbench.bench.params import default_bench
from fsmbench.io.recording import read_recording
from fsmbench.live import commands, jobs
from fsmbench.live.attributes import QualityLatch, by_name, evaluate
from fsmbench.live.core import LiveBench
from fsmbench.live.loop import PacedLoop
from fsmbench.live.states import AlarmHysteresis, Refused, Ringdown
from fsmbench.live.tasks import TaskControl

BENCH = default_bench()
FS = BENCH.nominal.converter.fs_hz
WAIT_S = 60.0  # wall-clock seconds a wait may take before it fails (2 busy cores)


def wait_until(check: Callable[[], Any], what: str, *, timeout_s: float = WAIT_S) -> Any:
    deadline = time.monotonic() + timeout_s
    while True:
        value = check()
        if value:
            return value
        if time.monotonic() > deadline:
            pytest.fail(f"timed out after {timeout_s:g} s (wall clock) waiting for {what}")
        time.sleep(0.01)


def step_until(live: LiveBench, check: Callable[[], bool], what: str, *,
               bench_s: float = 120.0, block: int = 500) -> None:
    """Advance the bench by hand until ``check()``; fail after ``bench_s`` of bench time."""
    for _ in range(round(bench_s * FS / block)):
        if check():
            return
        live.advance(block)
        time.sleep(0)  # let the writer and task threads run
    pytest.fail(f"{what} did not happen within {bench_s:g} s of bench time: {live.status}")


def idle(live: LiveBench) -> None:
    step_until(live, lambda: live._job is None and live._task is None, "the end of the job",
               bench_s=300.0)


@pytest.fixture
def live(tmp_path: Path) -> Iterator[LiveBench]:
    bench = LiveBench(BENCH, seed=7, output_folder=tmp_path / "out")
    bench.advance(1000)
    yield bench
    bench.stop()


def refused(fn: Callable[..., Any], *args: Any, reason: str) -> str:
    with pytest.raises(Refused) as exc:
        fn(*args)
    assert exc.value.reason == reason, (exc.value.reason, exc.value.sentence)
    sentence = exc.value.sentence
    assert "\n" not in sentence and sentence.isascii(), sentence
    return sentence


# -- 1. State that lies -------------------------------------------------------------------


def test_reset_during_an_experiment_leaves_no_pending_restore(live: LiveBench) -> None:
    # Case 1.1: Reset during RunExperiment left a "restore" that closed the loop at the end
    # of the next Record, with no CloseLoop sent.
    live.close_loop()
    live.run_experiment("data_huddle_test_1")  # open loop: the experiment opened it
    live.advance(5000)
    assert live.state == "MOVING" and not live.loop_closed
    reply = live.reset()
    assert "stopped" in reply and "loop open" in reply
    idle(live)
    assert live.state == "ON" and not live.loop_closed
    live.record(json.dumps({"signals": ["Vph"], "duration_s": 1.0, "name": "after_reset"}))
    idle(live)
    step_until(live, lambda: False if live.loop_closed else live.bench_time_s > 10.0,
               "10 s of bench time")
    assert not live.loop_closed and live.state == "ON", live.status


def test_speed_is_bounded_and_a_new_speed_acts_at_once(tmp_path: Path) -> None:
    # Case 1.2: SpeedFactor 1e-6 put the loop to sleep for ~1e4 s while State said ON.
    live = LiveBench(BENCH, seed=1, output_folder=tmp_path, speed=1.0)
    for bad in (1e-6, 0.0, -1.0, float("nan"), float("inf"), 1e4, True):
        sentence = refused(setattr, live, "speed", bad, reason="FSM_BadArgument")
        assert "[0.01, 100]" in sentence
    live.start()
    try:
        live.speed = 0.01  # the slowest: 10 ms of bench time per wall-clock second
        wait_until(lambda: live.heartbeat > 2, "a block at speed 0.01")
        live.speed = 50.0
        t0 = live.bench_time_s
        # The old loop slept a whole block's wall time before it read the new speed.
        wait_until(lambda: live.bench_time_s > t0 + 2.0, "2 s of bench time at speed 50")
        assert live.state == "ON"
    finally:
        live.stop()


def test_a_stalled_loop_is_fault_invalid_and_reset_recovers(tmp_path: Path) -> None:
    # Cases 1.2 and 1.4: a frozen bench read as ON with valid quality; no heartbeat.
    live = LiveBench(BENCH, seed=2, output_folder=tmp_path, speed=20.0, watchdog_s=1.0)
    release = threading.Event()
    step = live.backend.step
    calls = [0]

    def stuck_step(n: int) -> Any:
        calls[0] += 1
        if calls[0] == 20:
            release.wait(60.0)  # the loop hangs inside a block
        return step(n)

    live.backend.step = stuck_step  # type: ignore[method-assign]
    live.start()
    try:
        wait_until(lambda: live.state == "FAULT", "the watchdog's FAULT")
        assert "has not advanced" in live.status, live.status
        latch = QualityLatch()
        for name in ("BenchTime", "BeamAngleH", "Heartbeat"):
            assert evaluate(by_name(name), live, latch)[1] == "INVALID", name
        assert refused(live.close_loop, reason="FSM_Fault").startswith("CloseLoop refused in "
                                                                        "FAULT")
        refused(live.record, json.dumps({"duration_s": 1}), reason="FSM_Fault")
        # Reset cannot clear it while the loop thread is stuck.
        assert "does not answer" in refused(live.reset, reason="FSM_Fault")
        release.set()
        beat = live.heartbeat
        wait_until(lambda: live.heartbeat > beat + 5, "the loop to run again")
        # Running again is not a reason to leave FAULT by itself: only Reset is.
        assert live.state == "FAULT"
        assert "cleared FAULT (stall)" in live.reset()
        assert live.state in ("ON", "ALARM")
        assert evaluate(by_name("BenchTime"), live, latch)[1] == "VALID"
    finally:
        release.set()
        live.stop()


def test_a_dead_loop_is_fault_and_reset_restarts_it(tmp_path: Path) -> None:
    # Case 1.3's other half: "Reset then returns ON with the loop dead".
    live = LiveBench(BENCH, seed=3, output_folder=tmp_path, speed=20.0)
    step = live.backend.step
    calls = [0]

    def failing_step(n: int) -> Any:
        calls[0] += 1
        if calls[0] == 10:
            raise RuntimeError("injected failure")
        return step(n)

    live.backend.step = failing_step  # type: ignore[method-assign]
    live.start()
    try:
        wait_until(lambda: live.state == "FAULT", "FAULT after the loop died")
        assert "The bench loop stopped: RuntimeError: injected failure" in live.status
        reply = live.reset()
        assert "the bench loop restarted" in reply
        t0 = live.bench_time_s
        wait_until(lambda: live.bench_time_s > t0 + 1.0, "the restarted loop to advance")
        assert live.state == "ON", live.status
    finally:
        live.stop()


def test_a_failed_write_ends_the_record_not_the_loop(live: LiveBench,
                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    # Case 1.3: a failed write at the end of a Record gave FAULT with the loop dead.
    def eisdir(*args: Any, **kwargs: Any) -> Any:
        raise IsADirectoryError(errno.EISDIR, "Is a directory", "somewhere.mat")

    monkeypatch.setattr(jobs, "write_recording", eisdir)
    live.record(json.dumps({"signals": ["Vph", "Vpv"], "duration_s": 0.5, "name": "broken"}))
    idle(live)
    assert live.state == "ON", live.status
    assert "Record broken failed" in live.status and "Is a directory" in live.status
    assert "the samples are kept in" in live.status  # the streamed NeXus file
    beat, t0 = live.heartbeat, live.bench_time_s
    live.advance(1000)
    assert live.heartbeat == beat + 1 and live.bench_time_s > t0


# -- 3. ALARM with hysteresis ---------------------------------------------------------------


def test_alarm_hysteresis_rule() -> None:
    rule = AlarmHysteresis()
    active, since = rule.next(active=False, since_s=0.0, now_s=1.0, enter_measure=0.05,
                              leave_measure=0.0)
    assert active and since == 1.0
    # Below the leave threshold, but before the minimum dwell: stays.
    assert rule.next(active=True, since_s=1.0, now_s=2.5, enter_measure=0.0,
                     leave_measure=0.0)[0]
    assert not rule.next(active=True, since_s=1.0, now_s=3.0, enter_measure=0.0,
                         leave_measure=0.0)[0]
    # Above the leave threshold after the dwell: stays.
    assert rule.next(active=True, since_s=1.0, now_s=9.0, enter_measure=0.0,
                     leave_measure=0.01)[0]


def test_alarm_time_left_when_no_converter_touches_a_rail_again() -> None:
    rule = AlarmHysteresis()  # 1 s window at 1 kHz: the alarm ends below 2 rail samples
    rails = np.zeros(1000, dtype=bool)
    assert rule.time_left_s(since_s=0.0, now_s=5.0, rails=rails, fs_hz=1e3) == 0.0
    rails[[100, 900]] = True
    # The older rail sample leaves the window after 101 new samples.
    assert rule.time_left_s(since_s=0.0, now_s=5.0, rails=rails, fs_hz=1e3) == \
        pytest.approx(0.101, abs=1e-12)
    # The 2 s dwell, when longer, decides.
    assert rule.time_left_s(since_s=4.5, now_s=5.0, rails=rails, fs_hz=1e3) == \
        pytest.approx(1.5, abs=1e-12)


def test_close_loop_waits_out_the_saturation_alarm_and_names_an_excitation(
        live: LiveBench) -> None:
    # Issue 31: CloseLoop after the rails was refused "Stop the excitation" with none running
    # (FSM_NotAllowed); the README promises FSM_Settling and the time left.
    live.start_excitation(json.dumps({"input": "Uch", "kind": "noise", "amplitude_v": 0.8}))
    step_until(live, lambda: live.state == "ALARM", "the saturation ALARM", bench_s=10.0,
               block=100)
    assert "Stop the excitation" in refused(live.close_loop, reason="FSM_NotAllowed")
    live.stop_excitation()
    live.advance(100)
    assert live.state == "ALARM"  # the 2 s dwell has not run out
    sentence = refused(live.close_loop, reason="FSM_Settling")
    assert "is no more" in sentence and "s of bench time left" in sentence, sentence
    assert "Stop the excitation" not in sentence
    step_until(live, lambda: live.state == "ON", "the ALARM to end", bench_s=5.0, block=100)
    assert "loop closed" in live.close_loop()


def test_an_intermittently_clipping_excitation_gives_few_state_changes(
        live: LiveBench) -> None:
    # Case 3.4: 86 State events in 10 s under an accepted excitation.
    live.start_excitation(json.dumps({"input": "Uch", "kind": "noise", "amplitude_v": 0.8}))
    changes, raw = 0, 0
    state, saturating = live.state, False
    for _ in range(1000):  # 10 s of bench time in 10 ms blocks
        live.advance(100)
        changes += live.state != state
        state = live.state
        now = live.monitor.saturating_now()
        raw += now != saturating
        saturating = now
    assert raw >= 20  # the case is real: the rails are hit now and then (seed 7)
    # Each ALARM lasts at least min_dwell_s (2 s): at most 2 changes per 2 s, and 1 more.
    assert 1 <= changes <= 11, (changes, raw)


# -- 5. Commands -----------------------------------------------------------------------------


def test_trip_reverts_the_controller_and_the_ringdown_refuses_close_loop(
        live: LiveBench, controller_x1: Path) -> None:
    # Cases 5.1 (CloseLoop accepted in ALARM while the mirror rings, and trips) and 5.4
    # (Reset kept the faulty controller loaded). The trip: a 3 V sine at the h mode added
    # to the loaded controller's command (a 20x controller is refused on the call now).
    live.controllers_folder.mkdir(parents=True)
    shutil.copy(controller_x1, live.controllers_folder / "controllers_sos.json")
    live.load_controller("controllers_sos.json")
    assert "fsmbench_controller" in live.controller_name
    live.close_loop()
    live.advance(1000)
    live.start_excitation(json.dumps({"input": "Uch", "kind": "sine", "amplitude_v": 3.0,
                                      "frequency_hz": 411.5}))
    step_until(live, lambda: live.state == "FAULT", "the protection's FAULT", bench_s=2.0,
               block=100)
    assert "tripped: none is loaded now" in live.status, live.status
    reply = live.reset()
    assert "no controller loaded" in reply
    assert live.state == "ALARM" and "still rings" in live.status, live.status
    sentence = refused(live.close_loop, reason="FSM_Settling")
    assert "s of bench time left" in sentence
    # The ringdown ends: the 4QD deviation falls below the settle level.
    step_until(live, lambda: live.state == "ON", "the mirror to settle", bench_s=30.0,
               block=100)
    assert live.ringdown.time_left_s(live.monitor.qd_deviation_v(0.05)) == 0
    assert "the ESRF study's controller" in live.close_loop()  # not the one that tripped
    live.advance(round(2 * FS))
    assert live.state == "RUNNING", live.status


def test_ringdown_time_left() -> None:
    ring = Ringdown(decay_time_s=(0.4, 0.8), settled_v=0.5)
    assert ring.time_left_s((0.1, 0.4)) == 0.0
    # exp(-t/0.8) from 5 V to 0.5 V: 0.8 ln 10.
    assert ring.time_left_s((1.0, 5.0)) == pytest.approx(0.8 * np.log(10.0), rel=1e-12)
    assert ring.time_left_s((float("nan"), 0.0)) == float("inf")


def test_abort_keeps_what_was_recorded(live: LiveBench) -> None:
    # Case 5.4: no Abort for a running Record or experiment.
    path = Path(live.record(json.dumps({"signals": ["Vph", "Vpv"], "duration_s": 60,
                                        "name": "long", "format": "nexus"})))
    for _ in range(4):
        live.advance(5000)  # 2 s
    reply = live.abort()
    assert "record long stopped after 2.0 s" in reply
    idle(live)
    assert live.state == "ON" and "stopped by Abort after 2.0 of 60.0 s" in live.status
    assert read_recording(path).sizes["t"] == round(2.0 * FS)
    # Issue 31: the NeXus file had no start or end time and no mark that it was cut short.
    with h5py.File(path, "r") as f:
        entry = f["entry"]
        start, end = (datetime.datetime.fromisoformat(entry[k][()].decode())
                      for k in ("start_time", "end_time"))
        assert start.tzinfo is not None and start <= end
        assert entry.attrs["ended"] == "stopped by Abort"
        assert entry.attrs["planned_duration_s"] == 60.0
        assert entry.attrs["recorded_duration_s"] == 2.0
    assert live.abort() == "nothing was running"


def test_experiment_abort_restores_the_loop(live: LiveBench) -> None:
    live.close_loop()
    path = Path(live.run_experiment("data_cal_pd_h"))  # open loop
    live.advance(5000)
    assert not live.loop_closed
    live.abort()
    assert live.loop_closed  # the loop it found: part of RunExperiment, logged with its cause
    idle(live)
    assert live.state == "RUNNING"
    assert read_recording(path).sizes["t"] == 5000


def test_long_work_runs_off_the_call_and_abort_cancels_it(
        live: LiveBench, monkeypatch: pytest.MonkeyPatch) -> None:
    # Case 5.3: a full-band multisine blocked the client's call ~5 s.
    gate = threading.Event()

    def slow_design(ex: Any, *, fs_hz: float, half_range_v: float,
                    control: TaskControl) -> Any:
        control.progress(0.4)
        while not gate.wait(0.01):
            control.progress(0.4)
        raise AssertionError("not reached: Abort cancels first")

    monkeypatch.setattr(commands, "design_multisine", slow_design)
    reply = live.start_excitation(json.dumps({"input": "Uch", "kind": "multisine",
                                              "amplitude_v": 0.1}))
    assert "designing" in reply
    assert live.state == "MOVING" and live.task_text.startswith("designing a multisine")
    wait_until(lambda: live.progress_percent == 40.0, "progress 40 %")
    assert refused(live.load_controller, __file__, reason="FSM_Busy")
    refused(live.close_loop, reason="FSM_Busy")
    assert "cancelled" in live.abort()
    assert live.state == "ON" and live.task_text == ""
    gate.set()
    assert "Aborted: designing" in live.status


def test_multisine_designed_in_the_background_starts(live: LiveBench) -> None:
    live.start_excitation(json.dumps({"input": "Uch", "kind": "multisine", "amplitude_v": 0.1,
                                      "band_hz": [1, 5000]}))
    idle(live)
    doc = json.loads(live.excitation_text)
    assert doc["kind"] == "multisine" and doc["input"] == "Uch"
    # Schroeder phases and clipping: a crest factor well below random phases' 3-4.
    assert doc["crest_factor"] < 2.0
    assert doc["peak_v"] == pytest.approx(0.1 * doc["crest_factor"], rel=1e-9)


@pytest.mark.parametrize(("doc", "words"), [
    ({"input": "Uch", "kind": "multisine", "amplitude_v": 0.1, "period_s": 0},
     "period_s must be a number of seconds in [0.01, 100]"),
    ({"input": "Uch", "kind": "multisine", "amplitude_v": 0.1, "period_s": 1e5},
     "period_s must be a number of seconds in [0.01, 100]"),
    ({"input": "Uch", "kind": "multisine", "amplitude_v": 0.1, "period_s": 0.12345},
     "not a whole number of samples"),
    ({"input": "Uch", "kind": "sine", "amplitude_v": 0.1, "frequency_hz": 1e6},
     "below Nyquist"),
    ({"input": "Uch", "kind": "noise", "amplitude_v": 0.1, "band_hz": [10, 20000]},
     "goes above Nyquist (5000 Hz"),
    ({"input": "Uch", "kind": "multisine", "amplitude_v": 0.1, "band_hz": [10, 20000]},
     "goes above Nyquist"),
    ({"input": "Uch", "kind": "noise", "amplitude_v": 0.1, "ampltude": 3}, "unknown key"),
    ({"input": "Uch", "kind": "sine", "amplitude_v": 0.1, "frequency_hz": True},
     "frequency_hz in (0, 5000)"),
])
def test_out_of_bench_arguments_are_refused(live: LiveBench, doc: dict, words: str) -> None:
    # Cases 5.5 and 6.1: period_s 0 (ZeroDivisionError), 1e5 s (15 GB), a 1 MHz sine and a
    # band to 20 kHz were accepted.
    sentence = refused(live.start_excitation, json.dumps(doc), reason="FSM_BadArgument")
    assert words in sentence, sentence
    assert live.state == "ON" and live.excitation_text == "{}"


def test_nan_is_refused_in_words(live: LiveBench) -> None:
    # Case 5.5: NaN gave "cannot convert float NaN" (JSON's NaN is Python's extension).
    for key in ("amplitude_v", "period_s"):
        doc = {"input": "Uch", "kind": "multisine", "amplitude_v": 0.1, key: float("nan")}
        refused(live.start_excitation, json.dumps(doc), reason="FSM_BadArgument")


@pytest.mark.parametrize(("name", "words"), [
    ("x" * 300, "too long for a file name"),
    ("mesure_été", "must be ASCII letters"),
    ("../escape", "must be ASCII letters"),
])
def test_names_are_checked_against_the_filesystem(live: LiveBench, name: str,
                                                  words: str) -> None:
    # Cases 6.2 (300 characters: FAULT, then a frozen bench) and 6.4 (SystemError).
    sentence = refused(live.record, json.dumps({"duration_s": 1, "name": name}),
                       reason="FSM_BadArgument")
    assert words in sentence
    t0 = live.bench_time_s
    live.advance(1000)
    assert live.state == "ON" and live.bench_time_s > t0


def test_existing_files_are_not_overwritten(live: LiveBench) -> None:
    # Case 6.3: --out on a recordings folder: RunExperiment and Record overwrote data_uch.mat.
    folder = live.output_folder
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "data_uch.mat").write_bytes(b"a recording of the real bench")
    sentence = refused(live.run_experiment, "data_uch", reason="FSM_Output")
    assert "data_uch.mat exists" in sentence and "overwrite" in sentence
    refused(live.record, json.dumps({"duration_s": 1, "name": "data_uch"}), reason="FSM_Output")
    assert (folder / "data_uch.mat").read_bytes() == b"a recording of the real bench"
    live.record(json.dumps({"duration_s": 0.1, "signals": ["Vph"], "name": "data_uch",
                            "overwrite": True}))
    idle(live)
    assert read_recording(folder / "data_uch.mat", require=()).sizes["t"] == round(0.1 * FS)


def test_durations_are_bounded_by_the_disk(live: LiveBench,
                                           monkeypatch: pytest.MonkeyPatch) -> None:
    # Case 6.5: every argument bounded (sizes against disk).
    class Usage:
        free = 100 * 2**20

    monkeypatch.setattr(jobs.shutil, "disk_usage", lambda _: Usage())
    sentence = refused(live.record, json.dumps({"duration_s": 600, "format": "nexus"}),
                       reason="FSM_Output")
    assert "needed for 600 s of 11 signals" in sentence and "free in" in sentence
    sentence = refused(live.record, json.dumps({"duration_s": 600}), reason="FSM_Output")
    assert 'ask "format": "nexus"' in sentence  # a .mat this long is built in memory


def test_a_record_streams_to_disk(live: LiveBench) -> None:
    # Case 7: Record held every sample in RAM until the end (300 s: +1 GB).
    block = 500  # samples per hand-stepped block (step_until)
    signals = 11
    tracemalloc.start()
    try:
        path = Path(live.record(json.dumps({"duration_s": 60, "format": "nexus",
                                            "name": "stream"})))
        base = tracemalloc.get_traced_memory()[0]
        tracemalloc.reset_peak()
        idle(live)
        peak = tracemalloc.get_traced_memory()[1] - base
    finally:
        tracemalloc.stop()
    held = 60 * FS * (signals + 1) * 8  # every sample of the 11 signals and t: 58 MB
    # Streamed, the peak does not grow with the duration: at most a full queue (the writer
    # thread may fall behind a hand-stepped bench on a busy machine), one HDF5 batch, and
    # 8 MB of the rest (9 MB measured in all for 20 s and 60 s with the queue near empty:
    # the spectra's temporaries, the batch). Below half of held, so it fails if the samples
    # are kept.
    bound = (jobs.QUEUE_BLOCKS * block + jobs.BATCH_SAMPLES) * signals * 8 + 8 * 2**20
    assert bound < held / 2
    assert peak < bound, (peak / 2**20, bound / 2**20, held / 2**20)
    assert read_recording(path).sizes["t"] == round(60 * FS)


# -- 4. Quality ----------------------------------------------------------------------------


def test_quality_from_limits_with_hysteresis_and_invalid_when_not_finite(
        live: LiveBench, monkeypatch: pytest.MonkeyPatch) -> None:
    # Case 4.1: quality was always VALID (NaN, 0.177 rad in FAULT, a frozen bench).
    latch = QualityLatch()
    spec = by_name("BeamAngleH")
    values = iter([0.177, 0.148, 0.144, 0.06, 0.01, float("nan")])
    monkeypatch.setattr(live.monitor, "beam_angle_rad", lambda: (next(values), 0.0))
    # 177000 urad: ALARM; 148000: inside the limit but not by the 5000 urad hysteresis;
    # 144000: WARNING; 60000: WARNING; 10000: VALID; NaN: INVALID.
    got = [evaluate(spec, live, latch)[1] for _ in range(6)]
    assert got == ["ALARM", "ALARM", "WARNING", "WARNING", "VALID", "INVALID"]


# -- An excitation in closed loop (for issue 24's loop that watches itself) -----------------


def test_an_excitation_in_running_is_added_at_the_controller_output(tmp_path: Path) -> None:
    # Two twins of one seed, closed alike; one gets a sine on Uch while RUNNING. What the
    # controller added is K applied to the difference of the 4QD readings it read (linear,
    # zero difference of state when the sine starts), so the DAC difference less that part
    # is what was added after the controller: the sine itself, to DAC quantisation.
    twins = [LiveBench(BENCH, seed=5, output_folder=tmp_path / name) for name in ("a", "b")]
    for live in twins:
        live.advance(1000)
        live.close_loop()
        live.advance(round(2 * FS))
    excited = twins[0]
    reply = excited.start_excitation(json.dumps({"input": "Uch", "kind": "sine",
                                                 "amplitude_v": 0.2, "frequency_hz": 37}))
    assert "sine on Uch started" in reply and excited.state == "RUNNING"
    paths = [Path(live.record(json.dumps({"signals": ["Uch", "Ucv", "Vph", "Vpv"],
                                          "duration_s": 1.0, "name": "x"}))) for live in twins]
    for live in twins:
        idle(live)
    assert excited.state == "RUNNING" and excited.loop_closed, excited.status
    a, b = (read_recording(p) for p in paths)
    np.testing.assert_array_equal(a["t"].values, b["t"].values)
    d_u = np.column_stack([a[s].values - b[s].values for s in ("Uch", "Ucv")])
    d_y = np.column_stack([a[s].values - b[s].values for s in ("Vph", "Vpv")])
    k = excited.backend.controller
    assert k is not None
    x = np.zeros(k.a.shape[0])
    by_controller = np.zeros_like(d_u)
    for i, e in enumerate(d_y):
        by_controller[i] = k.c @ x + k.d @ e
        x = k.a @ x + k.b @ e
    added = d_u - by_controller
    t = a["t"].values
    basis = np.column_stack([np.sin(2 * np.pi * 37.0 * t), np.cos(2 * np.pi * 37.0 * t)])
    coef = np.linalg.lstsq(basis, added[:, 0], rcond=None)[0]
    lsb = BENCH.nominal.converter.lsb_v
    # The controller's part is large (it must be removed for the check to mean anything).
    assert np.abs(by_controller[:, 0]).max() > 100 * lsb
    # Each run's DAC rounds by at most half an LSB: their difference by at most one.
    assert np.abs(added[:, 0] - basis @ coef).max() <= 1.001 * lsb
    assert np.abs(added[:, 1]).max() <= 1.001 * lsb  # nothing added to Ucv
    assert abs(np.hypot(*coef) - 0.2) < lsb


@pytest.mark.parametrize("command", ["start_excitation", "run_experiment", "record",
                                     "load_controller"])
def test_deeply_nested_json_is_a_bad_argument(live: LiveBench, command: str) -> None:
    # Issue 31: "[[[[…]]]]" 100 000 deep answered FSM_Internal "RecursionError".
    deep = "{\"a\": " + "[" * 100_000 + "]" * 100_000 + "}"
    state = live.state
    sentence = refused(getattr(live, command), deep, reason="FSM_BadArgument")
    assert "nests too deeply" in sentence, sentence
    assert live.state == state


def test_paced_loop_measures_the_speed_it_reaches() -> None:
    # Issue 31: SpeedFactor 10 ran at 1.88x and nothing said so. A step that takes at least
    # as long in wall clock as in bench time caps the loop at 1x whatever is asked (sleeps
    # only lengthen), so asking 4x must read at most ~1x.
    bench_time = [0.0]

    def step() -> float:
        time.sleep(0.01)
        bench_time[0] += 0.01
        loop.beat()
        return bench_time[0]

    loop = PacedLoop(step=step, speed=lambda: 4.0, block_s=lambda: 0.01, watchdog_s=30.0,
                     on_stall=lambda lag: None, on_death=lambda exc: None)
    assert math.isnan(loop.reached_speed)  # nothing run yet
    loop.start()
    try:
        wait = time.monotonic()
        while math.isnan(loop.reached_speed) and time.monotonic() - wait < 60.0:
            time.sleep(0.05)
        reached = loop.reached_speed
    finally:
        loop.stop()
    # 2 s of pairs, each step's clock read after its sleep: at most 1x, plus one step's
    # worth of the window's ends (0.01 s over >= 1 s).
    assert 0.0 < reached <= 1.02, reached


def test_a_slow_pace_is_a_warning_once_and_cleared_once(
        live: LiveBench, monkeypatch: pytest.MonkeyPatch) -> None:
    logged: list[tuple[str, str]] = []
    monkeypatch.setattr(live, "log", lambda level, message: logged.append((level, message)))
    reached = [float("nan")]
    monkeypatch.setattr(PacedLoop, "reached_speed", property(lambda self: reached[0]))
    live.speed = 10.0
    logged.clear()
    for value in (9.5, 1.88, 1.9, 8.0, 9.6, 9.7, 1.0):  # SpeedFactor 10
        reached[0] = value
        live.advance(round(FS))  # one bench second: one look at the pace
    warnings = [m for level, m in logged if level == "WARNING"]
    back = [m for level, m in logged if "again" in m]
    assert len(warnings) == 2 and "1.88x, 19 % of the SpeedFactor 10" in warnings[0], logged
    assert len(back) == 1 and "9.6x again" in back[0], logged  # 8.0 is not yet 95 %
    assert live.speed_reached == 1.0
