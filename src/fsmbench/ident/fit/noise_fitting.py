"""The fitters of the noise model: Welch cross-spectra, Whittle likelihood, lines, drift.

Used by :mod:`fsmbench.ident.noise_model` and :mod:`fsmbench.ident.fit.qd_noise`
(the former's module notes state the rules). The closed-form spectra of the engine's
streams come from :mod:`fsmbench.sim.spectra`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.linalg import block_diag, cho_factor, cho_solve, toeplitz
from scipy.optimize import least_squares, minimize_scalar, nnls

from fsmbench.jsonutil import plain_json
from fsmbench.signal.welch import (
    WelchOptions,
    cross_spectral_density,
    effective_averages,
    hanning,
)
from fsmbench.sim.spectra import flicker_corners, flicker_psd, walk_psd

__all__ = [
    "ERROR_BANDS_HZ",
    "Broadband",
    "Estimate",
    "Spectrum",
    "block_cov",
    "broadband",
    "drift_fit",
    "groups",
    "line_estimate",
    "line_excess",
    "smeared",
    "welch",
    "whittle",
]

FloatArray = NDArray[np.float64]
#: Bands of the fit error [Hz]; the last ends at fs/2.
ERROR_BANDS_HZ = ((0.1, 1.0), (1.0, 10.0), (10.0, 100.0), (100.0, 1000.0), (1000.0, math.inf))
Z_TERM, LR_TERM, Z_LINE, CAUCHY, REJECT = 3.0, 9.0, 5.0, 3.0, 5.0
LINE_HALF_HZ, SCATTER_DB = 3.0, 0.2
DB = 10.0 / math.log(10.0)  # dB per unit relative change


def _num(x: Any) -> float:
    return math.nan if x is None else float(x)


@dataclass(frozen=True)
class Estimate:
    """One fitted value, in the unit its key names.

    Attributes
    ----------
    value : float
        What the engine gets: the estimate, or 0 when not significant.
    estimate, std : float
        The fit's estimate and its standard deviation (NaN: not available).
    significant : bool
        The term passed its rule (module notes); for ``newport_noise_rad``: the
        records disagree with the bench file.
    """

    value: float
    estimate: float
    std: float = math.nan
    significant: bool = True

    def to_json(self) -> dict[str, Any]:
        """``{value, estimate, std, significant}`` (NaN as null)."""
        return dict(plain_json(asdict(self)))

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> Estimate:
        """Inverse of :meth:`to_json`."""
        return cls(_num(d["value"]), _num(d["estimate"]), _num(d["std"]), bool(d["significant"]))



def smeared(fun: Callable[[FloatArray], FloatArray], f: FloatArray,
             t_w: FloatArray) -> FloatArray:
    """Three points at ±sqrt(0.5)/T: the Hann kernel's second moment, 1/(3 T²)."""
    d = math.sqrt(0.5) / t_w
    return (fun(f - d) + fun(f) + fun(f + d)) / 3.0


# --------------------------------------------------------------------------- spectra and fits
@dataclass(frozen=True)
class Spectrum:
    f: FloatArray  # (F,) [Hz]
    s: NDArray[np.complex128]  # (F, 3, 3) one-sided CSD of Vph, Vpv, Va, test-averaged
    nu: float  # effective Welch averages, summed over the tests
    c: float  # bins per independent value
    t_w: float  # window length [s]
    rho2: FloatArray  # |correlation|² of bins 0..15 apart

    @property
    def g(self) -> float:
        return self.nu / self.c


def welch(xs: list[FloatArray], length: int, fs: float) -> Spectrum:
    w = hanning(length)
    opts = WelchOptions.from_matlab(window=w, fs_hz=fs)
    acc: Any = 0.0
    nu = 0.0
    for x in xs:
        s, k = cross_spectral_density(x - x.mean(axis=1, keepdims=True), opts)
        n_d = effective_averages(w, opts.noverlap, k)
        acc, nu = acc + n_d * s, nu + n_d
    w2, n = w**2, np.arange(length)
    e2 = float(np.sum(w2)) ** 2
    rho2 = np.array([abs(np.sum(w2 * np.exp(-2j * np.pi * j * n / opts.nfft))) ** 2
                     for j in range(16)]) / e2
    return Spectrum(opts.frequencies_hz, acc / nu, nu, opts.nfft * float(np.sum(w2**2)) / e2,
                     length / fs, rho2)


def groups(f: FloatArray, g: FloatArray, src: FloatArray) -> NDArray[np.intp]:
    """Group label of every bin: consecutive bins of one spectrum and band, 0.2 dB scatter."""
    labels, n = np.zeros(f.size, dtype=np.intp), 0
    for k in np.unique(src):
        for lo, hi in ERROR_BANDS_HZ:
            if not (idx := np.flatnonzero((src == k) & (f >= lo) & (f < hi))).size:
                continue
            size = max(1, math.ceil(1.0 / (g[idx[0]] * (SCATTER_DB / DB) ** 2)))
            lab = np.arange(idx.size) // size
            if idx.size > size and idx.size % size < size / 2:
                lab[lab == lab[-1]] -= 1  # a short last group joins the previous one
            labels[idx], n = n + lab, n + int(lab[-1]) + 1
    return labels


