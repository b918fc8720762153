"""The Welch leakage bias (identify, Welch) against its definition summed directly.

    python benchmarks/bench_leakage_bias.py [--repeats 5]

``fsmbench.ident.frf.leakage.welch_leakage_bias`` on the lines of a 1 s Welch
estimate (10 kHz, nfft 16384: 8 192 lines) of a model with the twin's two
lightly damped Sercalo modes behind its delay, against the same function with
``exact=True``: the kernel's whole grid (257 model evaluations a line, NumPy),
the definition the fast path must reproduce. Prints the medians, their ratio
and the largest difference relative to the largest bias.
"""

from __future__ import annotations

import argparse

import numpy as np

from fsmbench.ident.frf.leakage import welch_leakage_bias
from fsmbench.signal.welch import hanning
from timing import timed_runs

FS_HZ = 10_000.0


def two_modes(f_hz: np.ndarray) -> np.ndarray:
    """The twin's Sercalo modes (251.2 Hz, ζ 1e-3; 411.5 Hz, ζ 1.2e-3) behind 150 µs, (F, 2, 1)."""
    s = 2j * np.pi * f_hz
    wn = [(2 * np.pi * fn, z) for fn, z in ((251.2, 1e-3), (411.5, 1.2e-3))]
    h = np.stack([w**2 / (s**2 + 2 * z * w * s + w**2) for w, z in wn], axis=1)[:, :, None]
    return h * np.exp(-s * 150e-6)[:, None, None]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    window = hanning(int(FS_HZ))
    f = np.arange(1, 8193) * FS_HZ / 16384
    ours_s, _ = timed_runs(lambda: welch_leakage_bias(two_modes, f, fs_hz=FS_HZ,
                                                      window=window), args.repeats)
    peer_s, _ = timed_runs(lambda: welch_leakage_bias(two_modes, f, fs_hz=FS_HZ,
                                                      window=window, exact=True), args.repeats)
    fast = welch_leakage_bias(two_modes, f, fs_hz=FS_HZ, window=window)
    exact = welch_leakage_bias(two_modes, f, fs_hz=FS_HZ, window=window, exact=True)
    print(f"{f.size} lines, a 2x1 model with two 0.1 %-damped modes")
    print(f"fsmbench welch_leakage_bias: {ours_s * 1e3:8.1f} ms (median of {args.repeats})")
    print(f"direct kernel sum:           {peer_s * 1e3:8.1f} ms")
    print(f"ratio direct / fsmbench:     {peer_s / ours_s:8.2f}x")
    worst = np.max(np.abs(fast - exact)) / np.max(np.abs(exact))
    print(f"largest difference / largest bias: {worst:.1e}")


if __name__ == "__main__":
    main()
