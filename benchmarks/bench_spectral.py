"""Benchmark: one-pass ``spectral_matrix`` vs the scipy.signal calls a user would write.

Data: the seed's identification layout - two experiments (``data_uch`` excites
``Uch``, ``data_ucv`` excites ``Ucv``), 31 s each at 10 kHz, white-noise input
through a lightly damped second-order resonance at 411 Hz plus measurement
noise, two outputs (``Vph``, ``Vpv``). Window ``hanning(10000)`` (MATLAB's, the
seed's ``hanning(ceil(1*fs))``), MATLAB defaults: noverlap 5000, nfft 16384,
no detrending.

(a) fsmbench: one ``spectral_matrix`` per experiment + ``combine_columns`` ->
    the 2x2 FRF matrix, its 4 coherences (and PSDs and confidence bounds).
(b) scipy: for each of the 4 pairs, ``tfestimate`` as ``csd(x, y) / welch(x)``
    and ``mscohere`` as ``coherence(x, y)``: 4 x (csd + welch) + 4 coherence =
    12 scipy.signal calls, ~28 channel-FFT passes vs 6 for (a).

Run: ``python benchmarks/bench_spectral.py [--repeats 7] [--seed 0]``.
"""

from __future__ import annotations

import argparse
import os

import numpy as np
import scipy
import scipy.signal as ss

from fsmbench.ident import FrequencyResponse, combine_columns, hanning, spectral_matrix
from timing import timed_runs

FS_HZ = 1e4
DURATION_S = 31.0
F0_HZ, ZETA = 411.0, 0.01  # the seed's first mode, lightly damped
OUTPUTS = ("Vph", "Vpv")
COUPLING = {"Uch": (1.0, 0.15), "Ucv": (0.1, 0.7)}  # (Vph, Vpv) gain of each excitation


def resonance() -> tuple[np.ndarray, np.ndarray]:
    """Digital w0^2/(s^2 + 2 zeta w0 s + w0^2), bilinear with pre-warping at F0_HZ."""
    w0 = 2.0 * FS_HZ * np.tan(np.pi * F0_HZ / FS_HZ)  # pre-warped: peak lands on 411 Hz
    return ss.bilinear([w0**2], [1.0, 2.0 * ZETA * w0, w0**2], fs=FS_HZ)


def make_data(seed: int) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Experiment name -> (input (N,), outputs (N, 2))."""
    rng = np.random.default_rng(seed)
    b, a = resonance()
    n = int(DURATION_S * FS_HZ)
    data = {}
    for name, (g_h, g_v) in COUPLING.items():
        u = rng.standard_normal(n)
        y = ss.lfilter(b, a, u)
        outputs = np.column_stack([g_h * y, g_v * y]) + 0.05 * rng.standard_normal((n, 2))
        data[name] = (u, outputs)
    return data


def run_fsmbench(
    data: dict[str, tuple[np.ndarray, np.ndarray]], win: np.ndarray
) -> FrequencyResponse:
    columns = [
        spectral_matrix(u, y, input_names=[name], output_names=list(OUTPUTS), window=win,
                        fs_hz=FS_HZ)
        for name, (u, y) in data.items()
    ]
    return combine_columns(columns)


def run_scipy(
    data: dict[str, tuple[np.ndarray, np.ndarray]], win: np.ndarray
) -> tuple[dict[tuple[str, str], np.ndarray], dict[tuple[str, str], np.ndarray]]:
    kw = {"fs": FS_HZ, "window": win, "noverlap": win.size // 2, "nfft": 16384, "detrend": False}
    tf, coh = {}, {}
    for name, (u, y) in data.items():
        for k, out in enumerate(OUTPUTS):
            _, pxy = ss.csd(u, y[:, k], **kw)  # scipy: conj(U) Y, i.e. MATLAB's Pyx
            _, pxx = ss.welch(u, **kw)
            tf[(out, name)] = pxy / pxx
            _, coh[(out, name)] = ss.coherence(u, y[:, k], **kw)
    return tf, coh



def max_relative_difference(a: np.ndarray, b: np.ndarray) -> float:
    scale = np.maximum(np.abs(b), np.finfo(float).tiny)
    return float(np.max(np.abs(a - b) / scale))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=7, help="timed repetitions (>= 7)")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    repeats = max(7, args.repeats)

    data = make_data(args.seed)
    win = hanning(int(np.ceil(1 * FS_HZ)))
    print(f"numpy {np.__version__}, scipy {scipy.__version__}, {os.cpu_count()} CPU(s)")
    print(f"2 experiments x {DURATION_S:g} s at {FS_HZ:g} Hz, window hanning({win.size}), "
          f"{repeats} timed runs each\n")

    t_ours, runs_ours = timed_runs(lambda: run_fsmbench(data, win), repeats)
    t_scipy, runs_scipy = timed_runs(lambda: run_scipy(data, win), repeats)

    g = run_fsmbench(data, win)
    tf, coh = run_scipy(data, win)
    d_tf = max(max_relative_difference(g.frf.sel(output=o, input=i).values, v)
               for (o, i), v in tf.items())
    d_coh = max(max_relative_difference(g.coherence.sel(output=o, input=i).values, v)
                for (o, i), v in coh.items())

    print(f"(a) fsmbench spectral_matrix x2 + combine_columns : median {t_ours * 1e3:8.1f} ms  "
          f"(runs: {', '.join(f'{t * 1e3:.0f}' for t in runs_ours)})")
    print(f"(b) scipy 4x(csd + welch) + 4x coherence          : median {t_scipy * 1e3:8.1f} ms  "
          f"(runs: {', '.join(f'{t * 1e3:.0f}' for t in runs_scipy)})")
    print(f"speed-up (b)/(a): {t_scipy / t_ours:.2f}x")
    print(f"max relative difference: FRF {d_tf:.2e}, coherence {d_coh:.2e}")
    print(f"averages per column: K = {g.n_segments[0]}, n_d = {g.effective_averages[0]:.1f}")


if __name__ == "__main__":
    main()
