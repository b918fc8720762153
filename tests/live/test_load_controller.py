"""``LoadController`` decides on the call: where the file is, what it is, whether it is safe
(issue 31, items 2 and 3).

Every refusal is the command's own reply (a ``Refused`` in the bench, a ``DevFailed`` through
Tango: never an OK followed by a failure in Status), the loop runs on with the controller it
had, and no client-visible string (the reply, Status, the log) holds bytes of the file. The
EPICS side of the same cases is in ``test_epics.py`` (its IOC is shared there).
"""

from __future__ import annotations

import json
import os
import shutil
import time
from collections.abc import Iterator
from pathlib import Path

import control as ct
import pytest

from fsmbench.bench.params import Bench, default_bench
from fsmbench.control.export import InputScaling, write_controllers_mat, write_sos_json
from fsmbench.live.controllers import MAX_CONTROLLER_BYTES, MAX_CONTROLLER_STATES
from fsmbench.live.core import FileMemory, LiveBench
from fsmbench.live.states import Refused

BENCH = default_bench()
FS = BENCH.nominal.converter.fs_hz
SEED_NAME = "the ESRF study's controller (9.2)"
#: Bytes a message must not share with a file: longer than any word a sentence shares with
#: a text file by chance ("controller", "/tmp/pytest-"), far shorter than any excerpt.
WINDOW = 10
SECRET = b"Qz7-secret: root:x:0:0:root:/root:/bin/bash\ndaemon:x:1:1::/usr/sbin:/nologin\n"


def shares_bytes(text: str, content: bytes) -> str:
    """A run of :data:`WINDOW` bytes of ``content`` found in ``text`` ("" when none)."""
    raw = text.encode("ascii", "replace")
    for i in range(max(0, len(content) - WINDOW + 1)):
        if content[i:i + WINDOW] in raw:
            return content[i:i + WINDOW].decode("latin-1")
    return ""


def _tuned(bench: Bench, k: ct.StateSpace, folder: Path) -> Path:
    """fsmbench's controller as a previous tune leaves it: ``tuned`` in controllers_sos.json."""
    gd = bench.true.quad_diode.gain_v_per_rad
    scaling = InputScaling(qd_gain_v_per_rad=(float(gd.h), float(gd.v)),
                           plant_source="identified (test)")
    folder.mkdir(parents=True, exist_ok=True)
    return write_sos_json(folder / "controllers_sos.json", {"tuned": k}, scaling=scaling,
                          ts_s=bench.true.converter.ts_s, descriptions={"tuned": "a tune's"})


@pytest.fixture
def folder(tmp_path: Path, controller_x1: Path, controller_x20: Path,
           fsmbench_controller: ct.StateSpace) -> Path:
    """The controllers folder: good and bad files, links out of it, a FIFO."""
    inside = tmp_path / "controllers"
    inside.mkdir()
    shutil.copy(controller_x1, inside / "controllers_sos.json")
    shutil.copy(controller_x20, inside / "x20.json")
    (inside / "notes.txt").write_bytes(SECRET)
    outside = tmp_path / "elsewhere"
    outside.mkdir()
    (outside / "secret.json").write_bytes(SECRET)
    shutil.copy(controller_x1, outside / "controllers_sos.json")  # valid, but outside
    (inside / "passwd_link").symlink_to("/etc/passwd")
    (inside / "outside_link.json").symlink_to(outside / "secret.json")
    (inside / "design_link").symlink_to(outside)
    os.mkfifo(inside / "fifo")
    _tuned(BENCH, fsmbench_controller, inside / "tune-device" / "tune_controller_1")
    return inside


