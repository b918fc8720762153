"""fsmbench on benches it was not built on: the independent simulator's corpus (issue 30).

Each bench of ``tests/indsim`` (its own physics, frames and signs, no fsmbench
code) is simulated, then studied exactly as a user with the DEFAULT bench file
would (``fsmbench study --data``, or ``identify`` with ``--identify-only``).
For each bench the script prints:

* the identified values within the issue's tolerances against the simulator's
  ``truth.json`` (resonances 0.5 %, damping 25 %, gains 3 %, the 4QD gain 1 %,
  delays ±0.5 sample; the Newport's natural frequency 2 %, the tolerance
  ``fsmbench.twin.compare`` states for its pole pair without a sharp feature);
* the failed checks (every corpus bench is clean: each is a false alarm);
* the verdict's status (never "not verified" on thirteen consistent files);
* the findings (departures from the bench file) and, with ``--rerun``, the
  findings of a rerun with the ``bench_identified.toml`` it wrote (none expected).

Run: ``python benchmarks/corpus_study.py OUT [--bench NAME ...] [--seed N]
[--duration-scale X] [--identify-only] [--rerun] [--corpus DIR]``. ``--corpus``
reuses benches already written there (``python -m indsim``'s layout).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

#: key -> (kind, tolerance): "rel" relative, "samples" absolute in sampling periods.
TOLERANCES: dict[str, tuple[str, float]] = {
    **{f"qd_gain_v_per_rad.{a}": ("rel", 0.01) for a in "hv"},
    **{f"current_amp_gain_a_per_v.{a}": ("rel", 0.03) for a in "hv"},
    **{f"sercalo.{a}.resonance_hz": ("rel", 0.005) for a in "hv"},
    **{f"sercalo.{a}.damping_ratio": ("rel", 0.25) for a in "hv"},
    **{f"sercalo.{a}.dc_gain_v_per_a": ("rel", 0.03) for a in "hv"},
    **{f"newport_gain_v_per_v.{a}": ("rel", 0.03) for a in "hv"},
    **{f"newport.{a}.natural_freq_hz": ("rel", 0.02) for a in "hv"},
    **{f"newport.{a}.damping_ratio": ("rel", 0.25) for a in "hv"},
    **{f"newport.{a}.internal_delay_s": ("samples", 0.5) for a in "hv"},
    "delay_s.sercalo": ("samples", 0.5),
    "delay_s.newport": ("samples", 0.5),
}


def _get(tree: Any, key: str) -> float | None:
    node = tree
    for part in key.split("."):
        if not isinstance(node, dict) or part not in node:
            return None
        node = node[part]
    return float(node) if isinstance(node, (int, float)) else None


def compare(identified: dict[str, Any], truth: dict[str, Any]) -> list[dict[str, Any]]:
    """One row per tolerance key: identified, true, error, within."""
    fs = float(truth["fs_hz"])
    rows = []
    for key, (kind, tol) in TOLERANCES.items():
        ours, true = _get(identified, key), _get(truth, key)
        if true is None:
            continue
        if ours is None:
            rows.append({"key": key, "identified": None, "true": true, "error": math.nan,
                         "within": False, "tolerance": f"{tol:g} {kind}"})
            continue
        err = (ours / true - 1.0) if kind == "rel" else (ours - true) * fs
        rows.append({"key": key, "identified": ours, "true": true, "error": err,
                     "within": abs(err) <= tol, "tolerance": f"{tol:g} {kind}"})
    return rows


def study_one(data: Path, out: Path, *, identify_only: bool, params: Path | None = None
              ) -> dict[str, Any]:
    """Run the study (or the identification) on one bench's records in-process."""
    from fsmbench.bench.params import default_bench, load_bench
    from fsmbench.io.folder import load_recordings
    from fsmbench.stages import identify_stage
    from fsmbench.study import run_study

    bench = default_bench() if params is None else load_bench(params)
    t0 = time.perf_counter()
    if identify_only:
        out.mkdir(parents=True, exist_ok=True)
        conv = bench.nominal.converter
        loaded = load_recordings(data, fs_hz=None, adc_range_v=conv.range_v,
                                 adc_bits=conv.bits)
        ident = identify_stage(loaded.recordings, bench=bench, out_dir=out,
                               source=str(data), unusable=loaded.unusable()).result
        failed = [c.sentence() for c in (*loaded.checks, *ident.checks) if not c.passed]
        return {"seconds": time.perf_counter() - t0, "verdict": "", "status": "",
                "failed": failed, "warnings": list(ident.warnings),
                "identification": json.loads((out / "identification.json").read_text())}
    run_study(out_dir=out, data_dir=data, bench=bench)
    summary = json.loads((out / "summary.json").read_text())
    return {"seconds": time.perf_counter() - t0, "verdict": summary["verdict"],
            "status": summary["verdict_status"],
            "failed": [f"{c['subject']}: {c['name']}: {c.get('advice', '')[:160]}"
                       for c in summary.get("failed_checks", [])],
            "warnings": [],
            "identification": json.loads((out / "identification.json").read_text())}


