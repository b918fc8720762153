"""Steps in the Attocube distance ``Va``: an interferometer that lost count (fringe loss).

An interferometer that loses count reports a distance that jumps, between two
samples, by a fraction of a micrometre or more, in a record whose noise is a
nanometre. Such a record must not give any number: its rms, PSD and drift are
the jump's, not the bench's. :func:`find_jumps` finds them, and
:func:`fsmbench.io.folder.check_recording` turns the result into the check
``va_continuous``.

The rule, on the increments ``d[i] = Va[i+1] − Va[i]`` [m]:

1. ``r[i] = d[i] − median(d[i−4 … i+4])``: the local median of nine increments
   is the smooth motion's own increment (air and thermal drift, nm over
   seconds; the repeatability runs' 1 Hz, ~1 µm motion, < 0.4 nm per sample),
   so ``r`` is the noise of the increments plus what is not smooth. A single
   outlier does not move a median of nine.
2. The noise scale ``σ`` is ``1.4826 · median |r − median r|`` (the MAD, equal
   to the standard deviation for Gaussian noise and blind to a few jumps), per
   block of :data:`SCALE_BLOCK` samples, so that a noisier stretch of a long
   record does not lower the threshold elsewhere; never below
   :data:`SCALE_FLOOR_M`.
3. A jump at sample ``i + 1`` is ``|r[i]| > T · σ`` with both neighbours
   ``|r[i ± 1]|`` below :data:`ISOLATION` of ``|r[i]|``: a loss of count puts its
   whole size on one increment, while a fast but band-limited motion spreads
   comparable increments over adjacent samples. ``T`` is :data:`JUMP_THRESHOLD`,
   or :data:`TAIL_FACTOR` times the record's own tail (the
   :data:`TAIL_RANK`-th largest ``|r|/σ`` below :data:`JUMP_THRESHOLD`) when that
   is larger: a jump stands out of its record's noise, whatever the noise's
   shape. Gaussian increments' tail (the 10th largest of 10⁶ is ~4.6 σ) leaves
   ``T`` at 10; a bench whose closed loop puts the DAC's steps on the beam (an
   independent simulator's bench with 7.5 times the plant gain: kurtosis 2.6, the
   10th largest residual under 10 σ at ~8 σ) raises it, where 10 σ alone named
   an 8 nm step a fringe loss.

Increments that are exactly 0 are left out first, so a ``Va`` held between updates
(an interferometer slower than the ADC) is scanned at its updates.

False alarms: Gaussian increments exceed 10 σ with probability 1.5e-23 per sample
(1.3e-14 in a day at 10 kHz). The twin's are heavier-tailed: on its huddle and
repeatability records of four benches (packaged, real, stiff, soft; 100 s each, seed
11, 2.8e7 increments) 568 residuals exceed 5 σ where Gaussian noise gives 16, 7
exceed 6 σ, none 7 σ; the largest is 6.4 σ. No jump was found on any of them. On
their 100 s huddle test 1, jumps of ±1 µm, ±100 nm and 30 nm at random samples were
all found at their sample (20 of 20 each); 10 nm (~9 σ) was not.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from itertools import pairwise
from typing import Any, Final

import numpy as np
import xarray as xr
from numba import njit
from numpy.typing import NDArray

from fsmbench.checks import Check

__all__ = [
    "DEPTH",
    "ISOLATION",
    "JUMP_THRESHOLD",
    "MEDIAN_HALF_WIDTH",
    "SCALE_BLOCK",
    "SCALE_FLOOR_M",
    "TAIL_FACTOR",
    "TAIL_RANK",
    "VaJumps",
    "find_jumps",
    "jump_check",
    "jump_words",
    "va_unit_hint",
]

#: Threshold in robust standard deviations of the increments' residual: Gaussian noise
#: exceeds 10 σ with probability 1.5e-23 per sample, so even tails 1e8 times heavier
#: than Gaussian give no false alarm in a day at 10 kHz (8.6e8 samples).
JUMP_THRESHOLD: Final = 10.0
#: A jump is at least this many times the record's own tail (heavy-tailed noise, module
#: notes): twice the largest residuals the bulk of the record reaches.
TAIL_FACTOR: Final = 2.0
#: Rank of the residual that measures the record's tail, among those below
#: :data:`JUMP_THRESHOLD` (jumps themselves, however many, are above it).
TAIL_RANK: Final = 10
#: Half width of the local median of the increments [samples]: nine increments (0.9 ms at
#: 10 kHz) follow any motion slower than ~100 Hz, and a median of nine ignores up to four
#: outliers.
MEDIAN_HALF_WIDTH: Final = 4
#: Samples per block of the noise scale (6.6 s at 10 kHz): the MAD of 65 536 samples is
#: within 0.5 % of the noise's standard deviation, and a long record's noise may change.
SCALE_BLOCK: Final = 1 << 16
#: Smallest noise scale [m]: 1 pm, the Attocube's output resolution (bench file
#: ``attocube.resolution_m``); a record quieter than that is not resolved.
SCALE_FLOOR_M: Final = 1e-12
#: A jump's neighbours carry less than half its residual: a step band-limited to fewer
#: than ~3 samples per rise (the Newport's 600 Hz at 10 kHz) puts as much on the next one.
ISOLATION: Final = 0.5
#: Samples read beyond each side of a chunk: the residuals next to the chunk's own need
#: ``MEDIAN_HALF_WIDTH + 2`` non-zero increments, ten samples apart at most (a Va held
#: for ten samples between updates).
DEPTH: Final = 10 * (MEDIAN_HALF_WIDTH + 2)
_MAD_TO_STD: Final = 1.4826  # 1 / Φ⁻¹(3/4): the MAD of Gaussian noise is 0.6745 σ


@dataclass(frozen=True)
class VaJumps:
    """What :func:`find_jumps` found in one record.

    Attributes
    ----------
    n_samples : int
        Samples scanned.
    count : int
        Jumps found (samples after which ``Va`` stepped).
    first_index : int
        Sample index of the first jump: ``Va`` changes between samples
        ``first_index − 1`` and ``first_index`` (−1 without a jump).
    index : int
        Sample index of the largest step (a jump, or the largest residual
        when there is none; −1 for a record too short to scan).
    step_m : float
        That step, signed [m]: ``r`` at ``index − 1`` (the jump's size).
    scale_m : float
        The robust noise scale ``σ`` of the increments' residual at that
        step [m].
    threshold : float
        The threshold in units of ``σ`` (:data:`JUMP_THRESHOLD`, or the record's
        tail's when higher).
    """

    n_samples: int
    count: int
    first_index: int
    index: int
    step_m: float
    scale_m: float
    threshold: float = JUMP_THRESHOLD

    @property
    def ratio(self) -> float:
        """``|step_m| / scale_m``: the largest step in noise units."""
        return abs(self.step_m) / self.scale_m if self.scale_m > 0 else 0.0

    @property
    def limit_m(self) -> float:
        """The threshold at the largest step [m]: ``threshold · scale_m``."""
        return self.threshold * self.scale_m


def _block_scales(r: NDArray[np.float64], steps: NDArray[np.intp], n_steps: int
                  ) -> NDArray[np.float64]:
    """σ of each residual ``r`` at global step indices ``steps`` (sorted), per global block.

    Blocks are ``[k·B, (k+1)·B)`` in global step index (``B``: :data:`SCALE_BLOCK`);
    the record's last block joins the one before when it is shorter than ``B/2``.
    """
    full, tail = divmod(n_steps, SCALE_BLOCK)
    last = max(full if tail >= SCALE_BLOCK // 2 else full - 1, 0)
    block = np.minimum(steps // SCALE_BLOCK, last)
    scale = np.empty_like(r)
    cuts = np.flatnonzero(np.diff(block)) + 1
    for lo, hi in pairwise([0, *cuts.tolist(), r.size]):
        part = r[lo:hi]
        mad = float(np.median(np.abs(part - np.median(part))))
        scale[lo:hi] = max(_MAD_TO_STD * mad, SCALE_FLOOR_M)
    return scale


@njit(cache=True, nogil=True, inline="always")
def _median9(a0: float, a1: float, a2: float, a3: float, a4: float, a5: float, a6: float,
             a7: float, a8: float) -> float:  # pragma: no cover  (compiled)
    """The median of nine values: a selection network of 19 compare-exchanges (Paeth's,
    as Devillard's ``opt_med9``); the result is one of the values itself."""
    a1, a2 = min(a1, a2), max(a1, a2)
    a4, a5 = min(a4, a5), max(a4, a5)
    a7, a8 = min(a7, a8), max(a7, a8)
    a0, a1 = min(a0, a1), max(a0, a1)
    a3, a4 = min(a3, a4), max(a3, a4)
    a6, a7 = min(a6, a7), max(a6, a7)
    a1, a2 = min(a1, a2), max(a1, a2)
    a4, a5 = min(a4, a5), max(a4, a5)
    a7, a8 = min(a7, a8), max(a7, a8)
    a3 = max(a0, a3)
    a5 = min(a5, a8)
    a4, a7 = min(a4, a7), max(a4, a7)
    a6 = max(a3, a6)
    a4 = max(a1, a4)
    a2 = min(a2, a5)
    a4 = min(a4, a7)
    a4, a2 = min(a4, a2), max(a4, a2)
    a4 = max(a6, a4)
    return min(a4, a2)


@njit(cache=True, nogil=True)
def _increment_residuals(x: NDArray[np.float64]
                         ) -> tuple[NDArray[np.intp], NDArray[np.float64]]:  # pragma: no cover
    """The non-zero increments' indices ``k`` (``x[k+1] != x[k]``) and their residuals
    ``r = d − median(d[i−4 … i+4])`` over those increments, the window mirrored at the
    ends (``scipy.ndimage.median_filter(d, 9, mode="mirror")``, which the tests compare).
    One pass where numpy's diff, nonzero, take and scipy's rank filter made five."""
    n = x.size
    count = 0
    for k in range(n - 1):
        if x[k + 1] - x[k] != 0.0:
            count += 1
    steps = np.empty(count, dtype=np.intp)
    d = np.empty(count)
    m = 0
    for k in range(n - 1):
        step = x[k + 1] - x[k]
        if step != 0.0:
            steps[m] = k
            d[m] = step
            m += 1
    r = np.empty(count)
    half = MEDIAN_HALF_WIDTH  # the network is for nine values
    if count < 2 * half + 1:
        return steps, r
    for i in range(count):
        if half <= i < count - half:
            med = _median9(d[i - 4], d[i - 3], d[i - 2], d[i - 1], d[i], d[i + 1], d[i + 2],
                           d[i + 3], d[i + 4])
        else:  # the ends: indices mirrored about the first and last values (not repeated)
            w = np.empty(9)
            for j in range(-half, half + 1):
                at = i + j
                if at < 0:
                    at = -at
                elif at >= count:
                    at = 2 * (count - 1) - at
                w[j + half] = d[at]
            med = _median9(w[0], w[1], w[2], w[3], w[4], w[5], w[6], w[7], w[8])
        r[i] = d[i] - med
    return steps, r


@dataclass(frozen=True)
class _Scanned:
    """One stretch's candidates: its isolated residuals above :data:`JUMP_THRESHOLD`
    (sample index, step [m], σ [m], z), its :data:`TAIL_RANK` largest residuals below it
    (z) and its largest residual of all (as a candidate)."""

    candidates: tuple[tuple[int, float, float, float], ...]
    bulk_top: tuple[float, ...]
    largest: tuple[int, float, float, float]


_EMPTY: Final = _Scanned((), (), (-1, 0.0, SCALE_FLOOR_M, 0.0))


def _scan(x: NDArray[np.float64], offset: int, own: tuple[int, int], n_samples: int
          ) -> _Scanned:
    """Scan the steps ``own = [lo, hi)`` (global indices) of ``x``, whose first sample is
    the record's sample ``offset``; ``x`` holds :data:`DEPTH` samples on each side of them
    where the record has them.

    Increments that are exactly 0 are left out first: a ``Va`` held between updates (an
    interferometer slower than the ADC, or a record upsampled) is scanned at its updates.
    The threshold is the record's, not the stretch's: :func:`_combine` sets it from every
    stretch's tail, so a record read whole and in chunks gives the same jumps.
    """
    lo, hi = own
    steps, r = _increment_residuals(x)
    if hi <= lo or steps.size < 2 * MEDIAN_HALF_WIDTH + 1:
        return _EMPTY
    mine = np.flatnonzero((steps >= lo - offset) & (steps < hi - offset))
    if not mine.size:
        return _EMPTY
    res = r[mine]
    sigma = _block_scales(res, steps[mine] + offset, n_samples - 1)
    z = np.abs(res) / sigma
    padded = np.concatenate(([0.0], np.abs(r), [0.0]))  # a record's end: no neighbour
    neighbours = np.maximum(padded[mine], padded[mine + 2])
    above = np.flatnonzero((z > JUMP_THRESHOLD) & (neighbours < ISOLATION * np.abs(res)))
    where = steps[mine] + offset + 1  # the sample after each increment
    bulk = z[z <= JUMP_THRESHOLD]
    top = np.sort(bulk)[-TAIL_RANK:] if bulk.size else bulk
    k = int(np.argmax(z))
    return _Scanned(
        tuple((int(where[i]), float(res[i]), float(sigma[i]), float(z[i])) for i in above),
        tuple(float(v) for v in top),
        (int(where[k]), float(res[k]), float(sigma[k]), float(z[k])))


def _threshold(bulk_top: list[float]) -> float:
    """The jump threshold in units of σ: :data:`JUMP_THRESHOLD`, raised to
    :data:`TAIL_FACTOR` times the record's tail when that is higher (module notes)."""
    if len(bulk_top) < TAIL_RANK:
        return JUMP_THRESHOLD
    tail = sorted(bulk_top)[-TAIL_RANK]
    return max(JUMP_THRESHOLD, TAIL_FACTOR * tail)


def _combine(n: int, parts: list[_Scanned]) -> VaJumps:
    """The record's jumps from its stretches' scans."""
    threshold = _threshold([v for p in parts for v in p.bulk_top])
    jumps = sorted(c for p in parts for c in p.candidates if c[3] > threshold)
    if jumps:
        best = max(jumps, key=lambda c: c[3])
    else:
        best = max((p.largest for p in parts), key=lambda c: c[3])
    return VaJumps(n, len(jumps), jumps[0][0] if jumps else -1, best[0], best[1], best[2],
                   threshold)


def find_jumps(va: Any) -> VaJumps:
    """Single-sample steps of ``Va`` (module notes for the rule).

    Parameters
    ----------
    va : array_like or dask.array.Array, shape (N,)
        The Attocube distance [m], finite (checked before). A Dask array is
        scanned chunk by chunk, each with its neighbours' edge samples, in
        memory bounded by a chunk.

    Returns
    -------
    VaJumps
        Counts, the first jump and the largest step with its noise scale.
    """
    n = int(va.shape[0])
    if n < 2 * MEDIAN_HALF_WIDTH + 3:
        return VaJumps(n, 0, -1, -1, 0.0, SCALE_FLOOR_M)
    if not type(va).__module__.startswith("dask"):
        return _combine(n, [_scan(np.asarray(va, dtype=np.float64), 0, (0, n - 1), n)])
    import dask

    chunks = list(va.chunks[0])
    if len(chunks) > 1 and chunks[-1] < SCALE_BLOCK // 2:  # the short tail joins its neighbour
        chunks[-2:] = [chunks[-2] + chunks[-1]]
        va = va.rechunk({0: tuple(chunks)})
    depth = DEPTH
    starts = np.concatenate(([0], np.cumsum(chunks))).astype(int)
    tasks = [dask.delayed(_scan)(va[max(lo - depth, 0):min(hi + depth, n)], max(lo - depth, 0),
                                 (int(lo), min(int(hi), n - 1)), n)
             for lo, hi in pairwise(starts.tolist())]
    return _combine(n, list(dask.compute(*tasks)))


def jump_words(j: VaJumps, *, t_s: float) -> str:
    """A failed check's advice: where, how large, against what noise, and the cause."""
    more = "" if j.count < 2 else f" ({j.count} jumps in all" + (
        ")" if j.first_index == j.index
        else f", the first between samples {j.first_index - 1} and {j.first_index})")
    unit, scale = ("µm", 1e6) if abs(j.step_m) >= 1e-6 else ("nm", 1e9)
    return (f"Va jumps by {j.step_m * scale:+.4g} {unit} between samples {j.index - 1} and "
            f"{j.index} (t = {t_s:.7g} s), {j.ratio:.0f} times the noise of its "
            f"sample-to-sample steps ({j.scale_m * 1e9:.2g} nm rms){more}: the interferometer "
            "lost count (fringe loss); this record's Va is not used: re-record it, or cut the "
            "record before the jump")


#: Typical rms of Va [m] by experiment, to name the unit of a Va that is not in metres:
#: the huddle tests' ~1 nm (twin 0.9–1.4 nm, seed 1.75 nm), the repeatability runs'
#: ~0.4 µm (twin 0.26–0.44 µm for the 1 V Newport motion), the other runs' ~1 µm.
_TYPICAL_VA_RMS_M: Final = {"data_huddle": 1e-9, "data_rep": 4e-7, "": 1e-6}
_VA_UNITS: Final = (("millimetres", 1e-3), ("micrometres", 1e-6), ("nanometres", 1e-9),
                    ("picometres", 1e-12))


def va_unit_hint(rms: float, experiment: str) -> str:
    """Advice for a Va whose rms [m] is too large: the unit that makes it this experiment's.

    Parameters
    ----------
    rms : float
        Rms of Va as recorded, read as metres.
    experiment : str
        Experiment name (``"data_rep_h"`` …): its typical rms decides the unit.
    """
    typical = next(v for k, v in _TYPICAL_VA_RMS_M.items() if experiment.startswith(k))
    if not (math.isfinite(rms) and rms > 0):
        return "Va is not a distance in metres"
    name, factor = min(_VA_UNITS, key=lambda u: abs(math.log10(rms * u[1] / typical)))
    # Unit prefixes are 1000× apart: within 1.5 decades of the typical value the nearest
    # prefix is the only one that fits; farther, no unit explains it.
    if abs(math.log10(rms * factor / typical)) > 1.5:
        return "Va is not a distance in metres"
    usual = f"~{typical * 1e9:g} nm" if typical < 1e-7 else f"~{typical * 1e6:g} µm"
    return (f"it looks like {name} (in metres its rms would be {rms * factor:.3g} m, this "
            f"experiment's usual {usual}): save Va in metres (Va = Va*{factor:g})")


def jump_check(ds: xr.Dataset, subject: str) -> Check:
    """The check ``va_continuous`` of a recording's ``Va`` (``subject``: ``"file: Va"``).

    Passed with the largest single-sample step [m] when :func:`find_jumps`
    finds no jump; failed with the largest jump's size, its sample, time and
    noise scale in the advice otherwise.
    """
    found = find_jumps(ds["Va"].data)
    limit = (f"≤ {found.limit_m:.3g} m ({found.threshold:.3g} × the robust noise scale of "
             f"Va's sample-to-sample steps, {found.scale_m * 1e9:.2g} nm)")
    if not found.count:
        return Check("va_continuous", True, abs(found.step_m), limit, subject, unit="m")
    t_s = float(np.asarray(ds["t"].data[found.index]))
    return Check("va_continuous", False, abs(found.step_m), limit, subject,
                 jump_words(found, t_s=t_s), unit="m")
