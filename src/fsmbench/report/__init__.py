"""Figures and the self-contained HTML report."""

from fsmbench.report.html import Figure, Section, Table, figure_from_matplotlib, write_report

__all__ = ["Figure", "Section", "Table", "figure_from_matplotlib", "write_report"]
