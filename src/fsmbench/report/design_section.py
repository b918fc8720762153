"""The control chapters as one section, for callers that still take a single section.

The chapters themselves are built by
:func:`fsmbench.report.control_sections.control_sections` (seed sections
5–10, each its own section); :func:`design_section` nests them under one
heading.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from fsmbench.report.control_sections import control_sections
from fsmbench.report.html import Section

if TYPE_CHECKING:
    from fsmbench.stages import DesignStage

__all__ = ["design_section"]


def design_section(stage: DesignStage, *, plant_source: str) -> Section:
    """Seed sections 5–10 as subsections of one "Control" section.

    Parameters
    ----------
    stage : DesignStage
        The design stage (result and twin check).
    plant_source : str
        Where the plant comes from, in words.
    """
    return Section(title="Control (seed sections 5–10)", anchor="control",
                   subsections=tuple(control_sections(stage, plant_source=plant_source)))
