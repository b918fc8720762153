"""The whole control study on the true plant: JSON and files (figures: tests/report)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from fsmbench.bench.blocks import PlantModel
from fsmbench.bench.params import Bench
from fsmbench.control.study import (
    CONTROLLERS_MAT,
    CONTROLLERS_SOS_JSON,
    MATLAB_LOADER,
    DesignResult,
    design_study,
)
from fsmbench.io.matfile import load_mat

AXIS_KEYS = {"stable", "gain_margin_db", "phase_margin_deg", "modulus_margin", "crossover_hz",
             "sensitivity_at_1hz"}


@pytest.fixture(scope="module")
def study(true_plant: PlantModel, bench: Bench) -> DesignResult:
    return design_study(true_plant, bench=bench)


def test_json_has_the_promised_keys(study: DesignResult) -> None:
    js = study.to_json()
    json.dumps(js, allow_nan=False)  # plain numbers only, NaN/inf as None
    assert js["objective"]["sensitivity_bound_at_1hz"] == pytest.approx(2e-4)
    for name in ("seed_controller", "fsmbench_controller", "newport_controller"):
        assert "meets_objective" in js[name]
        for axis in "hv":
            assert set(js[name][axis]) >= AXIS_KEYS
    for axis in "hv":
        assert {"damping_ratio_open", "damping_ratio_closed"} <= set(js["iff"][axis])
    assert {"worst_gain_margin_db", "worst_phase_margin_deg"} <= set(js["robustness"])


def test_study_findings(study: DesignResult) -> None:
    js = study.to_json()
    assert js["fsmbench_controller"]["meets_objective"] is True
    assert js["fsmbench_controller"]["meets_margins"] is True
    assert js["seed_controller"]["stable"] is True
    assert js["seed_controller"]["meets_objective"] is False  # |L(1 Hz)| ~ 250-450 < 5e3
    assert js["newport_controller"]["stable"] is True
    assert js["robustness"]["all_stable"] is True
    assert js["robustness"]["worst_gain_margin_db"] >= 6.0
    assert js["robustness"]["worst_phase_margin_deg"] >= 30.0
    # Fig. 42: with fsmbench's loop the Newport's 1 Hz motion reaches the beam attenuated
    # by |S(1 Hz)| < 2e-4.
    att = js["newport_to_beam"]["attenuation_at_1hz"]["fsmbench_controller"]
    assert max(att.values()) < 2e-4


def test_write(study: DesignResult, tmp_path: Path) -> None:
    paths = study.write(tmp_path)
    assert [p.name for p in paths] == [CONTROLLERS_MAT, CONTROLLERS_SOS_JSON, MATLAB_LOADER]
    m = load_mat(tmp_path / CONTROLLERS_MAT)
    assert {"seed_controller", "fsmbench_controller", "newport_controller",
            "iff_controller"} <= set(m)
    doc = json.loads((tmp_path / CONTROLLERS_SOS_JSON).read_text())
    assert set(doc["controllers"]) == {"seed_controller", "fsmbench_controller",
                                       "newport_controller"}
