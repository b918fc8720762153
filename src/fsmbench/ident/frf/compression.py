"""The 4QD's compression in the FRFs, corrected with the calibration's cubic term.

A 4QD reads ``V = a x + c x³`` (``x`` the beam angle; ``c < 0``: the spot
leaves the quadrants, :mod:`fsmbench.ident.calibration` fits it). An
experiment that moves the beam by a Gaussian ``x`` (white-noise excitation,
a random-phase multisine) measures the *best linear approximation*, by
Bussgang's theorem ``E[dV/dx] = a + 3 c σx²``: every line of the output's
FRF is ``1 + 3 (c/a) σx² = 1 + 3 κ σ_V²`` times the small-signal one
(``κ = c / a³`` [1/V²], ``σ_V²`` the output's variance in that experiment;
the 4QD's own noise, added after the compression, is < 1 % of it). On the
real-bench twin's noise records that is −1.2 % on the Sercalo's static gain
(−15 to −41 of its noise std).

:func:`compression_factors` gives the factor of each element (output, input)
from its output's variance in the column's experiment, and its standard
deviation: the cubic term's (the calibration's spectral sandwich) and the
next term of an error-function response with that cubic term,
``15 e σx⁴ = 13.5 (κ σ_V²)²`` (the twin's law is exactly cubic; a real
spot's is not). :func:`correct_compression` divides the FRF by the factors
and adds their uncertainty as the lines' ``compression`` variance part.
When the calibration kept a straight line, the factor is 1 and its std the
cubic term's bound.

A periodic excitation is not Gaussian where a few lines dominate the output
(a lightly damped mode between two lines of a multisine). The cubic's part
of line ``k`` coherent with the input is then exactly
``κ A_k (3 σ_V² − (3/4) A_k²)`` (``A_k`` the line's output amplitude, the
sum over every triple of lines that lands on ``k`` in phase with it), so a
periodic FRF's factor is ``1 + κ (3 σ_V² − (3/4) A_k²)`` line by line: the
two lines beside the real-bench twin's 411 Hz mode carried 2–5e-3 of bias,
25 of their stds, with Bussgang's factor.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace

import numpy as np
import xarray as xr

from fsmbench.ident.calibration import QdCalibration, trim_recording
from fsmbench.ident.frf.response import FrequencyResponse, with_variance_part

__all__ = ["CompressionFactors", "compression_factors", "correct_compression"]

_OUTPUT_AXIS = {"Vph": "h", "Vpv": "v"}


@dataclass(frozen=True)
class CompressionFactors:
    """The 4QD's compression of each FRF element.

    Attributes
    ----------
    outputs, inputs : tuple of str
        Element order.
    factor : ndarray, shape (p, m)
        ``1 + 3 κ σ_V²`` [1]: what the measured FRF is of the small-signal one.
    std : ndarray, shape (p, m)
        Its standard deviation [1].
    output_rms_v : ndarray, shape (p, m)
        ``σ_V`` of each output in each column's experiment [V].
    kappa_per_v2, kappa_std_per_v2 : ndarray, shape (p,)
        ``κ = c / a³`` of each output's 4QD axis and its std [1/V²].
    """

    outputs: tuple[str, ...]
    inputs: tuple[str, ...]
    factor: np.ndarray
    std: np.ndarray
    output_rms_v: np.ndarray
    kappa_per_v2: np.ndarray = field(default_factory=lambda: np.zeros(0))
    kappa_std_per_v2: np.ndarray = field(default_factory=lambda: np.zeros(0))

    def element(self, output: str, input_: str) -> tuple[float, float]:
        """``(factor, std)`` of one element."""
        i, j = self.outputs.index(output), self.inputs.index(input_)
        return float(self.factor[i, j]), float(self.std[i, j])

    def summary(self) -> dict[str, object]:
        """Plain values keyed ``<input>_to_<output>``."""
        return {f"{inp}_to_{out}": {"factor": float(self.factor[i, j]),
                                    "std": float(self.std[i, j]),
                                    "output_rms_v": float(self.output_rms_v[i, j])}
                for i, out in enumerate(self.outputs) for j, inp in enumerate(self.inputs)}


def compression_factors(recordings: Mapping[str, xr.Dataset], *,
                        columns: Sequence[tuple[str, str]], outputs: Sequence[str],
                        qd: Mapping[str, QdCalibration],
                        trims_s: Mapping[str, float]) -> CompressionFactors:
    """The compression factor of every element (see the module).

    Parameters
    ----------
    recordings : mapping of experiment name to Dataset
    columns : sequence of (experiment, input signal)
        The FRF's columns, as :func:`fsmbench.ident.frf.experiment.experiment_frf`.
    outputs : sequence of str
        ``Vph``, ``Vpv``.
    qd : mapping axis -> QdCalibration
        The 4QD calibrations (gain, cubic term and its std).
    trims_s : mapping of experiment name to seconds
    """
    p, m = len(outputs), len(columns)
    factor, std, rms = np.ones((p, m)), np.zeros((p, m)), np.zeros((p, m))
    kappas, kappa_stds = np.zeros(p), np.zeros(p)
    for j, (experiment, _signal) in enumerate(columns):
        ds = trim_recording(recordings[experiment], t0_s=trims_s.get(experiment, 0.0))
        for i, out in enumerate(outputs):
            cal = qd.get(_OUTPUT_AXIS.get(out, ""))
            v = np.asarray(ds[out].values, dtype=float)
            var = float(np.var(v))
            rms[i, j] = math.sqrt(var)
            if cal is None or cal.gain_v_per_rad == 0:
                continue
            a3 = cal.gain_v_per_rad**3
            kappa = cal.cubic_v_per_rad3 / a3
            kappa_std = cal.cubic_std_v_per_rad3 / abs(a3)
            kappas[i], kappa_stds[i] = kappa, kappa_std
            factor[i, j] = 1.0 + 3.0 * kappa * var
            fifth = 13.5 * (kappa * var) ** 2
            std[i, j] = math.hypot(3.0 * kappa_std * var, fifth)
    return CompressionFactors(outputs=tuple(outputs), inputs=tuple(s for _, s in columns),
                              factor=factor, std=std, output_rms_v=rms, kappa_per_v2=kappas,
                              kappa_std_per_v2=kappa_stds)


def _periodic_cubic(frf: FrequencyResponse, factors: CompressionFactors,
                    recordings: Mapping[str, xr.Dataset], *,
                    columns: Sequence[tuple[str, str]], trims_s: Mapping[str, float]
                    ) -> tuple[np.ndarray, np.ndarray]:
    """``κ DFT(v̄³)_k / U_k`` at every line of a periodic FRF and its std, (F, p, m).

    ``v̄`` is each output's period average over the periods the estimate kept
    (``column_options``), ``U_k`` the input's. On a periodic record the cubic's
    output is known line by line: its coherent part and the intermodulation
    products of the strong lines beside a mode, which land on the excited lines
    of an odd-odd grid (``2 f_a − f_b``) and on no non-excited line nearby.
    """
    shape = frf.frf.shape
    term, std = np.zeros(shape, dtype=complex), np.zeros(shape)
    rows = [factors.outputs.index(o) for o in frf.output_names]
    kappa = factors.kappa_per_v2[rows]
    kappa_std = factors.kappa_std_per_v2[rows]
    f_hz = frf.frequency_hz
    for experiment, signal in columns:
        opts = frf.column_options.get(signal, {})
        n, dropped = opts.get("period_samples"), opts.get("transient_periods")
        if signal not in frf.input_names or not n or dropped is None:
            continue
        j = frf.input_names.index(signal)
        ds = trim_recording(recordings[experiment], t0_s=trims_s.get(experiment, 0.0))
        u = np.asarray(ds[signal].values, dtype=float)
        y = np.column_stack([ds[o].values for o in frf.output_names]).astype(float)
        u, y = u - u.mean(), y - y.mean(axis=0)
        total = u.size // int(n)
        first = u.size - total * int(n) + int(dropped) * int(n)
        periods = total - int(dropped)
        if periods < 1:
            continue
        ub = u[first:first + periods * n].reshape(periods, n).mean(axis=0)
        yb = y[first:first + periods * n].reshape(periods, n, -1).mean(axis=0)
        uk = np.fft.rfft(ub)
        dk = np.fft.rfft(kappa[None, :] * yb**3, axis=0)  # (K, p)
        var = np.var(yb, axis=0)
        k = np.rint(f_hz * n / frf.fs_hz).astype(int)
        ok = (k > 0) & (k < uk.size)
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = np.where(ok[:, None], dk[np.clip(k, 0, uk.size - 1)]
                             / uk[np.clip(k, 0, uk.size - 1), None], 0.0)
        term[:, :, j] = ratio
        rel_kappa = np.where(kappa != 0, kappa_std / np.where(kappa != 0, np.abs(kappa), 1.0),
                             0.0)
        # The cubic's own std, and the next term of an error-function law (as the factor's).
        fifth = 13.5 * (kappa * var) ** 2
        std[:, :, j] = np.hypot(np.abs(ratio) * rel_kappa[None, :],
                                fifth[None, :] * np.abs(np.asarray(frf.frf.values)[:, :, j]))
    return term, std


def correct_compression(frf: FrequencyResponse, factors: CompressionFactors, *,
                        recordings: Mapping[str, xr.Dataset] | None = None,
                        columns: Sequence[tuple[str, str]] = (),
                        trims_s: Mapping[str, float] | None = None) -> FrequencyResponse:
    """The FRF with the 4QD's compression taken out, its uncertainty a ``compression`` part.

    Noise excitation (Welch, LPM): divided by each element's Bussgang factor.
    A periodic FRF with its ``recordings`` and ``columns``: less the cubic's
    output computed line by line from the period-averaged outputs
    (:func:`_periodic_cubic`). The lines' other variance parts scale by
    ``|H_corrected / H|²`` with the response.

    Parameters
    ----------
    frf : FrequencyResponse
    factors : CompressionFactors
    recordings : mapping of experiment name to Dataset, optional
    columns : sequence of (experiment, input signal)
    trims_s : mapping of experiment name to seconds, optional
    """
    f = np.array([[factors.element(o, i)[0] for i in frf.input_names]
                  for o in frf.output_names])[None, :, :] * np.ones((frf.frf.shape[0], 1, 1))
    sd = np.array([[factors.element(o, i)[1] for i in frf.input_names]
                   for o in frf.output_names])[None, :, :] * np.ones((frf.frf.shape[0], 1, 1))
    if (frf.estimator == "periodic" and factors.kappa_per_v2.size and recordings is not None
            and columns):
        term, tsd = _periodic_cubic(frf, factors, recordings, columns=columns,
                                    trims_s=trims_s or {})
        h = np.asarray(frf.frf.values)
        with np.errstate(divide="ignore", invalid="ignore"):
            # f complex: what the measured line is of the small-signal one
            f = np.where(np.abs(h - term) > 0, h / (h - term), 1.0)
            sd = np.where(np.abs(h - term) > 0, tsd / np.abs(h - term), 0.0)
    elif frf.estimator == "periodic" and factors.kappa_per_v2.size:
        # Line by line: less the self-term (3/4) kappa A_k^2 of each line's own amplitude.
        rows = [factors.outputs.index(o) for o in frf.output_names]
        kappa = factors.kappa_per_v2[rows][None, :, None]
        kappa_std = factors.kappa_std_per_v2[rows][None, :, None]
        resolution = frf.fs_hz / frf.window_length
        amp2 = (2.0 * np.abs(np.asarray(frf.frf.values)) ** 2
                * np.asarray(frf.input_psd.values) * resolution)  # A_k^2 [V^2]
        f = f - 0.75 * kappa * amp2
        sd = np.hypot(sd, 0.75 * kappa_std * amp2)
    scale = xr.DataArray(1.0 / f, dims=("frequency", "output", "input"),
                         coords={"frequency": frf.frf["frequency"].values,
                                 "output": list(frf.output_names),
                                 "input": list(frf.input_names)})
    var_scale = np.abs(scale) ** 2
    parts = {k: v * var_scale for k, v in frf.variance_parts.items()}
    base = replace(frf, frf=frf.frf * scale, cross_psd=frf.cross_psd * scale,
                   frf_variance=None if frf.frf_variance is None
                   else frf.frf_variance * var_scale, variance_parts=parts,
                   magnitude_lower=frf.magnitude_lower * np.abs(scale),
                   magnitude_upper=frf.magnitude_upper * np.abs(scale))
    if frf.frf_variance is None and not parts:
        # Welch: the random error is relative and stays; the variance becomes explicit.
        base = replace(base, frf_variance=base.line_variance(),
                       noise_dof=tuple(float(d) for d in frf.column_dof()))
    rel = sd / np.abs(f)
    return with_variance_part(base, "compression",
                              np.abs(np.asarray(base.frf.values)) ** 2 * rel**2)
