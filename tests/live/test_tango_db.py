"""``fsmbench serve`` under a real Tango database: PyTango's own ``DataBaseds`` on sqlite.

One database for the module (a free port, a temporary sqlite file); servers
are processes started and stopped by the tests, in order: registration and
defaults, a second start refused before the database is touched, two
benches in one database and the ``FsmBench INSTANCE`` entry point Starter
runs, properties and the loaded controller kept across a restart, events
(change, archive, periodic) through the database, and 3 readers with 1
commander for ``FSMBENCH_LIVE_LOAD_S`` seconds (default 10; the 60 s and
10 min runs are ``benchmarks/bench_live.py``) with zero errors.
"""

from __future__ import annotations

import gc
import json
import os
import shutil
import signal
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pytest

tango = pytest.importorskip("tango")

LOAD_S = float(os.environ.get("FSMBENCH_LIVE_LOAD_S", "10"))
DEVICE = "test/fsm/1"


class _Db(SimpleNamespace):
    host: str
    env: dict[str, str]
    folder: Path
    db: Any
    server: Any

    def proxy(self, name: str = DEVICE) -> Any:
        p = tango.DeviceProxy(f"tango://{self.host}/{name}")
        p.set_source(tango.DevSource.DEV)
        return p

    def properties(self, name: str = DEVICE) -> dict[str, list[str]]:
        keys = ["Backend", "Seed", "Speed", "OutputFolder", "WatchdogSeconds",
                "MemorisedController"]
        got = self.db.get_device_property(name, keys)
        return {k: list(got[k]) for k in keys}


@pytest.fixture(scope="module")
def tdb(parts: SimpleNamespace, tmp_path_factory: pytest.TempPathFactory) -> Iterator[_Db]:
    folder = tmp_path_factory.mktemp("tango-db")
    with parts.tango_database(folder) as host:
        env = {**os.environ, "TANGO_HOST": host}
        h, port = host.split(":")
        state = _Db(host=host, env=env, folder=folder, db=tango.Database(h, int(port)),
                    server=None)
        try:
            yield state
        finally:
            if state.server is not None:
                state.server.stop()
            # This process's client objects go before a later test runs a device server in
            # it (DeviceTestContext): that server's ORB ends with it, and a proxy freed
            # after that aborts the interpreter at exit (omniORB INV_OBJREF, status 134).
            state.db = None
            gc.collect()
            tango.ApiUtil.cleanup()


def serve(parts: SimpleNamespace, tdb: _Db, *args: str, name: str) -> Any:
    return parts.start([*parts_serve(), *args], env=tdb.env, folder=tdb.folder, name=name,
                       ready="Ready to accept request")


def parts_serve() -> list[str]:
    return [sys.executable, "-m", "fsmbench.cli", "serve"]


def refused(parts: SimpleNamespace, tdb: _Db, *args: str) -> str:
    status, err = parts.run_cli(list(args), env=tdb.env, cwd=tdb.folder)
    lines = err.strip().splitlines()
    assert status == 2 and len(lines) == 1, (status, err)
    return lines[0]


def _running(parts: SimpleNamespace, tdb: _Db) -> _Db:
    """The module's bench1 server, started if no earlier test left it running (a test run
    alone, e.g. by benchmarks/bench_live.py load)."""
    if tdb.server is None:
        tdb.server = serve(parts, tdb, "bench1", "--device", DEVICE, "--speed", "50", "--out",
                           str(tdb.folder / "out1"), name="bench1")
    return tdb


def test_register_and_write_only_absent_defaults(parts: SimpleNamespace, tdb: _Db) -> None:
    out = tdb.folder / "out1"
    _running(parts, tdb)
    assert f"{DEVICE} (FsmBench/bench1) registered in {tdb.host}" in tdb.server.text()
    props = tdb.properties()
    assert props["Speed"] == ["50.0"] and props["Seed"] == ["0"]
    assert props["OutputFolder"] == [str(out.resolve())] and props["Backend"] == ["twin"]
    assert props["WatchdogSeconds"] == ["5.0"]
    proxy = tdb.proxy()
    assert proxy.state() == tango.DevState.ON
    assert tdb.db.get_device_info(DEVICE).ds_full_name == "FsmBench/bench1"


