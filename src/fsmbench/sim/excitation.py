"""Open-loop commands the bench plays on its DAC channels, generated block by block.

An :class:`Excitation` says what to play (white or band-limited noise, a
sine, a random-phase multisine) on which channel from when; a
:class:`SampledExcitation` plays given samples (a designed excitation, see
:mod:`fsmbench.excite`). An :class:`ExcitationStream` plays either from a
sample counter, so a record cut into blocks receives, bit for bit, the
samples of one whole record: sines, multisines and sample arrays are
functions of the absolute sample index, noise draws from its own generator
sample by sample and its band-pass filter hands its state over between blocks.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from scipy.signal import butter, sosfilt, sosfilt_zi

__all__ = ["DAC_LIMIT_FRACTION", "Excitation", "ExcitationKind", "ExcitationStream",
           "SampledExcitation", "multisine_lines", "samples_sha256"]

ExcitationKind = Literal["noise", "sine", "multisine", "samples"]

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


def samples_sha256(samples_v: np.ndarray) -> str:
    """SHA-256 of samples as little-endian float64 (names a sample array in files)."""
    return hashlib.sha256(np.ascontiguousarray(samples_v, dtype="<f8").tobytes()).hexdigest()


@dataclass(frozen=True)
class SampledExcitation(Excitation):
    """Given samples played on one DAC channel from ``start_s``, one per converter sample.

    ``kind`` is ``"samples"``; ``amplitude_v`` is informative (e.g. the rms).

    Attributes
    ----------
    samples_v : ndarray, shape (n,)
        The commands [V], at the bench's sampling rate (stored read-only).
    loop_from : int or None
        After the last sample: None plays zeros; an index ``i`` repeats
        ``samples_v[i:]`` for ever (``i`` = the transient samples of a
        periodic excitation keeps it periodic).
    samples_sha256 : str
        SHA-256 of the samples (:func:`samples_sha256`), set on creation;
        excitations compare equal when their samples do.
    """

    samples_v: np.ndarray = field(default_factory=lambda: np.zeros(0), compare=False,
                                  repr=False)
    loop_from: int | None = None
    samples_sha256: str = field(init=False, default="")

    def __post_init__(self) -> None:
        x = np.array(self.samples_v, dtype=float)
        if self.kind != "samples":
            raise ValueError(f"a sampled excitation has kind 'samples', not {self.kind!r}")
        if x.ndim != 1 or x.size == 0 or not np.all(np.isfinite(x)):
            raise ValueError(f"excitation on {self.channel}: samples must be a non-empty, "
                             f"finite 1-D array, got shape {x.shape}")
        if self.loop_from is not None and not 0 <= self.loop_from < x.size:
            raise ValueError(f"excitation on {self.channel}: loop start {self.loop_from} is "
                             f"outside the {x.size} samples")
        x.setflags(write=False)
        object.__setattr__(self, "samples_v", x)
        object.__setattr__(self, "samples_sha256", samples_sha256(x))

    def peak_v(self) -> float:
        """Largest command [V] (exact)."""
        return float(np.max(np.abs(self.samples_v)))


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
        Noise samples (noise) or line phases (multisine); unused for sines and samples.
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
        elif excitation.kind == "samples":
            if not isinstance(excitation, SampledExcitation):
                raise ValueError(f"excitation on {excitation.channel} of kind 'samples' must "
                                 "be a SampledExcitation (it holds the samples)")
        elif excitation.kind not in ("noise", "sine"):
            raise ValueError(f"unknown excitation kind {excitation.kind!r}; "
                             "known: noise, sine, multisine, samples")

    def peak_v(self) -> float:
        """Largest command [V]: exact for sines, multisines and samples, 4.5 σ for noise."""
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
        elif isinstance(ex, SampledExcitation):
            out[on] = _played(ex, k[on] - self._start)
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


def _played(ex: SampledExcitation, i: np.ndarray) -> np.ndarray:
    """Samples at indices ``i >= 0`` counted from the first one played (see ``loop_from``)."""
    x = ex.samples_v
    n = x.size
    out = np.zeros(i.size)
    inside = i < n
    out[inside] = x[i[inside]]
    if ex.loop_from is not None and not inside.all():
        span = n - ex.loop_from
        out[~inside] = x[ex.loop_from + (i[~inside] - n) % span]
    return out
