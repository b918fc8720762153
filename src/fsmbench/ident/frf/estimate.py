"""Frequency responses with per-line uncertainty: the result type of the non-Welch estimators.

:class:`FrfEstimate` is what :func:`fsmbench.ident.frf.periodic.periodic_frf`
and :func:`fsmbench.ident.frf.lpm.local_polynomial_frf` return: the FRF at each
line with the variance of its estimation error, the output noise spectrum
estimated from the same data and a signal-to-noise ratio per line. It converts
to the :class:`~fsmbench.ident.frf.response.FrequencyResponse` the rest of the
identification consumes (:meth:`FrfEstimate.to_frequency_response`) and back
(:meth:`FrfEstimate.from_frequency_response`, for a Welch estimate).

Conventions
-----------
* DFT lines are normalised ``X(k) = N^-1/2 sum_t x(t) exp(-j 2 pi k t / N)``,
  so white noise of variance ``s^2`` has ``E|X(k)|^2 = s^2`` and its one-sided
  PSD is ``2 E|X(k)|^2 / fs`` (U^2/Hz); every PSD here uses that rule.
* ``frf_variance`` is ``E|G_hat - G|^2`` (complex variance); the real and
  imaginary parts each carry half of it when the error is circular.
* The signal-to-noise ratio is ``|G U|^2 / var(V)`` per DFT line of the
  estimator's data block (one period for periodic averaging, the whole
  record for the LPM), as Welch's coherence is per segment; ``snr / (1 + snr)``
  is the coherence a noise-free input and this output noise would give (the
  Welch coherence's meaning), used when converting to a
  :class:`FrequencyResponse`.
* Confidence bound: for a circular complex-normal error of *known* variance
  the region ``|G_hat - G| <= sqrt(-ln(1 - c)) std`` has probability ``c``
  (``|e|^2 / var`` is exponential with mean 1); 95 %: 1.73 std. The variance
  is estimated, on ``dof`` complex degrees of freedom: ``|e|^2 / var_hat`` is
  then ``F(2, 2 dof)`` (Hotelling's T² of the error's two parts), and the
  radius ``sqrt(F^-1(c; 2, 2 dof)) std`` (:func:`fsmbench.ident.frf.response.bound_factor`;
  1.88 std at 9 dof, 1.93 at the LPM's 7). The Gaussian radius covered 92 %.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import xarray as xr
from numpy.typing import NDArray

from fsmbench.ident.frf.response import DIMS, FrequencyResponse, _bounds, bound_factor

__all__ = ["FrfEstimate", "circular_bound_factor", "combine_estimates", "simo_signals"]


def circular_bound_factor(confidence: float, dof: float | None = None) -> float:
    """Radius of the ``confidence`` region of a circular complex-normal error, in std units.

    Parameters
    ----------
    confidence : float
        Probability in (0, 1), e.g. 0.95.
    dof : float, optional
        Complex degrees of freedom of the variance estimate (None: known).

    Returns
    -------
    float
        ``sqrt(-ln(1 - confidence))`` (dimensionless; 1.731 for 0.95) for a
        known variance, ``sqrt(F^-1(confidence; 2, 2 dof))`` for an estimated one.
    """
    return float(bound_factor(confidence, dof))


@dataclass(frozen=True, eq=False)
class FrfEstimate:
    """A frequency-response matrix with the variance of every line.

    Shapes: ``F`` lines, ``p`` outputs, ``m`` inputs (columns, each from its
    own single-input experiment).

    Attributes
    ----------
    frequency_hz : ndarray, float, shape (F,)
        Frequency of each line, Hz (only the lines estimated: the excited lines
        of a periodic excitation, every or every ``stride``-th line of the LPM).
    frf : ndarray, complex, shape (F, p, m)
        FRF estimate, U_out/U_in.
    frf_variance : ndarray, float, shape (F, p, m)
        Estimated ``E|G_hat - G|^2``, (U_out/U_in)^2.
    output_noise_psd : ndarray, float, shape (F, p, m)
        One-sided PSD of the output noise at each line in the experiment of
        column ``j``, U_out^2/Hz.
    input_psd : ndarray, float, shape (F, m)
        One-sided PSD of the (averaged) input at each line, U_in^2/Hz.
    snr : ndarray, float, shape (F, p, m)
        ``|G U|^2 / var(V)`` per DFT line of one data block (dimensionless).
    input_names, output_names : tuple of str
        Names of the ``m`` inputs and ``p`` outputs.
    fs_hz : float
        Sampling frequency, Hz.
    resolution_hz : float
        DFT line spacing of the estimator (``fs / N``), Hz.
    estimator : str
        ``"periodic"``, ``"lpm"`` or ``"welch"``.
    options : mapping
        The estimator's options (plain values), for the record.
    dof : tuple of float
        Degrees of freedom of the noise estimate per column (``P - 1`` periods,
        LPM residual dof, Welch ``n_d``).
    transient : ndarray, complex, shape (F, p, m) or None
        Transient (leakage) term estimated at each line, U_out (LPM only).
    confidence : float
        Level of :meth:`bound_radius` by default.
    distortion_variance : ndarray, shape (F, p, m), or None
        Variance the nonlinear distortion adds to each line [(U_out/U_in)^2]
        (periodic averaging of an odd grid: :func:`fsmbench.ident.frf.periodic.distortion`);
        ``frf_variance`` is the noise's alone.
    """

    frequency_hz: NDArray[np.float64]
    frf: NDArray[np.complex128]
    frf_variance: NDArray[np.float64]
    output_noise_psd: NDArray[np.float64]
    input_psd: NDArray[np.float64]
    snr: NDArray[np.float64]
    input_names: tuple[str, ...]
    output_names: tuple[str, ...]
    fs_hz: float
    resolution_hz: float
    estimator: str
    options: Mapping[str, Any] = field(default_factory=dict)
    dof: tuple[float, ...] = ()
    transient: NDArray[np.complex128] | None = None
    confidence: float = 0.95
    distortion_variance: NDArray[np.float64] | None = None

    def __post_init__(self) -> None:
        f = self.frequency_hz.shape[0]
        p, m = len(self.output_names), len(self.input_names)
        for name in ("frf", "frf_variance", "output_noise_psd", "snr"):
            if getattr(self, name).shape != (f, p, m):
                raise ValueError(f"{name} has shape {getattr(self, name).shape}, expected "
                                 f"{(f, p, m)} (lines, outputs, inputs)")
        if self.input_psd.shape != (f, m):
            raise ValueError(f"input_psd has shape {self.input_psd.shape}, expected {(f, m)}")

    @property
    def total_variance(self) -> NDArray[np.float64]:
        """Noise and distortion variance of each line [(U_out/U_in)^2], shape (F, p, m)."""
        if self.distortion_variance is None:
            return self.frf_variance
        return self.frf_variance + self.distortion_variance

    @property
    def frf_std(self) -> NDArray[np.float64]:
        """Standard deviation of the complex FRF error, U_out/U_in, shape (F, p, m)."""
        return np.sqrt(self.total_variance)

    def effective_dof(self) -> NDArray[np.float64]:
        """Welch–Satterthwaite complex dof of each line's total variance, (F, p, m)."""
        dof = np.broadcast_to(np.asarray(self.dof, dtype=float)[None, None, :]
                              if len(self.dof) == len(self.input_names)
                              else np.full((1, 1, len(self.input_names)), np.inf),
                              self.frf.shape)
        noise, total = self.frf_variance, self.total_variance
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.asarray(np.where(noise > 0, dof * (total / np.where(noise > 0, noise, 1.0))
                                       ** 2, np.inf), dtype=float)

    def bound_radius(self, confidence: float | None = None) -> NDArray[np.float64]:
        """Radius of the circular confidence region around each line, U_out/U_in, (F, p, m).

        F-based (the variance is estimated: see the module), on the Welch–Satterthwaite
        dof of the noise and distortion variances.
        """
        c = self.confidence if confidence is None else confidence
        return np.asarray(bound_factor(c, self.effective_dof()) * self.frf_std, dtype=float)

    def summary(self) -> dict[str, Any]:
        """JSON-ready description: estimator, options, lines and median relative std per pair."""
        with np.errstate(divide="ignore", invalid="ignore"):
            rel = self.frf_std / np.abs(self.frf)
        return {
            "estimator": self.estimator,
            "options": dict(self.options),
            "n_lines": int(self.frequency_hz.size),
            "resolution_hz": self.resolution_hz,
            "dof": list(self.dof),
            "median_relative_std": {
                f"{inp}_to_{out}": float(np.nanmedian(rel[:, i, j]))
                for i, out in enumerate(self.output_names)
                for j, inp in enumerate(self.input_names)},
        }

    def to_frequency_response(self) -> FrequencyResponse:
        """The :class:`FrequencyResponse` view the identification pipeline consumes.

        ``coherence = snr / (1 + snr)``; ``random_error = std / (sqrt 2 |G|)``
        (the std of ``|G|`` relative to ``|G|`` and of the phase in rad for a
        circular error); bounds at ``confidence`` from the normal approximation
        as for Welch; ``frf_variance`` and ``estimator`` carried along;
        ``window_length = nfft = round(fs / resolution)``, no overlap.
        """
        f = self.frequency_hz
        coords = {"frequency": ("frequency", f, {"units": "Hz"}),
                  "output": list(self.output_names), "input": list(self.input_names)}
        template = xr.DataArray(self.frf, dims=DIMS, coords=coords)

        def da(values: NDArray[Any], name: str, units: str) -> xr.DataArray:
            out = template.copy(deep=False, data=values)
            out.name, out.attrs = name, {"units": units}
            return out

        with np.errstate(divide="ignore", invalid="ignore"):
            eps = self.frf_std / (math.sqrt(2.0) * np.abs(self.frf))
        bounds = _bounds(self.frf, eps, self.confidence, self.effective_dof())
        shape = self.frf.shape
        pxx = np.broadcast_to(self.input_psd[:, None, :], shape).copy()
        pyy = (np.abs(self.frf) ** 2 * pxx + self.output_noise_psd)
        n = round(self.fs_hz / self.resolution_hz)
        m = len(self.input_names)
        return FrequencyResponse(
            frf=da(self.frf.copy(), "frf", "output/input"),
            coherence=da(self.snr / (1.0 + self.snr), "coherence", "1"),
            input_psd=da(pxx, "input_psd", "input^2/Hz"),
            output_psd=da(pyy, "output_psd", "output^2/Hz"),
            cross_psd=da(self.frf * pxx, "cross_psd", "output*input/Hz"),
            random_error=da(eps, "random_error", "1"),
            magnitude_lower=da(bounds[0], "magnitude_lower", "output/input"),
            magnitude_upper=da(bounds[1], "magnitude_upper", "output/input"),
            phase_lower_rad=da(bounds[2], "phase_lower_rad", "rad"),
            phase_upper_rad=da(bounds[3], "phase_upper_rad", "rad"),
            confidence=self.confidence,
            window_length=n,
            noverlap=0,
            nfft=n,
            fs_hz=self.fs_hz,
            n_segments=(1,) * m,
            effective_averages=tuple(self.dof) if len(self.dof) == m else (float("nan"),) * m,
            frf_variance=da(self.total_variance.copy(), "frf_variance", "(output/input)^2"),
            estimator=self.estimator,
            variance_parts=({} if self.distortion_variance is None else {
                "noise": da(self.frf_variance.copy(), "frf_variance", "(output/input)^2"),
                "distortion": da(self.distortion_variance.copy(), "frf_variance",
                                 "(output/input)^2")}),
            noise_dof=tuple(float(d) for d in self.dof) if len(self.dof) == m else (),
            column_options=self.column_options(),
        )

    def column_options(self) -> dict[str, dict[str, Any]]:
        """The options of each column (input name → plain values)."""
        cols = self.options.get("columns")
        if isinstance(cols, Mapping):
            return {str(k): dict(v) for k, v in cols.items()}
        return {inp: {k: v for k, v in self.options.items() if k != "columns"}
                for inp in self.input_names}

    @classmethod
    def from_frequency_response(cls, frf: FrequencyResponse) -> FrfEstimate:
        """A Welch :class:`FrequencyResponse` as an estimate with variance.

        Uses ``frf.frf_variance`` when present, else Bendat & Piersol's
        ``var(H) = 2 (random_error |H|)^2`` (from the estimated coherence; it
        misses the window's leakage bias near sharp resonances). Output noise
        PSD ``(1 - coherence) output_psd``; ``snr = coh / (1 - coh)``.
        """
        h = np.asarray(frf.frf.values)
        if frf.frf_variance is not None:
            var = np.asarray(frf.frf_variance.values, dtype=float)
        else:
            var = 2.0 * (np.asarray(frf.random_error.values) * np.abs(h)) ** 2
        coh = np.clip(np.asarray(frf.coherence.values, dtype=float), 0.0, 1.0)
        with np.errstate(divide="ignore"):
            snr = coh / (1.0 - coh)
        return cls(
            frequency_hz=frf.frequency_hz.copy(), frf=h.copy(), frf_variance=var,
            output_noise_psd=(1.0 - coh) * np.asarray(frf.output_psd.values),
            input_psd=np.asarray(frf.input_psd.values)[:, 0, :].copy(), snr=snr,
            input_names=frf.input_names, output_names=frf.output_names, fs_hz=frf.fs_hz,
            resolution_hz=frf.fs_hz / frf.window_length, estimator=frf.estimator,
            options={"window_length": frf.window_length, "noverlap": frf.noverlap,
                     "nfft": frf.nfft},
            dof=tuple(frf.effective_averages), confidence=frf.confidence)


