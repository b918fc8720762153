"""What the budget stage computed: :class:`BudgetResult` and the types it holds.

The stage's result types live apart from its computation
(:mod:`fsmbench.budget.study`), as :mod:`fsmbench.ident.result` does for the
identification, so that the report and the public API read a budget without
importing the code that makes one (the import contract "the report never
computes", ``pyproject.toml``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field

from fsmbench.budget.environment import AirBudget, FrameBudget
from fsmbench.budget.huddle import DacNoiseEstimate, HuddleAnalysis
from fsmbench.budget.optics import GeometryBudget
from fsmbench.budget.quantisation import NoiseSources
from fsmbench.budget.repeatability import HuddleWindow, RepeatabilityRecord
from fsmbench.budget.stability import StabilityRecord
from fsmbench.budget.table import ErrorBudget
from fsmbench.checks import Check, Notice
from fsmbench.jsonutil import plain_json

__all__ = ["BudgetResult", "ControllerBudget", "NonRepeatability"]


@dataclass(frozen=True)
class NonRepeatability:
    """Fig. 50 in numbers, one direction [m]: what the non-repeatability is made of.

    ``va_nonrep_rms_m``: measured (ESRF study's estimate); ``va_nonrep_unbiased_m``:
    corrected for the periods' own mean; ``tracking_nonrep_rms_m``: the
    non-repeatable part of the distance-error equivalent of the 4QD tracking
    error; ``huddle_va_rms_m``: the huddle test of ``huddle_test`` (the same
    configuration when present); ``predicted_rms_m``: the budget over the
    record's length; ``huddle_window``: that huddle test's ``Va`` over the
    repeatability records' length, for Fig. 50 (None without a huddle test).
    """

    direction: str
    va_nonrep_rms_m: float
    va_nonrep_unbiased_m: float
    tracking_nonrep_rms_m: float
    huddle_test: str | None
    huddle_va_rms_m: float | None
    predicted_rms_m: float
    huddle_window: HuddleWindow | None = field(default=None, repr=False)

    def to_json(self) -> dict[str, object]:
        """Plain values."""
        out = {k: v for k, v in self.__dict__.items() if k != "huddle_window"}
        out["huddle_window"] = (None if self.huddle_window is None
                                else self.huddle_window.to_json())
        return out


@dataclass(frozen=True)
class ControllerBudget:
    """The operating configuration's budget with one controller in the loop.

    ``budget`` over the huddle tests' window (``window_s``, mean removed);
    ``stationary_total_rms_m``: the same sources as stationary values (no window),
    what a record much longer than every correlation time would show.
    """

    controller: str
    budget: ErrorBudget
    stationary_total_rms_m: float

    def to_json(self) -> dict[str, object]:
        """The controller, its budget and the stationary total."""
        return {"controller": self.controller, "budget": self.budget.to_json(),
                "stationary_total_rms_m": self.stationary_total_rms_m}


@dataclass(frozen=True)
class BudgetResult:
    """Everything :func:`budget_study` computed; ``to_json()`` for the study's JSON.

    ``checks`` are the plausibility checks of the huddle and repeatability
    records (:func:`fsmbench.io.folder.check_recording`): a record failing one
    is left out, and ``skipped`` names the check. ``notices``: saturation and
    numerical warnings met while computing.
    """

    plant_source: str
    controller: str
    noise: NoiseSources
    geometry: GeometryBudget
    air: AirBudget
    frame: FrameBudget
    budget: ErrorBudget
    huddle: HuddleAnalysis | None
    dac_noise: DacNoiseEstimate | None
    predicted_huddle_va_rms_m: Mapping[int, float]
    repeatability: Mapping[str, RepeatabilityRecord]
    nonrep: Mapping[str, NonRepeatability]
    skipped: Mapping[str, str]
    checks: tuple[Check, ...] = ()
    notices: tuple[Notice, ...] = ()
    stability: Mapping[int, StabilityRecord] = field(default_factory=dict)
    stationary_total_rms_m: float = math.nan
    recommended: ControllerBudget | None = None

    @property
    def quoted(self) -> ControllerBudget:
        """The budget a verdict quotes: the recommended controller's when there is one."""
        if self.recommended is not None:
            return self.recommended
        return ControllerBudget(self.controller, self.budget, self.stationary_total_rms_m)

    @property
    def total_rms_m(self) -> float:
        """RSS of every source of the operating configuration [m]."""
        return self.budget.total_rms_m

    @property
    def limiting(self) -> str:
        """The largest source."""
        return self.budget.limiting

    def to_json(self) -> dict[str, object]:
        """JSON-ready dict, SI units in the keys (non-finite values as null).

        The total, the rows and the limiting source are in ``budget`` only.
        """
        huddle: dict[str, object] = {}
        if self.huddle is not None:
            for n, rec in self.huddle.records.items():
                d = rec.to_json()
                d["predicted_va_rms_m"] = self.predicted_huddle_va_rms_m.get(n)
                huddle[str(n)] = d
        out = {
            "params": "nominal", "plant_source": self.plant_source,
            "controller": self.controller,
            "noise": self.noise.to_json(), "geometry": self.geometry.to_json(),
            "air": self.air.to_json(), "frame": self.frame.to_json(),
            "budget": self.budget.to_json(), "huddle": huddle,
            "stationary_total_rms_m": self.stationary_total_rms_m,
            "recommended": None if self.recommended is None else self.recommended.to_json(),
            "huddle_comparison": None if self.huddle is None else {
                "comparisons": [c.to_json() for c in self.huddle.comparisons],
                "conclusion": self.huddle.conclusion,
                "qd_noise": None if self.huddle.qd_noise is None
                else self.huddle.qd_noise.to_json()},
            "dac_noise": None if self.dac_noise is None else self.dac_noise.to_json(),
            "repeatability": {k: r.to_json() for k, r in self.repeatability.items()},
            "nonrep_contributions": {k: v.to_json() for k, v in self.nonrep.items()},
            "stability": {str(k): v.to_json() for k, v in self.stability.items()},
            # Parts are named in words ("4QD noise from huddle data"): a list, not keys.
            "skipped": [{"part": k, "reason": v} for k, v in self.skipped.items()],
            "checks": [c.to_json() for c in self.checks],
            "notices": [n.to_json() for n in self.notices],
        }
        return plain_json(out)
