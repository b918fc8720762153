"""The study on four benches read with the default bench file: is it the user's bench?

    python benchmarks/own_benches.py [--seeds 3] [--duration S]

For the packaged bench, ``real_bench.toml`` and the two benches of
``tests/data/benches``, the thirteen experiments are simulated at the seed's
lengths (``--duration`` shortens the non-identification ones), ``twin_truth.json``
is removed, and ``fsmbench study --data`` runs with the packaged bench file. For
each bench and seed it prints:

- the closed-loop row (fsmbench's controller simulated on the bench identified
  from the recordings) against the same controller simulated on the true bench,
  per axis, and their ratio (issue 19: within 10 %);
- the model validation: recorded / predicted tracking-error rms of data_rep_h/v;
- the verdict and the study's wall time.
"""

from __future__ import annotations

import argparse
import json
import statistics
import tempfile
import time
from pathlib import Path

from fsmbench.bench.params import default_bench, load_bench, real_bench
from fsmbench.io.signals import EXPERIMENTS
from fsmbench.study import run_study
from fsmbench.twin import TwinRun, simulate_bench, write_twin
from fsmbench.twin.verify import verify_on_twin

BENCHES = Path(__file__).resolve().parents[1] / "tests" / "data" / "benches"
IDENT = ("data_cal_pd_h", "data_cal_pd_v", "data_uch", "data_ucv", "data_unh", "data_unv")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--duration", type=float, default=None,
                        help="length of the non-identification records [s] (default: seed's)")
    args = parser.parse_args()
    benches = {"packaged": default_bench(), "real_bench.toml": real_bench(),
               "stiff": load_bench(BENCHES / "stiff_bench.toml"),
               "soft": load_bench(BENCHES / "soft_bench.toml")}
    print(f"{'bench':<16} {'seed':>4} {'closed loop h/v [µrad]':>24} {'true bench h/v':>16} "
          f"{'ratio h/v':>12} {'validation h/v':>15} {'study [s]':>9}  verdict")
    ratios: dict[str, list[float]] = {}
    for name, truth in benches.items():
        for seed in range(args.seeds):
            with tempfile.TemporaryDirectory() as tmp:
                root = Path(tmp)
                ident = simulate_bench(truth, seed=seed, experiments=IDENT)
                rest = simulate_bench(truth, seed=seed, duration_s=args.duration,
                                      experiments=[e for e in EXPERIMENTS if e not in IDENT])
                write_twin(TwinRun(recordings={**ident.recordings, **rest.recordings},
                                   truth=ident.truth, seed=seed), root / "data")
                (root / "data" / "twin_truth.json").unlink()
                t0 = time.perf_counter()
                study = run_study(out_dir=root / "out", data_dir=root / "data")
                wall = time.perf_counter() - t0
                summary = json.loads((root / "out" / "summary.json").read_text())
                rows = {r["name"]: r for r in summary["requirements"]}
                row = rows["closed_loop_simulation"]["values"]
                k = study.design.result.controllers["fsmbench_controller"]
                true = verify_on_twin(k, bench=truth, plant=study.plant,
                                      name="fsmbench").measured_rms_rad
                r = {a: row[a] / true[a] for a in "hv"}
                ratios.setdefault(name, []).extend(r.values())
                val = rows["model_validation"]
                vr = (json.loads((root / "out" / "validation.json").read_text())[
                    "measured_over_predicted"] if val["status"] != "not verified" else None)
                vtext = "-" if vr is None else f"{vr['h']:.2f} / {vr['v']:.2f}"
                print(f"{name:<16} {seed:>4} {row['h'] * 1e6:>11.2f} / {row['v'] * 1e6:<10.2f} "
                      f"{true['h'] * 1e6:>7.2f} / {true['v'] * 1e6:<6.2f} "
                      f"{r['h']:>5.3f} / {r['v']:<5.3f} {vtext:>15} {wall:>9.1f}  "
                      f"{summary['verdict_status']}")
    print("\nclosed-loop row / true bench, over seeds and axes:")
    for name, values in ratios.items():
        print(f"  {name:<16} median {statistics.median(values):.3f}, "
              f"range {min(values):.3f}–{max(values):.3f}")


if __name__ == "__main__":
    main()
