"""``fsmbench serve`` as a user runs it: a device server process without a Tango database.

The server is a subprocess (``python -m fsmbench.cli serve --nodb``); a client
connects to ``tango://localhost:<port>/fsmbench/bench/1#dbase=no``. Every
wait has a wall-clock timeout that fails saying what it waited for; the
process is always killed at the end. The refusals (status 2, one line) run
the console script's entry point in this process: they exit before any
server starts.
"""

from __future__ import annotations

import contextlib
import json
import queue
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

tango = pytest.importorskip("tango")

from fsmbench.cli import main  # noqa: E402

WAIT_S = 60.0  # wall-clock seconds a wait may take (server start on 2 busy cores)
SERVE = [sys.executable, "-m", "fsmbench.cli", "serve"]


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("", 0))
        return int(s.getsockname()[1])


def _wait_until(check: Callable[[], Any], what: str, *, timeout_s: float = WAIT_S) -> Any:
    deadline = time.monotonic() + timeout_s
    while True:
        value = check()
        if value:
            return value
        if time.monotonic() > deadline:
            pytest.fail(f"timed out after {timeout_s:g} s (wall clock) waiting for {what}")
        time.sleep(0.05)


def _lines(stream: Any) -> queue.Queue[str]:
    """The stream's lines, read by a thread (a blocking read never hangs the test)."""
    q: queue.Queue[str] = queue.Queue()

    def pump() -> None:
        for line in stream:
            q.put(line)

    threading.Thread(target=pump, daemon=True).start()
    return q


def _ready_line(lines: queue.Queue[str], proc: subprocess.Popen[str], *,
                starts: str = "fsmbench serve:") -> str:
    deadline = time.monotonic() + WAIT_S
    seen: list[str] = []
    while time.monotonic() < deadline:
        try:
            line = lines.get(timeout=0.2)
        except queue.Empty:
            if proc.poll() is not None:
                pytest.fail(f"fsmbench serve exited with status {proc.returncode}: "
                            f"{''.join(seen)}{proc.stderr.read() if proc.stderr else ''}")
            continue
        seen.append(line)
        if line.startswith(starts):
            return line
    pytest.fail(f"no {starts!r} line within {WAIT_S:g} s; stdout: {''.join(seen)}")


def _connect(address: str) -> Any:
    def ping() -> Any:
        try:
            proxy = tango.DeviceProxy(address)
            proxy.ping()
        except tango.DevFailed:
            return None
        return proxy

    proxy = _wait_until(ping, f"the device at {address}")
    proxy.set_source(tango.DevSource.DEV)  # the device's values, not the polling cache
    return proxy


@contextlib.contextmanager
def _served(cwd: Path, *args: str) -> Iterator[tuple[subprocess.Popen[str], int]]:
    """``fsmbench serve --nodb`` on a free port with ``args``; killed if a test leaves it."""
    port = _free_port()
    proc = subprocess.Popen([*SERVE, "--nodb", "--port", str(port), "--speed", "50", *args],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=cwd)
    try:
        yield proc, port
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(timeout=WAIT_S)


def test_serve_nodb_runs_the_twin_for_a_client(tmp_path: Path) -> None:
    out = tmp_path / "live-out"
    with _served(tmp_path, "--out", str(out)) as (proc, port):
        line = _ready_line(_lines(proc.stdout), proc)
        assert f":{port}/fsmbench/bench/1#dbase=no" in line, line
        assert "twin" in line and "speed 50" in line, line
        proxy = _connect(f"tango://localhost:{port}/fsmbench/bench/1#dbase=no")
        assert proxy.state() == tango.DevState.ON
        assert proxy.SpeedFactor == 50.0
        t0 = proxy.BenchTime
        _wait_until(lambda: proxy.BenchTime > t0 + 0.5, "BenchTime to advance 0.5 s")
        proxy.CloseLoop()
        assert proxy.state() == tango.DevState.RUNNING
        assert proxy.LoopClosed is True
        path = Path(proxy.Record(json.dumps({"signals": ["Vph", "Vpv"], "duration_s": 0.2,
                                             "name": "served"})))
        assert path == out.resolve() / "served.mat"  # --out is where Record writes
        _wait_until(lambda: proxy.state() != tango.DevState.MOVING, "the record to be written")
        assert proxy.state() == tango.DevState.RUNNING
        assert path.is_file()
        proc.terminate()
        # Tango's own SIGTERM handler shuts the server down cleanly.
        assert proc.wait(timeout=WAIT_S) == 0


