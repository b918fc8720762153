"""Models fitted to responses and records: vector fitting, residues for fixed poles,
parameter standard deviations, modal estimates, regressions, noise fits, the truncation
of modes above the band.
"""

__all__: list[str] = []
