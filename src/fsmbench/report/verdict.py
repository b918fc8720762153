"""The verdict's first screen and its next step.

:func:`next_step` is computed from the results, never written by hand: the
failing or unverified requirement, the limiting budget row with the changes
that would shrink it (:func:`fsmbench.budget.provenance.remedies`, each with
the total it would leave) and, for a row the bench file only assumed, the
measurement that would replace it. :func:`verdict_html` draws the summary.
"""

from __future__ import annotations

import html
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

from fsmbench.budget.provenance import remedies

if TYPE_CHECKING:
    from fsmbench.checks import Check
    from fsmbench.report.summary import Requirement, Summary

__all__ = ["next_step", "verdict_html"]

_PROVENANCE_WORDS = {"measured": "measured", "derived": "derived from measurements",
                     "predicted": "predicted", "assumed": "assumed from the bench file"}


def _budget_step(budget: Any, row: Any) -> str:
    """The limiting row: what it is, the changes that shrink it, the measurement to replace it."""
    quoted = budget.quoted.budget
    fixes = remedies(quoted.rows, row.name, frame_expansion_per_k=budget.frame.expansion_per_k,
                     bits=int(budget.noise.bits))
    kind = getattr(row, "provenance", "derived")
    head = (f"the limiting source is {row.name} ({row.rms_m * 1e9:.3g} nm, "
            f"{_PROVENANCE_WORDS.get(kind, kind)})")
    parts = [f.sentence() for f in fixes]
    if kind == "assumed" and getattr(row, "replace_by", ""):
        parts.append(f"or measure it: {row.replace_by}")
    return head + (": " + "; ".join(parts) if parts else "") + "."


_IDENT = ("data_cal_pd_h", "data_cal_pd_v", "data_uch", "data_ucv", "data_unh", "data_unv")
#: The recordings each verdict row is judged from (the study's sections 2, 3, 11).
_NEEDS: Mapping[str, tuple[str, ...]] = {
    "control_objective": _IDENT, "gain_margin": _IDENT, "phase_margin": _IDENT,
    "robust_stability": _IDENT, "closed_loop_simulation": _IDENT,  # the Newport's runs too
    "model_validation": (*_IDENT, "data_rep_h", "data_rep_v"),
    "distance_error_budget": (*(f"data_huddle_test_{i}" for i in range(1, 6)), "data_unh",
                              "data_unv"),
}


def _files_step(open_: Sequence[Requirement], skipped: Mapping[str, str],
                failed: Sequence[Check] = ()) -> str:
    """What to do with the files the unjudged rows need: rename, correct, or record them
    (a file read but refused by a failed check: record again, naming the check)."""
    wanted = list(dict.fromkeys(e for r in open_ for e in _NEEDS.get(r.name, ())))
    refused = list(dict.fromkeys(f"{e} ({c.title})" for e in wanted if e not in skipped
                                 for c in failed if c.subject.startswith(f"{e}.mat")))
    needed = [e for e in wanted if e in skipped]
    renames = [skipped[e].split("; found ", 1)[1] for e in needed if "; found " in skipped[e]]
    absent = [e for e in needed if skipped[e].startswith(f"no {e}.")
              and "; found " not in skipped[e]]
    broken = [f"{e} ({skipped[e]})" for e in needed if not skipped[e].startswith(f"no {e}.")]
    parts = ([f"rename the files the study did not recognise ({'; '.join(renames)})"]
             if renames else [])
    parts += [f"correct {'; '.join(broken)}"] if broken else []
    parts += [f"record {', '.join(absent)}"] if absent else []
    parts += [f"record again {'; '.join(refused)}"] if refused else []
    return ", ".join(parts)


