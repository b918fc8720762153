"""Streaming Welch estimates for the live bench: a rolling ASD and an accumulating H1 FRF.

Both estimators are fed block by block (any block length, down to one sample)
and give the numbers fsmbench's batch functions (:mod:`fsmbench.signal.welch`,
MATLAB semantics) give on the same samples:

* :class:`RollingAsd`: ``sqrt(pwelch(x, hanning(ceil(window_s*fs)), [], [], fs))``
  of the last ``span_s`` seconds of each channel, the seed's 1 s Welch
  (:func:`fsmbench.budget.spectra.esrf_welch`) over a sliding span.
* :class:`AccumulatingFrf`: ``tfestimate`` (H1) and ``mscohere`` of one input and
  several outputs over every complete Welch segment pushed since the start (or
  the last :meth:`AccumulatingFrf.reset`); segments that straddle two blocks are
  kept, through a tail buffer shorter than one segment.

Window: MATLAB's ``hanning(L)`` (symmetric, no zero end-points), ``L =
ceil(window_s * fs_hz)`` samples, as every Welch estimate of the study uses;
FFT length MATLAB's default ``max(256, 2^nextpow2(L))``.

Memory is bounded: the ASD keeps a ring buffer of ``span_s`` seconds, the FRF
only its spectral sums and one segment of tail.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import scipy.fft
from numpy.typing import ArrayLike, NDArray

from fsmbench.signal.welch import WelchOptions, hanning, pwelch

__all__ = ["AccumulatingFrf", "AsdSnapshot", "FrfSnapshot", "RollingAsd"]

# Segments transformed per rfft call in AccumulatingFrf.push: bounds the
# temporary (channels x segments x nfft complex) array of one large block.
_SEGMENTS_PER_CHUNK = 32


# --------------------------------------------------------------------------- shared checks
def _check_fs(fs_hz: float) -> float:
    fs = float(fs_hz)
    if not (math.isfinite(fs) and fs > 0.0):
        raise ValueError(f"sampling frequency must be a positive finite value in Hz, got {fs_hz!r}")
    return fs


def _window_options(fs_hz: float, window_s: float, noverlap: int | None) -> WelchOptions:
    """``hanning(ceil(window_s * fs))`` with the given overlap (MATLAB default if None)."""
    win_s = float(window_s)
    if not (math.isfinite(win_s) and win_s > 0.0):
        raise ValueError(f"Welch window length must be a positive duration in s, got {window_s!r}")
    length = math.ceil(win_s * fs_hz)  # the seed's hanning(ceil(1*fs))
    return WelchOptions.from_matlab(window=hanning(length), noverlap=noverlap, fs_hz=fs_hz)


def _names(names: Sequence[str], what: str) -> tuple[str, ...]:
    if isinstance(names, str):
        raise TypeError(f"{what} must be a sequence of signal names, got the string {names!r}")
    out = tuple(str(n) for n in names)
    if not out:
        raise ValueError(f"{what} must name at least one signal")
    if len(set(out)) != len(out):
        raise ValueError(f"{what} has repeated signal names: {', '.join(out)}")
    return out


def _check_finite(block: NDArray[np.float64], names: Sequence[str], owner: str) -> None:
    """Raise naming the first signal and sample that is NaN or infinite (rows = signals)."""
    bad = ~np.isfinite(block)
    if bad.any():
        row, col = np.argwhere(bad)[0]
        raise ValueError(
            f"{owner}: signal {names[row]!r} has {int(bad[row].sum())} NaN or infinite "
            f"sample(s) in the pushed block (first at index {col} of the block); the block "
            "was not used"
        )


def _real_float(x: ArrayLike, what: str, owner: str) -> NDArray[np.float64]:
    arr = np.asarray(x)
    if np.iscomplexobj(arr):
        raise TypeError(f"{owner}: {what} is complex; only real signals are supported")
    return arr.astype(np.float64, copy=False)


# --------------------------------------------------------------------------- rolling ASD
@dataclass(frozen=True, eq=False)
class AsdSnapshot:
    """Amplitude spectral densities of the last samples of every channel.

    Attributes
    ----------
    frequency_hz : ndarray, shape (F,)
        One-sided frequency grid ``(0:nfft/2) * fs/nfft``, Hz (read-only).
    asd : ndarray, shape (n_channels, F)
        ``sqrt`` of the one-sided Welch PSD of each channel, unit/sqrt(Hz)
        (read-only); row ``i`` is ``channels[i]``.
    channels : tuple of str
        Channel names, in the order of the rows of ``asd``.
    n_samples_used : int
        Samples per channel the estimate is computed on (the latest ones).
    span_s : float
        ``n_samples_used / fs``, s: the time span the estimate covers.
    n_segments : int
        Number of Welch segments averaged.
    """

    frequency_hz: NDArray[np.float64]
    asd: NDArray[np.float64]
    channels: tuple[str, ...]
    n_samples_used: int
    span_s: float
    n_segments: int


class RollingAsd:
    """ASD of the last ``span_s`` seconds of several channels, fed block by block.

    :meth:`spectrum` equals ``sqrt(pwelch(x_last, window=hanning(L), fs_hz=fs))``
    of :func:`fsmbench.signal.welch.pwelch` (MATLAB's ``[]`` overlap, i.e. 50 %,
    and ``[]`` nfft), with ``x_last`` the last ``round(span_s * fs)`` samples of
    each channel, or all of them while fewer have been pushed. The
    configuration is fixed at construction (read-only properties).

    Parameters
    ----------
    fs_hz : float
        Sampling frequency, Hz.
    channels : sequence of str
        Channel names (the columns of every pushed block), distinct.
    window_s : float, optional
        Welch segment length, s; ``L = ceil(window_s * fs_hz)`` samples, Hann
        window ``hanning(L)``. Default 1 s (the study's).
    span_s : float, optional
        Time span kept and analysed, s; ``round(span_s * fs_hz)`` samples, at
        least one segment. Default 10 s.

    Notes
    -----
    :meth:`push` is O(n) per block of n samples (one copy into a ring buffer
    of ``span_s`` seconds); :meth:`spectrum` computes the Welch estimate of the
    buffer, about ``2 span_s / window_s`` FFTs of ``nfft`` points per channel.
    """

    def __init__(self, *, fs_hz: float, channels: Sequence[str], window_s: float = 1.0,
                 span_s: float = 10.0) -> None:
        fs = _check_fs(fs_hz)
        self._channels = _names(channels, "RollingAsd channels")
        self._options = _window_options(fs, window_s, None)
        span = float(span_s)
        capacity = round(span * fs) if math.isfinite(span) else 0
        if capacity < self._options.window_length:
            raise ValueError(
                f"RollingAsd span of {span_s!r} s ({capacity} samples at {fs:g} Hz) is shorter "
                f"than one Welch segment, {self._options.describe_window()}"
            )
        self._window_s = float(window_s)
        self._span_s = span
        self._buffer = np.zeros((len(self._channels), capacity))  # channel-major ring buffer
        self._write = 0  # column the next sample goes to
        self._count = 0  # valid columns, <= capacity
        self._pushed = 0

    # ----------------------------------------------------------------- configuration
    @property
    def fs_hz(self) -> float:
        """Sampling frequency, Hz."""
        return self._options.fs_hz

    @property
    def channels(self) -> tuple[str, ...]:
        """Channel names, the columns of a pushed block."""
        return self._channels

    @property
    def window_s(self) -> float:
        """Requested Welch segment length, s."""
        return self._window_s

    @property
    def span_s(self) -> float:
        """Requested span, s."""
        return self._span_s

    @property
    def window_length(self) -> int:
        """Segment length ``L``, samples."""
        return self._options.window_length

    @property
    def noverlap(self) -> int:
        """Overlap of consecutive segments, samples (``floor(L/2)``)."""
        return self._options.noverlap

    @property
    def nfft(self) -> int:
        """FFT length, samples."""
        return self._options.nfft

    @property
    def capacity(self) -> int:
        """Samples per channel kept, ``round(span_s * fs_hz)``."""
        return int(self._buffer.shape[1])

    @property
    def n_samples_pushed(self) -> int:
        """Samples per channel pushed since construction or :meth:`reset`."""
        return self._pushed

    # ----------------------------------------------------------------- streaming
    def reset(self) -> None:
        """Forget every sample pushed so far."""
        self._write = self._count = self._pushed = 0

    def push(self, block: ArrayLike) -> None:
        """Append a block of samples.

        Parameters
        ----------
        block : array_like, shape (n, n_channels)
            ``n >= 0`` new samples, one column per channel (unit of each
            channel); shape (n,) is accepted for a single channel.

        Raises
        ------
        ValueError
            Wrong shape, or NaN/infinite samples (the message names the
            channel); the estimator is left unchanged.
        """
        arr = _real_float(block, "the pushed block", "RollingAsd")
        c = len(self._channels)
        if arr.ndim == 1 and c == 1:
            arr = arr[:, None]
        if arr.ndim != 2 or arr.shape[1] != c:
            raise ValueError(
                f"RollingAsd: a block must have shape (n, {c}) for the channels "
                f"{', '.join(self._channels)}, got shape {arr.shape}"
            )
        data = arr.T  # (c, n)
        _check_finite(data, self._channels, "RollingAsd")
        n, cap = data.shape[1], self.capacity
        self._pushed += n
        if n >= cap:  # the block alone fills the span
            self._buffer[:] = data[:, n - cap:]
            self._write, self._count = 0, cap
            return
        first = min(n, cap - self._write)
        self._buffer[:, self._write:self._write + first] = data[:, :first]
        self._buffer[:, :n - first] = data[:, first:]
        self._write = (self._write + n) % cap
        self._count = min(self._count + n, cap)

    def samples(self) -> NDArray[np.float64]:
        """The samples kept, oldest first, shape (n_channels, n_samples_used) (a copy)."""
        if self._count < self.capacity:  # not yet wrapped: columns 0 .. count-1 in order
            return self._buffer[:, :self._count].copy()
        return np.concatenate([self._buffer[:, self._write:], self._buffer[:, :self._write]],
                              axis=1)

    def spectrum(self) -> AsdSnapshot | None:
        """ASD of the last ``span_s`` seconds (or of everything, if less was pushed).

        Returns
        -------
        AsdSnapshot or None
            None while fewer samples than one Welch segment (``window_length``)
            have been pushed; otherwise the snapshot, ``asd`` in unit/sqrt(Hz).
        """
        if self._count < self.window_length:
            return None
        x = self.samples()
        window = self._options.window
        rows = []
        n_seg = 0
        for name, channel in zip(self._channels, x, strict=True):
            psd = pwelch(channel, window=window, fs_hz=self.fs_hz, x_name=name)
            rows.append(np.sqrt(psd.values.real))
            n_seg = psd.n_segments
        asd = np.stack(rows)
        f = self._options.frequencies_hz
        for arr in (asd, f):
            arr.setflags(write=False)
        return AsdSnapshot(frequency_hz=f, asd=asd, channels=self._channels,
                           n_samples_used=int(x.shape[1]), span_s=x.shape[1] / self.fs_hz,
                           n_segments=n_seg)


# --------------------------------------------------------------------------- accumulating FRF
@dataclass(frozen=True, eq=False)
class FrfSnapshot:
    """H1 frequency responses and coherences of one input to several outputs.

    Attributes
    ----------
    frequency_hz : ndarray, shape (F,)
        One-sided frequency grid, Hz (read-only).
    h1 : ndarray, complex, shape (p, F)
        ``Pyx / Pxx`` per output (MATLAB ``tfestimate``), output unit / input
        unit (read-only); row ``i`` is ``output_names[i]``.
    coherence : ndarray, shape (p, F)
        Magnitude-squared coherence ``|Pyx|^2 / (Pxx Pyy)`` per output
        (MATLAB ``mscohere``), dimensionless in [0, 1] (read-only).
    n_segments : int
        Welch segments averaged.
    n_samples : int
        Samples the segments cover, ``(n_segments - 1) * hop + L``: the batch
        functions applied to the first ``n_samples`` pushed samples give the
        same numbers.
    input_name : str
        The excited input.
    output_names : tuple of str
        The outputs, in the order of the rows.
    """

    frequency_hz: NDArray[np.float64]
    h1: NDArray[np.complex128]
    coherence: NDArray[np.float64]
    n_segments: int
    n_samples: int
    input_name: str
    output_names: tuple[str, ...]


class AccumulatingFrf:
    """H1 estimate and coherence from one input to ``p`` outputs, accumulating as data come.

    Every complete Welch segment of the samples pushed since construction (or
    :meth:`reset`) is averaged, including segments that straddle two blocks:
    :meth:`result` equals :func:`fsmbench.signal.welch.tfestimate` and
    :func:`fsmbench.signal.welch.mscohere` (window ``hanning(L)``, overlap
    ``floor(overlap * L)``, default nfft) of the first ``n_samples`` pushed
    samples, to rounding. Only the spectral sums and a tail shorter than one
    segment are kept.

    Parameters
    ----------
    fs_hz : float
        Sampling frequency, Hz.
    input_name : str
        Name of the excited input (used in messages and the snapshot).
    output_names : sequence of str
        Names of the ``p`` outputs, the columns of every pushed ``y``.
    window_s : float, optional
        Segment length, s; ``L = ceil(window_s * fs_hz)`` samples. Default 1 s.
    overlap : float, optional
        Overlap of consecutive segments as a fraction of ``L`` in [0, 1);
        ``floor(overlap * L)`` samples. Default 0.5 (MATLAB's default).
    """

    def __init__(self, *, fs_hz: float, input_name: str, output_names: Sequence[str],
                 window_s: float = 1.0, overlap: float = 0.5) -> None:
        fs = _check_fs(fs_hz)
        ov = float(overlap)
        if not 0.0 <= ov < 1.0:
            raise ValueError(f"AccumulatingFrf overlap must be a fraction in [0, 1), got "
                             f"{overlap!r}")
        length = _window_options(fs, window_s, None).window_length
        self._options = _window_options(fs, window_s, math.floor(ov * length))
        self._names = _names([input_name, *_names(output_names, "AccumulatingFrf outputs")],
                             "AccumulatingFrf signals (input and outputs)")
        self._window_s = float(window_s)
        self._overlap = ov
        p, n_freq = len(self._names) - 1, self._options.nfft // 2 + 1
        self._tail = np.zeros((p + 1, length))  # samples of the next, incomplete segment
        self._sxx = np.zeros(n_freq)
        self._syx = np.zeros((p, n_freq), dtype=np.complex128)
        self._syy = np.zeros((p, n_freq))
        self._low = np.zeros(p + 1)  # min and max of every signal over the covered samples
        self._high = np.zeros(p + 1)
        self.reset()

    # ----------------------------------------------------------------- configuration
    @property
    def fs_hz(self) -> float:
        """Sampling frequency, Hz."""
        return self._options.fs_hz

    @property
    def input_name(self) -> str:
        """The excited input's name."""
        return self._names[0]

    @property
    def output_names(self) -> tuple[str, ...]:
        """The outputs' names, the columns of a pushed ``y``."""
        return self._names[1:]

    @property
    def window_s(self) -> float:
        """Requested segment length, s."""
        return self._window_s

    @property
    def overlap(self) -> float:
        """Requested overlap, fraction of a segment."""
        return self._overlap

    @property
    def window_length(self) -> int:
        """Segment length ``L``, samples."""
        return self._options.window_length

    @property
    def noverlap(self) -> int:
        """Overlap of consecutive segments, samples."""
        return self._options.noverlap

    @property
    def nfft(self) -> int:
        """FFT length, samples."""
        return self._options.nfft

    @property
    def n_segments(self) -> int:
        """Segments accumulated so far."""
        return self._k

    @property
    def n_samples_pushed(self) -> int:
        """Samples pushed since construction or :meth:`reset`."""
        return self._pushed

    # ----------------------------------------------------------------- streaming
    def reset(self) -> None:
        """Forget every sample and sum: start a new estimate."""
        self._fill = 0
        self._k = 0
        self._pushed = 0
        for acc in (self._sxx, self._syx, self._syy):
            acc[...] = 0.0
        self._low[:] = np.inf
        self._high[:] = -np.inf

    def push(self, u: ArrayLike, y: ArrayLike) -> None:
        """Append simultaneous samples of the input and the outputs.

        Parameters
        ----------
        u : array_like, shape (n,)
            Input samples (input unit), ``n >= 0``.
        y : array_like, shape (n, p)
            Output samples (output units), one column per output; shape (n,)
            is accepted for a single output.

        Raises
        ------
        ValueError
            Wrong shapes or NaN/infinite samples (the message names the
            signal); the estimator is left unchanged.
        """
        uu = _real_float(u, f"input {self.input_name!r}", "AccumulatingFrf")
        yy = _real_float(y, "the outputs", "AccumulatingFrf")
        p = len(self._names) - 1
        if yy.ndim == 1 and p == 1:
            yy = yy[:, None]
        if uu.ndim != 1 or yy.ndim != 2 or yy.shape != (uu.size, p):
            raise ValueError(
                f"AccumulatingFrf: expected u of shape (n,) and y of shape (n, {p}) for the "
                f"outputs {', '.join(self.output_names)}, got {uu.shape} and {yy.shape}"
            )
        data = np.empty((p + 1, uu.size))
        data[0] = uu
        data[1:] = yy.T
        _check_finite(data, self._names, "AccumulatingFrf")
        n, length = uu.size, self.window_length
        self._pushed += n
        if self._fill + n < length:  # no segment completes: just store
            self._tail[:, self._fill:self._fill + n] = data
            self._fill += n
            return
        buf = np.concatenate([self._tail[:, :self._fill], data], axis=1)
        hop = self._options.hop
        k_new = (buf.shape[1] - length) // hop + 1
        self._accumulate(buf, k_new)
        covered = buf[:, :(k_new - 1) * hop + length]
        np.minimum(self._low, covered.min(axis=1), out=self._low)
        np.maximum(self._high, covered.max(axis=1), out=self._high)
        rest = buf[:, k_new * hop:]  # shorter than one segment
        self._tail[:, :rest.shape[1]] = rest
        self._fill = rest.shape[1]

    def _accumulate(self, buf: NDArray[np.float64], k_new: int) -> None:
        """Add the spectra of the ``k_new`` segments starting at 0, hop, ... of ``buf``."""
        opt = self._options
        segments = np.lib.stride_tricks.sliding_window_view(buf, opt.window_length,
                                                            axis=1)[:, ::opt.hop]
        for k0 in range(0, k_new, _SEGMENTS_PER_CHUNK):
            k1 = min(k0 + _SEGMENTS_PER_CHUNK, k_new)
            spectra = scipy.fft.rfft(segments[:, k0:k1] * opt.window, n=opt.nfft, axis=-1)
            x, ys = spectra[0], spectra[1:]  # (kb, F) and (p, kb, F)
            # |X|^2 as re^2 + im^2, as the batch engine: exactly real.
            self._sxx += (x.real ** 2 + x.imag ** 2).sum(axis=0)
            self._syy += (ys.real ** 2 + ys.imag ** 2).sum(axis=1)
            self._syx += (ys * x.conj()).sum(axis=1)
        self._k += k_new

    def result(self) -> FrfSnapshot | None:
        """H1 and coherence over every segment so far.

        Returns
        -------
        FrfSnapshot or None
            None while fewer than two segments are complete (with one, the
            coherence is identically 1; ``mscohere`` refuses it too).

        Raises
        ------
        ValueError
            A signal is constant over the samples covered: it has no power at
            any non-zero frequency, so H1 or the coherence is undefined (the
            batch functions refuse it the same way).
        """
        if self._k < 2:
            return None
        n_cov = (self._k - 1) * self._options.hop + self.window_length
        for name, low, high in zip(self._names, self._low, self._high, strict=True):
            if low == high:
                raise ValueError(
                    f"AccumulatingFrf: signal {name!r} is constant ({low:g} for all {n_cov} "
                    "samples analysed): it has no power at any non-zero frequency, so the "
                    "coherence and the frequency response are undefined"
                )
        # The batch functions' density scale 2/(fs sum(w^2) K) cancels in both ratios.
        h1 = self._syx / self._sxx
        coh = np.abs(self._syx) ** 2 / (self._syy * self._sxx)
        f = self._options.frequencies_hz
        for arr in (h1, coh, f):
            arr.setflags(write=False)
        return FrfSnapshot(frequency_hz=f, h1=h1, coherence=coh, n_segments=self._k,
                           n_samples=n_cov, input_name=self.input_name,
                           output_names=self.output_names)
