"""``tune`` through the live Tango device (issue 24): the same guarded procedure as on the
twin, acting only by the device's commands with the loop closed.

Each test starts its own twin device (``DeviceTestContext``, no database) at 50x real
time with the loop closed by the ESRF study's controller. A deliberately worse
candidate is refused through the device (its controller unchanged); ``fsmbench tune
--device`` loads fsmbench's controller designed on the closed-loop identification and
meets the 6.1 objective. Nothing asserts on wall clock.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import control as ct
import pytest

tango = pytest.importorskip("tango")

from fsmbench.bench.esrf import esrf_decentralised_controller  # noqa: E402
from fsmbench.bench.params import Bench  # noqa: E402
from fsmbench.cli import main  # noqa: E402
from fsmbench.control.controller import controller_of  # noqa: E402
from fsmbench.tune.device import DeviceTarget  # noqa: E402
from fsmbench.tune.guarded import TuneOptions, tune_guarded  # noqa: E402
from fsmbench.tune.measure import MeasurementOptions  # noqa: E402

SEED_NAME = "the ESRF study's controller (9.2)"  # what the device calls it


def _seed_loop(bench: Bench, gain: float, name: str) -> Any:
    gd = bench.nominal.quad_diode.gain_v_per_rad
    k = esrf_decentralised_controller()
    k = ct.ss(k.A, k.B, gain * k.C, gain * k.D, inputs=["Rh", "Rv"], outputs=["Uch", "Ucv"])
    return controller_of(k, name=name, ts_s=bench.true.converter.ts_s,
                         gd_v_per_rad=(float(gd.h), float(gd.v)))


def test_a_worse_candidate_is_refused_through_the_device(device: tuple[Any, str],
                                                        bench: Bench, tmp_path: Path) -> None:
    proxy, address = device
    running = _seed_loop(bench, 1.0, SEED_NAME)
    target = DeviceTarget(proxy, bench=bench, running=running, folder=tmp_path / "files",
                          address=address)
    # One measured stage of 4 periods (what the guards need); no Newport sine on the device.
    opts = TuneOptions(watch_s=6.0, settle_s=1.5, disturbance_v=0.0,
                       measurement=MeasurementOptions(periods=4, refine=False))
    worse = _seed_loop(bench, 0.3, "the ESRF study's controller x0.3")
    try:
        r = tune_guarded(target=target, bench=bench, running=running, options=opts, seed=2,
                         candidate=worse)
    except ValueError as exc:
        # A one-stage fit that keeps a mode on the wrong axis (once 244 Hz for h, before the
        # resonance search ignored isolated noisy lines) must stop the guard before any
        # design or load.
        assert "not plausible" in str(exc) and "wrong axis" in str(exc), exc
        assert proxy.Controller == SEED_NAME and proxy.LoopClosed
        return
    assert r.decision == "refused", r.reason
    assert "margins" in r.reason  # x0.3: phase margin ~22 deg < 30 (on the twin)
    assert r.switches == ()
    assert proxy.Controller == SEED_NAME and proxy.LoopClosed
    # The records came from the device: one stage of 4 periods locates both modes within
    # its +/-5 % band (it measured -0.6 % on v once: the precision is stage 2's, asserted
    # in the test below).
    found = r.measurement.identification.to_json()["sercalo"]
    for a in ("h", "v"):
        truth = float(bench.true.sercalo.resonance_hz[a])
        assert found[a]["resonance_hz"] == pytest.approx(truth, rel=0.05)
    # The measurement's beam error stays under the user's bound (30 urad rms).
    assert max(r.measurement.tracking_added_rad().values()) <= 30e-6
    assert r.target.startswith("the live device")


def test_tune_device_loads_a_better_controller(device: tuple[Any, str], bench: Bench,
                                               tmp_path: Path,
                                               monkeypatch: pytest.MonkeyPatch) -> None:
    proxy, address = device
    out = tmp_path / "tune"
    load = DeviceTarget.load
    records: list[dict[str, Any]] = []

    def load_seen(self: DeviceTarget, loop: Any) -> dict[str, Any]:
        # What tune.json says at the moment of the load (issue 31: the decision first).
        records.append(json.loads((out / "tune.json").read_text()))
        return load(self, loop)

    monkeypatch.setattr(DeviceTarget, "load", load_seen)
    # A 12 s watch: over 10.5 s the running loop's error reads 38-47 µrad on the twin (12
    # seeds; 37-47 over 4.5 s), so the candidate's predicted 33 is always 10 % better.
    assert main(["tune", "--device", address, "--out", str(out), "--watch-s", "12",
                 "--periods", "4", "--seed", "1"]) == 0
    # Written before the load: the measurement, the candidate, why, and the controller
    # that ran before with how the device's LoadController returns to it.
    first = records[0]
    assert first["decision"] == "loading" and first["transaction"]["outcome"] is None
    assert first["transaction"]["candidate"].startswith("fsmbench's controller")
    assert "better by more than 10 %" in first["transaction"]["why"]
    assert first["transaction"]["running_before"]["name"] == SEED_NAME
    assert first["transaction"]["running_before"]["restore_with"][0] == "seed"
    assert set(first["before"]["measured_rms_rad"]) == {"h", "v"}
    assert first["identified"]["h"]["resonance_hz"] > 0.0
    js = json.loads((out / "tune.json").read_text())
    assert js["decision"] == "loaded", js["reason"]
    assert js["transaction"]["outcome"] == "loaded"
    assert js["transaction"]["left_on"] == proxy.Controller
    assert js["target"] == f"the live device {address}"
    for a in ("h", "v"):
        assert js["before"]["sensitivity_at_1hz"][a] > js["objective_sensitivity_bound_at_1hz"]
        assert js["after"]["sensitivity_at_1hz"][a] < 2e-4  # the 6.1 objective, restored
        assert js["after"]["phase_margin_deg"][a] >= 30.0
        # Measured on the device after loading: better than before, and within the
        # roll-back tolerance (25 %) of the prediction.
        assert js["after"]["measured_rms_rad"][a] < js["before"]["measured_rms_rad"][a]
        assert js["after"]["measured_rms_rad"][a] <= 1.25 * js["after"]["predicted_rms_rad"][a]
    # Identified through the device in two stages: the resonances within the open-loop
    # tolerance (0.5 %) of the twin device's (the packaged bench).
    for a in ("h", "v"):
        assert js["identified"][a]["resonance_hz"] == pytest.approx(
            float(bench.true.sercalo.resonance_hz[a]), rel=5e-3)
    # Loaded by the device's own command, which names the file tune wrote.
    sw = js["switches"][0]
    assert sw["from"] == SEED_NAME and proxy.Controller == sw["to"]
    assert proxy.Controller.startswith("tuned") and proxy.LoopClosed
    assert Path(sw["file"]).is_file() and Path(sw["file"]).parent.parent.name == "tune-device"
    # The device's watch starts afresh on the loaded controller.
    assert not proxy.WatchVerdict.startswith("WARNING")


def test_tune_device_needs_the_loop_closed_and_the_running_controller(
        device: tuple[Any, str], bench: Bench, tmp_path: Path,
        capsys: pytest.CaptureFixture[str]) -> None:
    proxy, address = device
    wrong = _seed_loop(bench, 1.0, "another controller")
    with pytest.raises(ValueError, match="name the running controller"):
        DeviceTarget(proxy, bench=bench, running=wrong, folder=tmp_path, address=address)
    proxy.OpenLoop()
    with pytest.raises(ValueError, match="CloseLoop first"):
        DeviceTarget(proxy, bench=bench, running=_seed_loop(bench, 1.0, SEED_NAME),
                     folder=tmp_path, address=address)
    capsys.readouterr()
    assert main(["tune", "--twin", "--device", address, "--out", str(tmp_path / "x")]) == 2
    assert "--device: not allowed with argument --twin" in capsys.readouterr().err
    assert main(["tune", "--device", address, "--drift-rate", "2", "--out",
                 str(tmp_path / "y")]) == 2
    assert "--drift-rate: for --twin" in capsys.readouterr().err
