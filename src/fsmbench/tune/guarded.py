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

import functools
import math
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np
from scipy import signal

from fsmbench.bench.blocks import PlantModel
from fsmbench.bench.params import Bench
from fsmbench.control.analysis import control_objective
from fsmbench.control.controller import Controller, controller_of
from fsmbench.control.design import robustness
from fsmbench.control.loops import analyse_loop
from fsmbench.control.study import design_study
from fsmbench.sim.stream import BenchStream
from fsmbench.tune.measure import ClosedLoopMeasurement, measure_closed_loop
from fsmbench.tune.targets import TwinTarget
from fsmbench.tune.transaction import load_and_watch
from fsmbench.tune.values import (
    AXES,
    MAX_MODE_MOVE,
    TUNE_FORMAT,
    ControllerFigures,
    TuneOptions,
    TuneResult,
    TuneTarget,
    rms_by_axis,
    urad_text,
    with_changes,
)
from fsmbench.twin.closed_loop import drifted_bench
from fsmbench.twin.experiments import REP_AMPLITUDE_V
from fsmbench.twin.verify import predict_tracking

__all__ = [
    "MAX_MODE_MOVE",
    "TUNE_FORMAT",
    "ControllerFigures",
    "TuneOptions",
    "TuneResult",
    "TuneTarget",
    "implausible_modes",
    "not_plausible",
    "refusal_reason",
    "tune_guarded",
    "tune_twin",
]
# The values (tune.values) are re-exported: the procedure's module is where users look.