@pytest.fixture
def live(folder: Path, tmp_path: Path) -> Iterator[tuple[LiveBench, list[str]]]:
    """The bench closed with fsmbench's controller from the folder; its log lines."""
    lines: list[str] = []
    bench = LiveBench(BENCH, seed=5, output_folder=tmp_path / "out", controllers_folder=folder,
                      memory=FileMemory(tmp_path / "memory.json"),
                      log=lambda level, text: lines.append(text))
    bench.advance(1000)
    assert "in the loop" not in bench.load_controller("controllers_sos.json")
    bench.close_loop()
    bench.advance(1000)
    yield bench, lines
    bench.stop()


def _cases(folder: Path) -> list[tuple[str, str, bytes]]:
    """(argument, words of the refusal, bytes the client must never see)."""
    passwd = Path("/etc/passwd").read_bytes()
    outside = folder.parent / "elsewhere"
    return [
        ("", "the argument is empty", b""),
        ("   ", "the argument is empty", b""),
        ("/dev/zero", "is outside the controllers folder", b""),
        ("/etc/passwd", "is outside the controllers folder", passwd),
        (str(outside / "secret.json"), "is outside the controllers folder", SECRET),
        # A valid controller is refused too when it is not in the folder.
        (str(outside / "controllers_sos.json"), "is outside the controllers folder", b""),
        ("../elsewhere/secret.json", "is outside the controllers folder", SECRET),
        ("passwd_link", "is outside the controllers folder", passwd),
        ("outside_link.json", "is outside the controllers folder", SECRET),
        ("design_link", "is outside the controllers folder", b""),
        ("fifo", "is a FIFO (named pipe), not a controllers file", b""),
        ("notes.txt", "is not a controllers file fsmbench reads", SECRET),
        ("missing.json", "does not exist in the controllers folder", b""),
        ('{"path": ""}', "give a controllers file", b""),
        ("x20.json", "fails the check on the device's bench", b""),
    ]


def test_unsafe_arguments_are_refused_on_the_call_and_the_loop_runs_on(
        live: tuple[LiveBench, list[str]], folder: Path) -> None:
    bench, lines = live
    before = bench.backend.controller
    assert before is not None and before.name == "fsmbench_controller (controllers_sos.json)"
    status = bench.status
    for argument, words, content in _cases(folder):
        with pytest.raises(Refused) as exc:
            bench.load_controller(argument)
        sentence = exc.value.sentence
        assert exc.value.reason == "FSM_BadArgument", (argument, sentence)
        assert sentence.startswith("LoadController refused: ") and words in sentence, \
            (argument, sentence)
        if argument.strip().startswith("/") or argument in ("passwd_link", "fifo"):
            assert argument in sentence  # the path as the user typed it
        # Nothing changed: no task, no new Status, the same controller in the loop.
        assert bench.backend.controller is before and bench.task_text == ""
        assert bench.status == status
        bench.advance(round(0.2 * FS))
        assert bench.state == "RUNNING", (argument, bench.status)
        for text in (sentence, bench.status, *lines):
            leaked = shares_bytes(text, content) if content else ""
            assert not leaked, (argument, leaked, text)
            assert "root:" not in text and "Qz7" not in text, (argument, text)
    assert bench.controller_name == before.name


def test_the_20x_controller_is_refused_with_the_failed_margin_in_words(
        live: tuple[LiveBench, list[str]]) -> None:
    bench, _ = live
    with pytest.raises(Refused) as exc:
        bench.load_controller("x20.json")
    sentence = exc.value.sentence
    # The twin's 20x loop diverges by ~6 % a sample (|z| = 1.065 with this controller).
    assert "the closed loop is unstable: its largest pole has |z| = 1.0" in sentence, sentence
    assert "The loop runs on with fsmbench_controller (controllers_sos.json)" in sentence
    # Stable but thin: 3x leaves the gain margin under the design's 6 dB on one axis at least.
    doc = json.loads((bench.controllers_folder / "controllers_sos.json").read_text())
    for axis in ("h", "v"):
        section = doc["controllers"]["fsmbench_controller"][axis]["sos"][0]
        section[:3] = [3.0 * x for x in section[:3]]
    (bench.controllers_folder / "x3.json").write_text(json.dumps(doc))
    with pytest.raises(Refused) as exc:
        bench.load_controller("x3.json")
    sentence = exc.value.sentence
    assert "dB, at least 6 dB required" in sentence, sentence
    assert "unstable" not in sentence
    assert bench.backend.controller is not None
    assert bench.backend.controller.name.startswith("fsmbench_controller")


