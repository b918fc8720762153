"""Sercalo identification error against measurement time: noise + Welch, noise + LPM, multisine.

    python benchmarks/bench_measure.py [--seeds 3] [--lengths 2 5 10 20 30 60]
                                       [--multisines full:0.02 full:0.01 odd:0.005]
                                       [--limit-row] [--no-refine]

On the digital twin with every real-bench feature on
(:func:`fsmbench.bench.params.real_bench`, 10 kHz), for each measurement time
``T`` per axis (the seconds of excitation on ``Uch``, and the same on ``Ucv``;
the seed's 1 s with the Sercalo off comes before, as in ``data_uch``), each
seed and each method, the Sercalo-axis records are simulated and identified
as ``fsmbench identify`` does; the 4QD calibrations (``data_cal_pd_h/v``,
11 s, the seed's) are simulated once per seed and shared by every method.
The methods:

- ``noise + Welch``: the twin's own ``data_uch``/``data_ucv`` (white noise,
  20 mV rms, the seed's), ``IdentifyOptions(frf="welch")`` with the seed's
  coherence weights: the seed's way;
- ``noise + LPM``: the same records, ``frf="lpm", weights="variance"``;
- ``multisine + periodic``: a crest-factor-minimised multisine on ``Uch``
  and one on ``Ucv`` (``fsmbench.excite.design_multisine``, 1-2000 Hz at
  1 Hz; 5 Hz when ``T`` holds fewer than 4 periods of 1 s, as the estimator
  drops one period as the transient and needs two more: the 2 s rows of the
  multisines are on 5 Hz lines, coarse for modes 0.5-1 Hz wide), played in
  ``data_uch``/``data_ucv`` from 1 s for ``T`` seconds
  (:func:`fsmbench.twin.experiments.played_experiment`),
  ``frf="periodic", weights="variance"``, for each ``GRID:RMS`` of
  ``--multisines``. The defaults:

  * ``full:0.02``, every line at the noise's 20 mV rms (equal input power;
    the multisine puts it all in 1-2000 Hz where the white noise spreads it
    to 5 kHz, so the beam moves more: Vph 0.22 V rms against 0.15 V). The
    naive design: its lines include the mains harmonics (50 Hz multiples),
    coherent with a 1 s period, so periodic averaging keeps them as a bias
    of tiny variance; and the 4QD (an error function, 2 % compressed at the
    calibration's 0.33 V swing) compresses the beam's larger motion, whose
    odd-order intermodulation lands on the excited lines too. Both are
    biases the estimate's variance does not show (chi2 per dof ~40 on one
    seed at 10 s);
  * ``full:0.01``, the same at 10 mV: about the noise's beam motion (Vph
    0.11 V, Vpv 0.10 V rms), a quarter of the compression's intermodulation;
  * ``odd:0.005``, odd lines only (at 1, 5 and 25 Hz the mains harmonics are
    even lines, left free) at 5 mV, where the 4QD is nearly linear (Vph
    0.06 V rms, 0.15 V peak, inside the calibration's 0.33 V swing): the
    design a real bench calls for (chi2 per dof 1.2 on the same seed; a full
    grid at 5 mV loses the v axis to the mains lines: fit 96 % off). Lower
    power, so it shows what the estimator and the design do, not the power.

  All are far inside the converters' ranges: the check of
  ``fsmbench.excite.limits`` (converters only) allows 41 mV on the nominal
  model; ``--limit-row`` adds a full-grid row at that level.

Each method runs twice: the frequency-domain estimator and fit alone
(``refine_modes=False``, the point of the comparison: 1 s Welch windows
widen modes ~1 Hz wide and bias their damping up) and the full pipeline
(``refine_modes=True``: each mode's frequency and damping re-estimated from
the time records), rows marked ``+ refinement`` (``--no-refine`` skips them).
The same run seed gives the same bench noise in every method (each noise
source draws from its own stream keyed by experiment and source).

How to read the table: errors are the median over the seeds of
``|identified / true - 1|`` in percent, against the truth the twin run
returns (:func:`fsmbench.twin.compare.comparison_rows`): the Sercalo's
resonance, damping ratio and DC gain per axis (h, v). A failed
identification is counted as an infinite error and named below the table.
The last lines give, per method, the shortest ``T`` whose median damping
error is at most 5 % on both axes (``-`` when no length tried reaches it).

Default run: 3 seeds x 6 lengths x 5 methods x 2: 6.5 minutes measured on
a loaded 2-core machine (2.5 of simulation, 4 of identification).
No assertion: numbers, not verdicts.
"""

