"""A MAT-file followed by zeros: fsmbench against scipy.io.loadmat and h5py (issue 30, item 7).

    python benchmarks/bench_padding.py [--repeats 5] [--timeout 600] [--samples 100000]

A data_uch record (``--samples`` samples of t, Uch, Vch, Vph, Vpv) is written by
scipy (MAT v5, compressed and not) and by h5py in MATLAB's v7.3 layout, then
followed by 64 MiB and 20 GiB of zeros (``os.truncate``: a sparse hole, no disk
used). Timed, medians of ``--repeats`` runs (one run when it passes ``--timeout``
seconds, then stopped and printed as ``> timeout``):

- ``folder``: ``fsmbench.io.folder.load_recordings`` on a folder holding the file,
  what ``fsmbench identify`` and ``study`` do (the path that ran past 300 s);
- ``read``: ``fsmbench.io.recording.read_recording`` of the file;
- ``peer``: ``scipy.io.loadmat`` (v5) or h5py reading every dataset (v7.3) on the
  same file.

Each is timed on the file before padding too.

Each line says what the reader returned (the variables, or the error's first
words). Run it with ``PYTHONPATH`` at another checkout's ``src`` to time that one.
"""

from __future__ import annotations

import argparse
import contextlib
import functools
import os
import signal
import tempfile
import warnings
from collections.abc import Callable
from pathlib import Path
from types import FrameType
from typing import Any

import h5py
import numpy as np
import scipy.io

from fsmbench.io.folder import load_recordings
from fsmbench.io.recording import read_recording
from timing import timed_runs

PADS = {"64 MiB": 64 << 20, "20 GiB": 20 << 30}
HEADER = (b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: Mon Sep 21 10:00:00 2020 "
          b"HDF5 schema 1.00 .")


class _TooLongError(Exception):
    pass


def _alarm(_signum: int, _frame: FrameType | None) -> None:
    raise _TooLongError


def _variables(n: int) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(0)
    lsb = 20.0 / 2**16
    out = {"t": np.arange(n) / 1e4}
    out.update({k: np.round(rng.standard_normal(n) * 3000) * lsb
                for k in ("Uch", "Vch", "Vph", "Vpv")})
    return out


def _write(fmt: str, path: Path, v: dict[str, np.ndarray]) -> None:
    if fmt == "v7.3":
        with h5py.File(path, "w", userblock_size=512) as f:
            for name, x in v.items():
                f.create_dataset(name, data=x.reshape(1, -1)).attrs["MATLAB_class"] = \
                    np.bytes_("double")
        with open(path, "r+b") as fh:
            fh.write(HEADER.ljust(116, b" ") + b"\x00" * 8 + b"\x00\x02IM")
        return
    scipy.io.savemat(path, {k: x.reshape(-1, 1) for k, x in v.items()},
                     do_compression=fmt == "v5 compressed")


def _h5_all(path: Path) -> dict[str, Any]:
    with h5py.File(path, "r") as f:
        return {k: f[k][()] for k in f}


def _measure(fn: Callable[[], Any], repeats: int, timeout: float) -> tuple[str, str]:
    """(time, outcome) of ``fn``: the median of ``repeats`` runs, or ``> timeout``."""
    saved = signal.signal(signal.SIGALRM, _alarm)
    outcome = ""
    try:
        signal.setitimer(signal.ITIMER_REAL, timeout)
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                result = fn()
            outcome = _outcome(result)
        except _TooLongError:
            return f"> {timeout:g} s", "stopped"
        except Exception as exc:
            outcome = f"raises {type(exc).__name__}: {str(exc).split(': ', 1)[-1][:60]}"
        finally:
            signal.setitimer(signal.ITIMER_REAL, 0)

        def quiet() -> None:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                with contextlib.suppress(Exception):  # the outcome is printed above
                    fn()
        median, _runs = timed_runs(quiet, repeats, warm_up=False)
    finally:
        signal.signal(signal.SIGALRM, saved)
    return f"{median * 1e3:9.2f} ms", outcome


def _outcome(result: Any) -> str:
    if hasattr(result, "recordings"):
        return (f"records {', '.join(result.recordings) or 'none'}"
                + "".join(f"; skipped {k}" for k in result.unusable()))
    if hasattr(result, "data_vars"):
        return f"variables {', '.join(map(str, result.data_vars))}"
    return f"variables {', '.join(k for k in result if not k.startswith('__'))}"


def _bench_format(fmt: str, v: dict[str, np.ndarray], repeats: int, timeout: float) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        data = Path(tmp) / "data"
        data.mkdir()
        path = data / "data_uch.mat"
        _write(fmt, path, v)
        size = path.stat().st_size
        name = "h5py" if fmt == "v7.3" else "scipy.io.loadmat"
        peer = functools.partial(_h5_all if fmt == "v7.3" else scipy.io.loadmat, path)
        print(f"\n{fmt}, {size / 1e6:.1f} MB of data")
        for label, pad in {"no padding": 0, **PADS}.items():
            os.truncate(path, size + pad)
            for who, fn in (("fsmbench folder", functools.partial(load_recordings, data)),
                            ("fsmbench read", functools.partial(read_recording, path)),
                            (name, peer)):
                took, what = _measure(fn, repeats, timeout)
                print(f"  {label:<11} {who:<17} {took}   {what}", flush=True)
            os.truncate(path, size)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--timeout", type=float, default=600.0)
    parser.add_argument("--samples", type=int, default=100_000)
    args = parser.parse_args()
    v = _variables(args.samples)
    print(f"data_uch: {args.samples} samples x {len(v)} variables; medians of {args.repeats}")
    for fmt in ("v5 compressed", "v5", "v7.3"):
        _bench_format(fmt, v, args.repeats, args.timeout)


if __name__ == "__main__":
    main()
