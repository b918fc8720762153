"""``fsmbench study --out OUT``: the whole ESRF study, on the twin or on ``--data``.

    fsmbench study [--data DIR] --out OUT [--seed N] [--duration S] [--params FILE]
                   [--figures png,pdf] [--distance-target NM] [--montecarlo DIR] [--json]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from fsmbench.bench.params import Bench
from fsmbench.cli.args import figure_formats, nanometres, seconds
from fsmbench.cli.inputs import bench_of, check_data
from fsmbench.cli.options import (
    add_identify_options,
    add_json,
    add_out,
    add_params,
    add_seed,
    add_timestamp,
    identify_options,
)
from fsmbench.cli.runfolder import progress, run_folder

__all__ = ["register", "run"]

# What the stages write besides the twin's records, measured on the twin study:
# report.html 7.7 MB, frf.mat 1.5 MB, the JSON files and small MAT-files < 0.2 MB.
_STUDY_BYTES = 10e6
_FIGURE_BYTES = 20e6  # per static format of --figures (measured 13.5 MB of PNG, 12.9 MB of PDF)


def register(sub: Any) -> None:
    """Add ``study`` to the sub-commands ``sub``."""
    p = sub.add_parser("study", help="the whole study; the twin when no --data is given")
    add_params(p)
    add_timestamp(p)
    p.add_argument("--data", metavar="DIR", default=None,
                   help="folder of recordings (.mat, .h5, .nxs)")
    add_out(p)
    add_seed(p, help="random seed of the twin's noise (default 0)")
    p.add_argument("--duration", metavar="S", type=seconds, default=None,
                   help="twin record length [s] (default: the ESRF study's)")
    p.add_argument("--figures", metavar="FORMATS", type=figure_formats, default=(),
                   help="also write every figure as png and/or pdf into OUT/figures "
                        "(comma list: png, pdf, png,pdf; default none)")
    p.add_argument("--distance-target", metavar="NM", type=nanometres, default=5e-9,
                   dest="distance_target_m",
                   help="largest acceptable Attocube distance error, rms [nm] (default 5)")
    p.add_argument("--montecarlo", metavar="DIR", default=None,
                   help="a fsmbench montecarlo output (or its montecarlo.json): the report lists "
                        "the draws that break each requirement, the robustness row names one "
                        "broken by 5 %% of the draws or more")
    add_json(p, help="print the verdict (summary.json's content) on stdout instead of the "
                     "report's path and the verdict's line")
    add_identify_options(p)
    p.set_defaults(func=run)


def _check_study_memory(args: argparse.Namespace, bench: Bench) -> None:
    """The study simulates every record whole and analyses it in memory: refuse what won't fit."""
    from fsmbench.io.matfile import available_memory_bytes
    from fsmbench.twin.sizes import simulation_memory_bytes

    need = simulation_memory_bytes(bench, duration_s=args.duration)
    have = available_memory_bytes()
    if need > have:
        length = (f"--duration {args.duration:g} s" if args.duration is not None
                  else "the ESRF study's record lengths (no --duration given)")
        raise ValueError(
            f"{length} needs about {need / 1e9:.1f} GB of memory (the "
            f"study simulates every record whole, then analyses it in memory) and this machine "
            f"has {have / 1e9:.1f} GB available: shorten --duration, or for long records run "
            "fsmbench simulate OUT --format nexus --duration S, then fsmbench budget OUT, which "
            "reads them block by block")


def run(args: argparse.Namespace) -> int:
    """The study; the report's path and the verdict (or summary.json) are the result."""
    from fsmbench.report.summary import Specification
    from fsmbench.study import run_study
    from fsmbench.twin.sizes import twin_bytes

    data = None if args.data is None else Path(args.data)
    if data is not None:
        from fsmbench.io.outdir import check_out_dir

        check_out_dir(Path(args.out), data)
        check_data(data)
    bench = bench_of(args)
    montecarlo = None
    if args.montecarlo is not None:
        from fsmbench.scale.montecarlo_run import read_montecarlo

        montecarlo = read_montecarlo(args.montecarlo)  # read before --out may be replaced
    need = _STUDY_BYTES + _FIGURE_BYTES * len(args.figures)
    if data is None:
        need += twin_bytes("mat5", duration_s=args.duration)
        _check_study_memory(args, bench)
    say = progress()
    with run_folder(args, args.out, data=data, need_bytes=need) as folder:
        result = run_study(out_dir=folder.staging, data_dir=data, bench=bench, seed=args.seed,
                           duration_s=args.duration, progress=say, figures=args.figures,
                           spec=Specification(distance_error_max_m=args.distance_target_m),
                           identify_options=identify_options(args, data=data),
                           montecarlo=montecarlo)
    if args.json:
        print(f"wrote {folder.final_path(result.report)}", file=sys.stderr)
    else:
        print(folder.final_path(result.report))
    # Once each, one line each: what was not used, what failed a check, what to know.
    for name, why in result.skipped_experiments.items():
        print(f"skipped {name}: {why}", file=sys.stderr)
    if result.summary is not None:
        for check in result.summary.failed_checks:
            print(f"check failed: {check.sentence()}", file=sys.stderr)
        for notice in result.summary.notices:
            print(f"note: {notice.sentence()}", file=sys.stderr)
        # The verdict is the study's result: on stdout, after the report's path.
        if args.json:
            summary = Path(folder.final_path(result.report)).parent / "summary.json"
            print(summary.read_text(encoding="utf-8"), end="")
        else:
            print(f"verdict: {result.summary.verdict}")
    return 0
