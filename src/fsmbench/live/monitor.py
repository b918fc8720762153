"""What the live device shows and guards: recent means and rms, saturation, the protection.

:class:`LiveMonitor` keeps the last second of the signals it needs in ring
buffers and answers the device's scalar attributes from them. Its
protection decides, after every block in closed loop, whether the loop
must be opened:

- **DAC saturation**: a controlled command (``Uch``, ``Ucv``) on a DAC rail
  for more than ``saturation_s`` (50 ms) of the last ``2 × saturation_s``
  — a loop that hits the rails that often no longer controls, whether the
  clipping is continuous or, as in a fast oscillation, intermittent;
- **diverging beam**: a 4QD reading (``Vph``, ``Vpv``) beyond
  ``beam_fraction`` (90 %) of the ADC's half range — the beam is leaving
  the diode — or not finite.

The coil-voltage channels (``Vch``, ``Vcv``, 60 dB amplifier) sit on the
ADC rails whenever the loop works hard and are not part of either test.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from fsmbench.live.backend import LiveBlock

__all__ = ["LiveMonitor", "ProtectionLimits", "Ring", "Trip"]


class Ring:
    """The last ``capacity`` samples of a few channels (a ring buffer).

    Parameters
    ----------
    capacity : int
        Samples kept.
    channels : sequence of str
    """

    def __init__(self, *, capacity: int, channels: Sequence[str]) -> None:
        self.capacity = int(capacity)
        self.channels = tuple(channels)
        self._data = np.zeros((self.capacity, len(self.channels)))
        self._next = 0
        self._count = 0

    def push(self, values: np.ndarray) -> None:
        """Append samples (n, n_channels)."""
        values = np.asarray(values, dtype=float).reshape(-1, len(self.channels))
        n = values.shape[0]
        if n >= self.capacity:
            self._data[:] = values[-self.capacity:]
            self._next = 0
        else:
            first = min(n, self.capacity - self._next)
            self._data[self._next:self._next + first] = values[:first]
            self._data[:n - first] = values[first:]
            self._next = (self._next + n) % self.capacity
        self._count = min(self.capacity, self._count + n)

    def last(self, n: int) -> np.ndarray:
        """The last ``min(n, held)`` samples, oldest first, shape (m, n_channels)."""
        m = min(n, self._count)
        idx = (self._next - m + np.arange(m)) % self.capacity
        return self._data[idx]

    def __len__(self) -> int:
        return self._count


@dataclass(frozen=True)
class ProtectionLimits:
    """When the protection opens the loop (see the module notes).

    Attributes
    ----------
    saturation_s : float
        Saturated time allowed within the last ``2 × saturation_s`` [s].
    beam_fraction : float
        Fraction of the ADC half range a 4QD reading may reach.
    """

    saturation_s: float = 0.05
    beam_fraction: float = 0.9


@dataclass(frozen=True)
class Trip:
    """Why and when the protection opened the loop.

    Attributes
    ----------
    reason : str
        In words, with the numbers.
    bench_time_s : float
        Bench time of the block that tripped [s].
    """

    reason: str
    bench_time_s: float


_SCALARS = ("Vph", "Vpv", "Va", "sat", "qd_sat")


class LiveMonitor:
    """Scalar views of the live bench and its protection.

    Parameters
    ----------
    fs_hz : float
    qd_gain_v_per_rad : (float, float)
        Calibrated 4QD gains (h, v) the angles are computed with [V/rad].
    half_range_v, lsb_v : float
        Converter half range and step [V] (the rails).
    limits : ProtectionLimits
    """

    def __init__(self, *, fs_hz: float, qd_gain_v_per_rad: tuple[float, float],
                 half_range_v: float, lsb_v: float,
                 limits: ProtectionLimits | None = None) -> None:
        self.fs_hz = float(fs_hz)
        self.gd = np.asarray(qd_gain_v_per_rad, dtype=float)
        self.half_range_v = float(half_range_v)
        self.lsb_v = float(lsb_v)
        self.limits = limits or ProtectionLimits()
        self._ring = Ring(capacity=round(self.fs_hz), channels=_SCALARS)
        self.samples = 0

    def _on_rail(self, x: np.ndarray) -> np.ndarray:
        # Positive rail is one step below +half range (two's complement codes).
        tol = self.lsb_v / 2 if self.lsb_v > 0 else 1e-12
        return (x >= self.half_range_v - self.lsb_v - tol) | (x <= -self.half_range_v + tol)

    def push(self, block: LiveBlock, *, loop_closed: bool) -> Trip | None:
        """Take a block; returns a :class:`Trip` when the protection must open the loop."""
        s = block.signals
        n = block.n
        nan = np.full(n, np.nan)
        dac = [s[c] for c in ("Uch", "Ucv") if c in s]
        sat = np.any([self._on_rail(x) for x in dac], axis=0) if dac else np.zeros(n, bool)
        qd = [s[c] for c in ("Vph", "Vpv") if c in s]
        qd_sat = np.any([self._on_rail(x) for x in qd], axis=0) if qd else np.zeros(n, bool)
        self._ring.push(np.column_stack([s.get("Vph", nan), s.get("Vpv", nan), s.get("Va", nan),
                                         sat.astype(float), qd_sat.astype(float)]))
        self.samples += n
        if not loop_closed or n == 0:
            return None
        t = (block.start_sample + n) / self.fs_hz
        window = round(2 * self.limits.saturation_s * self.fs_hz)
        saturated_s = float(self._ring.last(window)[:, 3].sum()) / self.fs_hz
        if saturated_s > self.limits.saturation_s:
            return Trip(reason=f"the DAC saturated {saturated_s * 1e3:.0f} ms of the last "
                               f"{window / self.fs_hz * 1e3:.0f} ms (limit "
                               f"{self.limits.saturation_s * 1e3:.0f} ms)", bench_time_s=t)
        limit = self.limits.beam_fraction * self.half_range_v
        for name, x in zip(("Vph", "Vpv"), qd, strict=False):
            if not np.all(np.isfinite(x)):
                return Trip(reason=f"the 4QD reading {name} is not finite", bench_time_s=t)
            peak = float(np.max(np.abs(x)))
            if peak > limit:
                return Trip(reason=f"the beam diverges: {name} reached {peak:.2f} V, beyond "
                                   f"{limit:.1f} V ({self.limits.beam_fraction:.0%} of the "
                                   "4QD's ADC range)", bench_time_s=t)
        return None

    def _window(self, seconds: float) -> np.ndarray:
        return self._ring.last(max(1, round(seconds * self.fs_hz)))

    def beam_angle_rad(self) -> tuple[float, float]:
        """Mean beam angle (h, v) over the last 0.1 s [rad] (4QD voltage over its gain)."""
        w = self._window(0.1)
        if not len(w):
            return (float("nan"), float("nan"))
        return (float(np.mean(w[:, 0]) / self.gd[0]), float(np.mean(w[:, 1]) / self.gd[1]))

    def distance_m(self) -> float:
        """Mean Attocube distance over the last 0.1 s [m]."""
        w = self._window(0.1)
        return float(np.mean(w[:, 2])) if len(w) else float("nan")

    def tracking_rms_rad(self) -> tuple[float, float]:
        """Rms about the mean of the beam angle (h, v) over the last 1 s [rad]."""
        w = self._window(1.0)
        if len(w) < 2:
            return (float("nan"), float("nan"))
        return (float(np.std(w[:, 0]) / abs(self.gd[0])), float(np.std(w[:, 1]) / abs(self.gd[1])))

    def dac_saturation(self) -> float:
        """Fraction of the last 1 s with a controlled command on a DAC rail."""
        w = self._window(1.0)
        return float(np.mean(w[:, 3])) if len(w) else 0.0

    def saturating_now(self) -> bool:
        """A controlled DAC command or a 4QD reading on a rail in the last 10 ms."""
        return self.rail_fraction(0.01) > 0

    def rail_fraction(self, seconds: float) -> float:
        """Fraction of the last ``seconds`` with a controlled DAC command or a 4QD reading on
        a rail [1] (0 before any sample)."""
        w = self._window(seconds)
        return float(np.mean(np.maximum(w[:, 3], w[:, 4]))) if len(w) else 0.0

    def rail_flags(self, seconds: float) -> np.ndarray:
        """Each of the last ``seconds`` of samples, oldest first: a controlled DAC command or a
        4QD reading on a rail (bool, shape (N,))."""
        w = self._window(seconds)
        return np.maximum(w[:, 3], w[:, 4]) > 0 if len(w) else np.zeros(0, dtype=bool)

    def qd_deviation_v(self, seconds: float) -> tuple[float, float]:
        """Largest deviation of ``Vph``, ``Vpv`` from their mean over the last ``seconds``
        [V] (the mirror's ringing amplitude in open loop; NaN before any sample)."""
        w = self._window(seconds)
        if not len(w):
            return (float("nan"), float("nan"))
        dev = np.max(np.abs(w[:, :2] - np.mean(w[:, :2], axis=0)), axis=0)
        return (float(dev[0]), float(dev[1]))
