"""The live bench without Tango: a paced loop over a backend, its commands and its views.

:class:`LiveBench` runs the backend in a thread, block by block, paced to
``speed`` × the wall clock (the simulated loop itself is always exact at
its sampling rate). Commands act between blocks, under one lock. Every
view the device publishes is computed here from the blocks: scalars by
:class:`~fsmbench.live.monitor.LiveMonitor`, spectra by
:mod:`fsmbench.live.spectra`, once per second of bench time.

States (Tango's names): ``ON`` loop open, ``RUNNING`` loop closed,
``MOVING`` an experiment or a recording runs, ``ALARM`` a converter
saturates, ``FAULT`` the protection opened the loop (until :meth:`reset`).
"""

from __future__ import annotations

import json
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from fsmbench.bench.params import Bench
from fsmbench.control.load import load_controllers, select_controller
from fsmbench.io.recording import make_recording, write_recording
from fsmbench.io.signals import EXPERIMENTS
from fsmbench.live.arguments import parse_excitation, parse_record
from fsmbench.live.backend import LiveBlock, PlaybackBackend, TwinBackend
from fsmbench.live.monitor import LiveMonitor, Trip
from fsmbench.live.spectra import AccumulatingFrf, FrfSnapshot, RollingAsd
from fsmbench.sim.controller import sercalo_feedback
from fsmbench.sim.engine import DiscreteController
from fsmbench.twin.experiments import seed_experiments, seed_feedback

__all__ = ["ASD_SIGNALS", "LiveBench", "LiveJob"]

#: Signals whose amplitude spectral density the device publishes.
ASD_SIGNALS = ("Vph", "Vpv", "Va")
_FRF_OUTPUTS = ("Vph", "Vpv")


@dataclass(frozen=True)
class LiveJob:
    """A recording or an experiment in progress.

    Attributes
    ----------
    kind : {"experiment", "record"}
    name : str
    path : Path
        Where the file will be.
    signals : tuple of str
    n_samples : int
    start_sample : int
    """

    kind: str
    name: str
    path: Path
    signals: tuple[str, ...]
    n_samples: int
    start_sample: int


