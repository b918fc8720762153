"""Welch's estimate with MATLAB's semantics: windows, options, the engine, the result type.

The engine :func:`cross_spectral_density` computes every segment's FFT of every
channel once and accumulates the full cross-spectral matrix; MATLAB's four
functions (:mod:`fsmbench.signal.welch`), its Dask twin
(:mod:`fsmbench.signal.welch_dask`) and
:func:`fsmbench.ident.frf.response.spectral_matrix` are thin views on it, so all
of them agree to floating-point reordering. Every convention used here, with its
source, is listed in the docstring of :mod:`fsmbench.ident.frf.spectral`.
"""

from __future__ import annotations

import math
import operator
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np
import scipy.fft
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "SpectrumResult",
    "WelchOptions",
    "cross_spectral_density",
    "default_nfft",
    "default_noverlap",
    "effective_averages",
    "hamming",
    "hann",
    "hanning",
    "segment_sums",
]

# Memory cap for one block of segment FFTs (complex128). A 31 s, 10 kHz,
# 3-channel record with hanning(10000) needs ~24 MB, i.e. a single rfft call;
# hour-long records are processed in blocks instead of exhausting memory.
_BLOCK_BYTES = 1 << 28

Quantity = Literal["psd", "cpsd", "tf", "coherence"]


# --------------------------------------------------------------------------- windows
def _symmetric_cosine(
    n: int, *, kind: Literal["hanning", "hann", "hamming"]
) -> NDArray[np.float64]:
    """Half window then mirror, as MATLAB's ``hanning.m``/``gencoswin.m`` do (exact symmetry)."""
    n = _positive_int(n, "window length")
    if n == 1:
        return np.ones(1)
    half = (n + 1) // 2  # MATLAB: m = n/2 (even) or (n+1)/2 (odd)
    if kind == "hanning":
        k = np.arange(1, half + 1, dtype=np.float64)
        w = 0.5 * (1.0 - np.cos(2.0 * np.pi * k / (n + 1)))
    else:
        x = np.arange(half, dtype=np.float64) / (n - 1)
        a0, a1 = (0.5, 0.5) if kind == "hann" else (0.54, 0.46)
        w = a0 - a1 * np.cos(2.0 * np.pi * x)
    tail = w[::-1] if n % 2 == 0 else w[-2::-1]
    return np.concatenate([w, tail])


def hanning(n: int) -> NDArray[np.float64]:
    """MATLAB ``hanning(n)``: symmetric Hann window without zero end-points.

    Parameters
    ----------
    n : int
        Window length in samples, ``n >= 1``.

    Returns
    -------
    ndarray, shape (n,)
        ``0.5*(1 - cos(2*pi*k/(n+1)))`` for ``k = 1..n`` (dimensionless). Differs
        from ``scipy.signal.windows.hann(n)``, whose end-points are zero.
    """
    return _symmetric_cosine(n, kind="hanning")


def hann(n: int) -> NDArray[np.float64]:
    """MATLAB ``hann(n)`` (symmetric): ``0.5 - 0.5*cos(2*pi*k/(n-1))``, ``k = 0..n-1``.

    Parameters
    ----------
    n : int
        Window length in samples, ``n >= 1``.

    Returns
    -------
    ndarray, shape (n,)
        The window (dimensionless), zero at both ends; ``hann(1)`` is ``[1]``.
    """
    return _symmetric_cosine(n, kind="hann")


def hamming(n: int) -> NDArray[np.float64]:
    """MATLAB ``hamming(n)`` (symmetric): ``0.54 - 0.46*cos(2*pi*k/(n-1))``, ``k = 0..n-1``.

    Parameters
    ----------
    n : int
        Window length in samples, ``n >= 1``. MATLAB's spectral functions use
        this window when the ``window`` argument is an integer.

    Returns
    -------
    ndarray, shape (n,)
        The window (dimensionless).
    """
    return _symmetric_cosine(n, kind="hamming")


# --------------------------------------------------------------------------- options
def _positive_int(value: object, what: str) -> int:
    if isinstance(value, bool | np.bool_):
        raise TypeError(f"{what} must be an integer, got a boolean")
    try:
        n = operator.index(value)  # type: ignore[arg-type]
    except TypeError:
        raise TypeError(f"{what} must be an integer, got {value!r}") from None
    if n < 1:
        raise ValueError(f"{what} must be >= 1, got {n}")
    return n


def default_noverlap(window_length: int) -> int:
    """MATLAB's ``noverlap = []``: ``floor(0.5 * window_length)`` samples."""
    return _positive_int(window_length, "window length") // 2


