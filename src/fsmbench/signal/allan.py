"""Overlapping Allan deviation of long records (NumPy or Dask), and its noise-type regions.

Definition (IEEE Std 1139-2008; W. J. Riley, *Handbook of Frequency Stability
Analysis*, NIST SP 1065 (2008), eq. 11 written for frequency data): for samples
``y_0 .. y_{N-1}`` of a frequency-like quantity (e.g. the measured distance ``Va``, m)
taken every ``1/fs`` s, and an averaging factor ``m`` (``tau = m/fs``), let

    B_k = sum_{i=k}^{k+m-1} y_i          (so the m-average is  ybar_k = B_k / m)

    sigma^2(tau) = 1 / (2 m^2 (N - 2m + 1)) * sum_{k=0}^{N-2m} (B_{k+m} - B_k)^2
                 = 1 / (2 (N - 2m + 1))     * sum_{k=0}^{N-2m} (ybar_{k+m} - ybar_k)^2,

i.e. half the mean square difference of all overlapping pairs of adjacent
m-averages; ``N - 2m + 1`` terms. This is ``allantools.oadev(y, rate=fs,
data_type="freq")`` (which integrates ``y`` to phase ``x`` with ``N + 1`` points
and uses ``N_x - 2m`` terms: the same count).

How it is computed (exact sums, bounded memory): the record is cut in cells of
``n`` samples (``task_samples``). A task handles the terms ``k0 .. k1-1`` of one
``tau`` (``k1 - k0 <= n``): it starts from two *anchors* ``B_{k0}`` and ``B_{k0+m}``
and slides them with running sums of ``y_{k+m} - y_k`` (O(n) work). An anchor over
at most ``2n`` samples is summed directly; a longer one is its head and tail
pieces plus the exact (``math.fsum``) sum of precomputed per-cell totals. So a
task reads at most ~7n samples whatever ``m`` is, the work is O(N) per ``tau``,
and no running sum ever spans the record: a global cumulative sum would lose
``Va``'s nanometres under its metre-scale offset on a 10^9-sample record. The
first sample is subtracted from every sample first (the deviation does not
depend on a constant offset) for the same reason.

Memory: each task holds ~7 cells. Dask keeps a loaded chunk until its last reader
has run, and the readers of a chunk at lag ``m`` run ``2m`` samples apart, so with
the long default taus (up to ``N/4``) the threaded scheduler may hold a good part
of the record (measured: 320 MB of random chunks, peak RSS 0.66 GB against 0.19 GB
for the interpreter). On ``dask.distributed`` workers spill to disk instead; a
memory-bounded run on one machine should limit ``taus_s`` or read the record in
several passes.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np
from numba import njit
from numpy.typing import ArrayLike, NDArray

from fsmbench.signal.segments import read_span as read

if TYPE_CHECKING:  # welch_dask imports Dask, an extra: imported where the Dask path runs
    from fsmbench.signal.welch_dask import _TimeChunks

__all__ = ["AllanRegion", "AllanResult", "allan_deviation", "allan_regions"]

_Read = tuple[list[Any], int, int]  # (chunks, offset in the first, length)

# Nominal log-log slopes of the overlapping ADEV of frequency-like data (SP 1065, Table 4).
_NOISE_TYPES = (
    # The differences of a white noise average to ~1/m: a quantity with no low-frequency
    # content, e.g. one a feedback loop holds (SP 1065's white phase noise).
    ("bounded", "bounded (white phase) noise", -1.0),
    ("white", "white noise", -0.5),
    ("flicker", "flicker noise", 0.0),
    ("random_walk", "random walk", 0.5),
    ("drift", "drift", 1.0),
)
# A local slope is attributed to a noise type when within +/-0.15 of its nominal slope:
# the nominal slopes are 0.5 apart, so this leaves a 0.2-wide gap where a knee between
# two noise types (or an estimate with few degrees of freedom) is attributed to neither.
SLOPE_TOLERANCE = 0.15
# A region needs at least this many consecutive tau intervals (3 points): one interval
# with the right slope is as often chance as noise type at the long-tau end.
_MIN_INTERVALS = 2


@dataclass(frozen=True, eq=False)
class AllanResult:
    """Overlapping Allan deviation of one record.

    Attributes
    ----------
    tau_s : ndarray, shape (T,)
        Averaging times ``m/fs``, s, increasing.
    adev : ndarray, shape (T,)
        Overlapping Allan deviation at each ``tau``, unit of the record.
    n_terms : ndarray of int, shape (T,)
        Number of overlapping differences averaged, ``N - 2m + 1``.
    m : ndarray of int, shape (T,)
        Averaging factor (samples per average) of each ``tau``.
    fs_hz : float
        Sampling frequency, Hz.
    n_samples : int
        Record length ``N``, samples.
    unit : str
        Unit of the record (and of ``adev``), e.g. ``"m"``; may be empty.
    kind : str
        ``"overlapping"``.
    """

    tau_s: NDArray[np.float64]
    adev: NDArray[np.float64]
    n_terms: NDArray[np.int64]
    m: NDArray[np.int64]
    fs_hz: float
    n_samples: int
    unit: str = ""
    kind: str = "overlapping"

    def regions(self) -> tuple[AllanRegion, ...]:
        """Noise-type regions of this result, see :func:`allan_regions`."""
        return allan_regions(self)


@dataclass(frozen=True)
class AllanRegion:
    """A contiguous range of ``tau`` over which the ADEV follows one noise type.

    Attributes
    ----------
    noise : str
        ``"white"``, ``"flicker"``, ``"random_walk"`` or ``"drift"``.
    label : str
        The same in words (``"white noise"``).
    nominal_slope : float
        Log-log slope of that noise type: -1/2, 0, +1/2, +1.
    slope : float
        Least-squares log-log slope fitted over the region's points.
    tau_start_s, tau_stop_s : float
        First and last ``tau`` of the region, s.
    level_at_1s : float
        The fitted line's deviation at ``tau = 1 s`` (extrapolated if 1 s is outside),
        unit of the record. For drift ``a*t``, ``a = sqrt(2) * level_at_1s`` per second.
    unit : str
        Unit of the record.
    """

    noise: str
    label: str
    nominal_slope: float
    slope: float
    tau_start_s: float
    tau_stop_s: float
    level_at_1s: float
    unit: str = ""

    def describe(self) -> str:
        """One line for the report: ``"white noise: 800 pm at 1 s, slope −0.50, 1 ms–300 ms"``."""
        slope = f"{self.slope:.2f}".replace("-", "−")
        text = (
            f"{self.label}: {_si(self.level_at_1s, self.unit)} at 1 s, slope {slope}, "
            f"{_si(self.tau_start_s, 's')}–{_si(self.tau_stop_s, 's')}"
        )
        if self.noise == "drift":
            rate = math.sqrt(2.0) * self.level_at_1s
            text += f" (drift rate about {_si(rate, self.unit)} per second)"
        return text


_PREFIXES = {-15: "f", -12: "p", -9: "n", -6: "µ", -3: "m", 0: "", 3: "k", 6: "M", 9: "G"}


def _si(value: float, unit: str) -> str:
    """``8e-10, "m"`` -> ``"800 pm"``; without a unit, 3 significant digits."""
    if not unit or value == 0.0 or not math.isfinite(value):
        return f"{value:.3g} {unit}".strip()
    exp = math.floor(math.log10(abs(value)) / 3.0) * 3
    exp = min(max(exp, -15), 9)
    return f"{value / 10.0**exp:.3g} {_PREFIXES[exp]}{unit}"


# --------------------------------------------------------------------------- tasks
def _read(pieces: Sequence[NDArray[np.float64]], offset: int,
          length: int) -> NDArray[np.float64]:
    return read(pieces, offset, length)


def _first(pieces: Sequence[NDArray[np.float64]]) -> float:
    return float(pieces[0][0])


def _cell_sum(pieces: Sequence[NDArray[np.float64]], offset: int, length: int, ref: float) -> float:
    return float(np.sum(_read(pieces, offset, length) - ref))


def _fsum_rows(rows: Sequence[Sequence[float]]) -> NDArray[np.float64]:
    """Exact sum of each row (one row of block sums per tau), independent of the order."""
    return np.array([math.fsum(r) for r in rows])


def _collect(values: Sequence[float]) -> NDArray[np.float64]:
    return np.asarray(values, dtype=np.float64)


def _anchor(heads: Sequence[_Read], cells: tuple[int, int], totals: NDArray[np.float64],
            ref: float) -> float:
    parts = [float(np.sum(_read(p, o, n) - ref)) for p, o, n in heads]
    return math.fsum([*parts, *totals[cells[0] : cells[1]].tolist()])


def _block(reads: Sequence[_Read], anchors: Sequence[tuple[Sequence[_Read], tuple[int, int]]],
           totals: NDArray[np.float64], ref: float) -> float:
    """``sum (B_{k+m} - B_k)^2`` over one block of terms (see the module docstring)."""
    # Non-finite samples are reported by name after the computation, not warned about here.
    with np.errstate(invalid="ignore", over="ignore"):
        y1, y2, y3 = (_read(p, o, n) - ref for p, o, n in reads)
        a0, a1 = (_anchor(h, c, totals, ref) for h, c in anchors)
        b0 = a0 + np.concatenate([[0.0], np.cumsum(y2 - y1)])
        b1 = a1 + np.concatenate([[0.0], np.cumsum(y3 - y2)])
        d = b1 - b0
        return float(np.dot(d, d))


def _check_finite(
    pieces: Sequence[NDArray[np.float64]], offset: int, length: int, start: int
) -> int:
    """Index of the first non-finite sample of ``start .. start+length-1``, or -1."""
    bad = np.flatnonzero(~np.isfinite(_read(pieces, offset, length)))
    return -1 if bad.size == 0 else int(bad[0]) + start


# --------------------------------------------------------------------------- API
def _factors(taus_s: ArrayLike | None, fs_hz: float, n: int) -> NDArray[np.int64]:
    if taus_s is None:
        top = max(1, n // 4)
        return np.array([1 << p for p in range(top.bit_length()) if (1 << p) <= top])
    taus = np.atleast_1d(np.asarray(taus_s, dtype=np.float64))
    if taus.ndim != 1 or taus.size == 0 or not np.all(np.isfinite(taus)):
        raise ValueError(f"taus_s must be a non-empty list of finite times in s, got {taus_s!r}")
    m = np.rint(taus * fs_hz).astype(np.int64)
    for tau, mi in zip(taus, m, strict=True):
        if mi < 1:
            raise ValueError(
                f"tau {tau:g} s is shorter than one sample ({1.0 / fs_hz:g} s at {fs_hz:g} Hz)"
            )
        if 2 * mi > n:
            raise ValueError(
                f"tau {tau:g} s needs two averages of {mi} samples, but the record has only "
                f"{n} samples ({n / fs_hz:g} s)"
            )
    return np.unique(m)


def allan_deviation(
    x: Any,
    *,
    fs_hz: float,
    taus_s: ArrayLike | None = None,
    unit: str = "",
    name: str = "record",
    task_samples: int | None = None,
) -> AllanResult:
    """Overlapping Allan deviation of a frequency-like record, NumPy or Dask (out of core).

    Parameters
    ----------
    x : array_like or dask.array.Array, shape (N,)
        Real, finite samples of the quantity (unit U, e.g. m for ``Va``), ``N >= 2``.
        A Dask array may be chunked along time in any way; it is read in tasks of
        ``task_samples`` and never loaded whole.
    fs_hz : float
        Sampling frequency, Hz.
    taus_s : array_like of float, optional
        Averaging times, s; each is rounded to a whole number ``m`` of samples
        (``tau_s`` of the result holds ``m/fs``) and needs ``2m <= N``. Default:
        octave spacing, ``m = 1, 2, 4, ...`` up to ``N/4`` (``tau`` from ``1/fs`` to
        ``N/(4 fs)``), where at least ``N/2`` differences are averaged.
    unit : str, optional
        Unit of ``x``, used in :meth:`AllanRegion.describe`.
    name : str, optional
        Signal name used in error messages.
    task_samples : int, optional
        Samples per task and per cell (see the module docstring). Default:
        ``max(largest chunk, 2**18)``. Memory per task is ~7 cells of float64.

    Returns
    -------
    AllanResult
        The formula of the module docstring evaluated at each ``tau``.

    Raises
    ------
    ValueError
        Fewer than 2 samples, NaN or infinite samples (count and first index),
        a ``tau`` shorter than one sample or longer than half the record.
    """
    fs = float(fs_hz)
    if not (math.isfinite(fs) and fs > 0.0):
        raise ValueError(f"fs_hz must be a positive finite frequency in Hz, got {fs_hz!r}")
    if not type(x).__module__.startswith("dask"):
        return _allan_in_memory(np.asarray(x, dtype=np.float64), fs=fs, taus_s=taus_s,
                                unit=unit, name=name)
    return _allan_dask(x, fs=fs, taus_s=taus_s, unit=unit, name=name, task_samples=task_samples)


def _allan_dask(x: Any, *, fs: float, taus_s: ArrayLike | None, unit: str, name: str,
                task_samples: int | None) -> AllanResult:
    """The module's formula on a Dask array, in tasks of ``task_samples`` (out of core).

    Parameters as :func:`allan_deviation` (``fs`` [Hz] already checked).
    """
    import dask
    from dask.base import tokenize

    from fsmbench.signal.welch_dask import _MIN_TASK_SAMPLES, _TimeChunks, as_time_chunked

    arr = as_time_chunked(x, what=name)
    if arr.ndim != 1:
        raise ValueError(f"{name} must be a 1-D array of samples, got shape {arr.shape}")
    n = int(arr.shape[0])
    if n < 2:
        raise ValueError(f"{name} has {n} sample(s); the Allan deviation needs at least 2")
    factors = _factors(taus_s, fs, n)
    longest = max(arr.chunks[0])
    cell = int(task_samples) if task_samples is not None else max(longest, _MIN_TASK_SAMPLES)
    if cell < 1:
        raise ValueError(f"task_samples must be >= 1, got {task_samples}")
    chunks = _TimeChunks(arr)
    gname = "allan-" + tokenize(arr, factors.tobytes(), cell)
    dsk: dict[Any, Any] = {}
    keys = _cell_tasks(dsk, chunks, gname=gname, n=n, cell=cell)
    rows = _block_tasks(dsk, chunks, gname=gname, factors=factors, n=n, cell=cell, keys=keys)
    dsk[(gname, 0)] = (_fsum_rows, rows)
    dsk[(f"{gname}-bad", 0)] = (_collect, keys.finite)
    sums_lazy = chunks.array_from(gname, dsk, ((len(rows),),), np.float64)
    bad_lazy = chunks.array_from(f"{gname}-bad", dsk, ((len(keys.finite),),), np.float64)
    sums, first_bad = dask.compute(sums_lazy, bad_lazy)
    bad = [int(i) for i in first_bad if i >= 0]
    if bad:
        raise _non_finite_error(name, bad[0])
    return _allan_result(np.asarray(sums), factors=factors, fs=fs, n=n, unit=unit)


class _CellKeys(NamedTuple):
    """Graph keys of the first sample, of the cells' totals and of each cell's finite check."""

    ref: str
    totals: str
    finite: list[tuple[str, int]]


def _cell_tasks(dsk: dict[Any, Any], chunks: _TimeChunks, *, gname: str, n: int,
                cell: int) -> _CellKeys:
    """Add to ``dsk`` the first sample, each whole cell's total less it, each cell's check.

    Parameters
    ----------
    dsk : dict
        The Dask graph, extended in place.
    chunks : _TimeChunks
        The record's chunks along time.
    gname : str
        The graph's name (prefix of every key).
    n, cell : int
        Samples of the record and of a cell.
    """
    ref, totals = f"{gname}-ref", f"{gname}-totals"
    dsk[ref] = (_first, chunks.covering(0, 1)[0])
    cells = []
    for j in range(n // cell):
        dsk[(f"{gname}-cell", j)] = (_cell_sum, *chunks.covering(j * cell, (j + 1) * cell), ref)
        cells.append((f"{gname}-cell", j))
    dsk[totals] = (_collect, cells)
    finite = []
    for j, start in enumerate(range(0, n, cell)):
        dsk[(f"{gname}-finite", j)] = (
            _check_finite, *chunks.covering(start, min(start + cell, n)), start
        )
        finite.append((f"{gname}-finite", j))
    return _CellKeys(ref=ref, totals=totals, finite=finite)


def _anchor_reads(chunks: _TimeChunks, a: int, b: int, *, cell: int) -> list[Any]:
    """What :func:`_anchor` sums for ``B`` over samples ``a .. b-1``: reads and a cell range.

    Over at most two cells the samples themselves; longer, the head and the tail
    read and the whole cells between them taken from their totals.
    """
    if b - a <= 2 * cell:
        return [[chunks.covering(a, b)], [0, 0]]
    c0, c1 = -(-a // cell), b // cell
    return [[chunks.covering(a, c0 * cell), chunks.covering(c1 * cell, b)], [c0, c1]]


def _block_tasks(dsk: dict[Any, Any], chunks: _TimeChunks, *, gname: str,
                 factors: NDArray[np.int64], n: int, cell: int,
                 keys: _CellKeys) -> list[list[tuple[str, int]]]:
    """Add to ``dsk`` one :func:`_block` task per ``cell`` terms of each ``m``; their keys.

    Parameters as :func:`_cell_tasks`; ``factors`` are the averaging factors
    ``m`` [samples], ``keys`` the cells' tasks. Returns one row of keys per ``m``.
    """
    rows = []
    for m in (int(v) for v in factors):
        n_terms = n - 2 * m + 1
        row = []
        for k0 in range(0, n_terms, cell):
            k1 = min(k0 + cell, n_terms)
            reads = [chunks.covering(k0 + s, k1 - 1 + s) for s in (0, m, 2 * m)]
            anchors = [_anchor_reads(chunks, k0, k0 + m, cell=cell),
                       _anchor_reads(chunks, k0 + m, k0 + 2 * m, cell=cell)]
            key = (f"{gname}-block-{m}", k0 // cell)
            dsk[key] = (_block, reads, anchors, keys.totals, keys.ref)
            row.append(key)
        rows.append(row)
    return rows


def _non_finite_error(name: str, index: int) -> ValueError:
    """The error naming the record and its first NaN or infinite sample (index)."""
    return ValueError(
        f"{name} contains NaN or infinite samples (first at index {index}); remove or "
        "interpolate them before the Allan deviation"
    )


def _allan_result(sums: NDArray[np.float64], *, factors: NDArray[np.int64], fs: float, n: int,
                  unit: str) -> AllanResult:
    """The read-only result from ``sum (B_{k+m} - B_k)^2`` of each ``m`` (``fs`` in Hz)."""
    n_terms_all = n - 2 * factors + 1
    avar = sums / (2.0 * factors.astype(np.float64) ** 2 * n_terms_all)
    out = AllanResult(tau_s=factors / fs, adev=np.sqrt(avar), n_terms=n_terms_all.astype(np.int64),
                      m=factors.astype(np.int64), fs_hz=fs, n_samples=n, unit=unit)
    for a in (out.tau_s, out.adev, out.n_terms, out.m):
        a.setflags(write=False)
    return out


def _allan_in_memory(x: NDArray[np.float64], *, fs: float, taus_s: ArrayLike | None,
                     unit: str, name: str) -> AllanResult:
    """The module's formula on a record in memory (no Dask needed).

    The m-sample averages come from a cumulative sum of ``x - x[0]`` (the
    offset removed first, so nanometre noise is not lost under a metre-scale
    distance); the Dask path sums the same terms in cells. The squares are
    positive, so blocked accumulation sums them to ~1e-15 relative:
    ``math.fsum``'s exactness cost ~1 s per million terms per tau (11 s of the
    study's budget stage) for digits no comparison uses. The sums run compiled
    (:func:`_second_difference_energies`): one pass per tau and no temporaries,
    where NumPy's slices made three arrays of N per tau
    (``benchmarks/bench_allan.py``).
    """
    if x.ndim != 1:
        raise ValueError(f"{name} must be a 1-D array of samples, got shape {x.shape}")
    n = int(x.size)
    if n < 2:
        raise ValueError(f"{name} has {n} sample(s); the Allan deviation needs at least 2")
    bad = np.flatnonzero(~np.isfinite(x))
    if bad.size:
        raise _non_finite_error(name, int(bad[0]))
    factors = _factors(taus_s, fs, n)
    c = np.concatenate([[0.0], np.cumsum(x - x[0])])
    sums = _second_difference_energies(c, factors)
    return _allan_result(sums, factors=factors, fs=fs, n=n, unit=unit)


#: Terms summed into one partial sum before it joins the total: rounding grows
#: with ~(block + N/block)·eps instead of N·eps for a plain running sum.
_SUM_BLOCK = 1024


@njit(cache=True)
def _second_difference_energies(c: NDArray[np.float64],
                                factors: NDArray[np.int64]) -> NDArray[np.float64]:
    """``sum_k (c[k+2m] - 2 c[k+m] + c[k])**2`` for each ``m`` of ``factors``, (M,).

    ``c`` is the cumulative sum of the record with a leading 0, so each term is
    the difference of two adjacent m-sample sums (pragma: compiled, numba).
    """
    out = np.empty(factors.size)
    for i in range(factors.size):
        m = factors[i]
        n_terms = c.size - 2 * m
        total = 0.0
        k = 0
        while k < n_terms:
            stop = min(k + _SUM_BLOCK, n_terms)
            part = 0.0
            for j in range(k, stop):
                d = (c[j + 2 * m] - c[j + m]) - (c[j + m] - c[j])
                part += d * d
            total += part
            k = stop
        out[i] = total
    return out


def allan_regions(result: AllanResult) -> tuple[AllanRegion, ...]:
    """Contiguous ``tau`` ranges where the ADEV follows one standard noise type.

    The local log-log slope between consecutive ``tau`` is attributed to the
    noise type whose nominal slope (white -1/2, flicker 0, random walk +1/2,
    drift +1; SP 1065 Table 4 for frequency data) is within
    :data:`SLOPE_TOLERANCE`; runs of at least two intervals with the same type
    form a region, whose slope and level are fitted by least squares on
    ``log(adev)`` versus ``log(tau)`` over the run's points.

    Parameters
    ----------
    result : AllanResult
        An Allan deviation with at least 3 taus (fewer give no region).

    Returns
    -------
    tuple of AllanRegion
        In increasing ``tau``; intervals matching no type (knees) belong to none.
    """
    tau, adev = np.asarray(result.tau_s), np.asarray(result.adev)
    ok = (adev > 0.0) & np.isfinite(adev)
    if tau.size < 3 or not ok.all():
        return ()
    lt, la = np.log10(tau), np.log10(adev)
    slopes = np.diff(la) / np.diff(lt)
    kinds: list[int | None] = []
    for s in slopes:
        best = min(range(len(_NOISE_TYPES)), key=lambda i: abs(s - _NOISE_TYPES[i][2]))
        kinds.append(best if abs(s - _NOISE_TYPES[best][2]) <= SLOPE_TOLERANCE else None)
    regions = []
    i = 0
    while i < len(kinds):
        j = i
        while j + 1 < len(kinds) and kinds[j + 1] == kinds[i]:
            j += 1
        kind = kinds[i]
        if kind is not None and j - i + 1 >= _MIN_INTERVALS:
            pts = slice(i, j + 2)  # interval q joins points q and q+1
            slope, intercept = np.polyfit(lt[pts], la[pts], 1)
            key, label, nominal = _NOISE_TYPES[kind]
            regions.append(AllanRegion(
                noise=key, label=label, nominal_slope=nominal, slope=float(slope),
                tau_start_s=float(tau[i]), tau_stop_s=float(tau[j + 1]),
                level_at_1s=float(10.0**intercept), unit=result.unit,
            ))
        i = j + 1
    return tuple(regions)