def test_serve_json_says_where_it_serves_in_one_document(tmp_path: Path) -> None:
    # A script starts the server and takes its address from stdout, as tune --device takes it.
    with _served(tmp_path, "--json", "--out", str(tmp_path / "live")) as (proc, port):
        doc = json.loads(_ready_line(_lines(proc.stdout), proc, starts="{"))
        assert (doc["format"], doc["format_version"]) == ("fsmbench.serve", 1)
        assert doc["protocol"] == "tango" and doc["backend"] == "twin"
        assert doc["speed"] == 50.0 and doc["device"] == "fsmbench/bench/1"
        assert doc["address"].endswith(f":{port}/fsmbench/bench/1#dbase=no"), doc
        assert doc["output_folder"] == doc["controllers_folder"] == str((tmp_path / "live")
                                                                        .resolve())
        proxy = _connect(doc["address"].replace(doc["address"].split("/")[2],
                                                f"localhost:{port}"))
        assert proxy.state() == tango.DevState.ON
        proc.terminate()
        assert proc.wait(timeout=WAIT_S) == 0


def _serve_error(capsys: pytest.CaptureFixture[str], *args: str) -> str:
    """``fsmbench serve ARGS`` (the console script's entry point, in this process) expecting
    a user error: status 2, one line on stderr; returns it."""
    status = main(["serve", *args])
    err = capsys.readouterr().err
    assert status == 2, (status, err)
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("fsmbench serve: error:"), lines[0]
    return lines[0]


def test_playback_without_a_folder_is_refused(capsys: pytest.CaptureFixture[str]) -> None:
    line = _serve_error(capsys, "--backend", "playback", "--nodb", "--port", "0")
    assert "--backend playback needs the folder to play" in line


