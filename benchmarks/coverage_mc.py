"""Coverage of the identification's standard deviations on the twin (issue 20).

    python benchmarks/coverage_mc.py [--seeds 20] [--benches default real]
                                  [--estimators welch lpm periodic] [--jsonl FILE]

For each bench (the packaged default and ``real_bench.toml``), each FRF
estimator and each run seed ``0 .. N-1`` the identification experiments are
simulated on the twin and identified as ``fsmbench identify --frf EST
--weights variance`` does; every value ``identification.json`` reports with a
standard deviation is compared with the truth the twin run returns
(``twin_truth.json``, same keys): ``z = (identified - true) / std``. A value
is *covered* when, over the seeds, the fraction with ``|z| <= 1.96`` is at
least 0.9 and ``std(z)`` lies in [0.7, 1.4]; a value reported without a std
counts as not covered.

A value whose std holds a *bounded* part (``bounded_parts`` in
``identification.json``: a fixed systematic known to lie within ±half-width,
e.g. the lags a delay fit cannot tell from a delay) is the same offset on
every run of one bench: over seeds it shifts z but does not spread it, so
``std(z) < 0.7`` is what a bound that holds gives, and ``std(z)`` cannot test
the bound. Such a value is checked by its parts: the fraction within ±1.96
total std ≥ 0.9 and ``std(z) <= 1.4`` as above, the random parts calibrated
(``std`` over the seeds of ``(error − mean error) / random std`` in
[0.7, 1.4]) and the bias inside the bound (``|mean error|`` ≤ half-width +
1.96 standard errors of the mean). The table prints both.

The FRF lines are checked the same way: every line of the Sercalo's
(``Uc -> Vp``, 10 Hz-1 kHz) and the Newport's (``Un -> Vp``, 5 Hz-2 kHz)
matrices against the twin's exact sampled response (the discretised true
plant, :func:`fsmbench.sim.plant.twin_discrete`): the fraction inside the
report's 95 % region and ``std(z)`` of the real and imaginary parts of the
error, each over its half of the line's variance. The lines within 3 Hz of a
Sercalo mode are summarised apart ("near modes"), where a 1 s window smears
the response.

Records: ``welch`` and ``lpm`` identify the twin's own noise records
(``data_uch`` ... ``data_unv``, the seed's lengths); ``periodic`` identifies
random-phase odd-odd multisines (1-2000 Hz on a 1 Hz grid, 10 mV rms on
``Uch``/``Ucv``, 50 mV on ``Unh``/``Unv``, a new phase realisation per seed),
played with 3 transient periods and 20 more, as ``fsmbench excite --odd-odd
--transient-periods 3 --periods 20`` makes them; the identification is not
told how many periods are transient. The 4QD calibrations (``data_cal_pd_h``,
``data_cal_pd_v``) are the twin's, shared by the three estimators.

One process, one core (about 40 s per seed and bench for the three
estimators on a 2-core machine). ``--jsonl`` keeps every seed's numbers,
so a table can be printed again (``--table-only``) or extended.
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")

import argparse
import json
import math
import sys
import time
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import xarray as xr

from fsmbench.bench.params import Bench, default_bench, real_bench
from fsmbench.excite.design import design_multisine
from fsmbench.ident.pipeline import Identification, IdentifyOptions, identify
from fsmbench.sim.plant import twin_discrete
from fsmbench.twin.experiments import esrf_experiments, played_experiment
from fsmbench.twin.simulate import simulate_experiment
from fsmbench.twin.truth import twin_truth

__all__ = [
    "CASE_ESTIMATORS",
    "FRF_BANDS_HZ",
    "MIN_INSIDE",
    "STD_Z_RANGE",
    "CaseResult",
    "coverage_table",
    "parameter_stats",
    "run_case",
    "summarise",
]

#: The issue's criteria: fraction within +-1.96 std, and the spread of z.
MIN_INSIDE = 0.9
STD_Z_RANGE = (0.7, 1.4)
Z95 = 1.959963984540054
CASE_ESTIMATORS = ("welch", "lpm", "periodic")
CAL = ("data_cal_pd_h", "data_cal_pd_v")
NOISE = ("data_uch", "data_ucv", "data_unh", "data_unv")
#: Lines checked per matrix [Hz].
FRF_BANDS_HZ = {"sercalo": (10.0, 1000.0), "newport": (5.0, 2000.0)}
#: Lines within this of a Sercalo mode are "near modes" [Hz].
NEAR_MODE_HZ = 3.0
#: Multisines of the periodic case: rms [V] per input, grid, band, resolution, periods.
MULTISINE_RMS_V = {"Uch": 0.01, "Ucv": 0.01, "Unh": 0.05, "Unv": 0.05}
MULTISINE_BAND_HZ = (1.0, 2000.0)
MULTISINE_PERIODS = 20
MULTISINE_TRANSIENT_PERIODS = 3
_MATRICES = {"sercalo": (("Uch", "Ucv"), ("Vph", "Vpv")),
             "newport": (("Unh", "Unv"), ("Vph", "Vpv"))}


def benches() -> dict[str, Bench]:
    """The two benches of the issue, by short name."""
    return {"default": default_bench(), "real": real_bench()}


# ----------------------------------------------------------------------- records


def _truth(bench: Bench, seed: int, specs: Sequence[Any],
           realized: Mapping[str, Mapping[str, float]]) -> dict[str, Any]:
    return twin_truth(bench, seed=seed, experiments=specs, realized=realized,
                      controller_name=None)


def noise_records(bench: Bench, seed: int) -> tuple[dict[str, xr.Dataset], dict[str, Any]]:
    """The twin's calibration and noise records of one seed (one core), and its truth."""
    plant = twin_discrete(bench.true)
    specs = [s for s in esrf_experiments() if s.name in (*CAL, *NOISE)]
    results = {s.name: simulate_experiment(bench, s, seed=seed, plant=plant) for s in specs}
    truth = _truth(bench, seed, specs, {k: r.realized for k, r in results.items()})
    return {k: r.recording for k, r in results.items()}, truth


