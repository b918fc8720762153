"""Multi-channel frequency-response estimation in one pass, with confidence bounds.

:func:`spectral_matrix` turns an experiment (inputs ``(N, m)``, outputs
``(N, p)``) into a :class:`FrequencyResponse`: H1 FRF matrix, ordinary
coherences, PSDs and Bendat & Piersol confidence bounds, as
:class:`xarray.DataArray` objects with dims ``("frequency", "output",
"input")``. :func:`combine_columns` assembles single-input experiments (the
seed's ``data_uch``/``data_ucv``) into one matrix. Conventions and sources:
see :mod:`fsmbench.ident.frf.spectral`.
"""

from __future__ import annotations

import json
import math
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from statistics import NormalDist
from typing import Any, NamedTuple

import numpy as np
import xarray as xr
from numpy.typing import ArrayLike, NDArray
from scipy.stats import f as f_dist
from scipy.stats import t as t_dist

from fsmbench.signal.welch import (
    WelchOptions,
    _as_signal,
    _check_has_power,
    _check_record,
    _label,
    cross_spectral_density,
    effective_averages,
)

__all__ = ["FrequencyResponse", "bound_factor", "combine_columns", "spectral_matrix",
           "with_variance_part"]

DIMS = ("frequency", "output", "input")
# Sxx is treated as singular where its condition number exceeds this: beyond
# ~1e12 the solve loses more than 4 of float64's ~16 significant digits.
_MAX_CONDITION = 1e12


