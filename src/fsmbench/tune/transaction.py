"""A loop change as a transaction: step 6 of :func:`fsmbench.tune.guarded.tune_guarded`.

:func:`load_and_watch` changes the running loop in four steps, each one recorded:

1. **decided**: the measurement and the decision (the candidate, why it is to be
   loaded, and the controller running before, with what checked it and how the target
   returns to it) go to ``journal`` *before* anything is loaded (``tune --device``
   writes them as ``tune.json``, atomically);
2. **load** the candidate bumplessly (the device: its own ``LoadController``, which
   checks it on the device's bench on the call);
3. **watch** it for ``watch_s``: a measured tracking error above the prediction by more
   than ``rollback_tolerance`` on an axis rolls back (:meth:`TuneTarget.roll_back
   <fsmbench.tune.guarded.TuneTarget.roll_back>`, the device's ``LoadController`` of
   the controller it ran before), which is watched again;
4. **done**: the outcome (``loaded``, ``rolled_back``) and the controller the bench is
   left on go to ``journal``.

Anything that cuts steps 1-3 short (Ctrl-C, SIGTERM, a lost connection, a refused
command, an attribute that stays INVALID, a bug) rolls back to the controller that ran
before (it passed the device's check: it was running) unless the bench already runs it,
with Ctrl-C held while it does, and records ``interrupted`` with the controller the bench
is left on, in one sentence. A roll-back that fails says so, with the ``LoadController``
argument that returns the device by hand. A ``KeyboardInterrupt`` (or another
``BaseException``) is raised again; an ``Exception`` as :class:`LoopChangeError` carrying
the sentence.
"""

from __future__ import annotations

import contextlib
import json
import signal
import threading
from collections.abc import Callable, Iterator, Mapping
from types import FrameType
from typing import Any

import numpy as np

from fsmbench.control.controller import Controller
from fsmbench.tune.device_errors import device_failure
from fsmbench.tune.values import (
    AXES,
    ControllerFigures,
    TuneOptions,
    TuneResult,
    TuneTarget,
    rms_by_axis,
    urad_text,
    with_changes,
)

__all__ = [
    "OUTCOMES",
    "LoopChangeError",
    "LoopOpenedError",
    "ctrl_c_held",
    "failure_cause",
    "load_and_watch",
]

#: What a loop change ends as (``tune.json``'s ``transaction.outcome``).
OUTCOMES = ("loaded", "rolled_back", "interrupted", "loop_opened")


class LoopOpenedError(ValueError):
    """The loop was opened under tune (a protection trip, or an operator's OpenLoop).

    Nothing is loaded back: the device chose what it holds (after a trip, the last
    controller that ran without tripping) and a closed loop waits for an operator.

    Attributes
    ----------
    holds : str or None
        The controller the device holds for its next CloseLoop.
    sentence : str
        The state it is left in and what to do, in words.
    """

    def __init__(self, message: str, *, holds: str | None, sentence: str) -> None:
        super().__init__(message)
        self.holds = holds
        self.sentence = sentence


class LoopChangeError(ValueError):
    """An error cut the load or its watch short; the bench was rolled back (or the
    roll-back failed), as the message's last sentence says.

    Attributes
    ----------
    sentence : str
        Which controller the bench is left on, in one sentence.
    """

    def __init__(self, message: str, sentence: str) -> None:
        super().__init__(message)
        self.sentence = sentence


#: A function building the tune result from the step's figures (``tune_guarded``'s).
Make = Callable[..., "TuneResult"]


def failure_cause(exc: BaseException) -> str:
    """What cut the change short, in words."""
    if isinstance(exc, KeyboardInterrupt):
        return "interrupted (Ctrl-C)"
    if type(exc).__name__ == "Terminated":
        return "terminated (SIGTERM)"
    failure = device_failure(exc)  # Tango's DevFailed, or a refusal or lost IOC over CA
    if failure is not None:
        return failure.cause()
    text = " ".join(str(exc).split())
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


