"""The verdict a reader acts on: does the bench meet its specifications, and why.

:func:`build_summary` reads the stages' results and states, for each of the
bench's requirements (seed Table 5 and §6.1, and a distance target), the
value found, the limit and pass or fail; what limits the performance; every
skipped experiment, failed check and fallback in words; and one headline per
stage. The same :class:`Summary` is written as ``summary.json``, embedded in
the report as ``<script type="application/json" id="fsmbench-summary">`` and
drawn as the report's first screen (:func:`verdict_html`).
"""

from __future__ import annotations

import html
import math
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field
from typing import Any

from fsmbench import __version__
from fsmbench.checks import Check, Notice
from fsmbench.jsonutil import plain_json

__all__ = ["SUMMARY_FORMAT", "PartSkipped", "Requirement", "Specification", "StageLine", "Summary",
           "build_summary", "verdict_html"]

SUMMARY_FORMAT = ("fsmbench.summary", 1)


@dataclass(frozen=True)
class Specification:
    """What the bench must achieve.

    Attributes
    ----------
    sensitivity_bound : float
        Largest |S| at ``objective_frequency_hz`` (seed §6.1: e_max / y_max =
        10 µrad / 0.05 rad = 2e-4).
    objective_frequency_hz : float
        Frequency of the sample motion (seed §6.1: 1 Hz).
    gain_margin_min_db, phase_margin_min_deg : float
        Robustness requirements of the design (6 dB, 30°).
    distance_error_max_m : float
        Largest acceptable Attocube distance error, rms, in m. The seed sets
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
    """One requirement against its measured or predicted value.

    ``passed`` is None when the study could not decide (the stage did not run).
    """

    name: str
    description: str
    value: str
    limit: str
    passed: bool | None
    explanation: str = ""
    link: str = ""


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

    def to_json(self) -> dict[str, Any]:
        """``summary.json``: format name and version first, then the verdict."""
        out: dict[str, Any] = {
            "format": SUMMARY_FORMAT[0], "format_version": SUMMARY_FORMAT[1],
            "fsmbench_version": __version__, "source": self.source, "is_twin": self.is_twin,
            "meets_specifications": self.meets_specifications, "verdict": self.verdict,
            "limiting": self.limiting,
            "requirements": [asdict(r) for r in self.requirements],
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


def _loop_requirements(design: Mapping[str, Any], spec: Specification) -> list[Requirement]:
    """The control requirements, from ``design.json``'s payload."""
    out: list[Requirement] = []
    fsm = design["fsmbench_controller"]
    s1 = {a: float(fsm[a]["sensitivity_at_1hz"]) for a in ("h", "v")}
    worst = max(s1.values())
    out.append(Requirement(
        name="control_objective",
        description=(f"Sample motion rejected at {spec.objective_frequency_hz:g} Hz: |S| "
                     "with fsmbench's controller, h / v (seed §6.1)"),
        value=_pair(s1, ".2e"), limit=f"≤ {spec.sensitivity_bound:.0e}",
        passed=worst <= spec.sensitivity_bound,
        explanation=(f"The 0.05 rad stroke at 1 Hz leaves {worst * 0.05 * 1e6:.1f} µrad of "
                     "beam-angle error (the seed's maximum wanted error is 10 µrad)."),
        link="#decentralised-control"))
    gm = {a: float(fsm[a]["gain_margin_db"] or math.inf) for a in ("h", "v")}
    pm = {a: float(fsm[a]["phase_margin_deg"] or math.inf) for a in ("h", "v")}
    stable = all(bool(fsm[a]["stable"]) for a in ("h", "v"))
    margins_ok = stable and min(gm.values()) >= spec.gain_margin_min_db \
        and min(pm.values()) >= spec.phase_margin_min_deg
    out.append(Requirement(
        name="stability_margins",
        description="fsmbench's controller: closed loop stable, gain and phase margins, h / v",
        value=f"{_pair(gm, '.1f')} dB, {_pair(pm, '.1f')}°",
        limit=f"≥ {spec.gain_margin_min_db:g} dB and ≥ {spec.phase_margin_min_deg:g}°",
        passed=margins_ok, link="#decentralised-control"))
    rob = design.get("robustness") or {}
    if rob:
        out.append(Requirement(
            name="robust_stability",
            description=("fsmbench's controller stays stable with the resonances ±5 % and the "
                         "damping ×0.5 and ×2"),
            value=(f"{'all' if rob['all_stable'] else 'not all'} "
                   f"{len(rob.get('cases', []))} perturbed plants stable, worst gain margin "
                   f"{rob['worst_gain_margin_db']:.1f} dB"),
            limit="all stable", passed=bool(rob["all_stable"]), link="#decentralised-control"))
    return out