def test_a_valid_controller_loads_and_seed_and_last_good_return(
        live: tuple[LiveBench, list[str]], tmp_path: Path) -> None:
    bench, _ = live
    reply = bench.load_controller("seed")
    assert reply.startswith(f"{SEED_NAME} in the loop (bumpless); checked on the device's bench")
    assert bench.backend.controller is not None and bench.backend.controller.name == SEED_NAME
    assert "gain margins" in reply and "modulus margins" in reply
    reply = bench.load_controller("last-good")
    assert reply.startswith("fsmbench_controller (controllers_sos.json) in the loop")
    assert bench.load_controller("last-good").startswith(SEED_NAME)
    # A design folder means its controllers file (the same checks on that file).
    assert bench.load_controller(".").startswith("fsmbench_controller (controllers_sos.json)")
    bench.advance(round(0.5 * FS))
    assert bench.state == "RUNNING", bench.status
    # Remembered, and restored through the same checks by the next start.
    again = LiveBench(BENCH, seed=6, output_folder=tmp_path / "out2",
                      controllers_folder=bench.controllers_folder,
                      memory=FileMemory(tmp_path / "memory.json"))
    try:
        assert "restored the controller fsmbench_controller" in again.restore_controller()
        assert again.controller_name == "fsmbench_controller (controllers_sos.json)"
        # last-good knows nothing older after a restart: said, and nothing changes.
        with pytest.raises(Refused, match="last-good: no controller before"):
            again.load_controller("last-good")
    finally:
        again.stop()


def test_a_remembered_file_made_unsafe_is_not_restored(live: tuple[LiveBench, list[str]],
                                                       tmp_path: Path) -> None:
    bench, _ = live
    memory = FileMemory(tmp_path / "memory.json")
    assert memory.load() == {"path": str(bench.controllers_folder / "controllers_sos.json"),
                             "controller": "fsmbench_controller"}
    (bench.controllers_folder / "controllers_sos.json").write_bytes(SECRET)
    again = LiveBench(BENCH, seed=6, output_folder=tmp_path / "out2",
                      controllers_folder=bench.controllers_folder, memory=memory)
    try:
        words = again.restore_controller()
        assert "was not loaded" in words and "is not a controllers file" in words, words
        assert again.controller_name.startswith("none") and "was not loaded" in again.status
        assert not shares_bytes(again.status, SECRET)
    finally:
        again.stop()


def test_fsmbench_s_own_tuned_files_load_and_run_a_new_tune(
        live: tuple[LiveBench, list[str]], fsmbench_controller: ct.StateSpace) -> None:
    """A previous tune's controllers_sos.json (and design's controllers.mat) can be the running
    controller of a new tune: loaded by the device, then named by ``--running FILE::tuned``
    (its prewarped integrator sections were refused as a pole at z = -1)."""
    from fsmbench.tune.running import loop_from_file

    bench, _ = live
    sos = bench.controllers_folder / "tune-device" / "tune_controller_1" / "controllers_sos.json"
    mat = write_controllers_mat(sos.with_name("controllers.mat"), {"tuned": fsmbench_controller},
                                ts_s=BENCH.true.converter.ts_s)
    for path in (sos, mat):
        rel = str(path.relative_to(bench.controllers_folder))
        reply = bench.load_controller(json.dumps({"path": rel, "controller": "tuned"}))
        assert reply.startswith(f"tuned ({path.name}) in the loop"), reply
        loop = loop_from_file(f"{path}::tuned", BENCH)
        assert loop.name == bench.controller_name  # what tune --device compares
        bench.advance(round(0.5 * FS))
        assert bench.state == "RUNNING", bench.status


