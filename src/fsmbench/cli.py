"""The ``fsmbench`` command.

    fsmbench params   [--params FILE] [--out DIR] [--json]
    fsmbench simulate OUT [--duration S] [--seed N] [--params FILE] [--format F]
    fsmbench identify DATA --out OUT [--params FILE]
    fsmbench budget   DATA --out OUT [--params FILE]
    fsmbench design   DATA --out OUT [--params FILE] [--seed N]
    fsmbench study    [--data DIR] --out OUT [--seed N] [--duration S] [--params FILE]

Every command writes only under its output folder, never into a data folder.
Errors print one line naming the file and the problem and exit with status 2.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from fsmbench import __version__
from fsmbench.bench.params import Bench, ParamsError, load_bench, param_rows, save_bench

__all__ = ["main"]


def _progress() -> Callable[[str], None]:
    start = time.perf_counter()

    def say(msg: str) -> None:
        print(f"[{time.perf_counter() - start:6.1f} s] {msg}", file=sys.stderr, flush=True)

    return say


def _bench(args: argparse.Namespace) -> Bench:
    return load_bench(args.params)


def _cmd_params(args: argparse.Namespace) -> int:
    bench = _bench(args)
    rows = param_rows(bench)
    if args.json:
        print(json.dumps([r.__dict__ for r in rows], indent=2))
    else:
        width = max(len(r.key) for r in rows)
        print(f"{'parameter':<{width}}  {'nominal':<26} {'true (twin)':<26} {'unit':<9} source")
        for r in rows:
            print(f"{r.key:<{width}}  {r.nominal:<26} {r.true:<26} {r.unit:<9} {r.source}")
    if args.out is not None:
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        path = save_bench(bench, out / "bench.toml")
        print(f"wrote {path}", file=sys.stderr)
    return 0


def _cmd_simulate(args: argparse.Namespace) -> int:
    from fsmbench.twin.simulate import simulate_bench, write_twin

    out = args.out_pos or args.out
    if out is None:
        raise ValueError("simulate needs an output folder: fsmbench simulate OUT")
    say = _progress()
    bench = _bench(args)
    run = simulate_bench(bench, seed=args.seed, duration_s=args.duration,
                         experiments=args.experiments, progress=say)
    say(f"writing {len(run.recordings)} records to {out}")
    paths = write_twin(run, out, format=args.format)
    for p in paths:
        print(p)
    say("done")
    return 0


@dataclass(frozen=True)
class _StageInput:
    """What every stage command starts from: folders, bench, progress, recordings."""

    data: Path
    out: Path
    bench: Bench
    say: Callable[[str], None]
    recordings: dict[str, Any]


def _stage_input(args: argparse.Namespace) -> _StageInput:
    """Check the folders (never write into the data), read every experiment present."""
    from fsmbench.io.folder import load_recordings
    from fsmbench.io.outdir import check_out_dir

    data, out = Path(args.data), Path(args.out)
    check_out_dir(out, data)
    if not data.is_dir():
        raise FileNotFoundError(f"data folder {data} does not exist")
    out.mkdir(parents=True, exist_ok=True)
    say = _progress()
    loaded = load_recordings(data, progress=say)
    recordings = loaded.recordings
    for name, why in loaded.skipped.items():
        say(f"skipped {name}: {why}")
    return _StageInput(data=data, out=out, bench=_bench(args), say=say, recordings=recordings)


def _cmd_identify(args: argparse.Namespace) -> int:
    from fsmbench.ident.compare import compare_with_truth
    from fsmbench.stages import identify_stage

    inp = _stage_input(args)
    result, paths = identify_stage(inp.recordings, bench=inp.bench, out_dir=inp.out,
                                   source=str(inp.data), progress=inp.say)
    for step, why in result.skipped.items():
        inp.say(f"step {step} skipped: {why}")
    for warning in result.warnings:
        print(f"fsmbench identify: warning: {warning}", file=sys.stderr)
    for path in paths:
        print(path)
    truth_path = inp.data / "twin_truth.json"
    reference = json.loads(truth_path.read_text()) if truth_path.is_file() else None
    for row in compare_with_truth(result.to_json(), reference=reference, bench=inp.bench):
        print(row, file=sys.stderr)
    return 0


def _cmd_budget(args: argparse.Namespace) -> int:
    from fsmbench.stages import budget_stage, choose_plant

    inp = _stage_input(args)
    plant = choose_plant(inp.recordings, bench=inp.bench, progress=inp.say)
    inp.say(f"plant: {plant.source}")
    inp.say("noise and error budget, huddle tests, repeatability (seed sections 3, 4, 11)")
    result, paths = budget_stage(inp.recordings, bench=inp.bench, out_dir=inp.out, plant=plant)
    for path in paths:
        print(path)
    print(f"total {1e9 * result.total_rms_m:.3g} nm rms; limiting source: {result.limiting}",
          file=sys.stderr)
    for part, why in result.skipped.items():
        print(f"skipped {part}: {why}", file=sys.stderr)
    return 0


def _cmd_design(args: argparse.Namespace) -> int:
    from fsmbench.stages import choose_plant, design_stage

    inp = _stage_input(args)
    plant = choose_plant(inp.recordings, bench=inp.bench, progress=inp.say)
    inp.say(f"plant: {plant.source}")
    stage, paths = design_stage(bench=inp.bench, out_dir=inp.out, plant=plant, seed=args.seed,
                                progress=inp.say)
    for path in paths:
        print(path)
    p = stage.payload
    for name in ("seed_controller", "fsmbench_controller", "newport_controller"):
        loop = p[name]
        axes = "; ".join(f"{a}: GM {loop[a]['gain_margin_db']} dB, PM {loop[a]['phase_margin_deg']}"
                         f" deg, fc {loop[a]['crossover_hz']} Hz" for a in ("h", "v"))
        print(f"{name}: meets objective {loop['meets_objective']}; {axes}", file=sys.stderr)
    twin = p["closed_loop_twin"]
    print("fsmbench controller on the twin: tracking error "
          + ", ".join(f"{a} {1e6 * v:.3g} µrad rms (predicted "
                      f"{1e6 * twin['predicted_rms_rad'][a]:.3g})"
                      for a, v in twin["tracking_error_rms_rad"].items()), file=sys.stderr)
    return 0


def _cmd_study(args: argparse.Namespace) -> int:
    from fsmbench.study import run_study

    say = _progress()
    result = run_study(out_dir=args.out, data_dir=args.data, bench=_bench(args), seed=args.seed,
                       duration_s=args.duration, progress=say)
    print(result.report)
    for name, why in result.skipped_experiments.items():
        print(f"skipped {name}: {why}", file=sys.stderr)
    return 0


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="fsmbench",
        description="Fast-steering-mirror bench: digital twin, identification, budget, control.")
    parser.add_argument("--version", action="version", version=f"fsmbench {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)

    def common(p: argparse.ArgumentParser) -> None:
        p.add_argument("--params", metavar="FILE", default=None,
                       help="bench parameters (TOML); default: the packaged Sercalo bench")

    p = sub.add_parser("params", help="print the bench parameters with units and sources")
    common(p)
    p.add_argument("--out", metavar="DIR", default=None, help="also write DIR/bench.toml")
    p.add_argument("--json", action="store_true", help="print JSON instead of a table")
    p.set_defaults(func=_cmd_params)

    p = sub.add_parser("simulate", help="run the seed's 13 experiments on the digital twin")
    common(p)
    p.add_argument("out_pos", metavar="OUT", nargs="?", default=None, help="output folder")
    p.add_argument("--out", metavar="DIR", default=None, help="output folder (same as OUT)")
    p.add_argument("--duration", metavar="S", type=float, default=None,
                   help="length of every record [s] (default: the seed's, 100 s huddle tests)")
    p.add_argument("--seed", metavar="N", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--format", choices=("mat5", "mat73", "nexus"), default="mat5",
                   help="file format (default: MATLAB v5)")
    p.add_argument("--experiments", metavar="NAME", nargs="+", default=None,
                   help="only these experiments (e.g. data_uch data_ucv)")
    p.set_defaults(func=_cmd_simulate)

    stage_commands = (
        ("identify", "seed section 2: 4QD, amplifiers, Sercalo, Newport, the full plant",
         _cmd_identify),
        ("budget", "seed sections 3, 4, 11: huddle tests, error budget, repeatability",
         _cmd_budget),
        ("design", "seed sections 5-10: plant analysis, controllers, verification on the "
                   "twin, export", _cmd_design),
    )
    for name, text, func in stage_commands:
        p = sub.add_parser(name, help=text)
        common(p)
        p.add_argument("data", metavar="DATA", help="folder of recordings (.mat, .h5, .nxs)")
        p.add_argument("--out", metavar="DIR", required=True, help="output folder")
        if name == "design":
            p.add_argument("--seed", metavar="N", type=int, default=0,
                           help="twin seed of the closed-loop verification (default 0)")
        p.set_defaults(func=func)

    p = sub.add_parser("study", help="the whole study; the twin when no --data is given")
    common(p)
    p.add_argument("--data", metavar="DIR", default=None, help="folder of recordings (.mat)")
    p.add_argument("--out", metavar="DIR", required=True, help="output folder")
    p.add_argument("--seed", metavar="N", type=int, default=0, help="twin seed (default 0)")
    p.add_argument("--duration", metavar="S", type=float, default=None,
                   help="twin record length [s] (default: the seed's)")
    p.set_defaults(func=_cmd_study)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``fsmbench`` console script; returns the exit status."""
    args = _parser().parse_args(argv)
    from fsmbench.io.errors import RecordingError

    try:
        return int(args.func(args))
    except (ParamsError, RecordingError, ValueError, FileNotFoundError) as exc:
        print(f"fsmbench {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"fsmbench {args.command}: interrupted; no partial file was left behind",
              file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