def _twin_requirement(design: Mapping[str, Any]) -> Requirement | None:
    twin = design.get("closed_loop_twin")
    if not twin:
        return None
    ratio = twin["measured_over_predicted"]
    ok = all(0.9 <= float(r) <= 1.1 for r in ratio.values())
    qd = twin["predicted_parts_rad"]
    share = {a: (qd[a].get("qd_noise", 0.0) / twin["predicted_rms_rad"][a]) ** 2
             for a in ("h", "v")}
    return Requirement(
        name="closed_loop_on_the_twin",
        description=("fsmbench's controller run on the twin at 10 kHz (16-bit converters, every "
                     "noise): tracking error measured against the linear prediction, h / v"),
        value=(f"{_pair(twin['tracking_error_rms_rad'], '.3g', 1e6)} µrad rms measured, "
               f"{_pair(twin['predicted_rms_rad'], '.3g', 1e6)} predicted"),
        limit="measured / predicted within 0.9–1.1", passed=ok,
        explanation=(f"The 4QD's own noise makes {_pair(share, '.0%')} of the predicted "
                     "variance: the loop cannot reject what its sensor adds."),
        link="#decentralised-control")


def build_summary(*, source: str, is_twin: bool, spec: Specification,
                  skipped: Mapping[str, str], n_experiments: int, n_read: int,
                  parts_skipped: Sequence[PartSkipped] = (),
                  checks: Sequence[Check] = (), notices: Sequence[Notice] = (),
                  identification: Mapping[str, Any] | None,
                  identification_headline: str = "",
                  plant_source: str, plant_identified: bool,
                  budget: Any | None, design: Mapping[str, Any] | None) -> Summary:
    """The verdict of a study.

    Parameters
    ----------
    source : str
        Where the data came from, in words.
    is_twin : bool
    spec : Specification
    skipped : mapping
        Experiment → why it was not used.
    parts_skipped : sequence of PartSkipped
        What a stage left out of a record it had (a huddle test too short to
        analyse …), and why.
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
    budget : BudgetResult or None
    design : mapping or None
        ``design.json``'s payload.
    """
    reqs: list[Requirement] = []
    stages: list[StageLine] = []
    findings: list[str] = []
    fallbacks: list[str] = []
    read = f"{n_read} of {n_experiments} experiments read"
    stages.append(StageLine("recordings", "ran" if not skipped else "partial",
                            read + (f"; {len(skipped)} not used (listed below)" if skipped
                                    else ""), "#bench"))
    if identification is None or not identification.get("ran"):
        stages.append(StageLine("identification", "skipped",
                                "not run: none of its experiments is usable", "#identification"))
    else:
        warn = identification.get("warnings") or []
        part = identification.get("skipped") or {}
        status = "ran" if not warn and not part else "partial"
        text = identification_headline or "ran"
        if part:
            text += "; skipped: " + "; ".join(f"{k} ({v})" for k, v in part.items())
        if warn:
            text += f"; {len(warn)} quality warning(s)"
        stages.append(StageLine("identification", status, text, "#identification"))
    if not plant_identified:
        fallbacks.append(f"The budget and the design used the {plant_source}.")
    if budget is not None:
        b = budget.budget
        total = float(b.total_rms_m)
        limit = spec.distance_error_max_m
        top = max(b.rows, key=lambda r: r.rms_m)
        how = _MECHANISM_WORDS.get(top.mechanism, top.mechanism)
        reqs.append(Requirement(
            name="distance_error_budget",
            description="Attocube distance error, every source combined (rms)",
            value=f"{total * 1e9:.3g} nm", limit=f"≤ {limit * 1e9:g} nm",
            passed=total <= limit,
            explanation=(f"Limiting source: {top.name} ({top.rms_m * 1e9:.3g} nm, "
                         f"{(top.rms_m / total) ** 2:.0%} of the variance); it {how}."),
            link="#error-budget"))
        stages.append(StageLine("budget", "ran" if not budget.skipped else "partial",
                                f"distance error {total * 1e9:.3g} nm rms; limiting source "
                                f"{top.name}", "#error-budget"))
        limiting = (f"{top.name}, {top.rms_m * 1e9:.3g} nm of the {total * 1e9:.3g} nm total: "
                    f"it {how}.")
    else:
        stages.append(StageLine("budget", "skipped", "not run", "#error-budget"))
        limiting = "unknown: the budget did not run"
    if design is not None:
        reqs += _loop_requirements(design, spec)
        twin = _twin_requirement(design)
        if twin is not None:
            reqs.append(twin)
        seed = design["seed_controller"]
        s_seed = {a: float(seed[a]["sensitivity_at_1hz"]) for a in ("h", "v")}
        if not seed.get("meets_objective"):
            findings.append(
                f"The seed's decentralised controller (9.2) misses its own objective: |S(1 Hz)| "
                f"= {_pair(s_seed, '.1e')} against {spec.sensitivity_bound:.0e} (errata E27); "
                "fsmbench's controller meets it.")
        fsm = design["fsmbench_controller"]
        stages.append(StageLine(
            "design", "ran",
            f"fsmbench's controller: |S(1 Hz)| {_pair({a: fsm[a]['sensitivity_at_1hz'] for a in 'hv'}, '.1e')}, "  # noqa: E501
            f"crossover {_pair({a: fsm[a]['crossover_hz'] for a in 'hv'}, '.0f')} Hz",
            "#decentralised-control"))
    else:
        stages.append(StageLine("design", "skipped", "not run", "#decentralised-control"))
    decided = [r.passed for r in reqs if r.passed is not None]
    meets = None if not decided else all(decided)
    failed_names = [r.description for r in reqs if r.passed is False]
    if meets is None:
        verdict = "No verdict: the stages that decide it did not run."
    elif meets:
        verdict = ("The bench meets its specifications with fsmbench's controller"
                   + (" (on the nominal model, not an identified one)." if not plant_identified
                      else "."))
    else:
        verdict = "The bench does NOT meet its specifications: " + "; ".join(failed_names) + "."
    failed_checks = tuple(c for c in checks if not c.passed)
    return Summary(source=source, is_twin=is_twin, meets_specifications=meets, verdict=verdict,
                   limiting=limiting, requirements=tuple(reqs), stages=tuple(stages),
                   findings=tuple(findings), fallbacks=tuple(fallbacks), skipped=dict(skipped),
                   parts_skipped=tuple(parts_skipped),
                   failed_checks=failed_checks, notices=tuple(notices), specification=spec)


