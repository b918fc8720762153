"""The live bench without a control system: a paced loop over a backend, its commands, views.

:class:`LiveBench` runs the backend block by block in a paced thread
(:class:`~fsmbench.live.loop.PacedLoop`, with a heartbeat and a watchdog);
commands act between blocks under one lock. The Tango device
(:mod:`fsmbench.live.device`) and the EPICS IOC (:mod:`fsmbench.live.epics`)
are thin layers over it and read its views through one attribute table
(:mod:`fsmbench.live.attributes`).

The state is computed from facts (:mod:`fsmbench.live.states`) and every
loop transition has a cause: a command, the end of an experiment (which
restores the loop it found, part of ``RunExperiment``) or a protection
trip. Each is logged, and ``on_change`` is told of every changed view, outside
the lock (a Tango event push takes the device's monitor, which a client call
may hold while it waits for this lock). Recordings stream to disk in their
own thread (:mod:`fsmbench.live.jobs`); long work runs off the client's call
(:mod:`fsmbench.live.tasks`).
"""

from __future__ import annotations

import contextlib
import json
import logging
import math
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from fsmbench.bench.params import Bench
from fsmbench.live.backend import LiveBlock, PlaybackBackend, TwinBackend
from fsmbench.live.commands import BenchCommands, Job
from fsmbench.live.controllers import BenchCheck
from fsmbench.live.loading import ControllerCommands, ControllerMemory, FileMemory
from fsmbench.live.loop import PacedLoop
from fsmbench.live.monitor import LiveMonitor
from fsmbench.live.spectra import AccumulatingFrf, FrfSnapshot, RollingAsd
from fsmbench.live.states import MAX_SPEED, MIN_SPEED, AlarmHysteresis, Refused, Ringdown
from fsmbench.live.tasks import Task
from fsmbench.live.watching import LiveWatch, WatchView
from fsmbench.sim.engine import DiscreteController

__all__ = ["ASD_SIGNALS", "MAX_SPEED", "MIN_SPEED", "SLOW_PACE", "SLOW_PACE_CLEAR",
           "ControllerMemory", "FileMemory", "LiveBench"]

#: Signals whose amplitude spectral density the device publishes.
ASD_SIGNALS = ("Vph", "Vpv", "Va")
FRF_OUTPUTS = ("Vph", "Vpv")
#: Bounds of the speed factor (bench seconds per wall-clock second).
#: Speed reached over asked below which the bench logs a WARNING, and above which it clears.
SLOW_PACE = 0.9
SLOW_PACE_CLEAR = 0.95
#: Longest wait of a view read for the loop's lock [s] (a stuck loop: the value is stale).
_READ_WAIT_S = 0.5

T = TypeVar("T")
_log = logging.getLogger("fsmbench.live")


