"""``fsmbench design DATA --out OUT``: ESRF study sections 5-10 (plant analysis,
controllers, verification on the bench identified from DATA, export).

    fsmbench design DATA --out OUT [--params FILE] [--seed N] [--bench DIR] [--json]
"""

from __future__ import annotations

import argparse
import sys
from typing import Any

from fsmbench.cli.commands.budget import add_stage_options, check_identification, plant_of
from fsmbench.cli.inputs import StageInput, print_document, sim_bench, stage_folder, stage_input
from fsmbench.cli.options import add_json, add_seed
from fsmbench.report.text import design_table

__all__ = ["register", "run"]

# design.json, controllers.mat, controllers_sos.json and run.json.
_SMALL_BYTES = 1e6

def register(sub: Any) -> None:
    """Add ``design`` to the sub-commands ``sub``."""
    p = sub.add_parser("design", help="ESRF study sections 5-10: plant analysis, controllers, "
                                      "verification on the twin, export")
    add_stage_options(p, simulates=True)
    add_json(p, help="print design.json's content on stdout instead of the table")
    add_seed(p, help="random seed of the closed-loop verification's twin (default 0)")
    p.set_defaults(func=run)


def _simulated(args: argparse.Namespace, inp: StageInput, plant: Any) -> Any:
    """The bench the design's closed-loop check runs: identified, never the packaged twin."""
    from fsmbench.stages import SimulationBench, simulation_bench

    if args.bench_dir is not None:
        return SimulationBench(sim_bench(args))
    return simulation_bench(bench=inp.bench, is_twin=False,
                            identification=plant.identification,
                            label=f"the bench identified from the recordings in {inp.data}")


def run(args: argparse.Namespace) -> int:
    """Design and verify; the table of margins (or design.json) is the result."""
    from fsmbench.stages import IDENT_EXPERIMENTS, design_stage

    check_identification(args)
    with stage_folder(args, _SMALL_BYTES) as folder:
        inp = stage_input(args, uses=IDENT_EXPERIMENTS if args.bench_dir is None else ())
        plant = plant_of(args, inp)
        stage = design_stage(bench=inp.bench, out_dir=folder.staging, plant=plant,
                             seed=args.seed, progress=inp.say,
                             simulated=_simulated(args, inp, plant))
    paths = stage.files
    for path in paths:
        print(f"wrote {folder.final_path(path)}", file=sys.stderr)
    if args.json:
        print_document(folder, paths, "design.json")
    else:
        print("\n".join(design_table(stage.payload)))
    return 0
