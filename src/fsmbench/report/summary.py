"""The verdict a reader acts on: does the bench meet its specifications, and why.

:func:`build_summary` reads the stages' results and states, for each of the
bench's requirements (ESRF study Table 5 and §6.1, margins, robust stability, a
distance target, the closed loop simulated on the bench, and the model's own
check on the recorded closed loop):

- the value found, per axis where it has axes, as numbers in SI with their
  unit, and the display string beside them;
- the limit, as numbers and in words;
- its status: ``pass``, ``fail`` or ``not verified`` (what is missing);
- its provenance: ``measured`` (from the recordings), ``derived`` (computed
  from measurements), ``predicted`` (simulated or computed on a named bench)
  or ``assumed`` (a bench-file value no recording checked), with the detail.

The verdict is three-valued (meets / does not meet / not verified); a model
that does not predict the user's own closed loop makes it *not verified*.
It ends with the next step, computed from the results (:mod:`.verdict`).
The same :class:`Summary` is written as ``summary.json``, embedded in the
report and drawn as its first screen (:func:`fsmbench.report.verdict.verdict_html`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field, replace
from typing import Any, Literal

from fsmbench.checks import Check, Notice
from fsmbench.jsonutil import plain_json
from fsmbench.report.sections.montecarlo import robustness_sentence
from fsmbench.report.verdict import next_step, verdict_html
from fsmbench.version import __version__

__all__ = [
    "FINDINGS",
    "SUMMARY_FORMAT",
    "PartSkipped",
    "Requirement",
    "Specification",
    "StageLine",
    "StudyEvidence",
    "Summary",
    "build_summary",
    "verdict_html",
]

#: Failed checks that are findings about a device or an analysis, not data contradicting
#: itself: the Newport found off its datasheet, a margin the numerics could not compute.
#: Every other failed check leaves the verdict not verified (never a pass on data
#: that contradicts itself or the bench file).
FINDINGS = frozenset({"newport_amplitude_bandwidth", "newport_phase_bandwidth",
                      "newport_peaking", "coprime_factor_margin"})

#: 2: requirements carry numbers (``values`` per axis in SI, ``unit``, ``limits``), a
#: ``status`` (pass / fail / not verified) and a ``provenance``; the verdict is three-valued
#: (``verdict_status``) and ends with ``next_step``. 3: ``values`` are what ``limits`` bound,
#: in one ``unit`` (the two prediction checks give their ratios, no longer rad), named by
#: ``quantity``; the other numbers are in ``other_values``, units in their keys.
SUMMARY_FORMAT = ("fsmbench.summary", 3)

Provenance = Literal["measured", "derived", "predicted", "assumed", ""]
Status = Literal["pass", "fail", "not verified"]


@dataclass(frozen=True)
class Specification:
    """What the bench must achieve.

    Attributes
    ----------
    sensitivity_bound : float
        Largest |S| at ``objective_frequency_hz`` (ESRF study §6.1: e_max / y_max =
        10 µrad / 0.05 rad = 2e-4).
    objective_frequency_hz : float
        Frequency of the sample motion (ESRF study §6.1: 1 Hz).
    gain_margin_min_db, phase_margin_min_deg : float
        Robustness requirements of the design (6 dB, 30°).
    distance_error_max_m : float
        Largest acceptable Attocube distance error, rms, in m. The ESRF study sets
        none; 5 nm is a few nanometres, the scale the study aims for, and is
        configurable.
    """

    sensitivity_bound: float = 2e-4
    objective_frequency_hz: float = 1.0
    gain_margin_min_db: float = 6.0
    phase_margin_min_deg: float = 30.0
    distance_error_max_m: float = 5e-9


@dataclass(frozen=True)
class Requirement:
    """One requirement against its limit.

    Attributes
    ----------
    name : str
        Identifier (``control_objective`` …).
    description : str
        What is required, in words with units.
    value, limit : str
        What was found and the limit, as a reader sees them.
    passed : bool or None
        None when not verified.
    explanation : str
    link : str
        Anchor of the report chapter.
    values : mapping
        The numbers ``limits`` bound, SI: ``{"h": x, "v": y}`` per axis, or
        ``{"total": x}``.
    unit : str
        Unit of ``values`` and ``limits`` (``"1"`` for dimensionless).
    limits : mapping
        ``{"min": a}``, ``{"max": b}`` or both, in ``unit``.
    quantity : str
        What ``values`` are, an id with the unit in it (``phase_margin_deg``,
        ``simulated_over_predicted``).
    other_values : mapping
        The other numbers behind ``value``, each under an id with its unit
        (``simulated_rms_rad``: ``{"h", "v"}`` [rad]).
    provenance : {"measured", "derived", "predicted", "assumed"}
    provenance_detail : str
        Where the number comes from, in words (which bench it ran on).
    missing : str
        When not verified: what is missing, in words.
    reason : int
        When not verified: its reason's number in the summary's ``reasons``
        (1-based; 0 otherwise), so a reader reads each reason once.
    action : str
        When it fails and the evidence names the cause: what to do first, in words.
    """

    name: str
    description: str
    value: str
    limit: str
    passed: bool | None
    explanation: str = ""
    link: str = ""
    values: Mapping[str, float | None] = field(default_factory=dict)
    unit: str = ""
    limits: Mapping[str, float] = field(default_factory=dict)
    provenance: Provenance = ""
    provenance_detail: str = ""
    missing: str = ""
    reason: int = 0
    action: str = ""
    quantity: str = ""
    other_values: Mapping[str, Any] = field(default_factory=dict)

    @property
    def status(self) -> Status:
        """``pass``, ``fail`` or ``not verified``."""
        if self.passed is None:
            return "not verified"
        return "pass" if self.passed else "fail"

    def to_json(self) -> dict[str, Any]:
        """Numbers first, then the words (``display`` holds what a reader sees)."""
        return {"name": self.name, "description": self.description, "status": self.status,
                "passed": self.passed, "quantity": self.quantity, "values": dict(self.values),
                "unit": self.unit, "limits": dict(self.limits),
                "other_values": dict(self.other_values), "provenance": self.provenance,
                "provenance_detail": self.provenance_detail, "missing": self.missing,
                "reason": self.reason, "action": self.action,
                "display": {"value": self.value, "limit": self.limit},
                "explanation": self.explanation, "link": self.link}


@dataclass(frozen=True)
class PartSkipped:
    """A part of a stage's work left out although its record was read."""

    stage: str
    part: str
    reason: str


