"""Everything the budget needs from a long huddle test, in two sequential reads.

A huddle test read out of core (Dask arrays, e.g. 24 h = 864 M samples per
signal) is analysed by the ESRF study's processing (section 3: mean removal, the
50 Hz low pass of ``Va``, Welch PSDs, rms) and by the long-term view
(:mod:`fsmbench.budget.stability`: Allan deviations, drift, envelopes). Done
estimate by estimate, that is some twenty reads of the record, and Dask
graphs over its tens of thousands of chunks. Here the record is read twice,
block after block (:mod:`fsmbench.signal.streaming`):

1. the raw ``Va``, ``Vph``, ``Vpv``: their means (needed by everything the ESRF study
   computes on mean-removed signals), Allan deviations up to 10 s, 0.1 s and
   1 s means, min/max envelopes;
2. the mean-removed signals: Welch PSDs, rms, and ``Va`` through the 50 Hz low
   pass (its rms and envelope).

Memory is a few blocks (8 MiB per signal each) whatever the length. The
results equal the in-memory analysis to 1e-12 (``tests/budget/test_huddle_lazy.py``,
``tests/budget/test_stability.py``).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterable, Iterator, Mapping
from dataclasses import dataclass

import numpy as np
import xarray as xr
from numpy.typing import NDArray

from fsmbench.budget.signals import LazyTrim, finite_blocks, trim_record
from fsmbench.signal.allan import AllanResult
from fsmbench.signal.envelope import Envelope
from fsmbench.signal.streaming import (
    BLOCK_SAMPLES,
    AllanStream,
    BlockMeanStream,
    EnvelopeStream,
    LowpassStream,
    SumStream,
    WelchStream,
)
from fsmbench.signal.welch import SpectrumResult, WelchOptions, hanning

__all__ = ["LongRecordSummary", "allan_factors", "summarise_long_record"]

FloatArray = NDArray[np.float64]
SIGNALS = ("Va", "Vph", "Vpv")

#: Averaging times up to this use averages starting at every sample [s]; longer ones
#: use averages starting every :data:`STRIDE_S` (:mod:`fsmbench.budget.stability`).
FULL_OVERLAP_MAX_TAU_S = 10.0
STRIDE_S = 0.1


def allan_factors(n: int, fs_hz: float) -> tuple[NDArray[np.int64], int]:
    """Octave-spaced averaging factors read at every sample, and the stride of the rest.

    Returns ``(fine_m, stride)``: ``fine_m`` = 1, 2, 4 … up to 10 s (and ``n/4``);
    longer averaging times use the means of ``stride`` samples (0.1 s).
    """
    stride = max(1, round(STRIDE_S * fs_hz))
    m_full = max(1, min(n // 4, round(FULL_OVERLAP_MAX_TAU_S * fs_hz)))
    return 2 ** np.arange(int(np.floor(np.log2(m_full))) + 1, dtype=np.int64), stride


@dataclass(frozen=True, eq=False)
class LongRecordSummary:
    """The reductions of one huddle test that the budget and the report use.

    Attributes
    ----------
    name : str
        Experiment name.
    fs_hz : float
        Sampling rate [Hz].
    trim : LazyTrim
        The samples analysed (``t >= t0_s``).
    means : dict
        Mean of ``Va`` [m], ``Vph``, ``Vpv`` [V] over the trimmed record.
    rms : dict
        Rms about those means, same units.
    psd : dict
        The ESRF study's Welch PSD (1 s Hann) of each mean-removed signal.
    lpf_hz : float
        Corner of the low pass applied to ``Va`` [Hz].
    va_lowpass_rms_m : float
        Rms about its mean of the low-passed, mean-removed ``Va`` [m].
    va_second_means_m : ndarray (N // fs,)
        Means of ``Va`` over consecutive whole seconds [m].
    stride_means : dict
        Means over consecutive :data:`STRIDE_S` of each signal (coarse Allan input).
    allan_fine : dict
        Overlapping Allan deviation of each raw signal at ``allan_factors``.
    envelopes : dict
        Min/max/mean per bin of each raw signal and of ``Va_lowpass``.
    read_s : float
        Wall time of the two reads [s] (reported, never compared).
    """

    name: str
    fs_hz: float
    trim: LazyTrim
    means: dict[str, float]
    rms: dict[str, float]
    psd: dict[str, SpectrumResult]
    lpf_hz: float
    va_lowpass_rms_m: float
    va_second_means_m: FloatArray
    stride_means: dict[str, FloatArray]
    allan_fine: dict[str, AllanResult]
    envelopes: dict[str, Envelope]
    read_s: float

    @property
    def n_samples(self) -> int:
        """Samples analysed per signal."""
        return self.trim.n


def summarise_long_record(ds: xr.Dataset, *, name: str, t0_s: float = 1.0,
                          duration_s: float | None = None, lpf_hz: float = 50.0,
                          n_bins: int = 2000, block_samples: int = BLOCK_SAMPLES,
                          progress: Callable[[str], None] | None = None) -> LongRecordSummary:
    """Read a huddle test twice, block after block, and reduce it (see the module).

    Parameters
    ----------
    ds : xarray.Dataset
        ``Va`` [m], ``Vph``, ``Vpv`` [V] on ``t`` [s] (NumPy or Dask), attribute ``fs_hz``.
    name : str
        Experiment name, for messages.
    t0_s, duration_s : float
        The ESRF study's trim: samples before ``t0_s`` [s] are dropped; at most
        ``duration_s`` [s] are kept (None: the rest of the record).
    lpf_hz : float
        Corner of the ESRF study's low pass on ``Va`` [Hz].
    n_bins : int
        Bins of the envelopes (at most the number of samples).
    block_samples : int
        Samples per block read.
    progress : callable, optional
        Receives each read's progress (:func:`fsmbench.progress.advance`).

    Raises
    ------
    ValueError
        Naming the record and signal: a signal missing, fewer than 2 s left,
        NaN or infinite samples.
    """
    missing = [v for v in SIGNALS if v not in ds]
    if missing:
        raise ValueError(f"{name}: missing {missing} (ESRF study 3.1 loads t, Vph, Vpv, Va)")
    fs = float(ds.attrs["fs_hz"])
    trim = trim_record(ds, t0_s=t0_s, duration_s=duration_s, fs_hz=fs)
    n = trim.n
    if n < 2 * math.ceil(fs):
        raise ValueError(f"{name}: {n / fs:.3g} s left after removing t < {t0_s:g} s; the "
                         "huddle analysis needs at least 2 s (two 1 s Welch windows)")
    signals = {k: ds[k].data for k in SIGNALS}
    started = time.monotonic()
    fine_m, stride = allan_factors(n, fs)
    bins = min(n_bins, n)

    def blocks(what: str) -> Iterator[tuple[int, dict[str, FloatArray]]]:
        return finite_blocks(signals, name=name, start=trim.start, stop=trim.start + n,
                             fs_hz=fs, what=what, block_samples=block_samples,
                             progress=progress)

    raw = _read_raw(blocks("reading the raw signals"), name=name, n=n, fs=fs, fine_m=fine_m,
                    stride=stride, bins=bins)
    means = {k: s.mean for k, s in raw.sums.items()}
    cen = _read_centred(blocks("spectra and low pass"), means=means, name=name, n=n, fs=fs,
                        lpf_hz=lpf_hz, bins=bins)
    return LongRecordSummary(
        name=name, fs_hz=fs, trim=trim, means=means,
        rms={k: s.rms for k, s in cen.centred.items()},
        psd={k: w.result() for k, w in cen.welch.items()}, lpf_hz=lpf_hz,
        va_lowpass_rms_m=cen.low_sums.rms_about_mean, va_second_means_m=raw.seconds.result(),
        stride_means={k: s.result() for k, s in raw.strided.items()},
        allan_fine={k: a.result() for k, a in raw.allan.items()},
        envelopes={**{k: e.result() for k, e in raw.env.items()},
                   "Va_lowpass": cen.low_env.result()},
        read_s=time.monotonic() - started)


@dataclass(frozen=True)
class _RawRead:
    """Read 1's streams over the raw signals (their results are taken at the end)."""

    sums: dict[str, SumStream]
    allan: dict[str, AllanStream]
    strided: dict[str, BlockMeanStream]
    seconds: BlockMeanStream
    env: dict[str, EnvelopeStream]


def _read_raw(blocks: Iterable[tuple[int, dict[str, FloatArray]]], *, name: str, n: int,
              fs: float, fine_m: NDArray[np.int64], stride: int, bins: int) -> _RawRead:
    """Read 1: means, fine Allan deviations, stride and 1 s means, envelopes of the raw signals.

    Parameters
    ----------
    blocks : iterable of (offset, {signal: block})
        The trimmed record's blocks (:func:`~fsmbench.budget.signals.finite_blocks`).
    name : str
        Experiment name, for messages.
    n : int
        Samples read per signal.
    fs : float
        Sampling rate [Hz].
    fine_m, stride : array of int, int
        :func:`allan_factors`.
    bins : int
        Bins of the envelopes.
    """
    sums = {k: SumStream() for k in SIGNALS}
    allan = {k: AllanStream(n_samples=n, fs_hz=fs, factors=fine_m, unit="m" if k == "Va" else "V",
                            name=f"{name}.{k}") for k in SIGNALS}
    strided = {k: BlockMeanStream(per=stride) for k in SIGNALS}
    seconds = BlockMeanStream(per=round(fs))
    env = {k: EnvelopeStream(n_samples=n, n_bins=bins, fs_hz=fs) for k in SIGNALS}
    for _, block in blocks:
        for k, x in block.items():
            sums[k].update(x)
            allan[k].update(x)
            strided[k].update(x)
            env[k].update(x)
        seconds.update(block["Va"])
    return _RawRead(sums=sums, allan=allan, strided=strided, seconds=seconds, env=env)


@dataclass(frozen=True)
class _CentredRead:
    """Read 2's streams over the mean-removed signals and ``Va``'s low pass."""

    welch: dict[str, WelchStream]
    centred: dict[str, SumStream]
    low_sums: SumStream
    low_env: EnvelopeStream


def _read_centred(blocks: Iterable[tuple[int, dict[str, FloatArray]]], *,
                  means: Mapping[str, float], name: str, n: int, fs: float, lpf_hz: float,
                  bins: int) -> _CentredRead:
    """Read 2: the mean-removed signals as the seed processes them (Welch, rms, low pass).

    Parameters as :func:`_read_raw`; ``means`` of each signal from read 1 (unit of
    the signal), ``lpf_hz`` the low pass's corner on ``Va`` [Hz].
    """
    options = WelchOptions.from_matlab(window=hanning(math.ceil(fs)), noverlap=None, nfft=None,
                                       fs_hz=fs)
    welch = {k: WelchStream(options=options, n_samples=n, name=f"{name}.{k}") for k in SIGNALS}
    centred = {k: SumStream() for k in SIGNALS}
    lowpass = LowpassStream(cutoff_hz=lpf_hz, fs_hz=fs)
    low_sums = SumStream()
    low_env = EnvelopeStream(n_samples=n, n_bins=bins, fs_hz=fs)
    for _, block in blocks:
        for k, x in block.items():
            d = x - means[k]
            welch[k].update(d)
            centred[k].update(d)
            if k == "Va":
                y = lowpass.filter(d)
                low_sums.update(y)
                low_env.update(y)
    return _CentredRead(welch=welch, centred=centred, low_sums=low_sums, low_env=low_env)
