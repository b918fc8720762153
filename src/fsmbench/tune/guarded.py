"""``tune``: one guarded step from a running bench to a better controller, the loop closed.

On the twin (:func:`tune_twin`), every step logged:

1. **before**: the running controller's tracking error is *measured* on the bench
   as it runs (the 4QD reading over its gain, mean removed, both axes, while the
   Newport plays the ESRF study's repeatability motion, a 1 Hz sine of 1 V on
   both axes: the disturbance the 6.1 objective is about);
2. **identify** with the loop closed (:func:`fsmbench.tune.measure.measure_closed_loop`):
   the Sercalo's ``Gc`` and delay, the rest of the plant from the bench file;
3. **design** on the identified plant: the same study as ``fsmbench design``
   (:func:`fsmbench.control.study.design_study`), fsmbench's controller the candidate;
4. **verify** on the identified bench: stability, margins (each axis's gain and
   phase margins at least ``min_gain_margin_db`` and ``min_phase_margin_deg``),
   robust stability over the design's perturbed set, ``|S(1 Hz)|``, and the
   predicted tracking error (:func:`fsmbench.twin.verify.predict_tracking`);
5. **compare**: the candidate is loaded only if its predicted tracking error is
   below ``1 - better_by`` of the running controller's *measured* one on every axis;
6. **load** bumplessly (:meth:`fsmbench.sim.stream.BenchStream.set_controller`: the
   new controller's state set so that its first command is the last one) and
   **watch** for ``watch_s``: if the measured tracking error exceeds the prediction
   by more than ``rollback_tolerance`` on an axis, the running controller is
   loaded back (bumplessly) and watched again. Step 6 is a transaction
   (:func:`fsmbench.tune.transaction.load_and_watch`): the measurement and the
   decision are handed to ``journal`` before anything is loaded, the outcome after the
   watch; an interruption or error once the load has started (Ctrl-C, a lost
   connection, a crash) rolls back to the running controller through the target's own
   means (:meth:`TuneTarget.roll_back`) and says which controller the bench is left on.

The decision is ``loaded``, ``refused``, ``rolled_back`` or ``interrupted``, with its
reason (``loading`` in the record written before the load).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

import control as ct
import numpy as np
from scipy import signal

from fsmbench import __version__
from fsmbench.bench.axes import PerAxis
from fsmbench.bench.blocks import PlantModel
from fsmbench.bench.params import Bench
from fsmbench.jsonutil import plain_json
from fsmbench.sim.controller import feedback_controller
from fsmbench.sim.engine import DiscreteController
from fsmbench.sim.loaded import RunningController
from fsmbench.sim.stream import BenchStream
from fsmbench.tune.measure import ClosedLoopMeasurement, MeasurementOptions, measure_closed_loop
from fsmbench.twin.closed_loop import ClosedLoopPlay, drifted_bench
from fsmbench.twin.experiments import REP_AMPLITUDE_V
from fsmbench.twin.simulate import TwinRun

__all__ = ["MAX_MODE_MOVE", "TUNE_FORMAT", "ControllerFigures", "Loop", "TuneOptions",
           "TuneResult", "TuneTarget", "implausible_modes", "loop_of", "not_plausible",
           "tune_guarded", "tune_twin"]

#: A resonance further than this from the model's is not a drift a tune follows (the drift
#: scenarios move it by a few %): a mode assigned to the wrong axis, or another bench.
MAX_MODE_MOVE = 0.15

#: ``tune.json``'s format and version.
TUNE_FORMAT = ("fsmbench.tune", 1)
AXES = ("h", "v")
# Welch segments of the tracking-error ASDs [s]: 0.5 Hz resolution, 1 Hz line resolved.
_ASD_SEGMENT_S = 2.0


@dataclass(frozen=True)
class TuneOptions:
    """The guards of :func:`tune_twin`.

    Attributes
    ----------
    better_by : float
        The candidate's predicted tracking error must be below ``1 - better_by``
        of the running controller's measured one, every axis [1].
    watch_s : float
        Measurement time of the running controller, and of the loaded one [s].
    settle_s : float
        Left out at the start of each watch (the loop's transient) [s].
    rollback_tolerance : float
        The loaded controller is rolled back when its measured tracking error
        exceeds ``(1 + rollback_tolerance)`` times the prediction on an axis [1].
    min_gain_margin_db, min_phase_margin_deg : float
        Least margins of each axis on the identified bench (the design's own
        requirements, :class:`fsmbench.control.design.DesignOptions`: 6 dB, 30°).
    disturbance_v : float
        Amplitude of the Newport's 1 Hz sine on both axes during the watches [V].
    measurement : MeasurementOptions
    """

    better_by: float = 0.10
    watch_s: float = 10.0
    settle_s: float = 2.0
    rollback_tolerance: float = 0.25
    min_gain_margin_db: float = 6.0
    min_phase_margin_deg: float = 30.0
    disturbance_v: float = REP_AMPLITUDE_V
    measurement: MeasurementOptions = field(default_factory=MeasurementOptions)

    def __post_init__(self) -> None:
        if not 0.0 <= self.better_by < 1.0:
            raise ValueError(f"the margin a candidate must be better by is in [0, 1), got "
                             f"{self.better_by!r}")
        if not self.watch_s > self.settle_s >= 0.0:
            raise ValueError(f"the watch ({self.watch_s!r} s) must be longer than its settling "
                             f"time ({self.settle_s!r} s)")

    def to_json(self) -> dict[str, Any]:
        """Plain values."""
        return {"better_by": self.better_by, "watch_s": self.watch_s,
                "settle_s": self.settle_s, "rollback_tolerance": self.rollback_tolerance,
                "min_gain_margin_db": self.min_gain_margin_db,
                "min_phase_margin_deg": self.min_phase_margin_deg,
                "disturbance_v": self.disturbance_v,
                "measurement": self.measurement.to_json()}


@dataclass(frozen=True, eq=False)
class Loop:
    """A controller as designed (continuous ``K``) and as the bench runs it.

    Attributes
    ----------
    name : str
        In words.
    k : control.StateSpace
        Continuous ``Rh, Rv → Uch, Ucv`` (the loop is ``u = -K y``).
    feedback : DiscreteController
        Tustin at the converter rate, dividing the 4QD readings by ``gd_v_per_rad``.
    gd_v_per_rad : (float, float)
    """

    name: str
    k: ct.StateSpace
    feedback: DiscreteController
    gd_v_per_rad: tuple[float, float]


def loop_of(k: ct.StateSpace, *, name: str, ts_s: float,
            gd_v_per_rad: tuple[float, float]) -> Loop:
    """``k`` wired as the real-time code runs it (Tustin, readings divided by the 4QD gains)."""
    fb = feedback_controller(k, gd_v_per_rad=PerAxis(h=gd_v_per_rad[0], v=gd_v_per_rad[1]),
                             ts_s=ts_s, name=name)
    return Loop(name=name, k=k, feedback=fb,
                gd_v_per_rad=(float(gd_v_per_rad[0]), float(gd_v_per_rad[1])))


@dataclass(frozen=True)
class ControllerFigures:
    """One controller on the identified bench, and on the running bench when measured.

    Attributes
    ----------
    name : str
    sensitivity_at_1hz : dict axis -> float
        ``|S(j 2 pi f0)|`` of each axis's loop [1].
    gain_margin_db, phase_margin_deg, modulus_margin : dict axis -> float
    stable : bool
    robust_stable : bool or None
        Stable over the design's perturbed set (None: not checked).
    predicted_rms_rad : dict axis -> float
        Predicted tracking-error rms with the Newport's 1 Hz sine [rad].
    measured_rms_rad : dict axis -> float or None
        Measured on the running bench [rad] (None: never ran).
    """

    name: str
    sensitivity_at_1hz: dict[str, float]
    gain_margin_db: dict[str, float]
    phase_margin_deg: dict[str, float]
    modulus_margin: dict[str, float]
    stable: bool
    robust_stable: bool | None
    predicted_rms_rad: dict[str, float]
    measured_rms_rad: dict[str, float] | None = None

    def to_json(self) -> dict[str, Any]:
        """Plain values."""
        return plain_json(dict(self.__dict__))


@dataclass(frozen=True, eq=False)
class TuneResult:
    """What :func:`tune_twin` did and why.

    Attributes
    ----------
    decision : {"loaded", "refused", "rolled_back", "interrupted", "loading"}
        ``loading``: the record written before the load (the candidate, why, and the
        controller running before); ``interrupted``: the load or its watch was cut short
        and the bench rolled back (``transaction`` says to which controller).
    reason : str
        In words, with the numbers.
    before : ControllerFigures
        The running controller (measured before, predicted on the identified bench).
    candidate : ControllerFigures
        The new controller (measured only if it was loaded).
    after : ControllerFigures
        What runs at the end (the candidate, or the running one measured again
        after a roll-back, or the running one unchanged when refused).
    objective_bound : float
        The 6.1 bound on ``|S(1 Hz)|`` [1].
    drift_pct : float
        The resonance drift the twin ran with [%].
    measurement : ClosedLoopMeasurement
    log : tuple of str
        Every step, in order.
    psd_f_hz : ndarray, shape (F,)
    psd_before, psd_after : ndarray, shape (F, 2)
        Tracking-error PSDs [rad²/Hz] measured before and at the end (Welch, 2 s
        Hann segments).
    switches : tuple of dict
        Each controller switch: sample, from, to, command before and after [V].
    options : TuneOptions
    candidate_loop : Loop
        The candidate as designed and wired (to offer it again, or export it).
    target : str
        What was tuned, in words (the twin, or the device's address).
    transaction : dict or None
        Step 6's record (:func:`fsmbench.tune.transaction.load_and_watch`): ``state``
        (decided, done), ``outcome`` (loaded, rolled_back, interrupted; None before the
        load), the candidate, ``why``, ``running_before`` (its name and how the target
        returns to it), ``left_on`` (the controller the bench is left on) and
        ``sentence`` (that, in words); None when nothing was to be loaded.
    """

    decision: str
    reason: str
    before: ControllerFigures
    candidate: ControllerFigures
    after: ControllerFigures
    objective_bound: float
    drift_pct: float
    measurement: ClosedLoopMeasurement
    log: tuple[str, ...]
    psd_f_hz: np.ndarray
    psd_before: np.ndarray
    psd_after: np.ndarray
    switches: tuple[dict[str, Any], ...]
    options: TuneOptions
    candidate_loop: Loop
    target: str = "the digital twin"
    transaction: Mapping[str, Any] | None = None

    def to_json(self) -> dict[str, Any]:
        """``tune.json``'s content (SI units)."""
        name, version = TUNE_FORMAT
        return plain_json({
            "format": name, "format_version": version, "fsmbench_version": __version__,
            "target": self.target, "decision": self.decision, "reason": self.reason,
            "objective_sensitivity_bound_at_1hz": self.objective_bound,
            "drift_resonance_pct": self.drift_pct,
            "before": self.before.to_json(), "candidate": self.candidate.to_json(),
            "after": self.after.to_json(),
            "measurement": self.measurement.to_json(),
            "identified": self.measurement.identification.to_json().get("sercalo"),
            "switches": list(self.switches), "log": list(self.log),
            "options": self.options.to_json(),
            **({} if self.transaction is None else {"transaction": dict(self.transaction)})})


def _figures(loop: Loop, *, plant: PlantModel, bench: Bench, objective: Any,
             robust: bool | None, watch_s: float, disturbance_v: float) -> ControllerFigures:
    from fsmbench.control.loops import analyse_loop
    from fsmbench.twin.verify import predict_tracking

    la = analyse_loop(plant, loop.k, objective=objective, name=loop.name)
    predicted, parts = predict_tracking(plant, loop.k, bench=bench,
                                        gd_used_v_per_rad=loop.gd_v_per_rad,
                                        f_min_hz=1.0 / watch_s)
    # predict_tracking plays the Newport's sine at the ESRF study's 1 V: scaled to what the
    # target plays (none on the live device, which measures what runs).
    for a in AXES:
        sine = parts[a]["newport_sine"]
        predicted[a] = math.sqrt(max(predicted[a] ** 2 - sine**2, 0.0)
                                 + (sine * disturbance_v / REP_AMPLITUDE_V) ** 2)
    axes = dict(zip(AXES, la.axes.values(), strict=True))
    return ControllerFigures(
        name=loop.name,
        sensitivity_at_1hz={a: float(ax.sensitivity_at_f0) for a, ax in axes.items()},
        gain_margin_db={a: float(ax.margins.gain_margin_db) for a, ax in axes.items()},
        phase_margin_deg={a: float(ax.margins.phase_margin_deg) for a, ax in axes.items()},
        modulus_margin={a: float(ax.margins.modulus_margin) for a, ax in axes.items()},
        stable=bool(la.stable and la.nyquist.stable), robust_stable=robust,
        predicted_rms_rad={a: float(predicted[a]) for a in AXES})


class TuneTarget(Protocol):
    """A running bench :func:`tune_guarded` acts on: the twin or the live device.

    Attributes
    ----------
    label : str
        What it is, in words.
    fs_hz : float
    drift_pct : float
        The twin's resonance drift from the bench file [%] (0 on a device: unknown).
    """

    label: str
    fs_hz: float
    drift_pct: float

    def run(self, duration_s: float, *, settle_s: float) -> np.ndarray:
        """The running loop's tracking error after ``settle_s`` of ``duration_s`` [rad],
        (n, 2), mean removed."""

    def load(self, loop: Loop) -> dict[str, Any]:
        """Load ``loop`` bumplessly in the running loop; the switch, JSON-ready."""

    def roll_back(self, loop: Loop, *, force: bool = False) -> dict[str, Any]:
        """Return to ``loop``, the controller that ran when tune started, by the means that
        put it there (the device: its own ``LoadController``); the switch, JSON-ready.
        ``force``: load it even when the target reads it as running already."""

    def running_controller(self) -> str:
        """The name of the controller the bench runs now."""

    def checkpoint(self, loop: Loop) -> dict[str, Any]:
        """``loop`` (running now) as the record names it: its name, what checked it and how
        :meth:`roll_back` returns to it, JSON-ready."""

    def play(self, plays: Sequence[ClosedLoopPlay], *, controller: RunningController,
             settle_s: float, seed: int,
             progress: Callable[[str], None] | None) -> TwinRun:
        """Play each excitation with the loop closed; the records (data_cl_* layout)."""


def _rms(e: np.ndarray) -> dict[str, float]:
    return {a: float(np.sqrt(np.mean(e[:, i] ** 2))) for i, a in enumerate(AXES)}


def _asd(e: np.ndarray, fs_hz: float) -> tuple[np.ndarray, np.ndarray]:
    """Welch PSD per axis [rad²/Hz]."""
    f, p = signal.welch(e, fs=fs_hz, nperseg=min(e.shape[0], round(_ASD_SEGMENT_S * fs_hz)),
                        axis=0)
    return f, p


def _urad(d: Mapping[str, float]) -> str:
    return ", ".join(f"{a} {1e6 * v:.3g} µrad" for a, v in d.items())


def tune_twin(*, bench: Bench, running: Loop, drift_pct: float = 0.0,
              options: TuneOptions | None = None, seed: int = 0,
              candidate: Loop | None = None,
              after_load: Callable[[BenchStream], str] | None = None,
              progress: Callable[[str], None] | None = None) -> TuneResult:
    """One guarded tuning step on the twin (see the module notes).

    Parameters
    ----------
    bench : Bench
        The bench file: the model the measurement is designed on, the noise the
        predictions use, the blocks a closed-loop measurement does not see.
    running : Loop
        The controller running when ``tune`` starts.
    drift_pct : float
        The twin's Sercalo resonance moved by this much from the bench file [%].
    options : TuneOptions, optional
    seed : int
    candidate : Loop, optional
        Offer this controller instead of designing one (its ``k`` is verified the same way).
    after_load : callable, optional
        Changes the running twin when the candidate is loaded (a plant that moves, a new
        vibration line: what the watch is for), e.g.
        ``lambda s: s.set_plant(...)`` or ``s.add_excitation(...)``; returns the change in
        words, logged.

    Raises
    ------
    ValueError
        The running controller does not stabilise the twin, or the Sercalo cannot be
        identified in closed loop (named).
    """
    from fsmbench.tune.targets import TwinTarget

    opts = options or TuneOptions()
    target = TwinTarget(drifted_bench(bench, resonance_pct=drift_pct), running, seed=seed,
                        amplitude_v=opts.disturbance_v, drift_pct=drift_pct)
    hook = None if after_load is None else (lambda _t: after_load(target.stream))
    return tune_guarded(target=target, bench=bench, running=running, options=opts, seed=seed,
                        candidate=candidate, after_load=hook, progress=progress)


def implausible_modes(sercalo: Mapping[str, Mapping[str, Any]], *, bench: Bench) -> str:
    """Why the identified Sercalo modes cannot be the bench's, in words ("" when they can).

    Parameters
    ----------
    sercalo : mapping axis -> {"resonance_hz", ...}
        The closed-loop identification's modes (``identification.json``'s ``sercalo``).
    bench : Bench
        The model the running controller runs on; its ``nominal`` resonances [Hz].

    A closed-loop fit whose notch starves an axis's resonance can place that axis's mode
    on the other axis's (twin: h at 244 Hz against 411.5 Hz): a controller designed on
    it would be verified on the same wrong plant, so the guard is the model's resonances.
    """
    words = []
    for axis, values in sercalo.items():
        expected = float(bench.nominal.sercalo.resonance_hz[axis])
        found = float(values.get("resonance_hz", math.nan))
        if not (math.isfinite(found) and abs(found / expected - 1.0) <= MAX_MODE_MOVE):
            words.append(f"the {axis} resonance at {found:.1f} Hz is "
                         f"{100 * (found / expected - 1.0):+.0f} % from the model's "
                         f"{expected:.1f} Hz (more than the {100 * MAX_MODE_MOVE:.0f} % a "
                         "drift moves it; likely a mode assigned to the wrong axis)")
    return "; ".join(words)


def not_plausible(measurement: ClosedLoopMeasurement, *, bench: Bench) -> str:
    """Why a closed-loop measurement cannot be designed on, in words ('' when it can)."""
    ident = measurement.identification
    if ident.plant is None:
        return (f"the Sercalo could not be identified in closed loop: "
                f"{ident.skipped.get('sercalo', 'no plant')}")
    why = implausible_modes(ident.to_json().get("sercalo", {}), bench=bench)
    return f"the Sercalo's closed-loop identification is not plausible: {why}" if why else ""


def tune_guarded(*, target: TuneTarget, bench: Bench, running: Loop,
                 options: TuneOptions | None = None, seed: int = 0,
                 candidate: Loop | None = None,
                 after_load: Callable[[TuneTarget], str] | None = None,
                 progress: Callable[[str], None] | None = None,
                 journal: Callable[[TuneResult], None] | None = None) -> TuneResult:
    """One guarded tuning step on ``target``, the twin or the live device (module notes).

    Parameters
    ----------
    target : TuneTarget
        The running bench: :class:`fsmbench.tune.targets.TwinTarget` or
        :class:`fsmbench.tune.device.DeviceTarget`.
    bench : Bench
        The bench file (see :func:`tune_twin`).
    running : Loop
        The controller running on ``target`` when ``tune`` starts.
    options : TuneOptions, optional
        Its ``disturbance_v`` must be what ``target`` plays during the watches.
    seed : int
        Noise seed of the twin's closed-loop measurement.
    candidate : Loop, optional
    after_load : callable, optional
        ``after_load(target)`` when the candidate is loaded; returns the change in words.
    journal : callable, optional
        ``journal(result)`` with the record of the decision before the candidate is loaded
        (decision ``loading``), with the outcome after the watch, and with ``interrupted``
        after an interruption's roll-back (:func:`fsmbench.tune.transaction.load_and_watch`);
        ``tune --device`` writes each as ``tune.json``.

    Raises
    ------
    ValueError
        The Sercalo cannot be identified in closed loop, or the target refuses (named).
    fsmbench.tune.transaction.LoopChangeError
        An error once the load had started (a lost connection, an attribute that stayed
        INVALID): rolled back first, the controller the bench is left on in the message.
    KeyboardInterrupt
        Ctrl-C once the load had started, raised again after the roll-back.
    """
    from fsmbench.control.analysis import control_objective
    from fsmbench.control.design import robustness
    from fsmbench.control.study import design_study
    from fsmbench.tune.transaction import load_and_watch

    opts = options or TuneOptions()
    log: list[str] = []

    def say(msg: str) -> None:
        log.append(msg)
        if progress is not None:
            progress(msg)

    objective = control_objective(bench.nominal)
    ts = bench.true.converter.ts_s
    watch = target
    drift_pct = target.drift_pct
    say(f"watching {running.name} for {opts.watch_s:g} s on {target.label}")
    e_before = watch.run(opts.watch_s, settle_s=opts.settle_s)
    measured_before = _rms(e_before)
    say(f"measured tracking error of {running.name}: {_urad(measured_before)} rms")

    rc = RunningController(feedback=running.feedback, a=np.zeros((0, 0)), b=np.zeros((0, 2)),
                           c=np.zeros((2, 0)), d=np.zeros((2, 2)), ts_s=ts,
                           gd_v_per_rad=running.gd_v_per_rad, name=running.name,
                           source=running.name)
    measurement = measure_closed_loop(play=target.play, model=bench, controller=rc,
                                      options=opts.measurement, seed=seed + 100,
                                      progress=say)
    if (first_why := not_plausible(measurement, bench=bench)):
        # A measurement the records do not carry (too little excitation at a resonance on
        # one run: its fit keeps a mode on the wrong axis) is made once again with new noise
        # before tune gives up, as a user would. Its usual cause, an isolated noisy line
        # taken for the h peak, is gone from the resonance search (detect_resonances).
        say(f"{first_why}: measured once again")
        measurement = measure_closed_loop(play=target.play, model=bench, controller=rc,
                                          options=opts.measurement, seed=seed + 300,
                                          progress=say)
    ident = measurement.identification
    if ident.plant is None:
        raise ValueError(f"the Sercalo could not be identified in closed loop: "
                         f"{ident.skipped.get('sercalo', 'no plant')}")
    sercalo = ident.to_json().get("sercalo", {})
    say("identified in closed loop: " + "; ".join(
        f"{a}: resonance {v['resonance_hz']:.2f} Hz, damping {v['damping_ratio']:.2e}"
        for a, v in sercalo.items())
        + f" ({measurement.duration_s:g} s of measurement, beam error added "
          f"{_urad(measurement.tracking_added_rad())} rms)")
    if (why := implausible_modes(sercalo, bench=bench)):
        raise ValueError(f"the Sercalo's closed-loop identification is not plausible: {why}; "
                         "nothing was loaded. Run tune again with more --periods, or "
                         "identify the bench in open loop")
    plant = ident.plant
    if candidate is None:
        say("designing on the identified plant (the same study as fsmbench design)")
        study = design_study(plant, bench=bench)
        gd = tuple(float(x) for x in np.diag(np.asarray(plant.blocks["Gd"].D, dtype=float)))
        candidate = loop_of(study.controllers["fsmbench_controller"],
                            name="fsmbench's controller (designed on the closed-loop "
                                 "identification)", ts_s=ts, gd_v_per_rad=(gd[0], gd[1]))
        robust = bool(study.robustness.all_stable)
    else:
        robust = bool(robustness(plant, candidate.k, objective=objective).all_stable)
    before = _figures(running, plant=plant, bench=bench, objective=objective, robust=None,
                      watch_s=opts.watch_s, disturbance_v=opts.disturbance_v)
    before = _replace(before, measured_rms_rad=measured_before)
    cand = _figures(candidate, plant=plant, bench=bench, objective=objective, robust=robust,
                    watch_s=opts.watch_s, disturbance_v=opts.disturbance_v)
    say(f"verified {candidate.name} on the identified bench: |S(1 Hz)| "
        + ", ".join(f"{a} {v:.3g}" for a, v in cand.sensitivity_at_1hz.items())
        + f"; predicted tracking error {_urad(cand.predicted_rms_rad)} rms")
    refusal = _refusal(cand, measured_before, opts)
    f_asd, asd_before = _asd(e_before, watch.fs_hz)
    if refusal:
        say(f"refused: {refusal}")
        return TuneResult(target=target.label, decision="refused", reason=refusal,
                          before=before, candidate=cand,
                          after=before, objective_bound=objective.sensitivity_bound,
                          drift_pct=drift_pct, measurement=measurement, log=tuple(log),
                          psd_f_hz=f_asd, psd_before=asd_before, psd_after=asd_before,
                          switches=(), options=opts, candidate_loop=candidate)
    why = (f"{candidate.name} predicted {_urad(cand.predicted_rms_rad)} rms against "
           f"{_urad(measured_before)} measured with {running.name} (better by more than "
           f"{100 * opts.better_by:g} % on both axes), margins and robust stability met")

    def make(decision: str, reason: str, *, candidate_figures: ControllerFigures,
             after: ControllerFigures, switches: Sequence[Mapping[str, Any]],
             transaction: Mapping[str, Any], e_after: np.ndarray | None = None) -> TuneResult:
        f, asd_after = (f_asd, asd_before) if e_after is None else _asd(e_after, watch.fs_hz)
        return TuneResult(target=target.label, decision=decision, reason=reason,
                          before=before, candidate=candidate_figures, after=after,
                          objective_bound=objective.sensitivity_bound,
                          drift_pct=drift_pct, measurement=measurement, log=tuple(log),
                          psd_f_hz=f, psd_before=asd_before, psd_after=asd_after,
                          switches=tuple(dict(s) for s in switches), options=opts,
                          candidate_loop=candidate, transaction=dict(transaction))

    return load_and_watch(target=target, running=running, candidate=candidate, before=before,
                          candidate_figures=cand, options=opts, why=why, make=make,
                          journal=journal, say=say, after_load=after_load)


def _replace(fig: ControllerFigures, **changes: Any) -> ControllerFigures:
    import dataclasses

    return dataclasses.replace(fig, **changes)


def _refusal(cand: ControllerFigures, measured_before: Mapping[str, float],
             opts: TuneOptions) -> str:
    """Why the candidate is not loaded, in words ('' when it may be)."""
    if not cand.stable:
        return f"{cand.name} does not stabilise the identified bench"
    if cand.robust_stable is False:
        return f"{cand.name} does not stabilise every bench of the design's perturbed set"
    for a in AXES:
        gm, pm = cand.gain_margin_db[a], cand.phase_margin_deg[a]
        if not (gm >= opts.min_gain_margin_db and pm >= opts.min_phase_margin_deg):
            return (f"{cand.name}'s margins on axis {a} ({gm:.3g} dB, {pm:.3g}°) are below "
                    f"{opts.min_gain_margin_db:g} dB and {opts.min_phase_margin_deg:g}°")
    short = [a for a in AXES if not cand.predicted_rms_rad[a]
             <= (1.0 - opts.better_by) * measured_before[a]]
    if short:
        return ("its predicted tracking error is not better than the running controller's "
                f"measured one by {100 * opts.better_by:g} % on " + ", ".join(
                    f"{a} ({1e6 * cand.predicted_rms_rad[a]:.3g} µrad predicted, "
                    f"{1e6 * measured_before[a]:.3g} µrad measured)" for a in short))
    if any(not math.isfinite(v) for v in cand.sensitivity_at_1hz.values()):
        return f"{cand.name}'s sensitivity at 1 Hz could not be evaluated"
    return ""
