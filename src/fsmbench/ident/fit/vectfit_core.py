"""Vector fitting core: data checks, the pole-relocation and residue steps.

The algorithm and its sources are described in :mod:`fsmbench.ident.fit.vectfit`,
which holds the public entry point, the starting poles, the order search and
the uncertainty; this module holds the iteration itself.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.linalg import lapack
from scipy.optimize import linear_sum_assignment

from fsmbench.ident.fit.vectfit_model import (
    VectorFitOptions,
    real_basis,
    state_blocks,
)

__all__: list[str] = []  # internal to fsmbench.ident.fit.vectfit

# Relaxed VF is abandoned for the classical d~ = 1 when |d~| leaves this range
# (Gustavsen 2006): sigma(s) ~ d~ at high frequency, a tiny d~ makes the new poles
# eig(A - b c~^T / d~) ill-conditioned.
_D_TILDE_RANGE = (1e-8, 1e8)
# A relative rms error below this is at the float64 round-off level of the
# least-squares solves: adding poles cannot improve it, removing a pole that
# keeps the error below it loses nothing.
_RMS_FLOOR = 1e-9
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

def _residue_only(data: _Data, poles: NDArray[np.complex128], asymptote: str) -> _Fit:
    lin = _solve_linear(data, poles, asymptote)
    ssr, rms = _errors(data, _model(data, poles, lin.coef, asymptote))
    return _Fit(poles, lin, ssr, rms, 0, False, ())
