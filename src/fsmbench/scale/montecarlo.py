"""Monte Carlo of the closed-loop repeatability experiment over the plant's uncertainty.

Each *draw* perturbs the twin's plant (``bench.true``) within its uncertainty,
runs the ESRF study's repeatability experiments (section 11: ``data_rep_h`` and
``data_rep_v``, a 1 V 1 Hz Newport sine from 1 s) in closed loop with one
controller, and measures

* the 4QD tracking error rms per axis [rad], as
  :func:`fsmbench.twin.verify.measure_tracking` (the axis moved by its experiment);
* the distance error: rms of ``Va`` about its mean [m], per experiment (it
  holds the ~1 µm the Newport's sine moves the path, repeatable), and the
  ESRF study's non-repeatable part (11.4): ``Va`` minus its mean over the whole
  1 s periods after settling, rms, times ``√(n/(n−1))`` for the mean taken
  from the same ``n`` periods (``nonrep_rms_unbiased_m`` of
  :mod:`fsmbench.budget.repeatability`);
* the margins of the loop on the perturbed *physical* plant: gain, phase and
  modulus margins of ``L_ii = (G Kd)_ii`` with the discrete controller
  ``Kd(e^{jωT})`` and the plant's exact delays, below the Nyquist frequency
  (the design study's discrete margins, :class:`fsmbench.control.loops.DiscreteComparison`);
* the closed loop's spectral radius ``ρ`` (exact discrete loop, the twin's
  stability test) and its slowest time constant ``−T / ln ρ`` [s].

A draw whose loop is unstable (``ρ ≥ 1``) is recorded as such, with NaN metrics.

Each draw is judged against the design's requirements (:class:`Limits`: stable, and
on both axes 6 dB, 30°, modulus 0.4); :meth:`MonteCarloResult.requirements` lists,
per requirement, every draw that breaks it with its noise seed and factors
(:mod:`fsmbench.scale.breaches`), so that a failing plant can be named and run again.

What is drawn (:class:`Ranges`, overridable by a TOML file)
    * Sercalo resonances, uniform in the design's robust set
      (:class:`fsmbench.control.design.DesignOptions` ``frequency_scales``: ±5 %);
    * Sercalo damping ratios, log-uniform over ``damping_scales`` (×0.5 … ×2);
    * 4QD, current-amplifier and Newport gains, uniform ±3 %: the loosest of the
      identification's accuracy targets on gains
      (:data:`fsmbench.twin.compare.TARGETS`: 4QD 1 %, current amplifier 2 %,
      Sercalo and Newport 3 %), so a controller designed on an identified
      plant meets a plant at least as far off as the identification may be;
    * the DAC delay and the Newport's internal delay, uniform within the
      identification's delay targets (± one sample, 0.1 ms), fractional (the
      twin's discretisation takes fractional delays).

Reproducibility
    Draw ``i``'s parameters and noise seed come from
    ``np.random.SeedSequence(ESRF study).spawn(n)[i]`` alone, never from a shared
    generator; the results are sorted by draw index. The same ``seed`` gives
    the same rows whatever the number of workers or the batch size, and the
    first ``m`` draws of a run of ``n > m`` are those of a run of ``m``.

Why not :func:`fsmbench.twin.simulate.simulate_bench`
    It runs the loop compiled for one plant (numba, seconds and a cached file
    per plant); every draw here is a new plant, so the draws run
    :class:`fsmbench.sim.stream.BenchStream` with the generic loop, which is
    bit-identical (the tests compare with :func:`~fsmbench.twin.verify.verify_on_twin`)
    and takes ~0.1 s per 6 s record.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from fsmbench.bench.blocks import physical_plant
from fsmbench.bench.params import Bench
from fsmbench.control.controller import Controller
from fsmbench.control.loops import discrete_axis_margins
from fsmbench.jsonutil import nested, plain_json, stamped
from fsmbench.scale.breaches import Limits, RequirementOutcome, requirement_outcomes
from fsmbench.sim.controller import closed_loop_spectral_radius
from fsmbench.sim.plant import ADC_CHANNELS, bench_discrete
from fsmbench.sim.stream import BenchStream
from fsmbench.twin.draws import (
    PARAMETERS,
    RANGE_OF_PARAMETER,
    Draw,
    Ranges,
    draw_parameters,
    parameter_values,
    perturbed_bench,
)
from fsmbench.twin.experiments import REP_FREQ_HZ, esrf_experiments, with_duration
from fsmbench.version import __version__

__all__ = [
    "METRICS",
    "MONTECARLO_FORMAT",
    "PARAMETERS",
    "RANGE_OF_PARAMETER",
    "SETTLED_TIME_CONSTANTS",
    "Draw",
    "DrawResult",
    "Limits",
    "MonteCarloResult",
    "MonteCarloSetup",
    "Ranges",
    "RequirementOutcome",
    "controller_json",
    "draw_parameters",
    "perturbed_bench",
    "run_draw",
    "run_draws",
    "run_montecarlo",
    "summarise",
]

#: ``montecarlo.json``'s format and version.
#: 2: `bench` and `bench_kind`: the bench the draws move (packaged or identified).
#: 3: `limits` and `requirements`: every draw that breaks each requirement, with its factors.
MONTECARLO_FORMAT = ("fsmbench.montecarlo", 3)

_EXPERIMENTS = (("h", "data_rep_h", "Vph"), ("v", "data_rep_v", "Vpv"))

#: Per-draw metrics: key -> (words for a table, unit shown, factor from SI to it).
METRICS: dict[str, tuple[str, str, float]] = {
    "tracking_error_rms_rad.h": ("tracking error h (4QD, sine and noise)", "µrad rms", 1e6),
    "tracking_error_rms_rad.v": ("tracking error v (4QD, sine and noise)", "µrad rms", 1e6),
    "distance_error_rms_m.h": ("Va about its mean, h run (with the 1 Hz motion)", "nm rms", 1e9),
    "distance_error_rms_m.v": ("Va about its mean, v run (with the 1 Hz motion)", "nm rms", 1e9),
    "distance_nonrepeatable_rms_m.h": ("non-repeatable distance, h run (11.4)", "nm rms", 1e9),
    "distance_nonrepeatable_rms_m.v": ("non-repeatable distance, v run (11.4)", "nm rms", 1e9),
    "gain_margin_db.h": ("gain margin h", "dB", 1.0),
    "gain_margin_db.v": ("gain margin v", "dB", 1.0),
    "phase_margin_deg.h": ("phase margin h", "°", 1.0),
    "phase_margin_deg.v": ("phase margin v", "°", 1.0),
    "modulus_margin.h": ("modulus margin h", "1", 1.0),
    "modulus_margin.v": ("modulus margin v", "1", 1.0),
    "spectral_radius": ("closed-loop spectral radius", "1", 1.0),
    "slowest_time_constant_s": ("slowest closed-loop time constant", "ms", 1e3),
    "settling_time_constants": ("time constants, sine start to metrics", "1", 1.0),
}

#: Fewer time constants than this between the sine's start and the metrics: "not settled"
#: (e^-10 = 5e-5 of the start transient left).
SETTLED_TIME_CONSTANTS = 10.0


# ----------------------------------------------------------------------------- controllers


def controller_json(controller: Controller) -> dict[str, Any]:
    """``montecarlo.json``'s controller: name, source, order, sample time, 4QD gains."""
    gd = controller.gd
    return plain_json({"name": controller.name, "source": controller.source,
                       "states": controller.n_states, "ts_s": controller.ts_s,
                       "gd_v_per_rad": {"h": gd[0], "v": gd[1]}})


