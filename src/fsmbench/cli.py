"""The ``fsmbench`` command.

    fsmbench params   [--params FILE] [--out DIR] [--json]
    fsmbench simulate OUT [--duration S] [--seed N] [--params FILE] [--format F]
                      [--excitation FILE…] [--bench DIR]
    fsmbench excite   OUT --input Uch --amplitude-rms V [--kind K] [--band LO HI] ...
                      [--bench DIR]
    fsmbench identify DATA --out OUT [--params FILE] [--frf auto|welch|lpm|periodic]
                      [--weights seed|variance]
    fsmbench budget   DATA --out OUT [--params FILE] [--bench DIR]
    fsmbench design   DATA --out OUT [--params FILE] [--seed N] [--bench DIR]
    fsmbench study    [--data DIR] --out OUT [--seed N] [--duration S] [--params FILE]
                      [--figures png,pdf] [--montecarlo DIR]
    fsmbench convert  IN OUT [--fs HZ]
    fsmbench serve    [--backend twin|playback DIR] [--params FILE] [--bench DIR] [--seed N]
                      [--speed X] [--nodb --port N] [--out DIR]
    fsmbench montecarlo DATA|--twin --out OUT [--n N] [--seed S] [--scheduler ADDRESS]
                      [--workers N] [--ranges TOML] [--controller FILE[::NAME]] [--bench DIR]

``--bench DIR`` is the one option of every command that simulates: the bench
identified in DIR (``identify`` or ``study`` output) instead of the packaged
twin. On recorded data the design's closed-loop check runs on the bench
identified from them, never on the packaged twin.

Every writing command also takes ``--timestamp`` (wall-clock time in MAT-file
headers and ``run.json``; default none, so the same inputs and seed give
byte-identical files).

Every command writes only under its output folder, never into a data folder,
and writes it as one transaction (:func:`fsmbench.io.outdir.output_transaction`):
after an error, Ctrl-C or SIGTERM the folder holds the complete previous run or
the complete new one, with its manifest ``run.json``.

Exit status: 0 success; 2 an error the user can fix (data, parameters, output
folder, disk), printed as one line ``fsmbench <cmd>: error: <file>: <problem>``;
130 interrupted by Ctrl-C (SIGINT); 143 terminated by SIGTERM (128 + 15, what a
shell reports for a process killed by SIGTERM); 1 a bug in fsmbench (traceback,
then a request to report it).
"""

from __future__ import annotations

import argparse
import contextlib
import math
import os
import signal
import sys
import threading
import traceback
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import FrameType
from typing import Any

# Ctrl-C while the command line loads (its imports take about a second): one line, the
# shell's 130, not a traceback; nothing has run, so no device, file or folder was touched.
try:
    from fsmbench import __version__
    from fsmbench.bench.params import Bench, ParamsError, load_bench, param_rows, save_bench
    from fsmbench.cli_args import (
        EXIT_USER_ERROR,
        Parser,
        add_identify_options,
        default_noted,
        factor,
        figure_formats,
        identify_options,
        nanometres,
        seconds,
        seed,
        typed_option,
    )
    from fsmbench.excite.cli import add_excite_command
    from fsmbench.io.convert_cli import add_convert_command
    from fsmbench.jsonutil import format_text, stamped
    from fsmbench.live.serve import add_serve_command
    from fsmbench.scale.mc_cli import add_montecarlo_command
    from fsmbench.tune.cli import add_closed_loop_options, add_tune_command, closed_loop_simulation
    from fsmbench.tune.identify_cli import (
        check_closed_loop_folder,
        identify_closed_loop_folder,
        is_closed_loop_folder,
        summary_lines,
    )
except KeyboardInterrupt:
    print("fsmbench: interrupted (Ctrl-C) while starting, before it contacted any device or "
          "wrote any file: nothing was changed", file=sys.stderr)
    raise SystemExit(130) from None

__all__ = ["EXIT_BUG", "EXIT_SIGINT", "EXIT_SIGTERM", "EXIT_USER_ERROR", "main"]

EXIT_SIGINT = 130
EXIT_SIGTERM = 143
EXIT_BUG = 1

# Bytes a record-second of twin data takes on disk, measured on `fsmbench simulate`
# (seed 0, the seed's lengths, 737.5 s of records in all): 76.65 MB as compressed
# MATLAB v5, 313.6 MB of raw float64 (what v7.3 and NeXus store uncompressed).
_TWIN_BYTES_PER_S = {"mat5": 76.65e6 / 737.5, "mat73": 313.6e6 / 737.5,
                     "nexus": 313.6e6 / 737.5}