def multisine_records(bench: Bench, seed: int) -> dict[str, xr.Dataset]:
    """Random-phase odd-odd multisines on the four inputs (see the module), one seed."""
    plant = twin_discrete(bench.true)
    fs = bench.true.converter.fs_hz
    out = {}
    for i, (channel, rms) in enumerate(MULTISINE_RMS_V.items()):
        design = design_multisine(
            input=channel, band_hz=MULTISINE_BAND_HZ, resolution_hz=1.0, amplitude_rms_v=rms,
            fs_hz=fs, seed=1000 * seed + i, periods=MULTISINE_PERIODS,
            transient_periods=MULTISINE_TRANSIENT_PERIODS, grid="odd-odd",
            phase_method="random")
        spec = played_experiment(channel=channel, samples_v=design.samples_v, fs_hz=fs,
                                 description="odd-odd multisine")
        out[spec.name] = simulate_experiment(bench, spec, seed=seed, plant=plant).recording
    return out


# ----------------------------------------------------------------------- parameters


def _get(tree: Mapping[str, Any], key: str) -> Any:
    node: Any = tree
    for part in key.split("."):
        if not isinstance(node, Mapping) or part not in node:
            return None
        node = node[part]
    return node


def _legacy_stds(js: Mapping[str, Any]) -> dict[str, float]:
    """The stds identification.json v3 gives, by truth key (before issue 20)."""
    diag = js.get("diagnostics") or {}
    out: dict[str, float] = {}
    for a in "hv":
        for key, path in ((f"qd_gain_v_per_rad.{a}", f"qd.{a}.gain_std_v_per_rad"),
                          (f"current_amp_gain_a_per_v.{a}", f"current_amp.{a}.gain_std_a_per_v"),
                          (f"sercalo.{a}.resonance_hz", f"sercalo_modes.{a}.resonance_hz_std"),
                          (f"sercalo.{a}.damping_ratio", f"sercalo_modes.{a}.damping_ratio_std"),
                          (f"sercalo.{a}.dc_gain_v_per_a",
                           f"sercalo.parameter_std.{a}.dc_gain_v_per_a_std"),
                          (f"newport_gain_v_per_v.{a}",
                           f"newport.dynamics.axes.{a}.gain_std_v_per_v"),
                          (f"newport.{a}.natural_freq_hz",
                           f"newport.dynamics.axes.{a}.natural_freq_std_hz"),
                          (f"newport.{a}.damping_ratio",
                           f"newport.dynamics.axes.{a}.damping_std")):
            v = _get(diag, path)
            if isinstance(v, (int, float)):
                out[key] = float(v)
    for key, path in (("delay_s.sercalo", "sercalo.delay_std_s"),
                      ("delay_s.newport", "newport.delay_std_s")):
        v = _get(diag, path)
        if isinstance(v, (int, float)):
            out[key] = float(v)
    return out


