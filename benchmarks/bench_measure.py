"""Sercalo identification error against measurement time: noise + Welch, noise + LPM, multisine.

    python benchmarks/bench_measure.py [--seeds 3] [--lengths 2 5 10 20 30 60]
                                       [--ms-rms 0.02 0.01] [--limit-row] [--no-refine]

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
  and one on ``Ucv`` (``fsmbench.excite.design_multisine``, 1-2000 Hz, full
  grid at 1 Hz; 2 Hz when ``T`` holds fewer than 4 periods of 1 s, as the
  estimator drops one period as the transient and needs two more), played in
  ``data_uch``/``data_ucv`` from 1 s for ``T`` seconds
  (:func:`fsmbench.twin.experiments.played_experiment`),
  ``frf="periodic", weights="variance"``, at each rms of ``--ms-rms``:
  20 mV, the noise's rms (equal input power; the multisine puts it all in
  1-2000 Hz, the white noise spreads it to 5 kHz, so the beam moves 1.5-1.9
  times more: Vph 0.22 V rms against 0.15 V), and 10 mV, about the noise's
  beam motion (Vph 0.11 V, Vpv 0.10 V rms). Both levels are well inside the
  converters' ranges (the check of ``fsmbench.excite.limits`` allows 41 mV on
  the nominal model) but not inside the 4QD's linear range: the real-bench
  4QD is an error function, 2 % compressed at the calibration's 0.33 V swing,
  and the multisine's odd-order intermodulation lands on its own lines, a
  bias the periodic estimate's variance does not show;
- ``multisine at the limit`` (``--limit-row``): the same design at the
  largest rms the converter check allows (nominal model, the tighter axis):
  what the check alone would let a user play.

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

Workaround: on the real-bench twin the LPM's DC line has low coherence
(drift and 1/f noise), and the delay estimator's running median of the
coherence pads the band's start with it, so the LPM Sercalo step fails with
"coherence >= 0.9 only up to 0 Hz". When that happens the LPM is rerun with
the running median taken over the lines above the band's lower edge only
(this file's ``_lines_above_low_edge``), and the count of such reruns is
printed. Default run: 3 seeds x 6 lengths, about 5 minutes on a loaded
2-core machine. No assertion: numbers, not verdicts.
"""

from __future__ import annotations

import argparse
import contextlib
import datetime as dt
import math
import platform
import statistics
import time
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import xarray as xr

from fsmbench.bench.params import Bench, real_bench
from fsmbench.excite.design import ExcitationDesign, design_multisine
from fsmbench.excite.limits import converter_peaks
from fsmbench.ident import delay as delay_module
from fsmbench.ident.pipeline import IdentifyOptions, identify
from fsmbench.sim.discretize import DiscretePlant
from fsmbench.sim.plant import twin_discrete
from fsmbench.twin.compare import comparison_rows
from fsmbench.twin.experiments import UC_NOISE_RMS_V, played_experiment, seed_experiments
from fsmbench.twin.simulate import simulate_bench, simulate_experiment

CAL = ["data_cal_pd_h", "data_cal_pd_v"]
AXIS_EXPERIMENT = {"Uch": "data_uch", "Ucv": "data_ucv"}
QUANTITIES = (("resonance_hz", "res"), ("damping_ratio", "damp"), ("dc_gain_v_per_a", "gain"))
BAND_HZ = (1.0, 2000.0)
# The estimator drops one period as the transient and needs two more for the noise estimate;
# one more keeps the noise estimate's degrees of freedom off its minimum.
MIN_PERIODS = 4
DAMPING_GOAL = 0.05  # the 5 % damping error


@dataclass(frozen=True)
class Method:
    """One row group of the table: which records and which estimator."""

    label: str
    records: str  # "noise" or "multisine"
    frf: str
    weights: str
    refine: bool
    rms_v: float = 0.0


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


_original_band = delay_module._coherent_band


def _lines_above_low_edge(f: np.ndarray, coh: np.ndarray, *, f_lo: float, f_max: float,
                          threshold: float, width: int) -> float:
    """The delay band's top, its running median over the lines above ``f_lo`` only."""
    keep = f > f_lo
    return _original_band(f[keep], coh[keep], f_lo=f_lo, f_max=f_max, threshold=threshold,
                          width=width)


@contextlib.contextmanager
def _band_workaround() -> Iterator[None]:
    delay_module._coherent_band = _lines_above_low_edge
    try:
        yield
    finally:
        delay_module._coherent_band = _original_band


class Runner:
    """Identifies one set of records with one method; counts failures and workarounds."""

    def __init__(self, bench: Bench) -> None:
        self.bench = bench
        self.workarounds = 0
        self.failures: list[str] = []

    def errors(self, method: Method, recordings: Mapping[str, xr.Dataset],
               truth: Mapping[str, Any], *, tag: str) -> dict[str, float]:
        """Errors of ``method`` on ``recordings`` (see the module notes)."""
        opts = IdentifyOptions(frf=method.frf,  # type: ignore[arg-type]
                               weights=method.weights,  # type: ignore[arg-type]
                               refine_modes=method.refine)
        result = identify(recordings, bench=self.bench, options=opts, source="twin")
        reason = result.skipped.get("sercalo", "")
        if method.frf == "lpm" and "only up to 0 Hz" in reason:
            self.workarounds += 1
            with _band_workaround():
                result = identify(recordings, bench=self.bench, options=opts, source="twin")
            reason = result.skipped.get("sercalo", "")
        if result.sercalo is None:
            self.failures.append(f"{method.label}, {tag}: {reason}")
        else:
            used = result.to_json()["diagnostics"]["frf_estimator"]["sercalo"]
            if used != method.frf:
                self.failures.append(f"{method.label}, {tag}: estimator {used} was used")
        return _errors(result, truth, self.bench)