@dataclass(frozen=True)
class StageLine:
    """One stage in one line: what it found, where it is in the report."""

    name: str
    status: str  # "ran", "partial", "fallback", "skipped"
    headline: str
    link: str = ""


@dataclass(frozen=True)
class Summary:
    """The study's verdict; see the module docstring."""

    source: str
    is_twin: bool
    meets_specifications: bool | None
    verdict: str
    limiting: str
    requirements: tuple[Requirement, ...]
    stages: tuple[StageLine, ...]
    findings: tuple[str, ...] = ()
    fallbacks: tuple[str, ...] = ()
    skipped: Mapping[str, str] = field(default_factory=dict)
    parts_skipped: tuple[PartSkipped, ...] = ()
    failed_checks: tuple[Check, ...] = ()
    notices: tuple[Notice, ...] = ()
    specification: Specification = field(default_factory=Specification)
    verdict_status: str = "not_verified"
    next_step: str = ""
    simulated_bench: str = ""
    reasons: tuple[str, ...] = ()

    def to_json(self) -> dict[str, Any]:
        """``summary.json``: format name and version first, then the verdict."""
        out: dict[str, Any] = {
            "format": SUMMARY_FORMAT[0], "format_version": SUMMARY_FORMAT[1],
            "fsmbench_version": __version__, "source": self.source, "is_twin": self.is_twin,
            "meets_specifications": self.meets_specifications,
            "verdict_status": self.verdict_status, "verdict": self.verdict,
            "next_step": self.next_step, "reasons": list(self.reasons),
            "simulated_bench": self.simulated_bench,
            "limiting": self.limiting,
            "requirements": [r.to_json() for r in self.requirements],
            "stages": [asdict(s) for s in self.stages],
            "findings": list(self.findings), "fallbacks": list(self.fallbacks),
            "skipped": dict(self.skipped), "parts_skipped": [asdict(p) for p in self.parts_skipped],
            "failed_checks": [c.to_json() for c in self.failed_checks],
            "notices": [n.to_json() for n in self.notices],
            "specification": asdict(self.specification),
        }
        result: dict[str, Any] = plain_json(out)
        return result


# How a budget row reaches the distance, in words (budget.table's mechanism keys).
_MECHANISM_WORDS = {
    "linear": "adds to the measured distance directly",
    "piston (4.2) + geometric (4.1)": ("moves the beam angle, which the distance sees through "
                                        "mirror piston (4.2) and the path geometry (4.1)"),
    "geometric (4.1)": "enters through the path geometry (4.1), quadratically",
}


