"""The live bench's commands: each checked against the state, logged, and answered in words.

:class:`BenchCommands` holds the commands of :class:`~fsmbench.live.core.LiveBench`
but ``LoadController`` (:mod:`fsmbench.live.loading`); the loop, the state and the views
are the core's. Every command

- is checked against the state first (:meth:`BenchCommands.check_allowed`,
  the table :data:`~fsmbench.live.states.ALLOWED`), then against its
  argument (:mod:`fsmbench.live.arguments`, :func:`~fsmbench.live.jobs.plan_job`);
- raises :class:`~fsmbench.live.states.Refused` (reason code, one sentence)
  or returns one sentence saying what it did;
- is logged: received (DEBUG), done (INFO), refused (WARNING).
"""

from __future__ import annotations

import contextlib
import functools
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, Concatenate, ParamSpec

import numpy as np

from fsmbench.io.signals import EXPERIMENTS
from fsmbench.live.arguments import parse_excitation, parse_experiment, parse_record
from fsmbench.live.backend import TwinBackend
from fsmbench.live.jobs import JobOutcome, JobPlan, JobWriter, plan_job
from fsmbench.live.spectra import AccumulatingFrf
from fsmbench.live.states import ALLOWED, Refused
from fsmbench.live.tasks import Task, TaskControl, design_multisine
from fsmbench.sim.excitation import Excitation, SampledExcitation
from fsmbench.twin.experiments import esrf_experiments, esrf_feedback

if TYPE_CHECKING:
    from fsmbench.bench.params import Bench
    from fsmbench.live.backend import PlaybackBackend
    from fsmbench.live.loop import PacedLoop
    from fsmbench.live.monitor import LiveMonitor
    from fsmbench.live.spectra import FrfSnapshot
    from fsmbench.live.states import AlarmHysteresis, Ringdown
    from fsmbench.sim.engine import DiscreteController

__all__ = ["CLOSE_WAIT_S", "COMMAND_WAIT_S", "BenchCommands", "Job"]

#: Longest wall-clock wait of CloseLoop for the mirror to settle [s] (below Tango's 3 s
#: client timeout); a longer ringdown is refused with the time left.
CLOSE_WAIT_S = 1.0
#: Longest wait of a command for the bench's lock [s] (a block takes milliseconds).
COMMAND_WAIT_S = 1.0
#: Commands that act on the bench (refused on a playback).
_ACTS = frozenset({"CloseLoop", "OpenLoop", "LoadController", "StartExcitation",
                   "RunExperiment"})
P = ParamSpec("P")


def _command(name: str) -> Callable[[Callable[Concatenate[Any, P], str]],
                                    Callable[Concatenate[Any, P], str]]:
    """Log a command (received, done, refused) and publish the views it changed."""

    def wrap(fn: Callable[Concatenate[Any, P], str]) -> Callable[Concatenate[Any, P], str]:
        @functools.wraps(fn)
        def run(self: Any, *args: P.args, **kwargs: P.kwargs) -> str:
            self.log("DEBUG", f"{name} received" + (f": {args[0]!r}" if args else ""))
            try:
                reply = fn(self, *args, **kwargs)
            except Refused as refused:
                text = refused.sentence if refused.sentence.startswith(name) else \
                    f"{name} refused: {refused.sentence}"
                self.log("WARNING", f"{text} [{refused.reason}]")
                raise
            self.log("INFO", f"{name}: {reply}")
            self.publish()
            return reply

        return run

    return wrap


class Job:
    """A recording or an experiment of the bench: its plan, writer and loop restoration.

    Parameters
    ----------
    plan : JobPlan
    restore : callable, optional
        ``restore(loop)`` when the job stops collecting: put the environment back
        and, when ``loop``, the loop as the job found it (experiments).
    on_done : callable
        ``on_done(job, outcome)`` when the file is written.
    thread_init : callable, optional
    """

    def __init__(self, plan: JobPlan, *, restore: Callable[[bool], None] | None,
                 on_done: Callable[[Job, JobOutcome], None],
                 thread_init: Callable[[], Any] | None) -> None:
        self.plan = plan
        self.restore = restore
        self.collecting = True
        self.writer = JobWriter(plan, on_done=lambda outcome: on_done(self, outcome),
                                thread_init=thread_init)


