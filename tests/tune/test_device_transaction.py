"""``tune --device`` as a transaction (issue 31): INVALID readings read again, the decision
written before the load, an interruption rolled back to the controller that ran before.

Each test runs its own twin device (the ``device`` fixture: 50x real time, loop closed by
the ESRF study's controller). ``invalid_reads`` makes the device answer reads with quality
INVALID (PyTango's value None), as it does on a busy machine when it cannot take its
bench's lock in 0.5 s; the interruption is a ``KeyboardInterrupt`` raised from the
target's ``load`` once the device runs the candidate. Nothing asserts on wall clock.
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

import control as ct
import pytest

pytest.importorskip("tango")

from fsmbench.bench.esrf import esrf_decentralised_controller
from fsmbench.bench.params import Bench
from fsmbench.cli import EXIT_SIGINT, EXIT_SIGTERM, Terminated, main
from fsmbench.control.controller import Controller, controller_of
from fsmbench.tune.device import DeviceTarget
from fsmbench.tune.guarded import TuneOptions, TuneResult, tune_guarded
from fsmbench.tune.measure import MeasurementOptions
from fsmbench.tune.reads import DeviceReadError
from fsmbench.tune.transaction import LoopChangeError

SEED_NAME = "the ESRF study's controller (9.2)"  # what the device calls it
# Two measured stages of 4 periods (the CLI test's, which locates both modes within 0.5 %);
# no Newport sine is played on the device. These tests need the candidate loaded to test
# the transaction around the load, so any gain loads it (better_by 0): a 4.5 s watch reads
# the running loop's error anywhere in 37-47 µrad on the twin (12 seeds), and the candidate
# predicts 33, so the rule's 10 % (tested in test_guarded) refused it in one CI run.
# For the same reason the phase margin asked is 25°, not 30: the candidate is designed on the
# bench file to 30° over its robust set, so on the 4-period identification of the twin its v
# margin reads 29.9-30.6° (8 twin seeds; below 30 in one of them and in one CI run, which
# refused it); refusal on margins is tested in test_device (a x0.3 gain, ~22°).
OPTIONS = TuneOptions(watch_s=6.0, settle_s=1.5, disturbance_v=0.0, better_by=0.0,
                      min_phase_margin_deg=25.0, measurement=MeasurementOptions(periods=4))


def _seed(bench: Bench) -> Controller:
    gd = bench.nominal.quad_diode.gain_v_per_rad
    k = esrf_decentralised_controller()
    k = ct.ss(k.A, k.B, k.C, k.D, inputs=["Rh", "Rv"], outputs=["Uch", "Ucv"])
    return controller_of(k, name=SEED_NAME, ts_s=bench.true.converter.ts_s,
                         gd_v_per_rad=(float(gd.h), float(gd.v)))


def test_invalid_readings_are_read_again_and_tune_goes_on(
        device: tuple[Any, str], invalid_reads: Any, bench: Bench, fsmbench_loop: Controller,
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    proxy, address = device
    # Three INVALID answers to the first reads of each attribute tune checks the device
    # with, and three more of SpeedFactor once the candidate is in the loop.
    for name in ("LoopClosed", "Controller", "SpeedFactor", "Task"):
        invalid_reads.arm(name, 3)
    target = DeviceTarget(proxy, bench=bench, running=_seed(bench), folder=tmp_path / "files",
                          address=address, running_source="seed")
    load = target.load

    def load_then_invalid(loop: Controller) -> dict[str, Any]:
        switch = load(loop)
        invalid_reads.arm("SpeedFactor", 3)
        return switch

    monkeypatch.setattr(target, "load", load_then_invalid)
    records: list[TuneResult] = []
    r = tune_guarded(target=target, bench=bench, running=_seed(bench), options=OPTIONS, seed=1,
                     candidate=fsmbench_loop, journal=records.append)
    # Every INVALID answer reached tune and was read again; tune went on to the end.
    assert r.decision in ("loaded", "rolled_back"), r.reason
    assert invalid_reads.served == {"LoopClosed": 3, "Controller": 3, "SpeedFactor": 6,
                                    "Task": 3}
    assert all(left == 0 for left in invalid_reads.left.values())
    assert r.transaction is not None and r.transaction["outcome"] == r.decision
    assert [rec.decision for rec in records] == ["loading", r.decision]
    assert proxy.Controller == r.transaction["left_on"] and proxy.LoopClosed


def test_an_attribute_invalid_beyond_the_bound_is_named_and_rolled_back(
        device: tuple[Any, str], invalid_reads: Any, bench: Bench, fsmbench_loop: Controller,
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    proxy, address = device
    # A 1 s bound (twenty reads) instead of 10 s: the test's time, not asserted.
    target = DeviceTarget(proxy, bench=bench, running=_seed(bench), folder=tmp_path / "files",
                          address=address, running_source="seed", invalid_wait_s=1.0)
    load = target.load
    in_loop: list[str] = []

    def load_then_invalid(loop: Controller) -> dict[str, Any]:
        switch = load(loop)
        in_loop.append(proxy.Controller)
        invalid_reads.forever("SpeedFactor")  # the attribute of the TypeError
        return switch

    monkeypatch.setattr(target, "load", load_then_invalid)
    records: list[TuneResult] = []
    with pytest.raises(LoopChangeError) as err:
        tune_guarded(target=target, bench=bench, running=_seed(bench), options=OPTIONS,
                     seed=1, candidate=fsmbench_loop, journal=records.append)
    message = str(err.value)
    assert isinstance(err.value.__cause__, DeviceReadError)
    assert "SpeedFactor" in message and "INVALID" in message and address in message
    # The candidate was in the loop; the device is back on the seed, through its own
    # LoadController, and the message's sentence says so.
    assert in_loop and in_loop[0] != SEED_NAME
    assert proxy.Controller == SEED_NAME and proxy.LoopClosed
    assert f"The device is left on {SEED_NAME}" in err.value.sentence
    assert err.value.sentence in message
    last = records[-1]
    assert [rec.decision for rec in records] == ["loading", "interrupted"]
    assert last.transaction is not None
    assert last.transaction["left_on"] == SEED_NAME
    assert last.transaction["rollback"]["done"] is True
    assert last.transaction["rollback"]["switch"]["request"] == "seed"


@pytest.mark.parametrize(("signal_name", "exit_status", "cause"), [
    ("SIGINT", EXIT_SIGINT, "interrupted (Ctrl-C)"),
    ("SIGTERM", EXIT_SIGTERM, "terminated (SIGTERM)"),
])
def test_tune_device_interrupted_after_the_load_returns_to_the_previous_controller(
        device: tuple[Any, str], tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str], signal_name: str, exit_status: int,
        cause: str) -> None:
    # The signal as the CLI receives it: Ctrl-C is a KeyboardInterrupt, SIGTERM the CLI's
    # handler's Terminated.
    interruption: BaseException = KeyboardInterrupt() if signal_name == "SIGINT" \
        else Terminated()
    proxy, address = device
    out = tmp_path / "tune"
    load = DeviceTarget.load
    seen: dict[str, Any] = {}

    def load_then_interrupt(self: DeviceTarget, loop: Controller) -> dict[str, Any]:
        seen["record"] = json.loads((out / "tune.json").read_text())  # before the load
        seen["switch"] = load(self, loop)
        seen["in_loop"] = proxy.Controller
        raise interruption  # the moment the candidate is in the loop

    monkeypatch.setattr(DeviceTarget, "load", load_then_interrupt)
    assert main(["tune", "--device", address, "--out", str(out), "--watch-s", "6",
                 "--periods", "4", "--seed", "1"]) == exit_status
    # The record before the load: the decision, the measurement, the controller before.
    first = seen["record"]
    assert first["decision"] == "loading"
    assert first["transaction"]["running_before"]["name"] == SEED_NAME
    assert first["transaction"]["running_before"]["restore_with"][0] == "seed"
    assert set(first["before"]["measured_rms_rad"]) == {"h", "v"}
    assert seen["in_loop"] == seen["switch"]["to"] != SEED_NAME
    # Rolled back through the device's LoadController, and said so.
    assert proxy.Controller == SEED_NAME and proxy.LoopClosed
    js = json.loads((out / "tune.json").read_text())
    assert js["decision"] == "interrupted"
    tx = js["transaction"]
    assert tx["outcome"] == "interrupted" and tx["cause"] == cause
    assert tx["left_on"] == SEED_NAME and tx["rollback"]["done"] is True
    captured = capsys.readouterr()
    assert f"The device is left on {SEED_NAME}" in captured.out
    assert cause in captured.err and "left as it was" not in captured.err


def test_a_trip_under_the_watch_is_said_and_nothing_is_loaded_on_a_faulted_device(
        device: tuple[Any, str], bench: Bench, fsmbench_loop: Controller, tmp_path: Path,
        monkeypatch: pytest.MonkeyPatch) -> None:
    # The protection trips the candidate while tune watches it (a 3 V sine at the h mode
    # added to its command, as the live trip tests do). The device opens the loop itself;
    # tune must say so and what to do, not load a controller into a FAULT (refused) nor
    # report the candidate as watched.
    proxy, address = device
    target = DeviceTarget(proxy, bench=bench, running=_seed(bench), folder=tmp_path / "files",
                          address=address, running_source="seed")
    load = target.load
    loads: list[str] = []

    def load_then_trip(loop: Controller) -> dict[str, Any]:
        switch = load(loop)
        proxy.StartExcitation(json.dumps({"input": "Uch", "kind": "sine", "amplitude_v": 3.0,
                                          "frequency_hz": 411.5}))
        # Tripped before the watch's Record: the device refuses it in FAULT (the other
        # order, a trip cutting the Record, leaves no file: the same LoopOpenedError).
        deadline = time.monotonic() + 60.0
        while str(proxy.state()) != "FAULT" and time.monotonic() < deadline:
            time.sleep(0.01)
        return switch

    roll_back = target.roll_back
    monkeypatch.setattr(target, "load", load_then_trip)
    monkeypatch.setattr(target, "roll_back",
                        lambda loop: loads.append(loop.name) or roll_back(loop))
    records: list[TuneResult] = []
    with pytest.raises(LoopChangeError) as err:
        tune_guarded(target=target, bench=bench, running=_seed(bench), options=OPTIONS,
                     seed=1, candidate=fsmbench_loop, journal=records.append)
    assert str(proxy.state()) == "FAULT" and not proxy.LoopClosed
    sentence = err.value.sentence
    assert "protection tripped" in sentence and "Reset" in sentence, sentence
    assert f"holding {proxy.Controller}" in sentence, sentence
    assert loads == []  # no LoadController into the faulted device
    last = records[-1]
    assert [rec.decision for rec in records] == ["loading", "interrupted"]
    assert last.transaction is not None and last.transaction["outcome"] == "loop_opened"
    assert last.transaction["left_on"] == proxy.Controller


def test_tune_device_stopped_before_a_decision_stops_its_work_and_says_what_runs(
        device: tuple[Any, str], tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    # Ctrl-C while tune plays its first closed-loop excitation: nothing was loaded, so
    # nothing is rolled back, but the excitation and the record tune started must stop,
    # and the output must say which controller the device runs (the soak's first finding:
    # "interrupted (Ctrl-C)" and nothing else, the excitation left to the device).
    proxy, address = device
    out = tmp_path / "tune"
    seen: dict[str, Any] = {}

    def play_then_interrupt(self: DeviceTarget, plays: Any, **_: Any) -> Any:
        self.proxy.Record(json.dumps({"signals": ["Vph", "Vpv"], "duration_s": 200.0,
                                      "name": "cut_short", "overwrite": True}))
        self.proxy.StartExcitation(json.dumps({"input": "Uch", "kind": "sine",
                                               "amplitude_v": 0.01, "frequency_hz": 37.0}))
        seen["state"] = str(self.proxy.state())
        seen["excitation"] = json.loads(self.proxy.Excitation)
        raise KeyboardInterrupt

    monkeypatch.setattr(DeviceTarget, "play", play_then_interrupt)
    assert main(["tune", "--device", address, "--out", str(out), "--watch-s", "6",
                 "--periods", "4", "--seed", "1"]) == EXIT_SIGINT
    assert seen["state"] == "MOVING" and seen["excitation"]  # tune's work was running
    deadline = time.monotonic() + 60.0
    while str(proxy.state()) == "MOVING" and time.monotonic() < deadline:
        time.sleep(0.01)
    assert json.loads(proxy.Excitation) == {} and str(proxy.state()) != "MOVING"
    assert proxy.Controller == SEED_NAME and proxy.LoopClosed
    captured = capsys.readouterr()
    said = f"Nothing was loaded: the device still runs {SEED_NAME}, as before tune"
    assert said in captured.out and "stopped its excitation and its record" in captured.out
    assert "interrupted (Ctrl-C) before a decision" in captured.err
    assert not out.exists()  # no decision, no record of one


def test_tune_device_stopped_while_it_loads_says_what_the_device_runs(
        device: tuple[Any, str], tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    # Ctrl-C after tune reached the device but before it sent a command (its models still
    # loading: the soak's SIGINT 4 s in over Channel Access): the device's controller,
    # read then, is said; the generic "left as it was" said nothing about the device.
    import fsmbench.cli.inputs as inputs

    called: list[bool] = []

    def interrupted(*_: Any, **__: Any) -> Any:
        called.append(True)
        raise KeyboardInterrupt

    # The bench file as the command line reads it (cli.inputs.bench_of), after the device
    # answered and before any command.
    monkeypatch.setattr(inputs, "load_bench", interrupted)
    proxy, address = device
    assert main(["tune", "--device", address, "--out", str(tmp_path / "tune")]) == EXIT_SIGINT
    assert called, "the interruption was not where the bench file is read"
    captured = capsys.readouterr()
    said = f"Nothing was loaded: the device still runs {SEED_NAME}, as before tune."
    assert said in captured.out and "interrupted (Ctrl-C) before a decision" in captured.err
    assert proxy.Controller == SEED_NAME and proxy.LoopClosed