def _multisine_period(*, inp: str, resolution_hz: float, fs_hz: float,
                      cache: dict[tuple[str, float], ExcitationDesign]) -> ExcitationDesign:
    """One period at 1 V rms (scaled per method; the design is linear in amplitude)."""
    key = (inp, resolution_hz)
    if key not in cache:
        cache[key] = design_multisine(input=inp, band_hz=BAND_HZ, resolution_hz=resolution_hz,
                                      amplitude_rms_v=1.0, fs_hz=fs_hz, seed=0, periods=1)
    return cache[key]


def _resolution_hz(length_s: float, resolution_hz: float) -> float:
    """The asked resolution, coarsened to whole-sample periods until ``T`` holds enough."""
    r = resolution_hz
    while length_s * r < MIN_PERIODS - 1e-9:
        r *= 2.0
    return r


def _limit_rms_v(bench: Bench, resolution_hz: float,
                 cache: dict[tuple[str, float], ExcitationDesign]) -> float:
    """Largest rms [V] the converter check allows on both axes (nominal model)."""
    fs = bench.nominal.converter.fs_hz
    fits = []
    for inp in AXIS_EXPERIMENT:
        d = _multisine_period(inp=inp, resolution_hz=resolution_hz, fs_hz=fs, cache=cache)
        fits.append(converter_peaks(d, params=bench.nominal).fitting_amplitude_rms_v())
    return min(fits)


def _played_records(bench: Bench, plant: DiscretePlant, *, rms_v: float, length_s: float,
                    resolution_hz: float, seed: int,
                    cache: dict[tuple[str, float], ExcitationDesign]) -> dict[str, xr.Dataset]:
    fs = bench.true.converter.fs_hz
    r = _resolution_hz(length_s, resolution_hz)
    out = {}
    for inp, name in AXIS_EXPERIMENT.items():
        one = _multisine_period(inp=inp, resolution_hz=r, fs_hz=fs, cache=cache).one_period()
        n_periods = round(length_s * r)
        spec = played_experiment(channel=inp, samples_v=rms_v * np.tile(one, n_periods),
                                 fs_hz=fs, description=f"multisine {rms_v * 1e3:g} mV rms")
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
    parser.add_argument("--ms-rms", type=float, nargs="+",
                        default=[UC_NOISE_RMS_V, UC_NOISE_RMS_V / 2],
                        help="multisine rms [V] (default: the seed noise's and half of it)")
    parser.add_argument("--limit-row", action="store_true",
                        help="add the multisine at the converter limit")
    parser.add_argument("--no-refine", action="store_true",
                        help="skip the full pipeline (refine_modes=True) rows")
    args = parser.parse_args(argv)

    t_start = time.perf_counter()
    bench = real_bench()
    fs = bench.true.converter.fs_hz
    plant = twin_discrete(bench.true)
    cache: dict[tuple[str, float], ExcitationDesign] = {}
    lengths = sorted(args.lengths)
    min_record = next(s for s in seed_experiments() if s.name == "data_uch").min_duration_s()
    start_s = next(s for s in seed_experiments()
                   if s.name == "data_uch").excitations[0].start_s
    if lengths[0] + start_s < min_record:
        parser.error(f"--lengths: {lengths[0]:g} s is shorter than data_uch's minimum of "
                     f"{min_record - start_s:g} s of excitation")

    base = [Method("noise + Welch", "noise", "welch", "seed", False),
            Method("noise + LPM", "noise", "lpm", "variance", False)]
    base += [Method(f"multisine {rms * 1e3:g} mV + periodic", "multisine", "periodic",
                    "variance", False, rms) for rms in args.ms_rms]
    limit_note = ""
    if args.limit_row:
        lim = _limit_rms_v(bench, args.resolution, cache)
        limit_note = (f"converter limit of the {args.resolution:g} Hz multisine (nominal "
                      f"model, tighter axis): {lim * 1e3:.3g} mV rms")
        base.append(Method(f"multisine {lim * 1e3:.3g} mV (limit) + periodic", "multisine",
                           "periodic", "variance", False, lim))
    methods = list(base)
    if not args.no_refine:
        methods += [Method(m.label + " + refinement", m.records, m.frf, m.weights, True, m.rms_v)
                    for m in base]

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
            played = {m.rms_v: _played_records(bench, plant, rms_v=m.rms_v, length_s=length,
                                               resolution_hz=args.resolution, seed=seed,
                                               cache=cache)
                      for m in base if m.records == "multisine"}
            t_sim += time.perf_counter() - t0
            t0 = time.perf_counter()
            for m in methods:
                recs = {**cal.recordings,
                        **(noise if m.records == "noise" else played[m.rms_v])}
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
    if runner.workarounds:
        print(f"LPM delay-band workaround used in {runner.workarounds} identification(s) "
              "(see the module notes)")
    for line in runner.failures:
        print(f"not identified: {line}")
    total = time.perf_counter() - t_start
    print(f"run time {total:.0f} s (simulation {t_sim:.0f} s, identification {t_ident:.0f} s)")


if __name__ == "__main__":
    main()