class BenchCommands:
    """The commands of :class:`~fsmbench.live.core.LiveBench` (see the module notes)."""

    if TYPE_CHECKING:  # provided by LiveBench
        bench: Bench
        backend: TwinBackend | PlaybackBackend
        fs_hz: float
        half_range_v: float
        output_folder: Path
        thread_init: Callable[[], Any] | None
        monitor: LiveMonitor
        ringdown: Ringdown
        alarm_rule: AlarmHysteresis
        loop: PacedLoop
        _lock: threading.RLock
        _loaded: DiscreteController | None
        _fault: tuple[str, str] | None
        _ringing: bool
        _alarm: tuple[bool, float]
        _job: Job | None
        _task: Task | None
        _notice: str
        _excitation: dict[str, Any] | None
        _frf: AccumulatingFrf | None
        _frf_cache: FrfSnapshot | None
        _speed: float

        def log(self, level: str, message: str) -> None: ...
        def publish(self) -> None: ...
        def _set_loop(self, controller: DiscreteController | None, *, hold: bool,
                      cause: str) -> None: ...
        def _stop_frf(self) -> None: ...
        def _state_line(self, state: str, *, with_numbers: bool) -> str: ...
        def _fault_sentence(self) -> str: ...
        @property
        def bench_time_s(self) -> float: ...
        def _ringing_sentence(self) -> str: ...
        @property
        def state(self) -> str: ...
        @property
        def command_state(self) -> str: ...
        @property
        def controller_name(self) -> str: ...

    # -- the state machine ---------------------------------------------------------

    @contextlib.contextmanager
    def _locked(self, command: str) -> Iterator[None]:
        """The bench's lock for a command, or FAULT's refusal when the loop will not give it."""
        if command in ALLOWED:
            self.check_allowed(command)  # the state's sentence first (a stall: FAULT's)
        if not self._lock.acquire(timeout=COMMAND_WAIT_S):
            raise Refused("FSM_Fault", f"{command} refused: the bench loop does not answer (it "
                                       f"has held the bench for over {COMMAND_WAIT_S:g} s); "
                                       "restart the device (Init) or the server")
        try:
            yield
        finally:
            self._lock.release()

    def check_allowed(self, command: str) -> None:
        """Nothing if ``command`` may run now; else :class:`Refused` saying why and what to do."""
        state = self.command_state
        job, task = self._job, self._task
        experiment = job is not None and job.collecting and job.plan.kind == "experiment"
        if command in _ACTS and not self.backend.acts:
            files = ", ".join(getattr(self.backend, "files", ()))
            raise Refused("FSM_Playback", f"{command} is not possible on a playback: the bench "
                                          f"replays the recorded files {files}")
        if state in ALLOWED[command]:
            if command in ("OpenLoop", "StopExcitation") and experiment:
                assert job is not None
                raise Refused("FSM_Busy", f"{command} refused: the experiment {job.plan.name} "
                                          "sets the loop and the excitations; Abort it first")
            if state == "MOVING" and command == "StartExcitation" and (task or experiment):
                raise Refused("FSM_Busy", f"{command} refused: "
                                          f"{self._state_line(state, with_numbers=True)}")
            return
        if state == "FAULT":
            raise Refused("FSM_Fault", f"{command} refused in FAULT: {self._fault_sentence()} "
                                       "Reset first.")
        if state == "MOVING":
            raise Refused("FSM_Busy", f"{command} refused: "
                                      f"{self._state_line(state, with_numbers=True)}")
        if state == "ALARM":
            raise Refused("FSM_NotAllowed", f"{command} refused in ALARM: "
                                            f"{self._state_line(state, with_numbers=True)} "
                                            "Wait for ON.")
        if command == "CloseLoop":
            raise Refused("FSM_NotAllowed", f"CloseLoop refused: the loop is already closed "
                                            f"with {self.controller_name} (LoadController swaps "
                                            "it bumplessly)")
        raise Refused("FSM_NotAllowed", f"{command} refused in {state}: "
                                        f"{self._state_line(state, with_numbers=True)}")

    # -- the loop ------------------------------------------------------------------

    def _seed_controller(self) -> DiscreteController:
        return replace(esrf_feedback(self.bench), name="the ESRF study's controller (9.2)")

    @_command("CloseLoop")
    def close_loop(self) -> str:
        """Close the loop with the loaded controller (the seed's if none), bumplessly.

        In ALARM because the mirror still rings after a trip, waits up to
        :data:`CLOSE_WAIT_S` of wall clock for it to settle, or refuses with the
        time left (``FSM_Settling``).
        """
        with self._locked("CloseLoop"):
            self.check_allowed("CloseLoop")
            settling = self.command_state == "ALARM"
            if settling:
                self._refuse_unsettled()
        waited = 0.0
        if settling:
            t0 = time.monotonic()
            while (self._ringing or self._alarm[0]) and \
                    time.monotonic() - t0 < CLOSE_WAIT_S + 0.5:
                time.sleep(0.01)
            waited = time.monotonic() - t0
        with self._locked("CloseLoop"):
            self.check_allowed("CloseLoop")
            if self.command_state == "ALARM":
                self._refuse_unsettled(wait=False)
            k = self._loaded or self._seed_controller()
            self._set_loop(k, hold=True, cause="CloseLoop")
        settled = f" after {waited:.2f} s (wall clock) for the mirror to settle" if waited else ""
        return f"loop closed with {k.name}{settled}"

    def _refuse_unsettled(self, *, wait: bool = True) -> None:
        """Refuse CloseLoop in ALARM unless the bench settles by itself within
        :data:`CLOSE_WAIT_S` (the mirror ringing after a trip, or the saturation alarm's
        hysteresis running out with no converter on a rail any more)."""
        if self._ringing:
            left = self.ringdown.time_left_s(
                self.monitor.qd_deviation_v(self.ringdown.window_s))
            why = self._ringing_sentence()
        else:
            rule = self.alarm_rule
            rails = self.monitor.rail_flags(rule.leave_window_s)
            if self._excitation is not None or (len(rails) and rails[-1]):
                held = ("" if self._excitation is not None else
                        " No excitation runs: the held DAC command or the beam keeps a "
                        "converter on its rail (Reset sets the commands to zero).")
                raise Refused("FSM_NotAllowed", "CloseLoop refused in ALARM: "
                                                f"{self._state_line('ALARM', with_numbers=True)}"
                                                + (held or " Stop the excitation and wait for "
                                                            "ON."))
            left = rule.time_left_s(since_s=self._alarm[1], now_s=self.bench_time_s,
                                    rails=rails, fs_hz=self.fs_hz)
            why = (f"A converter was on a rail {100 * float(np.mean(rails)):.1f} % of the last "
                   f"{rule.leave_window_s:g} s and is no more (the ALARM ends below "
                   f"{100 * rule.leave_fraction:g} %, at least {rule.min_dwell_s:g} s after it "
                   f"began): about {left:.1f} s of bench time left.")
        if not wait or not self.loop.running or left / self._speed > CLOSE_WAIT_S:
            raise Refused("FSM_Settling", f"CloseLoop refused: {why} "
                                          f"({left / self._speed:.1f} s of wall clock at speed "
                                          f"{self._speed:g}); try again then.")

    @_command("OpenLoop")
    def open_loop(self) -> str:
        """Open the loop, holding the last command (bumpless)."""
        with self._locked("OpenLoop"):
            self.check_allowed("OpenLoop")
            if self.backend.controller is None:
                return "the loop is already open"
            self._set_loop(None, hold=True, cause="OpenLoop")
        return "loop opened, holding the last command"

    @_command("Reset")
    def reset(self) -> str:
        """Return to a known state: loop open, command zero, nothing running, no FAULT.

        The controller loaded is the last that did not trip (or none); a dead
        loop thread is restarted. Returns what it did.
        """
        with self._locked("Reset"):
            restart = self.loop.started and (self.loop.dead or not self.loop.running)
            if self.loop.started and not restart and self.loop.stalled:
                raise Refused("FSM_Fault", f"Reset refused: {self._fault_sentence()} The loop "
                                           "thread does not answer; restart the device (Init) "
                                           "or the server.")
            done = [f"Reset at bench time {self.backend.time_s:.3f} s: loop open, command "
                    "zero, no excitation"]
            job, task = self._job, self._task
            if job is not None and job.collecting:
                self._end_collection(job, aborted="Reset", restore_loop=False)
                done.append(f"{job.plan.kind} {job.plan.name} stopped (its samples are "
                            "written)")
            if task is not None:
                task.cancel()
                self._task = None
                done.append(f"{task.what} cancelled")
            if isinstance(self.backend, TwinBackend):
                self._set_loop(None, hold=False, cause="Reset")
                self.backend.stop_excitation()
                self.backend.set_environment(compensation_unit=True, shielding=True)
            self._stop_frf()
            self._excitation = None
            if self._fault is not None:
                done.append(f"cleared FAULT ({self._fault[0]})")
            self._fault = None
            done.append(f"controller {self._loaded.name} loaded (the last that did not trip)"
                        if self._loaded is not None else
                        "no controller loaded (CloseLoop uses the ESRF study's, 9.2)")
            if restart:
                done.append("the bench loop restarted")
            self._notice = "; ".join(done) + "."
        if restart:
            self.loop.start()
        return self._notice

    @_command("Abort")
    def abort(self) -> str:
        """Stop a running recording or experiment (keeping what was recorded) and cancel a
        task. Returns what it stopped."""
        with self._locked("Abort"):
            done = []
            job, task = self._job, self._task
            if job is not None and job.collecting:
                self._end_collection(job, aborted="Abort")
                done.append(f"{job.plan.kind} {job.plan.name} stopped after "
                            f"{job.writer.taken / self.fs_hz:.1f} s; its samples are written "
                            f"to {job.plan.path}")
            elif job is not None:
                done.append(f"the file of {job.plan.name} is being written; it completes")
            if task is not None:
                task.cancel()
                self._task = None
                done.append(f"{task.what} cancelled")
                self._notice = f"Aborted: {task.what}."
        return "; ".join(done) if done else "nothing was running"

    # -- tasks ---------------------------------------------------------------------

    def _start_task(self, what: str, work: Callable[[TaskControl], Any],
                    apply: Callable[[Any], str]) -> None:
        def done(task: Task) -> None:
            with self._lock:
                if self._task is not task:  # Reset or Abort dropped it
                    return
                self._task = None
                if task.cancelled:
                    self._notice = f"Aborted: {what}."
                elif task.error:
                    self._notice = f"{what[0].upper()}{what[1:]} failed: {task.error}."
                else:
                    self._notice = apply(task.result)
            self.log("WARNING" if task.error else "INFO", self._notice)
            self.publish()

        self._task = Task(what, work, on_done=done, thread_init=self.thread_init)

    # -- excitations ---------------------------------------------------------------

    @_command("StartExcitation")
    def start_excitation(self, argument: str) -> str:
        """Start an excitation from JSON (see :func:`~fsmbench.live.arguments.parse_excitation`).

        Noise and sines start at once; a multisine is designed off the call
        (``Task``, ``Progress``) and starts when designed.
        """
        with self._locked("StartExcitation"):
            self.check_allowed("StartExcitation")
            ex = parse_excitation(argument, start_s=self.backend.time_s,
                                  half_range_v=self.half_range_v, fs_hz=self.fs_hz)
            if ex.kind != "multisine":
                self._play(ex, ex)
                return f"{ex.kind} on {ex.channel} started at bench time {ex.start_s:.3f} s"

            def work(control: TaskControl) -> tuple[SampledExcitation, float]:
                return design_multisine(ex, fs_hz=self.fs_hz, half_range_v=self.half_range_v,
                                        control=control)

            def apply(result: tuple[SampledExcitation, float]) -> str:
                sampled, crest = result
                try:
                    self.check_allowed("StartExcitation")
                except Refused as refused:
                    return f"The multisine was designed but not started: {refused.sentence}."
                now = self.backend.time_s
                self._play(replace(ex, start_s=now), replace(sampled, start_s=now),
                           crest=crest)
                return (f"Multisine on {ex.channel} started at bench time {now:.3f} s (crest "
                        f"factor {crest:.2f}).")

            self._start_task(f"designing a multisine on {ex.channel} ({ex.period_s:g} s "
                             "period)", work, apply)
        return "designing the multisine; it starts when designed (Task, Progress)"

    def _play(self, ex: Excitation, played: Excitation, *, crest: float | None = None) -> None:
        self.backend.stop_excitation()
        try:
            peak = self.backend.start_excitation(played)
        except ValueError as exc:
            raise Refused("FSM_BadArgument", f"StartExcitation refused: {exc}") from None
        self._excitation = {"input": ex.channel, "kind": ex.kind,
                            "amplitude_v": ex.amplitude_v, "band_hz": ex.band_hz,
                            "frequency_hz": ex.freq_hz or None, "peak_v": peak,
                            "start_time_s": ex.start_s}
        if ex.kind == "multisine":
            self._excitation.update(period_s=ex.period_s, crest_factor=crest)
        if isinstance(played, SampledExcitation):
            self._excitation.update(n_samples=int(played.samples_v.size),
                                    loop_from=played.loop_from,
                                    samples_sha256=played.samples_sha256)
        self._frf = AccumulatingFrf(fs_hz=self.fs_hz, input_name=ex.channel,
                                    output_names=("Vph", "Vpv"))
        self._frf_cache = None

    @_command("StopExcitation")
    def stop_excitation(self) -> str:
        """Stop the excitation (and an excitation's design); the FRF keeps its last estimate."""
        with self._locked("StopExcitation"):
            self.check_allowed("StopExcitation")
            task = self._task
            if task is not None and task.what.startswith("designing"):
                task.cancel()
                self._task = None
            was = self._excitation is not None
            self.backend.stop_excitation()
            self._stop_frf()
            self._excitation = None
        return "excitation stopped" if was else "no excitation was running"

    # -- experiments and recordings ------------------------------------------------

    @_command("RunExperiment")
    def run_experiment(self, argument: str) -> str:
        """Start one of the study's 13 experiments with the seed's protocol; returns its path.

        The argument is the name (``data_uch``) or ``{"name": ..., "overwrite":
        true}``. The file (``<output folder>/<name>.mat``, the seed's layout) is
        complete when the state leaves MOVING. Closed-loop experiments use the
        loaded controller (the seed's if none); when it ends (or is aborted) the
        loop and the environment are put back as they were.
        """
        specs = {s.name: s for s in esrf_experiments()}
        request = parse_experiment(argument, tuple(specs))
        spec = specs[request.name]
        with self._locked("RunExperiment"):
            self.check_allowed("RunExperiment")
            backend = self.backend
            assert isinstance(backend, TwinBackend)
            t0 = backend.time_s
            plan = plan_job(kind="experiment", name=spec.name, folder=self.output_folder,
                            fmt="mat", signals=tuple(s for s in EXPERIMENTS[spec.name].required
                                                     if s != "t"),
                            n_samples=round(spec.duration_s * self.fs_hz),
                            start_sample=round(t0 * self.fs_hz), t0_s=0.0, fs_hz=self.fs_hz,
                            source=f"fsmbench live ({backend.kind})",
                            overwrite=request.overwrite)
            before = backend.controller
            backend.stop_excitation()
            self._stop_frf()
            self._excitation = None
            # Closed with nothing loaded, the loop runs the seed's controller: keep it.
            k = (self._loaded or before or self._seed_controller()) if spec.closed_loop else None
            if k is not before:
                self._set_loop(k, hold=False, cause=f"RunExperiment {spec.name}")
            backend.set_environment(compensation_unit=spec.compensation_unit,
                                    shielding=spec.shielding)
            for ex in spec.excitations:
                backend.start_excitation(replace(ex, start_s=t0 + ex.start_s))

            def restore(loop: bool) -> None:
                backend.stop_excitation()
                backend.set_environment(compensation_unit=True, shielding=True)
                if loop and self._fault is None and backend.controller is not before:
                    self._set_loop(before, hold=False,
                                   cause=f"RunExperiment {spec.name} ended: the loop it found")

            self._start_job(plan, restore)
        return str(plan.path)

    @_command("Record")
    def record(self, argument: str) -> str:
        """Record signals from now: JSON ``{"signals": [...], "duration_s": s, "name": ...,
        "format": "mat"|"nexus", "overwrite": false}``; returns the file's path (complete when
        MOVING ends)."""
        request = parse_record(argument, fs_hz=self.fs_hz)
        with self._locked("Record"):
            self.check_allowed("Record")
            start = round(self.backend.time_s * self.fs_hz)
            plan = plan_job(kind="record", name=request.name, folder=self.output_folder,
                            fmt=request.format, signals=request.signals,
                            n_samples=max(1, round(request.duration_s * self.fs_hz)),
                            start_sample=start, t0_s=start / self.fs_hz, fs_hz=self.fs_hz,
                            source=f"fsmbench live ({self.backend.kind})",
                            overwrite=request.overwrite)
            self._start_job(plan, None)
        return str(plan.path)

    def _start_job(self, plan: JobPlan, restore: Callable[[bool], None] | None) -> None:
        self._job = Job(replace(plan, bench=self.bench), restore=restore,
                        on_done=self._job_written, thread_init=self.thread_init)

    def _collect(self, block: Any) -> None:
        job = self._job
        assert job is not None
        p = job.plan
        if job.writer.failed:
            self._end_collection(job, error=job.writer.failed)
            return
        missing = [s for s in p.signals if s not in block.signals]
        if missing:
            self._end_collection(job, error=f"signals {', '.join(missing)} are not in the played "
                                       f"file {block.source}")
            return
        take = min(p.n_samples - job.writer.taken, block.n)
        if take > 0 and not job.writer.put({s: block.signals[s][:take].copy()
                                            for s in p.signals}):
            self._end_collection(job, error="the disk does not keep up (the writer is too far "
                                       "behind the bench)")
            return
        if job.writer.taken >= p.n_samples:
            self._end_collection(job)

    def _end_collection(self, job: Job, *, aborted: str = "", error: str = "",
                        restore_loop: bool = True) -> None:
        job.collecting = False
        if job.restore is not None:
            restore, job.restore = job.restore, None
            restore(restore_loop)
        job.writer.finish(aborted=aborted, error=error)

    def _job_written(self, job: Job, outcome: JobOutcome) -> None:
        with self._lock:
            if job.collecting:  # the writer failed first
                self._end_collection(job, error=outcome.error or "the writer stopped")
            if self._job is job:
                self._job = None
            self._notice = outcome.sentence
        self.log("WARNING" if outcome.error else "INFO", outcome.sentence)
        self.publish()
