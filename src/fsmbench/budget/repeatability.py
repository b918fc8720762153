"""Non-repeatability of the measured distance (seed 11).

Alignment (11.1): the record starts ``align_s`` (1 s) after the first
non-zero Newport command (``Unh`` for ``data_rep_h``, ``Unv`` for
``data_rep_v``) and keeps whole periods only. In MATLAB's 1-based indices the
seed keeps ``i0 … iend−1`` with ``i0 = find(Un ~= 0, 1) + fs`` and
``iend = i0 + fs·floor((N − i0)/fs)``; here that is ``s0 = first + fs``
(0-based) and ``floor((N − s0 − 1)/P)`` periods of ``P = period·fs`` samples.

Repeatable part (11.4): the mean over periods at each position in the
period (``mean(reshape(Va, [fs n]), 2)``); non-repeatable part: the rest.
Its rms is the seed's number (19.6 nm h, 13.9 nm v). That estimate is biased
low by ``√((n−1)/n)`` for noise that is independent between periods (the mean
was taken from the same periods); ``nonrep_rms_unbiased_m`` corrects it.
11.6 repeats it after a 10 Hz first-order low pass (``lsim``, zero initial
state; :func:`~fsmbench.budget.spectra.first_order_lowpass`). The filter's
start-up transient (τ = 16 ms) on a signal that moves by ~1 µm per period
lands in the first period only, so it is *non-repeatable by construction*
and can make the filtered rms exceed the unfiltered one (the seed's 22.9 nm
against 19.6 nm, horizontal). ``nonrep_rms_lpf_settled_m`` drops the first
period after filtering (mean over the remaining periods).

Tracking error (11.3): the beam angle measured by the 4QD, ``R = Vp/Gd(0)``,
its PSD, and its distance-error equivalent. The seed's law is
``ΔL = L·α²/2`` with L = 0.1 m per axis; the traced law is ``Σ cᵢ αᵢ²``
with ``c = (6H + 4L)/16`` m/rad² (errata E15, E17). ``R`` includes the 4QD's
own noise, so this equivalent is an upper bound of the true geometric term.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np
import xarray as xr
from numpy.typing import NDArray

from fsmbench.bench.blocks import rotation
from fsmbench.bench.params import BenchParams
from fsmbench.budget.propagation import distance_coefficients
from fsmbench.budget.spectra import first_order_lowpass, seed_welch
from fsmbench.jsonutil import hv

__all__ = [
    "SEED_11",
    "AlignedRecord",
    "RepeatabilityRecord",
    "align_periods",
    "analyse_repeatability",
    "command_channel",
]

FloatArray = NDArray[np.float64]

#: Seed 11.4 and 11.7: rms of the non-repeatable part [m], and its 11.3 law length [m].
SEED_11: dict[str, float] = {"h_nonrep_rms_m": 19.6e-9, "v_nonrep_rms_m": 13.9e-9,
                             "h_nonrep_rms_lpf_m": 22.9e-9, "v_nonrep_rms_lpf_m": 13.9e-9,
                             "law_length_m": 0.1}
_CHANNEL = {"data_rep_h": "Unh", "data_rep_v": "Unv"}
_SIGNALS = ("Unh", "Unv", "Vph", "Vpv", "Va")


def command_channel(name: str, ds: xr.Dataset) -> str:
    """``Unh`` for ``data_rep_h``, ``Unv`` for ``data_rep_v``; else the command that moves first."""
    if name in _CHANNEL:
        return _CHANNEL[name]
    firsts = {c: np.flatnonzero(np.asarray(ds[c].values) != 0) for c in ("Unh", "Unv") if c in ds}
    moving = {c: int(i[0]) for c, i in firsts.items() if i.size}
    if not moving:
        raise ValueError(f"{name}: no Newport command (Unh, Unv are zero or absent); the "
                         f"repeatability analysis aligns on the first command (seed 11.1)")
    return min(moving, key=lambda c: moving[c])


@dataclass(frozen=True)
class AlignedRecord:
    """The record cut as the seed's 11.1: signals of shape (N,) from ``start`` on."""

    name: str
    channel: str
    fs_hz: float
    first_command_index: int
    start_index: int
    period_samples: int
    n_periods: int
    signals: dict[str, FloatArray]


