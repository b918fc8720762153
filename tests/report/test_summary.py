"""The verdict: each requirement against its limit, where its number comes from, what next."""

from __future__ import annotations

import json
import math
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pytest

from fsmbench.budget.table import BudgetRow
from fsmbench.checks import Check, Notice
from fsmbench.report.summary import Specification, StudyEvidence, build_summary
from fsmbench.report.verdict import verdict_html
from fsmbench.study import StudyResult


def _loop(s1: float, gm: float = 12.0, pm: float = 45.0, stable: bool = True) -> dict[str, Any]:
    axis = {"stable": stable, "gain_margin_db": gm, "phase_margin_deg": pm,
            "sensitivity_at_1hz": s1, "crossover_hz": 35.0}
    return {"h": axis, "v": {**axis, "sensitivity_at_1hz": s1 / 2}, "meets_objective": s1 <= 2e-4}


def _design(s1: float, *, simulated: bool = True, kind: str = "identified",
            **kw: Any) -> dict[str, Any]:
    closed = {
        "measured_over_predicted": {"h": 0.99, "v": 1.01},
        "tracking_error_rms_rad": {"h": 3.0e-5, "v": 3.1e-5},
        "predicted_rms_rad": {"h": 3.0e-5, "v": 3.1e-5},
        "predicted_parts_rad": {"h": {"qd_noise": 2.9e-5}, "v": {"qd_noise": 3.0e-5}},
        "bench": "the bench identified from the recordings in D", "bench_kind": kind}
    return {"fsmbench_controller": _loop(s1, **kw), "seed_controller": _loop(2.2e-3),
            "robustness": {"all_stable": True, "cases": [{"stable": True}] * 9,
                           "worst_gain_margin_db": 8.0},
            "closed_loop_twin": closed if simulated else None,
            "closed_loop_skipped": "" if simulated else "the Sercalo was not identified"}


def _row(name: str, rms: float, provenance: str, **kw: Any) -> BudgetRow:
    return BudgetRow(name=name, section="4", mechanism="linear", rms_m=rms, bias_m=0.0,
                     angle_rms_rad=None, seed_m=None, seed_note="", provenance=provenance, **kw)


def _budget(total_m: float, *, huddle: bool = True) -> SimpleNamespace:
    # Rows of 0.8 and 0.6 of the total: their squares sum to the total's.
    rows = (_row("metrology frame expansion", 0.8 * total_m, "assumed",
                 replace_by="a huddle test of at least 1 h"),
            _row("4QD electronic noise", 0.6 * total_m, "measured"))
    table = SimpleNamespace(total_rms_m=total_m, rows=rows, window_s=100.0, limiting=rows[0].name)
    quoted = SimpleNamespace(controller="fsmbench's controller", budget=table,
                             stationary_total_rms_m=3 * total_m)
    return SimpleNamespace(
        quoted=quoted, recommended=quoted, controller="ESRF study 9.2 K", budget=table, skipped={},
        huddle=SimpleNamespace(qd_noise=object()) if huddle else None,
        frame=SimpleNamespace(expansion_per_k=23e-6), noise=SimpleNamespace(bits=16))


def _validation(ratio: float = 1.02, action: str = "") -> SimpleNamespace:
    return SimpleNamespace(action=action,
        band_hz=(2.0, 5000.0), measured_rms_rad={"h": 4.0e-5 * ratio, "v": 4.1e-5 * ratio},
        predicted_rms_rad={"h": 4.0e-5, "v": 4.1e-5}, ratio={"h": ratio, "v": ratio},
        limits=(0.8, 1.25), passed=0.8 <= ratio <= 1.25, n_periods=40,
        experiments=("data_rep_h", "data_rep_v"), bench="the identified bench",
        controller="the ESRF study's controller", reason="" if 0.8 <= ratio <= 1.25
        else "h: recorded more than the model gives")


