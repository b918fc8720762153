"""The report's noise, error-budget, huddle and repeatability section (seed 3, 4, 11)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import matplotlib
import xarray as xr

from fsmbench.report.html import Section, Table, figure_from_matplotlib

__all__ = ["budget_section"]


def _nm(x: float | None) -> str:
    return "-" if x is None else f"{1e9 * x:.3g}"


def budget_section(result: Any, *, recordings: Mapping[str, xr.Dataset],
                   plant_source: str) -> Section:
    """Budget table, huddle conclusion, repeatability and the seed's figures.

    ``result`` is a :class:`fsmbench.budget.study.BudgetResult`.
    """
    from fsmbench.budget.figures import budget_figures

    b = result.budget
    rows = tuple((r.name, r.section, r.mechanism, _nm(r.rms_m), _nm(r.bias_m),
                  _nm(r.seed_m), r.seed_note) for r in b.rows)
    rows += (("total (RSS)", "", "", _nm(b.total_rms_m), _nm(b.total_bias_m), "", ""),)
    tables = [Table(caption=f"Error budget of the Attocube distance, {b.configuration} "
                            f"(nm rms; bias: the mean shift a quadratic term adds)",
                    header=("source", "seed §", "mechanism", "rms [nm]", "bias [nm]",
                            "seed [nm]", "note"), rows=rows)]
    paragraphs = [
        f"Plant: {plant_source}; controller: {result.controller}. Every source is propagated "
        "as a spectrum through the plant and the closed loop to the beam angle, and from the "
        "angle to the distance through the exact quadratic law of the beam path (4.1), not "
        "as a linear gain.",
        f"Limiting source: {b.limiting}. Total {1e9 * b.total_rms_m:.3g} nm rms.",
    ]
    if result.huddle is not None:
        paragraphs.append(result.huddle.conclusion)
        tables.append(Table(
            caption="Huddle tests (trimmed as the seed does, mean removed)",
            header=("test", "Va rms [nm]", "Vph rms [mV]", "Vpv rms [mV]"),
            rows=tuple((str(n), _nm(r.va_rms_m), f"{1e3 * r.vph_rms_v:.3g}",
                        f"{1e3 * r.vpv_rms_v:.3g}")
                       for n, r in sorted(result.huddle.records.items()))))
    if result.repeatability:
        tables.append(Table(
            caption="Non-repeatability (whole 1 s periods after the first command + 1 s)",
            header=("record", "non-repeatable rms [nm]", "with 10 Hz low-pass [nm]"),
            rows=tuple((name, _nm(r.nonrep_rms_m), _nm(r.nonrep_rms_lpf_m))
                       for name, r in result.repeatability.items())))
    if result.skipped:
        paragraphs.append("Skipped: " + "; ".join(f"{k} ({v})"
                                                   for k, v in result.skipped.items()) + ".")
    # The figures exist together until each is rendered and closed; the
    # context only silences matplotlib's "more than 20 figures" warning here.
    with matplotlib.rc_context({"figure.max_open_warning": 0}):
        figures = tuple(figure_from_matplotlib(f.figure, title=f.title, caption=f.caption,
                                               seed_ref=f.seed_ref)
                        for f in budget_figures(result, recordings))
    return Section(title="5. Noise, error budget, huddle tests and repeatability",
                   anchor="budget", paragraphs=tuple(paragraphs), tables=tuple(tables),
                   figures=figures)