# Peak memory of `fsmbench simulate` in the mat5/mat73 formats, which simulate every record
# in memory before writing (measured peak RSS, /usr/bin/time, 10 kHz): 0.33 GB of interpreter,
# numba and plant; one experiment of d seconds peaks at 0.33 GB + 4.85 MB per record-second
# (data_uch, data_cal_pd_h, data_huddle_test_1/3, data_rep_h at 200 s: 1.23-1.30 GB; data_rep_h
# at 400 s: 2.27 GB), i.e. ~61 float64 per sample in flight; the records finished before the
# others are held at <= 11 float64 per sample (t + the 10 signals of data_rep_*). The model
# over-estimates the default run (1.78 GB against 1.52 GB measured) and 13 x 60 s (1.49 GB
# against 1.20 GB).
_SIM_BASE_BYTES = 0.33e9
_SIM_WORKING_BYTES_PER_SAMPLE = 4.85e6 / 1e4
_SIM_HELD_BYTES_PER_SAMPLE = 11 * 8
# What the stages write besides the twin's records, measured on the twin study:
# report.html 7.7 MB, frf.mat 1.5 MB, the JSON files and small MAT-files < 0.2 MB.
_STUDY_BYTES = 10e6
_IDENT_BYTES = 2e6
_SMALL_BYTES = 1e6
_FIGURE_BYTES = 20e6  # per static format of --figures (measured 13.5 MB of PNG, 12.9 MB of PDF)


class Terminated(BaseException):
    """SIGTERM arrived; raised from the signal handler so every cleanup runs."""


def _progress() -> Callable[[str], None]:
    from fsmbench.progress import Reporter

    def final(msg: str) -> str:
        # A run's hidden staging folder is where it writes, not where its files will be.
        run = _Current.run
        return run.final_text(msg) if run is not None else msg

    return Reporter(rewrite=final)


BENCH_HELP = ("simulate the bench identified in DIR (the output of fsmbench identify or "
              "study: identification.json, plant.mat) instead of the packaged twin; converters "
              "and everything no recording measured come from --params")


def add_bench_option(p: argparse.ArgumentParser, *, also: str = "") -> None:
    """``--bench DIR``, the one option every simulating command takes (``also``: an alias)."""
    names = ["--bench", *([also] if also else [])]
    p.add_argument(*names, metavar="DIR", default=None, dest="bench_dir", help=BENCH_HELP)


def sim_bench(args: argparse.Namespace) -> Bench:
    """The bench a command simulates: identified in ``--bench DIR``, else the packaged one."""
    bench = _bench(args)
    folder = getattr(args, "bench_dir", None)
    if folder is None:
        return bench
    option = typed_option(args, "bench_dir", "--bench")  # or its alias --identification
    if Path(folder).is_file():
        raise ParamsError(f"{folder}: is a file; {option} needs a folder written by fsmbench "
                          "identify or study (a bench TOML goes to --params)")
    from fsmbench.sim.identified import identified_bench

    return identified_bench(folder, bench=bench, option=option)


def _bench(args: argparse.Namespace) -> Bench:
    path = args.params
    if path is not None and Path(path).is_dir():
        raise ParamsError(f"{path}: is a folder; --params needs a TOML file (e.g. one written "
                          "by fsmbench params --out DIR)")
    try:
        return load_bench(path)
    except UnicodeDecodeError as exc:
        raise ParamsError(f"{path}: is not UTF-8 text ({exc.reason} at byte {exc.start}); "
                          "--params needs a TOML file") from None


# ------------------------------------------------------------------ output transaction


class _Current:
    """The run folder being written, to map staging paths in messages."""

    run: Any = None


def _out_arguments(argv: Sequence[str], out: str | None) -> list[str]:
    """The command line with the output folder written ``.`` (run.json's own folder)."""
    if out is None:
        return list(argv)
    result = []
    for arg in argv:
        if arg == out:
            result.append(".")
        elif arg.startswith("--out=") and arg[len("--out="):] == out:
            result.append("--out=.")
        else:
            result.append(arg)
    return result


def _inputs(args: argparse.Namespace, data: str | Path | None) -> list[tuple[str, Any]]:
    """Every input path of the command line, with the option that named it."""
    pairs: list[tuple[str, Any]] = [("--data" if args.command == "study" else "DATA", data),
                                    ("--params", args.params),
                                    (typed_option(args, "bench_dir", "--bench"),
                                     getattr(args, "bench_dir", None))]
    pairs += [("--excitation", path) for path in getattr(args, "excitation", None) or ()]
    return pairs


