"""``tune --running PATH``: a controller from a controllers file, as the device runs it.

Checked against the device's own wiring of the same file (``sercalo_feedback`` of the
loaded discrete sections, as ``LoadController`` does): the loop tune measures, predicts and
swaps from must be that one, line for line.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from fsmbench.bench.esrf import esrf_decentralised_controller
from fsmbench.bench.params import Bench
from fsmbench.cli import main
from fsmbench.control.controller import controller_of
from fsmbench.control.export import InputScaling, write_sos_json
from fsmbench.control.load import load_controllers, select_controller
from fsmbench.sim.controller import sercalo_feedback
from fsmbench.tune.running import loop_from_file


def _response(ctrl: object, f_hz: np.ndarray, ts_s: float) -> np.ndarray:
    a, b, c, d = (np.asarray(getattr(ctrl, x)) for x in "abcd")
    z = np.exp(2j * np.pi * f_hz * ts_s)
    return np.array([c @ np.linalg.solve(zz * np.eye(a.shape[0]) - a, b) + d for zz in z])


@pytest.fixture
def tuned_file(bench: Bench, tmp_path: Path) -> Path:
    """The ESRF study's controller as a previous tune would have written it, named
    ``tuned`` (prewarped Tustin per section)."""
    gd = bench.nominal.quad_diode.gain_v_per_rad
    path = tmp_path / "controllers_sos.json"
    write_sos_json(path, {"tuned": esrf_decentralised_controller()},
                   scaling=InputScaling(qd_gain_v_per_rad=(float(gd.h), float(gd.v)),
                                        plant_source="identified (test)"),
                   ts_s=bench.true.converter.ts_s)
    return path


def test_running_controller_from_a_file_is_the_device_s(bench: Bench, tuned_file: Path) -> None:
    path = tuned_file
    loop = loop_from_file(str(path), bench)
    assert loop.name == "tuned (controllers_sos.json)"  # as LoadController names it
    ts = bench.true.converter.ts_s
    chosen = select_controller(load_controllers(path, ts_s=ts), None)
    device = sercalo_feedback(a=chosen.a, b=chosen.b, c=chosen.c, d=chosen.d,
                              gd_v_per_rad=chosen.gd_v_per_rad, name="device")
    f = np.array([0.1, 1.0, 10.0, 100.0, 251.2, 411.5, 1000.0, 4000.0])
    ours, theirs = _response(loop.feedback, f, ts), _response(device, f, ts)
    # The exact pre-image under Tustin: equal to round-off (the realisations differ).
    assert np.max(np.abs(ours - theirs) / np.max(np.abs(theirs), axis=(1, 2))[:, None, None]) \
        < 1e-8


def test_a_missing_running_file_is_refused_in_one_line(tmp_path: Path,
                                                       capsys: pytest.CaptureFixture[str]
                                                       ) -> None:
    code = main(["tune", "--twin", "--out", str(tmp_path / "out"),
                 "--running", str(tmp_path / "nope.json")])
    err = capsys.readouterr().err
    assert code != 0
    assert "nope.json" in err and len(err.strip().splitlines()) == 1


@pytest.fixture(scope="module")
def designed(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """``fsmbench design``'s own files (controllers.mat, controllers_sos.json) for the
    packaged bench: fsmbench's controller with its four integrators."""
    from fsmbench.bench.blocks import physical_plant
    from fsmbench.bench.params import default_bench
    from fsmbench.control.study import design_study

    b = default_bench()
    out = tmp_path_factory.mktemp("design")
    design_study(physical_plant(b.nominal, source="the bench file"), bench=b).write(out)
    return out


@pytest.mark.parametrize("name", ["controllers_sos.json", "controllers.mat"])
def test_fsmbench_s_own_files_can_be_the_running_controller(bench: Bench, designed: Path,
                                                           name: str) -> None:
    """Issue 31: after one tune, its controllers_sos.json was refused as 'a pole at z = -1'.
    Its integrator sections' delta realisation puts entries of ~1e12 in A, which the old
    det(I + A) < 1e-12 |I + A|^n test read as singular; no pole is near -1."""
    path = designed / name
    loop = loop_from_file(f"{path}::fsmbench_controller", bench)
    assert loop.name == f"fsmbench_controller ({name})"
    ts = bench.true.converter.ts_s
    chosen = select_controller(load_controllers(path, ts_s=ts), "fsmbench_controller")
    device = sercalo_feedback(a=chosen.a, b=chosen.b, c=chosen.c, d=chosen.d,
                              gd_v_per_rad=chosen.gd_v_per_rad, name="device")
    f = np.array([0.1, 1.0, 10.0, 100.0, 251.2, 411.5, 1000.0, 4000.0])
    ours, theirs = _response(loop.feedback, f, ts), _response(device, f, ts)
    # The exact pre-image under Tustin, through 1e12-sized entries: round-off (measured
    # 2e-12), with room.
    assert np.max(np.abs(ours - theirs) / np.max(np.abs(theirs), axis=(1, 2))[:, None, None]) \
        < 1e-8