from __future__ import annotations

import argparse
import datetime as dt
import math
import platform
import statistics
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, cast

import numpy as np
import xarray as xr

from fsmbench.bench.params import Bench, real_bench
from fsmbench.excite.design import ExcitationDesign, GridKind, design_multisine
from fsmbench.excite.limits import converter_peaks
from fsmbench.ident.pipeline import IdentifyOptions, identify
from fsmbench.sim.discretize import DiscretePlant
from fsmbench.sim.plant import twin_discrete
from fsmbench.twin.compare import comparison_rows
from fsmbench.twin.experiments import UC_NOISE_RMS_V, esrf_experiments, played_experiment
from fsmbench.twin.simulate import simulate_bench, simulate_experiment

CAL = ["data_cal_pd_h", "data_cal_pd_v"]
AXIS_EXPERIMENT = {"Uch": "data_uch", "Ucv": "data_ucv"}
QUANTITIES = (("resonance_hz", "res"), ("damping_ratio", "damp"), ("dc_gain_v_per_a", "gain"))
BAND_HZ = (1.0, 2000.0)
# The estimator drops one period as the transient and needs two more for the noise estimate;
# one more keeps the noise estimate's degrees of freedom off its minimum.
MIN_PERIODS = 4
DAMPING_GOAL = 0.05  # the 5 % damping error
# Full grid at the noise's rms (equal input power), odd grid at a quarter of it (see above).
DEFAULT_MULTISINES = [f"full:{UC_NOISE_RMS_V:g}", f"full:{UC_NOISE_RMS_V / 2:g}",
                      f"odd:{UC_NOISE_RMS_V / 4:g}"]


@dataclass(frozen=True)
class Method:
    """One row group of the table: which records and which estimator."""

    label: str
    records: str  # "noise" or "multisine"
    frf: str
    weights: str
    refine: bool
    rms_v: float = 0.0
    grid: str = "full"


def _errors(result: Any, truth: Mapping[str, Any], bench: Bench) -> dict[str, float]:
    """``|identified / true - 1|`` of the six Sercalo quantities; inf when not identified."""
    rows = {r.key: r for r in comparison_rows(result.to_json(), reference=truth, bench=bench)}
    out = {}
    for axis in "hv":
        for q, short in QUANTITIES:
            row = rows.get(f"sercalo.{axis}.{q}")
            out[f"{axis}.{short}"] = (math.inf if row is None
                                      else abs(row.identified / row.reference - 1.0))
    return out


class Runner:
    """Identifies one set of records with one method; collects failures."""

    def __init__(self, bench: Bench) -> None:
        self.bench = bench
        self.failures: list[str] = []

    def errors(self, method: Method, recordings: Mapping[str, xr.Dataset],
               truth: Mapping[str, Any], *, tag: str) -> dict[str, float]:
        """Errors of ``method`` on ``recordings`` (see the module notes)."""
        opts = IdentifyOptions(frf=method.frf,  # type: ignore[arg-type]
                               weights=method.weights,  # type: ignore[arg-type]
                               refine_modes=method.refine)
        result = identify(recordings, bench=self.bench, options=opts, source="twin")
        reason = result.skipped.get("sercalo", "")
        if result.sercalo is None:
            self.failures.append(f"{method.label}, {tag}: {reason}")
        else:
            used = result.to_json()["diagnostics"]["frf_estimator"]["sercalo"]
            if used != method.frf:
                self.failures.append(f"{method.label}, {tag}: estimator {used} was used")
        return _errors(result, truth, self.bench)


Cache = dict[tuple[str, float, str], ExcitationDesign]


def _multisine_period(*, inp: str, resolution_hz: float, fs_hz: float, grid: GridKind,
                      cache: Cache) -> ExcitationDesign:
    """One period at 1 V rms (scaled per method; the design is linear in amplitude)."""
    key = (inp, resolution_hz, grid)
    if key not in cache:
        cache[key] = design_multisine(input=inp, band_hz=BAND_HZ, resolution_hz=resolution_hz,
                                      amplitude_rms_v=1.0, fs_hz=fs_hz, seed=0, periods=1,
                                      grid=grid)
    return cache[key]


