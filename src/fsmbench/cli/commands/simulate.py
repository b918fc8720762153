"""``fsmbench simulate OUT``: the ESRF study's 13 experiments on the digital twin.

    fsmbench simulate OUT [--duration S] [--seed N] [--params FILE] [--format F]
                      [--experiments NAME…] [--excitation FILE…] [--bench DIR]
                      [--closed-loop CONTROLLER [--at output|reference] [--max-error-urad U]]
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from pathlib import Path
from typing import Any

from fsmbench.bench.params import Bench
from fsmbench.cli.args import default_noted, seconds
from fsmbench.cli.inputs import sim_bench
from fsmbench.cli.options import (
    add_bench,
    add_closed_loop,
    add_json,
    add_out,
    add_params,
    add_seed,
    add_timestamp,
    out_folder,
)
from fsmbench.cli.runfolder import check_inputs_first, print_files, progress, run_folder

__all__ = ["SMALL_BYTES", "register", "run"]

#: run.json and the small files beside the records.
SMALL_BYTES = 1e6


def register(sub: Any) -> None:
    """Add ``simulate`` to the sub-commands ``sub``."""
    p = sub.add_parser("simulate", help="run the ESRF study's 13 experiments on the digital twin")
    add_params(p)
    add_timestamp(p)
    add_out(p, positional=True)
    p.add_argument("--duration", metavar="S", type=seconds, default=None,
                   help="length of every record [s] (default: the ESRF study's, 100 s huddle "
                        "tests)")
    add_seed(p, help="random seed (default 0)")
    p.add_argument("--format", choices=("mat5", "mat73", "nexus"), default="mat5",
                   help="file format (default: MATLAB v5)")
    p.add_argument("--experiments", metavar="NAME", nargs="+", default=None,
                   help="only these experiments (e.g. data_uch data_ucv)")
    p.add_argument("--excitation", metavar="FILE", default=None, nargs="+",
                   help="play these designed excitations (fsmbench excite: folder, .json or "
                        ".mat) each in its input's experiment instead of the ESRF study's noise; "
                        "--experiments adds the ESRF study's own")
    add_closed_loop(p, help="play the excitations with the loop closed by CONTROLLER (seed: the "
                            "ESRF study's; or a controllers file or fsmbench design folder, "
                            "PATH[::NAME]) and write data_cl_uch, data_cl_ucv; without "
                            "--excitation, beam-bounded multisines designed on the bench",
                    max_error_default=30.0,
                    max_error_help="with --closed-loop and no --excitation: the rms beam error "
                                   "the designed multisines may add [µrad] (default 30)")
    add_bench(p)
    add_json(p, help="print the files written as JSON (format fsmbench.files) instead of one "
                     "path a line")
    p.set_defaults(func=run)


def _check_simulation_memory(args: argparse.Namespace, bench: Bench) -> None:
    """Refuse an in-memory simulation larger than the memory available, with the way out."""
    from fsmbench.io.matfile import available_memory_bytes
    from fsmbench.twin.sizes import simulation_memory_bytes

    if args.excitation is None and args.format == "nexus":
        return  # streamed block by block
    if args.excitation is not None and args.duration is None:
        return  # the files' own lengths, which excite bounds
    need = simulation_memory_bytes(bench, experiments=args.experiments,
                                   duration_s=args.duration,
                                   excitation_files=len(args.excitation or ()))
    have = available_memory_bytes()
    if need <= have:
        return
    length = (f"--duration {args.duration:g} s" if args.duration is not None
              else "the ESRF study's record lengths")
    if args.excitation is not None:
        what, fix = ("--excitation", "an excitation is played in memory whatever the format: "
                                     "shorten --duration")
    else:
        what, fix = (default_noted(args, "format", f"--format {args.format}"),
                     "--format nexus streams the records to disk "
                     "block by block in bounded memory (0.39 GB measured for a day), or "
                     "shorten --duration")
    raise ValueError(f"{what}: {length} needs about {need / 1e9:.1f} GB of memory (every "
                     f"record is simulated whole before it is written) and this machine has "
                     f"{have / 1e9:.1f} GB available; {fix}")


def run(args: argparse.Namespace) -> int:
    """Simulate and write the records; their paths are the result."""
    from fsmbench.twin.simulate import play_excitation, stream_bench
    from fsmbench.twin.sizes import twin_bytes

    out = out_folder(args)
    assert out is not None  # out_folder raises for a command that needs one
    check_inputs_first(args, out, None)
    bench = sim_bench(args)
    _check_simulation_memory(args, bench)  # before anything is simulated or written
    need = twin_bytes(args.format, experiments=args.experiments, duration_s=args.duration)
    with run_folder(args, out, data=None, need_bytes=need + SMALL_BYTES) as folder:
        say = progress()
        if args.closed_loop is not None:
            paths = _closed_loop_simulation(args, bench, folder.staging, say)
        elif args.excitation is not None:
            paths = play_excitation(args.excitation, bench, out_dir=folder.staging,
                                    seed=args.seed, duration_s=args.duration,
                                    experiments=args.experiments, format=args.format,
                                    progress=say)
        elif args.format == "nexus":
            # Streamed block by block: any --duration in bounded memory.
            paths = stream_bench(bench, out_dir=folder.staging, seed=args.seed,
                                 duration_s=args.duration, experiments=args.experiments,
                                 progress=say)
        else:
            paths = _simulate_in_memory(args, bench, folder.staging, say)
    print_files([folder.final_path(p) for p in paths], as_json=args.json, command="simulate")
    say("done")
    return 0


def _simulate_in_memory(args: argparse.Namespace, bench: Bench, staging: Path,
                        say: Callable[[str], None]) -> list[Path]:
    from fsmbench.twin.simulate import simulate_bench, write_twin

    sim = simulate_bench(bench, seed=args.seed, duration_s=args.duration,
                         experiments=args.experiments, progress=say)
    say(f"writing {len(sim.recordings)} records")
    return write_twin(sim, staging, format=args.format)


def _closed_loop_simulation(args: argparse.Namespace, bench: Bench, out_dir: Path,
                            say: Callable[[str], None]) -> list[Path]:
    """``--closed-loop``: the records data_cl_uch, data_cl_ucv, written to ``out_dir``."""
    from fsmbench.control.loaded import running_controller
    from fsmbench.twin.closed_loop import simulate_closed_loop
    from fsmbench.twin.simulate import write_twin

    if args.experiments:
        raise ValueError("--closed-loop writes data_cl_uch and data_cl_ucv only; run the "
                         "ESRF study's experiments (--experiments) in another simulate")
    controller = running_controller(args.closed_loop, bench=bench)
    result = simulate_closed_loop(bench=bench, controller=controller, sources=args.excitation,
                                  at=args.at, max_error_rad=args.max_error_urad * 1e-6,
                                  seed=args.seed, duration_s=args.duration, progress=say)
    return write_twin(result, out_dir, format=args.format)
