"""``fsmbench convert IN OUT``: a recording copied into a chunked NeXus archive.

A MATLAB v5 file cannot be read in parts; converted, it is read lazily with
bounded memory (:mod:`fsmbench.io.lazy`). Registered by :mod:`fsmbench.cli`.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from pathlib import Path
from typing import Any

from fsmbench.cli_args import factor

__all__ = ["add_convert_command"]


def add_convert_command(sub: Any, *, progress: Callable[[], Callable[[str], None]]) -> None:
    """Register ``convert`` on the ``fsmbench`` subparsers ``sub``.

    ``progress`` makes the progress printer of the command line.
    """

    def run(args: argparse.Namespace) -> int:
        from fsmbench.io.lazy import convert_recording

        src, dest = Path(args.source), Path(args.dest)
        if not src.is_file():
            raise FileNotFoundError(2, "no such recording", str(src))
        if dest.resolve() == src.resolve():
            raise ValueError(f"{dest}: the output would replace the input; inputs are never "
                             "modified")
        if not dest.parent.is_dir():
            raise FileNotFoundError(2, "output folder does not exist", str(dest.parent))
        print(convert_recording(src, dest, fs_hz=args.fs_hz, progress=progress()))
        return 0

    p = sub.add_parser("convert", help="copy a recording into a chunked NeXus archive (long "
                                       "records: lazy reading, bounded memory)")
    p.add_argument("source", metavar="IN", help="MATLAB v5/v7.3 or NeXus recording")
    p.add_argument("dest", metavar="OUT", help="the NeXus archive to write (.h5)")
    p.add_argument("--format", choices=("nexus",), default="nexus",
                   help="output format (nexus: chunked HDF5, read lazily)")
    p.add_argument("--fs", metavar="HZ", type=factor, default=None, dest="fs_hz",
                   help="sampling rate [Hz] (default: from t)")
    p.set_defaults(func=run)