def _resolution_hz(length_s: float, resolution_hz: float) -> float:
    """The asked resolution, coarsened 5-fold until ``T`` holds :data:`MIN_PERIODS` periods.

    5-fold: at 1 Hz, 5 Hz, 25 Hz the mains harmonics (multiples of 50 Hz) stay even lines,
    which an odd grid leaves out.
    """
    r = resolution_hz
    while length_s * r < MIN_PERIODS - 1e-9:
        r *= 5.0
    return r


def _limit_rms_v(bench: Bench, resolution_hz: float, grid: GridKind, cache: Cache) -> float:
    """Largest rms [V] ``excite`` allows on both axes: the converters in the nominal model
    (its gains are the larger ones) and the 4QD's linear range in the true one (the
    real bench's compression is a ``[true]`` feature)."""
    fs = bench.nominal.converter.fs_hz
    fits = []
    for inp in AXIS_EXPERIMENT:
        d = _multisine_period(inp=inp, resolution_hz=resolution_hz, fs_hz=fs, grid=grid,
                              cache=cache)
        fits.append(converter_peaks(d, params=bench.nominal).fitting_amplitude_rms_v())
        fits.append(converter_peaks(d, params=bench.true, model="true")
                    .fitting_amplitude_rms_v())
    return min(fits)


def _played_records(bench: Bench, plant: DiscretePlant, *, rms_v: float, grid: GridKind,
                    length_s: float, resolution_hz: float, seed: int,
                    cache: Cache) -> dict[str, xr.Dataset]:
    fs = bench.true.converter.fs_hz
    r = _resolution_hz(length_s, resolution_hz)
    out = {}
    for inp, name in AXIS_EXPERIMENT.items():
        one = _multisine_period(inp=inp, resolution_hz=r, fs_hz=fs, grid=grid,
                                cache=cache).one_period()
        n_periods = round(length_s * r)
        spec = played_experiment(channel=inp, samples_v=rms_v * np.tile(one, n_periods),
                                 fs_hz=fs, description=f"{grid} multisine {rms_v * 1e3:g} mV rms")
        out[name] = simulate_experiment(bench, spec, seed=seed, plant=plant).recording
    return out


def _median(values: Sequence[float]) -> float:
    return float(statistics.median(values))


