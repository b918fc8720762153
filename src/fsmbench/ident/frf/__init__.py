"""Frequency responses from records: Welch (MATLAB semantics), periodic averaging, the LPM,
closed-loop estimators, leakage and compression.
"""

__all__: list[str] = []