def _pair(values: Mapping[str, float], spec: str, scale: float = 1.0) -> str:
    return " / ".join(format(values[a] * scale, spec) for a in ("h", "v") if a in values)


def _hv(values: Mapping[str, Any]) -> dict[str, float | None]:
    out: dict[str, float | None] = {}
    for a in ("h", "v"):
        v = values.get(a)
        out[a] = None if v is None else float(v)
    return out


def _plant_words(plant_identified: bool, plant_source: str) -> tuple[Provenance, str]:
    if plant_identified:
        return "derived", ("the plant identified from the recordings (the study's section 2) "
                           "and the controller")
    return "assumed", f"the {plant_source}, not an identified plant"


def _loop_requirements(design: Mapping[str, Any], spec: Specification, *,
                       plant_identified: bool, plant_source: str,
                       plant_missing: str = "") -> list[Requirement]:
    """The control requirements, from ``design.json``'s payload.

    ``plant_missing``: the loop's blocks left nominal in an identified plant, in words
    (the 4QD calibration, the current amplifier): then the rows are not verified either.
    """
    prov, detail = _plant_words(plant_identified and not plant_missing, plant_source)
    # Judged on a model no recording checked, a control number is not verified.
    missing = ("an identified plant (data_uch, data_ucv)" if not plant_identified
               else plant_missing)

    def judged(ok: bool) -> bool | None:
        return ok if plant_identified and not plant_missing else None

    out: list[Requirement] = []
    fsm = design["fsmbench_controller"]
    s1 = {a: float(fsm[a]["sensitivity_at_1hz"]) for a in ("h", "v")}
    worst = max(s1.values())
    out.append(Requirement(
        name="control_objective",
        description=(f"Sample motion rejected at {spec.objective_frequency_hz:g} Hz: |S| "
                     "with fsmbench's controller, h / v (ESRF study §6.1)"),
        value=_pair(s1, ".2e"), limit=f"≤ {spec.sensitivity_bound:.0e}",
        passed=judged(worst <= spec.sensitivity_bound),
        explanation=(f"The 0.05 rad stroke at 1 Hz leaves {worst * 0.05 * 1e6:.1f} µrad of "
                     "beam-angle error (the ESRF study's maximum wanted error is 10 µrad)."),
        link="#decentralised-control", values=_hv(s1), unit="1",
        limits={"max": spec.sensitivity_bound}, provenance=prov, provenance_detail=detail,
        missing=missing, quantity="sensitivity_at_1hz"))
    stable = {a: bool(fsm[a]["stable"]) for a in ("h", "v")}
    gm = {a: float(fsm[a]["gain_margin_db"] if fsm[a]["gain_margin_db"] is not None
                   else math.inf) for a in ("h", "v")}
    pm = {a: float(fsm[a]["phase_margin_deg"] if fsm[a]["phase_margin_deg"] is not None
                   else math.inf) for a in ("h", "v")}
    unstable = "" if all(stable.values()) else (
        "Unstable on " + " and ".join(a for a in "hv" if not stable[a]) + ": the margins "
        "of an unstable loop mean nothing.")
    out.append(Requirement(
        name="gain_margin",
        description="fsmbench's controller: closed loop stable, gain margin, h / v",
        value=f"{_pair(gm, '.1f')} dB", limit=f"≥ {spec.gain_margin_min_db:g} dB",
        passed=judged(all(stable.values()) and min(gm.values()) >= spec.gain_margin_min_db),
        explanation=unstable, link="#decentralised-control",
        values={a: (gm[a] if math.isfinite(gm[a]) else None) for a in "hv"}, unit="dB",
        limits={"min": spec.gain_margin_min_db}, provenance=prov, provenance_detail=detail,
        missing=missing, quantity="gain_margin_db"))
    out.append(Requirement(
        name="phase_margin",
        description="fsmbench's controller: closed loop stable, phase margin, h / v",
        value=f"{_pair(pm, '.1f')}°", limit=f"≥ {spec.phase_margin_min_deg:g}°",
        passed=judged(all(stable.values()) and min(pm.values()) >= spec.phase_margin_min_deg),
        explanation=unstable, link="#decentralised-control",
        values={a: (pm[a] if math.isfinite(pm[a]) else None) for a in "hv"}, unit="deg",
        limits={"min": spec.phase_margin_min_deg}, provenance=prov, provenance_detail=detail,
        missing=missing, quantity="phase_margin_deg"))
    rob = design.get("robustness") or {}
    if rob:
        n = len(rob.get("cases", []))
        n_unstable = sum(1 for c in rob.get("cases", []) if c.get("stable") is False)
        out.append(Requirement(
            name="robust_stability",
            description=("fsmbench's controller stays stable with the resonances ±5 % and the "
                         "damping ×0.5 and ×2"),
            value=(f"{n - n_unstable} of {n} perturbed plants stable, worst gain margin "
                   f"{rob['worst_gain_margin_db']:.1f} dB"),
            limit="all stable", passed=judged(bool(rob["all_stable"])),
            link="#decentralised-control",
            values={"unstable_plants": float(n_unstable)}, unit="1", limits={"max": 0.0},
            quantity="unstable_plants",
            other_values={"perturbed_plants": float(n),
                          "worst_gain_margin_db": float(rob["worst_gain_margin_db"])},
            provenance=prov, provenance_detail=detail + " over the perturbed plants",
            missing=missing))
    return out


