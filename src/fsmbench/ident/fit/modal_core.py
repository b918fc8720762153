"""The engine of the modal fits: separable least squares over each mode's (f0, xi).

The estimators and their reasons are described in :mod:`fsmbench.ident.fit.modal`,
which holds the public entry points, the checks and the designs of each fit; this
module holds what they share: a mode's discrete denominator, the real design
columns, variable projection from a grid start, and the covariance.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import least_squares

__all__: list[str] = []  # internal to fsmbench.ident.fit.modal

_MAX_GRID = 401  # frequency grid points per mode in the initial search
_DAMPING_GRID = (0.25, 0.5, 1.0, 2.0, 4.0)  # multiples of the initial damping searched
_DAMPING_BOUNDS = (1e-7, 0.5)
# Bins each side over which the residual's power is averaged for the covariance: 62 values
# (real and imaginary parts), a relative std of 13 %, over 1 Hz of a 30 s record's DFT.
_SMOOTH_BINS = 15


def _discrete_denominator(q: NDArray[np.complex128], f0: float, xi: float,
                          ts: float) -> NDArray[np.complex128]:
    """``A(q) = (1 - p q)(1 - p* q)`` with ``p = exp(s T)`` of the mode ``(f0, xi)``."""
    w0 = 2.0 * np.pi * f0
    s = complex(-xi * w0, w0 * np.sqrt(max(1.0 - xi * xi, 0.0)))
    p = np.exp(s * ts)
    return 1.0 - 2.0 * p.real * q + abs(p) ** 2 * q * q


def _real_columns(cols: Sequence[NDArray[np.complex128]]) -> NDArray[np.float64]:
    """Columns for real coefficients: ``[Re; Im]`` of each complex basis vector."""
    return np.column_stack([np.concatenate([c.real, c.imag]) for c in cols])


def _complex_columns(cols: Sequence[NDArray[np.complex128]]) -> NDArray[np.float64]:
    """Two real columns per complex coefficient ``a + jb``: ``[Re; Im]`` and ``[-Im; Re]``."""
    out = []
    for c in cols:
        out.append(np.concatenate([c.real, c.imag]))
        out.append(np.concatenate([-c.imag, c.real]))
    return np.column_stack(out)


@dataclass(frozen=True)
class _Problem:
    """Separable least squares ``min || (Y - [V(theta) F] C) W ||`` over theta (2 per mode).

    ``y`` is (2K, R): R targets (outputs or paths) stacked real over imaginary
    parts, sharing one design; ``fixed`` holds the theta-independent columns,
    ``variable(f0, xi)`` the columns of one mode. ``W`` (per target) is set by :func:`_solve`.
    """

    y: NDArray[np.float64]
    fixed: NDArray[np.float64]
    variable: Callable[[float, float], NDArray[np.float64]]
    n_modes: int

    def projected(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        qf, _ = np.linalg.qr(self.fixed)
        return qf, self.y - qf @ (qf.T @ self.y)

    def residual(self, theta: NDArray[np.float64], qf: NDArray[np.float64],
                 y_perp: NDArray[np.float64]) -> NDArray[np.float64]:
        """Residual matrix (2K, R) with the linear parameters eliminated."""
        v = np.column_stack([self.variable(theta[2 * i], theta[2 * i + 1])
                             for i in range(self.n_modes)])
        v = v - qf @ (qf.T @ v)
        norms = np.linalg.norm(v, axis=0)
        v = v / np.where(norms > 0, norms, 1.0)
        coef, *_ = np.linalg.lstsq(v, y_perp, rcond=None)
        return np.asarray(y_perp - v @ coef)

    def linear_fit(self, theta: NDArray[np.float64]) -> _LinearFit:
        """Linear coefficients (variable columns first), shape (n_cols, R), and residual (2K, R)."""
        design = np.column_stack([*(self.variable(theta[2 * i], theta[2 * i + 1])
                                    for i in range(self.n_modes)), self.fixed])
        coef, *_ = np.linalg.lstsq(design, self.y, rcond=None)
        return _LinearFit(np.asarray(coef), np.asarray(self.y - design @ coef))


@dataclass(frozen=True)
class _LinearFit:
    """The linear coefficients of a :class:`_Problem` at fixed ``theta`` and its residual."""

    coef: NDArray[np.float64]  # (n_cols, R), the variable columns first
    residual: NDArray[np.float64]  # (2K, R), real over imaginary parts


@dataclass(frozen=True)
class _Solution:
    """The separable fit's nonlinear parameters and how the optimiser ended."""

    theta: NDArray[np.float64]  # (f0 [Hz], xi) per mode
    cov: NDArray[np.float64]  # their covariance (sandwich)
    weights: NDArray[np.float64]  # per target: the inverse of its residual's noise level
    n_evaluations: int  # residual evaluations of least_squares
    success: bool  # least_squares reported success


