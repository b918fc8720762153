"""The sign diagnosis in the words a user reads: checks, findings and the bench they imply.

:func:`~fsmbench.ident.evidence.signs.explain_signs` gives every explanation of
one axis's path signs with the fewest causes. This module turns them into
what the identification acts on:

* the records agree with the bench file: a passed ``signs_across_records``;
* one explanation with bench signs only: each sign is a :class:`Finding` with
  its bench-file key, and the bench the identification works with has it
  (:func:`with_signs`), so every step's model carries the bench's real signs;
* explanations with bench signs only beside ones with a flipped record: the
  records cannot tell them apart; the bench-only one is taken (the records are
  the evidence, a flip is a second event), each finding names the alternative
  and the record that would separate them; nothing is blocked;
* every explanation flips a record: the records contradict each other; a
  failed ``signs_across_records`` names every explanation and is attached to
  the records they concern, so the steps using them fall back. Advice that
  changes data (negate a signal) only when one explanation remains.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Final

from fsmbench.bench.axes import PerAxis
from fsmbench.bench.params import BenchParams
from fsmbench.checks import Check, Finding, Notice
from fsmbench.ident.evidence.signs import SignCause, SignDiagnosis, SignObservation, explain_signs

__all__ = ["SignOutcome", "diagnose_signs", "with_signs"]

#: The record that would separate a flip in a record from a bench sign, by record.
_SEPARATES: Final = {
    "data_uch": "a closed-loop record (data_huddle_test_3 or 5, data_rep_h): the loop ran "
                "stable only with the controller's sign matching the Sercalo's",
    "data_ucv": "a closed-loop record (data_huddle_test_3 or 5, data_rep_v): the loop ran "
                "stable only with the controller's sign matching the Sercalo's",
    "data_cal_pd_h": "data_rep_h, whose Vnh against Unh gives the Newport's metrology sign",
    "data_cal_pd_v": "data_rep_v, whose Vnv against Unv gives the Newport's metrology sign",
    "data_unh": "data_rep_h, whose Vnh against Unh gives the Newport's drive sign",
    "data_unv": "data_rep_v, whose Vnv against Unv gives the Newport's drive sign",
}
_AXIS_WORDS: Final = {"h": "horizontal", "v": "vertical"}


@dataclass(frozen=True)
class SignOutcome:
    """What the sign diagnosis of both axes gives the identification.

    Attributes
    ----------
    diagnoses : tuple of SignDiagnosis
    checks : tuple of Check
        One ``signs_across_records`` per axis judged.
    by_experiment : dict of str to tuple of Check
        The failed checks each record answers for.
    findings : tuple of Finding
        The bench signs the records give, with their keys.
    notices : tuple of Notice
    params : BenchParams
        The bench file's nominal parameters with the found signs.
    """

    diagnoses: tuple[SignDiagnosis, ...]
    checks: tuple[Check, ...]
    by_experiment: dict[str, tuple[Check, ...]]
    findings: tuple[Finding, ...]
    notices: tuple[Notice, ...]
    params: BenchParams


def _flip_axis(value: PerAxis, axis: str) -> PerAxis:
    return dataclasses.replace(value, **{axis: -value[axis]})


#: Where each bench sign lives in BenchParams: (section, field).
_FIELDS: Final = {"q": ("quad_diode", "gain_v_per_rad"),
                  "m": ("sercalo", "beam_angle_per_mirror_angle"),
                  "i": ("current_amplifier", "sign"),
                  "n": ("newport", "gain_rad_per_v"),
                  "r": ("newport", "metrology_sign"),
                  "c": ("voltage_amplifier", "sign")}


def _value(params: BenchParams, cause: SignCause) -> float:
    section, name = _FIELDS[cause.name]
    return float(getattr(getattr(params, section), name)[cause.axis])


def with_signs(params: BenchParams, causes: Iterable[SignCause]) -> BenchParams:
    """``params`` with each bench sign of ``causes`` reversed on its axis."""
    out = params
    for cause in causes:
        if cause.kind != "bench":
            continue
        section, name = _FIELDS[cause.name]
        part = getattr(out, section)
        part = dataclasses.replace(part, **{name: _flip_axis(getattr(part, name), cause.axis)})
        out = dataclasses.replace(out, **{section: part})
    return out


def _explanation_words(causes: Sequence[SignCause]) -> str:
    return " and ".join(c.words() for c in causes) if causes else "no cause"


def _separating(explanations: Sequence[Sequence[SignCause]]) -> str:
    """The record that would tell the explanations apart, in words ("" when none is known)."""
    records = [c.record for e in explanations for c in e if c.kind == "record"]
    hints = [_SEPARATES[r] for r in dict.fromkeys(records) if r in _SEPARATES]
    return "; ".join(hints)


def _evidence(d: SignDiagnosis, cause: SignCause) -> tuple[str, str]:
    """(the records, the measurements) of the observations through one bench sign."""
    through = [o for o in d.observations if cause.name in o.bench]
    records = ", ".join(dict.fromkeys(f"{o.record}.mat" for o in through))
    words = "; ".join(o.words for o in through if o.words)
    return records, words


def _findings(d: SignDiagnosis, chosen: Sequence[SignCause], params: BenchParams
              ) -> list[Finding]:
    others = [e for e in d.explanations if tuple(e) != tuple(chosen)]
    alternatives = tuple(_explanation_words(e) for e in others)
    separate = _separating(others)
    if alternatives and separate:
        alternatives = (*alternatives[:-1], f"{alternatives[-1]} ({separate} would separate "
                                             "them)")
    # With one cause more: another bench sign and one record flipped (less likely than one
    # cause, but the same records).
    alternatives += tuple(f"{_explanation_words(e)} (two causes)" for e in d.near)
    out = []
    for cause in chosen:
        value = _value(params, cause)
        records, words = _evidence(d, cause)
        out.append(Finding(cause.key, value, -value, "1" if cause.name in "irc" else _unit(cause),
                           records, f"{cause.words()} ({words})", 0.0, alternatives))
    return out


def _unit(cause: SignCause) -> str:
    return {"q": "V/rad", "m": "rad/rad", "n": "rad/V"}.get(cause.name, "1")


def _check(d: SignDiagnosis) -> Check:
    subject = (", ".join(dict.fromkeys(f"{o.record}.mat" for o in d.observations))
               + f": {_AXIS_WORDS[d.axis]} paths")
    limit = "one explanation of every path's sign by the bench's own signs"
    n_rev = len(d.reversed())
    value = f"{n_rev} of {len(d.observations)} reversed"
    if not d.contradicts:
        return Check("signs_across_records", True, value, limit, subject)
    rev = "; ".join(o.words for o in d.reversed() if o.words)
    if not d.explained:
        advice = (f"{rev}: no set of up to three causes explains these signs together; check "
                  "each record's cables and the signs applied when saving them")
    elif len(d.explanations) == 1:
        advice = (f"{rev}: the records contradict each other, and one cause explains it: "
                  f"{_explanation_words(d.explanations[0])}; record it again (or, knowing it, "
                  "negate that signal in that file)")
    else:
        causes = "; or ".join(_explanation_words(e) for e in d.explanations)
        separate = _separating(d.explanations)
        advice = (f"{rev}: the records contradict each other; each of these explains it: "
                  f"{causes}; the records cannot tell which"
                  + (f" ({separate} would)" if separate else "")
                  + ": check those records' cables and how they were saved")
    return Check("signs_across_records", False, value, limit, subject, advice)


def diagnose_signs(observations: Iterable[SignObservation], *, params: BenchParams
                   ) -> SignOutcome:
    """Explain both axes' path signs and say what follows (module notes).

    Parameters
    ----------
    observations : iterable of SignObservation
        The judged paths of both axes (``record``, signals, the bench signs along
        the path as :data:`~fsmbench.ident.evidence.signs.BENCH_SIGNS` letters).
    params : BenchParams
        The bench file's nominal parameters.

    Returns
    -------
    SignOutcome
    """
    obs = list(observations)
    diagnoses, checks, findings, notices = [], [], [], []
    by_experiment: dict[str, tuple[Check, ...]] = {}
    applied: list[SignCause] = []
    for axis in "hv":
        mine = [o for o in obs if _axis_of(o) == axis]
        if not mine:
            continue
        d = explain_signs(mine, axis=axis)
        diagnoses.append(d)
        check = _check(d)
        checks.append(check)
        if d.agrees:
            continue
        if not d.contradicts:
            chosen = d.bench_only[0]
            applied += chosen
            findings += _findings(d, chosen, params)
            if len(d.bench_only) > 1:
                notices.append(Notice("other", check.subject, (
                    "the records cannot tell these bench signs apart: "
                    + "; or ".join(_explanation_words(e) for e in d.bench_only)
                    + f"; taken: {_explanation_words(chosen)}")))
            continue
        # Contradiction: keep the bench signs every explanation shares; block the records.
        common = (set.intersection(*(set(e) for e in d.explanations))
                  if d.explanations else set())
        shared = [c for c in common if c.kind == "bench"]
        applied += shared
        findings += _findings(d, shared, params) if shared else []
        for record in d.records() or [o.record for o in d.reversed()]:
            by_experiment[record] = (*by_experiment.get(record, ()), check)
    return SignOutcome(tuple(diagnoses), tuple(checks), by_experiment, tuple(findings),
                       tuple(notices), with_signs(params, applied))


def _axis_of(o: SignObservation) -> str:
    """A path's axis from its signals' last letter (``Vph``: h)."""
    return o.output[-1] if o.output[-1] in "hv" else o.input[-1]
