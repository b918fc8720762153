"""``fsmbench identify DATA --out OUT``: ESRF study section 2 from the recordings (4QD,
amplifiers, Sercalo, Newport, the full plant), or with the loop closed.

    fsmbench identify DATA --out OUT [--params FILE] [--frf auto|welch|lpm|periodic]
                      [--weights seed|variance] [--closed-loop] [--json]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from fsmbench.cli.inputs import bench_of, print_document, stage_folder, stage_input
from fsmbench.cli.options import (
    add_identify_options,
    add_json,
    add_out,
    add_params,
    add_timestamp,
    identify_options,
)
from fsmbench.cli.runfolder import progress
from fsmbench.jsonutil import format_text

__all__ = ["register", "run"]

# identification.json, plant.mat, frf.mat, the bench files and run.json.
_IDENT_BYTES = 2e6

#: Identification steps in words (the ESRF study's section of each).
_STEP_WORDS = {"qd": "4QD calibration (2.1)", "current_amp": "current amplifiers (2.2)",
               "sercalo": "Sercalo (2.3)", "newport": "Newport (2.4)",
               "newport_dynamics": "Newport's dynamics (2.4)",
               "mode_refinement": "Sercalo modes on the full records (2.3)",
               "noise_model": "noise model of the huddle tests"}


def register(sub: Any) -> None:
    """Add ``identify`` to the sub-commands ``sub``."""
    p = sub.add_parser("identify", help="ESRF study section 2: 4QD, amplifiers, Sercalo, "
                                        "Newport, the full plant")
    add_params(p)
    add_timestamp(p)
    p.add_argument("data", metavar="DATA", help="folder of recordings (.mat, .h5, .nxs)")
    add_out(p)
    add_identify_options(p)
    p.add_argument("--closed-loop", action="store_true", dest="closed_loop",
                   help="identify the Sercalo from the closed-loop records data_cl_uch "
                        "and data_cl_ucv (joint input-output method), even beside "
                        "open-loop records; without it a folder of closed-loop records "
                        "only is detected")
    add_json(p, help="print the comparison as JSON on stdout instead of the table (with the "
                     "loop closed: identification.json's content)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Identify and write the identification folder; the comparison is the result."""
    from fsmbench.tune.closed_loop_folder import check_closed_loop_folder, is_closed_loop_folder

    asked = bool(args.closed_loop)
    if asked:
        check_closed_loop_folder(args.data)  # one line when DATA has no data_cl_*
    if asked or is_closed_loop_folder(args.data):  # or data_cl_* and no data_uch/ucv
        return _closed_loop(args, asked=asked)
    return _open_loop(args)


def _closed_loop(args: argparse.Namespace, *, asked: bool) -> int:
    from fsmbench.io.truth import read_twin_truth
    from fsmbench.tune.closed_loop_folder import identify_closed_loop_folder, summary_lines

    with stage_folder(args, _IDENT_BYTES) as folder:
        cl, paths = identify_closed_loop_folder(args.data, bench=bench_of(args),
                                                out_dir=folder.staging, progress=progress(),
                                                asked=asked)
    if args.json:
        print_document(folder, paths, "identification.json")
    else:
        print("\n".join(summary_lines(cl, read_twin_truth(Path(args.data)))))
    for path in paths:
        print(f"wrote {folder.final_path(path)}", file=sys.stderr)
    return 0


def _open_loop(args: argparse.Namespace) -> int:
    from fsmbench.io.truth import read_twin_truth
    from fsmbench.stages import identify_stage
    from fsmbench.twin.compare import comparison_json, readable_table

    with stage_folder(args, _IDENT_BYTES) as folder:
        reference = read_twin_truth(Path(args.data))
        inp = stage_input(args)
        stage = identify_stage(inp.recordings, bench=inp.bench, out_dir=folder.staging,
                               source=str(inp.data), progress=inp.say, unusable=inp.unusable,
                               options=identify_options(args, data=inp.data))
    result, paths = stage.result, stage.files
    for step, why in result.skipped.items():
        inp.say(f"step {step} skipped: {why}")
    for warning in result.warnings:
        print(f"fsmbench identify: warning: {warning}", file=sys.stderr)
    for path in paths:
        print(f"wrote {folder.final_path(path)}", file=sys.stderr)
    js = result.to_json()
    if args.json:
        print(format_text(comparison_json(
            js, reference=reference, bench=inp.bench,
            files=[str(folder.final_path(p)) for p in paths], skipped=result.skipped,
            warnings=list(result.warnings))), end="")
        return 0
    print("\n".join(readable_table(js, reference=reference, bench=inp.bench)))
    for finding in result.findings:
        print(f"found: {finding.sentence()}")
    if result.findings:
        print(f"the bench file that matches the records: "
              f"{folder.final_path(folder.staging / 'bench_identified.toml')}")
    for step, why in result.skipped.items():
        print(f"not identified: {_STEP_WORDS.get(step, step)}: "
              + _skip_sentence(why, frf=args.frf))
    return 0


def _skip_sentence(why: str, *, frf: str) -> str:
    """Why a step was skipped and what the user does about it, where the reason says it.

    A file present but not read is already named by the identification with its
    problem ("was not used (…): correct it or record it again"); a missing one
    gets "record it to identify it" here.
    """
    if "not periodic" in why and frf == "periodic":
        return (why.removesuffix("; use the LPM or Welch") + "; to identify it, run identify "
                "with --frf auto (periods averaged where the input repeats, the LPM "
                "elsewhere)")
    return "; ".join(
        f"{part}; record {part.removeprefix('missing ')} to identify it"
        if part.startswith("missing ") else part for part in why.split("; "))
