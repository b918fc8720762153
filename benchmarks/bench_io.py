"""Recording I/O speed against scipy.io, in one run.

    python benchmarks/bench_io.py [--repeats 5]

A seed huddle-test-sized record (1,010,000 samples x 12 signals, 16-bit
ADC values): fsmbench ``write_recording``/``read_recording`` (MAT v5, with
validation) against ``scipy.io.savemat``/``loadmat`` (compressed, no
validation) on the same variables. Prints medians and ratios.
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np
import scipy.io

from fsmbench.io.recording import make_recording, read_recording, write_recording
from fsmbench.io.signals import SIGNALS
from timing import timed_runs


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    n, lsb = 1_010_000, 20.0 / 2**16
    signals = {name: np.round(rng.standard_normal(n) * 3000) * lsb for name in SIGNALS}
    ds = make_recording(signals, fs_hz=1e4, experiment="data_rep_h")
    plain = {"t": ds["t"].values.reshape(-1, 1),
             **{k: v.reshape(-1, 1) for k, v in signals.items()}}
    with tempfile.TemporaryDirectory() as tmp:
        ours = Path(tmp) / "ours.mat"
        peer = Path(tmp) / "peer.mat"
        t_w = timed_runs(lambda: write_recording(ds, ours), args.repeats, warm_up=False)[0]
        t_pw = timed_runs(lambda: scipy.io.savemat(peer, plain, do_compression=True),
                           args.repeats, warm_up=False)[0]
        t_r = timed_runs(lambda: read_recording(ours), args.repeats, warm_up=False)[0]
        t_pr = timed_runs(lambda: scipy.io.loadmat(peer), args.repeats, warm_up=False)[0]
        size, psize = ours.stat().st_size, peer.stat().st_size
    print(f"{n} samples x {len(signals) + 1} variables (MAT v5, compressed)")
    print(f"write  fsmbench {t_w * 1e3:8.1f} ms   scipy.io.savemat {t_pw * 1e3:8.1f} ms"
          f"   ratio {t_pw / t_w:5.2f}x   sizes {size / 1e6:.1f} / {psize / 1e6:.1f} MB")
    print(f"read   fsmbench {t_r * 1e3:8.1f} ms   scipy.io.loadmat {t_pr * 1e3:8.1f} ms"
          f"   ratio {t_pr / t_r:5.2f}x   (fsmbench also validates every signal)")


if __name__ == "__main__":
    main()