def _closed_loop_requirement(design: Mapping[str, Any], *, is_twin: bool) -> Requirement:
    twin = design.get("closed_loop_twin")
    description = ("fsmbench's controller simulated in closed loop (converter quantisation, "
                   "every noise): tracking error, and its ratio to the linear prediction, h / v")
    if not twin:
        why = design.get("closed_loop_skipped") or "no bench to simulate"
        return Requirement(
            name="closed_loop_simulation", description=description, value="not simulated",
            limit="simulated / predicted within 0.9–1.1", passed=None,
            link="#decentralised-control", unit="1", limits={"min": 0.9, "max": 1.1},
            quantity="simulated_over_predicted", provenance="predicted",
            missing=f"a bench identified from the recordings ({why})")
    ratio = twin["measured_over_predicted"]
    ok = all(0.9 <= float(r) <= 1.1 for r in ratio.values())
    qd = twin["predicted_parts_rad"]
    share = {a: (qd[a].get("qd_noise", 0.0) / twin["predicted_rms_rad"][a]) ** 2
             for a in ("h", "v")}
    bench = twin.get("bench") or "the packaged twin"
    kind = twin.get("bench_kind", "packaged")
    where = (f"simulated on {bench}, the bench the twin data came from" if is_twin
             else f"simulated on {bench}")
    if kind == "packaged" and not is_twin:
        where += " (NOT the bench of these recordings)"
    return Requirement(
        name="closed_loop_simulation", description=description,
        value=(f"{_pair(twin['tracking_error_rms_rad'], '.3g', 1e6)} µrad rms simulated, "
               f"{_pair(twin['predicted_rms_rad'], '.3g', 1e6)} linear; ratio "
               f"{_pair(ratio, '.2f')}"),
        limit="simulated / predicted within 0.9–1.1", passed=ok,
        explanation=(f"Predicted: {where}. The 4QD's own noise makes {_pair(share, '.0%')} of "
                     "the variance: the loop cannot reject what its sensor adds."),
        link="#decentralised-control", values=_hv(ratio), unit="1",
        limits={"min": 0.9, "max": 1.1}, quantity="simulated_over_predicted",
        other_values={"simulated_rms_rad": _hv(twin["tracking_error_rms_rad"]),
                      "predicted_rms_rad": _hv(twin["predicted_rms_rad"])},
        provenance="predicted", provenance_detail=where)


