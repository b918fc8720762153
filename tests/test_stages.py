"""The budget and design stages: plant choice, files and the contracted JSON keys."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from fsmbench.bench.params import Bench
from fsmbench.stages import budget_stage, choose_plant, design_stage
from fsmbench.twin import TwinRun

DESIGN_KEYS = ["objective.sensitivity_bound_at_1hz", "iff.h.damping_ratio_open",
               "iff.v.damping_ratio_closed", "robustness.worst_gain_margin_db",
               "robustness.worst_phase_margin_deg",
               "closed_loop_twin.tracking_error_rms_rad.h",
               "closed_loop_twin.tracking_error_rms_rad.v"]
LOOP_KEYS = ["stable", "gain_margin_db", "phase_margin_deg", "modulus_margin", "crossover_hz",
             "sensitivity_at_1hz"]
BUDGET_KEYS = ["noise.adc_psd_v2_per_hz", "noise.dac_psd_v2_per_hz",
               "noise.newport_dac_angle_psd_rad2_per_hz", "noise.newport_dac_angle_rms_rad",
               "noise.newport_beam_angle_psd_rad2_per_hz", "noise.sercalo_dac_lsb_beam_angle_rad",
               "geometry.path_error_m_per_rad2", "budget.total_rms_m",
               "repeatability.h.nonrep_rms_m", "repeatability.v.nonrep_rms_lpf_m",
               "huddle.1.va_rms_m", "huddle.3.vph_rms_v", "huddle.5.vpv_rms_v"]


def _get(tree: dict, dotted: str) -> object:
    node: object = tree
    for part in dotted.split("."):
        assert isinstance(node, dict) and part in node, f"missing {dotted}"
        node = node[part]
    return node


def test_plant_choice(ident_twin: TwinRun, bench: Bench) -> None:
    chosen = choose_plant(ident_twin.recordings, bench=bench)
    assert chosen.source.startswith("identified") and chosen.identification is not None
    none = choose_plant({}, bench=bench)
    assert none.source.startswith("nominal physical model") and none.identification is None


def test_design_stage_writes_the_contracted_keys(ident_twin: TwinRun, bench: Bench,
                                                 tmp_path: Path) -> None:
    plant = choose_plant(ident_twin.recordings, bench=bench)
    paths = design_stage(bench=bench, out_dir=tmp_path, plant=plant).files
    assert sorted(p.name for p in paths) == ["controllers.mat", "controllers_sos.json",
                                             "design.json", "fsmbench_load.m"]
    data = json.loads((tmp_path / "design.json").read_text())
    assert (data["format"], data["format_version"]) == ("fsmbench.design", 2)
    # Without a bench of its own the design stage simulates the packaged twin, and says so.
    assert data["closed_loop_twin"]["bench_kind"] == "packaged"
    assert data["closed_loop_twin"]["bench"] == "the packaged twin (default_bench.toml)"
    for key in DESIGN_KEYS:
        assert isinstance(_get(data, key), float), key
    for name in ("seed_controller", "fsmbench_controller", "newport_controller"):
        assert isinstance(_get(data, f"{name}.meets_objective"), bool)
        for axis in "hv":
            for key in LOOP_KEYS:
                _get(data, f"{name}.{axis}.{key}")
    fsm = data["fsmbench_controller"]
    # Issue 5's goal: the objective of 6.1 with GM >= 6 dB and PM >= 30 deg on both axes.
    assert fsm["meets_objective"]
    for axis in "hv":
        assert fsm[axis]["stable"] and fsm[axis]["gain_margin_db"] >= 6.0
        assert fsm[axis]["phase_margin_deg"] >= 30.0
    assert data["robustness"]["worst_gain_margin_db"] >= 6.0
    assert data["robustness"]["worst_phase_margin_deg"] >= 30.0
    # The simulated loop agrees with the linear prediction (full noise model): within 5 %,
    # the linear model's white DAC quantisation against the simulated one (measured < 3 %).
    for ratio in data["closed_loop_twin"]["measured_over_predicted"].values():
        assert 0.95 < ratio < 1.05


def test_budget_stage_writes_the_contracted_keys(short_twin: TwinRun, bench: Bench,
                                                 tmp_path: Path) -> None:
    plant = choose_plant({}, bench=bench)
    stage = budget_stage(short_twin.recordings, bench=bench, out_dir=tmp_path, plant=plant)
    result, paths = stage.result, stage.files
    assert [p.name for p in paths] == ["budget.json"]
    data = json.loads(paths[0].read_text())
    for key in BUDGET_KEYS:
        value = _get(data, key)
        assert isinstance(value, float) and value >= 0, key
    assert (data["format"], data["format_version"]) == ("fsmbench.budget", 4)
    # Every row says where it comes from; an assumed one names what would replace it.
    for row in data["budget"]["rows"]:
        assert row["provenance"] in ("measured", "derived", "assumed"), row["name"]
        assert row["provenance"] != "assumed" or row["replace_by"] or "resolution" in \
            row["provenance_detail"], row["name"]
    assert data["stationary_total_rms_m"] > 0
    assert {"id", "name", "rms_m"} <= set(data["budget"]["rows"][0])
    assert data["budget"]["total_rms_m"] == pytest.approx(result.total_rms_m)
    # One total, one table: nothing of the budget block repeated at the top.
    assert not {"sources", "total_rms_m", "total_bias_m", "limiting", "plant"} & set(data)
    assert data["plant_source"] == plant.source
