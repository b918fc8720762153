"""The live device as :func:`fsmbench.tune.guarded.tune_guarded`'s target, over Tango or EPICS.

:func:`device_proxy` (:mod:`fsmbench.tune.proxy`) reaches the device:
``tango://HOST:PORT/dom/fam/member`` (or a bare Tango name) through PyTango's
``DeviceProxy``; ``ca://PREFIX``, the EPICS IOC of ``fsmbench serve --protocol epics
--prefix PREFIX``, through :class:`fsmbench.tune.ca_device.CaDevice`, which gives the same
calls over Channel Access (its PVs ``PREFIX:<Attribute>``, a command a put whose reply is
``PREFIX:Reply``). A refusal is PyTango's ``DevFailed`` or
:class:`~fsmbench.tune.device_errors.DeviceRefused`, a lost connection ``DevFailed`` or
:class:`~fsmbench.tune.device_errors.DeviceLost`; both read the same
(:func:`~fsmbench.tune.device_errors.device_failure`), so the transaction below is the same
on both protocols.

:class:`DeviceTarget` acts only through the device's own commands, the loop closed
all along:

* **measure** the running loop: ``Record`` of ``Vph``, ``Vpv`` (read back from the
  file the device writes), over the calibrated 4QD gains;
* **play** each closed-loop excitation: ``Record`` of the closed-loop signals
  (``Uch``, ``Ucv``, ``Vph``, ``Vpv``, ``Vch``, ``Vcv``), then, ``settle_s`` into it,
  ``StartExcitation`` of kind ``samples`` (the designed commands as a ``.npy`` file,
  added at the controller's output in RUNNING); the record is cut to the twin's
  layout (``settle_s`` before the excitation's first sample, to its last) from the
  excitation's start sample the device publishes (``Excitation``), and
  ``StopExcitation`` ends it;
* **load** a controller: its SOS file (:func:`fsmbench.control.export.write_sos_json`),
  written in the device's controllers folder (``ControllersPath``: the only folder
  ``LoadController`` reads), and ``LoadController``, which checks it on the device's
  bench and swaps it in bumplessly in RUNNING, on the call; the device's ``Controller``
  then names it;
* **roll back** to the controller the device ran when tune started, by the device's own
  ``LoadController`` of what it was loaded from (``seed``, or its file with ``--running
  FILE::NAME``), else ``last-good`` (the latest controller before the one in effect that
  ran without tripping), once any excitation and record tune started are stopped
  (``StopExcitation``, ``Abort``): the device checks it again on the call.

Every attribute read goes through :func:`fsmbench.tune.reads.read_valid`: the device
answers INVALID (PyTango's value None; over EPICS, SEVR INVALID) when it cannot take its
bench's lock in 0.5 s, and such a reading is read again for a bounded wall-clock time,
then named in an error. Over EPICS a value can also be up to one refresh of the IOC's
records old (0.1 s of wall clock): the record's start and the excitation's are read once
they have moved and name this excitation (:meth:`DeviceTarget._bench_time_now`,
:meth:`DeviceTarget._started`).

The device and ``tune`` share a filesystem (the excitation and controller files
``tune`` writes, the records the device writes). The device's own watch
(:mod:`fsmbench.live.watching`) holds its judgement while an excitation plays and
starts afresh on the loaded controller.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from fsmbench.bench.params import Bench
from fsmbench.control.controller import Controller
from fsmbench.control.export import InputScaling, write_sos_json
from fsmbench.io.recording import make_recording, read_recording
from fsmbench.sim.excitation import SampledExcitation, samples_sha256
from fsmbench.tune.device_errors import device_failure
from fsmbench.tune.proxy import device_proxy, release_proxy
from fsmbench.tune.reads import INVALID_WAIT_S, read_valid
from fsmbench.tune.transaction import LoopOpenedError
from fsmbench.twin.closed_loop import CLOSED_LOOP_SIGNALS, ClosedLoopPlay, excitation_variable
from fsmbench.twin.experiments import ExperimentSpec
from fsmbench.twin.simulate import TwinRun

__all__ = ["DeviceTarget", "device_proxy", "device_words", "release_proxy"]

#: Bench time the excitation may start late in its record [s], at least, and in wall clock
#: at the device's speed [s] (the client's round trips: 20 ms of wall clock is 1 s of bench
#: time at 50x); a record it misses is played again, up to :data:`_ATTEMPTS` times.
_LATE_S = 3.0
_LATE_WALL_S = 0.25
_ATTEMPTS = 3
#: Wall clock a command's work may take beyond its bench time at the device's speed [s].
_SLACK_S = 120.0


def _controllers_folder(where: str | None, folder: Path) -> Path:
    """Where the controllers tune loads are written: ``folder`` when the device's controllers
    folder (``ControllersPath``, None: a device that reads a controller from any path)
    holds it, else a folder of the same name in there."""
    if where is None:
        return folder
    return folder if folder.resolve().is_relative_to(Path(where).resolve()) \
        else Path(where) / folder.name


def _restore_requests(source: str | None) -> list[Any]:
    """The ``LoadController`` arguments that bring back the controller ``--running`` named
    (``seed``, or ``PATH[::NAME]``), then ``last-good``."""
    if source == "seed":
        return ["seed", "last-good"]
    if source is None or source == "fsmbench":
        return ["last-good"]
    path, sep, name = source.partition("::")
    doc = {"path": str(Path(path).resolve())}
    if sep:
        doc["controller"] = name
    return [doc, "last-good"]


def device_words(exc: BaseException) -> str:
    """A device's refusal (its sentence and reason code, on either protocol) or an error, in
    one line."""
    failure = device_failure(exc)
    return failure.sentence() if failure is not None else " ".join(str(exc).split())


class DeviceTarget:
    """The live device, loop closed (see the module notes).

    Parameters
    ----------
    proxy : tango.DeviceProxy or fsmbench.tune.ca_device.CaDevice
        The ``FsmBench`` device, or its EPICS IOC (:func:`device_proxy`).
    bench : Bench
        The bench file (the converter rate, the 4QD gains).
    running : Controller
        The controller the device runs; its name must be the device's ``Controller``.
    folder : Path
        Where the excitations and controllers played through the device are written
        (kept: the device remembers the loaded controller's file); the controllers in a
        folder of the same name in the device's controllers folder (``ControllersPath``)
        when ``folder`` is not in it.
    address : str
        In words, for the log and ``tune.json``.
    running_source : str, optional
        How ``running`` was named on tune's command line (``seed``, ``PATH[::NAME]``): what
        the roll-back asks ``LoadController`` for first (``last-good`` after it).
    invalid_wait_s : float
        Wall-clock time an INVALID attribute is read again for before it is an error [s].

    Raises
    ------
    ValueError
        The loop is not closed, or the device runs another controller (both named).
    fsmbench.tune.reads.DeviceReadError
        An attribute stayed INVALID for ``invalid_wait_s``.
    """

    def __init__(self, proxy: Any, *, bench: Bench, running: Controller, folder: Path,
                 address: str, running_source: str | None = None,
                 invalid_wait_s: float = INVALID_WAIT_S) -> None:
        self.proxy = proxy
        self.fs_hz = float(bench.true.converter.fs_hz)
        self.address = address
        self.label = f"the live device {address}"
        self.drift_pct = 0.0
        self.invalid_wait_s = float(invalid_wait_s)
        self.folder = Path(folder)
        self.folder.mkdir(parents=True, exist_ok=True)
        where = (str(self._attr("ControllersPath"))
                 if "ControllersPath" in proxy.get_attribute_list() else None)
        self.controllers = _controllers_folder(where, self.folder)
        self.gd = running.gd
        self.restore_requests = _restore_requests(running_source)
        self._n = 0
        state = str(proxy.state())
        if not self._attr("LoopClosed") or state not in ("RUNNING", "ALARM"):
            raise ValueError(f"{address}: the loop is not running (state {state}: "
                             f"{proxy.status()}); tune works with the loop closed: CloseLoop "
                             "first")
        now = self._attr("Controller")
        if now != running.name:
            raise ValueError(f"{address} runs {now!r}, not {running.name!r}: name the running "
                             "controller (--running)")

    # -- helpers -------------------------------------------------------------------

    def _attr(self, name: str) -> Any:
        """The attribute ``name``'s value, INVALID readings read again (module notes)."""
        return read_valid(self.proxy, name, device=self.label, wait_s=self.invalid_wait_s)

    def _name(self, what: str) -> str:
        self._n += 1
        return f"tune_{what}_{self._n}"

    def _wait(self, check: Callable[[], bool], what: str, bench_s: float) -> None:
        """Poll until ``check()``; a wall-clock limit from the bench time it needs."""
        limit = _SLACK_S if bench_s <= 0.0 else \
            _SLACK_S + bench_s / max(float(self._attr("SpeedFactor")), 1e-3)
        t0 = time.monotonic()
        while not check():
            if time.monotonic() - t0 > limit:
                raise ValueError(f"{self.label}: {what} did not happen within {limit:.0f} s "
                                 f"(wall clock); the device says: {self.proxy.status()}")
            time.sleep(0.01)

    def _record(self, signals: Sequence[str], duration_s: float,
                during: Callable[[float], Any] | None = None) -> tuple[Any, Any]:
        """Record ``signals`` for ``duration_s``; ``during(start_s)`` runs as it records.

        Returns the record (xarray) and what ``during`` returned.
        """
        try:
            path = self.proxy.Record(json.dumps({"signals": list(signals),
                                                 "duration_s": duration_s,
                                                 "name": self._name("record"),
                                                 "overwrite": True}))
        except Exception:
            # Refused because a trip opened the loop (FAULT) before the record: said as such.
            if not self._attr("LoopClosed"):
                self._loop_opened()
            raise
        out = during(self._bench_time_now()) if during is not None else None
        # The record ends (MOVING left) with its file, or without one when a trip cut it
        # before its first sample: then the loop is open, said as such.
        self._wait(lambda: str(self.proxy.state()) != "MOVING", f"the record {path}",
                   duration_s)
        if not Path(path).exists():
            if not self._attr("LoopClosed"):
                self._loop_opened()
            raise ValueError(f"{self.label}: the record {path} ended without a file: "
                             f"{self.proxy.status()}")
        return read_recording(path, require=()), out

    def _bench_time_now(self) -> float:
        """The device's ``BenchTime`` as it is now [s]: read until it moves.

        The IOC refreshes its records every 0.1 s of wall clock (5 s of bench time at 50x);
        the value just after a command can be that old, and a record's start taken from it
        put the excitation before the end of its settling. A value that has just moved is
        fresh (PyTango's are fresh at once: the second read has moved).
        """
        first = float(self._attr("BenchTime"))
        now = [first]

        def moved() -> bool:
            now.append(float(self._attr("BenchTime")))
            return now[-1] > first

        self._wait(moved, "the bench time to advance", 0.0)
        return now[-1]

    def _started(self, sha: str, since_s: float) -> float:
        """The bench time the excitation of samples ``sha`` started [s], from the device's
        ``Excitation``, once it names them and a start at or after ``since_s``.

        Waited for: the IOC refreshes ``Excitation`` every 0.1 s of wall clock, not within
        the put, so a read just after ``StartExcitation`` can still give the previous
        excitation (an earlier start: a record cut from it would be misplaced).
        """
        start: list[float] = []

        def ours() -> bool:
            try:
                doc = json.loads(str(self._attr("Excitation")))
            except ValueError:
                return False
            if not isinstance(doc, dict) or doc.get("samples_sha256") != sha:
                return False
            start.append(float(doc.get("start_time_s", -np.inf)))
            return start[-1] >= since_s

        self._wait(ours, "the excitation's start (Excitation naming its samples)", 0.0)
        return start[-1]

    # -- the target ----------------------------------------------------------------

    def run(self, duration_s: float, *, settle_s: float) -> np.ndarray:
        """The device's tracking error after ``settle_s`` of ``duration_s`` [rad], (n, 2).

        Raises
        ------
        LoopOpenedError
            The loop was open at the end of the record (a protection trip, an OpenLoop).
        """
        rec, _ = self._record(("Vph", "Vpv"), duration_s)
        if not self._attr("LoopClosed"):
            self._loop_opened()
        e = np.column_stack([np.asarray(rec["Vph"].values, dtype=float) / self.gd[0],
                             np.asarray(rec["Vpv"].values, dtype=float) / self.gd[1]])
        e = e[round(settle_s * self.fs_hz):]
        return e - e.mean(axis=0)

    def load(self, loop: Controller) -> dict[str, Any]:
        """``LoadController`` of ``loop`` (its SOS file), bumpless in RUNNING."""

        key = "tuned" if "closed-loop" in loop.name else "controller"
        where = self.controllers / self._name("controller") / "controllers_sos.json"
        where.parent.mkdir(parents=True, exist_ok=True)
        write_sos_json(where, {key: loop.continuous},
                       scaling=InputScaling(qd_gain_v_per_rad=loop.gd,
                                            plant_source=f"identified ({loop.name})"),
                       ts_s=1.0 / self.fs_hz, descriptions={key: loop.name})
        before = self._attr("Controller")
        reply = self.proxy.LoadController(json.dumps({"path": str(where), "controller": key}))
        self._wait(lambda: self._attr("Task") == "", "the controller's load", 0.0)

        def confirmed() -> bool:
            # The same name twice (a retune over a tuned controller) is told apart by the
            # file the device says it loaded; a read may lag the reply by an update.
            now = str(self._attr("Controller"))
            return now.startswith(key) and (now != before or str(where) in self.proxy.status())

        try:
            self._wait(confirmed, "the device's Controller naming what it loaded", 0.0)
        except ValueError:
            raise ValueError(f"{self.label}: LoadController of {loop.name} is not confirmed: "
                             f"the device replied {reply!r} but its Controller reads "
                             f"{self._attr('Controller')!r} ({self.proxy.status()})") from None
        now = self._attr("Controller")
        self.gd = loop.gd
        return {"bench_time_s": float(self._attr("BenchTime")), "from": before, "to": now,
                "file": str(where), "reply": reply}

    def _loop_opened(self) -> None:
        state, status, holds = str(self.proxy.state()), str(self.proxy.status()), \
            str(self._attr("Controller"))
        tripped = state == "FAULT" or "Protection opened the loop" in status
        what = "The protection tripped and opened the loop" if tripped else \
            "The loop was opened"
        todo = ("Reset, wait for ON (the mirror settles), then CloseLoop" if tripped
                else "CloseLoop when it should run again")
        sentence = (f"{what} while tune watched it: the device is in {state} with the loop "
                    f"open, holding {holds} for its next CloseLoop; {todo}.")
        raise LoopOpenedError(f"{self.label}: the loop is open ({status})", holds=holds,
                              sentence=sentence)

    def stand_down(self) -> str:
        """After tune stopped before it loaded anything: the excitation and the record it
        started stopped (``StopExcitation``, ``Abort``), and what the device runs, in one
        sentence (the loop's state said when it is not closed)."""
        stopped = []
        try:
            if json.loads(str(self._attr("Excitation")) or "{}"):
                self.proxy.StopExcitation()
                stopped.append("its excitation")
            if str(self.proxy.state()) == "MOVING":
                self.proxy.Abort()
                stopped.append("its record")
                self._wait(lambda: str(self.proxy.state()) != "MOVING",
                           "the end of tune's record", 0.0)
        except Exception as exc:  # say what could not be stopped, then what runs
            stopped.append(f"(stopping failed: {device_words(exc)})")
        holds = self.running_controller()
        closed = bool(self._attr("LoopClosed"))
        what = (f"the device still runs {holds}, as before tune" if closed else
                f"the device holds {holds} with the loop open (state "
                f"{self.proxy.state()}: {' '.join(str(self.proxy.status()).split())})")
        return (f"Nothing was loaded: {what}"
                + (f"; tune stopped {' and '.join(stopped)}." if stopped else "."))

    def running_controller(self) -> str:
        """The device's ``Controller``."""
        return str(self._attr("Controller"))

    def checkpoint(self, loop: Controller) -> dict[str, Any]:
        """``loop``, running now: the device's name for it and how :meth:`roll_back` asks
        ``LoadController`` for it again."""
        return {"name": loop.name, "device": self.label, "noun": "The device",
                "checked": "the device runs it: its LoadController checked it on the device's "
                           "bench when it was loaded (or it is the ESRF study's seed)",
                "restore_with": list(self.restore_requests)}

    def roll_back(self, loop: Controller, *, force: bool = False) -> dict[str, Any]:
        """Return the device to ``loop``, the controller it ran when tune started (module notes).

        Returns
        -------
        dict
            The switch: from, to, the ``LoadController`` argument that did it (``request``),
            the device's reply.

        Raises
        ------
        ValueError
            No argument brought ``loop`` back (each refusal named).
        """
        before = self.running_controller()
        if before == loop.name and not force:
            return {"from": before, "to": before, "reply": "already running"}
        self.proxy.StopExcitation()
        if str(self.proxy.state()) == "MOVING":
            self.proxy.Abort()
        self._wait(lambda: str(self.proxy.state()) != "MOVING", "the end of tune's record", 0.0)
        tried = []
        for request in self.restore_requests:
            text = request if isinstance(request, str) else json.dumps(request)
            try:
                reply = self.proxy.LoadController(text)
                self._wait(lambda: self._attr("Task") == "", "the controller's load", 0.0)
            except Exception as exc:  # a refusal: the next way back
                tried.append(f"LoadController {text!r}: {device_words(exc)}")
                continue
            now = self.running_controller()
            if now == loop.name:
                self.gd = loop.gd
                return {"from": before, "to": now, "request": text, "reply": reply}
            tried.append(f"LoadController {text!r} loaded {now!r}")
        raise ValueError(f"{self.label}: could not load {loop.name} back: {'; '.join(tried)}")

    def play(self, plays: Sequence[ClosedLoopPlay], *, controller: Controller,
             settle_s: float, seed: int,
             progress: Callable[[str], None] | None) -> TwinRun:
        """Each excitation played through the device with the loop closed (module notes)."""
        fs = self.fs_hz
        recordings: dict[str, Any] = {}
        specs = []
        for play in plays:
            variable = excitation_variable(play.channel, play.at)
            if play.at != "output":
                raise ValueError(f"{self.label} adds an excitation at the controller's output; "
                                 "not at the reference")
            x = np.asarray(play.samples_v, dtype=float)
            npy = self.folder / f"{self._name(play.name)}.npy"
            np.save(npy, x)
            n_settle = round(settle_s * fs)
            late_s = max(_LATE_S, _LATE_WALL_S * float(self._attr("SpeedFactor")))
            duration = 2 * settle_s + late_s + x.size / fs
            if progress is not None:
                progress(f"playing {play.description} on {play.channel} through "
                         f"{self.label} with the loop closed by {controller.name} "
                         f"({duration:g} s recorded)")

            def excite(start_s: float, play: ClosedLoopPlay = play, npy: Path = npy,
                       sha: str = samples_sha256(x)) -> float:
                self._wait(lambda: float(self._attr("BenchTime")) >= start_s + settle_s,
                           "the settling before the excitation", settle_s)
                doc: dict[str, Any] = {"input": play.channel, "kind": "samples",
                                       "path": str(npy)}
                if play.loop_from is not None:
                    doc["loop_from"] = int(play.loop_from)
                self.proxy.StartExcitation(json.dumps(doc))
                return self._started(sha, start_s)

            for attempt in range(1, _ATTEMPTS + 1):
                rec, e_start_s = self._record(CLOSED_LOOP_SIGNALS, duration, during=excite)
                self.proxy.StopExcitation()
                r0 = round(float(rec["t"].values[0]) * fs)
                first = round(e_start_s * fs) - r0  # the excitation's first sample in it
                lo, hi = first - n_settle, first + x.size
                if lo >= 0 and hi <= rec.sizes["t"]:
                    break
                why = (f"{self.label}: the excitation on {play.channel} started "
                       f"{first / fs:.2f} s into its {rec.sizes['t'] / fs:g} s record, not "
                       f"within the {settle_s:g} to {settle_s + late_s:g} s it needs (a slow "
                       "client)")
                if attempt == _ATTEMPTS:
                    raise ValueError(f"{why}, {_ATTEMPTS} times")
                if progress is not None:
                    progress(f"{why}: played again")
            signals = {s: np.asarray(rec[s].values, dtype=float)[lo:hi]
                       for s in CLOSED_LOOP_SIGNALS}
            signals[variable] = np.concatenate([np.zeros(n_settle), x])
            recordings[play.name] = make_recording(
                signals, fs_hz=fs, experiment=play.name,
                source=f"fsmbench tune through {self.label} (loop closed)")
            ex = SampledExcitation(play.channel, "samples", float(np.sqrt(np.mean(x**2))),
                                   settle_s, samples_v=x, loop_from=play.loop_from)
            specs.append(ExperimentSpec(
                name=play.name, description=f"{play.description} on {play.channel} "
                f"(controller output, from {settle_s:g} s), loop closed by {controller.name}, "
                f"through {self.label}", seed_section="closed loop",
                duration_s=(hi - lo) / fs, excitations=(ex,), closed_loop=True,
                compensation_unit=True, shielding=True))
        truth = {"source": self.label, "closed_loop": {
            "controller": controller.name, "settle_s": settle_s,
            "samples_sha256": {p.name: samples_sha256(np.asarray(p.samples_v, dtype=float))
                               for p in plays}}}
        return TwinRun(recordings=recordings, truth=truth, seed=seed, experiments=tuple(specs))
