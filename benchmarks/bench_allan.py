"""The in-memory overlapping Allan deviation against its peer, allantools.

    python benchmarks/bench_allan.py [--repeats 5] [--samples 1000000]

Times :func:`fsmbench.signal.allan.allan_deviation` on one 100 s record at
10 kHz (a huddle test's ``Va``: nanometre noise on a 0.7 m distance, octave
taus up to N/4) against ``allantools.oadev`` on the same record and taus,
and against the NumPy slicing fsmbench used before (three temporaries of N
per tau), in the same run; prints medians, ratios and the largest relative
difference of the deviations.
"""

from __future__ import annotations

import argparse

import allantools
import numpy as np

from fsmbench.signal.allan import allan_deviation
from timing import timed_runs


def _numpy_slices(y: np.ndarray, m: np.ndarray) -> np.ndarray:
    """The previous in-memory kernel: slices of the cumulative sum, one dot per tau."""
    c = np.concatenate([[0.0], np.cumsum(y - y[0])])
    out = np.empty(m.size)
    for i, mi in enumerate(int(v) for v in m):
        block = c[mi:] - c[:-mi]
        d = block[mi:] - block[:-mi]
        out[i] = np.sqrt(np.dot(d, d) / (2.0 * mi**2 * (y.size - 2 * mi + 1)))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--samples", type=int, default=1_000_000)
    args = parser.parse_args()
    fs = 10_000.0
    rng = np.random.default_rng(0)
    y = 0.7 + 1e-9 * rng.standard_normal(args.samples) + 1e-12 * np.cumsum(
        rng.standard_normal(args.samples))
    ours = allan_deviation(y, fs_hz=fs)
    t_ours, _ = timed_runs(lambda: allan_deviation(y, fs_hz=fs), args.repeats)
    t_np, _ = timed_runs(lambda: _numpy_slices(y, ours.m), args.repeats)
    t_ref, _ = timed_runs(lambda: allantools.oadev(y, rate=fs, data_type="freq",
                                                   taus=ours.tau_s), args.repeats)
    ref = allantools.oadev(y, rate=fs, data_type="freq", taus=ours.tau_s)[1]
    diff = float(np.max(np.abs(ours.adev / ref - 1.0)))
    diff_np = float(np.max(np.abs(ours.adev / _numpy_slices(y, ours.m) - 1.0)))
    print(f"overlapping Allan deviation, {args.samples} samples, {ours.m.size} octave taus, "
          f"median of {args.repeats}")
    print(f"  fsmbench (compiled, one pass per tau)  {t_ours * 1e3:8.1f} ms")
    print(f"  NumPy slices (the previous kernel)     {t_np * 1e3:8.1f} ms   "
          f"ratio {t_np / t_ours:5.1f}x   largest relative difference {diff_np:.1e}")
    print(f"  allantools.oadev                       {t_ref * 1e3:8.1f} ms   "
          f"ratio {t_ref / t_ours:5.1f}x   largest relative difference {diff:.1e}")


if __name__ == "__main__":
    main()
