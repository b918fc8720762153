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

__all__ = ["CHECK_TITLES", "Check", "Finding", "Notice", "failed", "first_failure"]


#: What each check tests, in the words a user reads (its ``name`` stays the JSON key).
CHECK_TITLES: dict[str, str] = {
    "attocube_noise_vs_model": "interferometer noise against the bench file's model",
    "calibration_r2": "4QD calibration linearity r²",
    "channels_distinct": "two channels holding two signals",
    "calibration_residual": "4QD calibration residual (share of the fitted swing)",
    "converter_range": "converter range",
    "coprime_factor_margin": "robust stability margin b_max",
    "current_amp_gain_vs_theoretical": "current-amplifier gain against 1/(R + Rc)",
    "excited_axis": "excited axis (direct over cross response)",
    "huddle_distinct": "huddle test distinct from the others",
    "huddle_loop_closed": "closed-loop huddle test ran the loop",
    "huddle_loop_open": "open-loop huddle test ran open",
    "huddle_qd_vs_model": "4QD huddle-test noise against the bench file's",
    "huddle_va_vs_prediction": "huddle-test distance noise against the budget's prediction",
    "integer_samples": "sample type",
    "model_validation": "model validation (recorded over predicted tracking error)",
    "newport_amplitude_bandwidth": "Newport amplitude bandwidth",
    "newport_gain_vs_model": "Newport gain against the bench file's",
    "newport_noise_vs_datasheet": "Newport noise against its datasheet",
    "newport_peaking": "Newport resonance peaking",
    "newport_phase_bandwidth": "Newport phase bandwidth",
    "noise_floor_across_files": "4QD noise floor across files",
    "plant_output_error": "the plant's response to the recorded commands against the 4QD "
                          "readings",
    "qd_gain_newport_vs_calibration": "4QD gain seen by the Newport experiments against "
                                      "the calibration's",
    "open_loop_record": "an open-loop run recorded open",
    "qd_gain_vs_nominal": "4QD gain against the bench file's",
    "qd_lag_across_axes": "4QD lag alike on both axes",
    "qd_noise_vs_model": "4QD noise against the bench file's",
    "rate_vs_controller": "sampling rate against the recorded controller's",
    "rate_vs_current_amplifier": "sampling rate against the coil path's corners",
    "record_length": "record long enough for its analysis",
    "record_padded": "record without zeros padded after its end",
    "sampling_rate": "sampling rate",
    "sercalo_gain_vs_model": "Sercalo gain against the bench file's",
    "signal_clipped": "signal not clipped",
    "signal_frozen": "signal never frozen for a stretch",
    "signal_varies": "signal varies",
    "signs_across_records": "path signs across the records",
    "va_continuous": "distance record continuous (no jump)",
    "va_in_metres": "distance in metres",
}


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
    unit : str
        Unit of ``value`` ("Hz", "dB", "m", "×" for a ratio; empty when
        dimensionless).
    """

    name: str
    passed: bool
    value: float | str | None
    limit: str
    subject: str = ""
    advice: str = ""
    unit: str = ""

    @property
    def title(self) -> str:
        """What the check tests, in words (:data:`CHECK_TITLES`)."""
        return CHECK_TITLES.get(self.name, self.name.replace("_", " "))

    def value_words(self) -> str:
        """The measured value with its unit ("814.9 Hz", "1.14×"; "not computed" for None)."""
        if self.value is None:
            return "not computed"
        if not isinstance(self.value, float):
            return str(self.value)
        if self.unit == "×":
            return f"{self.value:.4g}×"
        return f"{self.value:.4g} {self.unit}".rstrip()

    def sentence(self) -> str:
        """One line a user reads: subject, what was checked, value against limit, advice."""
        head = f"{self.subject}: " if self.subject else ""
        verdict = "passed" if self.passed else "failed"
        tail = f"; {self.advice}" if self.advice and not self.passed else ""
        return (f"{head}{self.title} {verdict} ({self.value_words()}, limit {self.limit})"
                f"{tail}")

    def to_json(self) -> dict[str, Any]:
        """JSON-ready dict (``plain_json`` convention)."""
        out: dict[str, Any] = plain_json(asdict(self))
        return out


@dataclass(frozen=True)
class Notice:
    """Something the user should know that did not stop the stage.

    Attributes
    ----------
    kind : str
        ``saturation``, ``rate``, ``dropped_variable``, ``numeric``, ``data_type``,
        ``trailing_bytes`` (bytes after a file's data ignored), ``file_choice`` (the
        experiment is in two files of the folder: which was read), ``time_jitter`` (``t``
        strays from a uniform grid by clock jitter) or ``other``.
    subject : str
        File and signal it concerns.
    message : str
        One line in words, with units.
    """

    kind: Literal["saturation", "rate", "dropped_variable", "numeric", "data_type",
                  "trailing_bytes", "file_choice", "time_jitter", "other"]
    subject: str
    message: str

    def sentence(self) -> str:
        """One line: ``subject: message``."""
        return f"{self.subject}: {self.message}" if self.subject else self.message

    def to_json(self) -> dict[str, Any]:
        """JSON-ready dict."""
        return dict(asdict(self))


@dataclass(frozen=True)
class Finding:
    """What the records measured where the bench file says otherwise: a fact about the bench.

    The bench file is a prior; a departure from it is not a fault of the
    records. A finding names the bench-file key, the value the records give
    it, and the other causes that would produce the same records.

    Attributes
    ----------
    key : str
        The bench-file key (``nominal.sercalo.beam_angle_per_mirror_angle.h``).
    bench_value, measured : float
        The bench file's value and the records', in ``unit``.
    unit : str
        Unit of both ("1" for a sign or a ratio).
    subject : str
        The records it rests on (``data_uch.mat, data_rep_h.mat``).
    message : str
        What was found, in words, with the evidence.
    std : float
        The measured value's standard deviation (0 for a sign the records fix).
    alternatives : tuple of str
        Other causes that fit the same records, each with what would separate it;
        empty when the records leave one.
    """

    key: str
    bench_value: float
    measured: float
    unit: str
    subject: str
    message: str
    std: float = 0.0
    alternatives: tuple[str, ...] = ()

    def sentence(self) -> str:
        """One line: subject, what was found, the key and both values, the alternatives."""
        head = f"{self.subject}: " if self.subject else ""
        unit = "" if self.unit in ("", "1") else f" {self.unit}"
        alt = (f" (or: {'; or '.join(self.alternatives)})" if self.alternatives else "")
        return (f"{head}{self.message}: {self.key} = {self.measured:.6g}{unit} (bench file "
                f"{self.bench_value:.6g}{unit}){alt}")

    def to_json(self) -> dict[str, Any]:
        """JSON-ready dict (``plain_json`` convention)."""
        out: dict[str, Any] = plain_json(asdict(self))
        return out


def failed(checks: Iterable[Check]) -> list[Check]:
    """The checks that did not pass, in order."""
    return [c for c in checks if not c.passed]


def first_failure(checks: Iterable[Check]) -> Check | None:
    """The first failed check, or None."""
    bad = failed(checks)
    return bad[0] if bad else None