def _check_inputs_first(args: argparse.Namespace, data: str | Path | None) -> None:
    """The inputs against the output folder, before any of them is read (``_run_folder``
    checks them again as the transaction starts)."""
    from fsmbench.io.outdir import check_inputs

    out = getattr(args, "out_pos", None) or getattr(args, "out", None)  # as _cmd_simulate
    if out is not None:
        check_inputs(out, _inputs(args, data), out_option=_out_option(args))


def _out_option(args: argparse.Namespace) -> str:
    """How the user gave the output folder: ``--out DIR``, or ``simulate``'s ``OUT``."""
    return typed_option(args, "out_pos", "") or typed_option(args, "out", "--out")


@contextlib.contextmanager
def _run_folder(args: argparse.Namespace, out: str, *, data: str | Path | None,
                need_bytes: float) -> Iterator[Any]:
    from fsmbench.io.matwrite import wall_clock_headers
    from fsmbench.io.outdir import output_transaction

    def warn(msg: str) -> None:
        print(f"fsmbench {args.command}: warning: {msg}", file=sys.stderr)

    with output_transaction(out, command=args.command,
                            arguments=_out_arguments(args.argv, out), data_dir=data,
                            need_bytes=int(need_bytes),
                            timestamp=getattr(args, "timestamp", False),
                            warn=warn, inputs=_inputs(args, data),
                            out_option=_out_option(args)) as run, \
            wall_clock_headers(getattr(args, "timestamp", False)):
        _Current.run = run  # kept after an error too: main maps paths in its message
        yield run


# ------------------------------------------------------------------ commands


def _cmd_params(args: argparse.Namespace) -> int:
    bench = _bench(args)
    rows = param_rows(bench)
    written = None
    if args.out is not None:
        with _run_folder(args, args.out, data=None, need_bytes=_SMALL_BYTES) as run:
            written = run.final_path(save_bench(bench, run.staging / "bench.toml"))
    if args.json:
        print(format_text(stamped({"bench": bench.origin,
                                   "parameters": [dict(r.__dict__) for r in rows]},
                                  format="fsmbench.params", version=1)))
    else:
        width = max(len(r.key) for r in rows)
        print(f"{'parameter':<{width}}  {'nominal':<26} {'true (twin)':<26} {'unit':<9} source")
        for r in rows:
            print(f"{r.key:<{width}}  {r.nominal:<26} {r.true:<26} {r.unit:<9} {r.source}")
    if written is not None:
        print(f"wrote {written}", file=sys.stderr)
    return 0


def _twin_bytes(args: argparse.Namespace, fmt: str) -> float:
    from fsmbench.twin.experiments import seed_experiments

    specs = seed_experiments()
    if getattr(args, "experiments", None):
        specs = tuple(s for s in specs if s.name in set(args.experiments))
    seconds = sum(args.duration if args.duration is not None else s.duration_s for s in specs)
    return seconds * _TWIN_BYTES_PER_S[fmt]


def _simulation_memory_bytes(args: argparse.Namespace, bench: Bench) -> float:
    """Peak memory of simulating the records in memory (see ``_SIM_BASE_BYTES``)."""
    import os

    from fsmbench.twin.experiments import seed_experiments

    specs = seed_experiments()
    if args.experiments:
        specs = tuple(s for s in specs if s.name in set(args.experiments))
    durations = [args.duration if args.duration is not None else s.duration_s for s in specs]
    if args.duration is not None:  # one record per excitation file
        durations += [args.duration] * len(args.excitation or ())
    durations.sort(reverse=True)
    in_flight = max(1, min(len(durations), os.cpu_count() or 1))  # simulate_bench's threads
    fs = bench.true.converter.fs_hz
    return (_SIM_BASE_BYTES + _SIM_WORKING_BYTES_PER_SAMPLE * fs * sum(durations[:in_flight])
            + _SIM_HELD_BYTES_PER_SAMPLE * fs * sum(durations[in_flight:]))


def _check_simulation_memory(args: argparse.Namespace, bench: Bench) -> None:
    """Refuse an in-memory simulation larger than the memory available, with the way out."""
    from fsmbench.io.matfile import available_memory_bytes

    if args.excitation is None and args.format == "nexus":
        return  # streamed block by block
    if args.excitation is not None and args.duration is None:
        return  # the files' own lengths, which excite bounds
    need = _simulation_memory_bytes(args, bench)
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


def _check_study_memory(args: argparse.Namespace, bench: Bench) -> None:
    """The study simulates every record whole and analyses it in memory: refuse what won't fit."""
    from fsmbench.io.matfile import available_memory_bytes

    need = _simulation_memory_bytes(argparse.Namespace(
        experiments=None, excitation=None, duration=args.duration), bench)
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


