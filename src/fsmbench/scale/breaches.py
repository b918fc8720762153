"""The Monte Carlo draws that break each requirement of the design, named with their draw.

A quantile says how often a requirement holds, not on which plants it fails:
this module lists, per requirement, every draw that breaks it, with its index,
its noise seed and its drawn factors (so that the plant can be rebuilt,
:func:`fsmbench.twin.draws.perturbed_bench`) and the value against the limit.

The requirements are the design's own (:class:`fsmbench.control.design.DesignOptions`):
a stable closed loop, and on both axes a gain margin ≥ 6 dB, a phase margin ≥ 30°
and a modulus margin ≥ 0.4. An unstable draw breaks every requirement (its
margins mean nothing); a margin of +inf (no crossing) meets its limit.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from fsmbench.control.design import DesignOptions
from fsmbench.jsonutil import nested, plain_json

if TYPE_CHECKING:
    from fsmbench.scale.montecarlo import DrawResult

__all__ = ["NOTABLE_SHARE", "Breach", "DrawRequirement", "Limits", "RequirementOutcome",
           "breach_sentence", "breach_values", "draw_requirements", "factors_sentence",
           "requirement_outcomes"]

#: A requirement broken by at least this share of the draws is reported in the verdict's
#: robustness row (one draw in twenty: the 5 % quantile the Monte Carlo table prints).
NOTABLE_SHARE = 0.05

_DESIGN = DesignOptions()


@dataclass(frozen=True)
class Limits:
    """The limits each draw is judged against (default: the design's requirements).

    Attributes
    ----------
    gain_margin_min_db : float
        Smallest gain margin on each axis [dB].
    phase_margin_min_deg : float
        Smallest phase margin on each axis [°].
    modulus_margin_min : float
        Smallest modulus margin ``min |1 + L|`` on each axis [1].
    """

    gain_margin_min_db: float = _DESIGN.gain_margin_db
    phase_margin_min_deg: float = _DESIGN.phase_margin_deg
    modulus_margin_min: float = _DESIGN.modulus_margin

    def to_json(self) -> dict[str, Any]:
        """``{gain_margin_min_db, phase_margin_min_deg, modulus_margin_min}``."""
        return plain_json({"gain_margin_min_db": self.gain_margin_min_db,
                           "phase_margin_min_deg": self.phase_margin_min_deg,
                           "modulus_margin_min": self.modulus_margin_min})


@dataclass(frozen=True)
class DrawRequirement:
    """One requirement every draw is judged against.

    Attributes
    ----------
    name : str
        Identifier (``stable``, ``gain_margin``, ``phase_margin``, ``modulus_margin``).
    quantity : str
        What is judged, in words (``phase margin``).
    description : str
        In words, with the limit and its unit.
    metric : str
        The :data:`fsmbench.scale.montecarlo.METRICS` key, without the axis for a
        per-axis metric.
    per_axis : bool
        Judged on ``metric.h`` and ``metric.v`` (both must hold).
    limit : float
        The bound, in the metric's unit.
    unit : str
        The metric's unit (``dB``, ``deg``, ``1``).
    kind : {"min", "below"}
        ``min``: the value must be ≥ ``limit`` (+inf meets it); ``below``: strictly < ``limit``.
    """

    name: str
    quantity: str
    description: str
    metric: str
    per_axis: bool
    limit: float
    unit: str
    kind: str

    def holds(self, value: float) -> bool:
        """Whether one value meets the limit (NaN never does)."""
        if self.kind == "below":
            return value < self.limit
        return value == math.inf or (math.isfinite(value) and value >= self.limit)

    def to_json(self) -> dict[str, Any]:
        """Name, words, metric, limit, unit and kind."""
        return plain_json({"name": self.name, "quantity": self.quantity,
                           "description": self.description,
                           "metric": self.metric, "per_axis": self.per_axis,
                           "limit": self.limit, "unit": self.unit, "kind": self.kind})


def draw_requirements(limits: Limits) -> tuple[DrawRequirement, ...]:
    """The requirements of :class:`Limits`, stability first."""
    return (
        DrawRequirement("stable", "spectral radius", "closed loop stable (spectral radius < 1)",
                        "spectral_radius", False, 1.0, "1", "below"),
        DrawRequirement("gain_margin", "gain margin",
                        f"gain margin ≥ {limits.gain_margin_min_db:g} dB",
                        "gain_margin_db", True, limits.gain_margin_min_db, "dB", "min"),
        DrawRequirement("phase_margin", "phase margin",
                        f"phase margin ≥ {limits.phase_margin_min_deg:g}°",
                        "phase_margin_deg", True, limits.phase_margin_min_deg, "deg", "min"),
        DrawRequirement("modulus_margin", "modulus margin",
                        f"modulus margin ≥ {limits.modulus_margin_min:g}",
                        "modulus_margin", True, limits.modulus_margin_min, "1", "min"),
    )


@dataclass(frozen=True)
class Breach:
    """One draw that breaks one requirement.

    Attributes
    ----------
    index, noise_seed : int
        The draw (its row in ``draws[]``) and the twin's noise seed it ran with.
    factors : mapping
        The drawn factors and offsets (:data:`fsmbench.twin.draws.PARAMETERS` keys).
    values : mapping
        The requirement's metric per axis (``h``, ``v``), or ``loop`` for a
        whole-loop one, in the requirement's unit (NaN: not computed or unstable).
    axes : tuple of str
        The axes that break it (``("loop",)`` for a whole-loop requirement).
    reason : {"outside the limit", "unstable", "not computed"}
        ``unstable``: the draw's closed loop is (every requirement breaks, its
        margins are NaN); ``not computed``: a stable draw whose margin is NaN.
    """

    index: int
    noise_seed: int
    factors: Mapping[str, float]
    values: Mapping[str, float]
    axes: tuple[str, ...]
    reason: str

    def to_json(self) -> dict[str, Any]:
        """``index``, ``noise_seed``, ``reason``, ``axes``, ``values``, ``factors`` (nested)."""
        return plain_json({"index": self.index, "noise_seed": self.noise_seed,
                           "reason": self.reason, "axes": list(self.axes),
                           "values": dict(self.values), "factors": nested(self.factors)})


@dataclass(frozen=True)
class RequirementOutcome:
    """Every draw that breaks one requirement, over a run.

    Attributes
    ----------
    requirement : DrawRequirement
    n_draws : int
        Draws judged (all of the run's).
    breaches : tuple of Breach
        Sorted by draw index.
    """

    requirement: DrawRequirement
    n_draws: int
    breaches: tuple[Breach, ...]

    @property
    def n_broken(self) -> int:
        """Draws that break the requirement."""
        return len(self.breaches)

    @property
    def share(self) -> float:
        """Share of the draws that break it [0–1] (NaN for no draw)."""
        return self.n_broken / self.n_draws if self.n_draws else math.nan

    @property
    def notable(self) -> bool:
        """At least :data:`NOTABLE_SHARE` of the draws break it."""
        return self.n_draws > 0 and self.n_broken >= NOTABLE_SHARE * self.n_draws

    def to_json(self) -> dict[str, Any]:
        """The requirement, the counts and every breach."""
        return plain_json({**self.requirement.to_json(), "draws": self.n_draws,
                           "broken": self.n_broken, "share": self.share,
                           "notable": self.notable,
                           "breaches": [b.to_json() for b in self.breaches]})


def _breach(req: DrawRequirement, d: DrawResult) -> Breach | None:
    axes = ("h", "v") if req.per_axis else ("loop",)
    values = {a: float(d.metrics[f"{req.metric}.{a}" if req.per_axis else req.metric])
              for a in axes}
    failing = tuple(a for a in axes if not req.holds(values[a]))
    if d.stable and not failing:
        return None
    if not d.stable:
        reason = "unstable"
        failing = failing or axes
    else:
        reason = ("not computed" if any(math.isnan(values[a]) for a in failing)
                  else "outside the limit")
    return Breach(index=d.index, noise_seed=d.noise_seed, factors=dict(d.factors),
                  values=values, axes=failing, reason=reason)


def requirement_outcomes(draws: Sequence[DrawResult], *,
                         limits: Limits) -> tuple[RequirementOutcome, ...]:
    """Per requirement of ``limits``, every draw of ``draws`` that breaks it.

    Parameters
    ----------
    draws : sequence of DrawResult
        A run's draws (any order; the breaches come sorted by index).
    limits : Limits

    Returns
    -------
    tuple of RequirementOutcome
        In the order of :func:`draw_requirements`.
    """
    ordered = sorted(draws, key=lambda d: d.index)
    out = []
    for req in draw_requirements(limits):
        found = (_breach(req, d) for d in ordered)
        out.append(RequirementOutcome(requirement=req, n_draws=len(ordered),
                                      breaches=tuple(b for b in found if b is not None)))
    return tuple(out)


# ----------------------------------------------------------------------------- in words
# From the JSON (``requirements[]`` of montecarlo.json), so that the command's table and
# the report, which reads the file, say the same.

_FACTOR_WORDS = (("resonance_scale", "resonance"), ("damping_scale", "damping"),
                 ("qd_gain_scale", "4QD gain"), ("current_amp_gain_scale", "current amplifier"),
                 ("newport_gain_scale", "Newport gain"))


def _value(x: float, unit: str) -> str:
    return {"deg": f"{x:.1f}°", "dB": f"{x:.1f} dB"}.get(unit, f"{x:.4g}")


def factors_sentence(factors: Mapping[str, Any]) -> str:
    """A draw's factors (nested as in ``montecarlo.json``), h/v, in words with units."""
    parts = [f"{words} ×{factors[k]['h']:.3f}/{factors[k]['v']:.3f}"
             for k, words in _FACTOR_WORDS if k in factors]
    parts += [f"{words} {1e6 * factors[k]:+.0f} µs" for k, words in
              (("dac_delay_offset_s", "DAC delay"), ("newport_delay_offset_s", "Newport delay"))
              if k in factors]
    return ", ".join(parts) + " (h/v)"


def breach_values(requirement: Mapping[str, Any], breach: Mapping[str, Any]) -> str:
    """``phase margin v 28.3° < 30° (h 35.1°)``: the values against the limit, with units.

    ``requirement`` and ``breach``: an entry of ``requirements[]`` and one of its
    ``breaches[]``, as :meth:`RequirementOutcome.to_json` writes them.
    """
    unit, limit, values = requirement["unit"], requirement["limit"], breach["values"]
    quantity = requirement["quantity"]
    if breach["reason"] == "unstable" and requirement["per_axis"]:
        what = "closed loop unstable"
    elif not requirement["per_axis"]:
        what = (f"{quantity} not computed" if values["loop"] is None else
                f"{quantity} {_value(values['loop'], unit)}, not below {_value(limit, unit)}")
    else:
        bad = breach["axes"]
        shown = [f"{quantity} {a} " + ("not computed" if values[a] is None
                                       else f"{_value(values[a], unit)} < {_value(limit, unit)}")
                 for a in bad]
        # A passing axis written null is +inf (no crossing): NaN never passes.
        good = [f"{a} " + ("∞" if values[a] is None else _value(values[a], unit))
                for a in ("h", "v") if a not in bad]
        what = ", ".join(shown) + (f" ({', '.join(good)})" if good else "")
    return what


def breach_sentence(requirement: Mapping[str, Any], breach: Mapping[str, Any]) -> str:
    """``draw 4: phase margin v 28.3° < 30° (h 35.1°); noise seed …; resonance ×…``.

    Arguments as :func:`breach_values`.
    """
    return (f"draw {breach['index']}: {breach_values(requirement, breach)}; noise seed "
            f"{breach['noise_seed']}; " + factors_sentence(breach["factors"]))
