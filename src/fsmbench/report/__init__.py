"""The report: figures as data, drawn interactively in one self-contained HTML file."""

from fsmbench.report.figures.spec import Bars, Figure, Label, Line, Panel, Rule
from fsmbench.report.html import Note, Section, Table, write_report

__all__ = ["Bars", "Figure", "Label", "Line", "Note", "Panel", "Rule", "Section", "Table",
           "write_report"]