def _cmd_simulate(args: argparse.Namespace) -> int:
    from fsmbench.twin.simulate import play_excitation, stream_bench

    out = args.out_pos or args.out
    if out is None:
        raise ValueError("simulate needs an output folder: fsmbench simulate OUT")
    _check_inputs_first(args, None)
    bench = sim_bench(args)
    _check_simulation_memory(args, bench)  # before anything is simulated or written
    with _run_folder(args, out, data=None,
                     need_bytes=_twin_bytes(args, args.format) + _SMALL_BYTES) as run:
        say = _progress()
        if args.closed_loop is not None:
            paths = closed_loop_simulation(args, bench, run.staging, say)
        elif args.excitation is not None:
            paths = play_excitation(args.excitation, bench, out_dir=run.staging, seed=args.seed,
                                    duration_s=args.duration, experiments=args.experiments,
                                    format=args.format, progress=say)
        elif args.format == "nexus":
            # Streamed block by block: any --duration in bounded memory.
            paths = stream_bench(bench, out_dir=run.staging, seed=args.seed,
                                 duration_s=args.duration, experiments=args.experiments,
                                 progress=say)
        else:
            paths = _simulate_in_memory(args, bench, run.staging, say)
    for p in paths:
        print(run.final_path(p))
    say("done")
    return 0


def _simulate_in_memory(args: argparse.Namespace, bench: Bench, staging: Path,
                        say: Callable[[str], None]) -> list[Path]:
    from fsmbench.twin.simulate import simulate_bench, write_twin

    sim = simulate_bench(bench, seed=args.seed, duration_s=args.duration,
                         experiments=args.experiments, progress=say)
    say(f"writing {len(sim.recordings)} records")
    return write_twin(sim, staging, format=args.format)


@dataclass(frozen=True)
class _StageInput:
    """What every stage command starts from: folders, bench, progress, recordings."""

    data: Path
    bench: Bench
    say: Callable[[str], None]
    recordings: dict[str, Any]
    skipped: dict[str, str] = field(default_factory=dict)
    unusable: dict[str, str] = field(default_factory=dict)


def _check_data(data: Path) -> None:
    if not data.exists():
        raise FileNotFoundError(2, "data folder does not exist", str(data))
    if not data.is_dir():
        raise NotADirectoryError(20, "is a file; DATA must be a folder of recordings",
                                 str(data))


def _stage_input(args: argparse.Namespace, *,
                 uses: tuple[str, ...] | None = None) -> _StageInput:
    """Read the bench and every experiment present (the folders are checked first).

    ``uses``: the experiments the command reads; a file it does not use, or one that
    is simply absent, is not mentioned (the command's own output says what ran).
    """
    from fsmbench.checks import failed
    from fsmbench.io.folder import load_recordings

    data = Path(args.data)
    say = _progress()
    bench = _bench(args)
    conv = bench.nominal.converter
    # The records' rate is judged by the identification against each other, then the bench
    # file (ident.evidence.rate).
    loaded = load_recordings(data, progress=say, fs_hz=None, adc_range_v=conv.range_v,
                             adc_bits=conv.bits)
    for name, why in loaded.unusable().items():
        # Simply absent: not mentioned; a near miss ("found DATA_UCH.mat: rename it …") is.
        if uses is None or name in uses:
            say(f"skipped {name}: {why}")
    # What the user must know about the files it uses, once each, one line each.
    for check in failed(loaded.checks):
        if uses is None or check.subject.split(".")[0] in uses:
            say(f"check failed: {check.sentence()}")
    for notice in loaded.notices:
        say(f"note: {notice.sentence()}")
    return _StageInput(data=data, bench=bench, say=say, recordings=dict(loaded.recordings),
                       skipped=dict(loaded.skipped), unusable=loaded.unusable())


def _stage_folder(args: argparse.Namespace, need_bytes: float) -> Any:
    from fsmbench.io.outdir import check_out_dir

    data = Path(args.data)
    check_out_dir(Path(args.out), data)
    _check_data(data)
    _bench(args)  # a bad --params fails before anything is computed or written
    return _run_folder(args, args.out, data=data, need_bytes=need_bytes)


