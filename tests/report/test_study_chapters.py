"""The study's chapters in two steps: chapter 11 gets the model's check on the recorded
loop last, and every other chapter stays the object drafted (its encoded figures hold)."""

from __future__ import annotations

from fsmbench.report.html import Section
from fsmbench.report.sections.study import CHAPTER_ANCHORS, with_recorded_loop_check


def _chapters() -> list[Section]:
    return [Section(title=f"{i + 1}. Chapter", anchor=a,
                    subsections=(Section(title=f"{i + 1}.1 Part"),))
            for i, a in enumerate(CHAPTER_ANCHORS)]


def test_the_check_on_the_recorded_loop_closes_chapter_11() -> None:
    drafted = _chapters()
    done = with_recorded_loop_check(drafted, validation=None, skipped="no repeatability "
                                    "record", montecarlo=None)
    assert len(done) == len(drafted)
    chapter11 = done[-2]
    assert chapter11.anchor == "non-repeatability"
    assert chapter11.subsections[:-1] == drafted[-2].subsections
    last = chapter11.subsections[-1]
    assert last.anchor == "validation" and "no repeatability record" in " ".join(
        b for b in last.blocks if isinstance(b, str))
    assert all(a is b for a, b in zip(done[:-2], drafted[:-2], strict=True))
    assert done[-1] is drafted[-1]  # the appendix