@dataclass(frozen=True, eq=False)
class FrequencyResponse:
    """H1 frequency-response matrix of one or more experiments, with its statistics.

    Every DataArray has dims ``("frequency", "output", "input")`` and coords
    ``frequency`` (Hz), ``output`` and ``input`` (signal names).

    Attributes
    ----------
    frf : xarray.DataArray, complex
        H1 estimate ``Syx Sxx^-1`` (``Pyx/Pxx`` for one input), U_out/U_in.
    coherence : xarray.DataArray, float
        Ordinary magnitude-squared coherence of each (output, input) pair.
    input_psd : xarray.DataArray, float
        PSD of the input of each column, U_in^2/Hz (same for every output).
    output_psd : xarray.DataArray, float
        PSD of each output in the experiment that gave the column, U_out^2/Hz
        (per column, since columns may come from different experiments).
    cross_psd : xarray.DataArray, complex
        ``Pyx`` = MATLAB ``cpsd(output, input)``, U_out U_in/Hz.
    random_error : xarray.DataArray, float
        Normalised random error of ``|H|`` (dimensionless), also the standard
        deviation of the phase in rad (Bendat & Piersol, ch. 9).
    magnitude_lower, magnitude_upper : xarray.DataArray, float
        Confidence bounds on ``|H|`` at level ``confidence``, U_out/U_in.
    phase_lower_rad, phase_upper_rad : xarray.DataArray, float
        Confidence bounds on ``angle(H)``, rad (not wrapped: ``angle(H) -/+ z eps``).
    confidence : float
        Two-sided confidence level of the bounds, e.g. 0.95.
    window_length, noverlap, nfft : int
        Segment length, overlap, FFT length, samples.
    fs_hz : float
        Sampling frequency, Hz.
    n_segments : tuple of int
        Number of averaged segments per input column (same order as ``input``).
    effective_averages : tuple of float
        Welch (1967) equivalent independent averages ``n_d`` per input column.
    frf_variance : xarray.DataArray, float, or None
        ``E|H_hat - H|^2`` per line, (U_out/U_in)^2, when the estimator gives
        one directly (periodic averaging, LPM: :mod:`fsmbench.ident.frf.estimate`);
        None for Welch, whose uncertainty is ``random_error``.
    estimator : str
        ``"welch"`` (H1, :func:`spectral_matrix`), ``"periodic"`` or ``"lpm"``.
    variance_parts : mapping str -> xarray.DataArray
        What ``frf_variance`` is made of, (U_out/U_in)^2 each: ``noise`` (the
        estimator's own), then any of ``distortion`` (non-excited lines of an
        odd grid), ``leakage`` (a Welch window's bias near the modes, a bound),
        ``compression`` (the 4QD's correction); empty when ``frf_variance`` is
        the noise alone (or None).
    noise_dof : tuple of float
        Complex degrees of freedom of the noise variance per column (``P − 1``
        periods, the LPM's ``q``, Welch ``n_d − 1``); empty: from
        ``effective_averages``.
    column_options : mapping input -> mapping
        The estimator's options and findings per column (plain values: the
        periods averaged, the transient periods dropped, the distortion seen).
    """

    frf: xr.DataArray
    coherence: xr.DataArray
    input_psd: xr.DataArray
    output_psd: xr.DataArray
    cross_psd: xr.DataArray
    random_error: xr.DataArray
    magnitude_lower: xr.DataArray
    magnitude_upper: xr.DataArray
    phase_lower_rad: xr.DataArray
    phase_upper_rad: xr.DataArray
    confidence: float
    window_length: int
    noverlap: int
    nfft: int
    fs_hz: float
    n_segments: tuple[int, ...]
    effective_averages: tuple[float, ...]
    frf_variance: xr.DataArray | None = None
    estimator: str = "welch"
    variance_parts: Mapping[str, xr.DataArray] = field(default_factory=dict)
    noise_dof: tuple[float, ...] = ()
    column_options: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)

    _ARRAYS = (
        "frf", "coherence", "input_psd", "output_psd", "cross_psd", "random_error",
        "magnitude_lower", "magnitude_upper", "phase_lower_rad", "phase_upper_rad",
    )

    @property
    def frequency_hz(self) -> NDArray[np.float64]:
        """Frequency grid, Hz, shape (F,)."""
        return np.asarray(self.frf["frequency"].values)

    def line_variance(self) -> xr.DataArray:
        """``E|H_hat − H|²`` of every line [(U_out/U_in)²]: ``frf_variance``, else Bendat &
        Piersol's ``2 (random_error |H|)²`` of a Welch estimate."""
        if self.frf_variance is not None:
            return self.frf_variance
        out = 2.0 * (self.random_error * np.abs(self.frf)) ** 2
        out.name = "frf_variance"
        return out

    def column_dof(self) -> NDArray[np.float64]:
        """Complex degrees of freedom of each column's noise variance, shape (m,)."""
        if self.noise_dof:
            return np.asarray(self.noise_dof, dtype=float)
        n_d = np.asarray(self.effective_averages, dtype=float)
        return n_d - 1.0 if self.estimator == "welch" else n_d

    def effective_dof(self) -> NDArray[np.float64]:
        """Welch–Satterthwaite dof of each line's total variance, shape (F, p, m): the noise
        part's dof, the other parts (bounds, model-based) as exactly known."""
        total = np.asarray(self.line_variance().values, dtype=float)
        noise = self.variance_parts.get("noise")
        nv = total if noise is None else np.asarray(noise.values, dtype=float)
        dof = self.column_dof()[None, None, :]
        with np.errstate(divide="ignore", invalid="ignore"):
            eff = np.where(nv > 0, dof * (total / np.where(nv > 0, nv, 1.0)) ** 2, np.inf)
        return np.asarray(eff, dtype=float)

    def bound_radius(self, confidence: float | None = None) -> xr.DataArray:
        """Radius of each line's circular confidence region [U_out/U_in], (F, p, m).

        ``sqrt(F(2, 2ν; c) · var)``: the noise variance is itself estimated (ν
        complex degrees of freedom), so the normalised error is F-distributed,
        not exponential (:func:`bound_factor`; Hotelling's T² for a 2-vector).
        """
        c = self.confidence if confidence is None else float(confidence)
        var = self.line_variance()
        factor = bound_factor(c, self.effective_dof())
        out = var.copy(data=factor * np.sqrt(np.asarray(var.values, dtype=float)))
        out.name = "bound_radius"
        return out

    @property
    def input_names(self) -> tuple[str, ...]:
        """Input (column) names."""
        return tuple(str(v) for v in self.frf["input"].values)

    @property
    def output_names(self) -> tuple[str, ...]:
        """Output (row) names."""
        return tuple(str(v) for v in self.frf["output"].values)

    def summary(self) -> dict[str, Any]:
        """JSON-serialisable summary: options, averages and per-pair key figures."""
        pairs = []
        for out in self.output_names:
            for inp in self.input_names:
                gain = np.abs(self.frf.sel(output=out, input=inp).values)
                coh = self.coherence.sel(output=out, input=inp).values
                finite = np.isfinite(gain[1:])
                peak = int(np.nanargmax(gain[1:])) + 1 if finite.any() else 0  # skip DC
                pairs.append({
                    "output": out,
                    "input": inp,
                    "median_coherence": float(np.nanmedian(coh)),
                    "peak_gain": float(gain[peak]),
                    "peak_gain_frequency_hz": float(self.frequency_hz[peak]),
                })
        return {
            "estimator": self.estimator,
            "inputs": list(self.input_names),
            "outputs": list(self.output_names),
            "fs_hz": self.fs_hz,
            "window_length": self.window_length,
            "window_duration_s": self.window_length / self.fs_hz,
            "noverlap": self.noverlap,
            "nfft": self.nfft,
            "frequency_resolution_hz": self.fs_hz / self.nfft,
            "n_frequencies": int(self.frequency_hz.size),
            "n_segments": dict(zip(self.input_names, self.n_segments, strict=True)),
            "effective_averages": dict(zip(self.input_names, self.effective_averages, strict=True)),
            "confidence": self.confidence,
            "pairs": pairs,
        }

    def to_json(self, **kwargs: Any) -> str:
        """:meth:`summary` as a JSON string (``kwargs`` go to :func:`json.dumps`)."""
        return json.dumps(self.summary(), **kwargs)


