"""Frequency responses of the bench's plant: fsmbench's modal sum against its peers.

    python benchmarks/bench_freqresp.py [--repeats 7]

The budget evaluates the 12-state plant (4 inputs, 8 outputs) on its 0.1 Hz grid
up to 5 kHz (50 000 points); the margin root finders evaluate a loop one point at
a time. Times, in the same run, median of ``--repeats``:

- ``fsmbench.bench.blocks.ss_response`` (modal sum checked against the solve)
  against the batched direct solve it replaces and python-control's
  ``frequency_response`` (its peer for a named state-space model);
- ``ResponseEvaluator`` against ``ss_response`` for one point per call.

Prints each median, the ratio, and the largest relative difference between them.
"""

from __future__ import annotations

import argparse

import control as ct
import numpy as np

from fsmbench.bench.blocks import ResponseEvaluator, physical_plant, solve_response, ss_response
from fsmbench.bench.params import default_bench
from timing import timed_runs


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--repeats", type=int, default=7)
    args = parser.parse_args()
    sys = physical_plant(default_bench().true).sys
    a, b, c, d = (np.asarray(x, dtype=float) for x in (sys.A, sys.B, sys.C, sys.D))
    f = np.arange(1, 50_001) * 0.1
    s = 2j * np.pi * f
    modal = ss_response(sys, s)
    exact = solve_response(a, b, c, d, s)
    peak = np.max(np.abs(exact), axis=0, keepdims=True)
    seen = np.abs(exact) > 1e-6 * peak
    rel = float(np.max(np.abs(modal - exact)[seen] / np.abs(exact)[seen]))
    t_modal, _ = timed_runs(lambda: ss_response(sys, s), args.repeats)
    t_solve, _ = timed_runs(lambda: solve_response(a, b, c, d, s), args.repeats)
    t_ct, _ = timed_runs(lambda: ct.frequency_response(sys, 2 * np.pi * f), args.repeats)
    print(f"{sys.nstates} states, {sys.ninputs} inputs, {sys.noutputs} outputs, "
          f"{f.size} frequencies; modal vs solve: max relative difference {rel:.1e}")
    print(f"  fsmbench ss_response (modal)    {1e3 * t_modal:8.1f} ms")
    print(f"  batched direct solve            {1e3 * t_solve:8.1f} ms   ({t_solve / t_modal:.1f}x)")
    print(f"  python-control frequency_resp.  {1e3 * t_ct:8.1f} ms   ({t_ct / t_modal:.1f}x)")

    points = 2j * np.pi * np.geomspace(1.0, 4000.0, 500)
    ev = ResponseEvaluator(sys, check_points=2j * np.pi * np.geomspace(1e-4, 1e5, 24))

    def one_at_a_time(fn: object) -> None:
        for x in points:
            fn(np.array([x]))  # type: ignore[operator]

    t_ev, _ = timed_runs(lambda: one_at_a_time(ev), args.repeats)
    t_ss, _ = timed_runs(lambda: one_at_a_time(lambda x: ss_response(sys, x)), args.repeats)
    print(f"one point per call, {points.size} calls:")
    print(f"  ResponseEvaluator               {1e6 * t_ev / points.size:8.1f} µs/call")
    print(f"  ss_response (solve per call)    {1e6 * t_ss / points.size:8.1f} µs/call   "
          f"({t_ss / t_ev:.1f}x)")


if __name__ == "__main__":
    main()
