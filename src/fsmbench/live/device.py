"""``FsmBench``: the bench as a Tango device (PyTango high-level API).

A thin layer over :class:`fsmbench.live.core.LiveBench`. The attributes are
made from the protocol-neutral table :data:`fsmbench.live.attributes.ATTRIBUTES`
(unit, format, limits, event criteria, polling), each read with its quality
(INVALID when not current, ALARM/WARNING from the limits). Every command is
checked against the state first (``is_<Command>_allowed``); a refusal is a
``DevFailed`` whose reason is a code (``FSM_BadArgument``, ``FSM_Settling``…,
:data:`fsmbench.live.states.REASONS`) and whose description is one ASCII
sentence, origin ``<device>/<command>`` (never a Python traceback).

Events: the polled scalars send change, archive and periodic events by their
criteria; ``State``, ``Status``, ``LoopClosed``, ``Controller``,
``Excitation``, ``SpeedFactor`` and ``Task`` are pushed (change and archive)
by one pusher thread whenever the bench says they changed; ``Init`` pushes
``State``. Every command, state change, trip and refusal goes to the Tango
logging (DEBUG, INFO, WARNING, ERROR).

Device properties: ``Backend`` (``twin`` or ``playback``), ``PlaybackFolder``,
``ParamsFile``, ``BenchFolder``, ``Seed``, ``Speed``, ``OutputFolder``,
``ControllersFolder`` (the only folder ``LoadController`` reads; empty: ``OutputFolder``),
``WatchdogSeconds``, ``DriftRate``, ``DriftStart`` (read from the database; written
there, as defaults, only when absent) and ``MemorisedController`` (the device's own: the controller
loaded, so that a restart brings it back).

This module imports PyTango: it is the ``fsmbench[tango]`` extra.
"""

from __future__ import annotations

import json
import queue
import threading
import time
import traceback
from collections.abc import Callable
from typing import Any

import numpy as np
import tango
from tango import AttrQuality, AttrWriteType, DevState, EnsureOmniThread
from tango.server import Device, attribute, command, device_property

from fsmbench.bench.params import default_bench, load_bench
from fsmbench.live.attributes import (
    ATTRIBUTES,
    MAX_SPECTRUM,
    PUSHED,
    AttributeSpec,
    QualityLatch,
    by_name,
    evaluate,
)
from fsmbench.live.core import LiveBench
from fsmbench.live.states import Refused, plain
from fsmbench.twin.identified import identified_bench

__all__ = ["DEFAULT_DEVICE_NAME", "EMPTY_TEXT", "PROPERTY_DEFAULTS", "FsmBench"]

DEFAULT_DEVICE_NAME = "fsmbench/bench/1"
_STATES = {"ON": DevState.ON, "RUNNING": DevState.RUNNING, "MOVING": DevState.MOVING,
           "ALARM": DevState.ALARM, "FAULT": DevState.FAULT}
_QUALITY = {"VALID": AttrQuality.ATTR_VALID, "WARNING": AttrQuality.ATTR_WARNING,
            "ALARM": AttrQuality.ATTR_ALARM, "INVALID": AttrQuality.ATTR_INVALID}
_DTYPE: dict[str, Any] = {"float": float, "int": int, "bool": bool, "str": str,
                          "spectrum": (float,), "image": ((float,),)}
EMPTY_TEXT: dict[str, Any] = {"float": float("nan"), "int": 0, "bool": False, "str": "",
                          "spectrum": np.zeros(0), "image": np.zeros((0, 0))}
#: Properties an administrator sets, with the defaults written when absent (text).
PROPERTY_DEFAULTS = {"Backend": "twin", "PlaybackFolder": "", "ParamsFile": "",
                     "BenchFolder": "", "Seed": "0", "Speed": "1.0",
                     "OutputFolder": "fsmbench-live", "ControllersFolder": "",
                     "WatchdogSeconds": "5.0",
                     "DriftRate": "0.0", "DriftStart": "0.0"}
_MEMORY = "MemorisedController"