#: fsmbench's own twin benches (packaged, or the test suite's files).
TWIN_BENCHES = {"default": None, "real": "real_bench.toml",
                "soft": str(ROOT / "tests/data/benches/soft_bench.toml"),
                "stiff": str(ROOT / "tests/data/benches/stiff_bench.toml")}


def _write_twin_bench(name: str, data: Path, *, seed: int) -> None:
    """The twin's thirteen records of one of its benches, its truth as ``truth.json`` (no
    ``twin_truth.json``: the study treats them as a user's recordings)."""
    from fsmbench.bench.params import load_bench
    from fsmbench.twin import simulate_bench, write_twin

    bench = load_bench(TWIN_BENCHES[name])
    write_twin(simulate_bench(bench, seed=seed), data)
    (data / "twin_truth.json").rename(data / "truth.json")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("out", type=Path)
    parser.add_argument("--bench", nargs="*", default=None)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--duration-scale", type=float, default=1.0)
    parser.add_argument("--corpus", type=Path, default=None,
                        help="benches already written (python -m indsim's layout)")
    parser.add_argument("--identify-only", action="store_true")
    parser.add_argument("--rerun", action="store_true",
                        help="identify again with the bench_identified.toml written")
    parser.add_argument("--twin", nargs="*", default=[],
                        help="fsmbench's own twin benches too: default, real, soft, stiff "
                             "(their twin_truth.json renamed truth.json: a user's records)")
    args = parser.parse_args(argv)

    import indsim

    benches = indsim.corpus()
    names = (args.bench if args.bench is not None else list(benches)) + [
        f"twin_{t}" for t in args.twin]
    corpus = args.corpus or args.out / "corpus"
    results = {}
    for name in names:
        data = corpus / name
        if not (data / "truth.json").exists():
            if name.startswith("twin_"):
                _write_twin_bench(name.removeprefix("twin_"), data, seed=args.seed)
            else:
                indsim.write_bench(indsim.simulate_bench(
                    benches[name], seed=args.seed, duration_scale=args.duration_scale), data)
        truth = json.loads((data / "truth.json").read_text())
        res = study_one(data, args.out / "study" / name, identify_only=args.identify_only)
        rows = compare(res["identification"], truth)
        res["rows"] = rows
        res["findings"] = [f["key"] for f in res["identification"].get("findings", [])]
        if args.rerun:
            again = study_one(data, args.out / "rerun" / name, identify_only=True,
                              params=args.out / "study" / name / "bench_identified.toml")
            res["rerun_findings"] = [f"{f['key']}: {f['bench_value']:.6g} -> "
                                     f"{f['measured']:.6g}"
                                     for f in again["identification"].get("findings", [])]
            res["rerun_failed"] = again["failed"]
        del res["identification"]
        results[name] = res
        within = sum(r["within"] for r in rows)
        misses = ", ".join(f"{r['key']} {r['error']:+.3g}" if r["identified"] is not None
                           else f"{r['key']} missing" for r in rows if not r["within"])
        print(f"{name:34s} {within:2d}/{len(rows):2d} within  false alarms "
              f"{len(res['failed'])}  {res['status'] or '-':14s} {res['seconds']:5.1f} s"
              + (f"  misses: {misses}" if misses else ""), flush=True)
        for line in res["failed"]:
            print(f"    failed: {line[:300]}", flush=True)
        if args.rerun:
            print(f"    rerun with bench_identified.toml: {len(res['rerun_findings'])} "
                  f"findings, {len(res['rerun_failed'])} failed checks"
                  + (f": {res['rerun_findings'][:4]}" if res["rerun_findings"] else ""),
                  flush=True)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "corpus_results.json").write_text(json.dumps(results, indent=1, default=str))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
