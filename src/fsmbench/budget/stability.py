"""What a long record shows that a 100 s one cannot: drift and Allan deviation.

For each huddle test, over the whole record after the ESRF study's trim (any
length, out of core for records read lazily):

- the **Allan deviation** (overlapping, :func:`fsmbench.signal.allan.allan_deviation`)
  of the Attocube distance ``Va`` [m] and of the beam angle the 4QD reads,
  ``Vph/Gd``, ``Vpv/Gd`` [rad], with its slope regions (white, flicker,
  random walk, drift) in words;
- the **drift**: the mean of each signal over consecutive bins (hundreds to a
  few thousand bins over the record), with the min/max envelope the time
  plots draw instead of every sample — the 4QD's offset and the distance as
  they wander over hours.

The ESRF study (section 3) shows PSDs of 100 s records; these views sit next to them.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import xarray as xr
from numpy.typing import NDArray

from fsmbench.budget.long_record import (
    FULL_OVERLAP_MAX_TAU_S,
    STRIDE_S,
    LongRecordSummary,
    allan_factors,
    summarise_long_record,
)
from fsmbench.budget.signals import block_means, is_lazy, lowpass, trim_record
from fsmbench.signal.allan import AllanResult, allan_deviation
from fsmbench.signal.envelope import Envelope, minmax_envelope

__all__ = [
    "FULL_OVERLAP_MAX_TAU_S",
    "SignalDrift",
    "StabilityRecord",
    "allan_of",
    "analyse_stability",
    "stability_from_summary",
]

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
        ``Va``, ``Va_lowpass`` (50 Hz, the ESRF study's filter), ``Rh``, ``Rv``.
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
    return _drift_of(minmax_envelope(x, fs_hz=fs_hz, n_bins=n_bins), signal=signal, unit=unit,
                     fs_hz=fs_hz)


def allan_of(x: Any, *, fs_hz: float, unit: str, name: str) -> Any:
    """Overlapping Allan deviation of a record in memory; beyond 10 s from 0.1 s averages.

    Fully overlapping estimates at long averaging times read samples 2m
    apart, which out of core holds a large part of the record in memory. Past
    ``FULL_OVERLAP_MAX_TAU_S`` the averages start every ``STRIDE_S`` instead
    of every sample: the overlapping estimator on the 0.1 s means, exactly
    (``tests/budget/test_stability.py``). With hundreds of 0.1 s steps per
    averaging time, the loss of degrees of freedom is under a percent.
    """

    fine_m, stride = allan_factors(int(x.shape[0]), fs_hz)
    fine = allan_deviation(x, fs_hz=fs_hz, taus_s=fine_m / fs_hz, unit=unit, name=name)
    return _with_coarse(fine, block_means(x, per=stride), stride=stride, name=name)


def _with_coarse(fine: Any, means: FloatArray, *, stride: int, name: str) -> Any:
    """``fine`` extended with the averaging times of the ``stride``-sample ``means`` beyond it."""

    fs_hz, unit = fine.fs_hz, fine.unit
    coarse_m = 2 ** np.arange(1, 64)
    coarse_m = coarse_m[(coarse_m * stride > fine.m[-1]) & (2 * coarse_m * 2 <= means.size)]
    if coarse_m.size == 0:
        return fine
    coarse = allan_deviation(means, fs_hz=fs_hz / stride, taus_s=coarse_m * stride / fs_hz,
                             unit=unit, name=name)
    return AllanResult(tau_s=np.concatenate([fine.tau_s, coarse.tau_s]),
                       adev=np.concatenate([fine.adev, coarse.adev]),
                       n_terms=np.concatenate([fine.n_terms, coarse.n_terms]),
                       m=np.concatenate([fine.m, coarse.m * stride]), fs_hz=fs_hz,
                       n_samples=fine.n_samples, unit=unit,
                       kind=f"overlapping (averages every {STRIDE_S:g} s beyond "
                            f"{FULL_OVERLAP_MAX_TAU_S:g} s)")


def _scaled_allan(a: Any, *, gain: float, unit: str) -> Any:
    """The Allan deviation of ``x / gain`` from that of ``x``."""

    return AllanResult(tau_s=a.tau_s, adev=a.adev / abs(gain), n_terms=a.n_terms, m=a.m,
                       fs_hz=a.fs_hz, n_samples=a.n_samples, unit=unit, kind=a.kind)


def _drift_of(env: Envelope, *, signal: str, unit: str, fs_hz: float,
              gain: float = 1.0) -> SignalDrift:
    """A :class:`SignalDrift` from the envelope of ``x``, for ``x / gain``."""
    lo = np.asarray(env.minimum, dtype=float) / gain
    hi = np.asarray(env.maximum, dtype=float) / gain
    if gain < 0:
        lo, hi = hi, lo
    mean = np.asarray(env.mean, dtype=float) / gain
    counts = np.asarray(env.samples_per_bin, dtype=float)
    return SignalDrift(signal=signal, unit=unit, t_s=np.asarray(env.t_s, dtype=float),
                       mean=mean, minimum=lo, maximum=hi,
                       overall_mean=float(np.sum(mean * counts) / np.sum(counts)),
                       samples_per_bin=np.asarray(env.samples_per_bin, dtype=np.int64),
                       fs_hz=fs_hz)


def stability_from_summary(summary: LongRecordSummary, *,
                           qd_gain_v_per_rad: tuple[float, float]) -> StabilityRecord:
    """The stability view of a record reduced out of core (:mod:`fsmbench.budget.long_record`)."""
    fs, name = summary.fs_hz, summary.name
    _, stride = allan_factors(summary.n_samples, fs)
    gains = {"Va": 1.0, "Rh": qd_gain_v_per_rad[0], "Rv": qd_gain_v_per_rad[1]}
    source = {"Va": "Va", "Rh": "Vph", "Rv": "Vpv"}
    units = {"Va": "m", "Rh": "rad", "Rv": "rad"}
    allan = {}
    for key, sig in source.items():
        fine = _scaled_allan(summary.allan_fine[sig], gain=gains[key], unit=units[key])
        allan[key] = _with_coarse(fine, summary.stride_means[sig] / gains[key], stride=stride,
                                  name=f"{name}.{key}")
    drift = {key: _drift_of(summary.envelopes[sig], signal=key, unit=units[key], fs_hz=fs,
                            gain=gains[key]) for key, sig in source.items()}
    drift["Va_lowpass"] = _drift_of(summary.envelopes["Va_lowpass"], signal="Va_lowpass",
                                    unit="m", fs_hz=fs)
    order = ("Va", "Va_lowpass", "Rh", "Rv")
    return StabilityRecord(name=name, duration_s=summary.n_samples / fs, fs_hz=fs, allan=allan,
                           drift={k: drift[k] for k in order},
                           qd_gain_v_per_rad=qd_gain_v_per_rad, out_of_core=True)


def analyse_stability(ds: xr.Dataset, *, name: str, qd_gain_v_per_rad: tuple[float, float],
                      t0_s: float = 1.0, lpf_hz: float = 50.0, n_bins: int = DRIFT_BINS,
                      summary: LongRecordSummary | None = None) -> StabilityRecord:
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
        The ESRF study's trim: samples before ``t0_s`` [s] are left out.
    lpf_hz : float
        Corner of the ESRF study's low pass applied to ``Va`` [Hz].
    n_bins : int
        Bins of the drift curves.
    summary : LongRecordSummary, optional
        The record already reduced out of core; computed here (two reads) when
        ``ds`` holds Dask arrays and none is given.
    """
    if summary is None and is_lazy(ds["Va"].data):
        summary = summarise_long_record(ds, name=name, t0_s=t0_s, lpf_hz=lpf_hz, n_bins=n_bins)
    if summary is not None:
        return stability_from_summary(summary, qd_gain_v_per_rad=qd_gain_v_per_rad)
    fs = float(ds.attrs["fs_hz"])
    trim = trim_record(ds, t0_s=t0_s, duration_s=None, fs_hz=fs)
    if trim.n < 4:
        raise ValueError(f"{name}: {trim.n} samples after the trim; the stability analysis "
                         "needs at least 4")
    sl = slice(trim.start, trim.start + trim.n)
    va = ds["Va"].data[sl]
    angles = {"Rh": ds["Vph"].data[sl] / qd_gain_v_per_rad[0],
              "Rv": ds["Vpv"].data[sl] / qd_gain_v_per_rad[1]}
    signals: Mapping[str, tuple[Any, str]] = {
        "Va": (va, "m"),
        "Va_lowpass": (lowpass(va - va.mean(), cutoff_hz=lpf_hz, fs_hz=fs), "m"),
        **{k: (v, "rad") for k, v in angles.items()},
    }
    bins = min(n_bins, trim.n)
    drift = {key: _binned(x, signal=key, unit=unit, n_bins=bins, fs_hz=fs)
             for key, (x, unit) in signals.items()}
    allan = {key: allan_of(x, fs_hz=fs, unit=unit, name=f"{name}.{key}")
             for key, (x, unit) in signals.items() if key != "Va_lowpass"}
    return StabilityRecord(name=name, duration_s=trim.n / fs, fs_hz=fs, allan=allan,
                           drift=drift, qd_gain_v_per_rad=qd_gain_v_per_rad, out_of_core=False)