def _validation_requirement(validation: Any, skipped: str) -> Requirement:
    description = ("The model predicts your own closed loop: data_rep_h/v tracking error "
                   "(ESRF study's controller, periodic motion removed), recorded against "
                   "predicted, "
                   "h / v")
    if validation is None:
        return Requirement(
            name="model_validation", description=description, value="not compared",
            limit="recorded / predicted within 0.8–1.25", passed=None, link="#validation",
            unit="1", limits={"min": 0.8, "max": 1.25}, quantity="recorded_over_predicted",
            provenance="measured",
            missing=skipped or "data_rep_h, data_rep_v and an identified bench")
    v = validation
    lo, hi = v.band_hz
    return Requirement(
        name="model_validation", description=description,
        value=(f"{_pair(v.measured_rms_rad, '.3g', 1e6)} µrad rms recorded, "
               f"{_pair(v.predicted_rms_rad, '.3g', 1e6)} predicted; ratio "
               f"{_pair(v.ratio, '.2f')}"
               + (f"; plant output error {plant.check.value_words()} the noise"
                  if (plant := getattr(v, "plant_check", None)) is not None else "")),
        limit=(f"recorded / predicted within {v.limits[0]:g}–{v.limits[1]:g}"
               + (", widened by the records' scatter to " + " / ".join(
                   f"{band[0]:.2f}–{band[1]:.2f}" for band in accepted.values())
                  if (accepted := getattr(v, "accepted", None)) else "")
               + (f"; under a DAC dead band, the plant output error {plant.check.limit}"
                  if plant is not None and len(getattr(v, "dead_band_axes", ())) > 0 else "")),
        passed=v.passed,
        explanation=(f"{lo:g} Hz to {hi:g} Hz, {v.n_periods} periods; predicted by simulating "
                     f"{', '.join(v.experiments)} on {v.bench} with {v.controller}."
                     + (f" {v.reason}." if v.reason else "")),
        link="#validation", values=_hv(v.ratio), unit="1",
        limits={"min": v.limits[0], "max": v.limits[1]}, quantity="recorded_over_predicted",
        other_values={"recorded_rms_rad": _hv(v.measured_rms_rad),
                      "predicted_rms_rad": _hv(v.predicted_rms_rad),
                      **({"accepted": {a: {"min": float(lo_hi[0]), "max": float(lo_hi[1])}
                                       for a, lo_hi in accepted.items()}}
                         if (accepted := getattr(v, "accepted", None)) else {})},
        provenance="measured",
        provenance_detail=f"recorded in {', '.join(v.experiments)}; compared with {v.bench}",
        action=v.action)


def _distance_requirement(budget: Any, spec: Specification) -> tuple[Requirement, str, Any]:
    quoted = budget.quoted
    b = quoted.budget
    total = float(b.total_rms_m)
    limit = spec.distance_error_max_m
    top = max(b.rows, key=lambda r: r.rms_m)
    how = _MECHANISM_WORDS.get(top.mechanism, top.mechanism)
    window = "stationary" if b.window_s is None else f"over {b.window_s:g} s, mean removed"
    measured_inputs = [r.name for r in b.rows if getattr(r, "provenance", "") == "measured"]
    assumed = [r for r in b.rows if getattr(r, "provenance", "") == "assumed"]
    assumed_share = sum(r.rms_m**2 for r in assumed) / total**2 if total > 0 else 0.0
    other = "" if budget.recommended is None else (
        f" With {budget.controller}: {budget.budget.total_rms_m * 1e9:.3g} nm.")
    huddle = getattr(budget, "huddle", None)
    measured = huddle is not None and getattr(huddle, "qd_noise", None) is not None
    # A budget whose own huddle tests contradict it is not a verdict.
    contradicted = [c for c in getattr(budget, "checks", ())
                    if not c.passed and c.name in ("huddle_va_vs_prediction", "huddle_qd_vs_model")]
    verified = measured and not contradicted
    explanation = (
        f"With {quoted.controller}, {window}; stationary value "
        f"{quoted.stationary_total_rms_m * 1e9:.3g} nm (a record much longer than the slowest "
        f"drift). Limiting source: {top.name} ({top.rms_m * 1e9:.3g} nm, "
        f"{(top.rms_m / total) ** 2:.0%} of the variance, "
        f"{getattr(top, 'provenance', 'derived')}); it {how}. Assumed terms (bench file, no "
        f"recording checked them) make {assumed_share:.0%} of the variance.{other}")
    req = Requirement(
        name="distance_error_budget",
        description=(f"Attocube distance error {window}, every source combined (rms), with "
                     f"{quoted.controller}"),
        value=f"{total * 1e9:.3g} nm", limit=f"≤ {limit * 1e9:g} nm",
        passed=(total <= limit) if verified else None, explanation=explanation,
        link="#error-budget", values={"total": total}, unit="m", limits={"max": limit},
        quantity="distance_error_rms_m", provenance="predicted",
        provenance_detail=("budget of measured inputs (" + ", ".join(measured_inputs)
                           + ") and assumed ones (" + ", ".join(r.name for r in assumed) + ")"
                           if measured_inputs else
                           "budget of the bench file's noise levels alone (no measured input)"),
        missing="" if verified else (
            "huddle tests that agree with the budget (" + "; ".join(
                f"{c.subject}: {c.advice}" for c in contradicted) + ")" if contradicted
            else "an open-loop huddle test (the measured 4QD noise)"))
    limiting = (f"{top.name}, {top.rms_m * 1e9:.3g} nm of the {total * 1e9:.3g} nm total "
                f"({getattr(top, 'provenance', 'derived')}): it {how}.")
    return req, limiting, top


