"""The values a tune passes around: its options, a controller's figures,
its result, and the target it tunes (:class:`TuneTarget`, the twin or a device).

Apart from the procedure (:mod:`fsmbench.tune.guarded`) so that the targets and the
load transaction, which the procedure drives, build on these and not on it.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from fsmbench.control.controller import Controller
from fsmbench.jsonutil import plain_json
from fsmbench.tune.measure import ClosedLoopMeasurement, MeasurementOptions
from fsmbench.twin.closed_loop import ClosedLoopPlay
from fsmbench.twin.experiments import REP_AMPLITUDE_V
from fsmbench.twin.simulate import TwinRun
from fsmbench.version import __version__

__all__ = ["AXES", "MAX_MODE_MOVE", "TUNE_FORMAT", "ControllerFigures", "TuneOptions",
           "TuneResult", "TuneTarget", "rms_by_axis", "urad_text", "with_changes"]

#: A resonance further than this from the model's is not a drift a tune follows (the drift
#: scenarios move it by a few %): a mode assigned to the wrong axis, or another bench.
MAX_MODE_MOVE = 0.15

#: ``tune.json``'s format and version.
TUNE_FORMAT = ("fsmbench.tune", 1)
AXES = ("h", "v")


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
    candidate_loop : Controller
        The candidate as designed (``continuous``) and wired (to offer it again, or export
        it).
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
    candidate_loop: Controller
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

    def load(self, loop: Controller) -> dict[str, Any]:
        """Load ``loop`` bumplessly in the running loop; the switch, JSON-ready."""

    def roll_back(self, loop: Controller, *, force: bool = False) -> dict[str, Any]:
        """Return to ``loop``, the controller that ran when tune started, by the means that
        put it there (the device: its own ``LoadController``); the switch, JSON-ready.
        ``force``: load it even when the target reads it as running already."""

    def running_controller(self) -> str:
        """The name of the controller the bench runs now."""

    def checkpoint(self, loop: Controller) -> dict[str, Any]:
        """``loop`` (running now) as the record names it: its name, what checked it and how
        :meth:`roll_back` returns to it, JSON-ready."""

    def play(self, plays: Sequence[ClosedLoopPlay], *, controller: Controller,
             settle_s: float, seed: int,
             progress: Callable[[str], None] | None) -> TwinRun:
        """Play each excitation with the loop closed; the records (data_cl_* layout)."""


def rms_by_axis(e: np.ndarray) -> dict[str, float]:
    """The rms of each column of ``e`` (n, 2), by axis name."""
    return {a: float(np.sqrt(np.mean(e[:, i] ** 2))) for i, a in enumerate(AXES)}


def urad_text(d: Mapping[str, float]) -> str:
    """``{"h": 3e-5, ...}`` [rad] in words: ``"h 30 µrad, ..."``."""
    return ", ".join(f"{a} {1e6 * v:.3g} µrad" for a, v in d.items())


def with_changes(fig: ControllerFigures, **changes: Any) -> ControllerFigures:
    """``fig`` with ``changes`` (``dataclasses.replace``)."""
    return dataclasses.replace(fig, **changes)
