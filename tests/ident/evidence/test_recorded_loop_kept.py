"""The closed-loop records' controller fits are kept with their records: the stages that
ask again (the screening, the rate's witness, the budget's huddle screen) fit none again."""

from __future__ import annotations

from dataclasses import asdict

import numpy as np
import pytest

from fsmbench.ident.evidence import recorded_loop
from fsmbench.ident.evidence.recorded_loop import CLOSED_LOOP_RECORDS, recorded_controllers
from fsmbench.twin.simulate import simulate_bench


def test_a_record_asked_again_is_not_fitted_again(monkeypatch: pytest.MonkeyPatch) -> None:
    run = simulate_bench(seed=11, duration_s=5.0, experiments=list(CLOSED_LOOP_RECORDS))
    records = {n: ds.copy() for n, ds in run.recordings.items()}
    first = recorded_controllers(records, fs_hz=1e4, step_v=20.0 / 2**16)
    made: list[str] = []
    real = recorded_loop.fit_record
    monkeypatch.setattr(recorded_loop, "fit_record",
                        lambda record, *a, **k: (made.append(record), real(record, *a, **k))[1])
    again = recorded_controllers(records, fs_hz=1e4, step_v=20.0 / 2**16)
    assert made == []
    # Other datasets with the same samples are other records: fitted anew, the same fits.
    copies = recorded_controllers({n: ds.copy() for n, ds in run.recordings.items()},
                                  fs_hz=1e4, step_v=20.0 / 2**16)
    assert sorted(made) == sorted(2 * list(CLOSED_LOOP_RECORDS))  # one fit per axis each
    for axis in "hv":
        assert len(first[axis].fits) == len(CLOSED_LOOP_RECORDS)
        np.testing.assert_equal(asdict(again[axis]), asdict(first[axis]))
        np.testing.assert_equal(asdict(copies[axis]), asdict(first[axis]))
