"""Soak of ``fsmbench tune --device`` under CPU load, with Ctrl-C at random times (issue 31).

    python benchmarks/tune_soak.py --protocol tango [--runs 20] [--interrupt 0.5]
                                   [--busy 2] [--seed 0] [--speed 50] [--keep DIR]

One ``fsmbench serve`` (the twin, ``--speed``: bench seconds per wall-clock second), a
Tango server without a database or an EPICS IOC on its own Channel Access port, with the
loop closed by the ESRF study's controller. ``--busy`` processes spin on the CPU the whole
time (the done-means' "a busy second process on each core"). Then ``--runs`` tune runs,
one after another, each naming as ``--running`` the controller the previous run left the
device on (its file and name when a run loaded one, else what the previous run started
from). A share ``--interrupt`` of the runs gets SIGINT at a random wall-clock time,
uniform over the typical run's length (the median of the uninterrupted runs so far; 60 s
before there is one), so it lands before, during and after the load.

After each run the script checks, and prints one row per run:

* the run gave a decision: exit status 0 with ``tune.json`` (loaded, refused, rolled back),
  or 130 after SIGINT with a sentence on stdout or stderr naming the controller the device
  is left on (or, interrupted while tune was still loading, that it had contacted no
  device);
* the device runs a checked controller: its ``Controller`` is the ESRF study's or one that
  a tune run loaded through ``LoadController`` (which checks a controller on the device's
  bench before it touches the loop), the loop closed, the device not in FAULT, no
  excitation playing;
* what tune said it left the device on is what the device runs.

Exit status 1 when any run fails a check. The table's last line is the count of runs,
decisions, interruptions (and where they landed) and failures.
"""

from __future__ import annotations

import argparse
import json
import os
import random
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

PYTHON = [sys.executable, "-m", "fsmbench.cli"]
START_WAIT_S = 120.0  # wall clock a server may take to start on two busy cores
RUN_LIMIT_S = 1800.0  # wall clock one tune run may take before the soak calls it hung


def _free_port(kind: int = socket.SOCK_STREAM) -> int:
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("", 0))
        return int(s.getsockname()[1])


def _wait(check: Callable[[], Any], what: str, timeout_s: float) -> Any:
    deadline = time.monotonic() + timeout_s
    while True:
        try:
            value = check()
        except Exception:
            value = None
        if value:
            return value
        if time.monotonic() > deadline:
            raise SystemExit(f"tune_soak: timed out after {timeout_s:g} s waiting for {what}")
        time.sleep(0.2)


class Device:
    """The served device, read and commanded the way its protocol's clients do."""

    address: str

    def read(self, name: str) -> Any:
        raise NotImplementedError

    def state(self) -> str:
        raise NotImplementedError

    def close_loop(self) -> None:
        raise NotImplementedError

    def close(self) -> None:
        """Release the client's connections."""


class TangoDevice(Device):
    def __init__(self, port: int) -> None:
        import tango

        self.address = f"tango://localhost:{port}/fsmbench/bench/1#dbase=no"
        self.proxy = _wait(lambda: self._proxy(tango), "the Tango server", START_WAIT_S)

    def _proxy(self, tango: Any) -> Any:
        proxy = tango.DeviceProxy(self.address)
        proxy.set_source(tango.DevSource.DEV)
        proxy.ping()
        return proxy

    def read(self, name: str) -> Any:
        return self.proxy.read_attribute(name).value

    def state(self) -> str:
        return str(self.proxy.state())

    def close_loop(self) -> None:
        self.proxy.CloseLoop()


