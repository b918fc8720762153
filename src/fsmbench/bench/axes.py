"""Per-axis values and the parameter files' error, shared by the bench modules."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["AXES", "ParamsError", "PerAxis"]

AXES = ("h", "v")


class ParamsError(ValueError):
    """A parameter file is malformed; the message names the file and the key."""


@dataclass(frozen=True)
class PerAxis:
    """One value per mirror axis: ``h`` (horizontal, Sercalo AX1) and ``v`` (vertical, AX2)."""

    h: float
    v: float

    def __getitem__(self, axis: str) -> float:
        if axis not in AXES:
            raise KeyError(f"axis must be 'h' or 'v', not {axis!r}")
        return float(getattr(self, axis))

    def as_array(self) -> np.ndarray:
        """The values as a float array ``[h, v]``, shape (2,)."""
        return np.array([self.h, self.v], dtype=float)