def _summary(*, total_m: float = 2.25e-9, s1: float = 1.2e-4, skipped: dict[str, str] | None = None,
             checks: tuple[Check, ...] = (), identified: bool = True, huddle: bool = True,
             validation: Any = "default", simulated: bool = True, **kw: Any) -> Any:
    return build_summary(
        StudyEvidence(
            source="test",
            is_twin=False,
            skipped=skipped or {},
            n_experiments=13,
            n_read=13 - len(skipped or {}),
            checks=checks,
            identification={"ran": True, "warnings": [], "skipped": {}},
            plant_source="identified" if identified else "nominal physical model (test)",
            plant_identified=identified,
            budget=_budget(total_m, huddle=huddle),
            design=_design(s1, simulated=simulated, **kw),
            validation=_validation() if validation == "default" else validation),
        spec=Specification())


def test_a_bench_within_every_limit_passes_with_numbers_and_provenance() -> None:
    s = _summary()
    assert s.meets_specifications is True and s.verdict_status == "meets"
    assert s.verdict.startswith("The bench meets its specifications")
    assert all(r.status == "pass" for r in s.requirements)
    # Every requirement says where its number comes from, in one of four words.
    assert {r.provenance for r in s.requirements} <= {"measured", "derived", "predicted",
                                                      "assumed"}
    by = {r.name: r for r in s.requirements}
    assert by["closed_loop_simulation"].provenance == "predicted"
    assert "identified from the recordings" in by["closed_loop_simulation"].provenance_detail
    assert by["model_validation"].provenance == "measured"
    assert by["control_objective"].values == {"h": 1.2e-4, "v": 6e-5}
    assert by["control_objective"].limits == {"max": 2e-4}
    # The distance row states its window and the stationary value (3 × 2.25 = 6.75 nm).
    dist = by["distance_error_budget"]
    assert "over 100 s, mean removed" in dist.description
    assert "stationary value 6.75 nm" in dist.explanation
    assert "64%" in dist.explanation  # 0.8² of the variance


def test_the_next_step_is_computed_from_the_limiting_row() -> None:
    s = _summary()
    # An invar frame scales the frame row by 1.2e-6 / 23e-6; the other row stays.
    frame = 0.8 * 2.25e-9 * 1.2e-6 / 23e-6
    total = math.hypot(frame, 0.6 * 2.25e-9)
    assert f"total to {total * 1e9:.3g} nm" in s.next_step
    assert "assumed" in s.next_step and "a huddle test of at least 1 h" in s.next_step


@pytest.mark.parametrize(("kw", "failing"), [
    ({"total_m": 6e-9}, "distance_error_budget"),           # above the 5 nm default
    ({"s1": 2.5e-4}, "control_objective"),                   # |S(1 Hz)| above 2e-4
    ({"pm": 25.0}, "phase_margin"),                          # phase margin below 30°
    ({"gm": 4.0}, "gain_margin"),                            # gain margin below 6 dB
])
def test_each_requirement_fails_on_its_own_and_the_headline_gives_value_and_limit(
        kw: dict[str, Any], failing: str) -> None:
    s = _summary(**kw)
    assert s.meets_specifications is False and s.verdict_status == "does_not_meet"
    assert [r.name for r in s.requirements if r.passed is False] == [failing]
    req = next(r for r in s.requirements if r.name == failing)
    assert "does NOT meet" in s.verdict and f"{req.value} against {req.limit}" in s.verdict


def test_an_unstable_loop_fails_both_margins() -> None:
    s = _summary(stable=False)
    assert {r.name for r in s.requirements if r.passed is False} == {"gain_margin",
                                                                     "phase_margin"}


@pytest.mark.parametrize(("kw", "open_row", "missing"), [
    ({"identified": False}, "control_objective", "an identified plant"),
    ({"huddle": False}, "distance_error_budget", "open-loop huddle test"),
    ({"simulated": False}, "closed_loop_simulation", "the Sercalo was not identified"),
    ({"validation": None}, "model_validation", "data_rep_h"),
])
def test_a_requirement_without_its_measurements_is_not_verified(
        kw: dict[str, Any], open_row: str, missing: str) -> None:
    s = _summary(**kw)
    req = next(r for r in s.requirements if r.name == open_row)
    assert req.status == "not verified" and missing in req.missing
    assert s.meets_specifications is None and s.verdict_status == "not_verified"
    assert s.verdict.startswith("Not verified") and "meets its specifications" not in s.verdict
    assert s.next_step.startswith("Next: record")