# ----------------------------------------------------------------------------- one draw


@dataclass(frozen=True, eq=False)
class MonteCarloSetup:
    """What every draw shares (sent once to each worker).

    Attributes
    ----------
    bench : Bench
        The bench the draws move: the packaged twin (its ``true`` physics) or an
        identified bench (its identified plant).
    controller : Controller
        The discrete controller of every draw, with its 4QD gains (``u = -K Vp / Gd``).
    ranges : Ranges
    duration_s, settle_s : float
        Record length and the start left out of the metrics [s]. Default 6 s
        and 2 s: the nominal loop's slowest closed-loop time constant is 56 ms
        (``−T / ln ρ``, ``ρ = 0.99822``), so the 1 s between the sine's start
        and the metrics holds 18 of them (``e^−18``: 1.5e-8 of the start
        transient left); 4 whole periods remain for the rms and the period
        mean. Each row records its own number of time constants.
    limits : Limits
        What each draw is judged against (default the design's requirements:
        6 dB, 30°, modulus 0.4); the simulation does not depend on it.
    """

    bench: Bench
    controller: Controller
    ranges: Ranges = field(default_factory=Ranges)
    duration_s: float = 6.0
    settle_s: float = 2.0
    limits: Limits = field(default_factory=Limits)

    def to_json(self) -> dict[str, Any]:
        """The bench drawn around, controller, ranges, record length, limits."""
        return plain_json({"bench": self.bench.label,
                           "bench_kind": "identified" if self.bench.is_identified
                           else "packaged",
                           "controller": controller_json(self.controller),
                           "ranges": self.ranges.to_json(), "duration_s": self.duration_s,
                           "settle_s": self.settle_s, "limits": self.limits.to_json()})