def whittle(p: FloatArray, x: FloatArray, g: FloatArray, fixed: FloatArray,
             labels: NDArray[np.intp]) -> tuple[FloatArray, FloatArray, float]:
    """Robust Whittle ML of p ≈ fixed + x θ, θ ≥ 0: θ, its covariance, −log L."""
    sd = 1.0 / np.sqrt(np.bincount(labels, g))  # Welch scatter of a group's mean, relative
    pg, fg = np.bincount(labels, p), np.bincount(labels, fixed)
    xg = np.stack([np.bincount(labels, col) for col in x.T], axis=1)
    med = float(np.median(p))
    # Start: Cauchy loss (scale 3 std) on the groups' log ratios: symmetric in dB and
    # redescending, so a shape the model lacks does not pull the model. Whittle punishes
    # a deficit far more than an excess and bends the whole model towards such a shape.
    start = np.r_[1.0, np.full(x.shape[1] - 1, 1e-3)]  # θ / median(P): of order one
    theta = med * least_squares(lambda u: np.log(pg / (fg + xg @ (med * u))) / sd, start,
                                loss="cauchy", f_scale=CAUCHY,
                                bounds=(np.r_[1e-9, np.zeros(x.shape[1] - 1)], np.inf)).x
    keep = np.zeros(p.size, dtype=bool)
    for _ in range(10):  # Whittle on the groups within 5 std of the current fit
        new_keep = (np.abs(np.log(pg / (fg + xg @ theta))) <= REJECT * sd)[labels]
        if np.array_equal(new_keep, keep):
            break
        keep = new_keep
        pk, xk, gk, fk = p[keep], x[keep], g[keep], fixed[keep]
        for _ in range(300):  # Fisher scoring: least squares weighted by g / S²
            w = np.sqrt(gk) / np.maximum(fk + xk @ theta, 1e-12 * med)
            new = nnls(xk * w[:, None], (pk - fk) * w, maxiter=50 * x.shape[1])[0]
            done = np.allclose(new, theta, rtol=1e-10, atol=0.0)
            theta = new
            if done:
                break
    s = np.maximum(fixed + x @ theta, 1e-12 * med)[keep]
    cov = np.linalg.pinv((x[keep] * (g[keep] / s**2)[:, None]).T @ x[keep])
    return theta, cov, float(np.sum(g[keep] * (np.log(s) + p[keep] / s)))


@dataclass(frozen=True)
class Broadband:
    w: float  # white floor [V²/Hz]
    a2: float  # A² [V²]
    cov: FloatArray
    nll: float
    f_min: float
    b2: float  # walk [V²/s]

    def psd(self, f: FloatArray, t_w: FloatArray, fs: float) -> FloatArray:
        fl = (smeared(lambda x: flicker_psd(x, f_min_hz=self.f_min, fs_hz=fs), f, t_w)
              if self.a2 else 0)
        wk = smeared(lambda x: walk_psd(x, fs_hz=fs), f, t_w) if self.b2 else 0
        return self.w + self.a2 * fl + self.b2 * wk + np.zeros_like(f)


def broadband(f: FloatArray, t_w: FloatArray, p: FloatArray, g: FloatArray, src: FloatArray,
               *, fs: float, f_min: float, fit_flicker: bool, a2: float = 0.0,
               b2: float = 0.0) -> Broadband:
    """White (+ 1/f when ``fit_flicker``, else ``a2`` fixed), the walk ``b2`` fixed."""
    fl = smeared(lambda x: flicker_psd(x, f_min_hz=f_min, fs_hz=fs), f, t_w)
    fixed = (b2 * smeared(lambda x: walk_psd(x, fs_hz=fs), f, t_w)
             + (0.0 if fit_flicker else a2 * fl))
    x = np.column_stack([np.ones_like(f), fl] if fit_flicker else [np.ones_like(f)])
    theta, cov, nll = whittle(p, x, g, fixed, groups(f, g, src))
    return Broadband(float(theta[0]), float(theta[1]) if fit_flicker else a2, cov, nll, f_min, b2)