def _cmd_identify(args: argparse.Namespace) -> int:
    from fsmbench.io.truth import read_twin_truth
    from fsmbench.stages import identify_stage
    from fsmbench.twin.compare import comparison_json, readable_table

    asked = bool(getattr(args, "closed_loop", False))
    if asked:
        check_closed_loop_folder(args.data)  # one line when DATA has no data_cl_*
    if asked or is_closed_loop_folder(args.data):  # or data_cl_* and no data_uch/ucv
        with _stage_folder(args, _IDENT_BYTES) as run:
            cl, paths = identify_closed_loop_folder(args.data, bench=_bench(args),
                                                    out_dir=run.staging, progress=_progress(),
                                                    asked=asked)
        print("\n".join(summary_lines(cl, read_twin_truth(Path(args.data)))))
        for path in paths:
            print(f"wrote {run.final_path(path)}", file=sys.stderr)
        return 0
    with _stage_folder(args, _IDENT_BYTES) as run:
        reference = read_twin_truth(Path(args.data))
        inp = _stage_input(args)
        result, paths = identify_stage(inp.recordings, bench=inp.bench, out_dir=run.staging,
                                       source=str(inp.data), progress=inp.say,
                                       unusable=inp.unusable,
                                       options=identify_options(args, data=inp.data))
    for step, why in result.skipped.items():
        inp.say(f"step {step} skipped: {why}")
    for warning in result.warnings:
        print(f"fsmbench identify: warning: {warning}", file=sys.stderr)
    for path in paths:
        print(f"wrote {run.final_path(path)}", file=sys.stderr)
    js = result.to_json()
    if args.json:
        print(format_text(comparison_json(
            js, reference=reference, bench=inp.bench,
            files=[str(run.final_path(p)) for p in paths], skipped=result.skipped,
            warnings=list(result.warnings))), end="")
    else:
        print("\n".join(readable_table(js, reference=reference, bench=inp.bench)))
        for finding in result.findings:
            print(f"found: {finding.sentence()}")
        if result.findings:
            print(f"the bench file that matches the records: "
                  f"{run.final_path(run.staging / 'bench_identified.toml')}")
        for step, why in result.skipped.items():
            print(f"not identified: {_STEP_WORDS.get(step, step)}: "
                  + _skip_sentence(why, frf=getattr(args, "frf", "auto")))
    return 0


#: Identification steps in words (the ESRF study's section of each).
_STEP_WORDS = {"qd": "4QD calibration (2.1)", "current_amp": "current amplifiers (2.2)",
               "sercalo": "Sercalo (2.3)", "newport": "Newport (2.4)",
               "newport_dynamics": "Newport's dynamics (2.4)",
               "mode_refinement": "Sercalo modes on the full records (2.3)",
               "noise_model": "noise model of the huddle tests"}


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


def _plant(args: argparse.Namespace, inp: _StageInput) -> Any:
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


def _simulated(args: argparse.Namespace, inp: _StageInput, plant: Any) -> Any:
    """The bench the design's closed-loop check runs: identified, never the packaged twin."""
    from fsmbench.stages import SimulationBench, simulation_bench

    if args.bench_dir is not None:
        return SimulationBench(sim_bench(args))
    return simulation_bench(bench=inp.bench, is_twin=False,
                            identification=plant.identification,
                            label=f"the bench identified from the recordings in {inp.data}")


def _check_identification(args: argparse.Namespace) -> None:
    _check_inputs_first(args, getattr(args, "data", None))
    if args.bench_dir is not None:
        sim_bench(args)  # bad files: one line, before any work


def _cmd_budget(args: argparse.Namespace) -> int:
    from fsmbench.stages import budget_stage

    _check_identification(args)
    with _stage_folder(args, _SMALL_BYTES) as run:
        inp = _stage_input(args)
        plant = _plant(args, inp)
        inp.say("noise and error budget, huddle tests, repeatability (ESRF study sections 3, 4, "
                "11)")
        result, paths = budget_stage(inp.recordings, bench=inp.bench, out_dir=run.staging,
                                     plant=plant, progress=inp.say)
    # The result on stdout, the files and what was skipped on stderr.
    for path in paths:
        print(f"wrote {run.final_path(path)}", file=sys.stderr)
    if args.json:
        _print_document(run, paths, "budget.json")
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


_CONTROLLER_NAMES = {"seed_controller": "the study's controller (9.2)",
                     "fsmbench_controller": "fsmbench's controller",
                     "newport_controller": "Newport alignment (10.2)"}


def _num(value: Any, fmt: str, unit: str = "") -> str:
    """A rounded value with its unit; "none" when absent, "∞" when infinite."""
    if value is None:
        return "none"
    x = float(value)
    if math.isinf(x):
        return "∞" if x > 0 else "-∞"
    return f"{x:{fmt}}{unit}"