@dataclass(frozen=True)
class DrawResult:
    """One draw's plant and what the loop did on it.

    Attributes
    ----------
    index, noise_seed : int
    stable : bool
        Closed-loop spectral radius below 1.
    factors : dict
        The draw (:data:`PARAMETERS` keys).
    parameters : dict
        The drawn plant's values, SI (keys like ``sercalo.resonance_hz.h``).
    metrics : dict
        :data:`METRICS` keys, SI; NaN for an unstable draw (except the spectral radius).
    """

    index: int
    noise_seed: int
    stable: bool
    factors: Mapping[str, float]
    parameters: Mapping[str, float]
    metrics: Mapping[str, float]

    def to_json(self) -> dict[str, Any]:
        """One row of ``montecarlo.json``: dotted keys nested, (h, v) pairs as objects."""
        return plain_json({"index": self.index, "noise_seed": self.noise_seed,
                           "stable": self.stable, "factors": nested(self.factors),
                           "parameters": nested(self.parameters),
                           "metrics": nested(self.metrics)})


def _margins(bench: Bench, choice: Controller) -> dict[str, float]:
    """Gain, phase and modulus margins of ``L_ii = (G Kd)_ii`` below Nyquist (exact delays)."""

    plant = (physical_plant(bench.true, source="drawn") if bench.model is None
             else bench.model.plant)
    margins = discrete_axis_margins(plant, a=choice.a, b=choice.b, c=choice.c, d=choice.d,
                                    ts_s=choice.ts_s)
    out: dict[str, float] = {}
    for axis, m in margins.items():
        out[f"gain_margin_db.{axis}"] = m.gain_margin_db
        out[f"phase_margin_deg.{axis}"] = m.phase_margin_deg
        out[f"modulus_margin.{axis}"] = m.modulus_margin
    return out


def _nonrepeatable_rms(va: np.ndarray, *, period: int) -> float:
    """Rms of ``va`` minus its mean over whole periods of ``period`` samples, unbiased [m]."""
    m = va.size // period
    if m < 2:
        return math.nan
    periods = va[:m * period].reshape(m, period)
    rest = periods - periods.mean(axis=0)[None]
    return float(np.sqrt(np.mean(rest**2) * m / (m - 1)))