def _mark(passed: bool | None) -> str:
    if passed is None:
        return '<span class="info">not decided</span>'
    return '<span class="pass">PASS</span>' if passed else '<span class="fail">FAIL</span>'


def verdict_html(summary: Summary) -> str:
    """The report's first screen: verdict, requirements, limiting source, what went wrong."""
    e = html.escape
    cls = {True: "pass", False: "fail", None: "info"}[summary.meets_specifications]
    out = ['<section class="verdict" id="verdict">',
           f'<h2 class="{cls}">{e(summary.verdict)}</h2>',
           f'<p class="meta">Data: {e(summary.source)}.</p>',
           "<table><thead><tr><th>requirement</th><th>found</th><th>limit</th><th>verdict</th>"
           "</tr></thead><tbody>"]
    for r in summary.requirements:
        why = f"<br><small>{e(r.explanation)}</small>" if r.explanation else ""
        link = f' <a href="{e(r.link)}">details</a>' if r.link else ""
        out.append(f"<tr><td>{e(r.description)}{why}</td><td>{e(r.value)}</td>"
                   f"<td>{e(r.limit)}</td><td>{_mark(r.passed)}{link}</td></tr>")
    out.append("</tbody></table>")
    out.append(f"<p><b>What limits the performance:</b> {e(summary.limiting)}</p>")
    for finding in summary.findings:
        out.append(f"<p>{e(finding)}</p>")
    problems = [*summary.fallbacks,
                *(f"{name}: {why}" for name, why in summary.skipped.items()),
                *(f"{p.stage}, {p.part}: {p.reason}" for p in summary.parts_skipped),
                *(c.sentence() for c in summary.failed_checks),
                *(n.sentence() for n in summary.notices)]
    if problems:
        out.append('<p><b>Skipped, fallbacks and warnings:</b></p><ul class="skips">')
        out += [f"<li>{e(p)}</li>" for p in problems]
        out.append("</ul>")
    else:
        out.append("<p>Every experiment was read and used; no check failed; nothing fell back.</p>")
    out.append("<table><thead><tr><th>stage</th><th>status</th><th>headline</th></tr></thead>"
               "<tbody>")
    for s in summary.stages:
        name = f'<a href="{e(s.link)}">{e(s.name)}</a>' if s.link else e(s.name)
        out.append(f"<tr><td>{name}</td><td>{e(s.status)}</td><td>{e(s.headline)}</td></tr>")
    out.append("</tbody></table></section>")
    return "\n".join(out)
