"""The live bench as an EPICS IOC (pythonSoftIOC, on EPICS base): the same core as Tango.

``fsmbench serve --protocol epics --prefix PREFIX`` serves one
:class:`~fsmbench.live.core.LiveBench` over Channel Access (and PV Access).
Its records come from the same table as the Tango attributes
(:data:`fsmbench.live.attributes.ATTRIBUTES`):

- a scalar is an ``ai`` (``longin``, ``bi``, a long string) ``PREFIX:<Name>``
  with ``EGU``, ``PREC``, ``LOPR``/``HOPR``, ``HIHI``/``HIGH``/``LOW``/``LOLO``
  (``MAJOR``/``MINOR``) with ``HYST``, and ``MDEL``/``ADEL`` from the change
  and archive criteria; a value that is not current or not finite is
  ``SEVR`` INVALID (``STAT`` TIMEOUT or UDF);
- a spectrum is a waveform, an image one waveform per row
  (``PREFIX:FrfMagnitudeVph``, ``…Vpv``);
- ``PREFIX:State`` (mbbi: ON, RUNNING, MOVING, ALARM MINOR, FAULT MAJOR) and
  ``PREFIX:Status``;
- a command is a record that runs it when processed: ``PREFIX:CloseLoop.PROC``
  (or a put of 1) for the commands without argument, a put of the JSON
  argument to ``PREFIX:Record`` and the others. The put completes when the
  command has run; ``PREFIX:Reply`` then says what it did, or why it was
  refused, ``PREFIX:ReplyCode`` is ``OK`` or the refusal's reason
  (``FSM_Settling``…, as Tango's), and ``PREFIX:Reply`` is in MINOR alarm
  (``STAT`` WRITE) after a refusal, until the next command succeeds;
  ``PREFIX:ReplyCount`` counts the replies.

The loaded controller is remembered in ``<out>/.fsmbench-ioc-<PREFIX>.json``;
``LoadController`` reads controller files only from ``--controllers DIR`` (default the
``--out`` folder).
This module imports softioc only when serving: it is the ``fsmbench[epics]`` extra.
"""

from __future__ import annotations

import contextlib
import ctypes
import faulthandler
import functools
import importlib.util
import logging
import math
import os
import re
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from fsmbench.live.announce import announce
from fsmbench.live.attributes import (
    ATTRIBUTES,
    AttributeSpec,
    QualityLatch,
    ca_units,
    evaluate,
    precision,
)
from fsmbench.live.states import STATES, Refused, plain

if TYPE_CHECKING:
    from fsmbench.live.core import LiveBench
    from fsmbench.live.serve import ServeOptions

__all__ = ["ACTIONS", "ARGUMENT_COMMANDS", "MAX_ARRAY_BYTES", "BenchIoc", "check_prefix",
           "pv_table", "serve_epics"]

#: Commands without argument (an Action record each) and with one (a long string).
ACTIONS = ("CloseLoop", "OpenLoop", "StopExcitation", "Abort", "Reset")
ARGUMENT_COMMANDS = ("LoadController", "StartExcitation", "RunExperiment", "Record")
#: Channel Access array size the IOC allows (a spectrum is 8193 doubles, 64 KiB, above
#: the 16 KiB default); clients need the same EPICS_CA_MAX_ARRAY_BYTES.
MAX_ARRAY_BYTES = 4_000_000
_UPDATE_S = 0.1  # how often the records are refreshed [s]
_SPECTRUM_S = 1.0  # least wall-clock time between two updates of a spectrum [s]
_STRING = 2048  # long-string records [bytes]
_PREFIX = re.compile(r"[A-Za-z0-9_:-]{1,40}")
#: Views refreshed with State before a command's put completes, and only there, Task last
#: (see BenchIoc._update_state).
_WITH_STATE = tuple(s for name in ("LoopClosed", "Controller", "Task") for s in ATTRIBUTES
                    if s.name == name)


def check_prefix(prefix: str) -> str:
    """A PV prefix: 1 to 40 of ``A-Z a-z 0-9 _ : -`` (record names stay under EPICS' 60)."""
    if not _PREFIX.fullmatch(prefix) or prefix.endswith(":"):
        raise ValueError(f"--prefix {prefix!r}: use 1 to 40 letters, digits, _, - or : (not "
                         "ending with :); the PVs are PREFIX:BeamAngleH, ...")
    return prefix