def _fmt(x: float) -> str:
    return "  fail" if not math.isfinite(x) else f"{100 * x:6.2f}"


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seeds", type=int, default=3, help="run seeds 0 .. N-1")
    parser.add_argument("--lengths", type=float, nargs="+", default=[2, 5, 10, 20, 30, 60],
                        help="measurement times per axis [s]")
    parser.add_argument("--resolution", type=float, default=1.0,
                        help="multisine line spacing [Hz] (coarsened for short records)")
    parser.add_argument("--multisines", nargs="+", default=DEFAULT_MULTISINES,
                        metavar="GRID:RMS_V",
                        help="multisines to play: grid (full, odd, odd-odd) and rms [V] "
                             f"(default: {' '.join(DEFAULT_MULTISINES)})")
    parser.add_argument("--limit-row", action="store_true",
                        help="add the multisine at the converter limit")
    parser.add_argument("--no-refine", action="store_true",
                        help="skip the full pipeline (refine_modes=True) rows")
    args = parser.parse_args(argv)

    t_start = time.perf_counter()
    bench = real_bench()
    fs = bench.true.converter.fs_hz
    plant = twin_discrete(bench.true)
    cache: Cache = {}
    lengths = sorted(args.lengths)
    min_record = next(s for s in esrf_experiments() if s.name == "data_uch").min_duration_s()
    start_s = next(s for s in esrf_experiments()
                   if s.name == "data_uch").excitations[0].start_s
    if lengths[0] + start_s < min_record:
        parser.error(f"--lengths: {lengths[0]:g} s is shorter than data_uch's minimum of "
                     f"{min_record - start_s:g} s of excitation")

    base = [Method("noise + Welch", "noise", "welch", "seed", False),
            Method("noise + LPM", "noise", "lpm", "variance", False)]
    for item in args.multisines:
        grid, _, rms_text = item.partition(":")
        if grid not in ("full", "odd", "odd-odd"):
            parser.error(f"--multisines {item}: the grid must be full, odd or odd-odd")
        try:
            rms = float(rms_text)
        except ValueError:
            parser.error(f"--multisines {item}: the rms must be a number of volts")
        base.append(Method(f"multisine {grid} {rms * 1e3:g} mV + periodic", "multisine",
                           "periodic", "variance", False, rms, grid))
    limit_note = ""
    if args.limit_row:
        lim = _limit_rms_v(bench, args.resolution, "full", cache)
        limit_note = (f"excite's limit of the {args.resolution:g} Hz multisine (converters "
                      f"and the 4QD's 1 % compression, tighter axis): {lim * 1e3:.3g} mV rms")
        base.append(Method(f"multisine {lim * 1e3:.3g} mV (limit) + periodic", "multisine",
                           "periodic", "variance", False, lim))
    methods = list(base)
    if not args.no_refine:
        methods += [Method(m.label + " + refinement", m.records, m.frf, m.weights, True,
                           m.rms_v, m.grid) for m in base]

    runner = Runner(bench)
    # errors[method label][length] -> list over seeds of the six errors
    errors: dict[str, dict[float, list[dict[str, float]]]] = {
        m.label: {t: [] for t in lengths} for m in methods}
    t_sim = 0.0
    t_ident = 0.0
    for seed in range(args.seeds):
        t0 = time.perf_counter()
        cal = simulate_bench(bench, seed=seed, experiments=CAL)
        t_sim += time.perf_counter() - t0
        truth = cal.truth
        for length in lengths:
            t0 = time.perf_counter()
            noise = simulate_bench(bench, seed=seed, duration_s=start_s + length,
                                   experiments=list(AXIS_EXPERIMENT.values())).recordings
            played = {(m.grid, m.rms_v): _played_records(
                bench, plant, rms_v=m.rms_v, grid=cast(GridKind, m.grid), length_s=length,
                resolution_hz=args.resolution, seed=seed, cache=cache)
                for m in base if m.records == "multisine"}
            t_sim += time.perf_counter() - t0
            t0 = time.perf_counter()
            for m in methods:
                recs = {**cal.recordings,
                        **(noise if m.records == "noise" else played[(m.grid, m.rms_v)])}
                errors[m.label][length].append(
                    runner.errors(m, recs, truth, tag=f"{length:g} s, seed {seed}"))
            t_ident += time.perf_counter() - t0
        print(f"  seed {seed} done ({time.perf_counter() - t_start:.0f} s)", flush=True)

    # ---------------------------------------------------------------- report
    cols = [f"{a}.{s}" for a in "hv" for _, s in QUANTITIES]
    width = max(len(m.label) for m in methods)
    print()
    print(f"Sercalo identification error on the real-bench twin ({fs / 1e3:g} kHz), median "
          f"|identified/true - 1| [%] over {args.seeds} seed(s)")
    print(f"{platform.node()}, {platform.machine()}, Python {platform.python_version()}, "
          f"{dt.datetime.now(dt.UTC).strftime('%Y-%m-%d %H:%M UTC')}")
    if limit_note:
        print(limit_note)
    head = (f"{'method':{width}s} {'T/axis':>7s} | " + " ".join(
        f"{c.replace('.res', ' res').replace('.damp', ' damp').replace('.gain', ' gain'):>7s}"
        for c in cols))
    print(head)
    print("-" * len(head))
    shortest: dict[str, str] = {}
    for m in methods:
        reached = "-"
        for length in lengths:
            per_seed = errors[m.label][length]
            med = {c: _median([e[c] for e in per_seed]) for c in cols}
            print(f"{m.label:{width}s} {length:6g}s | " + " ".join(f"{_fmt(med[c]):>7s}"
                                                                  for c in cols))
            if reached == "-" and max(med["h.damp"], med["v.damp"]) <= DAMPING_GOAL:
                reached = f"{length:g} s"
        shortest[m.label] = reached
    print()
    print(f"Shortest measurement time per axis with median damping error <= "
          f"{100 * DAMPING_GOAL:g} % on both axes (tried {', '.join(f'{t:g}' for t in lengths)}"
          " s):")
    for m in methods:
        print(f"  {m.label:{width}s}  {shortest[m.label]}")
    for line in runner.failures:
        print(f"not identified: {line}")
    total = time.perf_counter() - t_start
    print(f"run time {total:.0f} s (simulation {t_sim:.0f} s, identification {t_ident:.0f} s)")


if __name__ == "__main__":
    main()
