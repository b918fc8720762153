"""What a run of the twin takes: its records' bytes on disk, and the memory of simulating
them whole (what ``fsmbench simulate`` and ``fsmbench study`` check before they start)."""

from __future__ import annotations

import os
from collections.abc import Sequence

from fsmbench.bench.params import Bench
from fsmbench.twin.experiments import esrf_experiments

__all__ = ["simulation_memory_bytes", "twin_bytes"]

# Bytes a record-second of twin data takes on disk, measured on `fsmbench simulate`
# (seed 0, the seed's lengths, 737.5 s of records in all): 76.65 MB as compressed
# MATLAB v5, 313.6 MB of raw float64 (what v7.3 and NeXus store uncompressed).
_TWIN_BYTES_PER_S = {"mat5": 76.65e6 / 737.5, "mat73": 313.6e6 / 737.5,
                     "nexus": 313.6e6 / 737.5}
# Peak memory of `fsmbench simulate` in the mat5/mat73 formats, which simulate every record
# in memory before writing (measured peak RSS, /usr/bin/time, 10 kHz): 0.33 GB of interpreter,
# numba and plant; one experiment of d seconds peaks at 0.33 GB + 4.85 MB per record-second
# (data_uch, data_cal_pd_h, data_huddle_test_1/3, data_rep_h at 200 s: 1.23-1.30 GB; data_rep_h
# at 400 s: 2.27 GB), i.e. ~61 float64 per sample in flight; the records finished before the
# others are held at <= 11 float64 per sample (t + the 10 signals of data_rep_*). The model
# over-estimates the default run (1.78 GB against 1.52 GB measured) and 13 x 60 s (1.49 GB
# against 1.20 GB).
_SIM_BASE_BYTES = 0.33e9
_SIM_WORKING_BYTES_PER_SAMPLE = 4.85e6 / 1e4
_SIM_HELD_BYTES_PER_SAMPLE = 11 * 8


def _durations(experiments: Sequence[str] | None, duration_s: float | None) -> list[float]:
    specs = esrf_experiments()
    if experiments:
        specs = tuple(s for s in specs if s.name in set(experiments))
    return [duration_s if duration_s is not None else s.duration_s for s in specs]


def twin_bytes(fmt: str, *, experiments: Sequence[str] | None = None,
               duration_s: float | None = None) -> float:
    """Bytes the twin's records take on disk [B].

    Parameters
    ----------
    fmt : {"mat5", "mat73", "nexus"}
    experiments : sequence of str, optional
        Only these of the ESRF study's experiments (default all thirteen).
    duration_s : float, optional
        Every record's length [s] (default the ESRF study's).
    """
    return sum(_durations(experiments, duration_s)) * _TWIN_BYTES_PER_S[fmt]


def simulation_memory_bytes(bench: Bench, *, experiments: Sequence[str] | None = None,
                            duration_s: float | None = None,
                            excitation_files: int = 0) -> float:
    """Peak memory of simulating the records in memory [B] (the model above the constants).

    Parameters
    ----------
    bench : Bench
        Its converter rate sets the samples per second.
    experiments : sequence of str, optional
        Only these of the ESRF study's experiments (default all thirteen).
    duration_s : float, optional
        Every record's length [s] (default the ESRF study's).
    excitation_files : int
        Designed excitations played besides, one record of ``duration_s`` each (counted only
        with ``duration_s``: otherwise their own lengths, which ``excite`` bounds).
    """
    durations = _durations(experiments, duration_s)
    if duration_s is not None:
        durations += [duration_s] * excitation_files
    durations.sort(reverse=True)
    in_flight = max(1, min(len(durations), os.cpu_count() or 1))  # simulate_bench's threads
    fs = bench.true.converter.fs_hz
    return (_SIM_BASE_BYTES + _SIM_WORKING_BYTES_PER_SAMPLE * fs * sum(durations[:in_flight])
            + _SIM_HELD_BYTES_PER_SAMPLE * fs * sum(durations[in_flight:]))