def _as_matrix(data: ArrayLike, what: str) -> NDArray[Any]:
    arr = np.asarray(data)
    if arr.ndim == 1:
        arr = arr[:, None]
    if arr.ndim != 2 or arr.shape[1] == 0:
        raise ValueError(f"{what} must have shape (N, channels), got {arr.shape}")
    return arr


def _names(names: Sequence[str], count: int, what: str) -> list[str]:
    if isinstance(names, str):
        names = [names]
    out = [str(n) for n in names]
    if len(out) != count:
        raise ValueError(f"{what} has {len(out)} name(s) but the data has {count} channel(s)")
    if len(set(out)) != len(out):
        raise ValueError(f"{what} contains duplicate names: {out}")
    return out


def bound_factor(confidence: float, dof: float | ArrayLike | None = None) -> Any:
    """Radius of the ``confidence`` region of a circular complex error, in std units.

    With the variance known: ``sqrt(−ln(1 − c))`` (``|e|²/var`` is exponential;
    1.731 for 95 %). Estimated with ``dof`` complex degrees of freedom:
    ``|e|²/var_hat`` is ``F(2, 2 dof)`` and the radius ``sqrt(F⁻¹(c; 2, 2 dof))``
    (1.93 at 7 dof, the LPM's). Vectorised over ``dof``; infinite dof is the
    known-variance case.
    """
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"confidence must be in (0, 1), got {confidence!r}")
    known = math.sqrt(-math.log1p(-confidence))
    if dof is None:
        return known
    d = np.asarray(dof, dtype=float)
    finite = np.isfinite(d) & (d > 0)
    with np.errstate(invalid="ignore"):
        f = np.sqrt(f_dist.ppf(confidence, 2.0, 2.0 * np.where(finite, d, 1.0)))
    out = np.where(finite, f, known)
    return float(out) if out.ndim == 0 else out