def _plant_advice(plant_source: str, skipped: Mapping[str, str]) -> str:
    """What the user does so that the next run identifies the plant (a fallback's fix)."""
    sercalo = [n for n in ("data_uch", "data_ucv") if n in skipped]
    near = [skipped[n].split("; found ", 1)[1] for n in sercalo if "; found " in skipped[n]]
    if near:
        return "rename " + "; ".join(near) + ", then run the study again."
    refused = [f"{n} ({skipped[n]})" for n in sercalo if not skipped[n].startswith(f"no {n}.")]
    if refused:
        return "correct " + "; ".join(refused) + ", then run the study again."
    if sercalo:
        return ("record " + " and ".join(sercalo) + " (noise on each coil command with the "
                "4QD outputs, ESRF study 2.2–2.3), then run the study again.")
    if "warnings" in plant_source:
        return ("the failed checks listed below name each file and the likely cause: correct "
                "those files or record them again.")
    return "chapter 2 (identification) names the step that failed and why."


@dataclass(frozen=True, eq=False)
class StudyEvidence:
    """What the study's stages found: the verdict's one input beside the requirements.

    Attributes
    ----------
    source : str
        Where the data came from, in words.
    is_twin : bool
    skipped : mapping
        Experiment → why it was not used.
    parts_skipped : sequence of PartSkipped
        What a stage left out of a record it had, and why.
    n_experiments, n_read : int
        Experiments the study knows, experiments read.
    checks, notices : sequences
        Every plausibility check and notice of every stage.
    identification : mapping or None
        ``{"ran": bool, "warnings": [...], "skipped": {...}}`` of the identification.
    identification_headline : str
        One line on what was identified.
    plant_source : str
        Which plant the budget and design used, with the reason of any fallback.
    plant_identified : bool
    plant_missing : str
        The loop's blocks the identification left nominal, in words (empty: none).
    disturbance_missing : str
        The Newport's block when the identification left it to the bench file, with
        why (empty: identified): the distance budget, the closed-loop simulation and
        the model's check rest on it, so they are *assumed* and not verified.
    budget : BudgetResult or None
    design : mapping or None
        ``design.json``'s payload.
    validation : ClosedLoopValidation or None
        The model's check on the recorded closed loop.
    validation_skipped : str
        Why there is none.
    simulated_bench : str
        The bench the study's simulations ran on, in words.
    montecarlo : mapping, optional
        ``montecarlo.json``'s content: a requirement broken by ≥ 5 % of its draws is
        named in the robustness row (or in the findings without one).
    """

    source: str
    is_twin: bool
    skipped: Mapping[str, str]
    n_experiments: int
    n_read: int
    identification: Mapping[str, Any] | None
    plant_source: str
    plant_identified: bool
    budget: Any | None
    design: Mapping[str, Any] | None
    parts_skipped: Sequence[PartSkipped] = ()
    checks: Sequence[Check] = ()
    notices: Sequence[Notice] = ()
    identification_headline: str = ""
    plant_missing: str = ""
    disturbance_missing: str = ""
    validation: Any | None = None
    validation_skipped: str = ""
    simulated_bench: str = ""
    montecarlo: Mapping[str, Any] | None = None


def _reading_stages(e: StudyEvidence) -> list[StageLine]:
    """The recordings' and the identification's lines of the stages table."""
    stages = []
    read = f"{e.n_read} of {e.n_experiments} experiments read"
    stages.append(StageLine("recordings", "ran" if not e.skipped else "partial",
                            read + (f"; {len(e.skipped)} not used (listed below)" if e.skipped
                                    else ""), "#bench"))
    identification = e.identification
    if identification is None or not identification.get("ran"):
        stages.append(StageLine("identification", "skipped",
                                "not run: none of its experiments is usable", "#identification"))
        return stages
    warn = identification.get("warnings") or []
    part = identification.get("skipped") or {}
    status = "ran" if not warn and not part else "partial"
    text = e.identification_headline or "ran"
    if part:
        text += "; skipped: " + "; ".join(f"{k} ({v})" for k, v in part.items())
    if warn:
        text += f"; {len(warn)} quality warning(s)"
    stages.append(StageLine("identification", status, text, "#identification"))
    return stages


