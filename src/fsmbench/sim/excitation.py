"""Open-loop commands the bench plays on its DAC channels, generated block by block.

An :class:`Excitation` says what to play (white or band-limited noise, a
sine, a random-phase multisine) on which channel from when; an
:class:`ExcitationStream` plays it from a sample counter, so a record cut
into blocks receives, bit for bit, the samples of one whole record: sines
and multisines are functions of the absolute sample index, noise draws from
its own generator sample by sample and its band-pass filter hands its state
over between blocks.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from scipy.signal import butter, sosfilt, sosfilt_zi

__all__ = ["DAC_LIMIT_FRACTION", "Excitation", "ExcitationKind", "ExcitationStream",
           "multisine_lines"]

ExcitationKind = Literal["noise", "sine", "multisine"]

#: Peak of an excitation allowed against the DAC's half range (refused above).
DAC_LIMIT_FRACTION = 1.0


@dataclass(frozen=True)
class Excitation:
    """An open-loop command on one DAC channel.

    Attributes
    ----------
    channel : str
        ``Uch``, ``Ucv``, ``Unh`` or ``Unv``.
    kind : {"noise", "sine", "multisine"}
        Gaussian noise of standard deviation ``amplitude_v`` (white, or
        band-limited to ``band_hz`` by a 4th-order Butterworth band-pass); a
        sine of amplitude ``amplitude_v`` at ``freq_hz`` starting at phase 0;
        a multisine of rms ``amplitude_v`` with equal-amplitude lines every
        ``1/period_s`` inside ``band_hz`` and random phases.
    amplitude_v : float
        [V]: standard deviation (noise), amplitude (sine) or rms (multisine).
    start_s : float
        The command is zero before this time of the bench [s].
    freq_hz : float
        Sine frequency [Hz] (sine only).
    band_hz : tuple of float, optional
        (low, high) [Hz]: noise band (None: white to Nyquist) or multisine band.
    period_s : float
        Multisine period [s] (its frequency resolution is ``1/period_s``).
    """

    channel: str
    kind: ExcitationKind
    amplitude_v: float
    start_s: float
    freq_hz: float = 0.0
    band_hz: tuple[float, float] | None = None
    period_s: float = 1.0

    def peak_v(self) -> float:
        """Largest command the excitation gives [V] (noise: 4.5 standard deviations)."""
        if self.kind == "sine":
            return abs(self.amplitude_v)
        if self.kind == "multisine":
            # Random phases give crest factors of ~3-4 for many lines; the bound
            # over all phases is sqrt(2 n_lines), far too pessimistic. The
            # stream computes the real peak of the period it plays.
            return abs(self.amplitude_v) * 4.5
        return abs(self.amplitude_v) * 4.5


def multisine_lines(*, band_hz: tuple[float, float], period_s: float,
                    fs_hz: float) -> np.ndarray:
    """Frequencies of a multisine's lines [Hz]: multiples of ``1/period_s`` inside the band.

    Raises
    ------
    ValueError
        No line falls inside the band below Nyquist.
    """
    lo, hi = band_hz
    df = 1.0 / period_s
    k = np.arange(max(1, int(np.ceil(lo / df - 1e-9))), int(np.floor(hi / df + 1e-9)) + 1)
    f = k * df
    f = f[(f < fs_hz / 2)]
    if f.size == 0:
        raise ValueError(f"no multisine line between {lo:g} and {hi:g} Hz with a {period_s:g} s "
                         f"period below Nyquist ({fs_hz / 2:g} Hz)")
    return f


class ExcitationStream:
    """Plays one :class:`Excitation` sample by sample (see the module notes).

    Parameters
    ----------
    excitation : Excitation
    fs_hz : float
        Bench sampling rate [Hz].
    rng : numpy Generator
        Noise samples (noise) or line phases (multisine); unused for sines.
    """

    def __init__(self, excitation: Excitation, *, fs_hz: float,
                 rng: np.random.Generator) -> None:
        self.excitation = excitation
        self.fs_hz = float(fs_hz)
        self._rng = rng
        # First sample played: the first k with k/fs >= start_s (the same test as next()).
        self._start = int(np.ceil(excitation.start_s * fs_hz))
        while self._start > 0 and (self._start - 1) / fs_hz >= excitation.start_s:
            self._start -= 1
        while self._start / fs_hz < excitation.start_s:
            self._start += 1
        self._sos: np.ndarray | None = None
        self._zi: np.ndarray | None = None
        self._period: np.ndarray | None = None
        if excitation.kind == "noise" and excitation.band_hz is not None:
            lo, hi = excitation.band_hz
            nyq = fs_hz / 2
            if not 0 <= lo < hi:
                raise ValueError(f"noise band must be 0 <= low < high, got {excitation.band_hz}")
            if lo == 0:
                self._sos = butter(4, min(hi, 0.999 * nyq), btype="low", fs=fs_hz, output="sos")
            else:
                self._sos = butter(4, [lo, min(hi, 0.999 * nyq)], btype="band", fs=fs_hz,
                                   output="sos")
        elif excitation.kind == "multisine":
            band = excitation.band_hz or (1.0 / excitation.period_s, fs_hz / 2)
            f = multisine_lines(band_hz=band, period_s=excitation.period_s, fs_hz=fs_hz)
            n_period = round(excitation.period_s * fs_hz)
            if abs(n_period - excitation.period_s * fs_hz) > 1e-6:
                raise ValueError(f"multisine period {excitation.period_s:g} s is not a whole "
                                 f"number of samples at {fs_hz:g} Hz")
            phases = rng.uniform(0.0, 2.0 * np.pi, f.size)
            t = np.arange(n_period) / fs_hz
            one = np.cos(2.0 * np.pi * f[:, None] * t[None, :] + phases[:, None]).sum(axis=0)
            # Lines of equal amplitude a have rms a·sqrt(n/2): scale the period to the rms asked.
            self._period = one * (excitation.amplitude_v / np.sqrt(f.size / 2.0))
        elif excitation.kind not in ("noise", "sine"):
            raise ValueError(f"unknown excitation kind {excitation.kind!r}; "
                             "known: noise, sine, multisine")

    def peak_v(self) -> float:
        """Largest command [V]: exact for sines and multisines, 4.5 σ for noise."""
        if self._period is not None:
            return float(np.max(np.abs(self._period)))
        return self.excitation.peak_v()

    def next(self, k0: int, n: int) -> np.ndarray:
        """Samples ``k0 .. k0+n-1`` of the command [V], shape (n,); calls must be consecutive."""
        ex = self.excitation
        k = np.arange(k0, k0 + n)
        on = k / self.fs_hz >= ex.start_s
        out = np.zeros(n)
        n_on = int(on.sum())
        if n_on == 0:
            return out
        if ex.kind == "noise":
            w = ex.amplitude_v * self._rng.standard_normal(n_on) if ex.amplitude_v != 0 \
                else np.zeros(n_on)
            if self._sos is not None:
                if self._zi is None:
                    self._zi = sosfilt_zi(self._sos) * 0.0
                # The band-pass keeps the noise's rms only approximately; the
                # filter's noise gain is divided out so the rms is the one asked.
                w, self._zi = sosfilt(self._sos, w, zi=self._zi)
                w = w / self._noise_gain()
            out[on] = w
        elif ex.kind == "sine":
            t = k[on] / self.fs_hz
            out[on] = ex.amplitude_v * np.sin(2 * np.pi * ex.freq_hz * (t - ex.start_s))
        else:
            assert self._period is not None
            out[on] = self._period[(k[on] - self._start) % self._period.size]
        return out

    def _noise_gain(self) -> float:
        """Rms gain of the band-pass for white noise (from its impulse response)."""
        if not hasattr(self, "_gain"):
            assert self._sos is not None
            impulse = np.zeros(round(20 * self.fs_hz))
            impulse[0] = 1.0
            h = sosfilt(self._sos, impulse)
            self._gain = float(np.sqrt(np.sum(h * h)))
        return self._gain