def default_nfft(window_length: int) -> int:
    """MATLAB's ``nfft = []``: ``max(256, 2^nextpow2(window_length))``.

    ``hanning(10000)`` (the seed's ``ceil(1*fs)`` at 10 kHz) gives 16384.
    """
    n = _positive_int(window_length, "window length")
    return max(256, 1 << (n - 1).bit_length())


def effective_averages(window: ArrayLike, noverlap: int, n_segments: int) -> float:
    """Equivalent number of independent averages of a Welch estimate.

    Welch (1967), eq. for the variance of the averaged modified periodogram:
    ``Var/P^2 = (1/K) [1 + 2 sum_{j=1}^{K-1} (1 - j/K) rho(j)^2]`` with
    ``rho(j) = sum_n w[n] w[n + j D] / sum_n w[n]^2`` the window's overlap
    correlation at a shift of ``j`` hops ``D = L - noverlap``. The returned
    ``n_d = K / [...]`` is the number of independent averages giving the same
    variance (``n_d = K`` without overlap; ``K/1.056`` for Hann at 50 %).

    Parameters
    ----------
    window : array_like, shape (L,)
        Window samples (dimensionless).
    noverlap : int
        Overlap between segments, samples, ``0 <= noverlap < L``.
    n_segments : int
        Number of segments ``K`` averaged.

    Returns
    -------
    float
        ``n_d``, dimensionless, ``<= K``.
    """
    w = np.asarray(window, dtype=np.float64)
    k = _positive_int(n_segments, "number of segments")
    hop = w.size - int(noverlap)
    energy = float(np.dot(w, w))
    total = 1.0
    for j in range(1, k):
        shift = j * hop
        if shift >= w.size:
            break
        rho = float(np.dot(w[: w.size - shift], w[shift:])) / energy
        total += 2.0 * (1.0 - j / k) * rho * rho
    return k / total