def line_excess(spec: Spectrum, ch: int, f0: float, model: Callable[[FloatArray], FloatArray]
          ) -> tuple[float, float, float]:
    """Excess power of the line at f0 over the local continuum [unit²]; its null and full std."""
    d = np.abs(spec.f - f0)
    sel, side = np.flatnonzero(d <= LINE_HALF_HZ), (d > LINE_HALF_HZ) & (d <= 10.0)
    df = float(spec.f[1] - spec.f[0])
    kappa = float(np.sum(spec.s[side, ch, ch].real) / np.sum(model(spec.f[side])))
    p, s = spec.s[sel, ch, ch].real, kappa * model(spec.f[sel])
    lag = np.minimum(np.abs(sel[:, None] - sel[None, :]), spec.rho2.size - 1)
    r = np.where(lag < spec.rho2.size - 1, spec.rho2[lag], 0.0)
    # Σ S_k S_l |rho_(k-l)|² / nu, plus the continuum's own error, c / (nu n_side).
    var0 = float(s @ r @ s) / spec.nu + float(s.sum()) ** 2 * spec.c / (spec.nu * side.sum())
    var1 = var0 + 2 * float(s @ r @ np.maximum(p - s, 0.0)) / spec.nu  # + line x noise
    e = float(np.sum(p - s)) * df
    return e, df * math.sqrt(var0), df * math.sqrt(var1)


def line_estimate(e: float, sd0: float, sd: float) -> Estimate:
    amp, sig = math.sqrt(2 * max(e, 0.0)), e > Z_LINE * sd0
    return Estimate(amp if sig else 0.0, amp, sd / amp if amp else math.sqrt(2 * sd), bool(sig))


# --------------------------------------------------------------------------- drift
def block_cov(n: int, *, m: int, fs: float, white_var: float, a2: float,
               f_min: float) -> FloatArray:
    """Covariance (n, n) of means of m samples: white + FlickerStream's AR(1) parts, exactly."""
    cov = np.zeros(n)
    cov[0] = white_var / m
    if a2 > 0:
        corners, s2 = flicker_corners(f_min, fs)
        j = np.arange(1, n)
        for fc in corners:
            la = -2.0 * math.pi * fc / fs
            x, y = -math.expm1(la), -math.expm1(m * la)  # 1 - a, 1 - a^m
            cov[0] += a2 * s2 * (m + 2 * math.exp(la) * (m * x - y) / x**2) / m**2
            cov[1:] += a2 * s2 * np.exp((j * m - (m - 1)) * la) * (y / x) ** 2 / m**2
    return np.asarray(toeplitz(cov))


def drift_fit(ys: list[FloatArray], stat: list[FloatArray], t_b: float
           ) -> tuple[Estimate, Estimate]:
    """Slope [V/s] and walk [V/sqrt(s)] from every test's block means ``ys`` (n_i,)."""
    walks = []
    for y in ys:
        j = np.arange(y.size, dtype=float)
        c = np.minimum.outer(j, j) + 0.5  # Cov of a unit walk's means over blocks j, k
        np.fill_diagonal(c, j + 1.0 / 3.0)
        walks.append(t_b * c)
    y, c0, c1 = np.concatenate(ys), block_diag(*stat), block_diag(*walks)
    # An offset per test, one slope shared by the tests.
    x = np.column_stack([block_diag(*[np.ones((v.size, 1)) for v in ys]),
                         np.concatenate([(np.arange(v.size) + 0.5) * t_b for v in ys])])

    def reml(b2: float) -> tuple[float, FloatArray, FloatArray]:
        fac = cho_factor(c0 + b2 * c1)
        ci_x, ci_y = cho_solve(fac, x), cho_solve(fac, y)
        cov = np.asarray(np.linalg.inv(x.T @ ci_x), dtype=float)
        beta = cov @ (x.T @ ci_y)
        logdet = 2 * float(np.sum(np.log(np.diag(fac[0])))) - float(np.linalg.slogdet(cov)[1])
        return -0.5 * (logdet + float(y @ ci_y) - float(beta @ x.T @ ci_y)), beta, cov

    grid = max(float(np.mean([np.var(np.diff(v)) for v in ys])) / t_b, 1e-300) \
        * np.logspace(-6, 2, 33)
    i = int(np.argmax([reml(b2)[0] for b2 in grid]))
    u = float(minimize_scalar(lambda u: -reml(math.exp(u))[0], method="bounded",
                              bounds=(math.log(grid[max(i - 1, 0)]),
                                      math.log(grid[min(i + 1, grid.size - 1)]))).x)
    b, h = math.exp(u / 2), 0.02 * math.exp(u / 2)
    lr = 2 * (reml(b * b)[0] - reml(0.0)[0])
    curv = (reml((b + h) ** 2)[0] - 2 * reml(b * b)[0] + reml((b - h) ** 2)[0]) / h**2
    _, beta, cov = reml(b * b)  # the slope's GLS with the REML covariance, significant or not
    r, r_std = float(beta[-1]), math.sqrt(float(cov[-1, -1]))
    r_sig, b_sig = abs(r) > Z_TERM * r_std, lr > LR_TERM
    return (Estimate(r if r_sig else 0.0, r, r_std, bool(r_sig)),
            Estimate(b if b_sig else 0.0, b, 1 / math.sqrt(-curv) if curv < 0 else math.nan,
                     bool(b_sig)))


