"""Coverage of the identification's total stds on benches it was not built on (issue 30).

    python benchmarks/corpus_coverage.py [--benches sercalo_h_flipped qd_amp2_5k]
                                         [--seeds 20] [--jsonl FILE] [--table-only]

For each named bench of the independent simulator's corpus (``tests/indsim``:
its own physics, frames and signs) and each seed ``0 .. N-1``, the study's
records are simulated at their full lengths and identified as a user with the
DEFAULT bench file would (``identify``: the seed's estimator and weights); every
value ``identification.json`` reports with a total std is compared with the
simulator's ``truth.json`` (same keys), ``z = (identified − true) / std``. The
criteria are ``benchmarks/coverage_mc.py``'s: a value is covered when at least
90 % of the seeds have ``|z| ≤ 1.96`` and ``std(z)`` lies in [0.7, 1.4]; a value
whose std holds a bounded part is judged by its parts (the random parts
calibrated, the mean error inside the bound). ``--jsonl`` keeps each seed's
numbers so a table can be printed again or extended.
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import json
import sys
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
sys.path.insert(0, str(ROOT / "benchmarks"))

from coverage_mc import coverage_table, parameter_stats, summarise, value_errors  # noqa: E402
from fsmbench.bench.params import default_bench  # noqa: E402
from fsmbench.ident.pipeline import identify  # noqa: E402
from fsmbench.io.folder import load_recordings  # noqa: E402


def run_case(bench_name: str, seed: int) -> dict[str, object]:
    """One bench and seed: simulate, write, identify, compare with the truth."""
    import indsim

    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        run = indsim.simulate_bench(indsim.corpus()[bench_name], seed=seed)
        folder = indsim.write_bench(run, Path(tmp) / bench_name)
        truth = json.loads((folder / "truth.json").read_text())
        loaded = load_recordings(folder, fs_hz=None)
        result = identify(loaded.recordings, bench=default_bench(), source=str(folder))
    js = result.to_json()
    return {"bench": bench_name, "estimator": "welch", "seed": seed,
            "z": parameter_stats(js, truth), "frf": {}, "failed": "",
            "seconds": time.perf_counter() - t0,
            "extra": {"errors": value_errors(js, truth),
                      "skipped": dict(result.skipped), "warnings": list(result.warnings)}}


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--benches", nargs="+", default=["sercalo_h_flipped", "qd_amp2_5k"])
    parser.add_argument("--seeds", type=int, default=20)
    parser.add_argument("--first-seed", type=int, default=0)
    parser.add_argument("--jsonl", type=Path, default=None)
    parser.add_argument("--table-only", action="store_true")
    parser.add_argument("--markdown", action="store_true")
    args = parser.parse_args(argv)
    cases: list[dict[str, object]] = []
    if args.jsonl is not None and args.jsonl.exists():
        cases = [json.loads(line) for line in args.jsonl.read_text().splitlines() if line]
    if not args.table_only:
        done = {(c["bench"], c["seed"]) for c in cases}
        for bench in args.benches:
            for seed in range(args.first_seed, args.first_seed + args.seeds):
                if (bench, seed) in done:
                    continue
                case = run_case(bench, seed)
                cases.append(case)
                print(f"{bench} seed {seed}: {case['seconds']:.1f} s", flush=True)
                if args.jsonl is not None:
                    with args.jsonl.open("a") as f:
                        f.write(json.dumps(case) + "\n")
    rows = summarise([c for c in cases if c["bench"] in args.benches])
    print("\n".join(coverage_table(rows, markdown=args.markdown)))
    covered = sum(r.covered for r in rows)
    print(f"covered: {covered} of {len(rows)} rows")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
