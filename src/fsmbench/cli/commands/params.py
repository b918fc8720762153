"""``fsmbench params [--params FILE] [--out DIR] [--json]``: the bench's parameters with
their units and sources (the nominal model and the twin's truth)."""

from __future__ import annotations

import argparse
import sys
from typing import Any

from fsmbench.bench.params import param_rows, save_bench
from fsmbench.cli.inputs import bench_of
from fsmbench.cli.options import add_json, add_out, add_params, add_timestamp
from fsmbench.cli.runfolder import run_folder
from fsmbench.jsonutil import format_text, stamped

__all__ = ["register", "run"]

# bench.toml and run.json.
_SMALL_BYTES = 1e6


def register(sub: Any) -> None:
    """Add ``params`` to the sub-commands ``sub``."""
    p = sub.add_parser("params", help="print the bench parameters with units and sources")
    add_params(p)
    add_timestamp(p, where="run.json (with --out)")
    add_out(p, required=False, help="also write DIR/bench.toml")
    add_json(p, help="print JSON (format fsmbench.params) instead of a table")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Print the parameters; with ``--out`` also write them as ``bench.toml``."""
    bench = bench_of(args)
    rows = param_rows(bench)
    written = None
    if args.out is not None:
        with run_folder(args, args.out, data=None, need_bytes=_SMALL_BYTES) as folder:
            written = folder.final_path(save_bench(bench, folder.staging / "bench.toml"))
    if args.json:
        print(format_text(stamped({"bench": bench.origin,
                                   "parameters": [dict(r.__dict__) for r in rows]},
                                  format="fsmbench.params", version=1)), end="")
    else:
        width = max(len(r.key) for r in rows)
        print(f"{'parameter':<{width}}  {'nominal':<26} {'true (twin)':<26} {'unit':<9} source")
        for r in rows:
            print(f"{r.key:<{width}}  {r.nominal:<26} {r.true:<26} {r.unit:<9} {r.source}")
    if written is not None:
        print(f"wrote {written}", file=sys.stderr)
    return 0