def pv_table() -> str:
    """The PV table of the README (Markdown), from the records :class:`BenchIoc` makes."""
    lines = ["| PV | record | fields | does |", "|---|---|---|---|"]
    for spec in ATTRIBUTES:
        if spec.kind == "float" and not spec.writable:
            kind, fields = "ai", "EGU, PREC, LOPR/HOPR, the table's limits as HIHI/HIGH/LOW/" \
                                 "LOLO with HYST, change and archive criteria as MDEL/ADEL"
        elif spec.kind == "float":
            kind, fields = "ao (put to set)", "LOPR/HOPR 0.01/100; a put outside is refused " \
                                              "in Reply"
        else:
            kind, fields = {"int": ("longin", "MDEL/ADEL"), "bool": ("bi", "ZNAM Open, ONAM "
                                                                     "Closed"),
                            "str": ("long string (lsi)", "read with caget -S"),
                            "spectrum": ("waveform of double", "EGU, PREC, NELM"),
                            "image": ("waveform of double per row", "EGU, PREC, NELM")
                            }[spec.kind]
        names = [f"`PREFIX:{spec.name}{row}`" for row in spec.rows] if spec.rows else \
            [f"`PREFIX:{spec.name}`"]
        doc = spec.doc.replace("|", "\\|")
        lines.append(f"| {', '.join(names)} | {kind} | {fields} | {doc} |")
    lines += [
        "| `PREFIX:State` | mbbi | ON, RUNNING, MOVING, ALARM (MINOR), FAULT (MAJOR) | the "
        "state, from the facts |",
        "| `PREFIX:Status` | long string | – | the state in words: why, since when, what "
        "runs, the last outcome |",
        *(f"| `PREFIX:{name}`, `PREFIX:{name}.PROC` | Action (bo) | put 1, or process | runs "
          f"{name}; the put completes when it has run or was refused |" for name in ACTIONS),
        *(f"| `PREFIX:{name}` | long string out | put the argument (JSON or a name) | runs "
          f"{name} with it; the put completes when it has started or was refused |"
          for name in ARGUMENT_COMMANDS),
        "| `PREFIX:Reply` | long string | SEVR MINOR, STAT WRITE after a refusal | what the "
        "last command did, or why it was refused (the sentence of Tango's DevFailed) |",
        "| `PREFIX:ReplyCode` | stringin | – | `OK`, or the refusal's reason code "
        "(`FSM_Settling`, ...: Tango's DevFailed reason) |",
        "| `PREFIX:ReplyCount` | longin | – | replies so far (a client sees its command's "
        "reply when it has grown) |",
    ]
    return "\n".join(lines)


def _already_served(prefix: str) -> str:
    """What answers for ``PREFIX:Heartbeat`` already ("" when nothing), by a CA client.

    A separate process: pyepics' libca next to softioc's EPICS base in one
    process is not supported. Without pyepics the check is skipped.
    """
    code = ("import sys, epics\n"
            "pv = epics.PV(sys.argv[1], connection_timeout=1.5)\n"
            "print(pv.host if pv.wait_for_connection(timeout=1.5) else '')\n")
    try:
        out = subprocess.run([sys.executable, "-c", code, f"{prefix}:Heartbeat"],
                             capture_output=True, text=True, timeout=20, check=False)
    except (OSError, subprocess.TimeoutExpired):
        return ""
    return out.stdout.strip() if out.returncode == 0 else ""


def _readable_acf(path: Path) -> Path:
    """The access-security file, checked before anything starts (EPICS reads it in
    ``iocInit`` and, when it cannot, refuses every put)."""
    path = Path(path).resolve()
    try:
        text = path.read_text(encoding="ascii")
    except (OSError, UnicodeDecodeError) as exc:
        raise ValueError(f"--access-security {path}: cannot be read as an ASCII access-"
                         f"security file ({exc})") from None
    if "ASG(" not in text.replace(" ", ""):
        raise ValueError(f"--access-security {path}: no ASG(...) group; the records use "
                         "ASG(DEFAULT), e.g. ASG(DEFAULT) { RULE(1, READ) RULE(1, WRITE) "
                         "{ UAG(operators) } }")
    return path


