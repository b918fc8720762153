"""Recording I/O speed against scipy.io, in one run.

    python benchmarks/bench_io.py [--repeats 5]

A seed huddle-test-sized record (1,010,000 samples x 12 signals, 16-bit
ADC values): fsmbench ``write_recording``/``read_recording`` (MAT v5, with
validation) against ``scipy.io.savemat``/``loadmat`` (compressed, no
validation) on the same variables; then the compression alone, fsmbench's deflate
(ISA-L, ``matwrite._deflate``) against zlib's level 1 (its choice before) and
scipy's level. Prints medians and ratios.
"""

from __future__ import annotations

import argparse
import tempfile
import zlib
from pathlib import Path

import numpy as np
import scipy.io

from fsmbench.io import matwrite
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
    raw = [np.ascontiguousarray(v).tobytes() for v in plain.values()]
    total = sum(len(b) for b in raw)
    for label, deflate in (("zlib level 1", lambda b: zlib.compress(b, 1)),
                           ("zlib level 6 (scipy's)", lambda b: zlib.compress(b, 6))):
        t_d = timed_runs(lambda: [matwrite._deflate(b) for b in raw], args.repeats)[0]
        t_z = timed_runs(lambda f=deflate: [f(b) for b in raw], args.repeats)[0]
        ours_b = sum(len(matwrite._deflate(b)) for b in raw)
        peer_b = sum(len(deflate(b)) for b in raw)
        print(f"deflate {total / 1e6:.0f} MB: fsmbench {t_d * 1e3:7.1f} ms ({ours_b / total:.3f} "
              f"of the size)   {label} {t_z * 1e3:7.1f} ms ({peer_b / total:.3f})   ratio "
              f"{t_z / t_d:5.2f}x")


if __name__ == "__main__":
    main()