def test_a_second_start_is_refused_before_it_touches_the_database(
        parts: SimpleNamespace, tdb: _Db) -> None:
    # Case 2.1: a second serve rewrote the properties, exited, and left the running device
    # "exported 0" (new clients: API_DeviceNotExported) writing into its OutputFolder.
    _running(parts, tdb)
    before = tdb.properties()
    for args, words in (
            (["bench1", "--device", DEVICE, "--seed", "3", "--out", "elsewhere"],
             "FsmBench/bench1 is already running"),
            (["bench2", "--device", DEVICE], "belongs to the server FsmBench/bench1")):
        line = refused(parts, tdb, *parts_serve(), *args)
        assert line.startswith("fsmbench serve: error:") and words in line, line
    line = refused(parts, tdb, str(Path(sys.executable).parent / "FsmBench"), "bench1")
    assert line.startswith("FsmBench bench1: error:") and "already running" in line, line
    assert tdb.properties() == before
    assert tdb.db.get_device_info(DEVICE).exported
    fresh = tango.DeviceProxy(f"tango://{tdb.host}/{DEVICE}")  # a new client
    assert fresh.state() == tango.DevState.ON


def test_two_benches_and_the_starter_entry_point(parts: SimpleNamespace, tdb: _Db) -> None:
    # Case 2.3: no instance or device option (two benches could not share a database) and
    # no `FsmBench INSTANCE` for Starter/Astor.
    info = tango.DbDevInfo()
    info.name, info._class, info.server = "test/fsm/2", "FsmBench", "FsmBench/bench2"
    tdb.db.add_device(info)  # as an administrator registers it (Jive)
    tdb.db.put_device_property("test/fsm/2", {"Speed": ["20.0"],
                                              "OutputFolder": [str(tdb.folder / "out2")]})
    starter = parts.start([str(Path(sys.executable).parent / "FsmBench"), "bench2"],
                          env=tdb.env, folder=tdb.folder, name="bench2",
                          ready="Ready to accept request")
    try:
        second = tdb.proxy("test/fsm/2")
        assert second.state() == tango.DevState.ON and second.SpeedFactor == 20.0
        assert tdb.proxy().SpeedFactor == 50.0  # the first bench, untouched
        # The device wrote the defaults the database lacked, and kept the two set.
        props = tdb.properties("test/fsm/2")
        assert props["Speed"] == ["20.0"] and props["Seed"] == ["0"]
        assert props["WatchdogSeconds"] == ["5.0"]
    finally:
        assert starter.stop(signal.SIGINT) == 0  # Ctrl-C stops it cleanly, as SIGTERM does
    line = refused(parts, tdb, str(Path(sys.executable).parent / "FsmBench"), "nobody")
    assert "has no FsmBench device" in line


def test_properties_and_the_controller_survive_a_restart(
        parts: SimpleNamespace, tdb: _Db, controller_x1: Path) -> None:
    # Cases 2.2 (Seed=7 went back to 0 at every start) and the memorised controller.
    _running(parts, tdb)
    proxy = tdb.proxy()
    # The controllers folder is the output folder (the ControllersFolder property is empty).
    (tdb.folder / "out1").mkdir(exist_ok=True)
    path = Path(shutil.copy(controller_x1, tdb.folder / "out1" / "controllers_sos.json"))
    assert "loaded for the next CloseLoop" in proxy.LoadController("controllers_sos.json")
    name = proxy.Controller
    assert "fsmbench_controller" in name
    assert json.loads(tdb.properties()["MemorisedController"][0])["path"] == \
        str(path.resolve())
    assert tdb.server.stop() == 0
    tdb.server = None
    tdb.db.put_device_property(DEVICE, {"Seed": ["7"]})  # an administrator's setting
    line = refused(parts, tdb, *parts_serve(), "bench1", "--device", DEVICE, "--seed", "3")
    assert "Seed is '7' there, the command line asks '3'" in line
    tdb.server = serve(parts, tdb, "bench1", "--device", DEVICE, name="bench1-again")
    assert "properties written" not in tdb.server.text()
    assert tdb.properties()["Seed"] == ["7"] and tdb.properties()["Speed"] == ["50.0"]
    proxy = tdb.proxy()
    parts.wait_until(lambda: proxy.Task == "", "the memorised controller to load")
    assert proxy.Controller == name
    assert "restored from the last run" in proxy.status(), proxy.status()


class _Collect:
    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.got: dict[tuple[str, str], list[Any]] = {}

    def push_event(self, ev: Any) -> None:
        if ev.err:
            return
        key = (ev.attr_name.rsplit("/", 1)[-1].lower(), str(ev.event))
        with self.lock:
            self.got.setdefault(key, []).append(ev.attr_value.value)

    def count(self, name: str, kind: str) -> int:
        with self.lock:
            return len(self.got.get((name.lower(), kind), []))

    def values(self, name: str, kind: str) -> list[Any]:
        with self.lock:
            return list(self.got.get((name.lower(), kind), []))