def design_table(payload: dict[str, Any]) -> list[str]:
    """What ``fsmbench design`` prints: each loop's margins in words and units, the verdicts.

    The 1 Hz objective of ESRF study 6.1 (|S| ≤ e_max / y_max) is the Sercalo loop's: the
    Newport's alignment loop (10.2) is shown with its margins only.
    """
    bound = payload.get("objective", {}).get("sensitivity_bound_at_1hz")
    head = ["controller", "axis", "stable", "gain margin", "phase margin", "crossover",
            "|S(1 Hz)|", "objective 6.1"]
    body = []
    for name, words in _CONTROLLER_NAMES.items():
        loop = payload.get(name)
        if not loop:
            continue
        sercalo = name != "newport_controller"
        for a in ("h", "v"):
            ax = loop[a]
            verdict = ("–" if not sercalo or bound is None else
                       "met" if ax.get("sensitivity_at_1hz", math.inf) <= bound else "missed")
            body.append([words, a, "yes" if ax.get("stable") else "NO",
                         _num(ax.get("gain_margin_db"), ".1f", " dB"),
                         _num(ax.get("phase_margin_deg"), ".1f", "°"),
                         _num(ax.get("crossover_hz"), ".1f", " Hz"),
                         _num(ax.get("sensitivity_at_1hz"), ".2e"), verdict])
    widths = [max(len(str(x)) for x in col) for col in zip(head, *body, strict=True)]
    lines = ["  ".join(str(c).ljust(w) for c, w in zip(row, widths, strict=True)).rstrip()
             for row in (head, *body)]
    if bound is not None:
        lines.append(f"Objective 6.1 (the Sercalo loop): |S(1 Hz)| ≤ {bound:.0e}; the Newport "
                     "loop aligns, it does not reject the sample motion.")
    twin = payload.get("closed_loop_twin")
    if twin is None:
        lines.append(f"fsmbench's controller not simulated: {payload.get('closed_loop_skipped')}")
    else:
        lines.append(
            f"fsmbench's controller simulated on {twin['bench']}: tracking error "
            + ", ".join(f"{a} {1e6 * v:.3g} µrad rms (linear prediction "
                        f"{1e6 * twin['predicted_rms_rad'][a]:.3g} µrad)"
                        for a, v in twin["tracking_error_rms_rad"].items()))
    return lines


def _cmd_design(args: argparse.Namespace) -> int:
    from fsmbench.stages import IDENT_EXPERIMENTS, design_stage

    _check_identification(args)
    with _stage_folder(args, _SMALL_BYTES) as run:
        inp = _stage_input(args, uses=IDENT_EXPERIMENTS if args.bench_dir is None else ())
        plant = _plant(args, inp)
        stage, paths = design_stage(bench=inp.bench, out_dir=run.staging, plant=plant,
                                    seed=args.seed, progress=inp.say,
                                    simulated=_simulated(args, inp, plant))
    for path in paths:
        print(f"wrote {run.final_path(path)}", file=sys.stderr)
    if args.json:
        _print_document(run, paths, "design.json")
    else:
        print("\n".join(design_table(stage.payload)))
    return 0


def _print_document(run: Any, paths: Sequence[Path], name: str) -> None:
    """A written result file's content on stdout, as written (``--json``)."""
    path = next(Path(run.final_path(p)) for p in paths if Path(p).name == name)
    print(path.read_text(encoding="utf-8"), end="")


def _cmd_study(args: argparse.Namespace) -> int:
    from fsmbench.report.summary import Specification
    from fsmbench.study import run_study

    data = None if args.data is None else Path(args.data)
    if data is not None:
        from fsmbench.io.outdir import check_out_dir

        check_out_dir(Path(args.out), data)
        _check_data(data)
    bench = _bench(args)
    montecarlo = None
    if args.montecarlo is not None:
        from fsmbench.scale.mc_cli import read_montecarlo

        montecarlo = read_montecarlo(args.montecarlo)  # read before --out may be replaced
    need = _STUDY_BYTES + _FIGURE_BYTES * len(args.figures)
    if data is None:
        need += _twin_bytes(args, "mat5")
        _check_study_memory(args, bench)
    say = _progress()
    with _run_folder(args, args.out, data=data, need_bytes=need) as run:
        result = run_study(out_dir=run.staging, data_dir=data, bench=bench, seed=args.seed,
                           duration_s=args.duration, progress=say, figures=args.figures,
                           spec=Specification(distance_error_max_m=args.distance_target_m),
                           identify_options=identify_options(args, data=data),
                           montecarlo=montecarlo)
    if args.json:
        print(f"wrote {run.final_path(result.report)}", file=sys.stderr)
    else:
        print(run.final_path(result.report))
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
            summary = Path(run.final_path(result.report)).parent / "summary.json"
            print(summary.read_text(encoding="utf-8"), end="")
        else:
            print(f"verdict: {result.summary.verdict}")
    return 0


