"""Weighted vector fitting of frequency-response matrices (the seed's ``vectfit3`` step, 2.3 e).

:func:`vector_fit` fits a common-pole rational model

    H(s) = sum_n R_n / (s - a_n) + D + s E,     s = j 2 pi f,

to a ``p x m`` FRF matrix sampled at ``F`` frequencies, minimising the weighted
error ``sum |w (H_fit - H)|^2`` element by element. Implemented from the papers
(no code taken from ``vectfit3.m`` or scikit-rf):

* B. Gustavsen, A. Semlyen, "Rational approximation of frequency domain
  responses by vector fitting", IEEE Trans. Power Delivery 14(3), 1999:
  pole relocation by the zeros of the weighting function ``sigma(s)``,
  real-valued formulation, real basis ``1/(s-a) + 1/(s-a*)``,
  ``j/(s-a) - j/(s-a*)`` for a conjugate pair, new poles
  ``eig(A - b c~^T / d~)``, residues by linear least squares.
* B. Gustavsen, "Improving the pole relocating properties of vector
  fitting", IEEE Trans. Power Delivery 21(3), 2006: relaxed
  non-triviality constraint ``Re sum_k sigma(s_k) = N_s`` with ``d~`` free,
  falling back to ``d~ = 1`` when ``|d~|`` is tiny or huge.
* D. Deschrijver, M. Mrozowski, T. Dhaene, D. De Zutter, "Macromodeling of
  multiport systems using a fast implementation of the vector fitting
  method", IEEE MWCL 18(6), 2008: per-element QR of ``[w Phi, -w H Phi]``,
  keep only the rows of ``R`` that involve the ``sigma`` unknowns, stack those
  (cost linear in the number of elements).

Model order (``n_poles=None``): start from 1 %-damped pole pairs at the peaks of
the mean log-magnitude, add a pair or a real pole at the frequency of largest
error while the Bayesian information criterion (BIC) on the weighted residual
improves, then remove each real pole or pair whose removal the BIC does not
penalise (residues refitted, poles re-relocated).

Standard errors of the poles (``VectorFit.pole_covariance``, ``modes()``):
the converged model is treated as the weighted nonlinear least-squares
estimate in the pole parameters ``theta`` (a real pole, or ``(Re a, Im a)``
of a pair) with the residues, ``D`` and ``E`` eliminated (variable
projection: for each ``theta`` they are re-solved by linear least squares).
The Jacobian ``J`` of that weighted residual with respect to ``theta`` is
computed analytically (Golub & Pereyra 1973, see :func:`_pole_covariance`),
and ``cov = s^2 (J^T J)^-1`` with ``s^2 = SSR / (N_obs - N_params)``: the
Gauss-Newton covariance, valid when the weighted residuals are independent
with equal variance (e.g. ``w = 1/|H|`` and relative measurement noise) and the
noise is small. It describes the spread of the VF estimate as well (checked by
Monte Carlo in the tests: VF's fixed point and the least-squares optimum agree
to well within the standard error at small noise).

Numerics: the real-stacked per-element blocks are factorised by a chunked
tall-skinny QR (LAPACK ``dgeqrf``); columns are scaled to unit norm before
every least-squares solve. Convergence is declared when the largest relative
pole movement drops below ``tolerance`` (or the fit is exact to round-off);
a fit that does not converge returns its lowest-SSR iterate.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence

import numpy as np
import scipy.linalg as sla
import scipy.signal as ss
from numpy.typing import ArrayLike, NDArray
from scipy.interpolate import AAA

from fsmbench.ident.fit.vectfit_core import (
    _canonical,
    _combine,
    _Data,
    _design,
    _Fit,
    _model,
    _n_asym,
    _names,
    _residue_only,
    _validate,
    _vf,
    _worst,
)
from fsmbench.ident.fit.vectfit_model import (
    Mode,
    VectorFit,
    VectorFitOptions,
    pole_groups,
    residues_from_coefficients,
)

__all__ = ["Mode", "VectorFit", "VectorFitOptions", "vector_fit"]

# Starting poles a = omega (-zeta + j) with zeta = 1 %: lightly damped, as
# Gustavsen & Semlyen (1999) recommend (real part 1/100 of the imaginary part).
_START_DAMPING = 0.01
# A relative rms error below this is at the float64 round-off level of the
# least-squares solves: adding poles cannot improve it, removing a pole that
# keeps the error below it loses nothing.
_RMS_FLOOR = 1e-9
# A peak of the mean log-magnitude is a starting resonance if its prominence
# exceeds this (natural-log units, 0.35 ~ 3 dB) and 5 robust noise sigmas.
_MIN_PROMINENCE = 0.35
# AAA relative tolerance used for starting poles when no order is given: a
# starting set only, the order is then chosen by the BIC search.
_AAA_RTOL = 1e-3


# ----------------------------------------------------------------------------- starting poles


def _pair(f_hz: float) -> list[complex]:
    w = 2.0 * np.pi * f_hz
    a = complex(-_START_DAMPING * w, w)
    return [a, a.conjugate()]


def _band(data: _Data) -> tuple[float, float]:
    pos = data.f[data.f > 0.0]
    hi = float(data.f[-1])
    lo = float(pos[0]) if pos.size and pos[0] < hi else hi * 1e-3
    return lo, hi


def _log_poles(data: _Data, count: int, avoid: Sequence[complex] = ()) -> list[complex]:
    """``count`` poles: log-spaced 1 %-damped pairs over the band, a real pole if odd."""
    lo, hi = _band(data)
    out: list[complex] = []
    n_pairs = count // 2
    if n_pairs:
        taken = [abs(a) / (2.0 * np.pi) for a in avoid if a.imag > 0.0]
        grid = np.geomspace(lo, hi, n_pairs + len(taken))
        # keep the grid points farthest (in log-frequency) from the pairs already placed
        dist = np.array([min([abs(math.log(g / t)) for t in taken] or [math.inf]) for g in grid])
        for g in np.sort(grid[np.argsort(-dist, kind="stable")[:n_pairs]]):
            out += _pair(float(g))
    if count % 2:
        out.append(complex(-2.0 * np.pi * math.sqrt(lo * hi), 0.0))
    return out


def _log_magnitude(data: _Data) -> NDArray[np.float64]:
    """Mean over elements of ``log|H|`` where weighted (scale-invariant peak detector)."""
    active = (data.w > 0.0) & (np.abs(data.h) > 0.0)
    logm = np.log(np.where(active, np.abs(data.h), 1.0))
    cnt = active.sum(axis=0)
    return np.asarray(logm.sum(axis=0) / np.maximum(cnt, 1), dtype=float)


def _peak_frequencies(data: _Data) -> list[float]:
    """Frequencies (Hz) of the significant peaks of the mean log-magnitude, most prominent first."""
    g = _log_magnitude(data)
    if g.size < 5:
        return []
    noise = 1.4826 * float(np.median(np.abs(np.diff(g, 2)))) / math.sqrt(6.0)
    # prominence measured within +/- 5 % of the points: ~10x faster than over the whole band
    # on noisy data (many local maxima), and a resonance stands out locally anyway
    idx, props = ss.find_peaks(g, prominence=max(_MIN_PROMINENCE, 5.0 * noise),
                               wlen=max(21, g.size // 10))
    order = np.argsort(-props["prominences"], kind="stable")
    return [float(data.f[idx[k]]) for k in order if data.f[idx[k]] > 0.0]


def _aaa_poles(data: _Data, n_max: int | None) -> list[tuple[float, list[complex]]]:
    """(priority, poles) groups from an AAA fit of a scalar mix of the normalised elements."""
    lo, hi = _band(data)
    mask = np.all(data.w > 0.0, axis=0)
    if np.count_nonzero(mask) < 4:
        mask = np.ones(data.f.size, dtype=bool)
    mag = np.abs(data.h[:, mask])
    scale = np.exp(np.mean(np.log(np.where(mag > 0.0, mag, 1.0)), axis=1))
    mix = np.exp(2.399963j * np.arange(data.h.shape[0]))  # golden-angle phases: no cancellation
    y = (mix[:, None] * data.h[:, mask] / scale[:, None]).sum(axis=0)
    z = 1j * data.f[mask] / hi
    pos = data.f[mask] > 0.0
    z_all = np.concatenate([z, np.conj(z[pos])])
    y_all = np.concatenate([y, np.conj(y[pos])])
    kw: dict[str, float | int] = (
        {"rtol": 1e-13, "max_terms": n_max + 1} if n_max else {"rtol": _AAA_RTOL, "max_terms": 61}
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            approx = AAA(z_all, y_all, **kw)
            poles = approx.poles() * 2.0 * np.pi * hi
            res = approx.residues() * 2.0 * np.pi * hi
        except (ValueError, np.linalg.LinAlgError):
            return []
    out: list[tuple[float, list[complex]]] = []
    for a, r in zip(poles, res, strict=True):
        if not np.isfinite(a) or not 0.1 * 2 * np.pi * lo <= abs(a) <= 10 * 2 * np.pi * hi:
            continue
        a = complex(-abs(a.real), a.imag)
        if a.imag > 1e-3 * abs(a):
            out.append((abs(r) / max(-a.real, 1e-12), [a, a.conjugate()]))
        elif abs(a.imag) <= 1e-3 * abs(a):
            out.append((abs(r) / abs(a), [complex(a.real, 0.0)]))
    out.sort(key=lambda t: -t[0])
    return out


def _initial_poles(data: _Data, opts: VectorFitOptions, n: int | None) -> NDArray[np.complex128]:
    """Starting poles; exactly ``n`` of them when ``n`` is given."""
    method = opts.initial_poles
    groups: list[list[complex]]
    if method == "log":
        return np.array(_log_poles(data, n if n is not None else 2))
    if method == "aaa":
        groups = [g for _, g in _aaa_poles(data, n)]
    else:
        groups = [_pair(f) for f in _peak_frequencies(data)]
        if method == "auto" and not groups and n is None:
            groups = [g for _, g in _aaa_poles(data, None)]
    chosen: list[complex] = []
    for g in groups:
        if n is None or len(chosen) + len(g) <= n:
            chosen += g
    if n is None:
        return np.array(chosen if chosen else _log_poles(data, 2))
    chosen += _log_poles(data, n - len(chosen), avoid=chosen)
    return np.array(chosen)


# ----------------------------------------------------------------------------- model order


def _bic(data: _Data, fit: _Fit) -> float:
    """Bayesian information criterion of a fit (Gaussian weighted residuals).

    Parameters: the ``n`` real pole parameters plus the real coefficients of
    every element. The SSR is floored at the round-off level (``_RMS_FLOOR``):
    below it, fewer parameters always win.
    """
    n_obs = data.n_obs
    floor = _RMS_FLOOR**2 * float(np.sum(np.abs(data.w * data.h) ** 2))
    k = fit.poles.size + fit.coef.size
    return n_obs * math.log(max(fit.ssr, floor, 1e-300)) + k * math.log(n_obs)


def _worst_frequency(data: _Data, fit: _Fit, asymptote: str) -> float:
    err = np.abs(data.w * (_model(data, fit.poles, fit.coef, asymptote) - data.h)) ** 2
    ref = np.maximum((np.abs(data.w * data.h) ** 2).sum(axis=1, keepdims=True), 1e-300)
    e = (err / ref).sum(axis=0)
    if e.size >= 5:
        e = np.convolve(e, np.ones(5) / 5.0, mode="same")  # one noisy point is no resonance
    pos = data.f > 0.0
    return float(data.f[pos][np.argmax(e[pos])]) if pos.any() else float(data.f[-1])


def _without(poles: NDArray[np.complex128], k: int, pair: bool) -> NDArray[np.complex128]:
    return np.delete(poles, [k, k + 1] if pair else [k])




def _prune(data: _Data, fit: _Fit, asymptote: str) -> _Fit:
    """Greedily drop the real pole or pair whose removal costs least, while the BIC does not
    worsen; residues (not poles) refitted at each step. Returns ``fit`` itself if none goes."""
    while True:
        cands = [_residue_only(data, _without(fit.poles, k, pair), asymptote)
                 for k, pair in pole_groups(fit.poles) if fit.poles.size > (2 if pair else 1)]
        if not cands:  # keep at least one pole
            break
        reduced = min(cands, key=lambda t: _bic(data, t))
        if _bic(data, reduced) > _bic(data, fit):
            break
        fit = reduced
    return fit


def _auto_order(data: _Data, opts: VectorFitOptions, max_poles: int) -> _Fit:
    """Order search: grow while the BIC improves, then prune while it does not worsen."""
    start = _initial_poles(data, opts, None)
    if start.size > max_poles:
        start = _canonical(start)[:max_poles]
        if start.size and start[-1].imag > 0.0:  # do not split a pair
            start = start[:-1]
    if start.size == 0:
        start = np.array(_log_poles(data, 1))
    # a generous starting set (AAA on noisy data) is thinned before the first relocation
    start = _prune(data, _residue_only(data, _canonical(start), opts.asymptote),
                   opts.asymptote).poles
    fit = _vf(data, start, opts)
    while fit.poles.size < max_poles and _worst(fit.rms) >= _RMS_FLOOR:
        f_worst = _worst_frequency(data, fit, opts.asymptote)
        trials = [_vf(data, np.concatenate([fit.poles, [complex(-2.0 * np.pi * f_worst)]]), opts)]
        if fit.poles.size + 2 <= max_poles:
            trials.append(_vf(data, np.concatenate([fit.poles, _pair(f_worst)]), opts))
        best = min(trials, key=lambda t: _bic(data, t))
        if _bic(data, best) >= _bic(data, fit):
            break
        fit = best
    # prune, relocate the remaining poles, repeat until nothing is dropped
    while True:
        pruned = _prune(data, fit, opts.asymptote)
        if pruned is fit:
            return fit
        fit = _vf(data, pruned.poles, opts)


# ----------------------------------------------------------------------------- uncertainty


def _basis_derivatives(s: NDArray[np.complex128], poles: NDArray[np.complex128]
                       ) -> list[tuple[list[int], NDArray[np.complex128]]]:
    """Per pole parameter: (basis columns it moves, their derivatives (F, len))."""
    out: list[tuple[list[int], NDArray[np.complex128]]] = []
    for k, pair in pole_groups(poles):
        g1 = 1.0 / (s - poles[k]) ** 2
        if not pair:
            out.append(([k], g1[:, None]))
            continue
        g2 = 1.0 / (s - poles[k + 1]) ** 2
        plus, minus = g1 + g2, 1j * (g1 - g2)
        out.append(([k, k + 1], np.stack([plus, minus], axis=1)))  # d/d Re a
        out.append(([k, k + 1], np.stack([minus, -plus], axis=1)))  # d/d Im a
    return out


def _pole_covariance(data: _Data, fit: _Fit, asymptote: str) -> NDArray[np.float64]:
    """Gauss-Newton covariance of the real pole parameters (variable projection, see module).

    Exact Jacobian of the residual ``r(theta) = -P_perp(theta) w h`` with the
    residues eliminated (Golub & Pereyra 1973): per element
    ``J = P_perp V - Q Z`` with ``V_j = A_j x``, ``Z_j = R^-T A_j^T r``,
    ``A = w [Phi, 1, s] = Q R`` and ``A_j = dA / d theta_j``; since
    ``Q^T P_perp = 0``, ``J^T J = V^T V - (Q^T V)^T (Q^T V) + Z^T Z`` with
    ``Q^T V = R^-T A^T V``, so ``Q`` is never formed.
    """
    poles, lin = fit.poles, fit.lin
    coef, scale = lin.coef, lin.scale
    n = poles.size
    pa = _design(data.s, poles, asymptote)
    r = data.w * (_combine(coef, pa) - data.h)  # (Ne, F) weighted residual
    derivs = _basis_derivatives(data.s, poles)
    v = np.empty((data.h.shape[0], data.f.size, n), dtype=complex)  # A_j x
    u = np.zeros((data.h.shape[0], coef.shape[1], n))  # A_j^T r
    wr = data.w * r
    for j, (cols, dphi) in enumerate(derivs):
        v[:, :, j] = data.w * _combine(coef[:, cols], dphi)
        u[:, cols, j] = wr.real @ dphi.real + wr.imag @ dphi.imag
    # real inner products of complex columns: x^T y = Re(x^H y)
    wv = data.w[:, :, None] * v
    at_v = (pa.conj().T @ wv).real / scale[:, :, None]  # A_s^T V
    r_t_inv = np.linalg.pinv(np.swapaxes(lin.r, 1, 2))  # (R_s^T)^+, rank-safe
    qt_v = r_t_inv @ at_v
    z = r_t_inv @ (u / scale[:, :, None])
    vf = v.reshape(-1, n)
    vtv = vf.real.T @ vf.real + vf.imag.T @ vf.imag
    qtv2 = (np.swapaxes(qt_v, 1, 2) @ qt_v).sum(axis=0)
    jtj = vtv - qtv2 + (np.swapaxes(z, 1, 2) @ z).sum(axis=0)
    dof = data.n_obs - n - coef.size
    if dof <= 0 or not np.all(np.isfinite(jtj)):
        return np.full((n, n), np.nan)
    s2 = float(np.sum(np.abs(r) ** 2)) / dof
    d = np.sqrt(np.abs(np.diag(jtj)))
    d[d == 0.0] = 1.0
    inv = sla.pinvh(jtj / np.outer(d, d))
    return np.asarray(s2 * inv / np.outer(d, d), dtype=float)


# ----------------------------------------------------------------------------- public entry


def vector_fit(
    frequency_hz: ArrayLike,
    response: ArrayLike,
    *,
    weights: ArrayLike | None = None,
    input_names: Sequence[str] | None = None,
    output_names: Sequence[str] | None = None,
    options: VectorFitOptions = VectorFitOptions(),  # noqa: B008 - frozen, immutable default
) -> VectorFit:
    """Fit a common-pole rational model to a frequency-response matrix.

    Parameters
    ----------
    frequency_hz : array_like, float, shape (F,)
        Strictly increasing, non-negative frequencies, Hz.
    response : array_like, complex, shape (F, p, m) or (F,)
        FRF matrix ``H[f, output, input]`` (output units / input units); a 1-D
        array is a SISO response.
    weights : array_like, float, broadcastable to (F, p, m), optional
        Non-negative weights ``w`` of ``|w (H_fit - H)|^2``, per element and
        frequency (a 1-D array of length F applies to every element). A zero
        weight drops the point. Default ``1 / |H|`` per element: relative
        error, so that no element dominates by its magnitude.
    input_names, output_names : sequence of str, optional
        Names of the ``m`` inputs and ``p`` outputs (default ``u0..``, ``y0..``).
    options : VectorFitOptions
        Order, iteration and asymptote options.

    Returns
    -------
    VectorFit
        Poles (rad/s), residues, ``D``, ``E``, convergence record, per-element
        weighted relative rms error and pole covariance.

    Raises
    ------
    ValueError
        On NaN/inf, mismatched shapes, negative weights, non-increasing or
        negative frequencies, duplicate names, or too few weighted points for
        the requested order.
    """
    data = _validate(frequency_hz, response, weights)
    ins = _names(input_names, data.m, "u", "input_names")
    outs = _names(output_names, data.p, "y", "output_names")
    n_asym = _n_asym(options.asymptote)
    counts = np.count_nonzero(data.w, axis=1)
    min_points = int(counts[counts > 0].min())  # an element with no weighted point is left out
    capacity = 2 * min_points - n_asym  # real equations per element minus asymptote unknowns
    if options.n_poles is not None:
        if options.n_poles > capacity:
            raise ValueError(
                f"n_poles={options.n_poles} needs at least {(options.n_poles + n_asym + 1) // 2} "
                f"weighted frequency points per element, an element has only {min_points}"
            )
        fit = _vf(data, _initial_poles(data, options, options.n_poles), options)
    else:
        if capacity < 1:
            raise ValueError(f"an element has only {min_points} weighted frequency point(s)")
        fit = _auto_order(data, options, min(options.max_poles, capacity))
    n = fit.poles.size
    coef = fit.coef.reshape(data.p, data.m, -1).transpose(2, 0, 1)  # (n + n_asym, p, m)
    zero = np.zeros((data.p, data.m))
    return VectorFit(
        poles=fit.poles,
        residues=residues_from_coefficients(fit.poles, coef[:n]),
        d=coef[n] if n_asym >= 1 else zero,
        e=coef[n + 1] if n_asym == 2 else zero,
        input_names=ins,
        output_names=outs,
        iterations=fit.iterations,
        converged=fit.converged,
        options=options,
        rms_error=fit.rms.reshape(data.p, data.m),
        history=fit.history,
        pole_covariance=_pole_covariance(data, fit, options.asymptote),
        frequency_range_hz=(float(data.f[0]), float(data.f[-1])),
    )