def _tango_attribute(spec: AttributeSpec) -> Any:
    """A PyTango attribute from a row of the table."""
    kw: dict[str, Any] = {"name": spec.name, "dtype": _DTYPE[spec.kind], "doc": spec.doc,
                          "label": spec.name}
    if spec.kind in ("float", "int", "spectrum", "image"):
        kw.update(unit=spec.unit, format=spec.fmt, standard_unit=spec.standard_unit,
                  display_unit="1")
    if spec.kind == "spectrum":
        kw["max_dim_x"] = MAX_SPECTRUM
    if spec.kind == "image":
        kw.update(max_dim_x=MAX_SPECTRUM, max_dim_y=len(spec.rows))
    lim, ev = spec.limits, spec.events
    for key, value in (("min_alarm", lim.low_alarm), ("max_alarm", lim.high_alarm),
                       ("min_warning", lim.low_warning), ("max_warning", lim.high_warning),
                       ("min_value", spec.min_value), ("max_value", spec.max_value)):
        if value is not None:
            kw[key] = value
    if spec.kind in ("float", "int") and ev.polling_ms is not None:
        kw.update(polling_period=ev.polling_ms, period=str(ev.period_ms),
                  archive_period=str(ev.archive_period_ms))
        for key, value in (("abs_change", ev.abs_change), ("rel_change", ev.rel_change),
                           ("archive_abs_change", ev.archive_abs_change),
                           ("archive_rel_change", ev.archive_rel_change)):
            if value is not None:
                kw[key] = str(value)
    name = spec.name

    def read(self: FsmBench) -> Any:
        return self._read(by_name(name))

    kw["fget"] = read
    if spec.writable:
        kw["access"] = AttrWriteType.READ_WRITE

        def write(self: FsmBench, value: float) -> None:
            self._write(name, value)

        kw["fset"] = write
    return attribute(**kw)


class _Pusher:
    """Pushes change and archive events of the views the bench says changed, in one thread.

    The bench calls :meth:`put` from any of its threads, never blocking; the
    push itself takes the device's monitor, which a client call may hold.
    """

    def __init__(self, device: FsmBench) -> None:
        self._device = device
        self._queue: queue.Queue[str | None] = queue.Queue()
        self._thread = threading.Thread(target=self._run, name="fsmbench-events", daemon=True)
        self._thread.start()

    def put(self, view: str) -> None:
        self._queue.put(view)

    def stop(self) -> None:
        self._queue.put(None)
        self._thread.join(5.0)

    def _run(self) -> None:
        with EnsureOmniThread():
            while (view := self._queue.get()) is not None:
                try:
                    self._device._push(view)
                except Exception as exc:  # a push refused (monitor busy): the next one wins
                    self._device._log("DEBUG", f"event {view} not pushed: {exc}")