def _figures(loop: Controller, *, plant: PlantModel, bench: Bench, objective: Any,
             robust: bool | None, watch_s: float, disturbance_v: float) -> ControllerFigures:
    la = analyse_loop(plant, loop.continuous, objective=objective, name=loop.name)
    predicted, parts = predict_tracking(plant, loop.continuous, bench=bench,
                                        gd_used_v_per_rad=loop.gd,
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


# Welch segments of the tracking-error ASDs [s]: 0.5 Hz resolution, 1 Hz line resolved.
_ASD_SEGMENT_S = 2.0


def _asd(e: np.ndarray, fs_hz: float) -> tuple[np.ndarray, np.ndarray]:
    """Welch PSD per axis [rad²/Hz]."""
    f, p = signal.welch(e, fs=fs_hz, nperseg=min(e.shape[0], round(_ASD_SEGMENT_S * fs_hz)),
                        axis=0)
    return f, p


def tune_twin(*, bench: Bench, running: Controller, drift_pct: float = 0.0,
              options: TuneOptions | None = None, seed: int = 0,
              candidate: Controller | None = None,
              after_load: Callable[[BenchStream], str] | None = None,
              progress: Callable[[str], None] | None = None) -> TuneResult:
    """One guarded tuning step on the twin (see the module notes).

    Parameters
    ----------
    bench : Bench
        The bench file: the model the measurement is designed on, the noise the
        predictions use, the blocks a closed-loop measurement does not see.
    running : Controller
        The controller running when ``tune`` starts.
    drift_pct : float
        The twin's Sercalo resonance moved by this much from the bench file [%].
    options : TuneOptions, optional
    seed : int
    candidate : Controller, optional
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


def _measure(target: TuneTarget, *, bench: Bench, running: Controller, options: TuneOptions,
             seed: int, say: Callable[[str], None]) -> ClosedLoopMeasurement:
    """The closed-loop identification of ``target`` around ``running``: measured again once
    when the records do not carry it; refused when the Sercalo is not identified or its
    modes are not plausible (nothing loaded)."""
    measurement = measure_closed_loop(play=target.play, model=bench, controller=running,
                                      options=options.measurement, seed=seed + 100,
                                      progress=say)
    if (first_why := not_plausible(measurement, bench=bench)):
        # A measurement the records do not carry (too little excitation at a resonance on
        # one run: its fit keeps a mode on the wrong axis) is made once again with new noise
        # before tune gives up, as a user would. Its usual cause, an isolated noisy line
        # taken for the h peak, is gone from the resonance search (detect_resonances).
        say(f"{first_why}: measured once again")
        measurement = measure_closed_loop(play=target.play, model=bench, controller=running,
                                          options=options.measurement, seed=seed + 300,
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
          f"{urad_text(measurement.tracking_added_rad())} rms)")
    if (why := implausible_modes(sercalo, bench=bench)):
        raise ValueError(f"the Sercalo's closed-loop identification is not plausible: {why}; "
                         "nothing was loaded. Run tune again with more --periods, or "
                         "identify the bench in open loop")
    return measurement


def _designed(plant: PlantModel, *, bench: Bench,
              say: Callable[[str], None]) -> tuple[Controller, bool]:
    """fsmbench's controller designed on ``plant`` (the same study as ``fsmbench design``),
    and whether it stabilises the design's whole perturbed set."""
    say("designing on the identified plant (the same study as fsmbench design)")
    study = design_study(plant, bench=bench)
    gd = tuple(float(x) for x in np.diag(np.asarray(plant.blocks["Gd"].D, dtype=float)))
    loop = controller_of(study.controllers["fsmbench_controller"],
                         name="fsmbench's controller (designed on the closed-loop "
                         "identification)", ts_s=bench.true.converter.ts_s,
                         gd_v_per_rad=(gd[0], gd[1]))
    return loop, bool(study.robustness.all_stable)


def _result(decision: str, reason: str, *, target: TuneTarget, before: ControllerFigures,
            candidate: Controller, candidate_figures: ControllerFigures,
            after: ControllerFigures,
            switches: Sequence[Mapping[str, Any]], objective_bound: float,
            measurement: ClosedLoopMeasurement, log: list[str], f_asd: np.ndarray,
            asd_before: np.ndarray, options: TuneOptions,
            transaction: Mapping[str, Any] | None = None,
            e_after: np.ndarray | None = None) -> TuneResult:
    """One record of the step: ``decision`` and ``reason`` with what was measured (the log
    as it stands), the tracking-error spectrum after the load from ``e_after`` if given."""
    f, asd_after = (f_asd, asd_before) if e_after is None else _asd(e_after, target.fs_hz)
    return TuneResult(target=target.label, decision=decision, reason=reason, before=before,
                      candidate=candidate_figures, after=after, objective_bound=objective_bound,
                      drift_pct=target.drift_pct, measurement=measurement, log=tuple(log),
                      psd_f_hz=f, psd_before=asd_before, psd_after=asd_after,
                      switches=tuple(dict(s) for s in switches), options=options,
                      candidate_loop=candidate,
                      transaction=None if transaction is None else dict(transaction))


def _say(msg: str, *, log: list[str], progress: Callable[[str], None] | None) -> None:
    """A step of the log, also given to ``progress``."""
    log.append(msg)
    if progress is not None:
        progress(msg)


def tune_guarded(*, target: TuneTarget, bench: Bench, running: Controller,
                 options: TuneOptions | None = None, seed: int = 0,
                 candidate: Controller | None = None,
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
    running : Controller
        The controller running on ``target`` when ``tune`` starts.
    options : TuneOptions, optional
        Its ``disturbance_v`` must be what ``target`` plays during the watches.
    seed : int
        Noise seed of the twin's closed-loop measurement.
    candidate : Controller, optional
        Default: fsmbench's controller designed on the closed-loop identification.
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
        INVALID), or (KeyboardInterrupt) Ctrl-C: rolled back first, the controller the
        bench is left on in the message; Ctrl-C is raised again after the roll-back.
    """
    opts = options or TuneOptions()
    log: list[str] = []
    say = functools.partial(_say, log=log, progress=progress)
    objective = control_objective(bench.nominal)
    say(f"watching {running.name} for {opts.watch_s:g} s on {target.label}")
    e_before = target.run(opts.watch_s, settle_s=opts.settle_s)
    measured_before = rms_by_axis(e_before)
    say(f"measured tracking error of {running.name}: {urad_text(measured_before)} rms")

    measurement = _measure(target, bench=bench, running=running, options=opts, seed=seed,
                           say=say)
    plant = measurement.identification.plant
    assert plant is not None  # _measure raises without one
    if candidate is None:
        candidate, robust = _designed(plant, bench=bench, say=say)
    else:
        robust = bool(robustness(plant, candidate.continuous, objective=objective).all_stable)
    figures = functools.partial(_figures, plant=plant, bench=bench, objective=objective,
                                watch_s=opts.watch_s, disturbance_v=opts.disturbance_v)
    before = with_changes(figures(running, robust=None), measured_rms_rad=measured_before)
    cand = figures(candidate, robust=robust)
    say(f"verified {candidate.name} on the identified bench: |S(1 Hz)| "
        + ", ".join(f"{a} {v:.3g}" for a, v in cand.sensitivity_at_1hz.items())
        + f"; predicted tracking error {urad_text(cand.predicted_rms_rad)} rms")
    refusal = refusal_reason(cand, measured_before, opts)
    f_asd, asd_before = _asd(e_before, target.fs_hz)
    # Every record of this step (refused, loading, the outcome) shares what was measured.
    make = functools.partial(_result, target=target, before=before, candidate=candidate,
                             objective_bound=objective.sensitivity_bound,
                             measurement=measurement, log=log, f_asd=f_asd,
                             asd_before=asd_before, options=opts)
    if refusal:
        say(f"refused: {refusal}")
        return make("refused", refusal, candidate_figures=cand, after=before, switches=())
    why = (f"{candidate.name} predicted {urad_text(cand.predicted_rms_rad)} rms against "
           f"{urad_text(measured_before)} measured with {running.name} (better by more than "
           f"{100 * opts.better_by:g} % on both axes), margins and robust stability met")
    return load_and_watch(target=target, running=running, candidate=candidate, before=before,
                          candidate_figures=cand, options=opts, why=why, make=make,
                          journal=journal, say=say, after_load=after_load)


def refusal_reason(cand: ControllerFigures, measured_before: Mapping[str, float],
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