def test_a_model_that_misses_the_recorded_loop_makes_the_verdict_not_verified() -> None:
    s = _summary(validation=_validation(ratio=1.6))
    assert s.verdict_status == "not_verified" and s.meets_specifications is None
    assert "does not predict their own closed loop" in s.verdict
    assert "recorded more than the model gives" in s.next_step


def test_a_missed_loop_whose_cause_the_records_name_says_what_to_do_first() -> None:
    # The DAC's rounding limit-cycling (control.validation._dead_band): the action leads.
    s = _summary(validation=_validation(ratio=0.3, action="make the Sercalo DAC's step "
                                        "finer (a smaller current-amplifier gain)"))
    assert s.verdict_status == "not_verified"
    assert s.next_step.startswith("Next: make the Sercalo DAC's step finer")
    # The reason is the row's, said once: the next step does not repeat it.
    assert len(s.next_step.split()) <= 40, s.next_step
    assert s.verdict.endswith("— first, make the Sercalo DAC's step finer.")
    row = next(r for r in s.requirements if r.name == "model_validation")
    assert row.to_json()["action"].startswith("make the Sercalo DAC's step finer")


def test_a_dead_band_the_plant_explains_gives_a_verdict_from_the_other_rows() -> None:
    # control.validation: the loop's rms missed by a DAC dead band while the plant predicts
    # the records from their own commands (control.compare) -> the model row passes, and
    # the verdict is the other rows' (here fsmbench's loop simulated 2.6x its linear
    # prediction: does not meet), led by the records' action.
    action = "make the Sercalo DAC's step finer (a smaller current-amplifier gain)"
    plant = SimpleNamespace(check=Check("plant_output_error", True, 1.04, "≤ 2× the noise",
                                        unit="×"))
    validation = SimpleNamespace(
        **{**vars(_validation(ratio=0.3, action=action)), "passed": True,
           "reason": "h: recorded less than the model gives (a dead band); the plant itself "
                     "predicts the recorded 4QD readings", "plant_check": plant,
           "dead_band_axes": ("h", "v")})
    design = _design(1.2e-4)
    design["closed_loop_twin"]["measured_over_predicted"] = {"h": 2.65, "v": 2.01}
    s = build_summary(
        StudyEvidence(
            source="test",
            is_twin=False,
            skipped={},
            n_experiments=13,
            n_read=13,
            checks=(),
            identification={"ran": True, "warnings": [], "skipped": {}},
            plant_source="identified",
            plant_identified=True,
            budget=_budget(2.25e-9),
            design=design,
            validation=validation),
        spec=Specification())
    assert s.verdict_status == "does_not_meet", s.verdict
    assert "closed loop" in s.verdict and "2.65" in s.verdict
    assert s.next_step.startswith("Next: make the Sercalo DAC's step finer")
    row = next(r for r in s.requirements if r.name == "model_validation")
    assert row.passed is True and "plant output error 1.04× the noise" in row.value
    assert "dead band" in row.limit and "≤ 2× the noise" in row.limit


def test_the_distance_limit_is_configurable() -> None:
    s = build_summary(
        StudyEvidence(
            source="t",
            is_twin=True,
            skipped={},
            n_experiments=13,
            n_read=13,
            identification=None,
            plant_source="identified",
            plant_identified=True,
            budget=_budget(2.25e-9),
            design=None),
        spec=Specification(distance_error_max_m=2e-9))
    req = next(r for r in s.requirements if r.name == "distance_error_budget")
    assert req.passed is False and req.limit == "≤ 2 nm" and req.limits == {"max": 2e-9}


def test_skips_failed_checks_and_fallbacks_are_listed_first() -> None:
    check = Check(name="calibration_r2", passed=False, value=3.5e-7, limit="≥ 0.9",
                  subject="data_cal_pd_h.mat: Vph", advice="check the 4QD cable")
    s = _summary(skipped={"data_uch": "data_uch.mat: Vph: holds NaN at sample 12"},
                 checks=(check,), identified=False)
    page = verdict_html(s)
    assert "data_uch.mat: Vph: holds NaN" in page
    assert "4QD calibration linearity r² failed" in page and "check the 4QD cable" in page
    assert "nominal physical model" in page
    assert "NOT VERIFIED" in page and s.next_step in page
    # The fallback says what to do about it: the refused file, corrected.
    assert s.fallbacks[0].endswith("What to do: correct data_uch (data_uch.mat: Vph: holds NaN "
                                   "at sample 12), then run the study again.")