def _bounds(
    h: NDArray[np.complex128], eps: NDArray[np.float64], confidence: float,
    dof: float | NDArray[np.float64] | None = None,
) -> tuple[NDArray[np.float64], ...]:
    # Gaussian approximation of the estimation error (B&P ch. 9, valid for eps <~ 0.2); with
    # an estimated variance of `dof` complex degrees of freedom, Student's t on 2 dof.
    if dof is None:
        z: Any = NormalDist().inv_cdf(0.5 + confidence / 2.0)
    else:
        d = np.broadcast_to(np.asarray(dof, dtype=float), np.shape(eps))
        finite = np.isfinite(d) & (d > 0)
        z = np.where(finite, t_dist.ppf(0.5 + confidence / 2.0, 2.0 * np.where(finite, d, 1.0)),
                     NormalDist().inv_cdf(0.5 + confidence / 2.0))
    mag = np.abs(h)
    half = np.minimum(z * eps, np.pi)  # a phase interval wider than +/-pi says nothing more
    phase = np.angle(h)
    return mag * np.maximum(1.0 - z * eps, 0.0), mag * (1.0 + z * eps), phase - half, phase + half


def with_variance_part(frf: FrequencyResponse, name: str, variance: ArrayLike,
                       ) -> FrequencyResponse:
    """``frf`` with one more part in its line variance, its bounds recomputed.

    Parameters
    ----------
    frf : FrequencyResponse
    name : str
        The part (``leakage``, ``compression``, ``distortion``; added to one of
        that name already there).
    variance : array_like, shape (F, p, m)
        Its variance per line [(U_out/U_in)²] (NaN counts as 0).
    """
    add = np.nan_to_num(np.asarray(variance, dtype=float), nan=0.0)
    base = frf.line_variance()
    parts = dict(frf.variance_parts) or {"noise": base}
    parts[name] = (parts[name] + add) if name in parts else base.copy(data=add)
    total = base.copy(data=np.asarray(base.values, dtype=float) + add)
    total.name = "frf_variance"
    out = replace(frf, frf_variance=total, variance_parts=parts,
                  noise_dof=tuple(float(x) for x in frf.column_dof()))
    return _rebound(out)


