"""Errors and warnings raised while reading and writing recordings.

Every message names the file, the variable when there is one, and the
problem, so that a user can fix the file without a debugger, e.g.::

    data_uch.mat: variable 'Vph' holds 12 NaN values (first at index 4031, t = 0.4031 s)
"""

from __future__ import annotations

import os

__all__ = ["RecordingError", "SaturationWarning"]


class RecordingError(ValueError):
    """A recording or MAT-file cannot be used as it is.

    Parameters
    ----------
    file : str or os.PathLike
        The file (or, for in-memory data, a label such as
        ``"recording 'data_uch'"``) the problem was found in.
    problem : str
        What is wrong, worded to follow ``"variable 'X' "`` when ``variable``
        is given (e.g. ``"holds 3 NaN values ..."``) or ``"<file>: "``
        otherwise.
    variable : str, optional
        The variable concerned, if any.
    kind : str, optional
        The problem in a few words without its particulars (``"not uniformly
        sampled"``), so that files failing in the same way are named together.

    Attributes
    ----------
    file : str
        As given.
    problem : str
        As given.
    variable : str or None
        As given.
    kind : str or None
        As given.
    """

    file: str
    problem: str
    variable: str | None
    kind: str | None

    def __init__(
        self, file: str | os.PathLike[str], problem: str, *, variable: str | None = None,
        kind: str | None = None,
    ) -> None:
        # ``args`` holds only the positional arguments and ``variable`` lives in
        # ``__dict__``: BaseException.__reduce__ then pickles both, so the error
        # survives multiprocessing and copy.
        super().__init__(os.fspath(file), problem)
        self.file = os.fspath(file)
        self.problem = problem
        self.variable = variable
        self.kind = kind

    def __str__(self) -> str:
        if self.variable is None:
            return f"{self.file}: {self.problem}"
        return f"{self.file}: variable '{self.variable}' {self.problem}"


class SaturationWarning(UserWarning):
    """An ADC signal sits at the converter rails: those samples are clipped.

    Parameters
    ----------
    file : str or os.PathLike
        The file (or in-memory label) holding the signal.
    variable : str
        The signal name, one of :data:`fsmbench.io.signals.ADC_SIGNALS`.
    count : int
        Number of samples at the rails (dimensionless).
    total : int
        Number of samples of the signal (dimensionless).
    limit_v : float
        The rail threshold, in V: samples with ``|v| >= limit_v`` count.

    Attributes
    ----------
    fraction : float
        ``count / total`` (dimensionless, 0..1).
    percent : float
        ``100 * fraction``, in %.
    """

    def __init__(
        self,
        file: str | os.PathLike[str],
        variable: str,
        count: int,
        total: int,
        limit_v: float,
    ) -> None:
        super().__init__(os.fspath(file), variable, count, total, limit_v)
        self.file = os.fspath(file)
        self.variable = variable
        self.count = int(count)
        self.total = int(total)
        self.limit_v = float(limit_v)

    @property
    def fraction(self) -> float:
        """Fraction of samples at the rails (dimensionless, 0..1)."""
        return self.count / self.total if self.total else 0.0

    @property
    def percent(self) -> float:
        """Percentage of samples at the rails, in %."""
        return 100.0 * self.fraction

    def __str__(self) -> str:
        return (
            f"{self.file}: variable '{self.variable}' has {self.count} of {self.total} "
            f"samples ({self.percent:.4g} %) at the ADC rails (|v| >= {self.limit_v:.6g} V); "
            "those samples are clipped, not measured"
        )
