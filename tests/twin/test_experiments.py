"""The ESRF study's experiment protocols."""

from __future__ import annotations

import pytest

from fsmbench.twin.experiments import EXPERIMENT_NAMES, esrf_experiments


def test_thirteen_experiments_in_the_seeds_names() -> None:
    specs = esrf_experiments()
    names = [s.name for s in specs]
    assert len(names) == 13 and tuple(names) == EXPERIMENT_NAMES
    assert names[:6] == ["data_cal_pd_h", "data_cal_pd_v", "data_uch", "data_ucv", "data_unh",
                         "data_unv"]
    assert names[6:11] == [f"data_huddle_test_{i}" for i in range(1, 6)]
    assert names[11:] == ["data_rep_h", "data_rep_v"]


def test_table_3_configurations() -> None:
    cfg = {s.name: (s.closed_loop, s.compensation_unit, s.shielding) for s in esrf_experiments()}
    assert cfg["data_huddle_test_1"] == (False, False, False)
    assert cfg["data_huddle_test_2"] == (False, True, False)
    assert cfg["data_huddle_test_3"] == (True, True, False)
    assert cfg["data_huddle_test_4"] == (False, True, True)
    assert cfg["data_huddle_test_5"] == (True, True, True)
    assert cfg["data_rep_h"][0] and cfg["data_rep_v"][0]


def test_start_times_are_the_seeds_trims() -> None:
    """Excitations begin where the ESRF study's scripts cut (t0 = 1, 1, 3, 1.5 s)."""
    start = {s.name: s.excitations[0].start_s for s in esrf_experiments() if s.excitations}
    assert start["data_uch"] == 1.0 and start["data_ucv"] == 1.0
    assert start["data_unh"] == 3.0 and start["data_unv"] == 1.5
    assert start["data_cal_pd_h"] == 1.0
    rep = next(s for s in esrf_experiments() if s.name == "data_rep_h").excitations[0]
    assert rep.kind == "sine" and rep.freq_hz == 1.0


def test_huddle_tests_last_the_seeds_101_s() -> None:
    """ESRF study 3.2 trims t < 1 s and keeps 100 s: the raw record needs 101 s."""
    for s in esrf_experiments():
        if s.name.startswith("data_huddle"):
            assert s.duration_s == 101.0


def test_duration_override_and_its_limits() -> None:
    specs = esrf_experiments(duration_s=6.0)
    assert all(s.duration_s == 6.0 for s in specs)
    with pytest.raises(ValueError, match="too short for data_unh") as err:
        esrf_experiments(duration_s=4.0)
    assert "5 s" in str(err.value)