def align_periods(ds: xr.Dataset, *, name: str | None = None, align_s: float = 1.0,
                  period_s: float = 1.0) -> AlignedRecord:
    """Seed 11.1: start ``align_s`` after the first Newport command, keep whole periods.

    Raises
    ------
    ValueError
        Naming the experiment: a signal is missing, the command never moves,
        or fewer than two whole periods remain.
    """
    name = str(ds.attrs.get("experiment", "")) if name is None else name
    missing = [s for s in _SIGNALS if s not in ds]
    if missing:
        raise ValueError(f"{name}: missing {missing} (seed 11.1 loads t, Uch, Ucv, Unh, Unv, "
                         f"Vph, Vpv, Vnh, Vnv, Va)")
    fs = float(ds.attrs["fs_hz"])
    channel = command_channel(name, ds)
    nz = np.flatnonzero(np.asarray(ds[channel].values) != 0)
    if nz.size == 0:
        raise ValueError(f"{name}: the Newport command {channel} is zero throughout; the "
                         f"repeatability analysis aligns on its first non-zero sample (seed 11.1)")
    per = round(period_s * fs)
    n = ds.sizes["t"]
    first = int(nz[0])
    start = first + round(align_s * fs)
    n_periods = max(0, (n - start - 1) // per)
    if n_periods < 2:
        raise ValueError(f"{name}: {n_periods} whole period(s) of {period_s:g} s after "
                         f"{channel}'s first command + {align_s:g} s "
                         f"({(n - start) / fs:.3g} s left); at least two are needed")
    stop = start + n_periods * per
    sig = {s: np.asarray(ds[s].values, dtype=float)[start:stop] for s in _SIGNALS}
    return AlignedRecord(name=name, channel=channel, fs_hz=fs, first_command_index=first,
                         start_index=start, period_samples=per, n_periods=n_periods, signals=sig)


@dataclass(frozen=True)
class RepeatabilityRecord:
    """Seed 11.3–11.7 on one record (SI units).

    Arrays: ``va_periods_m``, ``va_lpf_periods_m``, ``command_periods_v``,
    ``tracking_distance_periods_m`` of shape (n_periods, P); ``repeatable_m``,
    ``repeatable_lpf_m`` (P,); spectra on ``f_hz`` (F,): ``psd_tracking_rad2_per_hz``
    (F, 2), ``psd_distance_m2_per_hz`` (F,) (traced law, both axes),
    ``psd_distance_seed_m2_per_hz`` (F, 2) (seed's ``L α²/2`` per axis),
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
    va_periods_m: FloatArray
    va_lpf_periods_m: FloatArray
    command_periods_v: FloatArray
    tracking_distance_periods_m: FloatArray
    repeatable_m: FloatArray
    repeatable_lpf_m: FloatArray
    f_hz: FloatArray
    psd_tracking_rad2_per_hz: FloatArray
    psd_distance_m2_per_hz: FloatArray
    psd_distance_seed_m2_per_hz: FloatArray
    psd_va_m2_per_hz: FloatArray

    def to_json(self) -> dict[str, object]:
        """Scalars, (h, v) pairs as ``{"h", "v"}``; the seed's numbers for this direction
        under ``seed``."""
        out: dict[str, object] = {}
        for f in fields(self):
            v = getattr(self, f.name)
            if isinstance(v, np.ndarray):
                continue
            out[f.name] = hv(v) if isinstance(v, tuple) else v  # every tuple field is (h, v)
        out["seed"] = {k[2:]: v for k, v in SEED_11.items() if k.startswith(f"{self.direction}_")}
        return out


def _nonrep(periods: FloatArray) -> tuple[FloatArray, float]:
    rep = periods.mean(axis=0)
    return rep, float(np.sqrt(np.mean((periods - rep) ** 2)))


def analyse_repeatability(ds: xr.Dataset, *, params: BenchParams, name: str | None = None,
                          align_s: float = 1.0, period_s: float = 1.0,
                          lpf_hz: float = 10.0) -> RepeatabilityRecord:
    """Seed 11 on one record (``data_rep_h`` or ``data_rep_v``).

    Parameters
    ----------
    ds : xarray.Dataset
        Record with ``Unh, Unv, Vph, Vpv, Va`` on ``t``, attribute ``fs_hz``.
    params : BenchParams
        4QD gains (``R = Vp/Gd``), geometry and beam factors (the distance law).
    name : str, optional
        Experiment name (default: the dataset's ``experiment`` attribute).
    align_s, period_s : float
        Delay after the first command and period [s] (seed: 1 s, 1 s).
    lpf_hz : float
        Corner of the low pass of 11.6 [Hz].

    Raises
    ------
    ValueError
        As :func:`align_periods`.
    """
    rec = align_periods(ds, name=name, align_s=align_s, period_s=period_s)
    fs, n, per = rec.fs_hz, rec.n_periods, rec.period_samples
    sig = rec.signals
    va = sig["Va"]
    vaf = first_order_lowpass(va, cutoff_hz=lpf_hz, fs_hz=fs)
    va_p, vaf_p = va.reshape(n, per), vaf.reshape(n, per)
    rep, nonrep = _nonrep(va_p)
    rep_f, nonrep_f = _nonrep(vaf_p)
    nonrep_settled = _nonrep(vaf_p[1:])[1] if n >= 3 else None
    gd = params.quad_diode.gain_v_per_rad.as_array()
    r = np.stack([sig["Vph"] / gd[0], sig["Vpv"] / gd[1]])  # (2, N) measured beam angle [rad]
    alpha = rotation(params.quad_diode.rotation_rad).T @ r  # table frame
    c = np.asarray(distance_coefficients(params))
    dist = c @ alpha**2
    law = SEED_11["law_length_m"]
    seed_dist = 0.5 * law * r**2
    dist_p = dist.reshape(n, per)
    _, dist_nonrep = _nonrep(dist_p)
    spectra = [seed_welch(x, fs_hz=fs, name=f"{rec.name}.{lab}") for x, lab in
               ((r[0], "Rh"), (r[1], "Rv"), (dist, "dL"), (seed_dist[0], "dLh_seed"),
                (seed_dist[1], "dLv_seed"), (va - va.mean(), "Va"))]
    direction = {"Unh": "h", "Unv": "v"}[rec.channel]
    return RepeatabilityRecord(
        name=rec.name, direction=direction, channel=rec.channel, fs_hz=fs,
        period_s=per / fs, n_periods=n, start_s=rec.start_index / fs,
        nonrep_rms_m=nonrep, nonrep_rms_unbiased_m=nonrep * math.sqrt(n / (n - 1)),
        nonrep_rms_lpf_m=nonrep_f, nonrep_rms_lpf_settled_m=nonrep_settled,
        repeatable_ptp_m=float(np.ptp(rep)),
        tracking_rms_rad=(float(np.sqrt(np.mean(r[0] ** 2))), float(np.sqrt(np.mean(r[1] ** 2)))),
        tracking_distance_mean_m=float(dist.mean()), tracking_distance_std_m=float(dist.std()),
        tracking_distance_nonrep_rms_m=dist_nonrep,
        seed_law_distance_std_m=(float(seed_dist[0].std()), float(seed_dist[1].std())),
        va_periods_m=va_p, va_lpf_periods_m=vaf_p,
        command_periods_v=sig[rec.channel].reshape(n, per), tracking_distance_periods_m=dist_p,
        repeatable_m=rep, repeatable_lpf_m=rep_f, f_hz=np.asarray(spectra[0].f_hz),
        psd_tracking_rad2_per_hz=np.stack([np.asarray(spectra[0].values, dtype=float),
                                           np.asarray(spectra[1].values, dtype=float)], axis=1),
        psd_distance_m2_per_hz=np.asarray(spectra[2].values, dtype=float),
        psd_distance_seed_m2_per_hz=np.stack([np.asarray(spectra[3].values, dtype=float),
                                              np.asarray(spectra[4].values, dtype=float)],
                                             axis=1),
        psd_va_m2_per_hz=np.asarray(spectra[5].values, dtype=float))
