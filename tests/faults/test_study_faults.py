"""Faults that once crashed ``fsmbench study`` itself (issue 10): a verdict, not a traceback."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from fsmbench.cli import main
from fsmbench.io.matwrite import save_mat
from fsmbench.twin import TwinRun


def test_huddle_tests_too_short_or_before_one_second_are_skipped_by_name(
        short_twin: TwinRun, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # The seed keeps t ≥ 1 s of a huddle test: a 0.5 s record, and one whose t lies
    # entirely below 1 s, leave nothing to analyse. The study once died drawing them.
    data = tmp_path / "data"
    data.mkdir()
    for name, t0_s, n in (("data_huddle_test_1", 0.0, 5000),
                          ("data_huddle_test_2", -200.0, 20000),
                          ("data_huddle_test_3", 0.0, 50000)):
        ds = short_twin.recordings[name]
        values = {str(k): ds[k].values[:n] for k in ds.data_vars}
        save_mat(data / f"{name}.mat", {"t": ds["t"].values[:n] + t0_s, **values})
    out = tmp_path / "out"
    # The distance target is read in nanometres (the requirement the verdict judges).
    assert main(["study", "--data", str(data), "--out", str(out),
                 "--distance-target", "2.5"]) == 0
    err = capsys.readouterr().err
    assert "Traceback" not in err
    summary = json.loads((out / "summary.json").read_text())
    assert summary["specification"]["distance_error_max_m"] == pytest.approx(2.5e-9)
    said = json.dumps(summary)
    assert "data_huddle_test_1" in said and "data_huddle_test_2" in said
    budget = json.loads((out / "budget.json").read_text())
    assert set(budget["huddle"]) == {"3"}  # only the usable test is analysed
