"""Weights of the Sercalo's rational fit: the seed's recipe or each line's inverse std.

The seed's (2.3e, Fig. 20): the coherence, 10 within ±10 % of each column's
resonance (:func:`detect_resonances`), 0 above 1 kHz (:func:`esrf_weights`),
divided by ``|H|`` so the fit minimises relative error; or ``1 / std(H)`` of
each line (:func:`variance_weights`), under which the fit's residuals have
unit variance.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import xarray as xr
from scipy.ndimage import median_filter

from fsmbench.ident.frf.response import FrequencyResponse

__all__ = ["detect_resonances", "esrf_weights", "fit_weights", "variance_weights"]


def detect_resonances(frf: FrequencyResponse, *, f_min_hz: float = 20.0,
                      f_max_hz: float = 1000.0) -> dict[str, float]:
    """Frequency [Hz] of the largest magnitude peak of each column's diagonal element.

    The seed's ``freqs_res_uh = 410``, ``freqs_res_uv = 250`` (read off Fig. 18).
    The peak is searched on the median of each line and its two neighbours, then
    taken at the largest ``|H|`` within one line of it: a resonance spans more than
    one line (a Welch window smears it over ~1.5 bins; a 0.1 %-damped mode at
    250 Hz keeps 70 % of its peak 0.25 Hz away), an isolated line is noise. In
    closed loop the h column's lines at the v resonance, where the v loop's gain
    hides the plant, carry standard deviations of 30-130 for a true value near 2:
    one of them above the h peak's ~380 put the h resonance at 251 Hz (a live
    record on the twin). Neither the line's own variance nor its confidence bound
    tells such a line from the peak (there the peak's lines are as uncertain).

    Parameters
    ----------
    frf : FrequencyResponse
        Column ``j``'s diagonal is output ``min(j, p-1)``.
    f_min_hz, f_max_hz : float
        The band searched [Hz].

    Returns
    -------
    dict input -> float
        The peak's frequency [Hz].
    """
    f = frf.frequency_hz
    band = np.flatnonzero((f >= f_min_hz) & (f <= f_max_hz))
    out = {}
    for j, inp in enumerate(frf.input_names):
        diag = frf.output_names[min(j, len(frf.output_names) - 1)]
        mag = np.abs(frf.frf.sel(output=diag, input=inp).values)[band]
        k = int(np.argmax(median_filter(mag, size=3, mode="nearest")))
        lo = max(0, k - 1)
        out[inp] = float(f[band][lo + int(np.argmax(mag[lo:k + 2]))])
    return out


def esrf_weights(frf: FrequencyResponse, *, resonances_hz: Mapping[str, float],
                 alpha: float = 0.1, boost: float = 10.0,
                 f_max_hz: float = 1000.0) -> xr.DataArray:
    """The seed's fit weights (2.3e, Fig. 20), dims ``(frequency, output, input)``.

    Coherence; ``boost`` where ``(1-alpha) f_r < f < (1+alpha) f_r`` for the
    column's resonance ``f_r``; 0 above ``f_max_hz``. The DC bin gets 0 too
    (a Welch estimate has no information there).
    """
    w = frf.coherence.copy(deep=True).fillna(0.0)
    f = frf.frequency_hz
    for inp, fr in resonances_hz.items():
        near = (f > (1 - alpha) * fr) & (f < (1 + alpha) * fr)
        w.loc[{"input": inp}] = xr.where(xr.DataArray(near, dims="frequency"), boost,
                                         w.sel(input=inp))
    w = w.where(xr.DataArray((f <= f_max_hz) & (f > 0), dims="frequency"), 0.0)
    return w


def variance_weights(frf: FrequencyResponse, *, f_max_hz: float = 1000.0) -> xr.DataArray:
    """Inverse standard deviation of each line, ``1 / std(H)``, dims (frequency, output, input).

    ``frf.frf_variance`` when the estimator gives it (periodic, LPM), else
    Bendat & Piersol's ``var(H) = 2 (random_error |H|)^2`` of a Welch
    estimate. As :func:`esrf_weights`: 0 at DC and above ``f_max_hz`` (the
    two-pole model is not meant for what lies above), and 0 where the
    variance is not finite and positive. Weighted so, the fit's residuals have
    unit variance (:mod:`fsmbench.ident.fit.parameter_std`).
    """
    if frf.frf_variance is not None:
        var = frf.frf_variance
    else:
        var = 2.0 * (frf.random_error * np.abs(frf.frf)) ** 2
    ok = np.isfinite(var) & (var > 0)
    w = xr.where(ok, 1.0 / np.sqrt(var.where(ok, 1.0)), 0.0)
    f = frf.frequency_hz
    return w.where(xr.DataArray((f <= f_max_hz) & (f > 0), dims="frequency"), 0.0)


def fit_weights(weights: xr.DataArray, h: np.ndarray, keep: np.ndarray, kind: str
                 ) -> np.ndarray:
    """Weights given to the vector fit: seed weights over ``|H|`` (relative error), or 1/std."""
    if kind == "variance":
        return np.asarray(weights.values[keep], dtype=float)
    mag = np.abs(h[keep])
    return np.asarray(weights.values[keep] / np.where(mag > 0, mag, np.inf), dtype=float)
