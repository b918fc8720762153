"""Fig. 46, the model against the recorded closed loop: one legend entry per trace colour."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from fsmbench.report.figures.spec import Line
from fsmbench.report.sections.validation import validation_figure


def _validation() -> SimpleNamespace:
    f = np.linspace(0.0, 100.0, 101)
    psd = np.column_stack([np.full(f.size, 1e-14), np.full(f.size, 2e-14)])
    predicted = SimpleNamespace(f_hz=f, parts={"qd_noise": 0.5 * psd, "mains": 0.25 * psd},
                                words={"qd_noise": "4QD noise", "mains": "mains lines"})
    return SimpleNamespace(f_hz=f, measured_psd=psd, predicted_psd=psd, predicted=predicted,
                           ratio={"h": 1.0, "v": 1.1}, experiments=["data_rep_h"],
                           n_periods=6, bench="the twin", controller="the ESRF study's "
                           "controller", band_hz=(1.0, 100.0))


def test_fig46_one_legend_entry_per_colour_named_by_axis() -> None:
    fig = validation_figure(_validation())
    colours: dict[str, set[str | None]] = {}
    names: dict[str, set[str]] = {}
    for p in fig.panels:
        for t in p.traces:
            assert isinstance(t, Line)
            key = t.group or t.name
            colours.setdefault(key, set()).add(t.color)
            names.setdefault(key, set()).add(t.name)
    assert all(len(c) == 1 for c in colours.values()), colours
    assert all(len(n) == 1 for n in names.values()), names
    recorded = sorted(n for ns in names.values() for n in ns if n.startswith("recorded"))
    assert recorded == ["recorded ASD of Rh (horizontal) [µrad/√Hz]",
                        "recorded ASD of Rv (vertical) [µrad/√Hz]"]