def _leaves(tree: Mapping[str, Any], prefix: str = "") -> Iterable[tuple[str, Mapping[str, Any]]]:
    """``(dotted key, item)`` of every ``{value, std, ...}`` in a nested tree."""
    for key, node in tree.items():
        name = f"{prefix}{key}"
        if isinstance(node, Mapping) and "value" in node and "std" in node:
            yield name, node
        elif isinstance(node, Mapping):
            yield from _leaves(node, name + ".")


def reported(js: Mapping[str, Any]) -> dict[str, tuple[float, float]]:
    """Every identified value with its std (NaN when none), by truth key.

    ``uncertainty`` (identification.json v4) when present, else the v3 stds.
    """
    unc = js.get("uncertainty")
    out: dict[str, tuple[float, float]] = {}
    if isinstance(unc, Mapping):
        for key, item in _leaves(unc):
            out[key] = (float(item["value"]), float(item["std"]))
        return out
    stds = _legacy_stds(js)
    for top in ("qd_gain_v_per_rad", "current_amp_gain_a_per_v", "newport_gain_v_per_v",
                "delay_s"):
        for sub, v in (js.get(top) or {}).items():
            key = f"{top}.{sub}"
            out[key] = (float(v), stds.get(key, math.nan))
    for top in ("sercalo", "newport"):
        for axis, vals in (js.get(top) or {}).items():
            for q, v in vals.items():
                key = f"{top}.{axis}.{q}"
                out[key] = (float(v), stds.get(key, math.nan))
    return out


def parameter_stats(js: Mapping[str, Any], truth: Mapping[str, Any]) -> dict[str, float]:
    """``z`` of every reported value against the truth's value of the same key (NaN: no std
    or no truth)."""
    out = {}
    for key, (value, std) in reported(js).items():
        ref = _get(truth, key)
        if not isinstance(ref, (int, float)):
            continue
        out[key] = ((value - float(ref)) / std if std > 0 and math.isfinite(std)
                    else math.nan)
    return out


def value_errors(js: Mapping[str, Any], truth: Mapping[str, Any]) -> dict[str, dict[str, float]]:
    """Every value's error against the truth with its total std and the std of its bounded
    (fixed-systematic) parts, so that the random part and the bound check apart."""
    unc = js.get("uncertainty")
    out: dict[str, dict[str, float]] = {}
    if not isinstance(unc, Mapping):
        return out
    for key, item in _leaves(unc):
        ref = _get(truth, key)
        if not isinstance(ref, (int, float)):
            continue
        parts = item.get("parts") or {}
        bounded_names = set(item.get("bounded_parts") or ())
        out[key] = {
            "error": float(item["value"]) - float(ref), "std": float(item["std"]),
            "bounded_std": math.sqrt(sum(float(v) ** 2 for k, v in parts.items()
                                         if k in bounded_names)),
            "random_std": math.sqrt(sum(float(v) ** 2 for k, v in parts.items()
                                        if k not in bounded_names))}
    return out


# ----------------------------------------------------------------------- FRF lines


def _line_variance(frf: Any) -> np.ndarray:
    if frf.frf_variance is not None:
        return np.asarray(frf.frf_variance.values, dtype=float)
    return 2.0 * (np.asarray(frf.random_error.values) * np.abs(np.asarray(frf.frf.values))) ** 2


def _bound_radius(frf: Any, var: np.ndarray) -> np.ndarray:
    """The report's 95 % region (the estimate's own radius when it has one)."""
    radius = getattr(frf, "bound_radius", None)
    if callable(radius):
        return np.asarray(radius(), dtype=float)
    return math.sqrt(-math.log(0.05)) * np.sqrt(var)