def _solve(problem: _Problem, guesses: list[tuple[float, float]], band: tuple[float, float],
           search_fraction: float) -> _Solution:
    """Grid start, weighted VarPro fit: theta (f0, xi)*, cov, weights, nfev, success."""
    qf, y_perp = problem.projected()
    n_out = problem.y.shape[1]
    weights = np.ones(n_out)

    def flat(theta: NDArray[np.float64]) -> NDArray[np.float64]:
        return (problem.residual(theta, qf, y_perp) * weights).ravel()

    theta = np.array([v for g in guesses for v in g], dtype=float)
    for i, (f_init, xi_init) in enumerate(guesses):  # coarse search, one mode at a time
        lo = max(band[0], f_init * (1.0 - search_fraction))
        hi = min(band[1], f_init * (1.0 + search_fraction))
        n_grid = int(min(_MAX_GRID, max(3, np.ceil((hi - lo) / (0.5 * xi_init * f_init)) + 1)))
        best = (np.inf, theta[2 * i], theta[2 * i + 1])
        for f_try in np.linspace(lo, hi, n_grid):
            for scale in _DAMPING_GRID:
                trial = theta.copy()
                trial[2 * i] = f_try
                trial[2 * i + 1] = float(np.clip(xi_init * scale, *_DAMPING_BOUNDS))
                cost = float(np.sum(flat(trial) ** 2))
                if cost < best[0]:
                    best = (cost, trial[2 * i], trial[2 * i + 1])
        theta[2 * i], theta[2 * i + 1] = best[1], best[2]

    def to_x(t: NDArray[np.float64]) -> NDArray[np.float64]:
        x = t.copy()
        x[1::2] = np.log(t[1::2])
        return x

    def to_theta(x: NDArray[np.float64]) -> NDArray[np.float64]:
        t = x.copy()
        t[1::2] = np.exp(x[1::2])
        return t

    lower = np.tile([band[0], np.log(_DAMPING_BOUNDS[0])], problem.n_modes)
    upper = np.tile([band[1], np.log(_DAMPING_BOUNDS[1])], problem.n_modes)
    x_scale = np.array([v for i in range(problem.n_modes)
                        for v in (theta[2 * i] * theta[2 * i + 1], 0.1)])
    n_lin = problem.fixed.shape[1] + problem.variable(*guesses[0]).shape[1] * problem.n_modes
    span = upper - lower
    theta = to_theta(np.clip(to_x(theta), lower + 1e-9 * span, upper - 1e-9 * span))
    nfev, success = 0, True
    for _ in range(2):  # second pass: outputs weighted by their residual noise level
        sol = least_squares(lambda x: flat(to_theta(x)), to_x(theta),
                            bounds=(lower, upper), x_scale=x_scale, xtol=1e-12, ftol=1e-12,
                            gtol=1e-12, method="trf")
        theta, nfev, success = to_theta(sol.x), nfev + int(sol.nfev), success and sol.success
        res = problem.residual(theta, qf, y_perp)
        dof_out = max(res.shape[0] - n_lin - theta.size, 1)
        sigma = np.sqrt(np.sum(res**2, axis=0) / dof_out)
        weights = 1.0 / np.where(sigma > 0, sigma, 1.0)
        if n_out == 1:
            break
    # Covariance of (f0, xi) from a central-difference Jacobian of the projected residual.
    steps = np.array([v for i in range(problem.n_modes)
                      for v in (1e-3 * theta[2 * i] * theta[2 * i + 1], 1e-3 * theta[2 * i + 1])])
    jac = np.empty((flat(theta).size, theta.size))
    for j, h in enumerate(steps):
        dp, dm = theta.copy(), theta.copy()
        dp[j] += h
        dm[j] -= h
        jac[:, j] = (flat(dp) - flat(dm)) / (2.0 * h)
    r = flat(theta)
    cov = _sandwich(problem, theta, r, jac)
    return _Solution(theta, cov, weights, nfev, bool(success))


def _sandwich(problem: _Problem, theta: NDArray[np.float64], r: NDArray[np.float64],
              jac: NDArray[np.float64]) -> NDArray[np.float64]:
    """Covariance of ``theta`` with the residual's variance varying over the band.

    ``(JᵀJ)⁻¹ Jᵀ diag(v) J (JᵀJ)⁻¹``, ``v`` each bin's residual power (real and
    imaginary parts, less the fit's leverage) averaged over ±``_SMOOTH_BINS``
    bins: the noise is white far from a mode, but a compressing sensor's
    distortion peaks at it, where the bins that carry ``(f0, xi)`` are (the
    real-bench twin's 1/f noise, mains and 4QD compression: a constant ``s²``
    made the stds 1.6x optimistic). For a locally white residual it is
    ``s² (JᵀJ)⁻¹``.
    """
    n_rows, n_out = problem.y.shape
    k = n_rows // 2
    res = r.reshape(n_rows, n_out)
    design = np.column_stack([*(problem.variable(theta[2 * i], theta[2 * i + 1])
                                for i in range(problem.n_modes)), problem.fixed])
    qd, _ = np.linalg.qr(design)
    lev = np.sum(qd**2, axis=1)
    lev_bin = np.clip(0.5 * (lev[:k] + lev[k:]), 0.0, 0.9)
    power = 0.5 * (res[:k] ** 2 + res[k:] ** 2) / (1.0 - lev_bin)[:, None]
    width = min(2 * _SMOOTH_BINS + 1, k)
    kernel = np.ones(width)
    norm = np.convolve(np.ones(k), kernel, mode="same")
    smooth = np.column_stack([np.convolve(power[:, o], kernel, mode="same") / norm
                              for o in range(n_out)])
    v = np.concatenate([smooth, smooth], axis=0).ravel()
    bread = np.linalg.pinv(jac.T @ jac)
    meat = jac.T @ (jac * v[:, None])
    return np.asarray(bread @ meat @ bread, dtype=float)
