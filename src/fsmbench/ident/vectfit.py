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

import dataclasses
import functools
import math
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla
import scipy.signal as ss
from numpy.typing import ArrayLike, NDArray
from scipy.interpolate import AAA
from scipy.linalg import lapack
from scipy.optimize import linear_sum_assignment

from fsmbench.ident.vectfit_model import (
    Mode,
    VectorFit,
    VectorFitOptions,
    pole_groups,
    real_basis,
    residues_from_coefficients,
    state_blocks,
)

__all__ = ["Mode", "VectorFit", "VectorFitOptions", "vector_fit"]

# Starting poles a = omega (-zeta + j) with zeta = 1 %: lightly damped, as
# Gustavsen & Semlyen (1999) recommend (real part 1/100 of the imaginary part).
_START_DAMPING = 0.01
# Relaxed VF is abandoned for the classical d~ = 1 when |d~| leaves this range
# (Gustavsen 2006): sigma(s) ~ d~ at high frequency, a tiny d~ makes the new poles
# eig(A - b c~^T / d~) ill-conditioned.
_D_TILDE_RANGE = (1e-8, 1e8)
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
# Stop a non-converging pole relocation after this many iterations without a
# lower weighted SSR (it keeps the best iterate anyway).
_STALL = 10
# Row chunks of the tall-skinny QR hold at most this many matrix entries: below
# OpenBLAS's level-2 threading threshold (2304 * 4 = 9216) and L1/L2-cache sized.
_CHUNK_ELEMENTS = 8192


@dataclass(frozen=True)
class _Data:
    """Validated problem, frequency points with zero weight everywhere dropped."""

    f: NDArray[np.float64]  # (F,) Hz
    s: NDArray[np.complex128]  # (F,) rad/s
    h: NDArray[np.complex128]  # (Ne, F), element index i = row * m + col
    w: NDArray[np.float64]  # (Ne, F)
    p: int
    m: int

    @property
    def n_obs(self) -> int:
        """Real residual entries with non-zero weight."""
        return 2 * int(np.count_nonzero(self.w))


@dataclass(frozen=True)
class _Fit:
    poles: NDArray[np.complex128]
    lin: _Linear  # residue-step solution with these poles
    ssr: float
    rms: NDArray[np.float64]  # (Ne,)
    iterations: int
    converged: bool
    history: tuple[float, ...]

    @property
    def coef(self) -> NDArray[np.float64]:
        """Real-basis coefficients ``[c, d, e]`` of every element, (Ne, n + n_asym)."""
        return self.lin.coef


# ----------------------------------------------------------------------------- input handling