class EpicsDevice(Device):
    def __init__(self, prefix: str) -> None:
        import epics

        self.epics = epics
        self.prefix = prefix
        self.address = f"ca://{prefix}"
        self.pvs: dict[str, Any] = {}
        _wait(lambda: self._pv("State").wait_for_connection(timeout=1.0), "the IOC",
              START_WAIT_S)

    def _pv(self, name: str) -> Any:
        if name not in self.pvs:
            self.pvs[name] = self.epics.PV(f"{self.prefix}:{name}", auto_monitor=False)
        return self.pvs[name]

    def read(self, name: str) -> Any:
        pv = self._pv(name)
        pv.wait_for_connection(timeout=10.0)
        return pv.get(as_string=True, use_monitor=False, timeout=10.0)

    def state(self) -> str:
        return str(self.read("State"))

    def close_loop(self) -> None:
        # The put completes when the command has run; a refusal (FSM_Settling on a busy
        # machine) is in ReplyCode: tried again, as an operator would.
        for _ in range(30):
            count = int(self.read("ReplyCount") or 0)
            self._pv("CloseLoop").put(1, wait=True, timeout=60.0)
            _wait(lambda c=count: int(self.read("ReplyCount") or 0) > c, "CloseLoop's reply",
                  60.0)
            if str(self.read("ReplyCode")) == "OK":
                return
            time.sleep(1.0)
        raise SystemExit(f"tune_soak: CloseLoop refused: {self.read('Reply')}")

    def close(self) -> None:
        for pv in self.pvs.values():
            pv.disconnect()
        self.epics.ca.finalize_libca()


@dataclass(frozen=True)
class RunRow:
    """One tune run: what it did and what the checks found."""

    index: int
    running: str
    status: int
    interrupted_at_s: float | None
    wall_s: float
    decision: str
    outcome: str
    said_left_on: str
    device_controller: str
    problems: tuple[str, ...]

    def line(self) -> str:
        sigint = "-" if self.interrupted_at_s is None else f"{self.interrupted_at_s:.0f} s"
        return (f"{self.index:3d}  {self.status:4d}  {sigint:>7}  {self.wall_s:6.0f} s  "
                f"{self.decision:12s} {self.outcome:12s} {self.device_controller[:46]:46s} "
                + ("ok" if not self.problems else "FAIL: " + "; ".join(self.problems)))


def _serve(protocol: str, *, out: Path, speed: float, env: dict[str, str]
           ) -> tuple[subprocess.Popen[bytes], Device]:
    live = out / "live"
    if protocol == "tango":
        port = _free_port()
        proc = subprocess.Popen([*PYTHON, "serve", "--nodb", "--port", str(port), "--speed",
                                 str(speed), "--out", str(live), "--controllers", str(out)],
                                stdout=(out / "serve.log").open("wb"),
                                stderr=subprocess.STDOUT, env=env)
        return proc, TangoDevice(port)
    prefix = f"SOAK{os.getpid()}"
    proc = subprocess.Popen([*PYTHON, "serve", "--protocol", "epics", "--prefix", prefix,
                             "--speed", str(speed), "--out", str(live), "--controllers",
                             str(out)], stdout=(out / "serve.log").open("wb"),
                            stderr=subprocess.STDOUT, env=env)
    return proc, EpicsDevice(prefix)


def _busy(n: int) -> list[subprocess.Popen[bytes]]:
    code = "while True: pass"
    return [subprocess.Popen([sys.executable, "-c", code]) for _ in range(n)]