class FsmBench(Device):
    """The fast-steering-mirror bench, live (the twin by default)."""

    Backend = device_property(dtype=str, default_value="twin",
                              doc="twin (the simulated bench) or playback (a folder replayed)")
    PlaybackFolder = device_property(dtype=str, default_value="",
                                     doc="folder of recordings for the playback backend")
    ParamsFile = device_property(dtype=str, default_value="",
                                 doc="bench parameters (TOML); empty: the packaged bench")
    BenchFolder = device_property(dtype=str, default_value="",
                                  doc="identification folder (fsmbench identify or study): the "
                                      "twin simulates that bench; empty: the bench file's")
    Seed = device_property(dtype=int, default_value=0, doc="seed of every noise source")
    Speed = device_property(dtype=float, default_value=1.0,
                            doc="bench seconds per wall-clock second at start")
    OutputFolder = device_property(dtype=str, default_value="fsmbench-live",
                                   doc="where RunExperiment and Record write")
    ControllersFolder = device_property(dtype=str, default_value="",
                                        doc="the only folder LoadController reads controller "
                                            "files from (relative paths are inside it); "
                                            "empty: OutputFolder")
    WatchdogSeconds = device_property(dtype=float, default_value=5.0,
                                      doc="wall-clock seconds without a bench block that make "
                                          "the device FAULT")
    DriftRate = device_property(dtype=float, default_value=0.0,
                                doc="twin: the Sercalo resonance drifts this fast [%/h] (0: "
                                    "none; for the loop's watch)")
    DriftStart = device_property(dtype=float, default_value=0.0,
                                 doc="twin: the bench time the drift starts [s]")
    MemorisedController = device_property(dtype=str, default_value="",
                                          doc="written by the device: the controller loaded "
                                              "(JSON), loaded again at start")

    for _spec in ATTRIBUTES:
        vars()[_spec.name] = _tango_attribute(_spec)
    del _spec

    # -- life cycle ----------------------------------------------------------------

    def init_device(self) -> None:
        super().init_device()
        self.bench: LiveBench | None = None
        self._latch = QualityLatch()
        self._init_error = ""
        for name in ("State", "Status", *PUSHED):
            self.set_change_event(name, True, False)
            self.set_archive_event(name, True, False)
        self._pusher = _Pusher(self)
        self._write_absent_properties()
        try:
            bench = load_bench(self.ParamsFile) if self.ParamsFile else default_bench()
            if self.BenchFolder:
                bench = identified_bench(self.BenchFolder, bench=bench,
                                         option="the BenchFolder property")
            self.bench = LiveBench(bench, backend=self.Backend,
                                   playback_folder=self.PlaybackFolder or None, seed=self.Seed,
                                   speed=self.Speed, output_folder=self.OutputFolder,
                                   controllers_folder=self.ControllersFolder or None,
                                   watchdog_s=self.WatchdogSeconds, log=self._log,
                                   on_change=self._pusher.put, memory=_Memory(self),
                                   thread_init=EnsureOmniThread,
                                   drift_pct_per_h=self.DriftRate,
                                   drift_start_s=self.DriftStart)
        except Exception as exc:
            self._init_error = plain(f"The device could not start: {exc}. Fix the property "
                                     "and run Init.")
            self._log("ERROR", self._init_error)
        else:
            self.bench.start()
            self._log("INFO", f"Init: {self.bench.restore_controller()}")
        self._pusher.put("State")
        self._pusher.put("Status")

    def delete_device(self) -> None:
        bench = getattr(self, "bench", None)
        if bench is not None and not tango.Util.instance().is_svr_shutting_down():
            # Init (and the admin's DevRestart) run delete_device first: refused here, the
            # device goes on untouched. A server shutting down stops whatever runs.
            self._call("Init", bench.check_init, log=True)
        if bench is not None:
            bench.stop()
        pusher = getattr(self, "_pusher", None)
        if pusher is not None:
            pusher.stop()

    def _write_absent_properties(self) -> None:
        """Write the defaults of the properties the database lacks (never overwrite one)."""
        util = tango.Util.instance()
        if not util._UseDb or util._FileDb:
            return
        try:
            db = util.get_database()
            have = db.get_device_property(self.get_name(), list(PROPERTY_DEFAULTS))
            absent = {k: [v] for k, v in PROPERTY_DEFAULTS.items() if not list(have[k])}
            if absent:
                db.put_device_property(self.get_name(), absent)
                self._log("INFO", f"default properties written: {', '.join(sorted(absent))}")
        except tango.DevFailed as exc:
            self._log("WARNING", f"default properties not written: {exc.args[0].desc}")

    def _log(self, level: str, message: str) -> None:
        text = plain(message)
        {"DEBUG": self.debug_stream, "INFO": self.info_stream, "WARNING": self.warn_stream,
         "ERROR": self.error_stream}[level](text)

    def _push(self, view: str) -> None:
        if view == "State":
            value: Any = self.dev_state()
            self.set_state(value)  # Tango pushes the device's own state, not the value given
        elif view == "Status":
            value = self.dev_status()
            self.set_status(value)
        elif view in PUSHED:
            spec = by_name(view)
            value, quality = evaluate(spec, self.bench, self._latch) if self.bench else \
                (None, "INVALID")
            if quality == "INVALID" or value is None:
                return
        else:
            return  # polled views (Progress) send their events from the polling
        self.push_change_event(view, value)
        self.push_archive_event(view, value)

    def dev_state(self) -> DevState:
        return DevState.FAULT if self.bench is None else _STATES[self.bench.state]

    def dev_status(self) -> str:
        return self._init_error if self.bench is None else plain(self.bench.status)

    # -- attributes ----------------------------------------------------------------

    def _read(self, spec: AttributeSpec) -> tuple[Any, float, AttrQuality]:
        if self.bench is None:
            return EMPTY_TEXT[spec.kind], time.time(), AttrQuality.ATTR_INVALID
        value, quality = evaluate(spec, self.bench, self._latch)
        if quality == "INVALID" or value is None:
            value = EMPTY_TEXT[spec.kind]
        elif spec.kind == "str":
            value = plain(value) if spec.name != "Excitation" else value
        return value, time.time(), _QUALITY[quality]

    def _write(self, name: str, value: float) -> None:
        bench = self._require()
        self._call(name, lambda: setattr(bench, "speed", value))

    # -- commands ------------------------------------------------------------------

    def _require(self) -> LiveBench:
        if self.bench is None:
            tango.Except.throw_exception("FSM_Fault", self._init_error,
                                         f"{self.get_name()}/Init")
        assert self.bench is not None
        return self.bench

    def _allowed(self, command_name: str) -> bool:
        bench = self._require()
        self._call(command_name, lambda: bench.check_allowed(command_name), log=True)
        return True

    def _call(self, command_name: str, fn: Callable[[], Any], *, log: bool = False) -> Any:
        """Run ``fn``; a refusal or an error becomes a DevFailed (reason, one sentence)."""
        origin = f"{self.get_name()}/{command_name}"
        try:
            return fn()
        except Refused as refused:
            if log:  # refusals inside the bench's commands are logged by the bench
                self._log("WARNING", f"{refused.sentence} [{refused.reason}]")
            tango.Except.throw_exception(refused.reason, plain(refused.sentence), origin)
        except tango.DevFailed:
            raise
        except Exception as exc:
            self._log("ERROR", f"{command_name} failed: {traceback.format_exc()}")
            tango.Except.throw_exception(
                "FSM_Internal", plain(f"{command_name} failed: {type(exc).__name__}: {exc} "
                                      "(a bug; the bench runs on)"), origin)

    def _do(self, command_name: str, method: Callable[..., str], *args: str) -> str:
        return plain(self._call(command_name, lambda: method(*args)))

    @command(dtype_out=str, doc_in="close the loop with the loaded controller (the ESRF study's if "
                                   "none); waits up to 1 s for a ringing mirror to settle",
             doc_out="what it did")
    def CloseLoop(self) -> str:
        return self._do("CloseLoop", self._require().close_loop)

    def is_CloseLoop_allowed(self) -> bool:
        return self._allowed("CloseLoop")

    @command(dtype_out=str, doc_in="open the loop, holding the last command",
             doc_out="what it did")
    def OpenLoop(self) -> str:
        return self._do("OpenLoop", self._require().open_loop)

    def is_OpenLoop_allowed(self) -> bool:
        return self._allowed("OpenLoop")

    @command(dtype_in=str, dtype_out=str,
             doc_in='controllers_sos.json / controllers.mat / a design folder in the '
                    'ControllersFolder (its path, or {"path": ..., "controller": name}), seed '
                    '(the ESRF study\'s controller) or last-good; checked on the bench on the '
                    'call',
             doc_out="what it loaded, with the margins it passed the check with")
    def LoadController(self, argument: str) -> str:
        return self._do("LoadController", self._require().load_controller, argument)

    def is_LoadController_allowed(self) -> bool:
        return self._allowed("LoadController")

    @command(dtype_in=str, dtype_out=str,
             doc_in='{"input": "Uch", "kind": "noise"|"sine"|"multisine", "amplitude_v": V, '
                    '"band_hz": [lo, hi], "frequency_hz": f, "period_s": T}',
             doc_out="what it did (a multisine is designed off the call: Task, Progress)")
    def StartExcitation(self, argument: str) -> str:
        return self._do("StartExcitation", self._require().start_excitation, argument)

    def is_StartExcitation_allowed(self) -> bool:
        return self._allowed("StartExcitation")

    @command(dtype_out=str, doc_in="stop the excitation (the FRF keeps its last estimate)",
             doc_out="what it did")
    def StopExcitation(self) -> str:
        return self._do("StopExcitation", self._require().stop_excitation)

    def is_StopExcitation_allowed(self) -> bool:
        return self._allowed("StopExcitation")

    @command(dtype_in=str, dtype_out=str,
             doc_in='experiment name, e.g. data_uch, or {"name": ..., "overwrite": true}',
             doc_out="path of the .mat file, complete when the state leaves MOVING")
    def RunExperiment(self, argument: str) -> str:
        return self._do("RunExperiment", self._require().run_experiment, argument)

    def is_RunExperiment_allowed(self) -> bool:
        return self._allowed("RunExperiment")

    @command(dtype_in=str, dtype_out=str,
             doc_in='{"signals": ["Vph", ...], "duration_s": s, "name": ..., '
                    '"format": "mat"|"nexus", "overwrite": false}',
             doc_out="path of the file, complete when the state leaves MOVING")
    def Record(self, argument: str) -> str:
        return self._do("Record", self._require().record, argument)

    def is_Record_allowed(self) -> bool:
        return self._allowed("Record")

    @command(dtype_out=str, doc_in="stop a running Record or experiment (its samples are "
                                   "written) and cancel a running task",
             doc_out="what it stopped")
    def Abort(self) -> str:
        return self._do("Abort", self._require().abort)

    @command(dtype_out=str, doc_in="back to a known state: loop open, command zero, nothing "
                                   "running, FAULT cleared, the last controller that did not "
                                   "trip", doc_out="what it did")
    def Reset(self) -> str:
        return self._do("Reset", self._require().reset)


class _Memory:
    """The loaded controller, remembered in the device property ``MemorisedController``."""

    where = f"the device property {_MEMORY}"

    def __init__(self, device: FsmBench) -> None:
        self._name = device.get_name()
        self._text = str(device.MemorisedController or "")

    def load(self) -> dict[str, str] | None:
        try:
            doc = json.loads(self._text) if self._text else None
        except ValueError:
            return None
        return {str(k): str(v) for k, v in doc.items()} if isinstance(doc, dict) and doc \
            else None

    def save(self, doc: dict[str, str] | None) -> None:
        self._text = json.dumps(doc or {})
        util = tango.Util.instance()
        if util._UseDb:
            util.get_database().put_device_property(self._name, {_MEMORY: [self._text]})