@pytest.mark.parametrize(("skipped", "plant_source", "advice"), [
    ({"data_ucv": "no data_ucv.mat (or .h5/.nxs) in D"}, "nominal physical model (data_ucv "
     "missing)", "record data_ucv (noise on each coil command"),
    ({"data_uch": "no data_uch.mat (or .h5/.nxs) in D; found Data_Uch.mat: rename it "
                  "data_uch.mat (file names are case-sensitive)"}, "nominal physical model",
     "rename Data_Uch.mat: rename it data_uch.mat"),
    ({}, "nominal physical model (the identification raised warnings: x)",
     "the failed checks listed below name each file"),
])
def test_a_fallback_says_what_to_do(skipped: dict[str, str], plant_source: str,
                                    advice: str) -> None:
    s = build_summary(
        StudyEvidence(
            source="t",
            is_twin=False,
            skipped=skipped,
            n_experiments=13,
            n_read=13 - len(skipped),
            identification=None,
            plant_source=plant_source,
            plant_identified=False,
            budget=None,
            design=None),
        spec=Specification())
    assert f"What to do: {advice}" in s.fallbacks[0]


def test_no_stage_no_verdict() -> None:
    s = build_summary(
        StudyEvidence(
            source="t",
            is_twin=False,
            skipped={},
            n_experiments=13,
            n_read=0,
            identification=None,
            plant_source="nominal",
            plant_identified=False,
            budget=None,
            design=None),
        spec=Specification())
    assert s.meets_specifications is None and s.verdict.startswith("No verdict")


def test_summary_json_has_numbers_units_provenance_and_the_display_beside() -> None:
    notice = Notice("saturation", "data_rep_h", "Vph: 5 % of samples at the ADC rails")
    s = _summary(checks=(), skipped=None)
    s = build_summary(
        StudyEvidence(
            source="t",
            is_twin=False,
            skipped={},
            n_experiments=13,
            n_read=13,
            notices=(notice,),
            identification=None,
            plant_source="identified",
            plant_identified=True,
            budget=_budget(1e-9),
            design=_design(1e-4),
            validation=_validation()),
        spec=Specification())
    js = json.loads(json.dumps(s.to_json(), allow_nan=False))
    assert js["format"] == "fsmbench.summary" and js["format_version"] == 3
    assert js["verdict_status"] == "meets" and js["next_step"]
    assert js["notices"][0]["kind"] == "saturation"
    assert all(" " not in k and "-" not in k for k in js)
    for req in js["requirements"]:
        assert req["status"] in ("pass", "fail", "not verified")
        assert req["provenance"] in ("measured", "derived", "predicted", "assumed")
        assert req["unit"] and req["limits"] and req["display"]["value"]
        assert all(isinstance(v, float) or v is None for v in req["values"].values())
    by = {r["name"]: r for r in js["requirements"]}
    # Version 3: values are what the limits bound, in one unit; the rms in other_values.
    row = by["closed_loop_simulation"]
    assert row["values"] == {"h": 0.99, "v": 1.01} and row["unit"] == "1"
    assert row["quantity"] == "simulated_over_predicted"
    assert row["other_values"]["simulated_rms_rad"] == {"h": 3.0e-5, "v": 3.1e-5}
    row = by["model_validation"]
    assert row["values"] == {"h": 1.02, "v": 1.02} and row["unit"] == "1"
    assert row["other_values"]["recorded_rms_rad"] == {"h": 4.0e-5 * 1.02, "v": 4.1e-5 * 1.02}
    for req in js["requirements"]:
        # Each status follows from its values and limits alone (all judged rows here).
        inside = all(v is None or (req["limits"].get("min", -math.inf) <= v
                                   <= req["limits"].get("max", math.inf))
                     for v in req["values"].values())
        assert req["passed"] is None or req["passed"] == inside, req["name"]