def _parser() -> argparse.ArgumentParser:
    parser = Parser(
        prog="fsmbench",
        description="Fast-steering-mirror bench: digital twin, identification, budget, control.")
    parser.add_argument("--version", action="version", version=f"fsmbench {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=Parser)

    def common(p: argparse.ArgumentParser, *, mat_files: bool = True) -> None:
        p.add_argument("--params", metavar="FILE", default=None,
                       help="bench parameters (TOML); default: the packaged Sercalo bench")
        where = "MAT-file headers and run.json" if mat_files else "run.json (with --out)"
        p.add_argument("--timestamp", action="store_true",
                       help=f"write the wall-clock time into {where} (default: none, so "
                            "that outputs are byte-identical)")

    p = sub.add_parser("params", help="print the bench parameters with units and sources")
    common(p, mat_files=False)
    p.add_argument("--out", metavar="DIR", default=None, help="also write DIR/bench.toml")
    p.add_argument("--json", action="store_true", help="print JSON instead of a table")
    p.set_defaults(func=_cmd_params)

    p = sub.add_parser("simulate", help="run the ESRF study's 13 experiments on the digital twin")
    common(p)
    p.add_argument("out_pos", metavar="OUT", nargs="?", default=None, help="output folder")
    p.add_argument("--out", metavar="DIR", default=None, help="output folder (same as OUT)")
    p.add_argument("--duration", metavar="S", type=seconds, default=None,
                   help="length of every record [s] (default: the ESRF study's, 100 s huddle "
                        "tests)")
    p.add_argument("--seed", metavar="N", type=seed, default=0, help="random seed (default 0)")
    p.add_argument("--format", choices=("mat5", "mat73", "nexus"), default="mat5",
                   help="file format (default: MATLAB v5)")
    p.add_argument("--experiments", metavar="NAME", nargs="+", default=None,
                   help="only these experiments (e.g. data_uch data_ucv)")
    p.add_argument("--excitation", metavar="FILE", default=None, nargs="+",
                   help="play these designed excitations (fsmbench excite: folder, .json or "
                        ".mat) each in its input's experiment instead of the ESRF study's noise; "
                        "--experiments adds the ESRF study's own")
    add_closed_loop_options(p)
    add_bench_option(p)
    p.set_defaults(func=_cmd_simulate)

    stage_commands = (
        ("identify", "ESRF study section 2: 4QD, amplifiers, Sercalo, Newport, the full plant",
         _cmd_identify),
        ("budget", "ESRF study sections 3, 4, 11: huddle tests, error budget, repeatability",
         _cmd_budget),
        ("design", "ESRF study sections 5-10: plant analysis, controllers, verification on the "
                   "twin, export", _cmd_design),
    )
    for name, text, func in stage_commands:
        p = sub.add_parser(name, help=text)
        common(p)
        p.add_argument("data", metavar="DATA", help="folder of recordings (.mat, .h5, .nxs)")
        p.add_argument("--out", metavar="DIR", required=True, help="output folder")
        if name == "identify":
            add_identify_options(p)
            p.add_argument("--closed-loop", action="store_true", dest="closed_loop",
                           help="identify the Sercalo from the closed-loop records data_cl_uch "
                                "and data_cl_ucv (joint input-output method), even beside "
                                "open-loop records; without it a folder of closed-loop records "
                                "only is detected")
            p.add_argument("--json", action="store_true",
                           help="print the comparison as JSON on stdout instead of the table")
        if name in ("budget", "design"):
            p.add_argument("--json", action="store_true",
                           help=f"print {name}.json's content on stdout instead of the "
                                + ("table" if name == "design" else "total"))
        if name == "design":
            p.add_argument("--seed", metavar="N", type=seed, default=0,
                           help="random seed of the closed-loop verification's twin (default 0)")
        if name in ("budget", "design"):
            p.add_argument("--bench", "--identification", metavar="DIR", default=None,
                           dest="bench_dir",
                           help="the bench identified in DIR (the output of fsmbench identify "
                                "or study: identification.json and plant.mat): its plant, "
                                "instead of identifying DATA again"
                                + ("; its simulation for the closed-loop check" if name ==
                                   "design" else "")
                                + " (--identification: the same, older name)")
        p.set_defaults(func=func)

    p = sub.add_parser("study", help="the whole study; the twin when no --data is given")
    common(p)
    p.add_argument("--data", metavar="DIR", default=None,
                   help="folder of recordings (.mat, .h5, .nxs)")
    p.add_argument("--out", metavar="DIR", required=True, help="output folder")
    p.add_argument("--seed", metavar="N", type=seed, default=0,
                   help="random seed of the twin's noise (default 0)")
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
    p.add_argument("--json", action="store_true",
                   help="print the verdict (summary.json's content) on stdout instead of the "
                        "report's path and the verdict's line")
    add_identify_options(p)
    p.set_defaults(func=_cmd_study)

    add_serve_command(sub, factor=factor)
    add_montecarlo_command(sub)
    add_excite_command(sub)
    add_tune_command(sub)

    add_convert_command(sub, progress=_progress)
    return parser


# ------------------------------------------------------------------ the exception boundary


def _describe(exc: BaseException) -> str:
    """``<file>: <problem>`` for an error the user can fix."""
    if isinstance(exc, OSError) and not isinstance(exc, _own_errors()):
        problem = exc.strerror or (exc.args[0] if exc.args else type(exc).__name__)
        if exc.filename is not None and exc.filename2 is not None:
            return f"{exc.filename} -> {exc.filename2}: {problem}"
        if exc.filename is not None:
            return f"{exc.filename}: {problem}"
        return str(problem)
    return str(exc)


def _own_errors() -> tuple[type[BaseException], ...]:
    from fsmbench.io.errors import RecordingError
    from fsmbench.io.outdir import OutputError

    return (ParamsError, RecordingError, OutputError)


def _raised_by_fsmbench(exc: BaseException) -> bool:
    """True when the innermost frame of the traceback is fsmbench's own code.

    A ``ValueError`` fsmbench raises on purpose (a duration too short, an
    unknown experiment) is a verdict for the user; one raised deep inside
    numpy or scipy is a bug to report.
    """
    tb = exc.__traceback__
    if tb is None:
        return True
    while tb.tb_next is not None:
        tb = tb.tb_next
    package = str(Path(__file__).resolve().parent)
    return str(Path(tb.tb_frame.f_code.co_filename).resolve()).startswith(package)


def _user_error(exc: BaseException) -> bool:
    if isinstance(exc, (*_own_errors(), OSError)):
        return True
    return isinstance(exc, ValueError) and _raised_by_fsmbench(exc)


@contextlib.contextmanager
def _sigterm_raises() -> Iterator[None]:
    """SIGTERM raises :class:`Terminated`, so staging folders and temporary files go."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def handler(_signum: int, _frame: FrameType | None) -> None:
        raise Terminated

    saved = signal.signal(signal.SIGTERM, handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, saved)


def _mapped(text: str) -> str:
    run = _Current.run
    return text if run is None else run.final_text(text)


#: A shell's status for a command killed by SIGPIPE (128 + 13): its reader closed the pipe.
EXIT_BROKEN_PIPE = 141


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``fsmbench`` console script; returns the exit status."""
    argv = list(sys.argv[1:] if argv is None else argv)
    try:
        args = _parser().parse_args(argv)
    except SystemExit as exc:  # --help, --version, or a bad argument (one line printed)
        return exc.code if isinstance(exc.code, int) else EXIT_USER_ERROR
    args.argv = argv
    _Current.run = None
    out = getattr(args, "out", None) or getattr(args, "out_pos", None) or "the output folder"
    prefix = f"fsmbench {args.command}: error:"
    untouched = f"{out} was left as it was (no partial output)"
    try:
        with _sigterm_raises():
            return int(args.func(args))
    except KeyboardInterrupt:
        print(f"{prefix} {out}: interrupted (Ctrl-C); {untouched}", file=sys.stderr)
        return EXIT_SIGINT
    except Terminated:
        print(f"{prefix} {out}: terminated (SIGTERM); {untouched}", file=sys.stderr)
        return EXIT_SIGTERM
    except BrokenPipeError:
        # The reader went away (``fsmbench params --json | head``): no error to tell it.
        # Later writes to stdout (the interpreter's flush at exit) go nowhere.
        with contextlib.suppress(OSError, ValueError):
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, sys.stdout.fileno())
        return EXIT_BROKEN_PIPE
    except Exception as exc:
        if not _user_error(exc):
            traceback.print_exc()
            print(f"fsmbench {args.command}: internal error ({type(exc).__name__}), a bug in "
                  f"fsmbench {__version__}; please report it with the command line and the "
                  "traceback above", file=sys.stderr)
            return EXIT_BUG
        text = _mapped(_describe(exc))
        print(f"{prefix} {' '.join(text.split())}", file=sys.stderr)
        return EXIT_USER_ERROR


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
