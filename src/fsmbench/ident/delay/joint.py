"""A path's delay fitted together with its poles and the sensor's bandwidth.

The phase of a measured path holds its poles, its pure delay and the lag of
the sensor amplifier in front of the ADC (the 4QD's). Read as one slope
(:mod:`fsmbench.ident.delay.bode`, from the phase alone), they mix. Here each path
is fitted, line by line and weighted by each line's random error, with a
model of exactly those parts as the converters sample them
(:func:`fsmbench.ident.delay.sampled.sampled_response`): its own modes, the hold, a
delay of any fraction of a sample and the sensor's low pass.

The sensor's bandwidth
----------------------
A low pass far above the measured band is only a lag there, the same lag as
a delay of ``group_delay_s`` (``1/wb`` for a first order, ``√2/wb`` for a
Butterworth): no fit can tell them apart, only its magnitude droop inside the
band can. The rule, stated once:

1. fit with the sensor the bench model gives (``quad_diode.bandwidth_hz``, a
   datasheet value; 0 = unlimited);
2. fit again with its bandwidth free, as a first order and as a Butterworth
   (the order that fits better is kept: same number of parameters); when that
   lowers the weighted squared residual by more than ``RESOLVED_LR`` (18.3)
   noise units, the bandwidth is *fitted* and carries its standard deviation.
   The threshold is a likelihood-ratio test corrected for the tests made (the
   largest ratio over two orders and 13 bandwidths, on each of the Newport's
   two axes: 52, Bonferroni): a bench without the sensor is reported to have
   one in at most 0.1 % of identifications (``SENSOR_FALSE_ALARM``);
3. otherwise the bench model's sensor stays and the profile of the fit over
   the bandwidth gives a one-sided 95 % lower bound (where the residual has
   grown by 2.71 units): "the data exclude a sensor slower than this".

The delay is the pure one, the sensor's lag apart, whenever the sensor is
known (fitted or from the bench model); with an unlimited sensor that the
data cannot resolve it includes the sensor's group delay. A plant model
without a sensor block needs the sum, ``effective_delay_s``.

Noise units: the residual is scaled by the fit's own reduced chi-square and
by the number of adjacent lines one Welch window correlates, as the standard
deviations are.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import least_squares
from scipy.stats import chi2 as chi2_dist

from fsmbench.ident.delay.sampled import SensorLowpass, StateSpace3, sampled_response
from fsmbench.ident.frf.response import FrequencyResponse

__all__ = ["RESOLVED_LR", "SENSOR_FALSE_ALARM", "SENSOR_TESTS", "JointFit", "SensorEstimate",
           "bartlett_ratio", "fit_jointly", "hac_factors", "line_std"]

FloatArray = NDArray[np.float64]

#: The stated false-alarm rate: the chance that an identification of a bench whose sensor
#: is the bench model's (none, on the default twin) reports a resolved 4QD amplifier.
SENSOR_FALSE_ALARM = 1e-3
#: Tests one identification makes: the Newport's two axes, each taking the largest
#: likelihood ratio over two orders and the 13 bandwidths scanned. A single test at 99.9 %
#: (10.83) passed on 1 in 50 axes of a sensor-free twin with the LPM: the maximum
#: over 26 candidate models is not chi-square(1).
SENSOR_TESTS = 2 * 2 * 13
#: Likelihood-ratio threshold: chi-square (1 dof) at ``1 - SENSOR_FALSE_ALARM / SENSOR_TESTS``
#: (Bonferroni: the rate per identification is at most ``SENSOR_FALSE_ALARM``), 18.3.
RESOLVED_LR = float(chi2_dist.isf(SENSOR_FALSE_ALARM / SENSOR_TESTS, 1))
#: One-sided 95 % bound of one parameter from a profile (chi-square, 1 dof, 90 % two-sided).
BOUND_LR = 2.71
#: The slowest sensor the bound search considers [Hz]: a 4QD amplifier slower than this
#: would be the dominant dynamics of the bench, not a detail of its paths.
SLOWEST_SENSOR_HZ = 10.0
_BISECTIONS = 8  # the bound to 2^(1/2^8) ~ 0.3 % in bandwidth


@dataclass(frozen=True)
class SensorEstimate:
    """The sensor low pass a joint fit used, and what the data say of it.

    Attributes
    ----------
    order : int
        1 or 2 (Butterworth).
    bandwidth_hz : float
        Bandwidth in the model [Hz]; 0 = unlimited.
    source : str
        ``"fitted"`` (the data resolve it), ``"bench model"`` (the bench
        parameters' value, not resolved), ``"unlimited"`` (no value given,
        not resolved) or ``"Newport"`` (resolved on the Newport's paths and
        used on this one).
    bandwidth_std_hz : float
        Standard deviation when fitted [Hz], else NaN.
    lower_bound_hz : float
        One-sided 95 % lower bound from the fit's profile when not fitted [Hz]
        (NaN when fitted or not tried; 0 when the slowest sensor tried, a quarter
        of the band's top, still fits the data).
    likelihood_ratio : float
        Decrease of the weighted squared residual with the bandwidth free, in
        noise units (> ``RESOLVED_LR``: resolved).
    """

    order: int
    bandwidth_hz: float
    source: str
    bandwidth_std_hz: float = math.nan
    lower_bound_hz: float = math.nan
    likelihood_ratio: float = 0.0

    @property
    def lowpass(self) -> SensorLowpass:
        """The low pass used."""
        return SensorLowpass(bandwidth_hz=self.bandwidth_hz, order=self.order)

    @property
    def group_delay_s(self) -> float:
        """Its low-frequency group delay [s] (0 when unlimited)."""
        return self.lowpass.group_delay_s

    def sentence(self) -> str:
        """What the fit concluded, in words with units."""
        kind = "first-order" if self.order == 1 else "second-order"
        if self.source == "fitted":
            return (f"{kind} sensor bandwidth {self.bandwidth_hz:.0f} ± "
                    f"{self.bandwidth_std_hz:.0f} Hz, resolved by the data (likelihood ratio "
                    f"{self.likelihood_ratio:.1f} above {RESOLVED_LR:.1f}: a false alarm in "
                    f"{100 * SENSOR_FALSE_ALARM:g} % of identifications)")
        if self.source == "Newport":
            return (f"the {kind} sensor resolved on the Newport's paths "
                    f"({self.bandwidth_hz:.0f} Hz) is used")
        used = (f"the bench model's {self.bandwidth_hz:.0f} Hz" if self.source == "bench model"
                else "no sensor low pass")
        if math.isnan(self.lower_bound_hz):
            return f"sensor not estimated on this path: {used} is used"
        bound = (f"the data exclude a {kind} sensor below {self.lower_bound_hz:.0f} Hz (95 %)"
                 if self.lower_bound_hz > 0 else "the data do not bound its bandwidth")
        return f"sensor not resolved in the band: {used} is used; {bound}"

    def summary(self) -> dict[str, Any]:
        """JSON-ready values."""
        return {"order": self.order, "bandwidth_hz": self.bandwidth_hz, "source": self.source,
                "bandwidth_std_hz": self.bandwidth_std_hz, "lower_bound_hz": self.lower_bound_hz,
                "likelihood_ratio": self.likelihood_ratio, "group_delay_s": self.group_delay_s}


@dataclass(frozen=True)
class JointFit:
    """One path fitted with its dynamics, its delay and the sensor (see the module).

    Attributes
    ----------
    parameters : ndarray, shape (P,)
        The path's own parameters (their meaning is the caller's model).
    parameter_std : ndarray, shape (P,)
        Their standard deviations.
    delay_s, delay_std_s : float
        Delay with the hold's half sample [s], the sensor's lag apart when it is known.
    sensor : SensorEstimate
    band_hz : (float, float)
        Lowest and highest line fitted [Hz].
    n_lines : int
    reduced_chi2 : float
        Weighted squared residual per degree of freedom (≈ 1 when the
        model and the lines' error estimates hold).
    fit_error : float
        Rms of ``|H_model − H| / |H|`` over the lines fitted.
    method : str
        How the path was modelled, in words.
    weighted_cost : float
        Sum of the squared weighted residuals (real and imaginary parts) [1].
    stride : int
        Every ``stride``-th line was fitted.
    noise_unit : float
        The cost of one noise unit (the reduced chi-square times the correlated
        lines per fitted line): a difference of costs over it is a likelihood
        ratio, comparable between fits of the same lines.
    """

    parameters: FloatArray
    parameter_std: FloatArray
    delay_s: float
    delay_std_s: float
    sensor: SensorEstimate
    band_hz: tuple[float, float]
    n_lines: int
    reduced_chi2: float
    fit_error: float
    method: str = field(default="joint: own poles, delay and sensor")
    weighted_cost: float = math.nan
    stride: int = 1
    noise_unit: float = math.nan

    @property
    def effective_delay_s(self) -> float:
        """``delay_s`` plus the sensor's group delay [s]: a sensor-free model's delay."""
        return self.delay_s + self.sensor.group_delay_s

    def summary(self) -> dict[str, Any]:
        """JSON-ready values."""
        return {"delay_s": self.delay_s, "delay_std_s": self.delay_std_s,
                "effective_delay_s": self.effective_delay_s, "sensor": self.sensor.summary(),
                "band_hz": list(self.band_hz), "n_lines": self.n_lines,
                "reduced_chi2": self.reduced_chi2, "fit_error": self.fit_error,
                "method": self.method}


def line_std(frf: FrequencyResponse, output: str, input_: str) -> FloatArray:
    """Standard deviation of each line's complex ``H`` (the FRF's own estimate with its
    systematic parts; Bendat & Piersol's for a Welch estimate without), path units."""
    var = frf.line_variance().sel(output=output, input=input_).values
    return np.sqrt(np.asarray(var, dtype=float))


@dataclass(frozen=True)
class _Solution:
    x: FloatArray  # path parameters, then the delay
    cost: float  # sum of squared weighted residuals
    jac: FloatArray


def fit_jointly(f_hz: FloatArray, response: NDArray[np.complex128], sigma: FloatArray, *,
                path: Callable[[FloatArray], StateSpace3], start: FloatArray,
                scale: FloatArray, lower: FloatArray, upper: FloatArray, delay_start_s: float,
                fs_hz: float, sensor: SensorLowpass, correlated_lines: float = 1.0,
                resolve_sensor: bool = True, max_lines: int = 500) -> JointFit:
    """Fit a path, its delay and (when the data resolve it) its sensor's bandwidth.

    Parameters
    ----------
    f_hz : array, shape (F,)
        Lines fitted [Hz].
    response : array, complex, shape (F,)
        Measured ``H`` at those lines.
    sigma : array, shape (F,)
        Standard deviation of each line's complex ``H`` (> 0).
    path : callable
        Path parameters ``(P,)`` → continuous ``(A, B, C)``.
    start, scale, lower, upper : arrays, shape (P,)
        Starting values, typical magnitudes and bounds of the path parameters.
    delay_start_s : float
        Starting delay, hold's half sample included [s].
    fs_hz : float
        Converter rate [Hz].
    sensor : SensorLowpass
        The bench model's sensor (its order is the one fitted; bandwidth 0 = unlimited).
    correlated_lines : float
        Adjacent lines one estimate correlates (≥ 1): the standard deviations
        and the noise units grow by its square root.
    resolve_sensor : bool
        Try the bandwidth free (steps 2–3 of the module's rule).
    max_lines : int
        At most this many lines (every k-th) enter the fit; ``correlated_lines``
        is divided by k (at least 1).
    """
    # Every k-th line: a Welch window correlates neighbours anyway, and the fit's cost
    # (tens of fits for the sensor's profile) grows with the lines.
    stride = max(1, math.ceil(np.size(f_hz) / max_lines))
    f = np.asarray(f_hz, dtype=float)[::stride]
    h = np.asarray(response, dtype=complex)[::stride]
    correlated_lines = max(1.0, correlated_lines / stride)
    t = 1.0 / fs_hz
    n_par = len(start)
    problem = _PathProblem(path=path, f=f, h=h, sig=np.asarray(sigma, dtype=float)[::stride],
                           fs_hz=fs_hz, n_par=n_par, lo=np.concatenate([lower, [0.5 * t]]),
                           hi=np.concatenate([upper, [max(1.0, 100 * delay_start_s)]]),
                           x_scale=np.concatenate([scale, [t]]))
    x_start = np.concatenate([np.asarray(start, dtype=float), [delay_start_s]])
    prior = problem.solve(x_start, sensor)
    m = 2 * f.size
    chi2 = prior.cost / max(1, m - n_par - 1)
    unit = max(chi2, 1e-300) * max(correlated_lines, 1.0)
    best, estimate = prior, SensorEstimate(order=sensor.order, bandwidth_hz=sensor.bandwidth_hz,
                                           source="bench model" if sensor.limited else "unlimited")
    if resolve_sensor:
        best, estimate = _resolve(problem.solve, prior=prior, sensor=sensor, fs_hz=fs_hz,
                                  unit=unit, estimate=estimate, f_max_hz=float(f[-1]))
    std, final_chi2 = _std_as_concluded(problem, best, estimate,
                                        correlated_lines=correlated_lines)
    model = sampled_response(path(best.x[:n_par]), f_hz=f, fs_hz=fs_hz, delay_s=best.x[n_par],
                             sensor=estimate.lowpass)
    return JointFit(parameters=best.x[:n_par].copy(), parameter_std=std[:n_par],
                    delay_s=float(best.x[n_par]), delay_std_s=float(std[n_par]),
                    sensor=estimate, band_hz=(float(f[0]), float(f[-1])), n_lines=int(f.size),
                    reduced_chi2=float(final_chi2),
                    fit_error=float(np.sqrt(np.mean(np.abs((model - h) / h) ** 2))),
                    weighted_cost=float(best.cost), stride=stride,
                    noise_unit=float(max(final_chi2, 1e-300) * max(correlated_lines, 1.0)))


@dataclass(frozen=True, eq=False)
class _PathProblem:
    """One path's weighted least squares over its parameters and the delay (last in ``x``)."""

    path: Callable[[FloatArray], StateSpace3]  # path parameters → continuous (A, B, C)
    f: FloatArray  # lines fitted [Hz]
    h: NDArray[np.complex128]  # measured H at those lines
    sig: FloatArray  # standard deviation of each line's complex H
    fs_hz: float  # converter rate [Hz]
    n_par: int  # path parameters
    lo: FloatArray  # bounds of x
    hi: FloatArray
    x_scale: FloatArray  # typical magnitudes of x

    def residual(self, x: FloatArray, lowpass: SensorLowpass) -> FloatArray:
        """Real, then imaginary parts of ``(H_model − H) / sigma`` with the sensor ``lowpass``."""
        r = (sampled_response(self.path(x[:self.n_par]), f_hz=self.f, fs_hz=self.fs_hz,
                              delay_s=x[self.n_par], sensor=lowpass) - self.h) / self.sig
        return np.concatenate([r.real, r.imag])

    def solve(self, x0: FloatArray, lowpass: SensorLowpass) -> _Solution:
        """The least-squares fit from ``x0`` (clipped to the bounds) with the sensor ``lowpass``."""
        x0 = np.clip(x0, self.lo, self.hi)
        out = least_squares(self.residual, x0, args=(lowpass,), x_scale=self.x_scale,
                            bounds=(self.lo, self.hi))
        return _Solution(x=np.asarray(out.x), cost=float(np.sum(out.fun**2)),
                         jac=np.asarray(out.jac))


def _std_as_concluded(problem: _PathProblem, best: _Solution, estimate: SensorEstimate, *,
                      correlated_lines: float) -> tuple[FloatArray, float]:
    """Standard deviations of the path and the delay with the sensor as concluded.

    Returns them (a fitted bandwidth's last) and the final reduced chi-square.
    ``correlated_lines``: adjacent fitted lines one estimate correlates (≥ 1).
    """
    # A fitted bandwidth is one more column (central difference), so that what it
    # correlates with carries its share.
    jac = best.jac[:, :problem.n_par + 1]
    if estimate.source == "fitted":
        bw, step = estimate.bandwidth_hz, 1e-3 * estimate.bandwidth_hz
        up = problem.residual(best.x, SensorLowpass(bandwidth_hz=bw + step,
                                                    order=estimate.order))
        down = problem.residual(best.x, SensorLowpass(bandwidth_hz=bw - step,
                                                      order=estimate.order))
        jac = np.column_stack([jac, (up - down) / (2 * step)])
    norms = np.linalg.norm(jac, axis=0)
    norms[norms == 0] = 1.0
    js = jac / norms
    final_chi2 = best.cost / max(1, 2 * problem.f.size - jac.shape[1])
    inv = np.linalg.pinv(js.T @ js)
    factor = np.full(jac.shape[1], max(correlated_lines, 1.0))
    if correlated_lines > 1.0:
        factor = hac_factors(inv @ js.T, problem.residual(best.x, estimate.lowpass),
                             correlated_lines)
    cov = inv / np.outer(norms, norms) * final_chi2
    return np.sqrt(np.clip(np.diag(cov) * factor, 0.0, None)), final_chi2


def hac_factors(influence: FloatArray, residual: FloatArray, nominal: float) -> FloatArray:
    """What each parameter's variance is of the independent-lines one, from the residual.

    ``influence`` (P, 2F) maps the real residuals (real parts of the F lines,
    then their imaginary parts, in frequency order) to the parameters' errors;
    each line's contribution ``ψ_k`` (both parts) is summed with Bartlett
    weights over ``±4·nominal`` lines (Newey & West) and divided by ``Σ ψ_k²``.
    A Hann window's lines are correlated *negatively* two apart, so for a
    smooth functional (a delay, a gain over hundreds of lines) the nominal
    factor (the window's equivalent noise bandwidth) was 2-5x pessimistic on
    the twin. Clipped to ``[1/nominal, nominal]``.
    """
    n = residual.size // 2
    psi = influence[:, :n] * residual[None, :n] + influence[:, n:2 * n] * residual[None, n:2 * n]
    ratio = bartlett_ratio(psi, math.ceil(4 * nominal))
    return np.asarray(np.clip(np.where(np.isfinite(ratio), ratio, nominal), 1.0 / nominal,
                              nominal), dtype=float)


def bartlett_ratio(scores: FloatArray, lags: int) -> FloatArray:
    """Each row's long-run variance over its variance (Newey & West, Bartlett weights).

    ``(Σ_k s_k² + 2 Σ_{j=1..L} (1 − j/(L+1)) Σ_k s_k s_{k+j}) / Σ_k s_k²`` for the
    rows of ``scores`` (shape (P, n) or (n,)), ``L = lags`` (at most ``n − 1``);
    NaN for a row of zeros. Shape (P,) (or (1,) for one row).
    """
    s = np.atleast_2d(np.asarray(scores, dtype=float))
    white = np.sum(s**2, axis=1)
    acc = white.copy()
    for j in range(1, min(lags, s.shape[1] - 1) + 1):
        acc += 2.0 * (1.0 - j / (lags + 1)) * np.sum(s[:, :-j] * s[:, j:], axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(white > 0, acc / np.where(white > 0, white, 1.0), np.nan)


def _resolve(solve: Callable[[FloatArray, SensorLowpass], _Solution], *, prior: _Solution,
             sensor: SensorLowpass, fs_hz: float, unit: float, estimate: SensorEstimate,
             f_max_hz: float) -> tuple[_Solution, SensorEstimate]:
    """Steps 2 and 3 of the module's rule: the bandwidth free, else its lower bound."""

    def at(bandwidth_hz: float, x0: FloatArray, order: int) -> _Solution:
        return solve(x0, SensorLowpass(bandwidth_hz=bandwidth_hz, order=order))

    # The bandwidth free, for either order (a first order and a Butterworth droop
    # differently inside the band; the data choose, with the same number of parameters):
    # a scan over a geometric grid (the cost is not convex in the bandwidth: a fast
    # sensor is a flat valley), then a golden-section refinement around the best.
    grid = np.geomspace(max(SLOWEST_SENSOR_HZ, f_max_hz / 4), 50 * fs_hz, 13)
    scans_by_order = {o: [(at(float(bw), prior.x, o), float(bw)) for bw in grid]
                      for o in (1, 2)}
    order = min(scans_by_order, key=lambda o: min(sol.cost for sol, _ in scans_by_order[o]))
    sol_best, bw_best = min(scans_by_order[order], key=lambda item: item[0].cost)
    k = int(np.flatnonzero(grid == bw_best)[0])
    lo_bw, hi_bw = grid[max(k - 1, 0)], grid[min(k + 1, grid.size - 1)]
    for _ in range(_BISECTIONS):
        a, b = math.exp(0.618 * math.log(lo_bw) + 0.382 * math.log(hi_bw)), \
            math.exp(0.382 * math.log(lo_bw) + 0.618 * math.log(hi_bw))
        sa, sb = at(a, sol_best.x, order), at(b, sol_best.x, order)
        if sa.cost < sb.cost:
            hi_bw = b
            if sa.cost < sol_best.cost:
                sol_best, bw_best = sa, a
        else:
            lo_bw = a
            if sb.cost < sol_best.cost:
                sol_best, bw_best = sb, b
    lr = (prior.cost - sol_best.cost) / unit
    if lr > RESOLVED_LR and bw_best < grid[-1]:
        # Standard deviation of the bandwidth from the profile's curvature in 1/bandwidth.
        step = 0.05 * bw_best
        up, down = at(bw_best + step, sol_best.x, order), at(bw_best - step, sol_best.x, order)
        curvature = (up.cost + down.cost - 2 * sol_best.cost) / step**2
        std = math.sqrt(unit / curvature) if curvature > 0 else math.inf
        return sol_best, SensorEstimate(order=order, bandwidth_hz=float(bw_best),
                                        source="fitted", bandwidth_std_hz=std,
                                        likelihood_ratio=float(lr))
    # Not resolved: the bench model's sensor stays; the bound is where the residual has
    # grown by BOUND_LR noise units over the best fit, on the slow side.
    order = sensor.order
    floor = min(sol_best.cost, prior.cost)
    excess = np.array([(s.cost - floor) / unit for s, _ in scans_by_order[order]])
    bound = 0.0
    if excess[0] > BOUND_LR:
        # From the slow end: the first bandwidth the data accept, refined between it
        # and the last one they exclude.
        accepted = np.flatnonzero(excess <= BOUND_LR)
        i = int(accepted[0]) if accepted.size else grid.size - 1
        lo_bw, hi_bw = float(grid[max(i - 1, 0)]), float(grid[i])
        for _ in range(_BISECTIONS):
            mid = math.sqrt(lo_bw * hi_bw)
            if (at(mid, sol_best.x, order).cost - floor) / unit > BOUND_LR:
                lo_bw = mid
            else:
                hi_bw = mid
        bound = hi_bw
    return prior, SensorEstimate(order=order, bandwidth_hz=estimate.bandwidth_hz,
                                 source=estimate.source, lower_bound_hz=bound,
                                 likelihood_ratio=float(max(lr, 0.0)))