@contextlib.contextmanager
def ctrl_c_held(say: Callable[[str], None], what: str) -> Iterator[None]:
    """Ctrl-C ignored (with a line saying so) while the bench is rolled back."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def hold(_signum: int, _frame: FrameType | None) -> None:
        say(f"Ctrl-C held: {what} first (SIGTERM or SIGKILL stop tune at once)")

    saved = signal.signal(signal.SIGINT, hold)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, saved)


def _by_hand(point: Mapping[str, Any]) -> str:
    """The ``LoadController`` arguments that return the device to the checkpoint."""
    ways = [w if isinstance(w, str) else json.dumps(w) for w in point.get("restore_with", ())]
    return " or ".join(f"LoadController {w!r}" for w in ways)


def _recover(target: TuneTarget, running: Controller, point: Mapping[str, Any],
             say: Callable[[str], None], *, load_started: bool
             ) -> tuple[str | None, dict[str, Any], str]:
    """Roll back to ``running`` unless the target runs it: (left on, roll-back, sentence).

    Once a load has started, the roll-back is made whatever the target reads: a device
    whose Controller had not caught up with a load it made read the old name, and tune
    once said "left on" a controller the device no longer ran. Loading the controller
    that runs is harmless (bumpless, checked again).
    """
    noun = str(point.get("noun", "The bench"))
    with ctrl_c_held(say, f"the roll-back to {running.name}"):
        try:
            now: str | None = target.running_controller()
        except Exception as exc:  # the device gone: try the roll-back all the same
            now, seen = None, failure_cause(exc)
        else:
            seen = ""
        if now == running.name and not load_started:
            return now, {"needed": False}, (
                f"{noun} is left on {running.name}, the controller it ran before tune "
                "(the candidate is not in the loop).")
        try:
            switch = target.roll_back(running, force=load_started)
        except Exception as exc:
            why = failure_cause(exc)
            try:
                now = target.running_controller()
            except Exception as again:
                now, seen = None, failure_cause(again)
            hand = _by_hand(point)
            seed = "" if "seed" in point.get("restore_with", ()) else \
                " (or LoadController 'seed' for the ESRF study's controller)"
            todo = (f"return it with {hand}{seed}, then read its Controller attribute"
                    if hand else "load it again")
            where = (f"{noun.lower()} is left on {now} (it passed the device's check when "
                     "it was loaded)" if now is not None else
                     f"which controller {noun.lower()} runs is unknown ({seen})")
            return now, {"needed": True, "done": False, "error": why}, (
                f"The roll-back to {running.name} FAILED ({why}): {where}; {todo}.")
        how = (f" by LoadController {switch['request']!r} (checked by the device)"
               if "request" in switch else "")
        return running.name, {"needed": True, "done": True, "switch": switch}, (
            f"{noun} is left on {running.name}, the controller it ran before tune, "
            f"loaded back{how}.")


def _loaded(target: TuneTarget, candidate: Controller, sw: Mapping[str, Any], *,
            after_load: Callable[[TuneTarget], str] | None,
            say: Callable[[str], None]) -> None:
    """Say that ``candidate`` was loaded (the switch ``sw``) and what ``after_load`` did."""
    say(f"loaded {candidate.name} bumplessly ("
        + (f"command {sw['command_before_v'][:2]} V -> {sw['command_after_v'][:2]} V)"
           if "command_before_v" in sw else f"the device: {sw.get('reply', '')})"))
    if after_load is not None:
        say(f"the bench changed as the controller was loaded: {after_load(target)}")


def _judge(target: TuneTarget, *, running: Controller, candidate: Controller,
           before: ControllerFigures, figures: ControllerFigures, e_after: np.ndarray,
           options: TuneOptions, why: str, tx: dict[str, Any],
           switches: list[dict[str, Any]], noun: str, make: Make,
           say: Callable[[str], None]) -> TuneResult:
    """The watch's verdict on the loaded candidate: kept, or the running controller loaded
    back when the measured tracking error exceeds the prediction (``tx`` and ``switches``
    completed in place)."""
    measured_after = figures.measured_rms_rad or {}
    worse = [a for a in AXES if not measured_after[a]
             <= (1.0 + options.rollback_tolerance) * figures.predicted_rms_rad[a]]
    if worse:
        reason = ("the measured tracking error exceeds the prediction by more than "
                  f"{100 * options.rollback_tolerance:g} % on " + ", ".join(
                      f"{a} ({1e6 * measured_after[a]:.3g} µrad measured, "
                      f"{1e6 * figures.predicted_rms_rad[a]:.3g} µrad predicted)"
                      for a in worse) + f": {running.name} loaded back")
        switches.append(target.roll_back(running))
        e_back = target.run(options.watch_s, settle_s=options.settle_s)
        say(f"rolled back: {reason}; measured again {urad_text(rms_by_axis(e_back))} rms")
        tx.update(state="done", outcome="rolled_back", left_on=running.name,
                  sentence=f"{noun} is left on {running.name}, the controller it ran "
                           "before tune (rolled back).")
        return make("rolled_back", reason, candidate_figures=figures,
                    after=with_changes(before, measured_rms_rad=rms_by_axis(e_back)),
                    switches=switches, transaction=tx, e_after=e_back)
    reason = (f"{why}; measured {urad_text(measured_after)} after loading, within "
              f"{100 * options.rollback_tolerance:g} % of the prediction")
    say(f"kept: {reason}")
    named = str(switches[0].get("to") or candidate.name)  # the target's name for it
    tx.update(state="done", outcome="loaded", left_on=named,
              sentence=f"{noun} is left on {named}"
                       + ("" if named == candidate.name else f" ({candidate.name})")
                       + f", loaded and watched for {options.watch_s:g} s.")
    return make("loaded", reason, candidate_figures=figures, after=figures,
                switches=switches, transaction=tx, e_after=e_after)


def _record_interruption(exc: BaseException, target: TuneTarget, *, running: Controller,
                         candidate: Controller, point: Mapping[str, Any], before: ControllerFigures,
                         figures: ControllerFigures, tx: dict[str, Any],
                         switches: list[dict[str, Any]],
                         journal: Callable[[TuneResult], None] | None, make: Make,
                         say: Callable[[str], None]) -> str:
    """After ``exc`` cut the change short: the bench returned to ``running`` (unless a trip
    opened the loop), ``tx`` completed and journalled; the message to raise with."""
    cause = failure_cause(exc)
    when = (f"after the load of {candidate.name} had started" if tx["load_started"] else
            f"before {candidate.name} was loaded")
    rollback: dict[str, Any]
    if isinstance(exc, LoopOpenedError):
        # A trip (or an OpenLoop) already took the candidate out; a LoadController now
        # would be refused in FAULT, and closing the loop is the operator's call.
        say(f"{cause} {when}")
        left, rollback, sentence = exc.holds, {"needed": False, "loop": "open"}, exc.sentence
    else:
        say(f"{cause} {when}: returning to {running.name}")
        left, rollback, sentence = _recover(target, running, point, say,
                                            load_started=bool(tx["load_started"]))
    if rollback.get("done"):
        switches.append(rollback["switch"])
    tx.update(state="done", cause=cause, left_on=left, rollback=rollback, sentence=sentence,
              outcome="loop_opened" if isinstance(exc, LoopOpenedError) else "interrupted")
    say(sentence)
    reason = f"{cause} {when}; {sentence}"
    after = before if left == running.name else figures
    try:
        if journal is not None:
            journal(make("interrupted", reason, candidate_figures=figures, after=after,
                         switches=switches, transaction=tx))
    except Exception as again:
        say(f"the record of the interruption could not be written: {failure_cause(again)}")
    return f"{cause}; {sentence}"


def load_and_watch(*, target: TuneTarget, running: Controller, candidate: Controller,
                   before: ControllerFigures, candidate_figures: ControllerFigures,
                   options: TuneOptions, why: str, make: Make,
                   journal: Callable[[TuneResult], None] | None,
                   say: Callable[[str], None],
                   after_load: Callable[[TuneTarget], str] | None = None) -> TuneResult:
    """Load ``candidate``, watch it, roll back on a worse tracking error (module notes).

    Parameters
    ----------
    target : TuneTarget
        The running bench, on ``running`` now.
    running : Controller
        The controller running (measured as ``before``).
    candidate : Controller
        The controller to load (its figures ``candidate_figures``, predicted).
    before, candidate_figures : ControllerFigures
    options : TuneOptions
        ``watch_s``, ``settle_s`` [s] and ``rollback_tolerance`` [1].
    why : str
        Why the candidate is to be loaded, in words with the numbers.
    make : callable
        ``make(decision, reason, candidate_figures=, after=, switches=, transaction=,
        e_after=None)``: the :class:`~fsmbench.tune.guarded.TuneResult` of a step
        (``e_after``: the last watch's tracking error [rad], (n, 2)).
    journal : callable or None
        Receives the record before the load (``loading``), after the watch, and after an
        interruption (``interrupted``).
    say : callable
        The log.
    after_load : callable, optional
        ``after_load(target)`` once loaded: the change it made to the bench, in words.

    Returns
    -------
    TuneResult
        Decision ``loaded`` or ``rolled_back``, its ``transaction`` record done.

    Raises
    ------
    LoopChangeError
        An ``Exception`` once the record was being written (``KeyboardInterrupt`` and
        SIGTERM's are raised again as they are): rolled back first; the message ends with
        the sentence saying which controller the bench is left on.
    """
    point = target.checkpoint(running)
    noun = str(point.get("noun", "The bench"))
    tx: dict[str, Any] = {
        "state": "decided", "outcome": None, "candidate": candidate.name, "why": why,
        "running_before": dict(point), "left_on": running.name, "load_started": False,
        "sentence": f"Decided to load {candidate.name}; the bench runs {running.name} until "
                    "it is loaded."}
    cand, switches = candidate_figures, []
    try:
        if journal is not None:
            journal(make("loading", why, candidate_figures=cand, after=before, switches=(),
                         transaction=tx))
            say(f"decision recorded before the load: {candidate.name} to replace {running.name}")
        tx["load_started"] = True
        switches.append(target.load(candidate))
        _loaded(target, candidate, switches[-1], after_load=after_load, say=say)
        e_after = target.run(options.watch_s, settle_s=options.settle_s)
        measured_after = rms_by_axis(e_after)
        cand = with_changes(cand, measured_rms_rad=measured_after)
        say(f"watched {candidate.name} for {options.watch_s:g} s: {urad_text(measured_after)} "
            f"rms (predicted {urad_text(cand.predicted_rms_rad)})")
        result = _judge(target, running=running, candidate=candidate, before=before,
                        figures=cand, e_after=e_after, options=options, why=why, tx=tx,
                        switches=switches, noun=noun, make=make, say=say)
    except BaseException as exc:
        message = _record_interruption(exc, target, running=running, candidate=candidate,
                                       point=point, before=before, figures=cand, tx=tx,
                                       switches=switches, journal=journal, make=make, say=say)
        if isinstance(exc, Exception):
            raise LoopChangeError(message, str(tx["sentence"])) from exc
        raise
    if journal is not None:
        journal(result)
    say(str(tx["sentence"]))
    return result

