"""Timing shared by the benchmarks: the median of repeated runs, and every run."""

from __future__ import annotations

import statistics
import time
from collections.abc import Callable


def timed_runs(fn: Callable[[], object], repeats: int, *,
               warm_up: bool = True) -> tuple[float, list[float]]:
    """Median and list of ``repeats`` wall-clock times of ``fn()`` [s].

    ``warm_up`` runs ``fn`` once first, untimed (imports, FFT plans, JIT caches).
    """
    if warm_up:
        fn()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), times
