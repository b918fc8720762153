"""One module per report chapter: tables, notes and figures from the stages' results.
"""

__all__: list[str] = []