class LiveBench:
    """The live bench (see the module notes).

    Parameters
    ----------
    bench : Bench
        The bench model (twin backend: simulated; both: calibrated 4QD gains, converters).
    backend : {"twin", "playback"}
    playback_folder : str or Path, optional
        Folder of recordings (playback backend).
    seed : int
    speed : float
        Bench seconds per wall-clock second (> 0).
    output_folder : str or Path
        Where experiments and recordings are written (created when needed).
    on_state : callable, optional
        Called with the new state name whenever it changes (the device pushes events).
    """

    def __init__(self, bench: Bench, *, backend: str = "twin",
                 playback_folder: str | Path | None = None, seed: int = 0, speed: float = 1.0,
                 output_folder: str | Path = "fsmbench-live",
                 on_state: Callable[[str], None] | None = None) -> None:
        self.bench = bench
        conv = bench.nominal.converter
        if backend == "twin":
            self.backend: TwinBackend | PlaybackBackend = TwinBackend(bench, seed=seed)
        elif backend == "playback":
            if not playback_folder:
                raise ValueError("the playback backend needs a folder of recordings")
            self.backend = PlaybackBackend(playback_folder, fs_hz=conv.fs_hz,
                                           adc_range_v=conv.range_v, adc_bits=conv.bits)
        else:
            raise ValueError(f"unknown backend {backend!r}; known: twin, playback")
        self.fs_hz = self.backend.fs_hz
        gd = bench.nominal.quad_diode.gain_v_per_rad
        self.qd_gain_v_per_rad = (float(gd.h), float(gd.v))
        self.monitor = LiveMonitor(fs_hz=self.fs_hz, qd_gain_v_per_rad=self.qd_gain_v_per_rad,
                                   half_range_v=conv.range_v / 2, lsb_v=conv.lsb_v)
        self.output_folder = Path(output_folder)
        self._on_state = on_state
        self._pending_states: list[str] = []
        self._lock = threading.RLock()
        self._speed = self._check_speed(speed)
        self._asd = {name: RollingAsd(fs_hz=self.fs_hz, channels=(name,)) for name in ASD_SIGNALS}
        self._asd_cache: dict[str, np.ndarray] = {}
        self._frf: AccumulatingFrf | None = None
        self._frf_cache: FrfSnapshot | None = None
        self._excitation: dict[str, Any] | None = None
        self._next_second = 1
        self._loaded: DiscreteController | None = None
        self._trip: Trip | None = None
        self._job: LiveJob | None = None
        self._job_parts: list[dict[str, np.ndarray]] = []
        self._job_restore: Callable[[], None] | None = None
        self._last_job: str = ""
        self._alarm = False
        self._state = "ON"
        self._status = "Loop open."
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._error: BaseException | None = None

    # -- running -------------------------------------------------------------------

    @staticmethod
    def _check_speed(speed: float) -> float:
        if not (np.isfinite(speed) and speed > 0):
            raise ValueError(f"speed must be a positive factor of real time, got {speed!r}")
        return float(speed)

    @property
    def block_samples(self) -> int:
        """Samples per block: 10 ms of bench time, 50 ms when running faster than 10×."""
        return round(self.fs_hz * (0.01 if self._speed <= 10 else 0.05))

    def start(self, *, thread_init: Callable[[], Any] | None = None) -> None:
        """Start the loop thread (``thread_init`` is entered in it, e.g. Tango's omni thread)."""
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, args=(thread_init,),
                                        name="fsmbench-live", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        """Stop the loop thread."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=10)

    def _run(self, thread_init: Callable[[], Any] | None) -> None:
        ctx = thread_init() if thread_init is not None else None
        try:
            if ctx is not None:
                ctx.__enter__()
            wall0, bench0 = time.monotonic(), self.backend.time_s
            speed = self._speed
            while not self._stop.is_set():
                self.advance(self.block_samples)
                with self._lock:
                    if self._speed != speed:
                        speed = self._speed
                        wall0, bench0 = time.monotonic(), self.backend.time_s
                    ahead = wall0 + (self.backend.time_s - bench0) / speed - time.monotonic()
                if ahead > 0:
                    self._stop.wait(ahead)
                elif ahead < -1.0:
                    # Slower than asked (a loaded machine): do not try to catch up.
                    wall0, bench0 = time.monotonic(), self.backend.time_s
        except BaseException as exc:
            self._error = exc
            self._set_state("FAULT", f"The bench loop stopped: {exc}")
            self._flush_states()
        finally:
            if ctx is not None:
                ctx.__exit__(None, None, None)

    def advance(self, n: int) -> LiveBlock:
        """Run ``n`` samples now (the loop thread calls this; tests may too, without it)."""
        with self._lock:
            block = self._advance(n)
        self._flush_states()
        return block

    def _advance(self, n: int) -> LiveBlock:
        with self._lock:
            block = self.backend.step(n)
            closed = self.backend.controller is not None
            trip = self.monitor.push(block, loop_closed=closed)
            if trip is not None:
                self.backend.set_controller(None, hold=False)
                self.backend.stop_excitation()
                self._excitation = None
                self._trip = trip
                self._set_state("FAULT", f"Protection opened the loop at bench time "
                                         f"{trip.bench_time_s:.3f} s: {trip.reason}. "
                                         "Reset to return to ON.")
            for name, asd in self._asd.items():
                if name in block.signals:
                    asd.push(block.signals[name][:, None])
            if self._frf is not None and self._excitation is not None:
                ch = self._excitation["input"]
                if ch in block.signals and all(o in block.signals for o in _FRF_OUTPUTS):
                    self._frf.push(block.signals[ch],
                                   np.column_stack([block.signals[o] for o in _FRF_OUTPUTS]))
            if self._job is not None:
                self._collect(block)
            end = block.start_sample + block.n
            if end >= self._next_second * self.fs_hz:
                self._next_second = int(end // self.fs_hz) + 1
                self._refresh_spectra()
            self._update_state()
            return block

    def _refresh_spectra(self) -> None:
        for name, asd in self._asd.items():
            snap = asd.spectrum()
            if snap is not None:
                self._asd_cache["frequency"] = snap.frequency_hz
                self._asd_cache[name] = snap.asd[0]
        if self._frf is not None and self._frf.n_segments:
            self._frf_cache = self._frf.result()

    def _set_state(self, state: str, status: str) -> None:
        changed = state != self._state
        self._state, self._status = state, status
        if changed:
            self._pending_states.append(state)

    def _flush_states(self) -> None:
        """Tell ``on_state`` of the state changes, outside the lock.

        The device's event push takes Tango's device monitor, which a client
        call (a command, an attribute read) holds while it waits for this lock:
        pushing with the lock held would deadlock the loop thread.
        """
        with self._lock:
            pending, self._pending_states = self._pending_states, []
        if self._on_state is not None:
            for state in pending:
                self._on_state(state)

    def _update_state(self) -> None:
        if self._state == "FAULT":
            return
        closed = self.backend.controller is not None
        self._alarm = self.monitor.saturating_now()
        if self._job is not None:
            job = self._job
            self._set_state("MOVING", f"{job.kind.capitalize()} {job.name} running: "
                                      f"{self._job_done() / self.fs_hz:.1f} of "
                                      f"{job.n_samples / self.fs_hz:.1f} s, into {job.path}.")
        elif self._alarm:
            self._set_state("ALARM", "A converter saturates (DAC command or 4QD reading on a "
                                     "rail in the last 10 ms).")
        elif closed:
            self._set_state("RUNNING", f"Loop closed with {self.controller_name}.")
        else:
            self._set_state("ON", "Loop open." + (f" Last file: {self._last_job}."
                                                  if self._last_job else ""))

    # -- views ---------------------------------------------------------------------

    @property
    def state(self) -> str:
        """ON, RUNNING, MOVING, ALARM or FAULT."""
        return self._state

    @property
    def status(self) -> str:
        """The state in words (why, since when)."""
        return self._status

    @property
    def speed(self) -> float:
        """Bench seconds per wall-clock second."""
        return self._speed

    @speed.setter
    def speed(self, value: float) -> None:
        with self._lock:
            self._speed = self._check_speed(value)

    @property
    def bench_time_s(self) -> float:
        """Bench time of the next sample [s]."""
        return self.backend.time_s

    @property
    def loop_closed(self) -> bool:
        """The Sercalo loop is closed."""
        return self.backend.controller is not None

    @property
    def controller_name(self) -> str:
        """The controller in the loop, else the one loaded for the next close, else ``none``."""
        k = self.backend.controller or self._loaded
        return k.name if k is not None else "none (CloseLoop uses the seed's controller, 9.2)"

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

    # -- commands ------------------------------------------------------------------

    def _require_acting(self, what: str) -> None:
        if self._state == "FAULT":
            raise ValueError(f"{what} refused: the bench is in FAULT ({self._status}); "
                             "Reset first")
        if isinstance(self.backend, PlaybackBackend):
            raise ValueError(f"{what} is not possible on a playback: the bench replays the "
                             f"recorded files {', '.join(self.backend.files)}")

    def _discrete(self, path: str, name: str | None) -> DiscreteController:
        ts = 1.0 / self.fs_hz
        chosen = select_controller(load_controllers(path, ts_s=ts), name)
        return sercalo_feedback(a=chosen.a, b=chosen.b, c=chosen.c, d=chosen.d,
                                gd_v_per_rad=chosen.qd_gain_v_per_rad or self.qd_gain_v_per_rad,
                                name=f"{chosen.name} ({Path(chosen.source_path).name})")

    def _seed_controller(self) -> DiscreteController:
        return replace(seed_feedback(self.bench), name="seed controller (9.2)")

    def load_controller(self, argument: str) -> str:
        """Load a controller: ``path`` or JSON ``{"path": ..., "controller": name}``.

        In closed loop the new controller takes over bumplessly at once;
        otherwise it is used by the next :meth:`close_loop`. Returns its name.
        """
        text = argument.strip()
        if text.startswith("{"):
            try:
                doc = json.loads(text)
            except json.JSONDecodeError as exc:
                raise ValueError(f"LoadController: the argument is not valid JSON ({exc})") \
                    from None
            if not isinstance(doc, dict) or "path" not in doc:
                raise ValueError('LoadController: give a path, or {"path": ..., '
                                 '"controller": name}')
            path, name = str(doc["path"]), doc.get("controller")
        else:
            path, name = text, None
        k = self._discrete(path, None if name is None else str(name))
        with self._lock:
            self._require_acting("LoadController")
            self._loaded = k
            if self.backend.controller is not None:
                self.backend.set_controller(k, hold=True)
            self._update_state()
        self._flush_states()
        return k.name

    def close_loop(self) -> None:
        """Close the loop with the loaded controller (the seed's if none), bumplessly."""
        with self._lock:
            self._require_acting("CloseLoop")
            if self._job is not None:
                raise ValueError(f"CloseLoop refused: {self._job.kind} {self._job.name} runs")
            k = self._loaded or self._seed_controller()
            self.backend.set_controller(k, hold=True)
            self._update_state()
        self._flush_states()

    def open_loop(self) -> None:
        """Open the loop, holding the last command (bumpless)."""
        with self._lock:
            self._require_acting("OpenLoop")
            if self._job is not None:
                raise ValueError(f"OpenLoop refused: {self._job.kind} {self._job.name} runs")
            self.backend.set_controller(None, hold=True)
            self._update_state()
        self._flush_states()

    def reset(self) -> None:
        """Leave FAULT (loop open, command zero, excitations stopped)."""
        with self._lock:
            if self.backend.acts:
                self.backend.set_controller(None, hold=False)
                self.backend.stop_excitation()
            self._excitation = None
            self._trip = None
            self._job = None
            self._job_parts = []
            self._state = "ON"
            self._update_state()
            self._pending_states.append(self._state)
        self._flush_states()

    def start_excitation(self, argument: str) -> None:
        """Start an excitation from JSON (see :func:`parse_excitation`)."""
        with self._lock:
            self._require_acting("StartExcitation")
            ex = parse_excitation(argument, start_s=self.backend.time_s,
                                  half_range_v=self.bench.nominal.converter.range_v / 2)
            self.backend.stop_excitation()
            peak = self.backend.start_excitation(ex)
            self._excitation = {"input": ex.channel, "kind": ex.kind,
                                "amplitude_v": ex.amplitude_v, "band_hz": ex.band_hz,
                                "frequency_hz": ex.freq_hz or None, "peak_v": peak,
                                "start_time_s": ex.start_s}
            self._frf = AccumulatingFrf(fs_hz=self.fs_hz, input_name=ex.channel,
                                        output_names=_FRF_OUTPUTS)
            self._frf_cache = None

    def stop_excitation(self) -> None:
        """Stop the excitation; the FRF keeps its last estimate (over every excited sample)."""
        with self._lock:
            self.backend.stop_excitation()
            if self._frf is not None and self._frf.n_segments:
                self._frf_cache = self._frf.result()
            self._frf = None
            self._excitation = None

    # -- experiments and recordings ------------------------------------------------

    def _busy(self, what: str) -> None:
        if self._job is not None:
            raise ValueError(f"{what} refused: {self._job.kind} {self._job.name} is running "
                             f"(into {self._job.path})")
        if self._state == "FAULT":
            raise ValueError(f"{what} refused: the bench is in FAULT; Reset first")

    def _begin(self, job: LiveJob) -> None:
        self.output_folder.mkdir(parents=True, exist_ok=True)
        self._job = job
        self._job_parts = []
        self._update_state()

    def _job_done(self) -> int:
        return sum(len(next(iter(p.values()))) for p in self._job_parts) if self._job_parts \
            else 0

    def _collect(self, block: LiveBlock) -> None:
        job = self._job
        assert job is not None
        need = job.n_samples - self._job_done()
        take = min(need, block.n)
        missing = [s for s in job.signals if s not in block.signals]
        if missing:
            self._finish_job(error=f"signals {', '.join(missing)} are not in the played file "
                                   f"{block.source}")
            return
        self._job_parts.append({s: block.signals[s][:take].copy() for s in job.signals})
        if self._job_done() >= job.n_samples:
            self._finish_job()

    def _finish_job(self, *, error: str | None = None) -> None:
        job = self._job
        assert job is not None
        self._job = None
        parts, self._job_parts = self._job_parts, []
        if self._job_restore is not None:
            self._job_restore()
            self._job_restore = None
        if error is not None:
            self._last_job = f"{job.name} failed: {error}"
            return
        signals = {s: np.concatenate([p[s] for p in parts]) for s in job.signals}
        conv = self.bench.nominal.converter
        if job.kind == "experiment":
            ds = make_recording(signals, fs_hz=self.fs_hz, experiment=job.name,
                                source=f"fsmbench live ({self.backend.kind})",
                                adc_range_v=conv.range_v, adc_bits=conv.bits)
        else:
            t = np.arange(job.start_sample, job.start_sample + job.n_samples) / self.fs_hz
            ds = make_recording(signals, t=t, experiment=job.name,
                                source=f"fsmbench live ({self.backend.kind})",
                                adc_range_v=conv.range_v, adc_bits=conv.bits)
        write_recording(ds, job.path,
                        format="nexus" if job.path.suffix in (".h5", ".nxs") else "mat5")
        self._last_job = str(job.path)

    def run_experiment(self, name: str) -> str:
        """Start one of the study's 13 experiments with the seed's protocol; returns its path.

        The file (``<output folder>/<name>.mat``, the seed's layout) is
        complete when the state leaves MOVING. Closed-loop experiments use
        the loaded controller (the seed's if none); the loop and the
        environment are restored afterwards.
        """
        specs = {s.name: s for s in seed_experiments()}
        if name not in specs:
            raise ValueError(f"RunExperiment: unknown experiment {name!r}; known: "
                             f"{', '.join(specs)}")
        spec = specs[name]
        with self._lock:
            self._busy("RunExperiment")
            self._require_acting("RunExperiment")
            backend = self.backend
            assert isinstance(backend, TwinBackend)
            before = backend.controller
            t0 = backend.time_s
            backend.stop_excitation()
            self._excitation = None
            self._frf = None
            backend.set_controller((self._loaded or self._seed_controller())
                                   if spec.closed_loop else None, hold=False)
            backend.set_environment(compensation_unit=spec.compensation_unit,
                                    shielding=spec.shielding)
            for ex in spec.excitations:
                backend.start_excitation(replace(ex, start_s=t0 + ex.start_s))

            def restore() -> None:
                backend.stop_excitation()
                backend.set_controller(before, hold=False)
                backend.set_environment(compensation_unit=True, shielding=True)

            self._job_restore = restore
            path = self.output_folder / f"{name}.mat"
            signals = tuple(s for s in EXPERIMENTS[name].required if s != "t")
            self._begin(LiveJob(kind="experiment", name=name, path=path, signals=signals,
                                n_samples=round(spec.duration_s * self.fs_hz),
                                start_sample=round(t0 * self.fs_hz)))
        self._flush_states()
        return str(path)

    def record(self, argument: str) -> str:
        """Record signals from now: JSON ``{"signals": [...], "duration_s": s, "name": ...,
        "format": "mat"|"nexus"}``; returns the file's path (complete when MOVING ends)."""
        request = parse_record(argument)
        with self._lock:
            self._busy("Record")
            path = self.output_folder / f"{request.name}{request.suffix}"
            self._begin(LiveJob(kind="record", name=request.name, path=path,
                                signals=request.signals,
                                n_samples=max(1, round(request.duration_s * self.fs_hz)),
                                start_sample=round(self.backend.time_s * self.fs_hz)))
        self._flush_states()
        return str(path)
