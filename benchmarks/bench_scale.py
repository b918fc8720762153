"""Long records out of core against scipy in memory, and Dask's 2-worker speed-up, in one run.

    python benchmarks/bench_scale.py [--hours 1] [--repeats 3] [--mc 200]

1. A huddle test of ``--hours`` (default 1 h: 3 signals of 36 M samples) is
   simulated once into a NeXus archive (streamed, ``fsmbench.twin.stream_bench``).
2. Each variant runs in its own process (so its peak memory, ``ru_maxrss``, is
   its own), ``--repeats`` times; medians are printed with the ratios:

   - ``fsmbench, out of core``: the huddle analysis of the record read lazily
     (Welch PSDs, rms, low pass, drift; Dask threads), then the three Welch
     PSDs alone;
   - ``fsmbench, 2 workers``: the same Welch PSDs on a ``LocalCluster`` of two
     single-threaded worker processes (graph pickled to the workers);
   - ``scipy, in memory``: the record read whole into numpy, then
     ``scipy.signal.welch`` with the same window and overlap (what the whole
     array costs: it needs every sample in memory).

3. Monte Carlo of ``--mc`` draws: ``benchmarks/bench_montecarlo.py`` (1 worker
   against all cores) is run and its lines are printed.

The peak memory limit of issue 13 (1.5 GB for the out-of-core analysis of
1 h) is printed next to the measurement. No assertion: numbers, not verdicts.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent


def _variant(kind: str, path: str) -> dict[str, float]:
    """Run one variant in this process; returns its timings [s]."""
    import numpy as np

    from fsmbench.budget.spectra import esrf_welch

    fs = 10_000.0
    out: dict[str, float] = {}
    if kind == "lazy":
        from fsmbench.budget.huddle import analyse_huddle_record
        from fsmbench.io.lazy import open_recording

        ds = open_recording(path)
        t0 = time.perf_counter()
        rec = analyse_huddle_record(ds, name="data_huddle_test_4")
        out["huddle_s"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        for v in ("Va", "Vph", "Vpv"):
            esrf_welch(ds[v].data, fs_hz=fs, name=v)
        out["welch_s"] = time.perf_counter() - t0
        out["va_rms_m"] = rec.va_rms_m
    elif kind == "cluster":
        from distributed import Client, LocalCluster

        from fsmbench.io.lazy import open_recording

        with LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                          dashboard_address=None) as cluster, Client(cluster):
            ds = open_recording(path)
            esrf_welch(ds["Va"].data[: round(60 * fs)], fs_hz=fs, name="warm-up")
            t0 = time.perf_counter()
            for v in ("Va", "Vph", "Vpv"):
                esrf_welch(ds[v].data, fs_hz=fs, name=v)
            out["welch_s"] = time.perf_counter() - t0
    else:
        import scipy.signal

        from fsmbench.ident import hanning
        from fsmbench.io.recording import read_recording

        t0 = time.perf_counter()
        ds = read_recording(path)
        arrays = [np.asarray(ds[v].values) for v in ("Va", "Vph", "Vpv")]
        out["read_s"] = time.perf_counter() - t0
        w = hanning(round(fs))
        t0 = time.perf_counter()
        for x in arrays:
            scipy.signal.welch(x - x.mean(), fs=fs, window=w, noverlap=w.size // 2,
                               nfft=16384, detrend=False)
        out["welch_s"] = time.perf_counter() - t0
    # This process's own peak resident memory (KiB on Linux) -> GB.
    out["peak_gb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6
    return out


def _measure(kind: str, path: str, repeats: int) -> tuple[dict[str, float], float]:
    """Median timings and largest peak memory [GB] of ``repeats`` runs, each its own process."""
    runs = []
    for _ in range(repeats):
        proc = subprocess.run([sys.executable, __file__, "--variant", kind, "--path", path],
                              capture_output=True, text=True, check=True)
        runs.append(json.loads(proc.stdout.strip().splitlines()[-1]))
    med = {k: statistics.median(r[k] for r in runs) for k in runs[0]}
    return med, max(r["peak_gb"] for r in runs)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--hours", type=float, default=1.0)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--mc", type=int, default=200, help="Monte Carlo draws (0: skip)")
    parser.add_argument("--variant", help=argparse.SUPPRESS)
    parser.add_argument("--path", help=argparse.SUPPRESS)
    parser.add_argument("--keep", metavar="DIR", help="keep the archive in DIR")
    args = parser.parse_args()
    if args.variant:
        print(json.dumps(_variant(args.variant, args.path)))
        return

    from fsmbench.bench.params import default_bench
    from fsmbench.twin.simulate import stream_bench

    folder = Path(args.keep) if args.keep else Path(tempfile.mkdtemp(prefix="bench-scale-"))
    path = folder / "data_huddle_test_4.h5"
    if not path.exists():
        t0 = time.perf_counter()
        stream_bench(default_bench(), out_dir=folder, seed=0, duration_s=args.hours * 3600,
                     experiments=["data_huddle_test_4"])
        print(f"simulated {args.hours:g} h into {path} ({path.stat().st_size / 1e9:.2f} GB) "
              f"in {time.perf_counter() - t0:.0f} s")
    n = round(args.hours * 3600 * 10_000)
    print(f"huddle test of {args.hours:g} h: 3 signals of {n / 1e6:.0f} M samples, "
          f"{os.cpu_count()} cores, medians of {args.repeats}")
    lazy, lazy_gb = _measure("lazy", str(path), args.repeats)
    cluster, _ = _measure("cluster", str(path), args.repeats)
    scipy_t, scipy_gb = _measure("scipy", str(path), args.repeats)
    print(f"  fsmbench out of core: huddle analysis {lazy['huddle_s']:7.1f} s, 3 Welch PSDs "
          f"{lazy['welch_s']:6.1f} s, peak memory {lazy_gb:5.2f} GB (limit 1.5 GB)")
    print(f"  fsmbench, 2 workers:                            3 Welch PSDs "
          f"{cluster['welch_s']:6.1f} s -> speed-up {lazy['welch_s'] / cluster['welch_s']:.2f}x")
    print(f"  scipy in memory:      read {scipy_t['read_s']:6.1f} s,       3 Welch PSDs "
          f"{scipy_t['welch_s']:6.1f} s, peak memory {scipy_gb:5.2f} GB")
    print(f"  Welch, fsmbench out of core / scipy in memory: "
          f"{lazy['welch_s'] / scipy_t['welch_s']:.2f}x the time, "
          f"{lazy_gb / scipy_gb:.2f}x the memory")
    if args.mc:
        print(f"Monte Carlo ({args.mc} draws): benchmarks/bench_montecarlo.py")
        subprocess.run([sys.executable, str(HERE / "bench_montecarlo.py"), "--n", str(args.mc),
                        "--repeats", "1"], check=True)


if __name__ == "__main__":
    main()
