"""What a long record shows that a 100 s one cannot: drift and Allan deviation.

For each huddle test, over the whole record after the seed's trim (any
length, out of core for records read lazily):

- the **Allan deviation** (overlapping, :func:`fsmbench.scale.allan.allan_deviation`)
  of the Attocube distance ``Va`` [m] and of the beam angle the 4QD reads,
  ``Vph/Gd``, ``Vpv/Gd`` [rad], with its slope regions (white, flicker,
  random walk, drift) in words;
- the **drift**: the mean of each signal over consecutive bins (hundreds to a
  few thousand bins over the record), with the min/max envelope the time
  plots draw instead of every sample — the 4QD's offset and the distance as
  they wander over hours.

The seed (section 3) shows PSDs of 100 s records; these views sit next to them.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import xarray as xr
from numpy.typing import NDArray

from fsmbench.budget.signals import block_means, compute, is_lazy, lowpass, trim_record

__all__ = ["SignalDrift", "StabilityRecord", "analyse_stability"]

FloatArray = NDArray[np.float64]

#: Bins of the drift and envelope curves: about two per pixel of a report panel.
DRIFT_BINS = 2000
#: Shortest bin of the drift: shorter means show the noise, not the drift [s].
DRIFT_MIN_BIN_S = 1.0


@dataclass(frozen=True, eq=False)
class SignalDrift:
    """One signal over the record, binned.

    Attributes
    ----------
    signal : str
        ``Va``, ``Rh``, ``Rv`` or ``Va_lowpass``.
    unit : str
        ``m`` or ``rad``.
    t_s : ndarray (B,)
        Bin centres, time since the trim [s].
    mean, minimum, maximum : ndarray (B,)
        Per bin, in ``unit`` (not mean-removed: offsets are the point).
    overall_mean : float
        Mean of every sample [unit].
    samples_per_bin : ndarray of int (B,)
    fs_hz : float
    """

    signal: str
    unit: str
    t_s: FloatArray
    mean: FloatArray
    minimum: FloatArray
    maximum: FloatArray
    overall_mean: float
    samples_per_bin: NDArray[np.int64]
    fs_hz: float

    def means(self, *, min_bin_s: float = DRIFT_MIN_BIN_S) -> tuple[FloatArray, FloatArray]:
        """(time [s], mean [unit]) over bins at least ``min_bin_s`` long.

        Consecutive bins are merged (sample-weighted) until each is that long,
        so that the means follow the drift, not the noise of short bins.
        """
        counts = self.samples_per_bin.astype(float)
        if counts.size == 0:
            return np.zeros(0), np.zeros(0)
        per = max(1, math.ceil(min_bin_s * self.fs_hz / float(counts.min())))
        groups = np.arange(counts.size) // per
        weight = np.bincount(groups, weights=counts)
        mean = np.bincount(groups, weights=self.mean * counts) / weight
        t = np.bincount(groups, weights=self.t_s * counts) / weight
        return t, mean

    @property
    def peak_to_peak(self) -> float:
        """Range of the means over bins of at least 1 s [unit]: the drift over the record."""
        _, mean = self.means()
        return float(np.max(mean) - np.min(mean)) if mean.size else 0.0


@dataclass(frozen=True, eq=False)
class StabilityRecord:
    """Drift and Allan deviation of one huddle test.

    Attributes
    ----------
    name : str
    duration_s : float
        Analysed length [s].
    fs_hz : float
    allan : dict of str to AllanResult
        ``Va`` [m], ``Rh``, ``Rv`` [rad].
    drift : dict of str to SignalDrift
        ``Va``, ``Va_lowpass`` (50 Hz, the seed's filter), ``Rh``, ``Rv``.
    qd_gain_v_per_rad : (float, float)
        The gains the angles were computed with [V/rad].
    out_of_core : bool
        The record was analysed from Dask chunks.
    """

    name: str
    duration_s: float
    fs_hz: float
    allan: dict[str, Any] = field(repr=False)
    drift: dict[str, SignalDrift] = field(repr=False)
    qd_gain_v_per_rad: tuple[float, float] = (1.0, 1.0)
    out_of_core: bool = False

    def to_json(self) -> dict[str, object]:
        """Scalars, the Allan curves and their regions (the drift curves stay for the figures)."""
        return {
            "name": self.name, "duration_s": self.duration_s, "fs_hz": self.fs_hz,
            "out_of_core": self.out_of_core,
            # Means over bins of at least 1 s: the drift, not the noise of short bins.
            "drift_peak_to_peak": {k: d.peak_to_peak for k, d in self.drift.items()},
            "allan": {k: {"unit": a.unit, "tau_s": a.tau_s.tolist(), "adev": a.adev.tolist(),
                          "regions": [{"noise": r.noise, "slope": r.slope,
                                       "tau_start_s": r.tau_start_s, "tau_stop_s": r.tau_stop_s,
                                       "level_at_1s": r.level_at_1s, "text": r.describe()}
                                      for r in a.regions()]}
                      for k, a in self.allan.items()},
        }


def _binned(x: Any, *, signal: str, unit: str, n_bins: int, fs_hz: float) -> SignalDrift:
    from fsmbench.scale.envelope import minmax_envelope

    env = minmax_envelope(x, fs_hz=fs_hz, n_bins=n_bins)
    mean = np.asarray(env.mean, dtype=float)
    counts = np.asarray(env.samples_per_bin, dtype=float)
    return SignalDrift(signal=signal, unit=unit, t_s=np.asarray(env.t_s, dtype=float),
                       mean=mean, minimum=np.asarray(env.minimum, dtype=float),
                       maximum=np.asarray(env.maximum, dtype=float),
                       overall_mean=float(np.sum(mean * counts) / np.sum(counts)),
                       samples_per_bin=np.asarray(env.samples_per_bin, dtype=np.int64),
                       fs_hz=fs_hz)


#: Averaging times up to this use averages starting at every sample [s]; longer ones use
#: averages starting every :data:`STRIDE_S` (see :func:`_allan`).
FULL_OVERLAP_MAX_TAU_S = 10.0
STRIDE_S = 0.1


def _allan_streamed(x: Any, *, fs_hz: float, factors: NDArray[np.int64], unit: str,
                    name: str, block: int = 1 << 20) -> Any:
    """Overlapping Allan deviation of a Dask record, read once, block after block.

    The formula of :mod:`fsmbench.scale.allan`. Each block is appended to the
    samples still needed (the last ``2 m_max`` or so), the m-sums come from a
    cumulative sum of that segment (``x - x[0]``), and every position is
    counted once, when all the samples it needs are in. Memory: one block plus
    ``2 m_max`` samples, whatever the record's length (a graph over all the
    averaging times at once makes Dask keep chunks until the last of them
    is done, which for a day is the whole record).
    """
    from fsmbench.scale.allan import AllanResult

    n = int(x.shape[0])
    m_all = np.asarray(factors, dtype=np.int64)
    x0 = float(x[0].compute())
    sums = np.zeros(m_all.size)
    done = np.zeros(m_all.size, dtype=np.int64)  # next position to count, per m
    last = n - 2 * m_all  # last position, per m
    buf = np.zeros(0)
    pos = 0  # global index of buf[0]
    for part in x.rechunk(block).to_delayed().ravel():
        chunk = np.asarray(part.compute(), dtype=np.float64)
        if not np.all(np.isfinite(chunk)):
            raise ValueError(f"{name} contains NaN or infinite samples; remove or interpolate "
                             "them before the Allan deviation")
        buf = np.concatenate([buf, chunk - x0])
        c = np.concatenate([[0.0], np.cumsum(buf)])
        for i, m in enumerate(int(v) for v in m_all):
            stop = min(last[i], pos + buf.size - 2 * m)  # last position whose samples are in
            if stop < done[i]:
                continue
            k = np.arange(done[i] - pos, stop - pos + 1)
            d = (c[k + 2 * m] - c[k + m]) - (c[k + m] - c[k])
            sums[i] += math.fsum(d * d)
            done[i] = stop + 1
        keep = int(min(done.min(), n)) - pos
        buf = buf[keep:]
        pos += keep
    n_terms = n - 2 * m_all + 1
    avar = sums / (2.0 * m_all.astype(np.float64) ** 2 * n_terms)
    return AllanResult(tau_s=m_all / fs_hz, adev=np.sqrt(avar), n_terms=n_terms, m=m_all,
                       fs_hz=fs_hz, n_samples=n, unit=unit)


def _allan(x: Any, *, fs_hz: float, unit: str, name: str) -> Any:
    """Overlapping Allan deviation; beyond 10 s from averages starting every 0.1 s.

    Fully overlapping estimates at long averaging times read samples 2m
    apart, which out of core holds a large part of the record in memory. Past
    ``FULL_OVERLAP_MAX_TAU_S`` the averages start every ``STRIDE_S`` instead
    of every sample: the overlapping estimator on the 0.1 s means, exactly
    (``tests/budget/test_stability.py``). With hundreds of 0.1 s steps per
    averaging time, the loss of degrees of freedom is under a percent.
    """
    from fsmbench.scale.allan import AllanResult, allan_deviation

    n = int(x.shape[0])
    stride = max(1, round(STRIDE_S * fs_hz))
    m_full = max(1, min(n // 4, round(FULL_OVERLAP_MAX_TAU_S * fs_hz)))
    fine_m = 2 ** np.arange(int(np.floor(np.log2(m_full))) + 1)
    if is_lazy(x):
        fine = _allan_streamed(x, fs_hz=fs_hz, factors=fine_m, unit=unit, name=name)
    else:
        fine = allan_deviation(x, fs_hz=fs_hz, taus_s=fine_m / fs_hz, unit=unit, name=name)
    means = block_means(x, per=stride)
    coarse_m = 2 ** np.arange(1, 64)
    coarse_m = coarse_m[(coarse_m * stride > fine_m[-1]) & (2 * coarse_m * 2 <= means.size)]
    if coarse_m.size == 0:
        return fine
    coarse = allan_deviation(means, fs_hz=fs_hz / stride, taus_s=coarse_m * stride / fs_hz,
                             unit=unit, name=name)
    return AllanResult(tau_s=np.concatenate([fine.tau_s, coarse.tau_s]),
                       adev=np.concatenate([fine.adev, coarse.adev]),
                       n_terms=np.concatenate([fine.n_terms, coarse.n_terms]),
                       m=np.concatenate([fine.m, coarse.m * stride]), fs_hz=fs_hz,
                       n_samples=n, unit=unit,
                       kind=f"overlapping (averages every {STRIDE_S:g} s beyond "
                            f"{FULL_OVERLAP_MAX_TAU_S:g} s)")


def analyse_stability(ds: xr.Dataset, *, name: str, qd_gain_v_per_rad: tuple[float, float],
                      t0_s: float = 1.0, lpf_hz: float = 50.0,
                      n_bins: int = DRIFT_BINS) -> StabilityRecord:
    """Drift and Allan deviation of ``Va`` and the 4QD angle over one whole record.

    Parameters
    ----------
    ds : xarray.Dataset
        ``Vph``, ``Vpv`` [V], ``Va`` [m] on ``t`` [s]; numpy or Dask arrays.
    name : str
        Experiment name (for messages).
    qd_gain_v_per_rad : (float, float)
        Calibrated 4QD gains (h, v) [V/rad]: the angle is the reading over the gain.
    t0_s : float
        The seed's trim: samples before ``t0_s`` [s] are left out.
    lpf_hz : float
        Corner of the seed's low pass applied to ``Va`` [Hz].
    n_bins : int
        Bins of the drift curves.
    """
    fs = float(ds.attrs["fs_hz"])
    trim = trim_record(ds, t0_s=t0_s, duration_s=None, fs_hz=fs)
    if trim.n < 4:
        raise ValueError(f"{name}: {trim.n} samples after the trim; the stability analysis "
                         "needs at least 4")
    sl = slice(trim.start, trim.start + trim.n)
    va = ds["Va"].data[sl]
    angles = {"Rh": ds["Vph"].data[sl] / qd_gain_v_per_rad[0],
              "Rv": ds["Vpv"].data[sl] / qd_gain_v_per_rad[1]}
    lazy = is_lazy(va)
    signals: Mapping[str, tuple[Any, str]] = {
        "Va": (va, "m"),
        "Va_lowpass": (lowpass(va - compute(va.mean())[0], cutoff_hz=lpf_hz, fs_hz=fs), "m"),
        **{k: (v, "rad") for k, v in angles.items()},
    }
    bins = min(n_bins, trim.n)
    drift = {key: _binned(x, signal=key, unit=unit, n_bins=bins, fs_hz=fs)
             for key, (x, unit) in signals.items()}
    allan = {key: _allan(x, fs_hz=fs, unit=unit, name=f"{name}.{key}")
             for key, (x, unit) in signals.items() if key != "Va_lowpass"}
    return StabilityRecord(name=name, duration_s=trim.n / fs, fs_hz=fs, allan=allan,
                           drift=drift, qd_gain_v_per_rad=qd_gain_v_per_rad, out_of_core=lazy)