@pytest.mark.parametrize(("a1", "refused"), [(1.0, True), (0.999, False)])
def test_a_pole_on_nyquist_is_refused_and_one_just_inside_is_not(
        bench: Bench, tuned_file: Path, tmp_path: Path, a1: float, refused: bool) -> None:
    """A section ``1 / (1 + a1 q)``: its pole z = -a1. On -1 it has no pre-image under
    Tustin; at -0.999 it is Tustin's image of a lowpass at ~640 times the sample rate."""
    doc = json.loads(tuned_file.read_text())
    doc["controllers"]["tuned"]["h"]["sos"].append([1.0, 0.0, 0.0, 1.0, a1, 0.0])
    path = tmp_path / "with_pole.json"
    path.write_text(json.dumps(doc))
    if refused:
        with pytest.raises(ValueError, match=r"has a pole at z = -1 \(Nyquist\)"):
            loop_from_file(f"{path}::tuned", bench)
        return
    loop = loop_from_file(f"{path}::tuned", bench)
    ts = bench.true.converter.ts_s
    chosen = select_controller(load_controllers(path, ts_s=ts), "tuned")
    device = sercalo_feedback(a=chosen.a, b=chosen.b, c=chosen.c, d=chosen.d,
                              gd_v_per_rad=chosen.gd_v_per_rad, name="device")
    f = np.array([1.0, 100.0, 411.5, 4000.0])
    ours, theirs = _response(loop.feedback, f, ts), _response(device, f, ts)
    # The pre-image's pole at ~4e7 rad/s and back: round-off times (2/T)/|1 + z| = 2e7.
    assert np.max(np.abs(ours - theirs) / np.max(np.abs(theirs), axis=(1, 2))[:, None, None]) \
        < 1e-6


def test_a_device_running_a_file_s_controller_is_accepted(bench: Bench, tmp_path: Path,
                                                          tuned_file: Path) -> None:
    """The device, having loaded ``tuned`` from a controllers file (as a previous tune
    leaves it), is tuned again with ``--running`` that file: the target accepts it."""
    path = tuned_file
    tango = pytest.importorskip("tango")
    from tango.test_context import DeviceTestContext

    from fsmbench.live.device import FsmBench
    from fsmbench.tune.device import DeviceTarget
    from fsmbench.tune.reads import read_valid

    ctx = DeviceTestContext(FsmBench, device_name="fsmbench/bench/1", process=False,
                            properties={"Speed": 50.0, "OutputFolder": str(tmp_path / "live"),
                                        "ControllersFolder": str(tmp_path)})
    with ctx as proxy:
        proxy.set_source(tango.DevSource.DEV)
        proxy.CloseLoop()
        # Checked on the device's bench and swapped in on the call.
        reply = proxy.LoadController(f'{{"path": "{path}", "controller": "tuned"}}')
        assert reply.startswith("tuned (controllers_sos.json) in the loop"), reply
        loop = loop_from_file(str(path), bench)
        # Read as tune reads it: a busy machine's INVALID answer (the bench lock not taken in
        # 0.5 s, value None) is read again, as a client must.
        assert read_valid(proxy, "Controller", device="fsmbench/bench/1") == loop.name
        target = DeviceTarget(proxy, bench=bench, running=loop, folder=tmp_path / "files",
                              address=ctx.get_device_access())
        assert target.gd == loop.gd