def _design_requirements(e: StudyEvidence, spec: Specification,
                         findings: list[str]) -> list[Requirement]:
    """The loops' requirements and the closed loop's, from ``design.json``; the ESRF study's
    controller missing its own objective added to ``findings``."""
    design = e.design
    assert design is not None
    reqs = _loop_requirements(design, spec, plant_identified=e.plant_identified,
                              plant_source=e.plant_source, plant_missing=e.plant_missing)
    reqs.append(_closed_loop_requirement(design, is_twin=e.is_twin))
    seed = design["seed_controller"]
    s_seed = {a: float(seed[a]["sensitivity_at_1hz"]) for a in ("h", "v")}
    if not seed.get("meets_objective"):
        findings.append(
            "The ESRF study's decentralised controller (9.2) misses its own objective: |S(1 "
            "Hz)| "
            f"= {_pair(s_seed, '.1e')} against {spec.sensitivity_bound:.0e} (errata E27); "
            "fsmbench's controller meets it.")
    return reqs


def _design_stage(design: Mapping[str, Any]) -> StageLine:
    """The design's line of the stages table: fsmbench's controller's |S(1 Hz)| and
    crossovers."""
    fsm = design["fsmbench_controller"]
    s1 = {a: fsm[a]["sensitivity_at_1hz"] for a in "hv"}
    return StageLine(
        "design", "ran",
        f"fsmbench's controller: |S(1 Hz)| {_pair(s1, '.1e')}, crossover "
        f"{_pair({a: fsm[a]['crossover_hz'] for a in 'hv'}, '.0f')} Hz",
        "#decentralised-control")


def build_summary(evidence: StudyEvidence, *, spec: Specification) -> Summary:
    """The verdict of a study on its evidence, against ``spec``'s requirements.

    Parameters
    ----------
    evidence : StudyEvidence
        What the stages found.
    spec : Specification
        The requirements.
    """
    e = evidence
    source, is_twin, skipped, parts_skipped = e.source, e.is_twin, e.skipped, e.parts_skipped
    checks, notices = e.checks, e.notices
    plant_source, plant_identified = e.plant_source, e.plant_identified
    budget, design = e.budget, e.design
    disturbance_missing, validation = e.disturbance_missing, e.validation
    validation_skipped, simulated_bench, montecarlo = (e.validation_skipped,
                                                       e.simulated_bench, e.montecarlo)
    reqs: list[Requirement] = []
    stages: list[StageLine] = []
    findings: list[str] = []
    fallbacks: list[str] = []
    stages += _reading_stages(e)
    if not plant_identified:
        fallbacks.append(f"The budget and the design used the {plant_source}. What to do: "
                         + _plant_advice(plant_source, skipped))
    top = None
    if budget is not None:
        req, limiting, top = _distance_requirement(budget, spec)
        reqs.append(req)
        stages.append(StageLine(
            "budget", "ran" if not budget.skipped else "partial",
            f"distance error {budget.quoted.budget.total_rms_m * 1e9:.3g} nm rms with "
            f"{budget.quoted.controller}; limiting source {top.name}", "#error-budget"))
    else:
        stages.append(StageLine("budget", "skipped", "not run", "#error-budget"))
        limiting = "unknown: the budget did not run"
    if design is not None:
        reqs += _design_requirements(e, spec, findings)
        stages.append(_design_stage(design))
    else:
        stages.append(StageLine("design", "skipped", "not run", "#decentralised-control"))
    if design is not None or validation is not None:
        reqs.append(_validation_requirement(validation, validation_skipped))
    if montecarlo is not None:
        reqs = _with_montecarlo(reqs, montecarlo, findings)
    if disturbance_missing and plant_identified:
        reqs = [_assumed(r, disturbance_missing) if r.name in _DISTURBANCE_ROWS else r
                for r in reqs]
        fallbacks.append(f"The distance budget, the closed-loop simulation and the model's "
                         f"check used the bench file's {disturbance_missing}: they are not "
                         "verified until it is identified.")
    status, verdict = _verdict(reqs, plant_identified=plant_identified)
    failed_checks = tuple(c for c in checks if not c.passed)
    contradictions = [c for c in failed_checks if c.name not in FINDINGS]
    reqs, reasons = _reasons(reqs)
    if status == "meets" and contradictions:
        first = contradictions[0]
        status = "not_verified"
        verdict = (f"Not verified: {len(contradictions)} check(s) of the recordings failed, "
                   f"first on {first.subject}")
        reasons = (*reasons, *(c.sentence() for c in contradictions))
    step = next_step(status=status, requirements=reqs, budget=budget, limiting_row=top,
                     skipped=skipped, failed_checks=contradictions)
    if status == "not_verified":
        verdict = _headline(verdict, step)
    return Summary(source=source, is_twin=is_twin,
                   meets_specifications={"meets": True, "does_not_meet": False}.get(status),
                   verdict=verdict, limiting=limiting, requirements=tuple(reqs),
                   stages=tuple(stages), findings=tuple(findings), fallbacks=tuple(fallbacks),
                   skipped=dict(skipped), parts_skipped=tuple(parts_skipped),
                   failed_checks=failed_checks, notices=tuple(notices), specification=spec,
                   verdict_status=status, next_step=step, simulated_bench=simulated_bench,
                   reasons=tuple(reasons))