def _sigint_default() -> None:
    """In the child before exec: SIGINT back to its default action."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _tune(device: Device, *, out: Path, running: str, seed: int, env: dict[str, str],
          interrupt_at_s: float | None, better_by_pct: float | None = None,
          after_line: tuple[str, float] | None = None) -> tuple[int, str, float, float | None]:
    """One ``tune --device`` run; its exit status, stdout and stderr, wall time and when
    SIGINT was sent [s] (None: not sent).

    ``interrupt_at_s``: SIGINT at that wall-clock time. ``after_line``: ``(text, delay_s)``,
    SIGINT ``delay_s`` after tune's progress (stderr) first shows ``text``: where in the
    run it lands, whatever the machine's load.
    """
    cmd = [*PYTHON, "tune", "--device", device.address, "--out", str(out), "--running",
           running, "--watch-s", "6", "--periods", "4", "--seed", str(seed)]
    if better_by_pct is not None:
        cmd += ["--better-by-pct", f"{better_by_pct:g}"]
    t0 = time.monotonic()
    # SIGINT as a terminal sends it: a soak started in the background (nohup, cmd &) runs
    # with SIGINT ignored, and its children inherit that; Python then keeps it ignored
    # and no run was ever interrupted (ten runs in a row exited 0 after their SIGINT).
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env,
                            preexec_fn=_sigint_default)
    err: list[bytes] = []
    seen = threading.Event()

    def read_err() -> None:
        assert proc.stderr is not None
        for line in iter(proc.stderr.readline, b""):
            err.append(line)
            if after_line is not None and after_line[0].encode() in line:
                seen.set()

    reader = threading.Thread(target=read_err, daemon=True)
    reader.start()
    sent: float | None = None
    if interrupt_at_s is not None:
        try:
            proc.wait(timeout=interrupt_at_s)
        except subprocess.TimeoutExpired:
            proc.send_signal(signal.SIGINT)
            sent = time.monotonic() - t0
    elif after_line is not None:
        while not seen.wait(0.1) and proc.poll() is None and \
                time.monotonic() - t0 < RUN_LIMIT_S:
            pass
        if seen.is_set():
            time.sleep(after_line[1])
            if proc.poll() is None:
                proc.send_signal(signal.SIGINT)
                sent = time.monotonic() - t0
    try:
        stdout, _ = proc.communicate(timeout=RUN_LIMIT_S)
    except subprocess.TimeoutExpired:
        proc.kill()
        stdout, _ = proc.communicate()
    reader.join(timeout=10)
    text = stdout.decode(errors="replace") + "\n" + b"".join(err).decode(errors="replace")
    return proc.returncode, text, time.monotonic() - t0, sent


def _next_running(tune_json: dict[str, Any], before: str) -> str:
    """The ``--running`` that names what a run left the device on."""
    tx = tune_json.get("transaction") or {}
    if tx.get("outcome") == "loaded":
        for sw in tune_json.get("switches", []):
            if sw.get("file"):
                key = str(sw.get("to", "")).split(" ", 1)[0] or "controller"
                return f"{sw['file']}::{key}"
    return before


def _check(device: Device, *, index: int, running: str, status: int, text: str,
           wall_s: float, interrupted_at_s: float | None, tune_json: dict[str, Any] | None,
           loaded: set[str], seed_name: str) -> RunRow:
    problems: list[str] = []
    decision = outcome = said = ""
    if tune_json is not None:
        decision = str(tune_json.get("decision", ""))
        tx = tune_json.get("transaction") or {}
        outcome = str(tx.get("outcome") or "")
        said = str(tx.get("left_on") or "")
        for sw in tune_json.get("switches", []):
            if sw.get("to"):
                loaded.add(str(sw["to"]))
    controller = str(device.read("Controller"))
    if status == 0:
        if tune_json is None or not decision:
            problems.append("exit 0 without a decision in tune.json")
    elif interrupted_at_s is not None and status == 130:
        if not any(words in text for words in ("left on", "still runs",
                                                 "before it contacted any device")):
            problems.append("interrupted without saying which controller the device runs")
    else:
        tail = " | ".join(text.strip().splitlines()[-3:])
        problems.append(f"exit status {status}: {tail}")
    if said and said != controller:
        problems.append(f"tune said it left the device on {said!r}; it runs {controller!r}")
    if controller != seed_name and controller not in loaded:
        problems.append(f"the device runs {controller!r}, which no LoadController checked")
    state = device.state()
    if state in ("FAULT", "MOVING") or str(device.read("LoopClosed")) not in ("True", "1",
                                                                                "Closed"):
        problems.append(f"the device is {state}, loop closed {device.read('LoopClosed')}")
    if str(device.read("Excitation")) not in ("{}", ""):
        problems.append(f"an excitation still plays: {device.read('Excitation')}")
    return RunRow(index=index, running=running, status=status,
                  interrupted_at_s=interrupted_at_s, wall_s=wall_s, decision=decision,
                  outcome=outcome, said_left_on=said, device_controller=controller,
                  problems=tuple(problems))


def soak(protocol: str, *, runs: int, interrupt: float, busy: int, seed: int, speed: float,
         work: Path, interrupt_at_s: Sequence[float | None] = (),
         window_s: tuple[float, float] | None = None, better_by_pct: float | None = None,
         after_text: str = "", after_max_s: float = 3.0,
         say: Callable[[str], None] = print) -> list[RunRow]:
    """The soak (see the module); one row per run.

    ``interrupt_at_s``: the first runs' SIGINT times [s of wall clock] (None: not
    interrupted), given instead of drawn; the later runs' are drawn, uniform over
    ``window_s`` when given (to land around the load), else over the typical run.
    ``better_by_pct``: tune's ``--better-by-pct`` (0: every candidate that passes its
    checks is loaded, so that interruptions can land during and after a load).
    ``after_text``: an interrupted run gets SIGINT a uniform 0 to ``after_max_s`` after its
    progress shows this text (e.g. ``decision recorded before the load``), instead of at a
    drawn time.
    """
    rng = random.Random(seed)
    env = dict(os.environ)
    env.setdefault("EPICS_CA_MAX_ARRAY_BYTES", "4000000")
    if protocol == "epics":
        # The IOC and its clients on their own Channel Access ports (no other IOC answers).
        server, beacon = _free_port(socket.SOCK_DGRAM), _free_port(socket.SOCK_DGRAM)
        env.update(EPICS_CA_SERVER_PORT=str(server), EPICS_CA_REPEATER_PORT=str(beacon),
                   EPICS_CA_ADDR_LIST="127.0.0.1", EPICS_CA_AUTO_ADDR_LIST="NO")
        os.environ.update({k: env[k] for k in ("EPICS_CA_SERVER_PORT", "EPICS_CA_REPEATER_PORT",
                                               "EPICS_CA_ADDR_LIST", "EPICS_CA_AUTO_ADDR_LIST",
                                               "EPICS_CA_MAX_ARRAY_BYTES")})
    server_proc, device = _serve(protocol, out=work, speed=speed, env=env)
    spinners = _busy(busy)
    rows: list[RunRow] = []
    try:
        _wait(lambda: device.state() == "ON", "the device ON", START_WAIT_S)
        device.close_loop()
        _wait(lambda: device.state() in ("RUNNING", "ALARM"),
              f"the loop closed (the device says {device.read('Status')!r})", START_WAIT_S)
        seed_name = str(device.read("Controller"))
        loaded: set[str] = set()
        running = "seed"
        say(f"{protocol}: {device.address}, {busy} busy processes, speed {speed:g}, starting "
            f"on {seed_name}")
        say("run  exit   SIGINT    wall  decision     outcome      device runs")
        for i in range(1, runs + 1):
            typical = statistics.median([r.wall_s for r in rows
                                         if r.interrupted_at_s is None and r.status == 0]
                                        or [60.0])
            lo, hi = window_s if window_s is not None else (1.0, typical)
            at = rng.uniform(lo, hi) if rng.random() < interrupt else None
            if i <= len(interrupt_at_s):
                at = interrupt_at_s[i - 1]
            out = work / f"run{i:02d}"
            after = None
            if after_text and at is not None:
                after, at = (after_text, rng.uniform(0.0, after_max_s)), None
            status, text, wall, sent = _tune(device, out=out, running=running,
                                             seed=seed + i, env=env, interrupt_at_s=at,
                                             better_by_pct=better_by_pct, after_line=after)
            path = out / "tune.json"
            js = json.loads(path.read_text()) if path.exists() else None
            row = _check(device, index=i, running=running, status=status, text=text,
                         wall_s=wall, interrupted_at_s=sent if status == 130 else None,
                         tune_json=js, loaded=loaded, seed_name=seed_name)
            rows.append(row)
            say(row.line())
            if row.problems:
                (work / f"run{i:02d}.log").write_text(text)
            if js is not None:
                running = _next_running(js, running)
            if str(device.read("Controller")) == seed_name:
                running = "seed"
            # After a trip or an interruption that left the loop open: closed again, as an
            # operator would, so that the next run starts from a running loop.
            if device.state() in ("ON",) and not row.problems:
                device.close_loop()
    finally:
        for p in spinners:
            p.kill()
        server_proc.send_signal(signal.SIGINT)
        try:
            server_proc.wait(timeout=60)
        except subprocess.TimeoutExpired:
            server_proc.kill()
        device.close()
    return rows


def summary(rows: Sequence[RunRow]) -> str:
    """The count of runs, decisions, interruptions (where they landed) and failures."""
    # An interrupted run's decision may be that nothing was loaded, said on its output.
    decided = sum(1 for r in rows if r.decision or (
        r.status == 130 and not any("without saying" in p for p in r.problems)))
    interrupted = [r for r in rows if r.interrupted_at_s is not None]
    landed: dict[str, int] = {}
    for r in interrupted:
        key = r.outcome or "before any decision"
        landed[key] = landed.get(key, 0) + 1
    outcomes: dict[str, int] = {}
    for r in rows:
        if r.interrupted_at_s is None:
            outcomes[r.decision or "none"] = outcomes.get(r.decision or "none", 0) + 1
    failed = sum(1 for r in rows if r.problems)
    return (f"{len(rows)} runs: {decided} gave a decision; uninterrupted: "
            + ", ".join(f"{k} {v}" for k, v in sorted(outcomes.items()))
            + f"; {len(interrupted)} interrupted ("
            + ", ".join(f"{k} {v}" for k, v in sorted(landed.items()))
            + f"); {failed} failed a check; median wall time "
            + f"{statistics.median([r.wall_s for r in rows]) if rows else 0:.0f} s")


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--protocol", choices=("tango", "epics"), default="tango")
    parser.add_argument("--runs", type=int, default=20)
    parser.add_argument("--interrupt", type=float, default=0.5,
                        help="share of the runs interrupted by SIGINT (default 0.5)")
    parser.add_argument("--busy", type=int, default=2, help="busy processes (default 2)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--speed", type=float, default=50.0)
    parser.add_argument("--keep", type=Path, default=None, help="work folder (kept)")
    parser.add_argument("--interrupt-at", type=str, default="",
                        help="the first runs' SIGINT times [s], comma-separated, - for none "
                             "(e.g. 8,-,40); the later runs' are drawn")
    parser.add_argument("--interrupt-window", type=str, default="",
                        help="draw the SIGINT times uniform in A,B [s of wall clock] (e.g. "
                             "60,110: around the load) instead of over the typical run")
    parser.add_argument("--interrupt-after", type=str, default="",
                        help="SIGINT a uniform 0 to --interrupt-after-max-s after tune's "
                             "progress shows this text (e.g. 'decision recorded before the "
                             "load'), wherever that lands in wall-clock time")
    parser.add_argument("--interrupt-after-max-s", type=float, default=3.0)
    parser.add_argument("--better-by-pct", type=float, default=None,
                        help="tune's --better-by-pct (0: load every candidate that passes "
                             "its checks, so that SIGINT can land during and after a load)")
    args = parser.parse_args(argv)
    times = [None if t.strip() == "-" else float(t) for t in args.interrupt_at.split(",")
             if t.strip()]
    window = tuple(float(x) for x in args.interrupt_window.split(",")) \
        if args.interrupt_window else None
    options = {"runs": args.runs, "interrupt": args.interrupt, "busy": args.busy,
               "seed": args.seed, "speed": args.speed, "interrupt_at_s": times,
               "window_s": window, "better_by_pct": args.better_by_pct,
               "after_text": args.interrupt_after, "after_max_s": args.interrupt_after_max_s}
    if args.keep is not None:
        args.keep.mkdir(parents=True, exist_ok=True)
        rows = soak(args.protocol, work=args.keep.resolve(), **options)  # type: ignore[arg-type]
    else:
        with tempfile.TemporaryDirectory() as tmp:
            rows = soak(args.protocol, work=Path(tmp), **options)  # type: ignore[arg-type]
    print(summary(rows))
    return 1 if any(r.problems for r in rows) else 0


if __name__ == "__main__":
    raise SystemExit(main())
