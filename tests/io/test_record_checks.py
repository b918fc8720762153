"""One recording's checks: computed once per record whatever the rate asked, the rate's
check always fresh, and a copy checked on its own."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from fsmbench.io import record_checks
from fsmbench.io.record_checks import check_recording
from fsmbench.twin import TwinRun


def test_the_rate_check_is_first_and_the_rest_is_the_rate_free_list(
        short_twin: TwinRun) -> None:
    ds = short_twin.recordings["data_huddle_test_1"]
    free, free_notes = check_recording(ds, name="data_huddle_test_1")
    for fs_hz, passed in ((1e4, True), (2e4, False)):
        checks, notes = check_recording(ds, name="data_huddle_test_1", fs_hz=fs_hz)
        assert checks[0].name == "sampling_rate" and checks[0].passed is passed
        assert checks[1:] == free and notes == free_notes


def test_a_record_is_scanned_once_for_all_its_checks(short_twin: TwinRun,
                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    """The loader, the identification and the budget ask for the same record's checks: the
    Va scan (the dearest) runs once."""
    ds = short_twin.recordings["data_huddle_test_2"].copy()  # a record no test checked yet
    scans: list[str] = []
    real = record_checks.jump_check

    def counted(*args: Any, **kwargs: Any) -> Any:
        scans.append(args[1])
        return real(*args, **kwargs)

    monkeypatch.setattr(record_checks, "jump_check", counted)
    first = check_recording(ds, name="data_huddle_test_2")
    again = check_recording(ds, name="data_huddle_test_2", fs_hz=1e4)
    assert len(scans) == 1 and again[0][1:] == first[0]


def test_a_changed_copy_is_checked_on_its_own(short_twin: TwinRun) -> None:
    ds = short_twin.recordings["data_huddle_test_3"]
    clean = check_recording(ds, name="data_huddle_test_3", fs_hz=1e4)[0]
    broken = ds.copy(deep=True)
    broken["Va"].values[len(broken["Va"]) // 2:] += 1e-6  # a 1 µm fringe jump
    found = {c.name: c.passed for c in check_recording(broken, name="data_huddle_test_3",
                                                       fs_hz=1e4)[0]}
    assert {c.name: c.passed for c in clean}["va_continuous"]
    assert found["va_continuous"] is False
    assert np.all(np.isfinite(broken["Va"].values))
