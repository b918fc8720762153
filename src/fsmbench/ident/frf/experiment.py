"""FRF matrices ``inputs → (Vph, Vpv)`` from the study's single-input experiments.

One column per experiment (``data_uch`` → ``Uch``, ``data_unh`` → ``Unh`` …),
each record trimmed and its means removed, then Welch's H1 (the seed's), the
local polynomial method or periodic averaging (:func:`experiment_frf`), with
the "auto" rule that picks periodic averaging when every input repeats
(:func:`choose_estimator`). Moved out of :mod:`fsmbench.ident.sercalo`: the
Newport's, the closed loop's and the compression's code read it too.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from typing import Literal, NamedTuple

import numpy as np
import xarray as xr
from numpy.typing import NDArray

from fsmbench.ident.calibration import require_signals, trim_recording
from fsmbench.ident.frf.estimate import FrfEstimate, combine_estimates
from fsmbench.ident.frf.lpm import LPM_NOISE_SMOOTHING, LpmOptions, local_polynomial_frf
from fsmbench.ident.frf.periodic import PeriodicOptions, detect_period, periodic_frf
from fsmbench.ident.frf.response import FrequencyResponse, combine_columns, spectral_matrix
from fsmbench.signal.welch import hanning

__all__ = ["OUTPUTS", "FrfEstimator", "choose_estimator", "experiment_frf"]

FrfEstimator = Literal["auto", "welch", "lpm", "periodic"]

OUTPUTS = ("Vph", "Vpv")


def choose_estimator(recordings: Mapping[str, xr.Dataset], *,
                     columns: Sequence[tuple[str, str]], trims_s: Mapping[str, float]) -> str:
    """The "auto" rule: ``"periodic"`` when every column's input repeats, else ``"welch"``.

    A record is periodic when its input correlates with itself shifted by one
    period above 0.9 (:func:`fsmbench.ident.frf.periodic.detect_period`: one
    FFT per record), with at least three whole periods (one dropped as the
    transient, two for the noise estimate). Non-periodic (noise) excitation
    keeps Welch's H1, the seed's estimator, so seed-style recordings give
    today's results; ask for ``"lpm"`` explicitly for the LPM.
    """
    for experiment, signal in columns:
        if experiment not in recordings or signal not in recordings[experiment]:
            return "welch"  # experiment_frf reports what is missing
        ds = trim_recording(recordings[experiment], t0_s=trims_s.get(experiment, 0.0))
        u = np.asarray(ds[signal].values, dtype=float)
        period = detect_period(u)
        if period is None or u.size // period < 3:
            return "welch"
    return "periodic"


def experiment_frf(recordings: Mapping[str, xr.Dataset], *, columns: Sequence[tuple[str, str]],
                   trims_s: Mapping[str, float], window_s: float = 1.0,
                   estimator: FrfEstimator = "welch",
                   transient_periods: Mapping[str, int] | None = None) -> FrequencyResponse:
    """FRF matrix ``inputs → (Vph, Vpv)`` from single-input experiments.

    Parameters
    ----------
    recordings : mapping of experiment name to Dataset
    columns : sequence of (experiment, input signal)
        E.g. ``[("data_uch", "Uch"), ("data_ucv", "Ucv")]``, one column each.
    trims_s : mapping of experiment name to seconds
        Start of each record removed first (the seed's ``t0``).
    window_s : float
        Hann window length [s] (seed: 1 s), Welch only.
    estimator : {"welch", "lpm", "periodic", "auto"}
        Welch H1 (the seed's); the local polynomial method on each whole
        record (every experiment cut to the shortest one's length, kept from
        its end, so that all columns share their lines; lines strided by the
        window width, 13, so that they are nearly independent); periodic
        averaging (the transient periods detected in the data, at least the
        excitation's own; the excited lines; the distortion of an odd grid
        from its non-excited lines); or :func:`choose_estimator`.
    transient_periods : mapping of experiment name to int, optional
        The excitation's own transient periods (``excitation.json``): the
        fewest the periodic average drops (default 1).

    Returns
    -------
    FrequencyResponse
        ``estimator`` says which; ``frf_variance`` set for LPM and periodic.

    Notes
    -----
    Each record's means (after trimming) are removed first: a beam off the 4QD's
    centre reads volts of mean, which Welch's window leaks onto the lines of a
    response of millivolts; a constant changes only the 0 Hz line otherwise.
    """
    if estimator == "auto":
        estimator = "periodic" if choose_estimator(
            recordings, columns=columns, trims_s=trims_s) == "periodic" else "welch"
    if estimator not in ("welch", "lpm", "periodic"):
        raise ValueError(f"estimator must be auto, welch, lpm or periodic, got {estimator!r}")
    data = _column_records(recordings, columns=columns, trims_s=trims_s)
    if estimator == "welch":
        return combine_columns([spectral_matrix(
            u, y, input_names=[signal], output_names=list(OUTPUTS),
            window=hanning(int(np.ceil(window_s * fs))), fs_hz=fs)
            for _, signal, fs, u, y in data])
    parts = (_lpm_estimates(data) if estimator == "lpm"
             else _periodic_estimates(data, transient_periods=transient_periods))
    return combine_estimates(parts).to_frequency_response()


class _ColumnRecord(NamedTuple):
    """One column's record: its input ``u`` (L,) and the outputs ``y`` (L, 2) [V], trimmed
    and their means removed, sampled at ``fs_hz`` [Hz]."""

    experiment: str
    signal: str
    fs_hz: float
    u: NDArray[np.float64]
    y: NDArray[np.float64]


def _column_records(recordings: Mapping[str, xr.Dataset], *,
                    columns: Sequence[tuple[str, str]],
                    trims_s: Mapping[str, float]) -> list[_ColumnRecord]:
    """Each column's record, trimmed, its means removed (:func:`experiment_frf`'s Notes).

    Raises
    ------
    ValueError
        An experiment or one of its signals missing.
    """
    data = []
    for experiment, signal in columns:
        if experiment not in recordings:
            raise ValueError(f"{experiment} is needed for the {signal} column and is missing")
        require_signals(recordings[experiment], (signal, *OUTPUTS),
                        purpose=f"the {signal} column of the FRF matrix")
        ds = trim_recording(recordings[experiment], t0_s=trims_s.get(experiment, 0.0))
        u = np.asarray(ds[signal].values, dtype=float)  # means removed (Notes)
        y = np.column_stack([ds[o].values for o in OUTPUTS]).astype(float)
        data.append(_ColumnRecord(experiment, signal, float(ds.attrs["fs_hz"]), u - u.mean(),
                                  y - y.mean(axis=0)))
    return data


def _lpm_estimates(data: Sequence[_ColumnRecord]) -> list[FrfEstimate]:
    """The LPM on each column's record, all cut to the shortest one (kept from its end)."""
    length = min(u.size for *_, u, _y in data)
    # The noise variance smoothed over 7 estimated lines (LpmOptions.noise_smoothing):
    # one line's 7 dof made the weighted fits' stds optimistic (in95 0.75-0.85).
    opts = LpmOptions(stride=2 * LpmOptions().n + 1, noise_smoothing=LPM_NOISE_SMOOTHING)
    return [local_polynomial_frf(u[-length:], y[-length:], fs_hz=fs, input_name=signal,
                                 output_names=list(OUTPUTS), options=opts,
                                 source=f"{exp}.mat")
            for exp, signal, fs, u, y in data]


def _periodic_estimates(data: Sequence[_ColumnRecord], *,
                      transient_periods: Mapping[str, int] | None) -> list[FrfEstimate]:
    """Periodic averaging of each column's record, on the lines every column excites."""
    least = dict(transient_periods or {})
    parts = [periodic_frf(u, y, fs_hz=fs, input_name=signal, output_names=list(OUTPUTS),
                          options=PeriodicOptions(
                              min_transient_periods=int(least.get(exp, 1))),
                          source=f"{exp}.mat")
             for exp, signal, fs, u, y in data]
    # Columns on the lines they share (a line excited in one record only is dropped).
    common = set(parts[0].frequency_hz.tolist())
    for part in parts[1:]:
        common &= set(part.frequency_hz.tolist())
    return [_on_lines(part, common) for part in parts]


def _on_lines(est: FrfEstimate, keep: set[float]) -> FrfEstimate:
    """The estimate on the lines of ``keep`` only [Hz]."""
    sel = np.array([f in keep for f in est.frequency_hz.tolist()], dtype=bool)
    if sel.all():
        return est
    return dataclasses.replace(
        est, frequency_hz=est.frequency_hz[sel], frf=est.frf[sel],
        frf_variance=est.frf_variance[sel], output_noise_psd=est.output_noise_psd[sel],
        input_psd=est.input_psd[sel], snr=est.snr[sel],
        transient=None if est.transient is None else est.transient[sel],
        distortion_variance=(None if est.distortion_variance is None
                             else est.distortion_variance[sel]))
