"""The verdict: each requirement against its limit, and what went wrong in words."""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pytest

from fsmbench.checks import Check, Notice
from fsmbench.report.summary import Specification, build_summary, verdict_html
from fsmbench.study import StudyResult


def _loop(s1: float, gm: float = 12.0, pm: float = 45.0, stable: bool = True) -> dict[str, Any]:
    axis = {"stable": stable, "gain_margin_db": gm, "phase_margin_deg": pm,
            "sensitivity_at_1hz": s1, "crossover_hz": 35.0}
    return {"h": axis, "v": {**axis, "sensitivity_at_1hz": s1 / 2}, "meets_objective": s1 <= 2e-4}


def _design(s1: float, **kw: Any) -> dict[str, Any]:
    return {"fsmbench_controller": _loop(s1, **kw), "seed_controller": _loop(2.2e-3),
            "robustness": {"all_stable": True, "cases": [{}] * 9, "worst_gain_margin_db": 8.0},
            "closed_loop_twin": {
                "measured_over_predicted": {"h": 0.99, "v": 1.01},
                "tracking_error_rms_rad": {"h": 3.0e-5, "v": 3.1e-5},
                "predicted_rms_rad": {"h": 3.0e-5, "v": 3.1e-5},
                "predicted_parts_rad": {"h": {"qd_noise": 2.9e-5}, "v": {"qd_noise": 3.0e-5}}}}


def _budget(total_m: float) -> SimpleNamespace:
    rows = [SimpleNamespace(name="DAC quantisation", rms_m=0.8 * total_m,
                            mechanism="mirror piston"),
            SimpleNamespace(name="4QD noise", rms_m=0.6 * total_m, mechanism="beam angle")]
    return SimpleNamespace(budget=SimpleNamespace(total_rms_m=total_m, rows=rows), skipped={})


def _summary(*, total_m: float = 2.25e-9, s1: float = 1.2e-4, skipped: dict[str, str] | None = None,
             checks: tuple[Check, ...] = (), identified: bool = True, **kw: Any) -> Any:
    return build_summary(
        source="test", is_twin=False, spec=Specification(), skipped=skipped or {},
        n_experiments=13, n_read=13 - len(skipped or {}), checks=checks,
        identification={"ran": True, "warnings": [], "skipped": {}},
        plant_source="identified" if identified else "nominal physical model (test)",
        plant_identified=identified, budget=_budget(total_m), design=_design(s1, **kw))


def test_a_bench_within_every_limit_passes() -> None:
    s = _summary()
    assert s.meets_specifications is True
    assert s.verdict.startswith("The bench meets its specifications")
    assert all(r.passed for r in s.requirements)
    # The limiting source is the largest row, with its share of the variance (0.8² = 64 %).
    assert s.limiting.startswith("DAC quantisation, 1.8 nm")
    budget = next(r for r in s.requirements if r.name == "distance_error_budget")
    assert "64%" in budget.explanation


@pytest.mark.parametrize(("kw", "failing"), [
    ({"total_m": 6e-9}, "distance_error_budget"),           # above the 5 nm default
    ({"s1": 2.5e-4}, "control_objective"),                   # |S(1 Hz)| above 2e-4
    ({"pm": 25.0}, "stability_margins"),                     # phase margin below 30°
    ({"stable": False}, "stability_margins"),
])
def test_each_requirement_fails_on_its_own(kw: dict[str, Any], failing: str) -> None:
    s = _summary(**kw)
    assert s.meets_specifications is False
    assert [r.name for r in s.requirements if r.passed is False] == [failing]
    assert "does NOT meet" in s.verdict


def test_the_distance_limit_is_configurable() -> None:
    s = build_summary(source="t", is_twin=True, spec=Specification(distance_error_max_m=2e-9),
                      skipped={}, n_experiments=13, n_read=13, identification=None,
                      plant_source="identified", plant_identified=True,
                      budget=_budget(2.25e-9), design=None)
    req = next(r for r in s.requirements if r.name == "distance_error_budget")
    assert req.passed is False and req.limit == "≤ 2 nm"


def test_skips_failed_checks_and_fallbacks_are_listed_first() -> None:
    check = Check(name="calibration_r2", passed=False, value=3.5e-7, limit="≥ 0.9",
                  subject="data_cal_pd_h.mat: Vph", advice="check the 4QD cable")
    s = _summary(skipped={"data_uch": "data_uch.mat: Vph: holds NaN at sample 12"},
                 checks=(check,), identified=False)
    page = verdict_html(s)
    assert "data_uch.mat: Vph: holds NaN" in page
    assert "calibration_r2 FAILED" in page and "check the 4QD cable" in page
    assert "nominal physical model" in page
    assert "on the nominal model" in s.verdict


def test_no_stage_no_verdict() -> None:
    s = build_summary(source="t", is_twin=False, spec=Specification(), skipped={},
                      n_experiments=13, n_read=0, identification=None, plant_source="nominal",
                      plant_identified=False, budget=None, design=None)
    assert s.meets_specifications is None and s.verdict.startswith("No verdict")


def test_summary_json_has_its_format_and_plain_values() -> None:
    notice = Notice("saturation", "data_rep_h", "Vph: 5 % of samples at the ADC rails")
    s = build_summary(source="t", is_twin=False, spec=Specification(), skipped={},
                      n_experiments=13, n_read=13, notices=(notice,), identification=None,
                      plant_source="identified", plant_identified=True,
                      budget=_budget(1e-9), design=_design(1e-4))
    js = json.loads(json.dumps(s.to_json(), allow_nan=False))
    assert js["format"] == "fsmbench.summary" and js["format_version"] == 1
    assert js["notices"][0]["kind"] == "saturation"
    assert all(" " not in k and "-" not in k for k in js)


def test_the_study_writes_the_summary_and_keeps_timings_apart(twin_study: StudyResult) -> None:
    out = Path(twin_study.out_dir)
    summary = json.loads((out / "summary.json").read_text())
    study = json.loads((out / "study.json").read_text())
    timings = json.loads((out / "timings.json").read_text())
    assert summary["is_twin"] is True and summary["meets_specifications"] in (True, False)
    assert study["meets_specifications"] == summary["meets_specifications"]
    assert "seconds" not in json.dumps(study)  # wall-clock times only in timings.json
    assert set(timings["seconds"]) >= {"simulate", "identify", "budget", "design", "report"}
    # Paths are relative to the output folder: the folder can move.
    assert study["report"] == "report.html" and study["data_dir"] == "twin-data"