def test_a_controller_tune_loaded_is_retuned_from(bench: Bench, fsmbench_loop: Any,
                                                 tmp_path: Path,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    # fsmbench's controller written as tune writes the one it loads (DeviceTarget.load:
    # named "tuned", the 4QD gains it was designed with), then a whole tune from it. Its
    # stage-1 multisine repeats every 40000 samples but nearly repeats 140 earlier, and
    # the controller read back is biproper: the two made a retune fail before a decision.
    path = tmp_path / "controllers_sos.json"
    write_sos_json(path, {"tuned": fsmbench_loop.continuous},
                   scaling=InputScaling(qd_gain_v_per_rad=fsmbench_loop.gd,
                                        plant_source="identified (a previous tune)"),
                   ts_s=bench.true.converter.ts_s, descriptions={"tuned": fsmbench_loop.name})
    out = tmp_path / "retuned"
    assert main(["tune", "--twin", "--running", f"{path}::tuned", "--out", str(out),
                 "--periods", "4", "--seed", "1"]) == 0, capsys.readouterr().err[-800:]
    js = json.loads((out / "tune.json").read_text())
    assert js["decision"] in ("loaded", "refused", "rolled_back")
    assert js["before"]["name"] == "tuned (controllers_sos.json)"


#: fsmbench's controller as ``tune --twin --seed 2 --periods 4`` designed it and
#: DeviceTarget.load wrote it (sections only). Its v axis's double zeros on z = -1 made the
#: pre-image by substitution carry zeros at 1e12 rad/s: 20 times it could not be written
#: again ("channel gain is not real"), and a retune over CA failed on it.
RETUNED = Path(__file__).parent / "data" / "retuned_controllers_sos.json"


def test_a_controller_read_from_a_file_can_be_scaled_and_written_again(
        bench: Bench, tmp_path: Path) -> None:
    import control as ct

    loop = loop_from_file(f"{RETUNED}::tuned", bench)
    ts = bench.true.converter.ts_s
    k = loop.continuous
    x20 = ct.ss(k.A, k.B, 20.0 * k.C, 20.0 * k.D, inputs=["Rh", "Rv"], outputs=["Uch", "Ucv"])
    scaling = InputScaling(qd_gain_v_per_rad=loop.gd, plant_source="a test")
    write_sos_json(tmp_path / "prewarped.json", {"x20": x20}, scaling=scaling, ts_s=ts)
    plain = write_sos_json(tmp_path / "plain.json", {"x20": x20}, scaling=scaling, ts_s=ts,
                           method="tustin")
    f = np.array([0.1, 1.0, 10.0, 100.0, 251.2, 411.5, 1000.0, 4000.0])
    again = select_controller(load_controllers(plain, ts_s=ts), "x20").response(f)
    file = select_controller(load_controllers(RETUNED, ts_s=ts), "tuned").response(f)
    # Plain Tustin of the pre-image is the file, so 20 times it is 20 times the file:
    # round-off (measured 9e-13), with room.
    scale = np.max(np.abs(file), axis=(1, 2))[:, None, None]
    assert np.max(np.abs(again - 20.0 * file) / (20.0 * scale)) < 1e-9


def test_a_retune_s_scaled_controller_is_refused_by_the_device_not_by_tune(
        bench: Bench, tmp_path: Path) -> None:
    """What the CA test does, on Tango's DeviceTestContext: the device runs the file's
    controller, tune asks it to load 20 times that one, and the device's check refuses it
    (PyTango's DevFailed, which tune's transaction reads). Tune's own export of it failed
    first when the pre-image carried zeros at 1e12 rad/s."""
    import shutil

    import control as ct

    tango = pytest.importorskip("tango")
    from tango.test_context import DeviceTestContext

    from fsmbench.live.device import FsmBench
    from fsmbench.tune.device import DeviceTarget

    folder = tmp_path / "controllers"
    folder.mkdir()
    path = Path(shutil.copy(RETUNED, folder / "controllers_sos.json"))
    ctx = DeviceTestContext(FsmBench, device_name="fsmbench/bench/1", process=False,
                            properties={"Speed": 50.0, "OutputFolder": str(tmp_path / "live"),
                                        "ControllersFolder": str(folder)})
    with ctx as proxy:
        proxy.set_source(tango.DevSource.DEV)
        proxy.CloseLoop()
        proxy.LoadController(f'{{"path": "{path}", "controller": "tuned"}}')
        loop = loop_from_file(f"{path}::tuned", bench)
        target = DeviceTarget(proxy, bench=bench, running=loop, folder=folder / "tune",
                              address=ctx.get_device_access())
        k = loop.continuous
        x20 = controller_of(ct.ss(k.A, k.B, 20.0 * k.C, 20.0 * k.D, inputs=["Rh", "Rv"],
                                  outputs=["Uch", "Ucv"]), name="20 times the previous run's",
                            ts_s=bench.true.converter.ts_s, gd_v_per_rad=loop.gd)
        with pytest.raises(tango.DevFailed) as refused:
            target.load(x20)
        error = refused.value.args[0]
        assert error.reason == "FSM_BadArgument", error
        assert "fails the check on the device's bench" in error.desc
        assert target.running_controller() == "tuned (controllers_sos.json)"
