"""Non-repeatability of the measured distance (ESRF study 11), on records of any length.

Alignment (11.1): the record starts ``align_s`` (1 s) after the first
non-zero Newport command (``Unh`` for ``data_rep_h``, ``Unv`` for
``data_rep_v``) and keeps whole periods only. In MATLAB's 1-based indices the
seed keeps ``i0 … iend−1`` with ``i0 = find(Un ~= 0, 1) + fs`` and
``iend = i0 + fs·floor((N − i0)/fs)``; here that is ``s0 = first + fs``
(0-based) and ``floor((N − s0 − 1)/P)`` periods of ``P = period·fs`` samples.
The command is read block by block from the start until it moves.

Repeatable part (11.4): the mean over periods at each position in the
period (``mean(reshape(Va, [fs n]), 2)``); non-repeatable part: the rest.
Its rms is the ESRF study's number (19.6 nm h, 13.9 nm v). That estimate is biased
low by ``√((n−1)/n)`` for noise that is independent between periods (the mean
was taken from the same periods); ``nonrep_rms_unbiased_m`` corrects it.
11.6 repeats it after a 10 Hz first-order low pass (``lsim``, zero initial
state; :func:`~fsmbench.budget.spectra.first_order_lowpass`). The filter's
start-up transient (τ = 16 ms) on a signal that moves by ~1 µm per period
lands in the first period only, so it is *non-repeatable by construction*
and can make the filtered rms exceed the unfiltered one (the ESRF study's 22.9 nm
against 19.6 nm, horizontal). ``nonrep_rms_lpf_settled_m`` drops the first
period after filtering (mean over the remaining periods).

Tracking error (11.3): the beam angle measured by the 4QD, ``R = Vp/Gd(0)``,
its PSD, and its distance-error equivalent. The ESRF study's law is
``ΔL = L·α²/2`` with L = 0.1 m per axis; the traced law is ``Σ cᵢ αᵢ²``
with ``c = (6H + 4L)/16`` m/rad² (errata E15, E17). ``R`` includes the 4QD's
own noise, so this equivalent is an upper bound of the true geometric term.

Out of core: one code path for every record (NumPy or Dask), read twice
block after block (:func:`fsmbench.signal.streaming.read_blocks`): read 1
folds ``Va``, its low pass and the distance equivalent period on period
(sums, minimum, maximum at each position: arrays of shape (P,)) and takes the
means, Welch PSDs and envelopes of the raw signals; read 2 needs the
repeatable parts and means: the non-repeatable rms's, their envelopes, the
PSD of ``Va`` less its mean. ``Va`` is processed less its first aligned
sample ``s`` (exact for a metre-scale offset with µm motion), so nanometres
are not lost under the offset; the low pass from rest of ``Va`` is that of
``Va − s`` plus the step response ``s·(1 − aᵏ)``. Memory: a few blocks.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Iterator, Mapping
from dataclasses import dataclass, field, fields

import numpy as np
import xarray as xr
from numpy.typing import NDArray

from fsmbench.bench.blocks import rotation
from fsmbench.bench.params import BenchParams
from fsmbench.budget.propagation import distance_coefficients
from fsmbench.budget.signals import finite_blocks, trim_record
from fsmbench.jsonutil import hv
from fsmbench.signal.envelope import Envelope
from fsmbench.signal.streaming import (
    BLOCK_SAMPLES,
    EnvelopeStream,
    LowpassStream,
    SumStream,
    WelchStream,
    read_blocks,
)
from fsmbench.signal.welch import WelchOptions, hanning

__all__ = [
    "ENVELOPE_BINS",
    "SEED_11",
    "AlignedRecord",
    "HuddleWindow",
    "PeriodAlignment",
    "RepeatabilityRecord",
    "align_periods",
    "analyse_repeatability",
    "command_channel",
    "find_alignment",
    "huddle_window",
]

FloatArray = NDArray[np.float64]

#: Seed 11.4 and 11.7: rms of the non-repeatable part [m], and its 11.3 law length [m].
SEED_11: dict[str, float] = {"h_nonrep_rms_m": 19.6e-9, "v_nonrep_rms_m": 13.9e-9,
                             "h_nonrep_rms_lpf_m": 22.9e-9, "v_nonrep_rms_lpf_m": 13.9e-9,
                             "law_length_m": 0.1}
#: Bins of the min/max envelopes of the time plots (at most the aligned samples).
ENVELOPE_BINS = 2000
_CHANNEL = {"data_rep_h": "Unh", "data_rep_v": "Unv"}
_SIGNALS = ("Unh", "Unv", "Vph", "Vpv", "Va")


def _first_nonzero(ds: xr.Dataset, channels: tuple[str, ...],
                   block_samples: int) -> dict[str, int]:
    """First non-zero sample of each channel, read from the start up to the first block
    where one of them moves (empty if none ever does)."""
    signals = {c: ds[c].data for c in channels}
    for offset, block in read_blocks(signals, start=0, stop=ds.sizes["t"],
                                     block_samples=block_samples):
        found = {c: offset + int(i[0]) for c, x in block.items()
                 if (i := np.flatnonzero(x != 0)).size}
        if found:
            return found
    return {}


def command_channel(name: str, ds: xr.Dataset, *, block_samples: int = BLOCK_SAMPLES) -> str:
    """``Unh`` for ``data_rep_h``, ``Unv`` for ``data_rep_v``; else the command that moves first."""
    if name in _CHANNEL:
        return _CHANNEL[name]
    moving = _first_nonzero(ds, tuple(c for c in ("Unh", "Unv") if c in ds), block_samples)
    if not moving:
        raise ValueError(f"{name}: no Newport command (Unh, Unv are zero or absent); the "
                         f"repeatability analysis aligns on the first command (ESRF study 11.1)")
    return min(moving, key=lambda c: moving[c])


@dataclass(frozen=True)
class PeriodAlignment:
    """Where ESRF study 11.1 cuts a record: samples ``start_index … stop_index − 1``."""

    name: str
    channel: str
    fs_hz: float
    first_command_index: int
    start_index: int
    period_samples: int
    n_periods: int

    @property
    def stop_index(self) -> int:
        """One past the last sample kept."""
        return self.start_index + self.n_periods * self.period_samples


@dataclass(frozen=True)
class AlignedRecord(PeriodAlignment):
    """The record cut as ESRF study 11.1 does: signals of shape (N,) from ``start`` (in memory)."""

    signals: dict[str, FloatArray]


def find_alignment(ds: xr.Dataset, *, name: str | None = None, align_s: float = 1.0,
                   period_s: float = 1.0, block_samples: int = BLOCK_SAMPLES) -> PeriodAlignment:
    """ESRF study 11.1 without reading the signals: start ``align_s`` after the first Newport
    command (read block by block until it moves), keep whole periods.

    Raises
    ------
    ValueError
        Naming the experiment: a signal is missing, the command never moves,
        or fewer than two whole periods remain.
    """
    name = str(ds.attrs.get("experiment", "")) if name is None else name
    missing = [s for s in _SIGNALS if s not in ds]
    if missing:
        raise ValueError(f"{name}: missing {missing} (ESRF study 11.1 loads t, Uch, Ucv, Unh, Unv, "
                         f"Vph, Vpv, Vnh, Vnv, Va)")
    fs = float(ds.attrs["fs_hz"])
    channel = command_channel(name, ds, block_samples=block_samples)
    nz = _first_nonzero(ds, (channel,), block_samples)
    if not nz:
        raise ValueError(f"{name}: the Newport command {channel} is zero throughout; the "
                         "repeatability analysis aligns on its first non-zero sample (ESRF study "
                         "11.1)")
    per = round(period_s * fs)
    n = ds.sizes["t"]
    first = nz[channel]
    start = first + round(align_s * fs)
    n_periods = max(0, (n - start - 1) // per)
    if n_periods < 2:
        raise ValueError(f"{name}: {n_periods} whole period(s) of {period_s:g} s after "
                         f"{channel}'s first command + {align_s:g} s "
                         f"({(n - start) / fs:.3g} s left); at least two are needed")
    return PeriodAlignment(name=name, channel=channel, fs_hz=fs, first_command_index=first,
                           start_index=start, period_samples=per, n_periods=n_periods)


def align_periods(ds: xr.Dataset, *, name: str | None = None, align_s: float = 1.0,
                  period_s: float = 1.0) -> AlignedRecord:
    """:func:`find_alignment` and the aligned signals, in memory (short records).

    Raises
    ------
    ValueError
        As :func:`find_alignment`.
    """
    al = find_alignment(ds, name=name, align_s=align_s, period_s=period_s)
    sl = slice(al.start_index, al.stop_index)
    sig = {s: np.asarray(ds[s].isel(t=sl).values, dtype=float) for s in _SIGNALS}
    return AlignedRecord(**{f.name: getattr(al, f.name) for f in fields(PeriodAlignment)},
                         signals=sig)


@dataclass(frozen=True, eq=False)
class RepeatabilityRecord:
    """ESRF study 11.3–11.7 on one record (SI units).

    Folded over the periods, shape (P,) whatever the record's length:
    ``repeatable_m``, ``repeatable_lpf_m`` (mean over periods of ``Va`` and of
    its low pass); ``va_min_m``, ``va_max_m`` (smallest and largest ``Va`` at
    each position, less the record's mean); ``va_nonrep_min_m``,
    ``va_nonrep_max_m`` (of ``Va`` less the repeatable part);
    ``va_lpf_settled_nonrep_min_m``, ``…_max_m`` (the low-passed periods 2 … n
    less their own mean); ``va_lpf_first_nonrep_m`` (the first low-passed
    period less ``repeatable_lpf_m``); ``tracking_distance_repeatable_m``.
    ``envelopes``: min/max/mean per bin over the aligned record
    (:data:`ENVELOPE_BINS`) of ``command`` [V], ``Vph``, ``Vpv`` [V], ``Va``
    (less its mean), ``tracking_distance``, ``Va_nonrep``,
    ``tracking_distance_nonrep`` [m], time from the alignment. Spectra on
    ``f_hz`` (F,): ``psd_tracking_rad2_per_hz`` (F, 2),
    ``psd_distance_m2_per_hz`` (F,) (traced law, both axes),
    ``psd_distance_seed_m2_per_hz`` (F, 2) (ESRF study's ``L α²/2`` per axis),
    ``psd_va_m2_per_hz`` (F,).
    """

    name: str
    direction: str
    channel: str
    fs_hz: float
    period_s: float
    n_periods: int
    start_s: float
    nonrep_rms_m: float
    nonrep_rms_unbiased_m: float
    nonrep_rms_lpf_m: float
    nonrep_rms_lpf_settled_m: float | None
    repeatable_ptp_m: float
    tracking_rms_rad: tuple[float, float]
    tracking_distance_mean_m: float
    tracking_distance_std_m: float
    tracking_distance_nonrep_rms_m: float
    seed_law_distance_std_m: tuple[float, float]
    repeatable_m: FloatArray
    repeatable_lpf_m: FloatArray
    va_min_m: FloatArray
    va_max_m: FloatArray
    va_nonrep_min_m: FloatArray
    va_nonrep_max_m: FloatArray
    va_lpf_settled_nonrep_min_m: FloatArray
    va_lpf_settled_nonrep_max_m: FloatArray
    va_lpf_first_nonrep_m: FloatArray
    tracking_distance_repeatable_m: FloatArray
    envelopes: Mapping[str, Envelope]
    f_hz: FloatArray
    psd_tracking_rad2_per_hz: FloatArray
    psd_distance_m2_per_hz: FloatArray
    psd_distance_seed_m2_per_hz: FloatArray
    psd_va_m2_per_hz: FloatArray

    @property
    def period_samples(self) -> int:
        """Samples per period P."""
        return int(self.repeatable_m.size)

    def to_json(self) -> dict[str, object]:
        """Scalars, (h, v) pairs as ``{"h", "v"}``; the ESRF study's numbers for this direction
        under ``seed`` (arrays and envelopes are left out)."""
        out: dict[str, object] = {}
        for f in fields(self):
            v = getattr(self, f.name)
            if isinstance(v, (np.ndarray, Mapping)):
                continue
            out[f.name] = hv(v) if isinstance(v, tuple) else v  # every tuple field is (h, v)
        out["seed"] = {k[2:]: v for k, v in SEED_11.items() if k.startswith(f"{self.direction}_")}
        return out


class _Fold:
    """Sum, minimum and maximum over periods at each of the P positions, the first period
    apart (kept whole) from the others, for samples given block after block."""

    def __init__(self, per: int) -> None:
        self.per = per
        self.first = np.zeros(per)
        self.rest_sum = np.zeros(per)
        self.rest_min = np.full(per, np.inf)
        self.rest_max = np.full(per, -np.inf)
        self._pos = 0

    def update(self, x: FloatArray) -> None:
        per, i = self.per, 0
        while i < x.size:
            k, p = divmod(self._pos + i, per)
            if p == 0 and k >= 1 and x.size - i >= per:
                m = (x.size - i) // per
                rows = x[i:i + m * per].reshape(m, per)
                self.rest_sum += rows.sum(axis=0)
                np.minimum(self.rest_min, rows.min(axis=0), out=self.rest_min)
                np.maximum(self.rest_max, rows.max(axis=0), out=self.rest_max)
                i += m * per
                continue
            j = min(x.size, i + per - p)
            seg, sl = x[i:j], slice(p, p + j - i)
            if k == 0:
                self.first[sl] = seg
            else:
                self.rest_sum[sl] += seg
                np.minimum(self.rest_min[sl], seg, out=self.rest_min[sl])
                np.maximum(self.rest_max[sl], seg, out=self.rest_max[sl])
            i = j
        self._pos += x.size

    def mean(self, n_periods: int) -> FloatArray:
        """Mean over all periods, (P,)."""
        return (self.first + self.rest_sum) / n_periods


class _Signals:
    """What both reads derive from a block: ``Va − s``, its low pass, the beam angle and the
    distance equivalents (the same arithmetic in both reads, so their samples agree)."""

    def __init__(self, *, params: BenchParams, fs_hz: float, lpf_hz: float, shift_m: float,
                 ) -> None:
        gd = params.quad_diode.gain_v_per_rad.as_array()
        self.gd = (float(gd[0]), float(gd[1]))
        self.rot_t = rotation(params.quad_diode.rotation_rad).T
        self.c = np.asarray(distance_coefficients(params))
        self.shift = shift_m
        self.log_a = -2.0 * math.pi * lpf_hz / fs_hz
        # a^k underflows to 0 past here: the step response s(1 − a^k) is then s.
        self.k_step = math.ceil(760.0 / -self.log_a) + 1
        self.lowpass = LowpassStream(cutoff_hz=lpf_hz, fs_hz=fs_hz)

    def derive(self, offset: int, block: Mapping[str, FloatArray]) -> dict[str, FloatArray]:
        va = block["Va"] - self.shift
        lpf = self.lowpass.filter(va)  # lsim from rest of Va − s
        if offset < self.k_step:  # … of Va, less s: minus s·a^k (the step response's start)
            k = np.arange(offset, min(offset + va.size, self.k_step))
            lpf[:k.size] -= self.shift * np.exp(k * self.log_a)
        r = np.stack([block["Vph"] / self.gd[0], block["Vpv"] / self.gd[1]])  # beam angle [rad]
        alpha = self.rot_t @ r  # table frame
        seed = 0.5 * SEED_11["law_length_m"] * r**2
        return {"va": va, "lpf": lpf, "rh": r[0], "rv": r[1], "dist": self.c @ alpha**2,
                "seed_h": seed[0], "seed_v": seed[1]}


def analyse_repeatability(ds: xr.Dataset, *, params: BenchParams, name: str | None = None,
                          align_s: float = 1.0, period_s: float = 1.0, lpf_hz: float = 10.0,
                          n_bins: int = ENVELOPE_BINS, block_samples: int = BLOCK_SAMPLES,
                          progress: Callable[[str], None] | None = None) -> RepeatabilityRecord:
    """ESRF study 11 on one record (``data_rep_h`` or ``data_rep_v``), read twice in blocks.

    Parameters
    ----------
    ds : xarray.Dataset
        Record with ``Unh, Unv, Vph, Vpv, Va`` on ``t`` (NumPy or Dask, N samples),
        attribute ``fs_hz``.
    params : BenchParams
        4QD gains (``R = Vp/Gd``), geometry and beam factors (the distance law).
    name : str, optional
        Experiment name (default: the dataset's ``experiment`` attribute).
    align_s, period_s : float
        Delay after the first command and period [s] (ESRF study: 1 s, 1 s).
    lpf_hz : float
        Corner of the low pass of 11.6 [Hz].
    n_bins : int
        Bins of the envelopes (at most the aligned samples).
    block_samples : int
        Samples per block read (memory: a few blocks of each signal).
    progress : callable, optional
        Receives a line per tenth of each read.

    Raises
    ------
    ValueError
        As :func:`find_alignment`; NaN or infinite samples (naming the signal).
    """
    al = find_alignment(ds, name=name, align_s=align_s, period_s=period_s,
                        block_samples=block_samples)
    fs, n, per = al.fs_hz, al.n_periods, al.period_samples
    bins = min(n_bins, n * per)
    signals = {k: ds[k].data for k in (al.channel, "Vph", "Vpv", "Va")}

    def blocks(keys: tuple[str, ...], what: str) -> Iterator[tuple[int, dict[str, FloatArray]]]:
        return finite_blocks({k: signals[k] for k in keys}, name=al.name, start=al.start_index,
                             stop=al.stop_index, fs_hz=fs, what=what,
                             block_samples=block_samples, progress=progress)

    shift = float(np.asarray(signals["Va"][al.start_index]))
    options = WelchOptions.from_matlab(window=hanning(math.ceil(fs)), noverlap=None, nfft=None,
                                       fs_hz=fs)
    first = _fold_periods(blocks((al.channel, "Vph", "Vpv", "Va"), "folding the periods"),
                          al=al, params=params, lpf_hz=lpf_hz, shift_m=shift, options=options,
                          bins=bins)
    read_2 = blocks(("Vph", "Vpv", "Va"), "non-repeatable parts and spectra")
    second = _nonrepeatable_parts(read_2, first, al=al, params=params, lpf_hz=lpf_hz,
                                  shift_m=shift, bins=bins)
    return _repeatability_record(al, first, second, shift_m=shift)


@dataclass(frozen=True)
class _FoldedRead:
    """Read 1's streams and means [m]: ``va_mean_m``, the repeatable parts ``rep_*`` (P,).

    ``va_mean_m``, ``rep_m``, ``rep_lpf_m`` are of ``Va − s`` (``s``: the first aligned
    sample); ``rep_settled_m`` is the low pass's mean over periods 2 … n only.
    """

    sums: dict[str, SumStream]
    welch: dict[str, WelchStream]
    fold_va: _Fold
    fold_lpf: _Fold
    env: dict[str, EnvelopeStream]
    va_mean_m: float
    rep_m: FloatArray
    rep_lpf_m: FloatArray
    rep_settled_m: FloatArray
    rep_dist_m: FloatArray


def _fold_periods(blocks: Iterable[tuple[int, dict[str, FloatArray]]], *,
                  al: PeriodAlignment, params: BenchParams, lpf_hz: float, shift_m: float,
                  options: WelchOptions, bins: int) -> _FoldedRead:
    """Read 1: folds, means, spectra and envelopes of the raw signals.

    ``blocks``: the aligned record's command, ``Vph``, ``Vpv`` [V] and ``Va`` [m]
    (cut at ``al``); ``params``, ``lpf_hz`` [Hz]: as :func:`analyse_repeatability`;
    ``shift_m``: ``Va``'s first aligned sample [m], removed from every sample;
    ``options``: the Welch PSDs' (1 s Hann); ``bins``: of the envelopes.
    """
    fs, n, per = al.fs_hz, al.n_periods, al.period_samples
    total = n * per
    keys_psd = ("rh", "rv", "dist", "seed_h", "seed_v")
    derived = _Signals(params=params, fs_hz=fs, lpf_hz=lpf_hz, shift_m=shift_m)
    sums = {k: SumStream() for k in ("va", "rh", "rv", "dist", "seed_h", "seed_v")}
    welch = {k: WelchStream(options=options, n_samples=total, name=f"{al.name}.{k}")
             for k in (*keys_psd, "va")}
    fold_va, fold_lpf, fold_dist = _Fold(per), _Fold(per), _Fold(per)
    env = {k: EnvelopeStream(n_samples=total, n_bins=bins, fs_hz=fs)
           for k in ("command", "Vph", "Vpv", "tracking_distance")}
    for offset, block in blocks:
        d = derived.derive(offset, block)
        for k, s in sums.items():
            s.update(d[k])
        for k in keys_psd:
            welch[k].update(d[k])
        fold_va.update(d["va"])
        fold_lpf.update(d["lpf"])
        fold_dist.update(d["dist"])
        env["command"].update(block[al.channel])
        env["Vph"].update(block["Vph"])
        env["Vpv"].update(block["Vpv"])
        env["tracking_distance"].update(d["dist"])
    return _FoldedRead(sums=sums, welch=welch, fold_va=fold_va, fold_lpf=fold_lpf, env=env,
                       va_mean_m=sums["va"].mean, rep_m=fold_va.mean(n),
                       rep_lpf_m=fold_lpf.mean(n), rep_settled_m=fold_lpf.rest_sum / (n - 1),
                       rep_dist_m=fold_dist.mean(n))


@dataclass(frozen=True)
class _NonRepeatableRead:
    """Read 2's streams: non-repeatable parts, signals less their means, their envelopes."""

    nonrep: dict[str, SumStream]
    centred: dict[str, SumStream]
    env: dict[str, EnvelopeStream]


def _nonrepeatable_parts(blocks: Iterable[tuple[int, dict[str, FloatArray]]],
                         first: _FoldedRead, *, al: PeriodAlignment, params: BenchParams,
                         lpf_hz: float, shift_m: float, bins: int) -> _NonRepeatableRead:
    """Read 2: what needs the repeatable parts and the means (read 1's, ``first``).

    ``blocks`` holds ``Vph``, ``Vpv`` [V] and ``Va`` [m]; the other parameters are
    :func:`_fold_periods`'. Read 1's Welch stream of ``Va`` is fed here.
    """
    fs, per = al.fs_hz, al.period_samples
    total = al.n_periods * per
    rep, rep_f, rep_settled = first.rep_m, first.rep_lpf_m, first.rep_settled_m
    derived = _Signals(params=params, fs_hz=fs, lpf_hz=lpf_hz, shift_m=shift_m)
    nonrep = {k: SumStream() for k in ("va", "lpf", "settled", "dist")}
    centred = {k: SumStream() for k in ("dist", "seed_h", "seed_v")}
    env = {k: EnvelopeStream(n_samples=total, n_bins=bins, fs_hz=fs)
           for k in ("Va", "Va_nonrep", "tracking_distance_nonrep")}
    for offset, block in blocks:
        d = derived.derive(offset, block)
        pos = np.arange(offset, offset + d["va"].size) % per
        va_nonrep = d["va"] - rep[pos]
        nonrep["va"].update(va_nonrep)
        nonrep["lpf"].update(d["lpf"] - rep_f[pos])
        later = max(0, per - offset)  # samples of the first period in this block
        if later < pos.size:
            nonrep["settled"].update(d["lpf"][later:] - rep_settled[pos[later:]])
        dist_nonrep = d["dist"] - first.rep_dist_m[pos]
        nonrep["dist"].update(dist_nonrep)
        for k, s in centred.items():
            s.update(d[k] - first.sums[k].mean)
        va_c = d["va"] - first.va_mean_m
        first.welch["va"].update(va_c)
        env["Va"].update(va_c)
        env["Va_nonrep"].update(va_nonrep)
        env["tracking_distance_nonrep"].update(dist_nonrep)
    return _NonRepeatableRead(nonrep=nonrep, centred=centred, env=env)


def _repeatability_record(al: PeriodAlignment, first: _FoldedRead, second: _NonRepeatableRead,
                          *, shift_m: float) -> RepeatabilityRecord:
    """The record's result from both reads (``shift_m``: ``Va``'s first aligned sample [m])."""
    fs, n, per = al.fs_hz, al.n_periods, al.period_samples
    sums, nonrep, centred = first.sums, second.nonrep, second.centred
    rep, rep_f, rep_settled = first.rep_m, first.rep_lpf_m, first.rep_settled_m
    fold_va, fold_lpf, va_mean = first.fold_va, first.fold_lpf, first.va_mean_m
    psd = {k: np.asarray(w.result().values, dtype=float) for k, w in first.welch.items()}
    f_hz = np.asarray(first.welch["va"].result().f_hz, dtype=float)
    nonrep_rms = nonrep["va"].rms
    va_lo = np.minimum(fold_va.first, fold_va.rest_min)
    va_hi = np.maximum(fold_va.first, fold_va.rest_max)
    return RepeatabilityRecord(
        name=al.name, direction={"Unh": "h", "Unv": "v"}[al.channel], channel=al.channel,
        fs_hz=fs, period_s=per / fs, n_periods=n, start_s=al.start_index / fs,
        nonrep_rms_m=nonrep_rms, nonrep_rms_unbiased_m=nonrep_rms * math.sqrt(n / (n - 1)),
        nonrep_rms_lpf_m=nonrep["lpf"].rms,
        nonrep_rms_lpf_settled_m=nonrep["settled"].rms if n >= 3 else None,
        repeatable_ptp_m=float(np.ptp(rep)),
        tracking_rms_rad=(sums["rh"].rms, sums["rv"].rms),
        tracking_distance_mean_m=sums["dist"].mean, tracking_distance_std_m=centred["dist"].rms,
        tracking_distance_nonrep_rms_m=nonrep["dist"].rms,
        seed_law_distance_std_m=(centred["seed_h"].rms, centred["seed_v"].rms),
        repeatable_m=shift_m + rep, repeatable_lpf_m=shift_m + rep_f,
        va_min_m=va_lo - va_mean, va_max_m=va_hi - va_mean,
        va_nonrep_min_m=va_lo - rep, va_nonrep_max_m=va_hi - rep,
        va_lpf_settled_nonrep_min_m=fold_lpf.rest_min - rep_settled,
        va_lpf_settled_nonrep_max_m=fold_lpf.rest_max - rep_settled,
        va_lpf_first_nonrep_m=fold_lpf.first - rep_f,
        tracking_distance_repeatable_m=first.rep_dist_m,
        envelopes={**{k: e.result() for k, e in first.env.items()},
                   **{k: e.result() for k, e in second.env.items()}},
        f_hz=f_hz,
        psd_tracking_rad2_per_hz=np.stack([psd["rh"], psd["rv"]], axis=1),
        psd_distance_m2_per_hz=psd["dist"],
        psd_distance_seed_m2_per_hz=np.stack([psd["seed_h"], psd["seed_v"]], axis=1),
        psd_va_m2_per_hz=psd["va"])


@dataclass(frozen=True)
class HuddleWindow:
    """``Va`` of a huddle test over the repeatability records' length (Fig. 50's last panel).

    ``envelope``: min/max per bin of ``Va`` less its mean over the window [m];
    ``va_rms_m``: its rms about that mean [m]; ``n_samples`` at ``fs_hz``.
    """

    name: str
    envelope: Envelope = field(repr=False)
    va_rms_m: float
    n_samples: int
    fs_hz: float

    @property
    def duration_s(self) -> float:
        """Length of the window [s]."""
        return self.n_samples / self.fs_hz

    def to_json(self) -> dict[str, object]:
        """The scalars (the envelope stays for the figure)."""
        return {"name": self.name, "va_rms_m": self.va_rms_m, "n_samples": self.n_samples,
                "fs_hz": self.fs_hz}


def huddle_window(ds: xr.Dataset, *, name: str, n_max: int,
                  n_bins: int = ENVELOPE_BINS) -> HuddleWindow:
    """``Va`` of a huddle test after the ESRF study's trim, its first ``n_max`` samples at most.

    Read twice in blocks (the record may be out of core): the mean, then the
    envelope and the rms about it.

    Parameters
    ----------
    ds : xarray.Dataset
        The huddle test (``Va`` [m] on ``t`` [s], attribute ``fs_hz``).
    name : str
        Its experiment name, for messages.
    n_max : int
        Most samples to use (the longest repeatability record's aligned length).
    n_bins : int
        Bins of the envelope.

    Raises
    ------
    ValueError
        Naming the record, when nothing is left after removing ``t < 1 s``.
    """
    fs = float(ds.attrs["fs_hz"])
    trim = trim_record(ds, t0_s=1.0, duration_s=None, fs_hz=fs)
    n = min(n_max, trim.n)
    if n < 1:
        raise ValueError(f"{name}: no sample left after removing t < 1 s")
    va = {"Va": ds["Va"].data}
    stop = trim.start + n
    sums = SumStream(shift=float(np.asarray(va["Va"][trim.start])))  # nm under an offset
    for _, block in read_blocks(va, start=trim.start, stop=stop):
        sums.update(block["Va"])
    mean, centred = sums.mean, SumStream()
    env = EnvelopeStream(n_samples=n, n_bins=min(n_bins, n), fs_hz=fs)
    for _, block in read_blocks(va, start=trim.start, stop=stop):
        centred.update(block["Va"] - mean)
        env.update(block["Va"] - mean)
    return HuddleWindow(name=name, envelope=env.result(), va_rms_m=centred.rms, n_samples=n,
                        fs_hz=fs)