def _validate(
    frequency_hz: ArrayLike,
    response: ArrayLike,
    weights: ArrayLike | None,
) -> _Data:
    f = np.asarray(frequency_hz, dtype=float)
    if f.ndim != 1 or f.size < 2:
        raise ValueError(f"frequency_hz must be 1-D with at least 2 points, got shape {f.shape}")
    if not np.all(np.isfinite(f)):
        raise ValueError("frequency_hz contains NaN or inf")
    if f[0] < 0.0:
        raise ValueError(f"frequency_hz must be non-negative, got {f[0]} Hz")
    if np.any(np.diff(f) <= 0.0):
        k = int(np.argmax(np.diff(f) <= 0.0))
        raise ValueError(
            f"frequency_hz must be strictly increasing: f[{k}] = {f[k]} Hz, "
            f"f[{k + 1}] = {f[k + 1]} Hz"
        )
    h = np.asarray(response)
    if not (np.issubdtype(h.dtype, np.number) and not np.issubdtype(h.dtype, np.bool_)):
        raise ValueError(f"response must be numeric, got dtype {h.dtype}")
    h = h.astype(complex)
    if h.ndim == 1:
        h = h[:, None, None]
    if h.ndim != 3 or h.shape[0] != f.size or h.shape[1] == 0 or h.shape[2] == 0:
        raise ValueError(
            f"response must have shape (F,) or (F, p, m) with F = len(frequency_hz) = {f.size}, "
            f"got {np.shape(response)}"
        )
    bad = ~np.isfinite(h)
    if bad.any():
        k, r, c = np.argwhere(bad)[0]
        raise ValueError(
            f"response contains {int(bad.sum())} NaN/inf value(s), first at "
            f"f = {f[k]} Hz, element ({r}, {c})"
        )
    n_f, p, m = h.shape
    if weights is None:
        mag = np.abs(h)
        floor = 1e-12 * mag.max(axis=0, keepdims=True)
        with np.errstate(divide="ignore"):
            w = np.where(floor > 0.0, 1.0 / np.maximum(mag, floor), 1.0)
    else:
        w = np.asarray(weights, dtype=float)
        if w.ndim == 1 and w.size == n_f:
            w = w[:, None, None]
        try:
            w = np.broadcast_to(w, h.shape)
        except ValueError:
            raise ValueError(
                f"weights of shape {np.shape(weights)} cannot be broadcast to the response "
                f"shape {h.shape}"
            ) from None
        if not np.all(np.isfinite(w)):
            raise ValueError("weights contain NaN or inf")
        if np.any(w < 0.0):
            raise ValueError(f"weights must be non-negative, minimum is {w.min()}")
    hw = h.reshape(n_f, p * m).T
    ww = np.array(w.reshape(n_f, p * m).T)
    keep = np.any(ww > 0.0, axis=0)
    if np.count_nonzero(keep) < 2:
        raise ValueError("fewer than 2 frequency points have a non-zero weight")
    f = f[keep]
    return _Data(f=f, s=2j * np.pi * f, h=hw[:, keep], w=ww[:, keep], p=p, m=m)


def _names(names: Sequence[str] | None, count: int, prefix: str, what: str) -> tuple[str, ...]:
    if names is None:
        return tuple(f"{prefix}{k}" for k in range(count))
    out = (names,) if isinstance(names, str) else tuple(str(v) for v in names)
    if len(out) != count:
        raise ValueError(f"{what} has {len(out)} name(s) but the response has {count}")
    if len(set(out)) != len(out):
        raise ValueError(f"{what} contains duplicate names: {out}")
    return out


def _n_asym(asymptote: str) -> int:
    return {"none": 0, "d": 1, "de": 2}[asymptote]


# ----------------------------------------------------------------------------- linear algebra


def _design(s: NDArray[np.complex128], poles: NDArray[np.complex128],
            asymptote: str) -> NDArray[np.complex128]:
    """``[Phi, 1, s]`` (asymptote columns as requested), shape (F, n + n_asym)."""
    cols = [real_basis(s, poles)]
    if asymptote in ("d", "de"):
        cols.append(np.ones((s.size, 1), dtype=complex))
    if asymptote == "de":
        cols.append(s[:, None])
    return np.concatenate(cols, axis=1)


