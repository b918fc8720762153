"""The recorded loop's controller fit (``ident.evidence.recorded_loop._fit_record``) against
its peer, ``numpy.linalg.lstsq`` on the whole design ``[K y, 1, t, t^2]`` per lag (what
it replaced), on the twin's closed-loop records.

    python benchmarks/bench_recorded_loop.py [--repeats 5]

Prints the median time of each over the records of one twin run (huddle tests 3 and 5,
``data_rep_h``, both axes), the ratio, and the largest relative difference of the
controller's coefficient (the two solve the same least squares).
"""

from __future__ import annotations

import argparse

import numpy as np
import scipy.signal

from fsmbench.bench.params import default_bench
from fsmbench.ident.evidence.recorded_loop import _LAGS, SETTLE_S, esrf_sos, fit_record
from fsmbench.twin.simulate import simulate_bench
from timing import timed_runs


def _lstsq_coefficient(u: np.ndarray, y: np.ndarray, *, axis: str, fs_hz: float) -> float:
    """The peer: a full least squares per lag, the best lag's coefficient on ``K y``."""
    k0 = round(SETTLE_S * fs_hz)
    uc = u[k0:]
    sos = esrf_sos(axis, fs_hz)
    t = np.arange(uc.size) / fs_hz
    t = t / t[-1]
    best = (-np.inf, 0.0)
    for lag in _LAGS:
        yl = np.concatenate([np.zeros(lag), y[:y.size - lag]]) - float(np.mean(y))
        x = np.column_stack([scipy.signal.sosfilt(sos, yl)[k0:], np.ones_like(t), t, t * t])
        coef, *_ = np.linalg.lstsq(x, uc, rcond=None)
        explained = 1.0 - float(np.var(uc - x @ coef)) / float(np.var(uc))
        best = max(best, (explained, float(coef[0])))
    return best[1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    bench = default_bench()
    conv = bench.nominal.converter
    run = simulate_bench(bench, seed=3, experiments=["data_huddle_test_3",
                                                     "data_huddle_test_5", "data_rep_h"])
    cases = [(name, np.asarray(ds[c].values, float), np.asarray(ds[r].values, float), c[-1])
             for name, ds in run.recordings.items() for c, r in (("Uch", "Vph"), ("Ucv", "Vpv"))]
    ours = timed_runs(lambda: [fit_record(n, u, y, axis=a, fs_hz=conv.fs_hz,
                                           step_v=conv.lsb_v) for n, u, y, a in cases],
                      args.repeats)[0]
    peer = timed_runs(lambda: [_lstsq_coefficient(u, y, axis=a, fs_hz=conv.fs_hz)
                               for _n, u, y, a in cases], args.repeats)[0]
    diff = max(abs(-1.0 / fit_record(n, u, y, axis=a, fs_hz=conv.fs_hz,
                                      step_v=conv.lsb_v).gd_used_v_per_rad
                   - _lstsq_coefficient(u, y, axis=a, fs_hz=conv.fs_hz))
               / abs(_lstsq_coefficient(u, y, axis=a, fs_hz=conv.fs_hz))
               for n, u, y, a in cases)
    samples = sum(u.size for _n, u, _y, _a in cases)
    print(f"{len(cases)} controller fits, {samples / 1e6:.1f} M samples, median of "
          f"{args.repeats}")
    print(f"  fsmbench (polynomial projected out once) {ours:7.3f} s")
    print(f"  numpy.linalg.lstsq on the whole design    {peer:7.3f} s")
    print(f"  ratio {peer / ours:.2f}x; largest relative difference of the coefficient "
          f"{diff:.1e}")


if __name__ == "__main__":
    main()
