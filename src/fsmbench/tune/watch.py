"""A loop that watches itself: its running tracking error against the loaded prediction.

Pure numerics, fed blocks of the measured tracking error (4QD reading over its
gain, both axes) as the bench runs; the live device and the twin call it alike.

Every ``window_s`` the ASD of the last window (Welch, ``segment_s`` Hann segments,
half overlap) is integrated band by band and compared with the prediction of
the loaded controller on the current model (the PSD of
:func:`fsmbench.control.validation.tracking_error_spectra`, lines included):

* the prediction of each band is **calibrated** on the first ``baseline_windows``
  windows after the controller is loaded (their mean measured/predicted ratio):
  the linear prediction misses part of the loop's response at a notched
  resonance, and the watch is for what changes afterwards;
* the **statistical band**: a band's measured power over ``M`` Welch bins of ``K``
  averaged segments has ``2 K M / c`` degrees of freedom (``c = 1.5``: the Hann
  window's neighbouring bins are correlated, Welch 1967), ``M`` the bins that
  carry the power (the participation ratio ``(sum S)² / sum S²`` of the
  baseline's spectrum: a lightly damped peak is one or two bins); against the
  baseline's mean of ``B`` windows the ratio is F-distributed, and ``z`` is the
  normal quantile of its tail probability (:func:`_z`);
* a **WARNING** when a band's ``z`` exceeds ``raise_sigma`` in ``raise_windows``
  consecutive windows; cleared (hysteresis) only when every band stays below
  ``clear_sigma`` for ``clear_windows`` consecutive windows;
* each axis's **resonance peak** in the tracking error (within ``resonance_width``
  of the model's resonance ``resonances_hz[i]``, h then v) is located in every
  window (parabolic on the log PSD) and compared with where the baseline had
  it, in units of its jitter over the baseline windows: a drift moves the peak
  long before it changes the band's power;
* the **likely cause**, where the spectrum shows it: *a resonance moved* when its
  peak moved, or when the
  excess is a peak within ``resonance_width`` of a Sercalo resonance (where the
  controller's notch or roll-off is), *a new line* when one bin holds most of
  the band's excess elsewhere, *the sensor noise floor rose* when the excess is
  spread over the band (and over several bands); each suggests ``fsmbench tune``.

The detection time of a slow drift is the time to the first window whose
excess reaches ``raise_sigma``, plus ``raise_windows - 1`` windows.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy import signal, stats

__all__ = ["BandCheck", "LoopWatch", "WatchEvent", "WatchOptions"]

AXES = ("h", "v")
# Welch with Hann segments at half overlap: neighbouring bins correlated, the effective number
# of independent bins in a band is about M / 1.5 (Welch 1967, Table 1's 50 % overlap).
_BIN_CORRELATION = 1.5


@dataclass(frozen=True)
class WatchOptions:
    """How the loop watches itself.

    Attributes
    ----------
    bands_hz : tuple of (float, float)
        The bands compared [Hz].
    window_s, segment_s : float
        Length of each judged window and of its Welch segments [s].
    raise_sigma, clear_sigma : float
        ``z`` that raises the warning and below which it clears (hysteresis).
    raise_windows, clear_windows : int
        Consecutive windows needed to raise and to clear.
    baseline_windows : int
        Windows right after the controller is loaded on which each band's prediction
        is calibrated (0: the bare prediction). The linear prediction misses part of
        the loop's response at a notched resonance (on the twin with the ESRF study's
        controller, 25 µrad rms measured in 200-300 Hz against 16.9 predicted): the
        watch judges what changed since, in the prediction's shape.
    resonance_width : float
        Relative distance of a peak from a resonance to blame the resonance [1].
    line_share : float
        Share of a band's excess one bin must hold to be called a new line [1].
    """

    bands_hz: tuple[tuple[float, float], ...] = (
        (0.5, 10.0), (10.0, 100.0), (100.0, 200.0), (200.0, 300.0), (300.0, 600.0),
        (600.0, 2000.0), (2000.0, 5000.0))
    window_s: float = 10.0
    segment_s: float = 1.0
    raise_sigma: float = 5.0
    clear_sigma: float = 2.0
    raise_windows: int = 3
    clear_windows: int = 3
    baseline_windows: int = 6
    resonance_width: float = 0.1
    line_share: float = 0.5

    def __post_init__(self) -> None:
        if not self.window_s >= 2 * self.segment_s > 0:
            raise ValueError(f"a window ({self.window_s!r} s) holds at least two Welch "
                             f"segments ({self.segment_s!r} s)")
        if not self.raise_sigma > self.clear_sigma >= 0:
            raise ValueError("the warning must clear below where it is raised")


@dataclass(frozen=True)
class BandCheck:
    """One band of one axis in one window.

    Attributes
    ----------
    axis : str
    band_hz : (float, float)
    measured_rad2, predicted_rad2 : float
        Power in the band [rad²].
    z : float
        Departure in units of the measurement's statistical scatter [1].
    peak_hz : float
        Frequency of the bin with the largest excess [Hz].
    peak_share : float
        That bin's share of the band's excess [1] (0 when there is none).
    moved_from_hz : float or None
        For a resonance's peak check: where the baseline had the peak [Hz] (``z`` is
        then the peak's shift in units of its jitter over the baseline windows).
    """

    axis: str
    band_hz: tuple[float, float]
    measured_rad2: float
    predicted_rad2: float
    z: float
    peak_hz: float
    peak_share: float
    moved_from_hz: float | None = None


@dataclass(frozen=True)
class WatchEvent:
    """A change of the warning, or a window while it is raised.

    Attributes
    ----------
    time_s : float
        End of the window [s] from the first sample fed.
    level : {"WARNING", "CLEARED"}
    cause : str
        In words, with the band and frequency, and what to do.
    bands : tuple of BandCheck
        The bands beyond ``raise_sigma``.
    """

    time_s: float
    level: str
    cause: str
    bands: tuple[BandCheck, ...] = ()


def _z(measured: float, reference: float, *, dof: float, baseline: int) -> float:
    """The departure of ``measured`` from ``reference`` as a normal quantile [1].

    A band power of ``dof`` degrees of freedom is ``reference chi2(dof)/dof``; against a
    reference that is itself the mean of ``baseline`` such windows their ratio is
    F(dof, baseline dof) distributed (chi2 over its dof when there is no baseline). The
    one-sided tail probability of the ratio, as the normal quantile with that tail: few
    degrees of freedom (a lightly damped peak is one or two bins) give a skewed ratio
    that a normal scale would raise alarms on.
    """
    if not reference > 0:
        return math.inf
    ratio = measured / reference
    tail = (stats.f.sf(ratio, dof, baseline * dof) if baseline
            else stats.chi2.sf(ratio * dof, dof))
    lower = (stats.f.cdf(ratio, dof, baseline * dof) if baseline
             else stats.chi2.cdf(ratio * dof, dof))
    return float(stats.norm.isf(tail) if tail < lower else -stats.norm.isf(lower))


@dataclass
class LoopWatch:
    """Feed it the tracking error as it comes (:meth:`feed`); it keeps the warning state.

    Parameters
    ----------
    f_hz : ndarray, shape (F,)
        Frequencies of the prediction [Hz], increasing, up to the Nyquist frequency.
    predicted_psd : ndarray, shape (F, 2)
        Predicted one-sided PSD of the tracking error per axis [rad²/Hz].
    fs_hz : float
    resonances_hz : sequence of float
        The Sercalo's resonances of the current model [Hz].
    line_power : mapping frequency -> (2,) power, optional
        Predicted lines (mains) [rad²], added to their band.
    options : WatchOptions
    """

    f_hz: np.ndarray
    predicted_psd: np.ndarray
    fs_hz: float
    resonances_hz: Sequence[float] = ()
    line_power: dict[float, np.ndarray] = field(default_factory=dict)
    options: WatchOptions = field(default_factory=WatchOptions)
    warning: bool = False
    events: list[WatchEvent] = field(default_factory=list)
    _buffer: list[np.ndarray] = field(default_factory=list)
    _buffered: int = 0
    _time_s: float = 0.0
    _above: int = 0
    _below: int = 0
    _baseline: list[tuple[BandCheck, ...]] = field(default_factory=list)
    _baseline_psd: list[np.ndarray] = field(default_factory=list)
    _last_psd: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    _last_f: np.ndarray = field(default_factory=lambda: np.zeros(0))
    _recent: list[tuple[BandCheck, ...]] = field(default_factory=list)
    history: list[tuple[float, tuple[BandCheck, ...]]] = field(default_factory=list)

    def feed(self, error_rad: np.ndarray) -> list[WatchEvent]:
        """Add samples (n, 2) [rad]; returns the events of the windows completed."""
        e = np.asarray(error_rad, dtype=float)
        if e.ndim != 2 or e.shape[1] != 2:
            raise ValueError(f"the tracking error is (n, 2) [rad], got {e.shape}")
        self._buffer.append(e)
        self._buffered += e.shape[0]
        n_win = round(self.options.window_s * self.fs_hz)
        out: list[WatchEvent] = []
        while self._buffered >= n_win:
            data = np.vstack(self._buffer)
            window, rest = data[:n_win], data[n_win:]
            self._buffer, self._buffered = [rest], rest.shape[0]
            self._time_s += n_win / self.fs_hz
            out += self._judge(window)
        self.events += out
        return out

    def discard(self) -> None:
        """Drop the samples of the window being filled (the loop was disturbed: an
        excitation, an experiment); the next window starts with the next samples fed.
        The time axis (``time_s`` of the events) counts judged windows only."""
        self._buffer, self._buffered = [], 0

    def check(self, window: np.ndarray) -> tuple[BandCheck, ...]:
        """The band checks of one window (n, 2) [rad]."""
        opts = self.options
        nseg = round(opts.segment_s * self.fs_hz)
        f, p = signal.welch(window - window.mean(axis=0), fs=self.fs_hz, nperseg=nseg, axis=0)
        k = 2 * window.shape[0] // nseg - 1  # Hann segments at half overlap
        df = f[1] - f[0]
        pred = np.column_stack([np.interp(f, self.f_hz, self.predicted_psd[:, i])
                                for i in range(2)])
        # The spectrum's shape for the scatter: the baseline's mean where there is one.
        done = len(self._baseline) >= self.options.baseline_windows > 0
        shape = np.mean(self._baseline_psd, axis=0) if done else pred
        self._last_psd = p
        self._last_f = f
        checks = []
        for i, axis in enumerate(AXES):
            for lo, hi in opts.bands_hz:
                sel = (f >= lo) & (f < hi)
                m = int(np.count_nonzero(sel))
                if m == 0:
                    continue
                measured = float(np.sum(p[sel, i]) * df)
                # The prediction integrated on its own grid: a 0.1 %-damped peak is narrower
                # than a Welch bin, and sampled at the bins its power would be missed.
                fine = (self.f_hz >= f[sel][0] - df / 2) & (self.f_hz < f[sel][-1] + df / 2)
                predicted = float(np.trapezoid(self.predicted_psd[fine, i],
                                               self.f_hz[fine])) + sum(
                    float(v[i]) for fl, v in self.line_power.items() if lo <= fl < hi)
                # Calibrated once the baseline is complete; its windows keep the bare
                # prediction (what the calibration divides by).
                base = self._calibration(axis, (lo, hi)) if done else 1.0
                predicted *= base
                # The band's independent bins: M for a flat spectrum, fewer where a narrow peak
                # holds the power (the participation ratio, (sum S)^2 / sum S^2).
                sb = shape[sel, i]
                m_eff = float(sb.sum() ** 2 / np.sum(sb**2)) if np.any(sb > 0) else float(m)
                z = _z(measured, predicted, dof=2.0 * k * m_eff / _BIN_CORRELATION,
                       baseline=len(self._baseline) if done else 0)
                excess = np.maximum(p[sel, i] - base * pred[sel, i], 0.0)
                j = int(np.argmax(excess))
                share = float(excess[j] / excess.sum()) if excess.sum() > 0 else 0.0
                checks.append(BandCheck(axis, (lo, hi), measured, predicted, float(z),
                                        float(f[sel][j]), share))
        return tuple(checks)

    def _peak_hz(self, f: np.ndarray, p: np.ndarray, f0: float) -> float:
        """The peak of ``p`` within ``resonance_width`` of ``f0``, parabolic on log power [Hz]."""
        w = self.options.resonance_width
        idx = np.flatnonzero((f >= f0 * (1 - w)) & (f <= f0 * (1 + w)))
        j = int(idx[np.argmax(p[idx])])
        if 0 < j < f.size - 1 and np.all(p[j - 1: j + 2] > 0):
            a, b, c = np.log(p[j - 1: j + 2])
            den = a - 2 * b + c
            shift = 0.5 * (a - c) / den if den < 0 else 0.0
            return float(f[j] + shift * (f[1] - f[0]))
        return float(f[j])

    def _peak_checks(self, f: np.ndarray, p: np.ndarray) -> tuple[BandCheck, ...]:
        """Each axis's resonance peak against where the baseline windows had it."""
        out = []
        df = f[1] - f[0]
        for i, (axis, f0) in enumerate(zip(AXES, self.resonances_hz, strict=False)):
            base = [self._peak_hz(self._last_f, q[:, i], f0) for q in self._baseline_psd]
            ref = float(np.mean(base))
            # The peak's jitter over the baseline windows, at least a tenth of a bin.
            jitter = max(float(np.std(base, ddof=1)) if len(base) > 1 else 0.0, 0.1 * df)
            now = self._peak_hz(f, p[:, i], f0)
            w = self.options.resonance_width
            band = (f0 * (1 - w), f0 * (1 + w))
            out.append(BandCheck(axis, band, 0.0, 0.0,
                                 abs(now - ref) / (jitter * math.sqrt(1 + 1 / len(base))),
                                 now, 1.0, moved_from_hz=ref))
        return tuple(out)

    def cause(self, bands: Sequence[BandCheck]) -> str:
        """The likely cause of the excess in ``bands``, in words, with what to do.

        A band whose excess peaks near a resonance is named first (the drift the watch
        is for moves the loop's response around it, a neighbouring band may rise more).
        """
        opts = self.options
        moved = [b for b in bands if b.moved_from_hz is not None]
        if moved:
            b = max(moved, key=lambda c: c.z)
            assert b.moved_from_hz is not None
            return (f"{b.axis} axis: the tracking error's peak near the Sercalo resonance moved "
                    f"from {b.moved_from_hz:.1f} Hz to {b.peak_hz:.1f} Hz "
                    f"({100 * (b.peak_hz / b.moved_from_hz - 1):+.1f} %): the resonance has "
                    "likely moved. Run fsmbench tune to re-identify and re-tune with the loop "
                    "closed")
        at_mode = [b for b in bands if b.peak_share >= 0.1 and any(
            abs(b.peak_hz / r - 1.0) <= opts.resonance_width for r in self.resonances_hz)]
        worst = max(at_mode or bands, key=lambda b: b.z)
        where = (f"{worst.axis} axis, {worst.band_hz[0]:g}-{worst.band_hz[1]:g} Hz: "
                 f"{math.sqrt(worst.measured_rad2) * 1e6:.3g} µrad rms measured against "
                 f"{math.sqrt(worst.predicted_rad2) * 1e6:.3g} predicted")
        near = [r for r in self.resonances_hz
                if abs(worst.peak_hz / r - 1.0) <= opts.resonance_width]
        if near and worst.peak_share >= 0.1:
            what = (f"a peak at {worst.peak_hz:.1f} Hz near the Sercalo resonance "
                    f"({near[0]:.1f} Hz in the model): the resonance has likely moved")
        elif worst.peak_share >= opts.line_share:
            what = f"a new line at {worst.peak_hz:.1f} Hz (mains, a pump, a fan)"
        elif len({b.band_hz for b in bands}) >= 2 or worst.peak_share < 0.1:
            what = "an excess spread over the band: the sensor noise floor has likely risen"
        else:
            what = f"an excess peaking at {worst.peak_hz:.1f} Hz"
        return f"{where}; {what}. Run fsmbench tune to re-identify and re-tune with the loop closed"

    def _calibration(self, axis: str, band: tuple[float, float]) -> float:
        """Measured over predicted power in ``band`` on the baseline windows (1 without)."""
        pairs = [(c.measured_rad2, c.predicted_rad2) for w in self._baseline for c in w
                 if c.axis == axis and c.band_hz == band and c.predicted_rad2 > 0]
        # The baseline's measured power over its predicted: a mean of powers, not of ratios.
        return float(sum(m for m, _p in pairs) / sum(p for _m, p in pairs)) if pairs else 1.0

    def _judge(self, window: np.ndarray) -> list[WatchEvent]:
        opts = self.options
        checks = self.check(window)
        if self.resonances_hz and len(self._baseline_psd) >= max(2, opts.baseline_windows):
            checks = checks + self._peak_checks(self._last_f, self._last_psd)
        self.history.append((self._time_s, checks))
        if len(self._baseline) < opts.baseline_windows:
            self._baseline.append(checks)  # the calibration: nothing judged yet
            self._baseline_psd.append(self._last_psd)
            return []
        beyond = tuple(c for c in checks if c.z > opts.raise_sigma)
        quiet = all(c.z < opts.clear_sigma for c in checks)
        self._above = self._above + 1 if beyond else 0
        self._recent = ([*self._recent, beyond] if beyond else [])[-opts.raise_windows:]
        self._below = self._below + 1 if quiet else 0
        if not self.warning and self._above >= opts.raise_windows:
            self.warning = True
            seen = tuple(b for w in self._recent for b in w)  # the windows that raised it
            return [WatchEvent(self._time_s, "WARNING", self.cause(seen), beyond)]
        if self.warning and self._below >= opts.clear_windows:
            self.warning = False
            return [WatchEvent(self._time_s, "CLEARED", "the tracking error is back within "
                               "its prediction in every band")]
        return []
