"""The Va jump scan of every record with an Attocube (the recordings stage's largest
check), against its numpy and scipy form, in one run.

    python benchmarks/bench_va_jumps.py [--repeats 20]

On a huddle-test-sized Va (1,010,000 samples, a nanometre of noise): the increments'
residuals from their running median of nine, compiled (``va_jumps._increment_residuals``)
against numpy's diff, nonzero and take with ``scipy.ndimage.median_filter`` (the peer,
and the form the rule is written in); then the whole ``find_jumps``. Prints medians and
the ratio; the two give the same bits (tests/io/test_va_jumps.py).
"""

from __future__ import annotations

import argparse

import numpy as np
from scipy.ndimage import median_filter

from fsmbench.io.va_jumps import MEDIAN_HALF_WIDTH, _increment_residuals, find_jumps
from timing import timed_runs


def _by_scipy(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    d = np.diff(x)
    steps = np.flatnonzero(d != 0.0)
    dn = d[steps]
    return steps, dn - median_filter(dn, size=2 * MEDIAN_HALF_WIDTH + 1, mode="mirror")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--repeats", type=int, default=20)
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    va = np.cumsum(rng.normal(0.0, 1e-10, 1_010_000)) + rng.normal(0.0, 1e-9, 1_010_000)
    ours = timed_runs(lambda: _increment_residuals(va), args.repeats)[0]
    peer = timed_runs(lambda: _by_scipy(va), args.repeats)[0]
    whole = timed_runs(lambda: find_jumps(va), args.repeats)[0]
    print(f"{va.size} samples of Va, median of {args.repeats}")
    print(f"residuals  fsmbench {ours * 1e3:6.1f} ms   numpy + scipy.ndimage.median_filter "
          f"{peer * 1e3:6.1f} ms   ratio {peer / ours:4.1f}x")
    print(f"find_jumps {whole * 1e3:6.1f} ms in all (the noise scale's block medians are numpy's)")


if __name__ == "__main__":
    main()
