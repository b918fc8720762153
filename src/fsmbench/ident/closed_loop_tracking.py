"""The tracking error during a closed-loop measurement (:mod:`fsmbench.ident.closed_loop`).

The 4QD's beam angle in each record, its rms before the excitation starts (the loop's
own error) and while excited, and what the excitation added: the rms of its synchronous
average over the periods when it repeats, else the quadrature difference of the two; to
judge against the user's bound on the error a measurement may add.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import xarray as xr

from fsmbench.ident.frf.periodic import detect_period
from fsmbench.jsonutil import plain_json

__all__ = ["TrackingDuringMeasurement"]

# The loop's own error is read on the record before the excitation starts, after the
# closing transient; shorter than this it is not measured.
_MIN_BEFORE_S = 0.5
# The loop's closing transient left out of the "before" window [s].
_SETTLE_S = 0.2


@dataclass(frozen=True)
class TrackingDuringMeasurement:
    """The 4QD's beam-angle error in one record: the loop's own, and with the excitation.

    Attributes
    ----------
    record : str
    before_rms_rad, during_rms_rad, added_rms_rad : dict axis -> float
        Rms (mean removed) before the excitation and while excited [rad]; what the
        excitation added [rad]: for a repeated excitation the rms of the
        synchronous average over its periods (noise share removed), else
        ``sqrt(during² - before²)``. ``before`` is NaN when the record holds less
        than 0.5 s of loop before the excitation (and then ``added`` too, for an
        excitation that does not repeat).
    bound_rad : float or None
        The user's bound on the added rms.
    """

    record: str
    before_rms_rad: dict[str, float]
    during_rms_rad: dict[str, float]
    added_rms_rad: dict[str, float]
    bound_rad: float | None = None

    @property
    def within_bound(self) -> bool | None:
        """Every axis's added rms within the bound (None: no bound or not measurable)."""
        if self.bound_rad is None or any(not math.isfinite(v) for v in self.added_rms_rad.values()):
            return None
        return all(v <= self.bound_rad for v in self.added_rms_rad.values())

    def to_json(self) -> dict[str, Any]:
        """Plain values."""
        return plain_json(
            {
                "record": self.record,
                "before_rms_rad": self.before_rms_rad,
                "during_rms_rad": self.during_rms_rad,
                "added_rms_rad": self.added_rms_rad,
                "bound_rms_rad": self.bound_rad,
                "within_bound": self.within_bound,
            }
        )


def _synchronous_added(e: np.ndarray, x: np.ndarray) -> float | None:
    """Rms of the part of ``e`` that repeats with the excitation ``x`` [same unit as e].

    The synchronous average over whole periods (the first dropped: the loop's transient)
    keeps what the excitation causes and averages the rest down; its noise share, the
    per-sample variance across periods over their number, is taken off. None when ``x``
    does not repeat at least three times.
    """

    n = detect_period(x)
    if n is None or x.size // n < 3:
        return None
    periods = x.size // n - 1
    seg = e[n : n + periods * n].reshape(periods, n)
    seg = seg - seg.mean()
    mean = seg.mean(axis=0)
    noise = float(np.mean(np.var(seg, axis=0, ddof=1))) / periods
    return float(np.sqrt(max(0.0, float(np.mean(mean**2)) - noise)))


def _tracking(
    ds: xr.Dataset,
    name: str,
    start: int,
    gd: tuple[float, float],
    bound: float | None,
    excitation: np.ndarray,
) -> TrackingDuringMeasurement:
    """The tracking error in record ``name`` excited from sample ``start`` (``excitation``
    from there on), the 4QD gains ``gd`` [V/rad] per axis and the user's ``bound`` [rad]."""
    fs = float(ds.attrs["fs_hz"])
    before: dict[str, float] = {}
    during: dict[str, float] = {}
    added: dict[str, float] = {}
    first = round(_SETTLE_S * fs)
    for i, (axis, sig) in enumerate((("h", "Vph"), ("v", "Vpv"))):
        e = np.asarray(ds[sig].values, dtype=float) / gd[i]
        during[axis] = float(np.std(e[start:]))
        before[axis] = (
            float(np.std(e[first:start])) if start - first >= _MIN_BEFORE_S * fs else float("nan")
        )
        # A repeated excitation's share is measured by the synchronous average (the loop's
        # own error, 1/f and drift included, averages out); else the quadrature difference
        # of the rms with and before it, which a short "before" window makes noisy.
        sync = _synchronous_added(e[start:], excitation)
        added[axis] = (
            sync
            if sync is not None
            else (
                float(np.sqrt(max(0.0, during[axis] ** 2 - before[axis] ** 2)))
                if math.isfinite(before[axis])
                else float("nan")
            )
        )
    return TrackingDuringMeasurement(name, before, during, added, bound)
