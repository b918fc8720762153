"""A value with its total uncertainty and the parts it is made of.

Every identified value is reported as an :class:`Uncertain`: the value, its
unit, what quantity it is, and one standard deviation per *part* — measurement
noise and each systematic contribution the identification can bound. The
total standard deviation is their root sum of squares (the parts are
independent by construction: each comes from another source of error).

Part names (:data:`PARTS`), each a one-sigma standard deviation in the
value's unit:

=======================  =======================================================
``noise``                measurement noise propagated through the estimator
``misfit``               what the model misses beyond the noise (reduced chi-square
                         above 1, a Birge-ratio inflation)
``sampled_model``        sampled against continuous model: what is left of it
                         (the estimators model the hold and fractional delays)
``leakage``              a Welch window's leakage near the modes (bias bound)
``transient``            a transient left in periodic averaging
``compression``          the 4QD's compression: the uncertainty of its correction
``distortion``           nonlinear distortion on the excited lines (best linear
                         approximation, from the non-excited lines)
``unresolved_lags``      lags a delay fit cannot tell from a delay (the 4QD
                         amplifier, the coil): bounded, not measured
``unresolved_sensor``    a 4QD amplifier the delays measure (its lag) but
                         neither the bench model nor the lines give the shape of:
                         the shift a first or second order of that lag causes
                         (the Newport's parameters; bounded)
``qd_amplifier_lag``     a 4QD amplifier the records decide (its order by the
                         Newport's lines, its lag by the delays): the measured
                         lag's std carried into the Newport's parameters (random)
``truncation``           modes above a fitted band that its model leaves out
                         (:mod:`fsmbench.ident.fit.truncation`): bounded
``definition``           what the quantity's definition adds (a rotation, a
                         nominal block the value is defined against)
``current_amp``          the current-amplifier gain's share (values divided by it)
``calibration``          another calibration's share (e.g. the 4QD gain's)
=======================  =======================================================

A *bounded* systematic (``unresolved_lags``) is a uniform interval
``[lo, hi]`` around the value, given as its half-width over √3 (the uniform
distribution's standard deviation).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

__all__ = ["PARTS", "Uncertain", "bounded", "largest_part", "total_std"]

PARTS = ("noise", "misfit", "sampled_model", "leakage", "transient", "compression",
         "distortion", "unresolved_lags", "unresolved_sensor", "qd_amplifier_lag", "truncation",
         "definition", "current_amp", "calibration")


def total_std(parts: Mapping[str, float]) -> float:
    """Root sum of squares of the parts [their unit]; NaN parts count as NaN."""
    return math.sqrt(sum(float(v) ** 2 for v in parts.values()))


def largest_part(parts: Mapping[str, float]) -> str:
    """Name of the largest part ("" when there is none)."""
    finite = {k: abs(float(v)) for k, v in parts.items() if math.isfinite(float(v))}
    return max(finite, key=lambda k: finite[k]) if finite else ""


def bounded(half_width: float) -> float:
    """One-sigma std of a systematic known only to lie within ``±half_width`` (uniform)."""
    return abs(float(half_width)) / math.sqrt(3.0)


@dataclass(frozen=True)
class Uncertain:
    """An identified value with its total standard deviation and its parts.

    Attributes
    ----------
    value : float
        The value [``unit``].
    unit : str
        SI unit of ``value`` and of every part ("1" when dimensionless).
    quantity : str
        What the value is, in words (its definition where it matters).
    parts : mapping str -> float
        One-sigma standard deviation of each contribution [``unit``]
        (:data:`PARTS`); absent parts are zero.
    derived : str
        Empty when the data determine the value; otherwise how it is derived
        from one they determine (e.g. "the effective delay less the lags").
    bounded_parts : tuple of str
        Parts that are bounds of a fixed systematic (uniform), not random
        errors: a coverage check over runs of one bench sees them as a
        fixed offset within ±√3 of their std.
    """

    value: float
    unit: str
    quantity: str
    parts: Mapping[str, float] = field(default_factory=dict)
    derived: str = ""
    bounded_parts: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        unknown = sorted(set(self.parts) - set(PARTS))
        if unknown:
            raise ValueError(f"unknown uncertainty part(s) {unknown}; known: {PARTS}")
        if any(float(v) < 0 for v in self.parts.values()):
            raise ValueError(f"uncertainty parts are standard deviations (>= 0), got "
                             f"{dict(self.parts)}")

    @property
    def std(self) -> float:
        """Total one-sigma standard deviation [``unit``]."""
        return total_std(self.parts)

    @property
    def largest_part(self) -> str:
        """Name of the largest part."""
        return largest_part(self.parts)

    def with_parts(self, **parts: float) -> Uncertain:
        """The same value with parts added (a part given twice adds in quadrature)."""
        merged = dict(self.parts)
        for name, std in parts.items():
            merged[name] = math.hypot(merged.get(name, 0.0), float(std))
        return Uncertain(self.value, self.unit, self.quantity, merged, self.derived,
                         self.bounded_parts)

    def to_json(self) -> dict[str, Any]:
        """``{value, std, unit, quantity, parts, largest_part, derived, bounded_parts}``."""
        return {"value": float(self.value), "std": self.std, "unit": self.unit,
                "quantity": self.quantity,
                "parts": {k: float(v) for k, v in self.parts.items()},
                "largest_part": self.largest_part, "derived": self.derived,
                "bounded_parts": list(self.bounded_parts)}