def _rebound(frf: FrequencyResponse) -> FrequencyResponse:
    """The magnitude and phase bounds and ``random_error`` of the line variance."""
    h = np.asarray(frf.frf.values)
    var = np.asarray(frf.line_variance().values, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        eps = np.sqrt(var) / (math.sqrt(2.0) * np.abs(h))
    lo, hi, plo, phi = _bounds(h, eps, frf.confidence, frf.effective_dof())
    return replace(frf, random_error=frf.random_error.copy(data=eps),
                   magnitude_lower=frf.magnitude_lower.copy(data=lo),
                   magnitude_upper=frf.magnitude_upper.copy(data=hi),
                   phase_lower_rad=frf.phase_lower_rad.copy(data=plo),
                   phase_upper_rad=frf.phase_upper_rad.copy(data=phi))


def spectral_matrix(
    inputs: ArrayLike,
    outputs: ArrayLike,
    *,
    input_names: Sequence[str],
    output_names: Sequence[str],
    window: int | ArrayLike,
    noverlap: int | None = None,
    nfft: int | None = None,
    fs_hz: float,
    confidence: float = 0.95,
) -> FrequencyResponse:
    """H1 FRF matrix, coherences and PSDs of one experiment, every FFT computed once.

    Parameters
    ----------
    inputs : array_like, shape (N, m) or (N,)
        Excitation records (unit U_in), one column per input.
    outputs : array_like, shape (N, p) or (N,)
        Response records (unit U_out), one column per output, same ``N``.
    input_names, output_names : sequence of str
        Channel names (length m and p); used as coordinates and in errors.
    window : int or array_like, shape (L,)
        As MATLAB: integer ``L`` means ``hamming(L)``; an array is used as is
        (the seed uses ``hanning(ceil(1*fs))``).
    noverlap : int, optional
        Overlap, samples; ``None`` is MATLAB's ``[]`` (``floor(L/2)``).
    nfft : int, optional
        FFT length, samples; ``None`` is ``max(256, 2^nextpow2(L))``.
    fs_hz : float
        Sampling frequency, Hz.
    confidence : float, optional
        Two-sided confidence level of the bounds, in (0, 1); default 0.95.

    Returns
    -------
    FrequencyResponse
        For ``m == 1`` each column equals ``tfestimate``/``mscohere``/``pwelch``
        of the pair to floating-point reordering.

    Raises
    ------
    ValueError
        NaN/inf samples, unequal lengths, a record shorter than two segments,
        a constant (zero-power) channel, or linearly dependent inputs at every
        frequency. Messages name the channel.

    Notes
    -----
    Frequencies where ``Sxx`` is singular (condition number > 1e12, ``m > 1``)
    get NaN in the FRF and bounds, with a :class:`RuntimeWarning`.
    """
    options = WelchOptions.from_matlab(window=window, noverlap=noverlap, nfft=nfft, fs_hz=fs_hz)
    if not 0.0 < float(confidence) < 1.0:
        raise ValueError(f"confidence must be in (0, 1), got {confidence!r}")
    sm = _checked_spectra(inputs, outputs, input_names=input_names, output_names=output_names,
                          options=options)
    m = len(sm.input_names)
    sxx, syx = sm.s[:, :m, :m], sm.s[:, m:, :m]
    pxx = np.diagonal(sxx, axis1=1, axis2=2).real  # (F, m)
    pyy = np.diagonal(sm.s[:, m:, m:], axis1=1, axis2=2).real  # (F, p)
    coh = np.abs(syx) ** 2 / (pyy[:, :, None] * pxx[:, None, :])

    with np.errstate(divide="ignore", invalid="ignore"):
        if m == 1:
            h = syx / pxx[:, None, :]  # exactly tfestimate's Pyx./Pxx
            # B&P: eps = sqrt(1 - g^2) / (|g| sqrt(2 n_d)); clip g^2 > 1 by rounding (1 ulp).
            eps = np.sqrt(np.clip(1.0 - coh, 0.0, None) / (coh * 2.0 * sm.n_d))
        else:
            # Called from here: its warning names this function's caller (stacklevel).
            h, eps = _multi_input(sxx, syx, pyy, sm.n_d, sm.input_names)
    bounds = _bounds(h, eps, float(confidence), max(sm.n_d - m, 1.0))
    return _frequency_response(sm, h=h, eps=eps, coherence=coh, input_psd=pxx, output_psd=pyy,
                               bounds=bounds, options=options, confidence=float(confidence))


class _SpectralMatrix(NamedTuple):
    """An experiment's cross-spectra ``s`` (F, m + p, m + p), the inputs first [U_a U_b/Hz],
    its channels' names, the ``segments`` averaged and Welch's equivalent averages ``n_d``."""

    s: NDArray[np.complex128]
    input_names: list[str]
    output_names: list[str]
    segments: int
    n_d: float


def _checked_spectra(inputs: ArrayLike, outputs: ArrayLike, *, input_names: Sequence[str],
                     output_names: Sequence[str], options: WelchOptions) -> _SpectralMatrix:
    """Every channel checked (finite, long enough, with power), then their cross-spectra;
    a ValueError names the channel (:func:`spectral_matrix`) or says the segments are few."""
    u = _as_matrix(inputs, "inputs")
    y = _as_matrix(outputs, "outputs")
    in_names = _names(input_names, u.shape[1], "input_names")
    out_names = _names(output_names, y.shape[1], "output_names")
    m = len(in_names)
    checked = [
        (_label(name, role), _as_signal(data[:, j], name=name, role=role))
        for data, names, role in ((u, in_names, "input"), (y, out_names, "output"))
        for j, name in enumerate(names)
    ]
    _check_record(checked, options, min_segments=2)  # coherence is identically 1 with one segment
    for who, arr in checked:
        _check_has_power(arr, who)

    s, k_seg = cross_spectral_density(np.stack([arr for _, arr in checked]), options)
    n_d = effective_averages(options.window, options.noverlap, k_seg)
    if n_d - m + 1 <= 0:
        raise ValueError(f"{k_seg} segments (n_d = {n_d:.3g}) are too few to estimate {m} inputs")
    return _SpectralMatrix(s, in_names, out_names, k_seg, n_d)


def _frequency_response(sm: _SpectralMatrix, *, h: NDArray[np.complex128],
                        eps: NDArray[np.float64], coherence: NDArray[np.float64],
                        input_psd: NDArray[np.float64], output_psd: NDArray[np.float64],
                        bounds: tuple[NDArray[np.float64], ...], options: WelchOptions,
                        confidence: float) -> FrequencyResponse:
    """The estimates as one :class:`FrequencyResponse`, every array on the same coordinates.

    ``input_psd`` (F, m) [U_in²/Hz] and ``output_psd`` (F, p) [U_out²/Hz] are spread over
    the (F, p, m) matrix; ``bounds`` are :func:`_bounds`'s four arrays.
    """
    m, p = len(sm.input_names), len(sm.output_names)
    f = options.frequencies_hz
    coords = {
        "frequency": ("frequency", f, {"units": "Hz"}), "output": sm.output_names,
        "input": sm.input_names,
    }

    template = xr.DataArray(h, dims=DIMS, coords=coords)  # coordinates/indexes built once

    def da(values: NDArray[Any], name: str, units: str) -> xr.DataArray:
        out = template.copy(deep=False, data=values)
        out.name, out.attrs = name, {"units": units}
        return out

    shape = (f.size, p, m)
    return FrequencyResponse(
        frf=da(h, "frf", "output/input"),
        coherence=da(coherence, "coherence", "1"),
        input_psd=da(np.broadcast_to(input_psd[:, None, :], shape).copy(), "input_psd",
                     "input^2/Hz"),
        output_psd=da(np.broadcast_to(output_psd[:, :, None], shape).copy(), "output_psd",
                      "output^2/Hz"),
        cross_psd=da(sm.s[:, m:, :m].copy(), "cross_psd", "output*input/Hz"),
        random_error=da(eps, "random_error", "1"),
        magnitude_lower=da(bounds[0], "magnitude_lower", "output/input"),
        magnitude_upper=da(bounds[1], "magnitude_upper", "output/input"),
        phase_lower_rad=da(bounds[2], "phase_lower_rad", "rad"),
        phase_upper_rad=da(bounds[3], "phase_upper_rad", "rad"),
        confidence=confidence,
        window_length=options.window_length,
        noverlap=options.noverlap,
        nfft=options.nfft,
        fs_hz=options.fs_hz,
        n_segments=(sm.segments,) * m,
        effective_averages=(sm.n_d,) * m,
    )


def _multi_input(
    sxx: NDArray[np.complex128],
    syx: NDArray[np.complex128],
    pyy: NDArray[np.float64],
    n_d: float,
    in_names: Sequence[str],
) -> tuple[NDArray[np.complex128], NDArray[np.float64]]:
    """H = Syx Sxx^-1 and its normalised random error for m > 1 inputs.

    Var(H_ki) ~ Gnn_k [Sxx^-1]_ii / (n_d - m + 1) with the residual spectrum
    Gnn_k = Syy_k - H_k Syx_k^H (Bendat & Piersol, multiple-input FRF error);
    the magnitude error is half of it: eps = sqrt(Var / 2) / |H|. For m = 1
    this is exactly the single-input formula.
    """
    m = sxx.shape[-1]
    cond = np.linalg.cond(sxx)
    singular = ~(cond < _MAX_CONDITION)
    names = ", ".join(repr(n) for n in in_names)
    if singular.all():
        raise ValueError(
            f"inputs {names} are linearly dependent at every frequency (e.g. the same excitation "
            "drives several inputs): the multi-input H1 estimate Syx Sxx^-1 is undefined; excite "
            "them independently, or record one experiment per input and use combine_columns"
        )
    if singular.any():
        warnings.warn(
            f"inputs {names} are linearly dependent at {int(singular.sum())} of {singular.size} "
            "frequencies (Sxx condition number > 1e12); the FRF is NaN there",
            RuntimeWarning,
            stacklevel=3,
        )
    safe = np.where(singular[:, None, None], np.eye(m), sxx)
    inv = np.linalg.inv(safe)
    h = syx @ inv
    gnn = np.clip(pyy - np.einsum("fki,fki->fk", h, syx.conj()).real, 0.0, None)
    inv_diag = np.diagonal(inv, axis1=1, axis2=2).real
    eps = np.sqrt(gnn[:, :, None] * inv_diag[:, None, :] / (1.0 * (n_d - m + 1))) / np.abs(h)
    h[singular] = np.nan
    eps[singular] = np.nan
    return h, eps


def combine_columns(responses: Sequence[FrequencyResponse]) -> FrequencyResponse:
    """Assemble single-experiment responses into one matrix, column by column.

    The seed identifies its 2x2 plant from two experiments: ``data_uch``
    (excitation ``Uch``) gives column ``Uch``, ``data_ucv`` gives column
    ``Ucv``; both measure outputs ``Vph`` and ``Vpv``.

    Parameters
    ----------
    responses : sequence of FrequencyResponse
        Results of :func:`spectral_matrix` with the same frequency grid (same
        ``fs_hz``, ``window_length``, ``noverlap``, ``nfft``), the same
        confidence level, the same output names (any order) and distinct
        input names.

    Returns
    -------
    FrequencyResponse
        Inputs concatenated in the given order; outputs in the first
        response's order. ``n_segments``/``effective_averages`` stay per column.
    """
    items = list(responses)
    if not items:
        raise ValueError("combine_columns needs at least one FrequencyResponse")
    first = items[0]
    for i, r in enumerate(items[1:], start=1):
        for attr in ("fs_hz", "window_length", "noverlap", "nfft", "confidence", "estimator"):
            if getattr(r, attr) != getattr(first, attr):
                raise ValueError(
                    f"response {i} has {attr}={getattr(r, attr)!r} but response 0 has "
                    f"{getattr(first, attr)!r}: columns must share one frequency grid and options"
                )
        if not np.array_equal(r.frequency_hz, first.frequency_hz):
            raise ValueError(f"response {i} is on a different frequency grid from response 0")
        if set(r.output_names) != set(first.output_names):
            raise ValueError(
                f"response {i} has outputs {list(r.output_names)} but response 0 has "
                f"{list(first.output_names)}"
            )
    inputs = [n for r in items for n in r.input_names]
    if len(set(inputs)) != len(inputs):
        raise ValueError(f"input names must be distinct across responses, got {inputs}")
    order = list(first.output_names)
    fields: dict[str, Any] = {
        name: xr.concat([getattr(r, name).sel(output=order) for r in items], dim="input")
        for name in FrequencyResponse._ARRAYS
    }
    variances = [r.frf_variance for r in items]
    names = sorted({k for r in items for k in r.variance_parts})
    parts = {}
    for name in names:
        cols = [(r.variance_parts[name] if name in r.variance_parts
                 else (r.line_variance() if name == "noise" else r.line_variance() * 0.0)
                 ).sel(output=order) for r in items]
        parts[name] = xr.concat(cols, dim="input")
    return FrequencyResponse(
        **fields,
        frf_variance=(None if any(v is None for v in variances) else
                      xr.concat([v.sel(output=order) for v in variances if v is not None],
                                dim="input")),
        variance_parts=parts,
        noise_dof=tuple(float(d) for r in items for d in r.column_dof()),
        column_options={k: v for r in items for k, v in r.column_options.items()},
        estimator=first.estimator,
        confidence=first.confidence,
        window_length=first.window_length,
        noverlap=first.noverlap,
        nfft=first.nfft,
        fs_hz=first.fs_hz,
        n_segments=tuple(k for r in items for k in r.n_segments),
        effective_averages=tuple(n for r in items for n in r.effective_averages),
    )