def test_the_study_writes_the_summary_and_keeps_timings_apart(twin_study: StudyResult) -> None:
    out = Path(twin_study.out_dir)
    summary = json.loads((out / "summary.json").read_text())
    study = json.loads((out / "study.json").read_text())
    timings = json.loads((out / "timings.json").read_text())
    assert summary["is_twin"] is True and summary["meets_specifications"] in (True, False, None)
    assert study["meets_specifications"] == summary["meets_specifications"]
    assert "seconds" not in json.dumps(study)  # wall-clock times only in timings.json
    assert set(timings["seconds"]) >= {"simulate", "identify", "budget", "design", "validation",
                                       "report"}
    # Paths are relative to the output folder: the folder can move.
    assert study["report"] == "report.html" and study["data_dir"] == "twin-data"
    # On twin data the closed loop runs on the packaged twin, which produced the data.
    sim = next(r for r in summary["requirements"] if r["name"] == "closed_loop_simulation")
    assert "packaged twin" in sim["provenance_detail"]


def test_data_contradicting_itself_is_never_a_pass_but_a_device_finding_is() -> None:
    lie = Check(name="qd_gain_newport_vs_calibration", passed=False, value=10.1,
                limit="0.8 to 1.25", subject="data_unh.mat: Vph",
                advice="the Newport run gives -1.66 V/V where … predict -0.165 V/V")
    s = _summary(checks=(lie,))
    assert s.verdict_status == "not_verified" and s.meets_specifications is None
    assert "data_unh.mat: Vph" in s.verdict and s.next_step.startswith("Next: correct")
    finding = Check(name="newport_amplitude_bandwidth", passed=False, value=815.8,
                    limit="within 25% of the datasheet's 600 Hz", subject="Newport h")
    assert _summary(checks=(finding,)).verdict_status == "meets"


def test_the_next_step_names_the_file_to_rename_correct_or_record() -> None:
    """A row left unjudged for want of a file: the file the loader nearly matched, or the
    one it refused with its reason, or the one absent, whichever the row needs."""
    skipped = {
        "data_uch": "no data_uch.mat (or .h5/.nxs) in D; found DATA_UCH.mat: rename it "
                    "data_uch.mat (file names are case-sensitive)",
        "data_ucv": "D/data_ucv.mat: Ucv holds 3 NaN values",
        "data_unh": "no data_unh.mat (or .h5/.nxs) in D",
    }
    s = _summary(skipped=skipped, simulated=False)
    assert s.verdict_status == "not_verified"
    assert s.next_step == (
        "Next: rename the files the study did not recognise (DATA_UCH.mat: rename it "
        "data_uch.mat (file names are case-sensitive)), correct data_ucv (D/data_ucv.mat: "
        "Ucv holds 3 NaN values), record data_unh, then run the study again.")


@pytest.mark.parametrize("kw", [{"identified": False}, {"validation": None},
                                {"identified": False, "huddle": False}])
def test_a_verdict_that_cannot_judge_reads_in_one_sentence_and_each_reason_once(
        kw: dict[str, Any]) -> None:
    # Issue 30: the headline ran to seven lines and each row repeated its 80-word reason.
    s = _summary(**kw)
    assert s.verdict_status == "not_verified"
    assert len(s.verdict.split()) <= 30 and s.verdict.count(".") == 1, s.verdict
    assert "— first, " in s.verdict  # the first thing to do
    open_rows = [r for r in s.requirements if r.passed is None]
    assert open_rows and all(r.reason >= 1 for r in open_rows)
    # Each reason is listed once, and each row points to its own.
    assert len(set(s.reasons)) == len(s.reasons)
    for r in open_rows:
        assert s.reasons[r.reason - 1] == f"missing: {r.missing}"
    html = verdict_html(s)
    for i in range(1, len(s.reasons) + 1):
        assert html.count(f'<li id="reason-{i}">') == 1
    # The requirements' table points to the reason; it does not repeat it.
    table = html.split("<table>", 1)[1].split("</table>", 1)[0]
    for r in open_rows:
        assert r.missing not in table and f'href="#reason-{r.reason}"' in table
