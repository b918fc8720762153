"""The closed-loop records' controller fits made two by two: the fits made one after the
other, each kept for the stages that ask again."""

from __future__ import annotations

from dataclasses import asdict

import numpy as np
import pytest

from fsmbench.forked import fork_available
from fsmbench.ident.evidence import recorded_loop
from fsmbench.ident.evidence.recorded_loop import CLOSED_LOOP_RECORDS, recorded_controllers
from fsmbench.twin.simulate import simulate_bench


@pytest.mark.skipif(not fork_available(), reason="needs fork and two cores")
def test_fits_two_by_two_are_the_fits_one_by_one(monkeypatch: pytest.MonkeyPatch) -> None:
    run = simulate_bench(seed=11, duration_s=5.0, experiments=list(CLOSED_LOOP_RECORDS))
    serial = recorded_controllers({n: ds.copy() for n, ds in run.recordings.items()},
                                  fs_hz=1e4, step_v=20.0 / 2**16)
    fresh = {n: ds.copy() for n, ds in run.recordings.items()}  # fitted by neither yet
    forked = recorded_controllers(fresh, fs_hz=1e4, step_v=20.0 / 2**16, parallel=True)
    for axis in "hv":
        assert len(forked[axis].fits) == len(CLOSED_LOOP_RECORDS)
        np.testing.assert_equal(asdict(forked[axis]), asdict(serial[axis]))
    # Every fit, the forked process's included, is kept: asked again, none is made.
    made: list[str] = []
    real = recorded_loop.fit_record
    monkeypatch.setattr(recorded_loop, "fit_record",
                        lambda record, *a, **k: (made.append(record), real(record, *a, **k))[1])
    recorded_controllers(fresh, fs_hz=1e4, step_v=20.0 / 2**16)
    assert made == []
