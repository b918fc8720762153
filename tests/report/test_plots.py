"""Time-domain figures: envelopes and labelled axes."""

from __future__ import annotations

import numpy as np
import pytest

from fsmbench.report.plots import envelope, experiment_figure
from fsmbench.twin import TwinRun


@pytest.mark.parametrize("n", [100, 10_007, 1_000_000])
def test_envelope_keeps_every_extreme(n: int) -> None:
    rng = np.random.default_rng(0)
    t = np.arange(n) / 1e4
    y = rng.standard_normal(n)
    tt, yy = envelope(t, y, bins=3000)
    assert yy.max() == y.max() and yy.min() == y.min()
    assert np.all(np.diff(tt) >= 0)  # still a time series
    assert tt.size <= max(n, 2 * 3000 + n % 3000 + 1)
    # every drawn point is a sample of the record
    idx = np.searchsorted(t, tt)
    np.testing.assert_array_equal(y[idx], yy)


@pytest.mark.parametrize("name", ["data_uch", "data_cal_pd_h", "data_rep_h",
                                  "data_huddle_test_3"])
def test_experiment_figures_have_units_on_every_axis(short_twin: TwinRun, name: str) -> None:
    fig = experiment_figure(short_twin.recordings[name], gn0_rad_per_v=2.62e-3, trim_s=1.0)
    for ax in fig.axes:
        assert "[" in ax.get_ylabel() and "]" in ax.get_ylabel(), (name, ax.get_ylabel())
    assert fig.axes[-1].get_xlabel() == "Time [s]"