def next_step(*, status: str, requirements: Sequence[Requirement], budget: Any | None,
              limiting_row: Any | None, skipped: Mapping[str, str] | None = None,
              failed_checks: Sequence[Check] = ()) -> str:
    """One or two sentences: what to do next, from the results (see the module notes).

    ``skipped``: the recordings the loader could not use (experiment → reason, with the
    near-miss file names it found), so that an unjudged row names the file to rename,
    correct or record; ``failed_checks``: the failed checks, so that a file read but refused is
    named to record again.
    """
    model = next((r for r in requirements if r.name == "model_validation"), None)
    if model is not None and model.passed is False and model.action:
        # The numbers and the mechanism are the model's row: said once, there.
        return (f"Next: {model.action}. The model's row below gives the recorded and "
                "predicted numbers.")
    if model is not None and model.passed is False:
        return ("Next: find why the model misses the recorded loop before trusting any "
                "prediction: " + (model.explanation or model.value) + " Check the 4QD gains "
                "the recorded loop divided by and the huddle tests' noise against the "
                "repeatability records' (section 11).")
    failed = [r for r in requirements if r.passed is False]
    if failed and model is not None and model.action:
        # A verified model whose records name the bench's flaw (a DAC dead band): the
        # flaw is what to fix before any redesign.
        return f"Next: {model.action}. The model's row below says why."
    if failed:
        first = failed[0]
        if first.name == "distance_error_budget" and budget is not None \
                and limiting_row is not None:
            return "Next: " + _budget_step(budget, limiting_row)
        return (f"Next: {first.description} fails ({first.value} against {first.limit}); "
                f"see {first.link or 'the report'} for the loop and redesign with the "
                "identified plant.")
    open_ = [r for r in requirements if r.passed is None]
    if open_:
        files = _files_step(open_, skipped or {}, failed_checks)
        if files:
            return f"Next: {files}, then run the study again."
        missing = sorted({r.missing for r in open_ if r.missing})
        return "Next: record " + "; ".join(missing) + ", then run the study again."
    if status == "not_verified":
        return ("Next: correct or record again the files the failed checks name (listed "
                "below with the likely cause), then run the study again.")
    if budget is not None and limiting_row is not None:
        return "Next, to do better: " + _budget_step(budget, limiting_row)
    return ""


def _mark(passed: bool | None) -> str:
    if passed is None:
        return '<span class="info">NOT VERIFIED</span>'
    return '<span class="pass">PASS</span>' if passed else '<span class="fail">FAIL</span>'


def verdict_html(summary: Summary) -> str:
    """The report's first screen: verdict, requirements, next step, what went wrong."""
    e = html.escape
    cls = {"meets": "pass", "does_not_meet": "fail"}.get(summary.verdict_status, "info")
    out = ['<section class="verdict" id="verdict">',
           f'<h2 class="{cls}">{e(summary.verdict)}</h2>',
           f'<p class="meta">Data: {e(summary.source)}.'
           + (f" Predictions simulated on {e(summary.simulated_bench)}."
              if summary.simulated_bench else "") + "</p>"]
    if summary.next_step:
        out.append(f'<p class="next-step"><b>{e(summary.next_step)}</b></p>')
    if summary.reasons:
        out.append('<p><b>Why not verified:</b></p><ol class="reasons">')
        out += [f'<li id="reason-{i}">{e(r)}</li>' for i, r in enumerate(summary.reasons, 1)]
        out.append("</ol>")
    out.append("<table><thead><tr><th>requirement</th><th>found</th><th>limit</th>"
               "<th>where the number comes from</th><th>verdict</th></tr></thead><tbody>")
    for r in summary.requirements:
        why = f"<br><small>{e(r.explanation)}</small>" if r.explanation else ""
        link = f' <a href="{e(r.link)}">details</a>' if r.link else ""
        origin = _PROVENANCE_WORDS.get(r.provenance, r.provenance)
        detail = f"<br><small>{e(r.provenance_detail)}</small>" if r.provenance_detail else ""
        missing = (f'<br><small><a href="#reason-{r.reason}">reason {r.reason}</a></small>'
                   if r.reason else
                   f"<br><small>missing: {e(r.missing)}</small>" if r.missing else "")
        out.append(f"<tr><td>{e(r.description)}{why}</td><td>{e(r.value)}</td>"
                   f"<td>{e(r.limit)}</td><td>{e(origin)}{detail}</td>"
                   f"<td>{_mark(r.passed)}{missing}{link}</td></tr>")
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
