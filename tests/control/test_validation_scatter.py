"""The model check's sampling scatter: each rms is an estimate from a finite record.

``band_power_scatter`` reads the relative variance of the Welch band power the model
check averages from the scatter of each period's band power. Checked against the
closed form for white noise (Parseval on a Hann window) and, for a lightly damped
resonance (the case that made short records fail a right model), by coverage: two
independent records of one process, their band powers computed by SciPy's Welch,
fall within ``SAMPLING_Z`` of the predicted log-ratio std as often as a normal law says.
"""

from __future__ import annotations

import numpy as np
import pytest
import xarray as xr
from scipy import signal

from fsmbench.control.validation import band_power_scatter, sampling_z

FS_HZ = 1000.0
PER = 1000  # one 1 s period
BAND_HZ = (2.0, 500.0)
GD = np.ones(2)


def _record(x: np.ndarray) -> dict[str, xr.Dataset]:
    t = np.arange(x.shape[0]) / FS_HZ
    return {"data_rep_h": xr.Dataset({"Vph": ("t", x[:, 0]), "Vpv": ("t", x[:, 1])},
                                     coords={"t": t})}


def _scatter(x: np.ndarray):
    return band_power_scatter(_record(x), ["data_rep_h"], gd=GD, fs_hz=FS_HZ, period_s=1.0,
                              settle_s=0.0, band_hz=BAND_HZ)


def test_white_noise_matches_the_hann_closed_form() -> None:
    # Summed over every line, a Hann periodogram of Gaussian white noise is Σ w² x² up to
    # a constant (Parseval): relative variance 2 Σw⁴ / (Σw²)² = 2 (35/128) / (3/8)² / N.
    # A batch of two periods holds three half-overlapping segments, which correlate by
    # ρ = 0.167 in power next to each other (Harris 1978, Table 1) and not beyond: the
    # batch's mean has (3 + 4ρ²)/9 of one segment's variance, the mean of B batches 1/B.
    n = 400
    x = np.random.default_rng(3).standard_normal((n * PER, 2))
    one = 2 * (35 / 128) / (3 / 8) ** 2 / PER
    expected = one * (3 + 4 * 0.167**2) / 9 / (n // 2)
    # 35 %: the variance is estimated from 200 batches (10 % std each axis, 3.5σ); the
    # band leaves out 0–2 Hz (0.4 % of the lines).
    np.testing.assert_allclose(_scatter(x).relative_variance, expected, rtol=0.35)


def _resonance(rng: np.random.Generator, n_samples: int) -> np.ndarray:
    # A 40 Hz mode with ζ = 0.01 driven by white noise: its correlation time (0.4 s)
    # under a period, the line a few bins wide, as the Sercalo's in a 1 s window.
    w0, zeta = 2 * np.pi * 40.0, 0.01
    b, a = signal.bilinear([w0**2], [1.0, 2 * zeta * w0, w0**2], fs=FS_HZ)
    e = rng.standard_normal((n_samples + 4000, 2))
    return np.asarray(signal.lfilter(b, a, e, axis=0)[4000:])


def _welch_band_power(x: np.ndarray) -> np.ndarray:
    f, p = signal.welch(x, fs=FS_HZ, window="hann", nperseg=PER, noverlap=PER // 2,
                        axis=0)
    inside = (f >= BAND_HZ[0]) & (f <= BAND_HZ[1])
    return np.asarray(p[inside].sum(axis=0))


@pytest.mark.parametrize("periods", [8, 40])
def test_the_widening_covers_two_records_of_one_process(periods: int) -> None:
    rng = np.random.default_rng(11)
    inside = []
    for _ in range(150):
        a, b = _resonance(rng, periods * PER), _resonance(rng, periods * PER)
        log_ratio = 0.5 * np.log(_welch_band_power(a) / _welch_band_power(b))
        sa, sb = _scatter(a), _scatter(b)
        for axis in (0, 1):
            std = 0.5 * np.sqrt(sa.relative_variance[axis] + sb.relative_variance[axis])
            inside.append(abs(log_ratio[axis]) <= sampling_z(sa, sb, axis=axis) * std)
    share = float(np.mean(inside))
    # 95 % expected; 300 draws give ±2.5 % (2σ) around it: 0.9 accepts that, while a std
    # half the true one would give ~67 % and a normal point on 8 periods' std ~86 %.
    assert 0.9 <= share <= 0.995, share
