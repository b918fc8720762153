"""The live bench's states and commands as a state machine, protocol-neutral.

The state is computed from facts, never stored as a label that could lie:

- **FAULT** the protection opened the loop, the bench loop stalled or died,
  or the device could not start (until ``Reset``);
- **MOVING** a command's work runs: a recording, an experiment, or a task
  off the client's call (designing an excitation);
- **ALARM** a converter is on a rail (with hysteresis: :class:`AlarmHysteresis`),
  the mirror still rings after a trip (:class:`Ringdown`), or the loop runs and
  its watch warns that the tracking error departs from the loaded controller's
  prediction (:mod:`fsmbench.live.watching`; the commands are then allowed as in
  RUNNING: the warning advises ``fsmbench tune``, which needs them);
- **RUNNING** the loop is closed;
- **ON** the loop is open.

:data:`ALLOWED` says which command each state accepts; a refusal is a
:class:`Refused` with a reason code (:data:`REASONS`) and one sentence. The
Tango device raises it as ``DevFailed`` (reason, sentence) and the EPICS IOC
puts it in its ``Reply`` PV: the same words on both.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["ALLOWED", "COMMANDS", "MAX_DRIFT_PCT_PER_H", "MAX_SPEED", "MIN_SPEED", "REASONS",
           "STATES", "AlarmHysteresis", "Refused", "Ringdown", "plain"]

STATES = ("ON", "RUNNING", "MOVING", "ALARM", "FAULT")

#: SpeedFactor's range [bench seconds per wall-clock second].
MIN_SPEED = 0.01
MAX_SPEED = 100.0
#: Largest drift rate of the twin's Sercalo resonance a server accepts [%/h].
MAX_DRIFT_PCT_PER_H = 10_000.0

#: Reason codes of refusals (the ``DevFailed`` reason; the IOC's ``ReplyCode``).
REASONS = {
    "FSM_BadArgument": "the argument is malformed or outside what the bench can do",
    "FSM_NotAllowed": "the command is not allowed in the current state",
    "FSM_Busy": "a recording, an experiment or a task runs",
    "FSM_Settling": "the mirror still rings; the sentence gives the settling time left",
    "FSM_Fault": "the device is in FAULT; Reset first",
    "FSM_Playback": "the bench replays recordings and cannot act",
    "FSM_Output": "the output folder, the disk or an existing file refuses the write",
    "FSM_Internal": "an unexpected error (a bug); the bench runs on",
}

COMMANDS = ("CloseLoop", "OpenLoop", "LoadController", "StartExcitation", "StopExcitation",
            "RunExperiment", "Record", "Abort", "Reset")

_ALL = frozenset(STATES)
#: States in which each command is accepted (finer checks follow in LiveBench).
ALLOWED: dict[str, frozenset[str]] = {
    "CloseLoop": frozenset({"ON", "ALARM"}),  # ALARM: only to wait for a short ringdown
    "OpenLoop": _ALL,  # safe in every state; refused only during an experiment
    "LoadController": frozenset({"ON", "RUNNING", "ALARM"}),
    "StartExcitation": frozenset({"ON", "RUNNING", "ALARM", "MOVING"}),  # MOVING: a Record
    "StopExcitation": _ALL,
    "RunExperiment": frozenset({"ON", "RUNNING"}),
    "Record": frozenset({"ON", "RUNNING", "ALARM"}),
    "Abort": _ALL,
    "Reset": _ALL,
}


class Refused(ValueError):  # noqa: N818  (reads as what happened: raise Refused)
    """A command the bench does not carry out: a reason code and one sentence.

    Parameters
    ----------
    reason : str
        One of :data:`REASONS`.
    sentence : str
        What is wrong and what to do, one line (kept as :func:`plain` ASCII).
    """

    def __init__(self, reason: str, sentence: str) -> None:
        if reason not in REASONS:
            raise KeyError(f"unknown refusal reason {reason!r}")
        sentence = plain(sentence)  # the same ASCII words on every protocol
        super().__init__(sentence)
        self.reason = reason
        self.sentence = sentence


_ASCII = {"±": "+/-", "µ": "u", "√": "sqrt", "×": "x", "≤": "<=", "≥": ">=", "–": "-",
          "—": "-", "’": "'", "‘": "'", "“": '"', "”": '"', "→": "->", "°": " deg",
          "…": "...", "Ω": "Ohm"}


def plain(text: str) -> str:
    """``text`` as one line of ASCII (``±`` → ``+/-``, ``µ`` → ``u``; others → ``?``).

    Tango sends exception texts as UTF-8 and clients decode them as Latin-1
    (``±`` arrived as ``Â±``); EPICS strings are bytes. ASCII reads the same
    everywhere.
    """
    out = "".join(_ASCII.get(ch, ch) for ch in " ".join(str(text).split()))
    return out.encode("ascii", "replace").decode("ascii")


@dataclass(frozen=True)
class AlarmHysteresis:
    """When converter saturation makes the state ALARM, and when it ends.

    ALARM starts when more than ``enter_fraction`` of the last ``enter_window_s``
    had a converter on a rail, and ends only when less than ``leave_fraction``
    of the last ``leave_window_s`` had, and at least ``min_dwell_s`` after it
    started: a signal that clips now and then gives one ALARM, not one per clip
    (86 State events in 10 s without it). Times are bench time.

    Attributes
    ----------
    enter_fraction, leave_fraction : float
        Fractions of samples on a rail [1].
    enter_window_s, leave_window_s, min_dwell_s : float
        [s] of bench time.
    """

    enter_fraction: float = 0.02
    enter_window_s: float = 0.1
    leave_fraction: float = 0.002
    leave_window_s: float = 1.0
    min_dwell_s: float = 2.0

    def next(self, *, active: bool, since_s: float, now_s: float, enter_measure: float,
             leave_measure: float) -> tuple[bool, float]:
        """The alarm after a block: ``(active, since_s)``.

        Parameters
        ----------
        active, since_s : bool, float
            The alarm before the block, and the bench time it started [s].
        now_s : float
            Bench time at the end of the block [s].
        enter_measure, leave_measure : float
            Rail fractions over ``enter_window_s`` and ``leave_window_s`` [1].
        """
        if not active:
            if enter_measure > self.enter_fraction:
                return True, now_s
            return False, since_s
        if leave_measure < self.leave_fraction and now_s - since_s >= self.min_dwell_s:
            return False, since_s
        return True, since_s

    def time_left_s(self, *, since_s: float, now_s: float, rails: np.ndarray,
                    fs_hz: float) -> float:
        """Bench time until an active alarm ends if no converter touches a rail again [s].

        Parameters
        ----------
        since_s, now_s : float
            When the alarm began and the bench time now [s].
        rails : array of bool, shape (N,)
            The last ``leave_window_s`` of samples, oldest first: on a rail or not.
        fs_hz : float
            Sample rate [Hz].
        """
        n = max(1, round(self.leave_window_s * fs_hz))
        flags = np.asarray(rails, dtype=bool)[-n:]
        # Samples that must leave the window before fewer than leave_fraction of it are rails:
        # the k oldest go first as new rail-free samples come in.
        tail = np.cumsum(flags[::-1])[::-1]  # rails in flags[k:], for each k
        allowed = self.leave_fraction * n
        k = int(np.argmax(np.append(tail, 0) < allowed))
        return max(since_s + self.min_dwell_s - now_s, k / fs_hz, 0.0)


@dataclass(frozen=True)
class Ringdown:
    """The mirror ringing after a trip, and how long it has left.

    The Sercalo is a lightly damped mode (ζ ≈ 0.001 at 250-410 Hz: a decay
    time ``1/(ζ ω)`` of about 0.4-0.8 s): left on the rails by a trip, it
    rings for seconds, and closing the loop on it trips again. The ringing
    amplitude is the largest deviation of a 4QD reading from its mean over
    the last ``window_s``; the mirror has settled below ``settled_v``.

    Attributes
    ----------
    decay_time_s : tuple of float
        ``1/(ζ 2π f)`` of each axis (h, v) [s].
    settled_v : float
        4QD deviation [V] below which the mirror counts as settled.
    window_s : float
        Window of the amplitude [s] (several periods of the mode).
    """

    decay_time_s: tuple[float, float]
    settled_v: float = 0.5
    window_s: float = 0.05

    def time_left_s(self, amplitude_v: tuple[float, float]) -> float:
        """Bench time until both axes ring below ``settled_v`` [s] (0 when settled).

        An exponential decay from the amplitude now; ``inf`` for an amplitude
        that is not finite.
        """
        left = 0.0
        for a, tau in zip(amplitude_v, self.decay_time_s, strict=True):
            if not math.isfinite(a):
                return math.inf
            if a > self.settled_v:
                left = max(left, tau * math.log(a / self.settled_v))
        return left