def frf_line_stats(result: Identification, bench: Bench) -> dict[str, dict[str, list[float]]]:
    """Per matrix (and its lines near the modes): the z of real and imaginary parts and
    whether each line is inside its region."""
    plant = twin_discrete(bench.true)
    out: dict[str, dict[str, list[float]]] = {}
    modes = [bench.true.sercalo.resonance_hz[a] for a in "hv"]
    for name, part in (("sercalo", result.sercalo), ("newport", result.newport)):
        if part is None:
            continue
        frf = part.frf
        ins, outs = _MATRICES[name]
        f = frf.frequency_hz
        lo, hi = FRF_BANDS_HZ[name]
        sel = (f >= lo) & (f <= hi)
        h = np.asarray(frf.frf.sel(input=list(ins), output=list(outs)).values)[sel]
        var = _line_variance(frf)
        idx_in = [frf.input_names.index(i) for i in ins]
        idx_out = [frf.output_names.index(o) for o in outs]
        var = var[sel][:, idx_out][:, :, idx_in]
        radius = _bound_radius(frf, _line_variance(frf))[sel][:, idx_out][:, :, idx_in]
        resp = plant.frequency_response(f[sel])
        true = resp[:, [plant.output_names.index(o) for o in outs]][
            :, :, [plant.input_names.index(i) for i in ins]]
        err = h - true
        ok = np.isfinite(err) & np.isfinite(var) & (var > 0)
        near = np.zeros_like(ok)
        near[np.min([np.abs(f[sel] - m) for m in modes], axis=0) <= NEAR_MODE_HZ] = True
        sd = np.sqrt(np.where(ok, var, 1.0) / 2.0)
        for label, mask in ((name, ok), (f"{name} near modes", ok & near)):
            if name == "newport" and label.endswith("near modes"):
                continue
            zr = (err.real / sd)[mask]
            zi = (err.imag / sd)[mask]
            inside = (np.abs(err) <= radius)[mask]
            out[label] = {"z": np.concatenate([zr, zi]).tolist(),
                          "inside": inside.astype(float).tolist()}
    return out


# ----------------------------------------------------------------------- one case


@dataclass(frozen=True)
class CaseResult:
    """One bench, estimator and seed."""

    bench: str
    estimator: str
    seed: int
    z: dict[str, float]
    frf: dict[str, dict[str, float]]
    failed: str = ""
    seconds: float = 0.0
    extra: dict[str, Any] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        """Plain values."""
        return {"bench": self.bench, "estimator": self.estimator, "seed": self.seed,
                "z": self.z, "frf": self.frf, "failed": self.failed,
                "seconds": self.seconds, "extra": self.extra}


def _frf_summary(stats: Mapping[str, Mapping[str, list[float]]]) -> dict[str, dict[str, float]]:
    """Sums per matrix, so that seeds combine without keeping every line."""
    out = {}
    for label, s in stats.items():
        z = np.asarray(s["z"])
        inside = np.asarray(s["inside"])
        out[label] = {"n_z": float(z.size), "sum_z": float(z.sum()),
                      "sum_z2": float((z * z).sum()), "n_lines": float(inside.size),
                      "n_inside": float(inside.sum())}
    return out


def run_case(bench_name: str, bench: Bench, estimator: str, seed: int,
             records: Mapping[str, xr.Dataset], truth: Mapping[str, Any]) -> CaseResult:
    """Identify one set of records with one estimator and compare with the truth."""
    t0 = time.perf_counter()
    opts = IdentifyOptions(frf=estimator, weights="variance")  # type: ignore[arg-type]
    try:
        result = identify(records, bench=bench, options=opts, source="twin")
    except Exception as exc:  # a failed seed is a row of the table, not a crash
        return CaseResult(bench_name, estimator, seed, {}, {}, failed=f"{type(exc).__name__}: "
                          f"{exc}", seconds=time.perf_counter() - t0)
    js = result.to_json()
    z = parameter_stats(js, truth)
    errors = value_errors(js, truth)
    frf = _frf_summary(frf_line_stats(result, bench))
    failed = "; ".join(f"{k}: {v}" for k, v in result.skipped.items()
                       if k in ("qd", "current_amp", "sercalo", "newport"))
    return CaseResult(bench_name, estimator, seed, z, frf, failed=failed,
                      seconds=time.perf_counter() - t0, extra={"errors": errors})


def run(bench_names: Sequence[str], estimators: Sequence[str], seeds: Iterable[int], *,
        log: Any = None) -> list[CaseResult]:
    """Every case of every seed (one process); ``log`` receives each case as a JSON line."""
    all_benches = benches()
    out = []
    for seed in seeds:
        for name in bench_names:
            bench = all_benches[name]
            t0 = time.perf_counter()
            noise, truth = noise_records(bench, seed)
            ms = (multisine_records(bench, seed) if "periodic" in estimators else {})
            sim_s = time.perf_counter() - t0
            for est in estimators:
                recs = dict(noise)
                if est == "periodic":
                    recs.update(ms)
                case = run_case(name, bench, est, seed, recs, truth)
                case.extra["simulation_s"] = sim_s
                out.append(case)
                if log is not None:
                    log.write(json.dumps(case.to_json()) + "\n")
                    log.flush()
                print(f"  {name:7s} {est:8s} seed {seed:2d}: {case.seconds:5.1f} s"
                      + (f"  FAILED {case.failed}" if case.failed else ""), flush=True)
    return out


