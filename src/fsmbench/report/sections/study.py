"""The study's report, chapter by chapter: every chapter in the ESRF study's order (1–11)
and the parameters appendix, assembled from the stages' results.

Assembled in two steps: :func:`study_chapters` from every stage but the model's check on
the recorded loop (the study drafts them, their figures encoded, while that check still
runs in another process), then :func:`with_recorded_loop_check` adds it to chapter 11.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import replace
from typing import Any, Final

import xarray as xr

from fsmbench.bench.params import Bench
from fsmbench.budget.result import BudgetResult
from fsmbench.control.study import DesignResult
from fsmbench.control.validation import ClosedLoopValidation
from fsmbench.ident.result import Identification
from fsmbench.report.html import Section
from fsmbench.report.sections.bench import bench_section, parameters_appendix
from fsmbench.report.sections.budget import budget_section
from fsmbench.report.sections.control import control_sections
from fsmbench.report.sections.huddle import huddle_section
from fsmbench.report.sections.ident import identification_section
from fsmbench.report.sections.montecarlo import montecarlo_section
from fsmbench.report.sections.noise import noise_subsection
from fsmbench.report.sections.repeatability import repeatability_section
from fsmbench.report.sections.validation import validation_subsection
from fsmbench.twin.verify import TrackingCheck

__all__ = ["CHAPTER_ANCHORS", "study_chapters", "with_recorded_loop_check"]

#: Each chapter's anchor, in order: the summary links to them.
CHAPTER_ANCHORS: Final = (
    "bench", "identification", "huddle-test", "error-budget", "plant-uncertainty",
    "plant-scaling", "plant-analysis", "active-damping", "decentralised-control",
    "newport-control", "non-repeatability", "parameters")


def study_chapters(*, bench: Bench, recordings: Mapping[str, xr.Dataset],
                   skipped: Mapping[str, str], source: str, is_twin: bool,
                   ident: Identification | None, truth: Mapping[str, Any] | None,
                   budget: BudgetResult, design: DesignResult,
                   twin_check: TrackingCheck | None, design_skipped: str,
                   plant_source: str) -> list[Section]:
    """Every chapter and the appendix; chapter 11 without the model's check on the
    recorded loop and the Monte Carlo draws (:func:`with_recorded_loop_check`).

    Parameters
    ----------
    bench : Bench
        The bench as the records describe it.
    recordings : mapping of experiment name to Dataset
        The records read; ``skipped``: those refused, with the reason.
    source : str
        Where the records come from, in words; ``is_twin``: the twin made them.
    ident : Identification or None
        Section 2's result (None: not run); ``truth``: the twin's, when it made the records.
    budget : BudgetResult
        Sections 3, 4 and 11's.
    design, twin_check, design_skipped
        Sections 5-10's result, fsmbench's controller on the simulated bench (None: not
        run, ``design_skipped`` says why).
    plant_source : str
        The plant the budget and the design used, in words.

    Raises
    ------
    RuntimeError
        The chapters are not the :data:`CHAPTER_ANCHORS`' count.
    """
    chapter2 = identification_section(ident, recordings=recordings, bench=bench, truth=truth,
                                      skipped=skipped)
    sections = [
        bench_section(bench, recordings=recordings, skipped=skipped, source=source,
                      is_twin=is_twin),
        replace(chapter2, subsections=(*chapter2.subsections, noise_subsection(
            None if ident is None else ident.noise_model))),
        huddle_section(budget, recordings=recordings),
        budget_section(budget, plant_source=plant_source),
        *control_sections(design, twin_check=twin_check, skipped=design_skipped,
                          plant_source=plant_source),
        repeatability_section(budget),
        parameters_appendix(bench, is_twin=is_twin),
    ]
    if len(sections) != len(CHAPTER_ANCHORS):
        raise RuntimeError(f"the report has {len(sections)} chapters, expected "
                           f"{len(CHAPTER_ANCHORS)}")
    return [replace(s, anchor=a) for s, a in zip(sections, CHAPTER_ANCHORS, strict=True)]


def with_recorded_loop_check(chapters: Sequence[Section], *,
                             validation: ClosedLoopValidation | None, skipped: str,
                             montecarlo: Mapping[str, Any] | None) -> list[Section]:
    """:func:`study_chapters` with chapter 11's last parts: the model's check on the
    recorded loop (``validation``, or why it was not made, ``skipped``) and the Monte
    Carlo draws (a ``montecarlo.json``'s content, when given). The other chapters are
    the same objects (their encoded figures stay valid)."""
    *before, chapter11, appendix = chapters
    return [*before, replace(chapter11, subsections=(
        *chapter11.subsections, validation_subsection(validation, skipped=skipped),
        *(() if montecarlo is None else (montecarlo_section(montecarlo),)))), appendix]