def combine_estimates(parts: Sequence[FrfEstimate]) -> FrfEstimate:
    """Columns of single-input estimates side by side (one experiment per input).

    Parameters
    ----------
    parts : sequence of FrfEstimate
        Same estimator, sampling rate, resolution and line frequencies, outputs
        in any order (the first one's order is kept), distinct inputs.

    Returns
    -------
    FrfEstimate
        ``m = sum of the parts' inputs``; ``dof`` per column; options of the
        first part; the transient only if every part has one.
    """
    items = list(parts)
    if not items:
        raise ValueError("combine_estimates needs at least one FrfEstimate")
    first = items[0]
    order = list(first.output_names)
    for i, e in enumerate(items[1:], start=1):
        for attr in ("estimator", "fs_hz", "resolution_hz", "confidence"):
            if getattr(e, attr) != getattr(first, attr):
                raise ValueError(f"estimate {i} has {attr}={getattr(e, attr)!r} but estimate 0 "
                                 f"has {getattr(first, attr)!r}")
        if not np.array_equal(e.frequency_hz, first.frequency_hz):
            raise ValueError(f"estimate {i} is on different lines from estimate 0 (excite every "
                             "input on the same grid, or use records of equal length)")
        if set(e.output_names) != set(order):
            raise ValueError(f"estimate {i} has outputs {list(e.output_names)}, estimate 0 "
                             f"{order}")
    inputs = [n for e in items for n in e.input_names]
    if len(set(inputs)) != len(inputs):
        raise ValueError(f"input names must be distinct across estimates, got {inputs}")

    def cat(name: str) -> NDArray[Any]:
        return np.concatenate([getattr(e, name)[:, [e.output_names.index(o) for o in order], :]
                               for e in items], axis=2)

    transient = (cat("transient") if all(e.transient is not None for e in items) else None)
    dist = None
    if any(e.distortion_variance is not None for e in items):
        dist = np.concatenate([
            (e.distortion_variance if e.distortion_variance is not None
             else np.zeros_like(e.frf_variance))[:, [e.output_names.index(o) for o in order], :]
            for e in items], axis=2)
    return FrfEstimate(
        frequency_hz=first.frequency_hz, frf=cat("frf"), frf_variance=cat("frf_variance"),
        output_noise_psd=cat("output_noise_psd"),
        input_psd=np.concatenate([e.input_psd for e in items], axis=1), snr=cat("snr"),
        input_names=tuple(inputs), output_names=tuple(order), fs_hz=first.fs_hz,
        resolution_hz=first.resolution_hz, estimator=first.estimator,
        options={**first.options,
                 "columns": {k: v for e in items for k, v in e.column_options().items()}},
        dof=tuple(d for e in items for d in e.dof), transient=transient,
        confidence=first.confidence, distortion_variance=dist)


def simo_signals(inputs: Any, outputs: Any, *, input_name: str,
                 output_names: str | Sequence[str], source: str
                 ) -> tuple[NDArray[np.float64], NDArray[np.float64], list[str]]:
    """One experiment's input (L,) and outputs (L, p) as float arrays, with the output names.

    Raises
    ------
    ValueError
        Naming ``source`` and the input: shapes that do not match, NaN or inf samples.
    """
    u = np.asarray(inputs, dtype=float)
    y = np.asarray(outputs, dtype=float)
    if y.ndim == 1:
        y = y[:, None]
    names = [str(o) for o in ([output_names] if isinstance(output_names, str) else output_names)]
    if u.ndim != 1 or y.ndim != 2 or y.shape[0] != u.size or y.shape[1] != len(names):
        raise ValueError(f"{source}: input {input_name} has shape {u.shape} and the outputs "
                         f"{y.shape}; expected (L,) and (L, {len(names)})")
    if not (np.all(np.isfinite(u)) and np.all(np.isfinite(y))):
        raise ValueError(f"{source}: {input_name} or an output has NaN/inf samples")
    return u, y, names