def test_events_through_the_database(parts: SimpleNamespace, tdb: _Db) -> None:
    # Cases 3.1-3.3: archive events, change criteria, events on the pushed views.
    _running(parts, tdb)
    proxy = tdb.proxy()
    events = _Collect()
    subs = [("BeamAngleH", tango.EventType.CHANGE_EVENT),
            ("BeamAngleH", tango.EventType.ARCHIVE_EVENT),
            ("BenchTime", tango.EventType.PERIODIC_EVENT),
            ("BenchTime", tango.EventType.ARCHIVE_EVENT),
            ("State", tango.EventType.CHANGE_EVENT), ("State", tango.EventType.ARCHIVE_EVENT),
            ("Controller", tango.EventType.CHANGE_EVENT),
            ("SpeedFactor", tango.EventType.CHANGE_EVENT),
            ("SpeedFactor", tango.EventType.ARCHIVE_EVENT),
            ("Excitation", tango.EventType.CHANGE_EVENT),
            ("Status", tango.EventType.CHANGE_EVENT)]
    ids = [proxy.subscribe_event(name, kind, events) for name, kind in subs]
    try:
        proxy.SpeedFactor = 40.0
        proxy.CloseLoop()
        proxy.StartExcitation(json.dumps({"input": "Unh", "kind": "noise",
                                          "amplitude_v": 0.01}))
        parts.wait_until(lambda: events.count("BenchTime", "periodic") >= 3
                         and events.count("BenchTime", "archive") >= 2
                         and events.count("BeamAngleH", "change") >= 2,
                         "periodic, archive and change events of the polled scalars")
        parts.wait_until(lambda: 40.0 in events.values("SpeedFactor", "change")
                         and 40.0 in events.values("SpeedFactor", "archive")
                         and tango.DevState.RUNNING in events.values("State", "change")
                         and tango.DevState.RUNNING in events.values("State", "archive")
                         and any('"noise"' in v for v in events.values("Excitation", "change"))
                         and any("Loop closed" in v for v in events.values("Status", "change")),
                         "the pushed events")
        assert events.count("BeamAngleH", "archive") >= 1
        proxy.StopExcitation()
        proxy.OpenLoop()
        proxy.SpeedFactor = 50.0
    finally:
        for i in ids:
            proxy.unsubscribe_event(i)


def test_three_readers_and_a_commander(parts: SimpleNamespace, tdb: _Db) -> None:
    """3 clients read while a 4th commands, for LOAD_S seconds: zero errors."""
    _running(parts, tdb)
    stop = threading.Event()
    errors: list[str] = []
    reads = [0, 0, 0]
    commands = [0]
    names = ["BeamAngleH", "TrackingErrorRmsV", "Distance", "BenchTime", "Heartbeat",
             "LoopClosed", "Controller", "AsdVph"]

    def reader(i: int) -> None:
        try:
            proxy = tdb.proxy()
        except tango.DevFailed as exc:
            errors.append(f"reader {i}: {exc.args[0].reason}: {exc.args[0].desc}")
            return
        while not stop.is_set():
            try:
                proxy.read_attributes(names)
                proxy.state()
                reads[i] += 1
            except tango.DevFailed as exc:
                errors.append(f"reader {i}: {exc.args[0].reason}: {exc.args[0].desc}")

    def commander() -> None:
        proxy = tdb.proxy()
        script = [("CloseLoop", None), ("StartExcitation",
                                        json.dumps({"input": "Unh", "kind": "sine",
                                                    "amplitude_v": 0.05, "frequency_hz": 3})),
                  ("Record", json.dumps({"signals": ["Vph"], "duration_s": 0.5,
                                         "name": "load", "overwrite": True})),
                  ("StopExcitation", None), ("OpenLoop", None)]
        k = 0
        while not stop.is_set():
            command, argument = script[k % len(script)]
            try:
                if proxy.state() != tango.DevState.MOVING:
                    proxy.command_inout(command, argument)
                    commands[0] += 1
                    k += 1
            except tango.DevFailed as exc:
                # A refusal (state moved under the commander) is an answer, not an error.
                if not exc.args[0].reason.startswith("FSM_"):
                    errors.append(f"commander: {exc.args[0].reason}: {exc.args[0].desc}")
            time.sleep(0.05)

    threads = [threading.Thread(target=reader, args=(i,)) for i in range(3)]
    threads.append(threading.Thread(target=commander))
    for t in threads:
        t.start()
    time.sleep(LOAD_S)
    stop.set()
    for t in threads:
        t.join(60.0)
    assert not errors, errors[:5]
    assert min(reads) > 0 and commands[0] > 0, (reads, commands)
    print(f"Tango, {LOAD_S:g} s: {sum(reads)} reads of {len(names)} attributes and State by 3 "
          f"readers {reads}, {commands[0]} commands, 0 errors")
    proxy = tdb.proxy()
    parts.wait_until(lambda: proxy.state() != tango.DevState.MOVING, "the last record")
    if proxy.LoopClosed:
        proxy.OpenLoop()
    assert proxy.state() in (tango.DevState.ON, tango.DevState.ALARM), proxy.status()