class LiveBench(ControllerCommands, BenchCommands):
    """The live bench (see the module notes).

    Parameters
    ----------
    bench : Bench
        The bench model (twin: simulated; both: calibrated 4QD gains, converters).
    backend : {"twin", "playback"}
    playback_folder : str or Path, optional
        Folder of recordings (playback backend).
    seed : int
    speed : float
        Bench seconds per wall-clock second, in [:data:`MIN_SPEED`, :data:`MAX_SPEED`].
    output_folder : str or Path
        Where experiments and recordings are written (created when needed).
    controllers_folder : str or Path, optional
        The only folder ``LoadController`` reads controller files from (a relative path is
        taken inside it; :mod:`fsmbench.live.controllers`); default ``output_folder``.
    watchdog_s : float
        Wall-clock time without a block that makes the loop count as stalled [s].
    log : callable, optional
        ``log(level, message)``, level ``DEBUG``/``INFO``/``WARNING``/``ERROR``
        (default: the ``fsmbench.live`` Python logger).
    on_change : callable, optional
        ``on_change(view)`` when a view changes: ``State``, ``Status``,
        ``LoopClosed``, ``Controller``, ``Excitation``, ``SpeedFactor``, ``Task``,
        ``Progress``. Called outside the lock, from any of the bench's threads.
    memory : ControllerMemory, optional
        Where the loaded controller is remembered (:meth:`restore_controller`).
    thread_init : callable, optional
        Context manager factory entered in each of the bench's threads.
    drift_pct_per_h : float
        The twin's Sercalo resonance drifts this fast, both axes [%/h] (0: none; what
        the loop's watch, :mod:`fsmbench.live.watching`, is for).
    drift_start_s : float
        Bench time the drift starts [s].
    """

    def __init__(self, bench: Bench, *, backend: str = "twin",
                 playback_folder: str | Path | None = None, seed: int = 0, speed: float = 1.0,
                 output_folder: str | Path = "fsmbench-live",
                 controllers_folder: str | Path | None = None, watchdog_s: float = 5.0,
                 log: Callable[[str, str], None] | None = None,
                 on_change: Callable[[str], None] | None = None,
                 memory: ControllerMemory | None = None,
                 thread_init: Callable[[], Any] | None = None,
                 drift_pct_per_h: float = 0.0, drift_start_s: float = 0.0) -> None:
        self.bench = bench
        conv = bench.nominal.converter
        if backend == "twin":
            self.backend: TwinBackend | PlaybackBackend = TwinBackend(
                bench, seed=seed, drift_pct_per_h=drift_pct_per_h, drift_start_s=drift_start_s)
        elif backend == "playback":
            if not playback_folder:
                raise ValueError("the playback backend needs a folder of recordings")
            self.backend = PlaybackBackend(playback_folder, fs_hz=conv.fs_hz,
                                           adc_range_v=conv.range_v, adc_bits=conv.bits)
        else:
            raise ValueError(f"unknown backend {backend!r}; known: twin, playback")
        self.fs_hz = self.backend.fs_hz
        self.half_range_v = conv.range_v / 2
        gd = bench.nominal.quad_diode.gain_v_per_rad
        self.qd_gain_v_per_rad = (float(gd.h), float(gd.v))
        self.monitor = LiveMonitor(fs_hz=self.fs_hz, qd_gain_v_per_rad=self.qd_gain_v_per_rad,
                                   half_range_v=self.half_range_v, lsb_v=conv.lsb_v)
        s = bench.nominal.sercalo
        self.ringdown = Ringdown(decay_time_s=tuple(  # type: ignore[arg-type]
            1.0 / (float(z) * 2 * np.pi * float(f))
            for z, f in ((s.damping_ratio.h, s.resonance_hz.h),
                         (s.damping_ratio.v, s.resonance_hz.v))))
        self.alarm_rule = AlarmHysteresis()
        self.output_folder = Path(output_folder)
        #: Resolved once: a path is inside it when it resolves there (links followed).
        self.controllers_folder = Path(controllers_folder if controllers_folder is not None
                                       else output_folder).resolve()
        self.bench_check = BenchCheck(bench)
        self.memory = memory
        self.thread_init = thread_init
        self._log_fn = log
        self._on_change = on_change
        self._lock = threading.RLock()
        self._publish_lock = threading.Lock()
        self._published: dict[str, Any] = {}
        self._speed = self.check_speed(speed)
        self._asd = {name: RollingAsd(fs_hz=self.fs_hz, channels=(name,)) for name in ASD_SIGNALS}
        self._asd_cache: dict[str, np.ndarray] = {}
        self._frf: AccumulatingFrf | None = None
        self._frf_cache: FrfSnapshot | None = None
        self._spectra_due = False
        self._excitation: dict[str, Any] | None = None
        self._next_second = 1
        self._slow = False  # running below SLOW_PACE of the speed asked (warned once)
        self._loaded: DiscreteController | None = None
        self._loaded_doc: dict[str, str] | None = None
        #: Loaded controllers that have not tripped, oldest first, with their source.
        self._good: list[tuple[DiscreteController, dict[str, str]]] = []
        self._fault: tuple[str, str] | None = None  # (kind, sentence)
        self._ringing = False
        self._alarm = (False, 0.0)  # (active, since bench time)
        self._job: Job | None = None
        self._task: Task | None = None
        self._notice = ""
        self.watch = LiveWatch(bench, qd_gain_v_per_rad=self.qd_gain_v_per_rad, log=self.log,
                               thread_init=thread_init)
        self._watch_view = self.watch.view(None)
        self.loop = PacedLoop(step=self._step, speed=lambda: self._speed,
                              block_s=lambda: self.block_samples / self.fs_hz,
                              watchdog_s=watchdog_s, on_stall=self._stalled,
                              on_death=self._died, thread_init=thread_init)

    # -- logging and events --------------------------------------------------------

    def log(self, level: str, message: str) -> None:
        """Log ``message`` at ``level`` (DEBUG, INFO, WARNING, ERROR)."""
        if self._log_fn is not None:
            self._log_fn(level, message)
        else:
            _log.log(getattr(logging, level), message)

    def _views(self) -> dict[str, Any]:
        ex = self._excitation
        return {"State": self.state, "Status": self._status_key(),
                "LoopClosed": self.loop_closed, "Controller": self.controller_name,
                "Excitation": None if ex is None else tuple(sorted(ex.items())),
                "SpeedFactor": self._speed, "Task": self.task_text,
                "Progress": round(self.progress_percent),
                "WatchVerdict": self._watch_view.verdict, "WatchCause": self._watch_view.cause}

    def publish(self) -> None:
        """Tell ``on_change`` of every view changed since the last call (never under the lock).

        Every thread calls it after acting: the loop after a block, a client
        after a command, a writer or task when it ends, the watchdog on a stall.
        """
        with self._publish_lock:
            views = self._views()
            changed = [k for k, v in views.items() if self._published.get(k, ...) != v]
            if "State" in changed:
                state = views["State"]
                level = {"FAULT": "ERROR", "ALARM": "WARNING"}.get(state, "INFO")
                self.log(level, f"State {self._published.get('State', 'none')} -> {state}: "
                                f"{self.status}")
            self._published = views
            if self._on_change is not None:
                for name in changed:
                    self._on_change(name)

    # -- running -------------------------------------------------------------------

    @staticmethod
    def check_speed(speed: float) -> float:
        """``speed`` if it is a factor of real time in [MIN_SPEED, MAX_SPEED], else Refused."""
        if isinstance(speed, bool) or not isinstance(speed, (int, float, np.floating)) or \
                not (np.isfinite(speed) and MIN_SPEED <= speed <= MAX_SPEED):
            raise Refused("FSM_BadArgument", f"SpeedFactor refused: {speed!r} is not a factor "
                                             f"of real time in [{MIN_SPEED:g}, {MAX_SPEED:g}]")
        return float(speed)

    @property
    def block_samples(self) -> int:
        """Samples per block: 10 ms of bench time, 50 ms when running faster than 10×."""
        return round(self.fs_hz * (0.01 if self._speed <= 10 else 0.05))

    def start(self) -> None:
        """Start the loop thread and its watchdog (after one block here: the compiled loop
        loads on the first, which would hold the lock for a second in the thread)."""
        self.advance(self.block_samples)
        self.loop.start()
        self.log("INFO", f"bench loop started ({self.backend.kind}, speed {self._speed:g})")
        self.publish()

    def stop(self) -> None:
        """Stop the loop thread and its watchdog; end a running job, keeping its samples."""
        self.loop.stop()
        self.watch.stop()
        with self._lock:
            job = self._job
            if job is not None and job.collecting:
                self._end_collection(job, aborted="the server's stop")
        if job is not None:
            job.writer.join(30.0)

    def _step(self) -> float:
        self.advance(self.block_samples)
        return self.backend.time_s

    def _stalled(self, lag_s: float) -> None:
        # From the watchdog, without the lock (a stuck loop may hold it): the loop opens
        # the loop itself if it runs again (_advance).
        self._fault = ("stall", f"The bench loop has not advanced for {lag_s:.1f} s of wall "
                                f"clock (limit {self.loop.stall_limit_s():.1f} s; last block "
                                f"ending at bench time {self.bench_time_s:.3f} s).")
        self.log("ERROR", self._fault[1])
        self.publish()

    def _died(self, exc: BaseException) -> None:
        self._fault = ("died", f"The bench loop stopped: {type(exc).__name__}: {exc}.")
        self.log("ERROR", self._fault[1])
        self.publish()

    def advance(self, n: int) -> LiveBlock:
        """Run ``n`` samples now (the loop thread calls this; tests may too, without it)."""
        with self._lock:
            block = self._advance(n)
            due, self._spectra_due = self._spectra_due, False
            frf = self._frf
            job = self._job
            quiet = self._excitation is None and not (
                job is not None and job.collecting and job.plan.kind == "experiment")
            controller = self.backend.controller
        # The watch judges outside the lock (a 10 s Welch every 10 s of bench time).
        for event in self.watch.push(controller=controller, quiet=quiet,
                                     vph=block.signals.get("Vph"), vpv=block.signals.get("Vpv"),
                                     end_s=(block.start_sample + block.n) / self.fs_hz):
            self.log("WARNING" if event.level == "WARNING" else "INFO",
                     f"the loop's watch: {event.level}: {event.cause}")
        self._watch_view = self.watch.view(controller)
        if due:
            self._refresh_spectra(frf)
        self.loop.beat()
        self.publish()
        return block

    def _advance(self, n: int) -> LiveBlock:
        if self._fault is not None and self.backend.controller is not None:
            # A stall's FAULT opens the loop as soon as the loop runs again.
            self._set_loop(None, hold=False, cause=f"FAULT ({self._fault[0]})")
        block = self.backend.step(n)
        closed = self.backend.controller is not None
        trip = self.monitor.push(block, loop_closed=closed)
        end_s = (block.start_sample + block.n) / self.fs_hz
        if trip is not None:
            self._tripped(trip.reason, trip.bench_time_s)
        for name, asd in self._asd.items():
            x = block.signals.get(name)
            if x is not None and np.all(np.isfinite(x)):
                asd.push(x[:, None])
        if self._frf is not None and self._excitation is not None:
            ch = self._excitation["input"]
            if ch in block.signals and all(o in block.signals for o in FRF_OUTPUTS):
                u = block.signals[ch]
                y = np.column_stack([block.signals[o] for o in FRF_OUTPUTS])
                if np.all(np.isfinite(u)) and np.all(np.isfinite(y)):
                    self._frf.push(u, y)
        if self._job is not None and self._job.collecting:
            self._collect(block)
        end = block.start_sample + block.n
        if end >= self._next_second * self.fs_hz:
            self._next_second = int(end // self.fs_hz) + 1
            self._spectra_due = True  # computed after the lock is released (advance)
            self._check_pace()
        m = self.monitor
        self._alarm = self.alarm_rule.next(
            active=self._alarm[0], since_s=self._alarm[1], now_s=end_s,
            enter_measure=m.rail_fraction(self.alarm_rule.enter_window_s),
            leave_measure=m.rail_fraction(self.alarm_rule.leave_window_s))
        if self._ringing and self.backend.controller is None and \
                self.ringdown.time_left_s(m.qd_deviation_v(self.ringdown.window_s)) == 0:
            self._ringing = False
            self.log("INFO", f"the mirror has settled (bench time {end_s:.3f} s)")
        return block

    def _tripped(self, reason: str, bench_time_s: float) -> None:
        tripped = self.backend.controller
        self._set_loop(None, hold=False, cause="the protection trip")
        self.backend.stop_excitation()
        self._stop_frf()
        self._excitation = None
        self._ringing = True
        revert = ""
        if tripped is not None and tripped is self._loaded:
            self._good = [g for g in self._good if g[0] is not tripped]
            self._loaded, self._loaded_doc = self._good[-1] if self._good else (None, None)
            self._remember()
            revert = (f" The controller {tripped.name} tripped: "
                      + (f"{self._loaded.name} is loaded again (the last that did not trip)."
                         if self._loaded is not None else
                         "none is loaded now (CloseLoop would use the ESRF study's)."))
        self._notice = ""  # the trip's sentence carries the news
        self._fault = ("trip", f"Protection opened the loop at bench time {bench_time_s:.3f} "
                               f"s: {reason}.{revert}")
        self.log("ERROR", self._fault[1])
        job = self._job
        if job is not None and job.collecting:
            self._end_collection(job, aborted="the protection trip", restore_loop=False)

    def _set_loop(self, controller: DiscreteController | None, *, hold: bool,
                  cause: str) -> None:
        """Close, swap or open the loop, saying why (every transition has a cause)."""
        before = self.backend.controller
        self.backend.set_controller(controller, hold=hold)
        if controller is None and before is not None:
            self.log("INFO", f"loop opened (cause: {cause})")
        elif controller is not None and before is None:
            self.log("INFO", f"loop closed with {controller.name} (cause: {cause})")
        elif controller is not None and controller is not before:
            self.log("INFO", f"controller {controller.name} took over (cause: {cause})")

    def _remember(self) -> None:
        if self.memory is None:
            return
        try:
            self.memory.save(self._loaded_doc)
        except Exception as exc:  # a database or disk refusing must not stop the bench
            self.log("WARNING", f"the loaded controller could not be remembered in "
                                f"{self.memory.where}: {exc}")

    def _refresh_spectra(self, frf: AccumulatingFrf | None) -> None:
        """New spectra, computed outside the lock (the three 10 s Welch ASDs take 15-45 ms
        on a busy machine: under the lock they were the p99 of every client's read).

        Only the loop's thread pushes samples into the estimators, and it is here, so
        they do not change meanwhile; a command may replace the FRF estimator: a result
        of the one it replaced is dropped.
        """
        snaps = {name: asd.spectrum() for name, asd in self._asd.items()}
        result = None
        if frf is not None and frf.n_segments:
            with contextlib.suppress(ValueError):  # a constant signal: no FRF yet
                result = frf.result()
        with self._lock:
            for name, snap in snaps.items():
                if snap is not None:
                    self._asd_cache["frequency"] = snap.frequency_hz
                    self._asd_cache[name] = snap.asd[0]
            if result is not None and self._frf is frf:
                self._frf_cache = result

    def _stop_frf(self) -> None:
        if self._frf is not None and self._frf.n_segments:
            with contextlib.suppress(ValueError):
                self._frf_cache = self._frf.result()
        self._frf = None

    # -- state ---------------------------------------------------------------------

    @property
    def state(self) -> str:
        """ON, RUNNING, MOVING, ALARM or FAULT, from the facts (see the module notes)."""
        if self._fault is not None or self.loop.stalled:
            return "FAULT"
        if self._job is not None or self._task is not None:
            return "MOVING"
        if self._alarm[0] or self._ringing:
            return "ALARM"
        if self.watch_view.warning:
            return "ALARM"  # the loop's watch warns; commands are allowed as in RUNNING
        return "RUNNING" if self.backend.controller is not None else "ON"

    def check_init(self) -> None:
        """Refuse a restart (Tango's ``Init``) that would cut what runs, with what to do.

        ``Init`` rebuilds the bench: the loop opens, BenchTime starts again at 0 and the
        remembered controller is loaded again. On a closed loop or a running job that is
        a surprise to whoever relies on them, so it is refused on the call.
        """
        what = self.task_text or (self._job.plan.name if self._job is not None else "")
        if self._job is not None or self._task is not None:
            raise Refused("FSM_NotAllowed", f"Init refused: {what or 'a job'} runs and Init "
                                            "would cut it (Init restarts the bench). Abort it "
                                            "or wait for it to end.")
        if self.backend.controller is not None:
            raise Refused("FSM_NotAllowed", "Init refused: the loop is closed (Init restarts "
                                            "the bench: the loop opens, BenchTime starts "
                                            "again at 0, the remembered controller is "
                                            "loaded again). OpenLoop first.")

    @property
    def watch_view(self) -> WatchView:
        """The loop's watch now (:mod:`fsmbench.live.watching`)."""
        return self.watch.view(self.backend.controller)

    @property
    def command_state(self) -> str:
        """The state the commands are checked against: :attr:`state`, except that the loop's
        watch's warning counts as RUNNING (it advises ``fsmbench tune``, which needs the
        commands of a running loop)."""
        state = self.state
        if state == "ALARM" and not (self._alarm[0] or self._ringing):
            return "RUNNING" if self.backend.controller is not None else "ON"
        return state

    def _fault_sentence(self) -> str:
        if self._fault is not None:
            return self._fault[1]
        if self.loop.dead or not self.loop.running:
            return f"The bench loop stopped: {self.loop.error}."
        return (f"The bench loop has not advanced for {self.loop.lag_s:.1f} s of wall clock "
                f"(limit {self.loop.stall_limit_s():.1f} s).")

    def _ringing_sentence(self) -> str:
        amp = self.monitor.qd_deviation_v(self.ringdown.window_s)
        left = self.ringdown.time_left_s(amp)
        return (f"The mirror still rings after the trip (4QD {max(amp):.2f} V, settled below "
                f"{self.ringdown.settled_v:g} V): about {left:.1f} s of bench time left.")

    def _state_line(self, state: str, *, with_numbers: bool) -> str:
        if state == "FAULT":
            ring = f" {self._ringing_sentence()}" if self._ringing and with_numbers else ""
            return f"{self._fault_sentence()}{ring} Reset to return to ON."
        if state == "MOVING":
            parts = []
            job, task = self._job, self._task
            if job is not None:
                p = job.plan
                done = (f"{job.writer.taken / self.fs_hz:.1f} of {p.duration_s:.1f} s, "
                        if with_numbers and job.collecting else "")
                phase = "running" if job.collecting else "writing its file"
                parts.append(f"{p.kind.capitalize()} {p.name} {phase}: {done}into {p.path}.")
            if task is not None:
                pct = f" ({self.progress_percent:.0f} %)" if with_numbers else ""
                parts.append(f"{task.what[0].upper()}{task.what[1:]}{pct}; Abort cancels it.")
            return " ".join(parts)
        if state == "ALARM":
            if not (self._ringing or self._alarm[0]):
                return (f"Loop closed with {self.controller_name}; its tracking error departs "
                        f"from the prediction (the loop's watch): {self.watch_view.cause}.")
            if not self._ringing:
                return ("A converter saturates (a DAC command or a 4QD reading on a rail; ALARM "
                        f"until under {self.alarm_rule.leave_fraction:.1%} of "
                        f"{self.alarm_rule.leave_window_s:g} s, at least "
                        f"{self.alarm_rule.min_dwell_s:g} s).")
            # The ringing is the cause of the rails after a trip: say that one.
            return self._ringing_sentence() if with_numbers else "The mirror still rings."
        if state == "RUNNING":
            return f"Loop closed with {self.controller_name}."
        return "Loop open."

    def _status_key(self) -> str:
        """Status without the numbers that change every block (what Status events carry)."""
        state = self.state
        return f"{state}|{self._state_line(state, with_numbers=False)}|{self._notice}"

    @property
    def status(self) -> str:
        """The state in words: why, since when, what runs, and the last outcome."""
        line = self._state_line(self.state, with_numbers=True)
        return f"{line} {self._notice}".strip()

    # -- views ---------------------------------------------------------------------

    def read(self, getter: Callable[[LiveBench], T]) -> tuple[T | None, bool]:
        """``(getter(self), current)`` under the lock; ``(None, False)`` when the loop holds
        it too long. ``current`` is False when the loop has stalled or died."""
        if not self._lock.acquire(timeout=_READ_WAIT_S):
            return None, False
        try:
            value = getter(self)
        finally:
            self._lock.release()
        return value, not (self.loop.stalled or
                           (self._fault is not None and self._fault[0] != "trip"))

    @property
    def speed(self) -> float:
        """Bench seconds per wall-clock second."""
        return self._speed

    @speed.setter
    def speed(self, value: float) -> None:
        speed = self.check_speed(value)
        with self._locked("SpeedFactor"):
            self._speed = speed
        self.log("INFO", f"SpeedFactor set to {speed:g}")
        self.publish()

    @property
    def bench_time_s(self) -> float:
        """Bench time of the next sample [s]."""
        return self.backend.time_s

    @property
    def heartbeat(self) -> int:
        """Blocks run since the start."""
        return self.loop.heartbeat

    @property
    def speed_reached(self) -> float:
        """Bench seconds per wall-clock second the loop ran over its last 2 s (NaN until it has
        run 1 s at the present speed, or without the loop thread)."""
        return self.loop.reached_speed

    def _check_pace(self) -> None:
        """A WARNING when the loop runs below 90 % of the speed asked, once, and an INFO when
        it is back above 95 % (hysteresis: one message per episode, not one per second)."""
        reached = self.loop.reached_speed
        if not math.isfinite(reached):
            return
        ratio = reached / self._speed
        if not self._slow and ratio < SLOW_PACE:
            self._slow = True
            self.log("WARNING", f"the bench runs at {reached:.3g}x, {100 * ratio:.0f} % of the "
                                f"SpeedFactor {self._speed:g} asked: the machine is busy; a "
                                "lower SpeedFactor keeps bench time regular")
        elif self._slow and ratio >= SLOW_PACE_CLEAR:
            self._slow = False
            self.log("INFO", f"the bench runs at {reached:.3g}x again, "
                             f"{100 * ratio:.0f} % of the SpeedFactor {self._speed:g}")

    @property
    def loop_lag_s(self) -> float:
        """Wall-clock time since the last block [s]."""
        return self.loop.lag_s

    @property
    def loop_closed(self) -> bool:
        """The Sercalo loop is closed."""
        return self.backend.controller is not None

    @property
    def controller_name(self) -> str:
        """The controller in the loop, else the one loaded for the next close, else ``none``."""
        k = self.backend.controller or self._loaded
        return k.name if k is not None else "none (CloseLoop uses the ESRF study's controller, 9.2)"

    @property
    def excitation_text(self) -> str:
        """The running excitation as JSON (``{}`` when none)."""
        with self._lock:
            if self._excitation is None:
                return "{}"
            doc = dict(self._excitation)
            if self._frf_cache is not None:
                doc["frf_samples"] = int(self._frf_cache.n_samples)
            return json.dumps(doc)

    @property
    def task_text(self) -> str:
        """What runs off the client's call ("" when nothing)."""
        task = self._task
        return "" if task is None else task.what

    @property
    def progress_percent(self) -> float:
        """Progress of the running job or task [%] (100 when idle)."""
        task, job = self._task, self._job
        if task is not None:
            return 100.0 * task.progress
        if job is not None:
            return 100.0 * min(1.0, job.writer.taken / job.plan.n_samples)
        return 100.0

    def asd(self, name: str) -> np.ndarray:
        """Amplitude spectral density of ``name`` over the last 10 s (V or m per √Hz)."""
        with self._lock:
            return self._asd_cache.get(name, np.zeros(0))

    def asd_frequency(self) -> np.ndarray:
        """Frequencies of the spectra [Hz]."""
        with self._lock:
            return self._asd_cache.get("frequency", np.zeros(0))

    def frf(self) -> FrfSnapshot | None:
        """The H1 estimate from the excited input to the 4QD (Vph, Vpv) so far."""
        with self._lock:
            return self._frf_cache

    def wait_idle(self, timeout_s: float = 60.0) -> bool:
        """Wait (wall clock) until no job or task runs; True if it happened."""
        deadline = time.monotonic() + timeout_s
        while self._job is not None or self._task is not None:
            if time.monotonic() > deadline:
                return False
            time.sleep(0.01)
        return True
