"""The saturating-step figure and its text draw what the result holds, nothing more."""

from __future__ import annotations

import numpy as np

from fsmbench.control.antiwindup_loop import SaturatingStep
from fsmbench.report.figures.antiwindup import saturating_step_figure
from fsmbench.report.figures.spec import Line


def _step(axis: str, recovered: float) -> SaturatingStep:
    t = np.arange(100) * 1e-3
    beam = {k: np.sin(t * (i + 1)) for i, k in enumerate(("without", "with", "linear"))}
    return SaturatingStep(name="K", axis=axis, t_s=t, step_rad=0.5, hold_s=0.03,
                          beam_rad=beam, command_v={k: 2 * v for k, v in beam.items()},
                          dac_limit_v=10.0, band_rad=0.01,
                          recovery_s={"without": np.inf, "with": recovered, "linear": 0.02},
                          saturated_s={"without": 0.09, "with": 0.03, "linear": 0.0},
                          tracking_time_s=0.02)


def test_figure_draws_each_run_normalised_and_one_legend_entry_per_run() -> None:
    steps = [_step("h", 0.05), _step("v", 0.06)]
    fig = saturating_step_figure(steps, key="k", title="t", caption="c")
    assert fig.columns == 2 and len(fig.panels) == 4
    beam_h = fig.panels[0]
    lines = [tr for tr in beam_h.traces if isinstance(tr, Line)]
    for line, key in zip(lines, ("without", "with", "linear"), strict=True):
        # every other sample drawn (the figure's 5 kHz), exactly those samples
        np.testing.assert_array_equal(line.y, steps[0].beam_rad[key][::2] / 0.5)
        np.testing.assert_array_equal(line.x, steps[0].t_s[::2] * 1e3)
    legends = [tr.name for p in fig.panels for tr in p.traces
               if isinstance(tr, Line) and tr.legend]
    assert len(legends) == len(set(legends)) == 3  # once each, in the first panel
    rails = {r.value for r in fig.panels[2].rules if r.axis == "y"}
    assert rails == {10.0, -10.0}
    assert any(r.axis == "x" and r.value == 30.0 for r in fig.panels[2].rules)  # step back [ms]
    assert steps[0].to_json()["recovery_after_step_back_s"] == {"without": None, "with": 0.05,
                                                               "linear": 0.02}
