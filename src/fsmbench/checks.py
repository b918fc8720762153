"""Plausibility checks and notices: the verdicts a stage gives about its inputs.

A :class:`Check` is one named test with its measured value and its limit
(``calibration_r2`` passed with 0.99998 ≥ 0.9); a failed check makes the
stage fall back or skip *with that check's name as the reason*. A
:class:`Notice` is something a user should know that does not stop the
stage (ADC saturation, a dropped variable, a sampling rate that differs
from the bench's). Both serialise into every stage's JSON
(``checks: [{name, passed, value, limit, advice, subject}]``) and are shown
in the report's summary.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import asdict, dataclass
from typing import Any, Literal

from fsmbench.jsonutil import plain_json

__all__ = ["Check", "Notice", "failed", "first_failure"]


@dataclass(frozen=True)
class Check:
    """One plausibility check.

    Attributes
    ----------
    name : str
        Identifier, lower case with underscores (``"calibration_r2"``).
    passed : bool
    value : float, str or None
        What was measured, in the unit the limit states.
    limit : str
        The acceptance rule in words with its unit (``"≥ 0.9"``).
    subject : str
        What was checked: file and signal (``"data_cal_pd_h.mat: Vph"``).
    advice : str
        What to do when it fails; empty when passed.
    """

    name: str
    passed: bool
    value: float | str | None
    limit: str
    subject: str = ""
    advice: str = ""

    def sentence(self) -> str:
        """One line a user reads: subject, check, value against limit, advice."""
        head = f"{self.subject}: " if self.subject else ""
        verdict = "passed" if self.passed else "FAILED"
        value = f"{self.value:.4g}" if isinstance(self.value, float) else str(self.value)
        tail = f"; {self.advice}" if self.advice and not self.passed else ""
        return f"{head}{self.name} {verdict} ({value}, limit {self.limit}){tail}"

    def to_json(self) -> dict[str, Any]:
        """JSON-ready dict (``plain_json`` convention)."""
        out: dict[str, Any] = plain_json(asdict(self))
        return out


@dataclass(frozen=True)
class Notice:
    """Something the user should know that did not stop the stage.

    Attributes
    ----------
    kind : {"saturation", "rate", "dropped_variable", "numeric", "data_type", "other"}
    subject : str
        File and signal it concerns.
    message : str
        One line in words, with units.
    """

    kind: Literal["saturation", "rate", "dropped_variable", "numeric", "data_type", "other"]
    subject: str
    message: str

    def sentence(self) -> str:
        """One line: ``subject: message``."""
        return f"{self.subject}: {self.message}" if self.subject else self.message

    def to_json(self) -> dict[str, Any]:
        """JSON-ready dict."""
        return dict(asdict(self))


def failed(checks: Iterable[Check]) -> list[Check]:
    """The checks that did not pass, in order."""
    return [c for c in checks if not c.passed]


def first_failure(checks: Iterable[Check]) -> Check | None:
    """The first failed check, or None."""
    bad = failed(checks)
    return bad[0] if bad else None