def test_limits_on_size_and_order(live: tuple[LiveBench, list[str]]) -> None:
    bench, _ = live
    big = bench.controllers_folder / "big.json"
    big.write_bytes(b" " * (MAX_CONTROLLER_BYTES + 1))
    with pytest.raises(Refused, match=r"big.json: is 256 KiB, over the 256 KiB"):
        bench.load_controller("big.json")
    doc = json.loads((bench.controllers_folder / "controllers_sos.json").read_text())
    chan = doc["controllers"]["fsmbench_controller"]["h"]
    chan["sos"] = chan["sos"] + [[1.0, 0.0, 0.0, 1.0, -0.5, 0.0]] * MAX_CONTROLLER_STATES
    (bench.controllers_folder / "tall.json").write_text(json.dumps(doc))
    with pytest.raises(Refused, match=f"more than the {MAX_CONTROLLER_STATES} this loop takes"):
        bench.load_controller("tall.json")


@pytest.mark.parametrize("kind", ["refused", "loaded"])
def test_refusals_and_loads_through_tango_on_the_call(folder: Path, tmp_path: Path,
                                                      kind: str) -> None:
    """Through a Tango client: each case answers within the client's 3 s timeout (a
    timeout would be a DevFailed here), refused ones with FSM_BadArgument, and Status
    and the Controller attribute never hold the file's bytes."""
    tango = pytest.importorskip("tango")
    from tango.test_context import DeviceTestContext

    from fsmbench.live.device import FsmBench

    ctx = DeviceTestContext(FsmBench, device_name="fsmbench/bench/1", process=False,
                            properties={"Speed": 20.0, "OutputFolder": str(tmp_path / "live"),
                                        "ControllersFolder": str(folder)})
    with ctx as proxy:
        proxy.set_source(tango.DevSource.DEV)
        assert proxy.ControllersPath == str(folder.resolve())
        proxy.CloseLoop()
        times = {}
        if kind == "loaded":
            for argument in ("controllers_sos.json", "seed", "last-good"):
                t0 = time.perf_counter()
                proxy.LoadController(argument)
                times[argument] = time.perf_counter() - t0
            assert proxy.Controller == "fsmbench_controller (controllers_sos.json)"
        else:
            for argument, words, content in _cases(folder):
                t0 = time.perf_counter()
                with pytest.raises(tango.DevFailed) as exc:
                    proxy.LoadController(argument)
                times[argument] = time.perf_counter() - t0
                err = exc.value.args[0]
                assert err.reason == "FSM_BadArgument" and words in err.desc, \
                    (argument, err.desc)
                for text in (err.desc, proxy.status(), proxy.Controller):
                    assert "root:" not in text and "Qz7" not in text, (argument, text)
                    assert not (content and shares_bytes(text, content)), (argument, text)
                assert proxy.Controller == SEED_NAME and proxy.LoopClosed
            assert str(proxy.state()) == "RUNNING", proxy.status()
        print(f"LoadController through Tango ({kind}), wall clock [ms]: "
              + ", ".join(f"{a!r} {1e3 * t:.0f}" for a, t in times.items()))


def test_the_ioc_memory_file_names_its_format_and_reads_the_older_one(tmp_path: Path) -> None:
    import json

    from fsmbench.live.loading import MEMORY_FORMAT

    memory = FileMemory(tmp_path / "memory.json")
    request = {"path": "/x/controllers_sos.json", "controller": "tuned"}
    memory.save(request)
    doc = json.loads((tmp_path / "memory.json").read_text())
    assert list(doc)[:2] == ["format", "format_version"]
    assert (doc["format"], doc["format_version"]) == MEMORY_FORMAT
    assert memory.load() == request
    (tmp_path / "memory.json").write_text(json.dumps(request))  # as written before the format
    assert memory.load() == request
    memory.save(None)
    assert memory.load() is None
