"""The controller recursion of the DAC-noise estimate (budget stage) against scipy.

    python benchmarks/bench_controller_run.py [--samples 1000000] [--repeats 5]

Runs the ESRF study's controller (discretised as the budget does) over one
100 s huddle record's worth of 4QD samples with
``fsmbench.budget.huddle._run_controller`` (compiled recursion) and with
``scipy.signal.dlsim``; prints the medians, their ratio and the largest
difference relative to the output's peak.
"""

from __future__ import annotations

import argparse

import numpy as np
from scipy import signal

from fsmbench.bench.esrf import esrf_decentralised_controller, tustin
from fsmbench.budget.huddle import run_controller
from timing import timed_runs


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--samples", type=int, default=1_000_000)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    k = tustin(esrf_decentralised_controller())
    r = 1e-6 * np.random.default_rng(0).standard_normal((2, args.samples))
    ours_s, _ = timed_runs(lambda: run_controller(k, r), args.repeats)
    system = (np.asarray(k.A), np.asarray(k.B), np.asarray(k.C), np.asarray(k.D), float(k.dt))
    peer_s, _ = timed_runs(lambda: signal.dlsim(system, r.T), args.repeats)
    ours = run_controller(k, r)
    ref = signal.dlsim(system, r.T)[1].T
    print(f"controller with {k.nstates} states, {args.samples} samples, 2 channels")
    print(f"fsmbench run_controller: {ours_s * 1e3:8.1f} ms (median of {args.repeats})")
    print(f"scipy.signal.dlsim:       {peer_s * 1e3:8.1f} ms")
    print(f"ratio scipy / fsmbench:   {peer_s / ours_s:8.2f}x")
    print(f"largest difference / peak: {np.abs(ours - ref).max() / np.abs(ref).max():.1e}")


if __name__ == "__main__":
    main()