def _access_security(path: Path) -> None:
    """Hand the file to EPICS before ``iocInit``, which parses it (``asInit``)."""
    from softioc import imports

    set_filename = imports.dbCore.asSetFilename
    set_filename.argtypes = (ctypes.c_char_p,)
    set_filename.restype = ctypes.c_int
    if set_filename(str(path).encode()) != 0:
        raise ValueError(f"--access-security {path}: EPICS refused the file name")


def _access_security_active(path: Path) -> None:
    """After ``iocInit``: a file EPICS could not parse leaves the IOC serving nothing (its
    ``asInit`` failed), so the server stops with EPICS's message above ours."""
    from softioc import imports

    if not ctypes.c_int.in_dll(imports.dbCore, "asActive").value:
        raise ValueError(f"--access-security {path}: EPICS cannot parse it (its message "
                         "above names the line); the IOC is not served")


class BenchIoc:
    """The records of one bench (see the module notes); build before ``iocInit``.

    Parameters
    ----------
    bench : LiveBench
    prefix : str
    """

    def __init__(self, bench: LiveBench, prefix: str) -> None:
        from softioc import builder

        self.bench = bench
        self.prefix = prefix
        self._latch = QualityLatch()
        self._records: dict[str, Any] = {}
        self._last_arrays: dict[str, Any] = {}
        self._posted: dict[str, tuple[Any, ...]] = {}
        self._refused: set[str] = set()  # records whose last update failed (logged once)
        self._lengths: dict[str, int] = {}
        self._stop = threading.Event()
        self._wake = threading.Event()
        self._thread: threading.Thread | None = None
        self._lock = threading.Lock()  # one command at a time
        self._state_lock = threading.Lock()
        builder.SetDeviceName(prefix)
        n_points = len(bench.asd_frequency()) or self._spectrum_points()
        for spec in ATTRIBUTES:
            self._make(builder, spec, n_points)
        self._records["State"] = builder.mbbIn(
            "State", *[(s, {"ALARM": "MINOR", "FAULT": "MAJOR"}.get(s, "NO_ALARM"))
                       for s in STATES], DESC="ON RUNNING MOVING ALARM FAULT")
        self._records["Status"] = builder.longStringIn("Status", length=_STRING)
        self._records["Reply"] = builder.longStringIn("Reply", length=_STRING)
        self._records["ReplyCode"] = builder.stringIn("ReplyCode", initial_value="OK")
        self._records["ReplyCount"] = builder.longIn("ReplyCount", initial_value=0)
        for name in ACTIONS:
            # initial_value: defined from the start (UDF made each SEVR INVALID until used).
            self._records[name] = builder.Action(
                name, on_update=self._action(name), blocking=True, initial_value=False,
                DESC=f"process to run {name}")
        for name in ARGUMENT_COMMANDS:
            self._records[name] = builder.longStringOut(
                name, length=_STRING, always_update=True, blocking=True,
                on_update=self._action(name), DESC=f"put the argument to run {name}")

    def _spectrum_points(self) -> int:
        from fsmbench.signal.welch import default_nfft  # the server's start: see serve_epics

        return default_nfft(math.ceil(self.bench.fs_hz)) // 2 + 1  # 1 s Hann window

    def _make(self, builder: Any, spec: AttributeSpec, n_points: int) -> None:
        lim, ev = spec.limits, spec.events
        fields: dict[str, Any] = {"DESC": spec.doc[:40]}
        if spec.kind in ("float", "int", "spectrum", "image"):
            fields["EGU"] = ca_units(spec.egu)
        if spec.display is not None:
            fields.update(LOPR=spec.display[0], HOPR=spec.display[1])
        if spec.kind == "float" and not spec.writable:
            for field, value, sev in (("HIHI", lim.high_alarm, "MAJOR"),
                                      ("HIGH", lim.high_warning, "MINOR"),
                                      ("LOW", lim.low_warning, "MINOR"),
                                      ("LOLO", lim.low_alarm, "MAJOR")):
                if value is not None:
                    fields[field] = value
                    fields[{"HIHI": "HHSV", "HIGH": "HSV", "LOW": "LSV", "LOLO": "LLSV"}[field]] \
                        = sev
            fields["HYST"] = lim.hysteresis
            fields["MDEL"] = ev.abs_change if ev.abs_change is not None else 0.0
            fields["ADEL"] = ev.archive_abs_change if ev.archive_abs_change is not None else 0.0
            self._records[spec.name] = builder.aIn(spec.name, PREC=precision(spec.fmt),
                                                   initial_value=0.0, **fields)
        elif spec.kind == "float":
            self._records[spec.name] = builder.aOut(
                spec.name, PREC=3, initial_value=float(self.bench.speed),
                on_update=self._speed, blocking=True, always_update=True, **fields)
        elif spec.kind == "int":
            fields["MDEL"] = int(ev.abs_change or 0)
            fields["ADEL"] = int(ev.archive_abs_change or 0)
            self._records[spec.name] = builder.longIn(spec.name, initial_value=0, **fields)
        elif spec.kind == "bool":
            self._records[spec.name] = builder.boolIn(spec.name, ZNAM="Open", ONAM="Closed",
                                                      initial_value=False, **fields)
        elif spec.kind == "str":
            self._records[spec.name] = builder.longStringIn(spec.name, length=_STRING,
                                                            **fields)
        else:
            for row in spec.rows or ("",):
                self._lengths[spec.name + row] = n_points
                self._records[spec.name + row] = builder.WaveformIn(
                    spec.name + row, length=n_points, datatype=float,
                    PREC=precision(spec.fmt), **fields)

    # -- commands ------------------------------------------------------------------

    def _reply(self, code: str, text: str) -> None:
        from softioc import alarm

        rec = self._records
        refused = code != "OK"
        # The Reply record carries the refusal's alarm (never the command record: setting an
        # alarm processes an output record, which would run the command again).
        rec["Reply"].set(plain(text)[:_STRING - 1],
                         severity=alarm.MINOR_ALARM if refused else alarm.NO_ALARM,
                         alarm=alarm.WRITE_ALARM if refused else alarm.NO_ALARM)
        rec["ReplyCode"].set(code[:39])
        self._update_state()  # before the put completes: a client then reads the new state
        rec["ReplyCount"].set(rec["ReplyCount"].get() + 1)
        self._wake.set()

    def _run(self, name: str, fn: Callable[[], str]) -> None:
        with self._lock:
            try:
                reply = fn()
            except Refused as refused:
                text = refused.sentence if refused.sentence.startswith(name) else \
                    f"{name} refused: {refused.sentence}"
                self._reply(refused.reason, text)
                return
            except Exception as exc:
                self.bench.log("ERROR", f"{name} failed: {type(exc).__name__}: {exc}")
                self._reply("FSM_Internal", f"{name} failed: {type(exc).__name__}: {exc} (a "
                                            "bug; the bench runs on)")
                return
            self._reply("OK", f"{name}: {reply}")

    def _action(self, name: str) -> Callable[[Any], None]:
        method = {"CloseLoop": "close_loop", "OpenLoop": "open_loop",
                  "StopExcitation": "stop_excitation", "Abort": "abort", "Reset": "reset",
                  "LoadController": "load_controller", "StartExcitation": "start_excitation",
                  "RunExperiment": "run_experiment", "Record": "record"}[name]

        def run(value: Any) -> None:
            fn = getattr(self.bench, method)
            if name in ARGUMENT_COMMANDS:
                self._run(name, lambda: fn(str(value)))
            else:
                self._run(name, fn)

        return run

    def _speed(self, value: float) -> None:
        def set_speed() -> str:
            self.bench.speed = float(value)
            return f"SpeedFactor set to {self.bench.speed:g}"

        self._run("SpeedFactor", set_speed)
        if self.bench.speed != value:  # refused: show the speed in force
            self._records["SpeedFactor"].set(self.bench.speed, process=False)

    # -- updates -------------------------------------------------------------------

    def _post(self, name: str, value: Any, **alarm: Any) -> None:
        """Set a record only when its value or alarm changes.

        Each ``set`` processes the record, and softioc's string records then post a
        monitor whatever the value: 7 a second of one text (an archiver in monitor mode
        keeps each). The numbers have their deadbands (MDEL, ADEL) as well.
        """
        key = (value, tuple(sorted(alarm.items())))
        if self._posted.get(name) == key:
            return
        self._records[name].set(value, **alarm)
        self._posted[name] = key

    def start(self) -> None:
        """Refresh the records from the bench, in a thread, until :meth:`stop`."""
        self._thread = threading.Thread(target=self._updates, name="fsmbench-ioc", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        """Stop refreshing."""
        self._stop.set()
        self._wake.set()
        if self._thread is not None:
            self._thread.join(5.0)

    def changed(self, view: str) -> None:
        """The bench's ``on_change``: refresh at once."""
        self._wake.set()

    def _updates(self) -> None:
        while not self._stop.is_set():
            self._wake.wait(_UPDATE_S)
            self._wake.clear()
            try:
                self.update()
            except Exception as exc:  # a record refusing a value must not stop the updates
                self.bench.log("WARNING", f"IOC update failed: {type(exc).__name__}: {exc}")

    def update(self) -> None:
        """Put the bench's views into the records (their severity with them).

        Record by record: one record refusing its value must not hold the others (a
        stall's INVALID count once stopped every later record, Controller and State
        among them, and a client then read the controller of before a load).
        """
        for spec in ATTRIBUTES:
            if spec in _WITH_STATE:
                continue  # with State, below
            self._guarded(spec.name, functools.partial(self._update_one, spec))
        self._guarded("State", self._update_state)

    def _guarded(self, name: str, update: Callable[[], None]) -> None:
        """``update()``, a failure logged once per record until it updates again."""
        try:
            update()
        except Exception as exc:
            if name not in self._refused:
                self._refused.add(name)
                self.bench.log("WARNING", f"IOC update of {self.prefix}:{name} failed: "
                                          f"{type(exc).__name__}: {exc}")
        else:
            self._refused.discard(name)

    def _update_one(self, spec: Any) -> None:
        """One attribute's record (its rows for a spectrum or an image)."""
        from softioc import alarm

        rec = self._records
        value, quality = evaluate(spec, self.bench, self._latch)
        if spec.kind in ("spectrum", "image"):
            if quality == "INVALID" or value is None:
                return
            rows = [value] if spec.kind == "spectrum" else list(value)
            for i, row in enumerate(spec.rows or ("",)):
                data = np.asarray(rows[i] if i < len(rows) else [], dtype=float)
                key = spec.name + row
                last, when = self._last_arrays.get(key, (None, -np.inf))
                # At most once a wall-clock second: at 50x the estimators renew 50 times
                # a second, and 64 KiB monitors that fast stall a client's event queue.
                if (last is None or last.shape != data.shape or
                        not np.array_equal(last, data)) and \
                        time.monotonic() - when >= _SPECTRUM_S:
                    self._last_arrays[key] = (data, time.monotonic())
                    rec[key].set(data[:self._lengths[key]])
            return
        if spec.writable:
            return  # SpeedFactor: its own record
        if spec.kind == "str":
            self._post(spec.name, plain(str(value))[:_STRING - 1])
        elif spec.kind == "bool":
            self._post(spec.name, bool(value))
        elif quality == "INVALID":
            stale = value is not None and math.isfinite(float(value))
            shown = float(value) if stale else 0.0
            # A longIn takes only an int: a float there raised and, before, cut the update
            self._post(spec.name, round(shown) if spec.kind == "int" else shown,
                       severity=alarm.INVALID_ALARM,
                       alarm=alarm.TIMEOUT_ALARM if stale else alarm.UDF_ALARM)
        else:
            self._post(spec.name, value)

    def _update_state(self) -> None:
        from softioc import alarm

        with self._state_lock:
            # Task is read first and written last: a task's result is in place (under the
            # bench's lock) before Task reads empty, so a client that sees Task empty reads
            # the Controller, LoopClosed and State it left (one read each, not one update).
            values = {spec.name: evaluate(spec, self.bench, self._latch)[0]
                      for spec in reversed(_WITH_STATE)}
            state = self.bench.state
            status = self.bench.status
            severity = {"ALARM": alarm.MINOR_ALARM, "FAULT": alarm.MAJOR_ALARM}.get(state, 0)
            self._post("State", STATES.index(state), severity=severity,
                       alarm=alarm.STATE_ALARM if severity else alarm.NO_ALARM)
            self._post("Status", plain(status)[:_STRING - 1])
            for spec in _WITH_STATE:
                value = values[spec.name]
                if value is not None:
                    self._post(spec.name, value if spec.kind == "bool"
                               else plain(str(value))[:_STRING - 1])


def serve_epics(options: ServeOptions, *, ready: str = "") -> int:
    """Run the IOC until SIGTERM or Ctrl-C; returns the exit status."""
    if importlib.util.find_spec("softioc") is None:
        raise ValueError("--protocol epics needs pythonSoftIOC: pip install 'fsmbench[epics]'")
    prefix = check_prefix(options.prefix)
    if not logging.getLogger().handlers:
        logging.basicConfig(level=logging.INFO, stream=sys.stderr,
                            format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    os.environ.setdefault("EPICS_CA_MAX_ARRAY_BYTES", str(MAX_ARRAY_BYTES))
    acf = _readable_acf(options.access_security) if options.access_security else None
    # Before the heavy imports (EPICS base, the bench's models): a prefix already served is
    # refused in the time a CA client takes to find it.
    host = _already_served(prefix)
    if host:
        raise ValueError(f"{prefix}:Heartbeat already answers (an IOC at {host}): stop it, or "
                         "choose another --prefix")
    from softioc import asyncio_dispatcher, builder, softioc

    # After the prefix check: a second IOC is refused before the bench's models load.
    from fsmbench.bench.params import default_bench, load_bench
    from fsmbench.live.core import FileMemory, LiveBench
    from fsmbench.twin.identified import identified_bench

    bench = load_bench(options.params_file) if options.params_file else default_bench()
    if options.bench_folder is not None:
        bench = identified_bench(options.bench_folder, bench=bench)
    out = options.output_folder.resolve()
    memory = FileMemory(out / f".fsmbench-ioc-{prefix.replace(':', '_')}.json")
    ioc: BenchIoc | None = None
    live = LiveBench(bench, backend=options.backend, playback_folder=options.playback_folder,
                     seed=options.seed, speed=options.speed, output_folder=out,
                     controllers_folder=(options.controllers_folder or out).resolve(),
                     watchdog_s=options.watchdog_s, memory=memory,
                     drift_pct_per_h=options.drift_pct_per_h,
                     drift_start_s=options.drift_start_s,
                     on_change=lambda view: ioc.changed(view) if ioc is not None else None)
    ioc = BenchIoc(live, prefix)
    builder.LoadDatabase()
    if acf is not None:
        _access_security(acf)
    dispatcher = asyncio_dispatcher.AsyncioDispatcher()
    softioc.iocInit(dispatcher)
    if acf is not None:
        _access_security_active(acf)
    stop = threading.Event()
    # kill -USR1 <pid>: every thread's stack on stderr (what a stuck IOC is doing).
    faulthandler.register(signal.SIGUSR1, all_threads=True)
    received: list[int] = []

    def on_signal(sig: int, _frame: Any) -> None:
        received.append(sig)
        stop.set()

    handlers = {sig: signal.signal(sig, on_signal) for sig in (signal.SIGTERM, signal.SIGINT)}
    try:
        live.start()
        live.log("INFO", live.restore_controller())
        ioc.update()
        ioc.start()
        announce(options, f"fsmbench serve: IOC {prefix} ({options.backend}, speed "
                          f"{options.speed:g}): {prefix}:BeamAngleH, {prefix}:State, "
                          f"{prefix}:CloseLoop ...{ready}", address=f"ca://{prefix}",
                 prefix=prefix, access_security=None if options.access_security is None
                 else str(options.access_security.resolve()))
        # Short waits: the handler runs in this thread between them, whatever else blocks.
        while not stop.wait(0.5):
            pass
        live.log("INFO", f"stopping on {signal.Signals(received[0]).name}: the records stop, "
                         "a running recording keeps what it has")
    finally:
        for sig, handler in handlers.items():
            with contextlib.suppress(ValueError):
                signal.signal(sig, handler)
        ioc.stop()
        live.stop()
        dispatcher.close()
    return 0