def test_playback_of_a_missing_folder_is_refused(tmp_path: Path,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    missing = tmp_path / "no-such-recordings"
    line = _serve_error(capsys, "--backend", "playback", str(missing), "--nodb", "--port", "0")
    assert f"{missing}: no such folder of recordings" in line


def test_a_missing_controllers_folder_is_refused(tmp_path: Path,
                                                capsys: pytest.CaptureFixture[str]) -> None:
    missing = tmp_path / "no-such-controllers"
    line = _serve_error(capsys, "--controllers", str(missing), "--nodb", "--port", "0")
    assert f"--controllers {missing}: no such folder" in line
    from fsmbench.live.serve import ServeOptions

    # The property the database gets: resolved; empty without the option (OutputFolder's).
    options = ServeOptions(backend="twin", playback_folder=None, params_file=None, seed=0,
                           speed=1.0, nodb=True, port=0, output_folder=tmp_path / "out",
                           controllers_folder=tmp_path)
    assert options.properties()["ControllersFolder"] == str(tmp_path.resolve())
    assert ServeOptions(backend="twin", playback_folder=None, params_file=None, seed=0,
                        speed=1.0, nodb=True, port=0, output_folder=tmp_path
                        ).properties()["ControllersFolder"] == ""


def test_a_busy_port_is_refused(capsys: pytest.CaptureFixture[str]) -> None:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as busy:
        busy.bind(("", 0))
        busy.listen()
        port = busy.getsockname()[1]
        line = _serve_error(capsys, "--nodb", "--port", str(port))
    assert f"port {port} is not free" in line and "--port" in line


def test_an_unreachable_database_is_one_line(capsys: pytest.CaptureFixture[str],
                                             monkeypatch: pytest.MonkeyPatch) -> None:
    # Case 2.4: an unreachable TANGO_HOST ended in a traceback reported as a bug.
    monkeypatch.setenv("TANGO_HOST", f"127.0.0.1:{_free_port()}")  # nothing listens there
    line = _serve_error(capsys, "bench1", "--device", "test/fsm/1")
    assert "the Tango database at TANGO_HOST=127.0.0.1:" in line and "does not answer" in line
    from fsmbench.cli.starter import main as starter_main

    assert starter_main(["bench1"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("FsmBench bench1: error:") and \
        "does not answer" in err[0], err


def test_starter_entry_point_needs_an_instance(capsys: pytest.CaptureFixture[str]) -> None:
    from fsmbench.cli.starter import main as starter_main

    assert starter_main([]) == 2
    assert "usage: FsmBench INSTANCE" in capsys.readouterr().err


@pytest.mark.parametrize(("args", "words"), [
    (("--protocol", "epics"), "needs --prefix PREFIX"),
    (("--prefix", "BL1"), "--prefix is for --protocol epics"),
    (("--access-security", "x.acf"), "--access-security is for --protocol epics"),
    (("--protocol", "epics", "--prefix", "BL1", "--access-security", "/nonexistent.acf"),
     "cannot be read"),
    (("--protocol", "epics", "--prefix", "BL1", "--nodb"), "INSTANCE, --device and --nodb"),
    (("--protocol", "epics", "--prefix", "BL 1"), "--prefix 'BL 1'"),
    (("--device", "nodomain"), "not a Tango device name"),
    (("--speed", "1e-6", "--nodb", "--port", "0"), "outside [0.01, 100]"),
])
def test_option_mistakes_are_one_line(capsys: pytest.CaptureFixture[str], args: tuple[str, ...],
                                      words: str) -> None:
    assert words in _serve_error(capsys, *args)


def test_sigterm_stops_the_server_while_it_designs(tmp_path: Path) -> None:
    # Case 6.1: a multisine of period 1e5 s took the server to 15 GB and it ignored SIGTERM.
    # The longest period allowed (100 s, full band) is designed off the call; SIGTERM during
    # the design ends the server cleanly.
    port = _free_port()
    proc = subprocess.Popen([*SERVE, "--nodb", "--port", str(port), "--out",
                             str(tmp_path / "out")], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, cwd=tmp_path)
    try:
        _ready_line(_lines(proc.stdout), proc)
        proxy = _connect(f"tango://localhost:{port}/fsmbench/bench/1#dbase=no")
        reply = proxy.StartExcitation(json.dumps({"input": "Uch", "kind": "multisine",
                                                  "amplitude_v": 0.1, "period_s": 100}))
        assert "designing" in reply
        assert proxy.Task.startswith("designing") or json.loads(proxy.Excitation)
        proc.terminate()
        assert proc.wait(timeout=WAIT_S) == 0
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(timeout=WAIT_S)


def test_without_the_epics_extra_the_core_imports_and_epics_is_one_line(
        tmp_path: Path) -> None:
    # The epics extra is optional: without softioc and pyepics the package and serve import,
    # and --protocol epics says what to install, in one line.
    code = ("import sys\n"
            "sys.modules['softioc'] = None; sys.modules['epics'] = None\n"
            "import fsmbench.live.core, fsmbench.live.epics\n"
            "from fsmbench.cli import main\n"
            "sys.exit(main(['serve', '--protocol', 'epics', '--prefix', 'NOEXTRA']))\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=WAIT_S, cwd=tmp_path, check=False)
    lines = done.stderr.strip().splitlines()
    assert done.returncode == 2 and len(lines) == 1, done.stderr
    assert "pip install 'fsmbench[epics]'" in lines[0], lines


def test_the_ioc_s_document_names_its_prefix_and_access_file(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from fsmbench.live.announce import announce
    from fsmbench.live.serve import ServeOptions

    acf = tmp_path / "bench.acf"
    options = ServeOptions(backend="twin", playback_folder=None, params_file=None, seed=0,
                           speed=1.0, nodb=False, port=0, output_folder=tmp_path / "out",
                           protocol="epics", prefix="BL:FSM", access_security=acf,
                           controllers_folder=tmp_path / "ctrl", announce_json=True)
    announce(options, "not printed", address="ca://BL:FSM", prefix="BL:FSM",
             access_security=str(acf))
    doc = json.loads(capsys.readouterr().out)
    assert doc["address"] == "ca://BL:FSM" and doc["protocol"] == "epics"
    assert doc["controllers_folder"] == str((tmp_path / "ctrl").resolve())
    assert doc["access_security"] == str(acf)
    announce(ServeOptions(**{**options.__dict__, "announce_json": False}), "the sentence",
             address="ca://BL:FSM")
    assert capsys.readouterr().out == "the sentence\n"
