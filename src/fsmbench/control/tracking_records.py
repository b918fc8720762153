"""The tracking error read from the repeatability records (ESRF study 11.4), as the
closed-loop validation compares it: each record's residual about its mean period, its
Welch PSD, and the sampling scatter of its band power."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import xarray as xr
from numpy.typing import NDArray
from scipy.stats import t as student

from fsmbench.control.compare import without_mean_period
from fsmbench.signal.welch import hanning, pwelch

__all__ = ["BATCH_PERIODS", "SAMPLING_Z", "BandPowerScatter", "band_power_scatter",
           "period_residual", "sampling_z", "tracking_psd"]

FloatArray = NDArray[np.float64]

#: Periods per batch of :func:`band_power_scatter`: 2 s, five times the Sercalo's
#: amplitude correlation time (1/(ζω) = 0.43 s at 411 Hz, ζ = 0.0009).
BATCH_PERIODS = 2
#: The two-sided 95 % point of a normal law: with a std known exactly, the band above is
#: widened by this many of the log-ratio's sampling std (:func:`sampling_z`: Student's t
#: when the std is read from the records' periods).
SAMPLING_Z = 1.96


def period_residual(ds: xr.Dataset, name: str, *, fs_hz: float, period_s: float,
              settle_s: float) -> tuple[FloatArray, int]:
    """``(Vph, Vpv)`` less their mean period, (n, 2), and the number of periods."""
    t = np.asarray(ds["t"].values, dtype=float)
    keep = t >= t[0] + settle_s
    v = np.column_stack([np.asarray(ds[c].values, dtype=float)[keep] for c in ("Vph", "Vpv")])
    per = round(period_s * fs_hz)
    n = v.shape[0] // per
    if n < 3:
        # Fewer than 3 periods leave the repeatable part's estimate holding half the noise.
        raise ValueError(f"{name}: {v.shape[0] / fs_hz:.3g} s after the first {settle_s:g} s "
                         f"hold {n} whole periods of {period_s:g} s; the model validation "
                         "needs at least 3")
    return without_mean_period(v, per)


def tracking_psd(recordings: Mapping[str, xr.Dataset], names: list[str], *, gd: FloatArray,
                  fs_hz: float, period_s: float, settle_s: float
                  ) -> tuple[FloatArray, FloatArray, int]:
    """Welch grid, PSD of ``e`` (F, 2) averaged over the records, fewest whole periods."""
    window = hanning(round(period_s * fs_hz))
    psds = []
    periods = []
    f = np.zeros(0)
    for name in names:
        resid, n = period_residual(recordings[name], name, fs_hz=fs_hz, period_s=period_s,
                             settle_s=settle_s)
        periods.append(n)
        e = resid / gd[None, :]
        cols = [pwelch(e[:, i], window=window, fs_hz=fs_hz, nfft=window.size,
                       x_name=f"{name} {c}") for i, c in enumerate(("Vph", "Vpv"))]
        f = np.asarray(cols[0].f_hz, dtype=float)
        psds.append(np.column_stack([c.values for c in cols]))
    return f, np.mean(psds, axis=0), min(periods)


@dataclass(frozen=True)
class BandPowerScatter:
    """The sampling scatter of a band power Welch averaged over periods.

    Attributes
    ----------
    relative_variance : array (2,)
        Of the averaged band power, h and v [1].
    dof : float
        Degrees of freedom of the variance estimate: the batches less one, the fewest
        of the records'.
    """

    relative_variance: FloatArray
    dof: float


def sampling_z(*scatters: BandPowerScatter, axis: int) -> float:
    """The two-sided 95 % point for a log-ratio whose variance the scatters estimate.

    Student's t with the Welch–Satterthwaite degrees of freedom of the summed variance
    (each estimate's ``dof``): a std read from 8 periods is itself uncertain, and a
    normal point would cover ~85 %, not 95 %."""
    var = [float(s.relative_variance[axis]) for s in scatters]
    den = sum(v**2 / max(s.dof, 1.0) for v, s in zip(var, scatters, strict=True))
    dof = sum(var) ** 2 / den if den > 0 else math.inf
    return SAMPLING_Z if not math.isfinite(dof) else float(student.ppf(0.975, dof))


def band_power_scatter(recordings: Mapping[str, xr.Dataset], names: list[str], *,
                       gd: FloatArray, fs_hz: float, period_s: float, settle_s: float,
                       band_hz: tuple[float, float]) -> BandPowerScatter:
    """Relative variance of the band power :func:`tracking_psd` averages, per axis.

    Batch means: the record's whole periods in consecutive batches of
    ``BATCH_PERIODS``, Welch's band power on each; their scatter over the batches is
    the average's, with ``batches − 1`` degrees of freedom. A lightly damped resonance
    in a 1 s window is a few lines whose amplitude persists from one half-overlapping
    segment to the next, so its rms is known to ~1/√(batches) and no better. The
    records' averages are independent. On white noise the batches leave out the
    segments across their edges and read the whole average's variance up to 1.33×
    high (799 segments against 600 for 400 periods): a conservative error, where
    reading every segment as independent put a lightly damped mode's rms at two thirds
    of its spread (coverage 83 % for 95 % on 8 periods; ``tests/control``).
    """
    per = round(period_s * fs_hz)
    half = per // 2
    window = hanning(per)
    scale = 1.0 / (fs_hz * float(np.sum(window**2)))
    f = np.fft.rfftfreq(per, 1.0 / fs_hz)
    inside = (f >= band_hz[0]) & (f <= band_hz[1])
    rel = []
    dofs = []
    for name in names:
        resid, n = period_residual(recordings[name], name, fs_hz=fs_hz, period_s=period_s,
                             settle_s=settle_s)
        e = resid / gd[None, :]
        # Batch means: Welch's band power on consecutive pairs of periods (its own
        # half-overlapping segments inside each), the batches independent where one
        # segment's are not (they share samples, and a line narrower than a bin keeps
        # its amplitude from one to the next).
        batches = max(n // BATCH_PERIODS, 2)
        size = (n // batches) * per
        powers = []
        for b in range(batches):
            x = e[b * size:(b + 1) * size]
            starts = np.arange(0, x.shape[0] - per + 1, half)
            segs = np.stack([x[i:i + per] for i in starts])
            spec = np.abs(np.fft.rfft(segs * window[None, :, None], axis=1)) ** 2 * scale
            powers.append(spec[:, inside, :].sum(axis=1).mean(axis=0))
        p = np.asarray(powers)  # (batches, 2)
        mean = p.mean(axis=0)
        var_mean = p.var(axis=0, ddof=1) / batches
        rel.append(np.where(mean > 0, var_mean / np.maximum(mean, 1e-300) ** 2, 0.0))
        dofs.append(float(batches - 1))
    # The records' average: independent estimates, equal weights.
    return BandPowerScatter(np.asarray(np.sum(rel, axis=0) / len(rel) ** 2, dtype=float),
                            min(dofs))
