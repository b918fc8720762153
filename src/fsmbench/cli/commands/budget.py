"""``fsmbench budget DATA --out OUT``: ESRF study sections 3, 4 and 11 (huddle tests,
noise and error budget, repeatability).

    fsmbench budget DATA --out OUT [--params FILE] [--bench DIR] [--json]
"""

from __future__ import annotations

import argparse
import sys
from typing import Any

from fsmbench.cli.args import typed_option
from fsmbench.cli.inputs import (
    StageInput,
    print_document,
    sim_bench,
    stage_folder,
    stage_input,
)
from fsmbench.cli.options import add_bench, add_json, add_out, add_params, add_timestamp
from fsmbench.cli.runfolder import check_inputs_first

__all__ = ["add_stage_options", "check_identification", "plant_of", "register", "run"]

# budget.json, its MAT-files and run.json.
_SMALL_BYTES = 1e6


def add_stage_options(p: argparse.ArgumentParser, *, simulates: bool) -> None:
    """``DATA --out DIR [--params FILE] [--timestamp] [--bench DIR]`` of ``budget`` and
    ``design`` (``simulates``: the identified bench also runs the closed-loop check)."""
    add_params(p)
    add_timestamp(p)
    p.add_argument("data", metavar="DATA", help="folder of recordings (.mat, .h5, .nxs)")
    add_out(p)
    add_bench(p, alias=True, help="the bench identified in DIR (the output of fsmbench identify "
                                  "or study: identification.json and plant.mat): its plant, "
                                  "instead of identifying DATA again"
                                  + ("; its simulation for the closed-loop check" if simulates
                                     else ""))


def register(sub: Any) -> None:
    """Add ``budget`` to the sub-commands ``sub``."""
    p = sub.add_parser("budget", help="ESRF study sections 3, 4, 11: huddle tests, error "
                                      "budget, repeatability")
    add_stage_options(p, simulates=False)
    add_json(p, help="print budget.json's content on stdout instead of the total")
    p.set_defaults(func=run)


def plant_of(args: argparse.Namespace, inp: StageInput) -> Any:
    """The plant of ``--bench DIR``, else the one identified from the recordings (or the
    bench file's model where they cannot give one)."""
    from fsmbench.stages import choose_plant

    if args.bench_dir is not None:
        from fsmbench.ident.load import load_identified_plant

        plant = load_identified_plant(args.bench_dir,
                                      option=typed_option(args, "bench_dir", "--bench"))
    else:
        plant = choose_plant(inp.recordings, bench=inp.bench, progress=inp.say,
                             source=str(inp.data))
    inp.say(f"plant: {plant.source}")
    return plant


def check_identification(args: argparse.Namespace) -> None:
    """The inputs, and ``--bench DIR``'s files, before any work (one line each)."""
    check_inputs_first(args, args.out, args.data)
    if args.bench_dir is not None:
        sim_bench(args)


def run(args: argparse.Namespace) -> int:
    """The budget; its total (or budget.json) is the result."""
    from fsmbench.stages import budget_stage

    check_identification(args)
    with stage_folder(args, _SMALL_BYTES) as folder:
        inp = stage_input(args)
        plant = plant_of(args, inp)
        inp.say("noise and error budget, huddle tests, repeatability (ESRF study sections 3, 4, "
                "11)")
        stage = budget_stage(inp.recordings, bench=inp.bench, out_dir=folder.staging,
                             plant=plant, progress=inp.say)
    result, paths = stage.result, stage.files
    # The result on stdout, the files and what was skipped on stderr.
    for path in paths:
        print(f"wrote {folder.final_path(path)}", file=sys.stderr)
    if args.json:
        print_document(folder, paths, "budget.json")
    else:
        print(f"total {1e9 * result.total_rms_m:.3g} nm rms; limiting source: "
              f"{result.limiting}")
        # The study's verdict quotes another controller's budget: say so, or the two look
        # unequal.
        print("with the ESRF study's controller as recorded (the study's budget.json has the "
              "same total; its verdict quotes fsmbench's controller, budget.json's "
              "recommended)")
    for part, why in result.skipped.items():
        print(f"skipped {part}: {why}", file=sys.stderr)
    return 0
