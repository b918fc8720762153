"""Monte Carlo of the closed loop on the twin: one process against a Dask LocalCluster.

    python benchmarks/bench_montecarlo.py [--n 200] [--repeats 3] [--workers N]

200 draws of the repeatability experiment (default 6 s records, 2 s settling,
the default ranges) with fsmbench's controller designed on the nominal plant:

1. one process, no Dask (``run_montecarlo(client=None)``, the reference);
2. a ``LocalCluster`` of ``--workers`` single-threaded processes (default all
   cores), started once outside the timing and warmed by a small run.

Prints median times, the speed-up, the cluster's start-up time, the CPU time
per draw in each mode (what the workers cost apart from waiting for a core:
on a machine other jobs load, the wall-clock speed-up is bounded by the cores
they leave free; the load average is printed before and after), and checks that
both give the same rows. BLAS threads are pinned to one per process, so a
worker is one core.
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")

import argparse
import time

import numpy as np

from fsmbench.bench.params import default_bench
from fsmbench.scale.montecarlo import METRICS, MonteCarloSetup, run_montecarlo
from fsmbench.scale.montecarlo_run import dask_client, designed_controller
from timing import timed_runs


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--n", type=int, default=200, help="draws (default 200)")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    args = parser.parse_args()

    bench = default_bench()
    setup = MonteCarloSetup(bench=bench, controller=designed_controller(bench))
    print(f"Monte Carlo, {args.n} draws of {setup.duration_s:g} s records "
          f"({os.cpu_count()} cores)")
    results = {}

    print(f"  load average before: {os.getloadavg()[0]:.2f}")

    def serial() -> None:
        results["serial"] = run_montecarlo(setup, n=args.n, seed=1)

    c0 = time.process_time()
    t_serial, runs_serial = timed_runs(serial, args.repeats, warm_up=False)
    cpu_serial = (time.process_time() - c0) / (args.repeats * args.n)
    t0 = time.perf_counter()
    with dask_client(scheduler=None, workers=args.workers) as client:
        run_montecarlo(setup, n=2 * args.workers, seed=99, client=client)  # import, JIT caches
        t_start = time.perf_counter() - t0

        def cluster() -> None:
            results["cluster"] = run_montecarlo(setup, n=args.n, seed=1, client=client)

        before = client.run(time.process_time)
        t_cluster, runs_cluster = timed_runs(cluster, args.repeats, warm_up=False)
        after = client.run(time.process_time)
        cpu_cluster = sum(after[w] - before[w] for w in after) / (args.repeats * args.n)
    same = all(np.array_equal(results["serial"].metric(k), results["cluster"].metric(k),
                              equal_nan=True) for k in METRICS)
    print(f"  1 process (no Dask)        {t_serial:8.2f} s  "
          f"({1e3 * t_serial / args.n:.0f} ms per draw; runs {np.round(runs_serial, 2)})")
    print(f"  LocalCluster, {args.workers} workers    {t_cluster:8.2f} s  "
          f"(runs {np.round(runs_cluster, 2)}); cluster start + warm-up {t_start:.1f} s")
    print(f"  CPU per draw: {1e3 * cpu_serial:.0f} ms in one process, "
          f"{1e3 * cpu_cluster:.0f} ms in the workers")
    print(f"  speed-up {t_serial / t_cluster:.2f}x on {args.workers} workers; "
          f"same rows: {'yes' if same else 'NO'}")
    print(f"  load average after: {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