def _with_montecarlo(reqs: list[Requirement], montecarlo: Mapping[str, Any],
                     findings: list[str]) -> list[Requirement]:
    """The robustness row with the Monte Carlo's sentence added to its explanation (the
    verdict stays the design's robust set's: the draws are another test of the same)."""

    sentence = robustness_sentence(montecarlo)
    if not sentence:
        return reqs
    if not any(r.name == "robust_stability" for r in reqs):
        findings.append(sentence)
        return reqs
    return [replace(r, explanation=" ".join(x for x in (r.explanation, sentence) if x))
            if r.name == "robust_stability" else r for r in reqs]


#: The requirements whose chain runs through the Newport's block (its drive moves the
#: repeatability runs' beam, its DAC adds noise).
_DISTURBANCE_ROWS = frozenset({"distance_error_budget", "closed_loop_simulation",
                               "model_validation"})


def _assumed(r: Requirement, missing: str) -> Requirement:
    """A requirement whose chain used a bench-file fallback: assumed, not verified."""
    return replace(r, passed=None, provenance="assumed",
                   provenance_detail=(f"assumed: the bench file's {missing}"
                                      + (f"; {r.provenance_detail}" if r.provenance_detail
                                         else "")),
                   missing=f"the identified {missing.split(':')[0]}")


#: Longest headline a reader takes in at once [words]; the reasons follow it.
HEADLINE_WORDS = 30


def _reasons(reqs: Sequence[Requirement]) -> tuple[list[Requirement], tuple[str, ...]]:
    """Each unverified row's reason, listed once: the rows carry its number."""
    reasons: list[str] = []
    out = []
    for r in reqs:
        if r.passed is None and r.missing:
            if r.missing not in reasons:
                reasons.append(r.missing)
            r = replace(r, reason=reasons.index(r.missing) + 1)
        out.append(r)
    return out, tuple(f"missing: {m}" for m in reasons)


def _headline(verdict: str, step: str) -> str:
    """``verdict``'s first clause and the next step's first action, in at most
    :data:`HEADLINE_WORDS` words (the reasons are listed below it, once)."""
    head = verdict.split(" (", 1)[0].rstrip(". ")
    action = step.removeprefix("Next: ").removeprefix("Next, to do better: ")
    for cut in (": ", "; ", " (", ", then"):
        action = action.split(cut, 1)[0]
    words = head.split() + (["— first,", *action.rstrip(".").split()] if action else [])
    if len(words) > HEADLINE_WORDS:
        words = [*words[:HEADLINE_WORDS - 1], "…"]
    return " ".join(words) + "."


def _against(r: Requirement) -> str:
    return f"{r.description}: {r.value} against {r.limit}"


def _verdict(reqs: Sequence[Requirement], *, plant_identified: bool) -> tuple[str, str]:
    """``(status, headline)``: meets / does_not_meet / not_verified, in words."""
    if not reqs:
        return "not_verified", "No verdict: the stages that decide it did not run."
    model = next((r for r in reqs if r.name == "model_validation"), None)
    if model is not None and model.passed is False:
        return "not_verified", ("Not verified: the model identified from the recordings does "
                                "not predict their own closed loop (" + model.value + "); "
                                "every prediction on it is in doubt.")
    failed = [r for r in reqs if r.passed is False]
    if failed:
        return "does_not_meet", ("The bench does NOT meet its specifications: "
                                 + "; ".join(_against(r) for r in failed) + ".")
    open_ = [r for r in reqs if r.passed is None]
    if open_:
        missing = sorted({r.missing for r in open_ if r.missing})
        return "not_verified", ("Not verified: " + ", ".join(r.name.replace("_", " ")
                                                             for r in open_)
                                + " could not be judged (missing: " + "; ".join(missing)
                                + ").")
    dist = next((r for r in reqs if r.name == "distance_error_budget"), None)
    tail = "" if dist is None else f" (distance error {dist.value}, limit {dist.limit})"
    return "meets", ("The bench meets its specifications with fsmbench's controller" + tail
                     + ("." if plant_identified else ", on the nominal model."))