# ----------------------------------------------------------------------- table


@dataclass(frozen=True)
class Row:
    """One table row: a parameter or an FRF matrix of one bench and estimator."""

    bench: str
    estimator: str
    key: str
    n: int
    inside: float
    std_z: float
    mean_z: float
    missing: int = 0
    #: The value's std holds a bounded part (a fixed systematic within ±half-width): its
    #: random part and its bound are then checked apart (:func:`summarise`).
    bounded: bool = False
    #: std over the seeds of (error − mean error) / random std (the random parts alone).
    std_z_random: float = math.nan
    #: |mean error| over (the bound's half-width + 1.96 standard errors of the mean).
    bias_in_bound: float = math.nan

    @property
    def covered(self) -> bool:
        """The issue's criteria, every seed reporting a std.

        A bounded systematic is the same offset on every run of one bench, so over seeds
        it shifts z but does not spread it: std(z) < 0.7 is then what a bound that holds
        gives. Such a row is covered when the fraction within ±1.96 std is ≥ 0.9,
        std(z) ≤ 1.4, the random parts alone are calibrated (std of the centred errors
        over the random std in [0.7, 1.4]) and the mean error lies within the bound.
        """
        if self.missing or self.n <= 0 or self.inside < MIN_INSIDE:
            return False
        if self.bounded and math.isfinite(self.std_z_random):
            return (self.std_z <= STD_Z_RANGE[1] and self.bias_in_bound <= 1.0
                    and STD_Z_RANGE[0] <= self.std_z_random <= STD_Z_RANGE[1])
        return STD_Z_RANGE[0] <= self.std_z <= STD_Z_RANGE[1]


def summarise(cases: Sequence[CaseResult | Mapping[str, Any]]) -> list[Row]:
    """Rows per (bench, estimator, parameter) and per (bench, estimator, FRF matrix)."""
    items = [c.to_json() if isinstance(c, CaseResult) else dict(c) for c in cases]
    groups: dict[tuple[str, str], list[dict[str, Any]]] = {}
    for c in items:
        groups.setdefault((c["bench"], c["estimator"]), []).append(c)
    rows = []
    for (bench, est), cs in groups.items():
        keys = sorted({k for c in cs for k in c["z"]})
        for key in keys:
            zs = [c["z"].get(key, math.nan) for c in cs]
            good = np.array([z for z in zs if math.isfinite(z)])
            missing = len(zs) - good.size
            rows.append(Row(bench, est, key, int(good.size),
                            float(np.mean(np.abs(good) <= Z95)) if good.size else math.nan,
                            float(np.std(good, ddof=1)) if good.size > 1 else math.nan,
                            float(np.mean(good)) if good.size else math.nan, missing,
                            **_bounded_stats(cs, key)))
        labels = sorted({k for c in cs for k in c["frf"]})
        for label in labels:
            s = {f: sum(c["frf"].get(label, {}).get(f, 0.0) for c in cs)
                 for f in ("n_z", "sum_z", "sum_z2", "n_lines", "n_inside")}
            n = s["n_z"]
            mean = s["sum_z"] / n if n else math.nan
            var = (s["sum_z2"] / n - mean**2) * n / (n - 1) if n > 1 else math.nan
            rows.append(Row(bench, est, f"FRF {label}", int(s["n_lines"]),
                            s["n_inside"] / s["n_lines"] if s["n_lines"] else math.nan,
                            math.sqrt(max(var, 0.0)), mean, 0))
    return rows