def _r_factors(n_el: int, n_f: int, k: int,
               fill: Callable[[int, NDArray[np.float64]], None]) -> NDArray[np.float64]:
    """``R`` of the QR factorisation of each element's real (2F, k) block, (Ne, k, k).

    ``fill(i, bt)`` writes the *transpose* of element ``i``'s block into a
    reused C-ordered (k, 2F) buffer (column ``j`` of the block is row ``j`` of
    ``bt``: real parts in ``bt[j, :F]``, imaginary parts in ``bt[j, F:]``), so
    that every write is contiguous and ``bt.T`` is the block in Fortran order.
    The block is factorised as a tall-skinny QR (TSQR): LAPACK ``dgeqrf`` on
    row chunks of at most ``_CHUNK_ELEMENTS / k`` rows, then on the stacked
    chunk ``R`` factors. Small chunks stay in cache and below OpenBLAS's
    threading threshold, whose thread synchronisation per Householder
    reflector dominates the cost of a tall matrix with few columns on a
    small or busy machine. Rows of ``R`` beyond ``2F`` are zero.
    """
    out = np.zeros((n_el, k, k))
    rows = 2 * n_f
    bt = np.empty((k, rows))
    buf = bt.T
    chunk = max(2 * k, _CHUNK_ELEMENTS // k)
    starts = range(0, rows, chunk)
    for i in range(n_el):
        fill(i, bt)
        parts = [_geqrf_r(buf[s : s + chunk]) for s in starts] if len(starts) > 1 else [buf]
        r = _geqrf_r(np.vstack(parts)) if len(parts) > 1 else _geqrf_r(buf)
        out[i, : r.shape[0]] = r
    return out


@functools.lru_cache(maxsize=64)
def _upper_mask(m: int, k: int) -> NDArray[np.float64]:
    """0/1 mask of the upper triangle of an (m, k) matrix (cheaper than np.triu per call)."""
    return np.triu(np.ones((m, k)))


def _geqrf_r(a: NDArray[np.float64]) -> NDArray[np.float64]:
    """Upper-triangular ``R`` (min(rows, k), k) of ``a`` (overwrites ``a`` when Fortran-ordered)."""
    qr, _tau, _work, info = lapack.dgeqrf(a, overwrite_a=True)
    if info != 0:
        raise np.linalg.LinAlgError(f"dgeqrf failed with info={info}")
    m = min(a.shape)
    return qr[:m] * _upper_mask(m, a.shape[1])


@dataclass(frozen=True)
class _Linear:
    """Residue-step solution: coefficients, and the scaled ``R`` factor for the covariance."""

    coef: NDArray[np.float64]  # (Ne, na)
    r: NDArray[np.float64]  # (Ne, na, na): R of the column-scaled w [Phi, 1, s]
    scale: NDArray[np.float64]  # (Ne, na) column scales


def _solve_linear(data: _Data, poles: NDArray[np.complex128], asymptote: str) -> _Linear:
    """Residue step: weighted LS with fixed poles, for every element."""
    pa = _design(data.s, poles, asymptote)
    n_el, n_f = data.h.shape
    na = pa.shape[1]
    # column scaling (the columns span decades: 1/(s-a) ~ 1/|a|, s ~ 2 pi f_max)
    scale = np.sqrt(np.einsum("if,fk->ik", data.w**2, np.abs(pa) ** 2))
    scale[scale == 0.0] = 1.0
    pa_t = np.ascontiguousarray(pa.T)
    pa_re, pa_im = pa_t.real, pa_t.imag
    wh = data.w * data.h

    def fill(i: int, bt: NDArray[np.float64]) -> None:
        w = data.w[i][None, :] / scale[i][:, None]
        np.multiply(w, pa_re, out=bt[:na, :n_f])
        np.multiply(w, pa_im, out=bt[:na, n_f:])
        bt[na, :n_f] = wh[i].real
        bt[na, n_f:] = wh[i].imag

    r = _r_factors(n_el, n_f, na + 1, fill)
    coef = np.empty((n_el, na))
    for i in range(n_el):
        coef[i] = np.linalg.lstsq(r[i, :na, :na], r[i, :na, na], rcond=None)[0]
    return _Linear(coef / scale, r[:, :na, :na], scale)


def _model(data: _Data, poles: NDArray[np.complex128], coef: NDArray[np.float64],
           asymptote: str) -> NDArray[np.complex128]:
    return _combine(coef, _design(data.s, poles, asymptote))


def _combine(coef: NDArray[np.float64], basis: NDArray[np.complex128]) -> NDArray[np.complex128]:
    """``coef @ basis.T`` (Ne, F) for real ``coef`` (Ne, k) and complex ``basis`` (F, k).

    Two real products: much faster than numpy's mixed real/complex matmul.
    """
    return (coef @ basis.real.T) + 1j * (coef @ basis.imag.T)


def _canonical(eigs: NDArray[np.complex128]) -> NDArray[np.complex128]:
    """Real poles and conjugate pairs (positive imaginary part first), sorted by ``|a|``."""
    upper = list(eigs[eigs.imag > 0.0])
    lower = eigs[eigs.imag < 0.0]
    items: list[tuple[float, float, list[complex]]] = []
    for a in eigs[eigs.imag == 0.0]:
        items.append((abs(a), 0.0, [complex(a.real, 0.0)]))
    for a in upper:
        items.append((abs(a), a.imag, [complex(a), complex(a).conjugate()]))
    # LAPACK returns exact conjugate pairs for a real matrix; guard anyway.
    for a in lower[len(upper):]:
        items.append((abs(a), 0.0, [complex(a.real, 0.0)]))
    items.sort(key=lambda t: (t[0], t[1]))
    return np.array([v for it in items for v in it[2]], dtype=complex)


def _relocate(data: _Data, poles: NDArray[np.complex128], opts: VectorFitOptions
              ) -> tuple[NDArray[np.complex128], float, NDArray[np.float64]]:
    """One pole-identification step (fast, relaxed VF).

    Returns the zeros of ``sigma(s)`` (the new poles) and, for free, the
    weighted SSR and per-element relative rms error of the residue fit with the
    *current* poles: the ``d~``
    column ``-w H`` comes right after ``w [Phi, 1, s]``, so its diagonal
    ``R`` entry is the norm of the residual of ``w H`` on that basis.
    """
    n = poles.size
    pa = _design(data.s, poles, opts.asymptote)
    phi = pa[:, :n]
    n_el, n_f = data.h.shape
    na = pa.shape[1]
    wh = data.w * data.h
    pa_t = np.ascontiguousarray(pa.T)
    pa_re, pa_im, phi_t = pa_t.real, pa_t.imag, pa_t[:n]

    def fill(i: int, bt: NDArray[np.float64]) -> None:
        # element i: columns [w Phi_a, -w H, -w H Phi] (rows of bt), real over imaginary
        # parts; unknowns [c, d, e, d~, c~]
        w = data.w[i][None, :]
        np.multiply(w, pa_re, out=bt[:na, :n_f])
        np.multiply(w, pa_im, out=bt[:na, n_f:])
        bt[na, :n_f] = -wh[i].real
        bt[na, n_f:] = -wh[i].imag
        prod = wh[i][None, :] * phi_t
        np.negative(prod.real, out=bt[na + 1 :, :n_f])
        np.negative(prod.imag, out=bt[na + 1 :, n_f:])

    r = _r_factors(n_el, n_f, na + n + 1, fill)  # (Ne, na + n + 1, na + n + 1)
    res2 = r[:, na, na] ** 2
    ref2 = np.sum(np.abs(wh) ** 2, axis=1)
    rms = np.sqrt(res2 / np.where(ref2 > 0.0, ref2, 1.0))
    sig = r[:, na:, na:].reshape(-1, n + 1)  # rows that involve only sigma's unknowns [d~, c~]
    d_t = 1.0
    c_t: NDArray[np.float64] | None = None
    if opts.relax:
        lam = math.sqrt(float(ref2.sum())) / data.s.size
        row = lam * np.concatenate([[float(data.s.size)], phi.real.sum(axis=0)])
        a_mat = np.vstack([sig, row])
        rhs = np.zeros(a_mat.shape[0])
        rhs[-1] = lam * data.s.size
        scale = np.linalg.norm(a_mat, axis=0)
        scale[scale == 0.0] = 1.0
        x = np.linalg.lstsq(a_mat / scale, rhs, rcond=None)[0] / scale
        if _D_TILDE_RANGE[0] <= abs(x[0]) <= _D_TILDE_RANGE[1]:
            d_t, c_t = float(x[0]), x[1:]
    if c_t is None:  # classical VF: d~ = 1, the d~ column moves to the right-hand side
        a_mat = sig[:, 1:]
        scale = np.linalg.norm(a_mat, axis=0)
        scale[scale == 0.0] = 1.0
        c_t = np.linalg.lstsq(a_mat / scale, -sig[:, 0], rcond=None)[0] / scale
    a_s, b_s = state_blocks(poles)
    new = np.asarray(np.linalg.eigvals(a_s - np.outer(b_s, c_t) / d_t), dtype=complex)
    if opts.stable:
        new = np.where(new.real > 0.0, -new.real + 1j * new.imag, new)
    # a pole at exactly 0 would make 1/(s - a) infinite at DC
    tiny = 1e-9 * 2.0 * np.pi * data.f[-1]
    new = np.where(np.abs(new) < tiny, -tiny + 0j, new)
    return _canonical(new), float(res2.sum()), rms


def _movement(old: NDArray[np.complex128], new: NDArray[np.complex128], eps: float) -> float:
    """Largest relative pole movement after optimal matching of old to new poles."""
    cost = np.abs(new[:, None] - old[None, :]) / np.maximum(np.abs(old[None, :]), eps)
    rows, cols = linear_sum_assignment(cost)
    return float(cost[rows, cols].max())


def _errors(data: _Data, model: NDArray[np.complex128]) -> tuple[float, NDArray[np.float64]]:
    err = np.abs(data.w * (model - data.h)) ** 2
    ref = np.abs(data.w * data.h) ** 2
    den = ref.sum(axis=1)
    # NaN where the relative error is undefined (no weighted point, or H = 0 there)
    rms = np.where(den > 0.0, np.sqrt(err.sum(axis=1) / np.where(den > 0.0, den, 1.0)), np.nan)
    return float(err.sum()), rms


def _worst(rms: NDArray[np.float64]) -> float:
    """Largest defined per-element relative rms error (0 if none is defined)."""
    finite = rms[np.isfinite(rms)]
    return float(finite.max()) if finite.size else 0.0


def _vf(data: _Data, poles0: NDArray[np.complex128], opts: VectorFitOptions) -> _Fit:
    """Relocate poles until they stop moving, then fit the residues.

    Converged: the largest relative pole movement is below ``opts.tolerance``,
    or the fit error is at the round-off floor (``_RMS_FLOOR``) for two
    successive iterates (surplus poles of an exact fit have no defined position
    and never settle). Otherwise the iteration stops after ``max_iterations``
    or ``_STALL`` iterations without a lower SSR, and the iterate with the
    smallest weighted SSR is returned.
    """
    poles = _canonical(poles0)
    eps = 2.0 * np.pi * max(data.f[0], 1e-3 * data.f[-1]) * 1e-3
    history: list[float] = []
    converged = False
    best: tuple[float, NDArray[np.complex128], int] = (math.inf, poles, 0)
    exact = 0
    for _ in range(opts.max_iterations):
        with np.errstate(all="ignore"):
            new, ssr, rms = _relocate(data, poles, opts)
        if ssr < best[0]:
            best = (ssr, poles, len(history))
        exact = exact + 1 if rms.max() < _RMS_FLOOR else 0
        if exact >= 2:
            converged = True
            break
        if new.size != poles.size or not np.all(np.isfinite(new)):
            break
        if len(history) - best[2] >= _STALL:
            break
        history.append(_movement(poles, new, eps))
        poles = new
        if history[-1] < opts.tolerance:
            converged = True
            break
    fit = _residue_only(data, poles, opts.asymptote)
    if not converged and best[0] < fit.ssr:
        poles, n_it = best[1], best[2]
        history = history[:n_it]
        fit = _residue_only(data, poles, opts.asymptote)
    return dataclasses.replace(fit, iterations=len(history), converged=converged,
                               history=tuple(history))


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


def _residue_only(data: _Data, poles: NDArray[np.complex128], asymptote: str) -> _Fit:
    lin = _solve_linear(data, poles, asymptote)
    ssr, rms = _errors(data, _model(data, poles, lin.coef, asymptote))
    return _Fit(poles, lin, ssr, rms, 0, False, ())


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