def run_draw(draw: Draw, setup: MonteCarloSetup) -> DrawResult:
    """Simulate one draw: stability, tracking and distance errors, margins.

    The repeatability experiments run as :func:`fsmbench.twin.simulate.simulate_experiment`
    runs them (same streams, same noise seeds), with the generic loop.
    """

    bench = perturbed_bench(setup.bench, draw.factors)
    p = bench.true
    plant = bench_discrete(bench)
    dk = setup.controller.feedback
    rho = closed_loop_spectral_radius(plant, dk, n_adc=len(ADC_CHANNELS))
    metrics = dict.fromkeys(METRICS, math.nan)
    metrics["spectral_radius"] = rho
    stable = rho < 1.0
    if stable:
        tau = -p.converter.ts_s / math.log(rho)
        metrics["slowest_time_constant_s"] = tau
        specs = {s.name: s for s in with_duration(
            [s for s in esrf_experiments() if s.name in {e for _a, e, _v in _EXPERIMENTS}],
            duration_s=setup.duration_s)}
        fs = p.converter.fs_hz
        gd = bench.nominal.quad_diode.gain_v_per_rad
        starts = [ex.start_s for s in specs.values() for ex in s.excitations]
        metrics["settling_time_constants"] = (setup.settle_s - max(starts)) / tau
        for axis, exp, vp in _EXPERIMENTS:
            spec = specs[exp]
            stream = BenchStream(p, seed=draw.noise_seed, name=spec.name,
                                 compensation_unit=spec.compensation_unit,
                                 shielding=spec.shielding, controller=dk,
                                 excitations=spec.excitations, plant=plant, specialise=False)
            out = stream.run(round(spec.duration_s * fs))
            t = np.arange(out.adc.shape[0]) / fs  # the recording's time axis
            keep = t >= t[0] + setup.settle_s
            e = out.signal(vp)[keep] / gd[axis]
            metrics[f"tracking_error_rms_rad.{axis}"] = float(np.sqrt(np.mean((e - e.mean())**2)))
            va = out.signal("Va")[keep]
            metrics[f"distance_error_rms_m.{axis}"] = float(np.sqrt(np.mean((va - va.mean())**2)))
            metrics[f"distance_nonrepeatable_rms_m.{axis}"] = _nonrepeatable_rms(
                va, period=round(fs / REP_FREQ_HZ))
        metrics.update(_margins(bench, setup.controller))
    return DrawResult(index=draw.index, noise_seed=draw.noise_seed, stable=bool(stable),
                      factors=dict(draw.factors), parameters=parameter_values(
                          p, identified=None if bench.model is None else bench.model.values),
                      metrics=metrics)


def run_draws(draws: Sequence[Draw], setup: MonteCarloSetup) -> list[DrawResult]:
    """Run a batch of draws in order (what one Dask task does)."""
    return [run_draw(d, setup) for d in draws]


# ----------------------------------------------------------------------------- many draws


@dataclass(frozen=True, eq=False)
class MonteCarloResult:
    """Every draw of a run, sorted by index, and its setup.

    Attributes
    ----------
    seed : int
    setup : MonteCarloSetup
    draws : tuple of DrawResult
        Sorted by ``index``.
    """

    seed: int
    setup: MonteCarloSetup
    draws: tuple[DrawResult, ...]

    def metric(self, key: str) -> np.ndarray:
        """One metric over the draws, shape (n,), SI (NaN for unstable draws)."""
        return np.array([d.metrics[key] for d in self.draws], dtype=float)

    def requirements(self) -> tuple[RequirementOutcome, ...]:
        """Per requirement of ``setup.limits``, every draw that breaks it (stability first)."""
        return requirement_outcomes(self.draws, limits=self.setup.limits)

    def to_json(self) -> dict[str, Any]:
        """``montecarlo.json``'s content: summary, setup and one row per draw."""

        name, version = MONTECARLO_FORMAT
        s = summarise(self)
        return stamped(plain_json({
            "fsmbench_version": __version__, "seed": self.seed, "n": len(self.draws),
            **self.setup.to_json(), "quantiles": nested(s["quantiles"]),
            "fraction_unstable": s["fraction_unstable"], "unstable_draws": s["unstable_draws"],
            "unsettled_draws": s["unsettled_draws"],
            "worst_draws": [d.to_json() for d in s["worst_draws"]],
            "requirements": [r.to_json() for r in self.requirements()],
            "metric_descriptions": nested({k: f"{w} [{u}]" for k, (w, u, _f)
                                           in METRICS.items()}),
            "parameter_descriptions": nested(PARAMETERS),
            "draws": [d.to_json() for d in self.draws]}), format=name, version=version)


def _severity(d: DrawResult) -> tuple[int, float]:
    """Sort key, worst first: unstable draws, then the larger tracking error (either axis)."""
    if not d.stable:
        return (0, -d.metrics["spectral_radius"])
    return (1, -max(d.metrics["tracking_error_rms_rad.h"], d.metrics["tracking_error_rms_rad.v"]))