@dataclass(frozen=True, eq=False)
class WelchOptions:
    """Resolved Welch options (what MATLAB uses after filling in ``[]``).

    Attributes
    ----------
    window : ndarray, shape (L,)
        Window samples (dimensionless), read-only.
    noverlap : int
        Overlap between consecutive segments, samples.
    nfft : int
        FFT length, samples. ``nfft < L`` wraps each windowed segment (MATLAB datawrap).
    fs_hz : float
        Sampling frequency, Hz.
    """

    window: NDArray[np.float64]
    noverlap: int
    nfft: int
    fs_hz: float

    @classmethod
    def from_matlab(
        cls,
        *,
        window: int | ArrayLike,
        noverlap: int | None = None,
        nfft: int | None = None,
        fs_hz: float,
    ) -> WelchOptions:
        """Resolve MATLAB-style arguments (``None`` plays MATLAB's ``[]``).

        Parameters
        ----------
        window : int or array_like, shape (L,)
            An integer ``L`` means MATLAB's ``hamming(L)``; an array is used as is.
        noverlap : int, optional
            Overlap, samples, ``0 <= noverlap < L``; default ``floor(L/2)``.
        nfft : int, optional
            FFT length, samples; default ``max(256, 2^nextpow2(L))``.
        fs_hz : float
            Sampling frequency, Hz, positive.
        """
        if isinstance(window, int | np.integer) and not isinstance(window, bool | np.bool_):
            win = hamming(int(window))
        else:
            win = np.array(window, dtype=np.float64)
            if win.ndim != 1 or win.size == 0:
                raise ValueError(
                    f"window must be an integer length or a 1-D array, got shape {win.shape}"
                )
            if not np.all(np.isfinite(win)):
                raise ValueError("window contains NaN or infinite values")
            if not np.any(win):
                raise ValueError("window is all zeros: no segment would carry any power")
        win.setflags(write=False)
        length = win.size
        ov = default_noverlap(length) if noverlap is None else operator.index(noverlap)
        if not 0 <= ov < length:
            raise ValueError(
                f"noverlap must satisfy 0 <= noverlap < window length ({length} samples), got {ov}"
            )
        n_fft = default_nfft(length) if nfft is None else _positive_int(nfft, "nfft")
        fs = float(fs_hz)
        if not (math.isfinite(fs) and fs > 0.0):
            raise ValueError(f"fs_hz must be a positive finite frequency in Hz, got {fs_hz!r}")
        return cls(window=win, noverlap=ov, nfft=n_fft, fs_hz=fs)

    @property
    def window_length(self) -> int:
        """Segment length ``L``, samples."""
        return int(self.window.size)

    @property
    def hop(self) -> int:
        """Segment start-to-start distance ``L - noverlap``, samples."""
        return self.window_length - self.noverlap

    @property
    def frequencies_hz(self) -> NDArray[np.float64]:
        """One-sided grid ``(0:floor(nfft/2)) * fs/nfft``, Hz, shape (nfft//2 + 1,)."""
        return np.arange(self.nfft // 2 + 1, dtype=np.float64) * (self.fs_hz / self.nfft)

    def n_segments(self, n_samples: int) -> int:
        """MATLAB's segment count ``floor((N - noverlap)/(L - noverlap))``."""
        return max(0, (int(n_samples) - self.noverlap) // self.hop)

    def effective_averages(self, n_samples: int) -> float:
        """Welch (1967) equivalent independent averages for a record of ``n_samples``."""
        return effective_averages(self.window, self.noverlap, self.n_segments(n_samples))

    def describe_window(self) -> str:
        """Human-readable window length (samples and seconds) for error messages."""
        length = self.window_length
        return f"a {length}-sample window ({length / self.fs_hz:.6g} s at {self.fs_hz:g} Hz)"


# --------------------------------------------------------------------------- input checks
def _label(name: str | None, role: str) -> str:
    """``"'Uch' (input x)"`` when a name is given, else the role (``"input x"``)."""
    return f"{name!r} ({role})" if name else role


def _as_signal(x: ArrayLike, *, name: str | None, role: str) -> NDArray[np.float64]:
    """Validate one real, finite, 1-D record and return it as float64 (samples)."""
    who = _label(name, role)
    arr = np.asarray(x)
    if arr.ndim != 1:
        raise ValueError(f"{who} must be a 1-D array of samples, got shape {arr.shape}")
    if np.iscomplexobj(arr):
        raise TypeError(f"{who} is complex; only real signals (one-sided spectra) are supported")
    arr = arr.astype(np.float64, copy=False)
    bad = np.flatnonzero(~np.isfinite(arr))
    if bad.size:
        raise ValueError(
            f"{who} contains {bad.size} NaN or infinite sample(s) (first at index {bad[0]}); "
            "remove or interpolate them before spectral estimation"
        )
    return arr


def _check_record(
    signals: Sequence[tuple[str, NDArray[np.float64]]],
    options: WelchOptions,
    *,
    min_segments: int = 1,
) -> int:
    """Check equal lengths and enough samples; return the common length ``N``.

    ``signals`` holds ``(label, samples)`` pairs; labels name the signal in errors.
    """
    lengths = [(lab, arr.size) for lab, arr in signals]
    if len({n for _, n in lengths}) > 1:
        detail = ", ".join(f"{lab} has {n}" for lab, n in lengths)
        raise ValueError(
            f"signals have different lengths ({detail} samples); spectral estimates need "
            "simultaneously sampled records of equal length"
        )
    n = lengths[0][1]
    needed = options.window_length + (min_segments - 1) * options.hop
    if n < needed:
        names = ", ".join(lab for lab, _ in lengths)
        what = "one segment" if min_segments == 1 else f"{min_segments} segments"
        raise ValueError(
            f"{names}: record of {n} samples is too short for {options.describe_window()}; "
            f"at least {needed} samples ({needed / options.fs_hz:.6g} s) are needed for {what}"
        )
    return n


def _check_has_power(x: NDArray[np.float64], who: str) -> None:
    """Raise if ``x`` is constant: its coherence (and an FRF from it) is undefined."""
    if x.size and np.ptp(x) == 0.0:
        raise ValueError(
            f"{who} is constant ({x[0]:g} for all {x.size} samples): it has no power at any "
            "non-zero frequency, so the coherence and the frequency response are undefined"
        )


# --------------------------------------------------------------------------- engine
def segment_sums(channels: NDArray[np.float64], *, n_segments: int,
                 window: NDArray[np.float64], hop: int, nfft: int) -> NDArray[np.complex128]:
    """Unscaled ``sum_k X_a conj(X_b)`` over the first ``n_segments`` segments.

    ``channels`` (c, N) real; segment ``k`` is ``channels[:, k*hop : k*hop + L]``
    times ``window`` (L,), MATLAB-datawrapped to ``nfft`` when ``nfft < L``.
    Returns shape (c, c, nfft//2 + 1), Hermitian in ``(a, b)``. The one
    accumulation of every Welch estimate here, in memory, in blocks and on Dask.
    """
    c = channels.shape[0]
    length = int(np.asarray(window).size)
    n_freq = nfft // 2 + 1
    acc = np.zeros((c, c, n_freq), dtype=np.complex128)
    # Strided view (no copy): segment k of channel a is channels[a, k*hop : k*hop + L].
    segments = np.lib.stride_tricks.sliding_window_view(channels, length, axis=1)[:, ::hop]
    segments = segments[:, :n_segments]
    block = max(1, _BLOCK_BYTES // (16 * c * n_freq))
    for k0 in range(0, n_segments, block):
        windowed = segments[:, k0 : k0 + block] * window  # (c, kb, L), a copy
        if nfft < length:
            # MATLAB datawrap: zero-pad to a multiple of nfft and sum the nfft-long pieces.
            pad = -length % nfft
            windowed = np.pad(windowed, ((0, 0), (0, 0), (0, pad)))
            windowed = windowed.reshape(c, windowed.shape[1], -1, nfft).sum(axis=2)
        spectra = scipy.fft.rfft(windowed, n=nfft, axis=-1)  # every segment x channel at once
        for a in range(c):
            # |X|^2 as re^2 + im^2: a complex product may use FMA and leave a 1e-22 imaginary part
            acc[a, a] += (spectra[a].real ** 2 + spectra[a].imag ** 2).sum(axis=0)
            for b in range(a + 1, c):
                acc[a, b] += (spectra[a] * spectra[b].conj()).sum(axis=0)
    for a in range(c):
        for b in range(a):
            acc[a, b] = acc[b, a].conj()
    return acc


def cross_spectral_density(
    channels: NDArray[np.float64], options: WelchOptions
) -> tuple[NDArray[np.complex128], int]:
    """One-sided cross-spectral density matrix of all channels, in one pass.

    Parameters
    ----------
    channels : ndarray, shape (c, N)
        Real records, one row per channel (unit U_a of channel ``a``).
    options : WelchOptions
        Resolved window, overlap, nfft and fs.

    Returns
    -------
    S : ndarray, complex, shape (nfft//2 + 1, c, c)
        ``S[f, a, b]`` equals MATLAB's ``cpsd(channel_a, channel_b)``, i.e. the
        average over segments of ``X_a conj(X_b)``, scaled to a one-sided
        density (U_a U_b / Hz). Hermitian in ``(a, b)``; the diagonal is
        ``pwelch`` of each channel (imaginary part exactly zero).
    n_segments : int
        Number of segments ``K`` averaged.
    """
    n = channels.shape[1]
    hop, nfft = options.hop, options.nfft
    k_total = options.n_segments(n)
    if k_total < 1:
        raise ValueError(f"record of {n} samples is too short for {options.describe_window()}")
    n_freq = nfft // 2 + 1
    acc = segment_sums(channels, n_segments=k_total, window=options.window, hop=hop, nfft=nfft)
    # Density scaling |X|^2 / (fs * sum(w^2)), averaged over K segments; one-sided:
    # double every bin except DC and (even nfft) Nyquist, which have no mirror image.
    energy = float(np.dot(options.window, options.window))
    scale = np.full(n_freq, 2.0 / (options.fs_hz * energy * k_total))
    scale[0] /= 2.0
    if nfft % 2 == 0:
        scale[-1] /= 2.0
    return np.moveaxis(acc * scale, -1, 0), k_total


# --------------------------------------------------------------------------- SISO API
@dataclass(frozen=True, eq=False)
class SpectrumResult:
    """A one-sided Welch estimate and the options that produced it.

    Attributes
    ----------
    f_hz : ndarray, shape (F,)
        Frequencies, Hz, ``(0:floor(nfft/2)) * fs/nfft``.
    values : ndarray, shape (F,)
        The estimate: PSD (U_x^2/Hz, real), CPSD (U_x U_y/Hz, complex),
        transfer function (U_y/U_x, complex) or coherence (dimensionless, real).
    quantity : {"psd", "cpsd", "tf", "coherence"}
        What ``values`` holds.
    window_length, noverlap, nfft : int
        Segment length, overlap and FFT length, samples.
    fs_hz : float
        Sampling frequency, Hz.
    n_segments : int
        Number of averaged segments ``K``.
    effective_averages : float
        Welch (1967) equivalent number of independent averages ``n_d``.
    """

    f_hz: NDArray[np.float64]
    values: NDArray[np.float64] | NDArray[np.complex128]
    quantity: Quantity
    window_length: int
    noverlap: int
    nfft: int
    fs_hz: float
    n_segments: int
    effective_averages: float


def _result(
    options: WelchOptions,
    values: NDArray[np.float64] | NDArray[np.complex128],
    quantity: Quantity,
    k: int,
) -> SpectrumResult:
    f = options.frequencies_hz
    for arr in (f, values):
        arr.setflags(write=False)
    return SpectrumResult(
        f_hz=f, values=values, quantity=quantity, window_length=options.window_length,
        noverlap=options.noverlap, nfft=options.nfft, fs_hz=options.fs_hz, n_segments=k,
        effective_averages=effective_averages(options.window, options.noverlap, k),
    )