def _bounded_stats(cases: Sequence[Mapping[str, Any]], key: str) -> dict[str, Any]:
    """The random part's calibration and the bias against the bound, for a value whose std
    holds a bounded part on every seed (empty otherwise, or for runs that kept no errors)."""
    errors = [(c.get("extra") or {}).get("errors", {}).get(key) for c in cases]
    if not errors or any(e is None for e in errors) or len(errors) < 3:
        return {}
    if not all(e["bounded_std"] > 0 and e["random_std"] > 0 for e in errors):
        return {}
    err = np.array([e["error"] for e in errors])
    random_std = np.array([e["random_std"] for e in errors])
    half_width = float(np.median([e["bounded_std"] for e in errors])) * math.sqrt(3.0)
    centred = (err - err.mean()) / random_std
    n = err.size
    sem = float(np.std(err, ddof=1)) / math.sqrt(n)
    return {"bounded": True,
            "std_z_random": float(np.std(centred, ddof=1)),
            "bias_in_bound": abs(float(err.mean())) / (half_width + Z95 * sem)}


def coverage_table(rows: Sequence[Row], *, markdown: bool = False) -> list[str]:
    """The table: fraction within +-1.96 std (FRF: inside the 95 % region), std(z), mean z."""
    if markdown:
        lines = ["| bench | estimator | quantity | n | in ±1.96σ | std(z) | mean z | "
                 "bounded part: std(z) of the random parts, mean error ÷ bound | ok |",
                 "|---|---|---|---|---|---|---|---|---|"]
        for r in rows:
            lines.append(f"| {r.bench} | {r.estimator} | {r.key} | {r.n} | {r.inside:.2f} | "
                         f"{r.std_z:.2f} | {r.mean_z:+.2f} | {_bounded_words(r)} | "
                         f"{'yes' if r.covered else 'no'}{_missing(r)} |")
        return lines
    w = max((len(r.key) for r in rows), default=10)
    lines = [f"{'bench':8s} {'estimator':9s} {'quantity':{w}s} {'n':>6s} {'in95':>5s} "
             f"{'std(z)':>7s} {'mean z':>8s}  ok"]
    for r in rows:
        bounded = f" (bounded: {_bounded_words(r)})" if r.bounded else ""
        lines.append(f"{r.bench:8s} {r.estimator:9s} {r.key:{w}s} {r.n:6d} {r.inside:5.2f} "
                     f"{r.std_z:7.2f} {r.mean_z:+8.2f}  {'yes' if r.covered else 'NO'}"
                     f"{_missing(r)}{bounded}")
    return lines


def _bounded_words(r: Row) -> str:
    return (f"{r.std_z_random:.2f}, {r.bias_in_bound:.2f}" if r.bounded else "")


def _missing(r: Row) -> str:
    return f" ({r.missing} without std)" if r.missing else ""


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seeds", type=int, default=20, help="run seeds 0 .. N-1 (default 20)")
    parser.add_argument("--first-seed", type=int, default=0)
    parser.add_argument("--benches", nargs="+", default=["default", "real"],
                        choices=["default", "real"])
    parser.add_argument("--estimators", nargs="+", default=list(CASE_ESTIMATORS),
                        choices=list(CASE_ESTIMATORS))
    parser.add_argument("--jsonl", type=Path, default=None,
                        help="append every case to this file (JSON lines)")
    parser.add_argument("--table-only", action="store_true",
                        help="print the table of --jsonl without running anything")
    parser.add_argument("--markdown", action="store_true", help="the table in Markdown")
    args = parser.parse_args(argv)
    if args.table_only:
        if args.jsonl is None:
            parser.error("--table-only needs --jsonl")
        cases: list[Any] = [json.loads(line) for line in args.jsonl.read_text().splitlines()
                            if line.strip()]
    else:
        t0 = time.perf_counter()
        log = args.jsonl.open("a") if args.jsonl is not None else None
        try:
            cases = list(run(args.benches, args.estimators,
                             range(args.first_seed, args.first_seed + args.seeds), log=log))
        finally:
            if log is not None:
                log.close()
        print(f"run time {time.perf_counter() - t0:.0f} s", flush=True)
    rows = summarise(cases)
    for line in coverage_table(rows, markdown=args.markdown):
        print(line)
    failed = [c for c in cases if (c.failed if isinstance(c, CaseResult) else c["failed"])]
    for c in failed:
        d = c.to_json() if isinstance(c, CaseResult) else c
        print(f"failed: {d['bench']} {d['estimator']} seed {d['seed']}: {d['failed']}")
    bad = [r for r in rows if not r.covered]
    print(f"{len(rows) - len(bad)} of {len(rows)} rows covered")
    return 0 if not bad else 1


if __name__ == "__main__":
    sys.exit(main())