def summarise(result: MonteCarloResult, *, worst: int = 5) -> dict[str, Any]:
    """Quantiles of each metric over the stable draws, the unstable fraction, the worst draws.

    Returns
    -------
    dict
        ``quantiles``: ``{metric: {p5, p50, p95, min, max, n}}`` (SI);
        ``fraction_unstable``, ``unstable_draws``; ``unsettled_draws``: stable
        draws with fewer than :data:`SETTLED_TIME_CONSTANTS` between the sine's
        start and the metrics; ``worst_draws`` (DrawResult): the ``worst`` rows ranked by
        :func:`_severity` (unstable first, then the larger tracking error).
    """
    quantiles: dict[str, dict[str, float]] = {}
    for key in METRICS:
        x = result.metric(key)
        x = x[np.isfinite(x)]
        if x.size == 0:
            quantiles[key] = {"p5": math.nan, "p50": math.nan, "p95": math.nan,
                              "min": math.nan, "max": math.nan, "n": 0}
            continue
        p5, p50, p95 = (float(v) for v in np.quantile(x, [0.05, 0.5, 0.95]))
        quantiles[key] = {"p5": p5, "p50": p50, "p95": p95, "min": float(x.min()),
                          "max": float(x.max()), "n": int(x.size)}
    n = len(result.draws)
    unstable = sum(not d.stable for d in result.draws)
    ranked = sorted(result.draws, key=lambda d: (*_severity(d), d.index))
    unsettled = sum(d.stable and not d.metrics["settling_time_constants"]
                    >= SETTLED_TIME_CONSTANTS for d in result.draws)
    return {"quantiles": quantiles, "fraction_unstable": unstable / n if n else math.nan,
            "unstable_draws": unstable, "unsettled_draws": unsettled,
            "worst_draws": ranked[:worst]}


def _batches(draws: Sequence[Draw], size: int) -> list[list[Draw]]:
    return [list(draws[i:i + size]) for i in range(0, len(draws), size)]


def run_montecarlo(setup: MonteCarloSetup, *, n: int, seed: int, client: Any = None,
                   batch_size: int | None = None,
                   progress: Callable[[str], None] | None = None) -> MonteCarloResult:
    """Run ``n`` draws, in this process or on a Dask cluster.

    Parameters
    ----------
    setup : MonteCarloSetup
    n : int
        Number of draws.
    seed : int
        Root of every draw's :class:`numpy.random.SeedSequence`.
    client : distributed.Client, optional
        Run the batches on its cluster (``client.map``); ``None``: here, one
        draw after the other (the reference).
    batch_size : int, optional
        Draws per Dask task; default about four tasks per worker, at most 20
        draws (~8 s) per task, so progress shows and the load balances.
    progress : callable, optional
        Called with a short message after each batch.

    Returns
    -------
    MonteCarloResult
        The same for the same ``seed`` and ``setup`` whatever ``client`` and ``batch_size``.
    """
    draws = draw_parameters(seed=seed, n=n, ranges=setup.ranges)
    results: list[DrawResult] = []
    if client is None:
        for d in draws:
            results.append(run_draw(d, setup))
            if progress is not None and (d.index + 1) % 10 == 0:
                progress(f"{d.index + 1}/{n} draws")
    else:
        from distributed import as_completed

        workers = max(1, len(client.scheduler_info().get("workers", {})))
        size = batch_size or max(1, min(20, math.ceil(n / (4 * workers))))
        # Workers need the discrete controller only (a control.StateSpace does not pickle).
        light = dataclasses.replace(setup, controller=dataclasses.replace(setup.controller,
                                                                          continuous=None))
        shared = client.scatter(light, broadcast=True)
        futures = client.map(run_draws, _batches(draws, size), setup=shared, pure=False)
        for future in as_completed(futures):
            results.extend(future.result())
            if progress is not None:
                progress(f"{len(results)}/{n} draws")
    results.sort(key=lambda r: r.index)
    return MonteCarloResult(seed=seed, setup=setup, draws=tuple(results))
