"""Two closed-loop measurements of the same plant on the same grid, merged line by line.

The closed-loop measurement (:mod:`fsmbench.tune.measure`) runs two stages: a
broadband one that locates the resonances, then one that puts the beam-error
budget on the few lines around them. Each stage is an independent estimate of
the same ``G`` on lines of the same grid (same period, same sampling rate).
Fitting only the second stage throws away the first's broadband lines (the
refined records starve the lines far from the modes: a stage-2 fit failed on
its coherence in 1 of 6 ``real_bench.toml`` runs) and half the measurement
time. :func:`merge_closed_loop_frf` keeps the union of the lines; on a line
both measured, the inverse-variance mean per element (its variance
``1 / sum(1 / var)``): the minimum-variance unbiased combination of
independent unbiased estimates. The variances are estimated, so the weights
scatter and the merged variance is understated a little: on simulated records
mean ``|z|^2`` 1.09 with the periodic estimator's 42 degrees of freedom per
line, 1.38 with 6 (``tests/ident/frf/test_closed_loop_stages.py``).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from fsmbench.ident.frf.closed_loop import ClosedLoopFrf
from fsmbench.ident.frf.estimate import FrfEstimate

__all__ = ["merge_closed_loop_frf"]


def _union(parts: Sequence[FrfEstimate]) -> tuple[NDArray[np.float64],
                                                  list[NDArray[np.intp]]]:
    """The union of the parts' lines [Hz] (F,) and each part's index into it."""
    grid = min(p.resolution_hz for p in parts)
    keys = [np.rint(p.frequency_hz / grid).astype(np.int64) for p in parts]
    union = np.unique(np.concatenate(keys))
    return (union * grid).astype(np.float64), [np.searchsorted(union, k) for k in keys]


def _merge(parts: Sequence[FrfEstimate], *, label: str) -> FrfEstimate:
    """Inverse-variance merge of estimates on one grid (element by element)."""
    first = parts[0]
    f, where = _union(parts)
    shape = (f.size, *first.frf.shape[1:])
    wsum = np.zeros(shape)
    gsum = np.zeros(shape, dtype=complex)
    noise = np.zeros(shape)
    seen = np.zeros(shape)
    input_psd = np.zeros((f.size, first.input_psd.shape[1]))
    for p, idx in zip(parts, where, strict=True):
        ok = np.isfinite(p.frf_variance) & (p.frf_variance > 0) & np.isfinite(p.frf)
        w = np.where(ok, 1.0 / np.where(ok, p.frf_variance, 1.0), 0.0)
        wsum[idx] += w
        gsum[idx] += w * np.where(ok, p.frf, 0.0)
        noise[idx] += np.where(ok, p.output_noise_psd, 0.0)
        seen[idx] += ok
        input_psd[idx] += p.input_psd
    with np.errstate(divide="ignore", invalid="ignore"):
        g = np.where(wsum > 0, gsum / wsum, np.nan + 0j)
        var = np.where(wsum > 0, 1.0 / wsum, np.inf)
        noise = np.where(seen > 0, noise / np.maximum(seen, 1), 0.0)
    blocks = float(np.mean([float(np.mean(p.options.get("periods_used", [1]))) for p in parts]))
    with np.errstate(divide="ignore", invalid="ignore"):
        snr = np.where(np.isfinite(var), np.abs(g) ** 2 / (blocks * var), 0.0)
    return FrfEstimate(
        frequency_hz=f, frf=g, frf_variance=var, output_noise_psd=noise,
        input_psd=input_psd, snr=np.where(np.isfinite(snr), snr, 0.0),
        input_names=first.input_names, output_names=first.output_names, fs_hz=first.fs_hz,
        resolution_hz=min(p.resolution_hz for p in parts), estimator=first.estimator,
        options={"merged": label, "parts": [dict(p.options) for p in parts]},
        dof=tuple(float(sum(d)) for d in zip(*(p.dof for p in parts), strict=True)),
        confidence=first.confidence)


def merge_closed_loop_frf(parts: Sequence[ClosedLoopFrf]) -> ClosedLoopFrf:
    """The union of the stages' lines, shared lines by their inverse-variance mean.

    Parameters
    ----------
    parts : sequence of ClosedLoopFrf
        Estimates of one plant from independent records, same estimator, sampling
        rate and grid (lines multiples of the finest resolution).

    Returns
    -------
    ClosedLoopFrf
        ``plant`` and ``direct`` merged; ``s_ur``, ``s_yr`` from the part with the
        smaller variance of ``G`` on each line (they depend on the loop, not on
        the excitation).

    Raises
    ------
    ValueError
        No part, or parts of different estimators, rates or channels.
    """
    items = list(parts)
    if not items:
        raise ValueError("nothing to merge: no closed-loop FRF given")
    first = items[0].plant
    for i, p in enumerate(items[1:], start=1):
        for attr in ("estimator", "fs_hz", "input_names", "output_names"):
            if getattr(p.plant, attr) != getattr(first, attr):
                raise ValueError(f"closed-loop FRF {i} has {attr} {getattr(p.plant, attr)!r}, "
                                 f"FRF 0 {getattr(first, attr)!r}: they cannot be merged")
        ratio = p.plant.resolution_hz / first.resolution_hz
        if abs(ratio - round(ratio)) > 1e-9 and abs(1 / ratio - round(1 / ratio)) > 1e-9:
            raise ValueError(f"closed-loop FRF {i} is on a {p.plant.resolution_hz:g} Hz grid, "
                             f"FRF 0 on {first.resolution_hz:g} Hz: not one grid")
    label = f"{len(items)} closed-loop measurements, lines merged by inverse variance"
    plant = _merge([p.plant for p in items], label=label)
    direct = _merge([p.direct for p in items], label=label)
    f, where = _union([p.plant for p in items])
    best = np.full(f.size, np.inf)
    s_ur = np.full((f.size, 2, 2), np.nan + 0j)
    s_yr = np.full((f.size, 2, 2), np.nan + 0j)
    for p, idx in zip(items, where, strict=True):
        total = np.sum(p.plant.frf_variance, axis=(1, 2))
        better = total < best[idx]
        s_ur[idx[better]] = p.s_ur[better]
        s_yr[idx[better]] = p.s_yr[better]
        best[idx[better]] = total[better]
    return ClosedLoopFrf(plant=plant, s_ur=s_ur, s_yr=s_yr, direct=direct,
                         method=f"{items[0].method}; {label}")
