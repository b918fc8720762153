"""``python -m indsim OUT [--bench NAME ...] [--seed N] [--duration-scale X]
[--bench-toml] [--compress]``."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from .corpus import corpus
from .write import timed_write


def main(argv: list[str] | None = None) -> int:
    """Write ``OUT/<bench>/`` (13 .mat + truth.json) for the named benches."""
    benches = corpus()
    ap = argparse.ArgumentParser(prog="python -m indsim", description=__doc__)
    ap.add_argument("out", type=Path, help="output folder")
    ap.add_argument("--bench", nargs="+", choices=sorted(benches), metavar="NAME",
                    help=f"benches to write (default all: {', '.join(benches)})")
    ap.add_argument("--seed", type=int, default=0, help="noise seed (default 0)")
    ap.add_argument("--duration-scale", type=float, default=1.0,
                    help="fraction of the study's record lengths (default 1)")
    ap.add_argument("--bench-toml", action="store_true",
                    help="also write OUT/<bench>.toml, the bench in fsmbench's bench-file "
                         "format (for --params)")
    ap.add_argument("--compress", action="store_true",
                    help="zip the MAT variables (about 5x smaller, slower to write)")
    args = ap.parse_args(argv)
    if not args.duration_scale > 0:
        ap.error("--duration-scale must be positive")
    for name in args.bench or list(benches):
        print(timed_write(benches[name], args.out, args.seed, args.duration_scale,
                          args.compress, args.bench_toml), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
