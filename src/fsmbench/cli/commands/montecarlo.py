"""``fsmbench montecarlo``: the closed-loop repeatability experiment over random plants.

    fsmbench montecarlo DATA|--bench DIR|--twin --out OUT [--n 1000] [--seed S]
                        [--scheduler ADDRESS] [--workers N] [--ranges TOML]
                        [--controller FILE[::NAME]] [--duration S] [--settle S]
                        [--batch-size N] [--params FILE] [--timestamp]

The draws move the bench the data came from: the bench identified from DATA,
or the one identified in ``--bench DIR`` (the output of ``identify`` or
``study``), or with ``--twin`` the packaged twin (its physics). A DATA folder
that cannot be identified is refused with the reason: fsmbench never draws
around the packaged bench for someone else's data.

The controller is fsmbench's, designed as ``fsmbench design`` does: on the
identified plant (DATA or ``--bench``), or with ``--twin`` on the nominal physical
plant; or one read from a ``controllers.mat`` / ``controllers_sos.json`` /
design folder with ``--controller FILE`` (``FILE::NAME`` picks a controller by name).

Draws run on Dask: a ``LocalCluster`` of ``--workers`` processes (default all
cores), or the running scheduler at ``--scheduler``. ``--workers 1`` without
``--scheduler`` runs in this process without Dask (the reference); the rows
are the same in every case.

The ranges file (``--ranges``) is TOML with ``key = [low, high]`` pairs; keys
left out keep their default (:class:`fsmbench.scale.montecarlo.Ranges`,
:func:`fsmbench.scale.montecarlo_run.read_ranges`)::

    resonance_scale = [0.95, 1.05]          # Sercalo resonances, × (uniform)
    damping_scale = [0.5, 2.0]              # Sercalo damping ratios, × (log-uniform)
    qd_gain_scale = [0.97, 1.03]            # 4QD gains, ×
    current_amp_gain_scale = [0.97, 1.03]   # current-amplifier gains, ×
    newport_gain_scale = [0.97, 1.03]       # Newport gains, ×
    dac_delay_s = [-1e-4, 1e-4]             # DAC delay, + s
    newport_delay_s = [-1e-4, 1e-4]         # Newport internal delay, + s

Writes ``OUT/montecarlo.json`` (format ``fsmbench.montecarlo`` version 3:
quantiles, unstable fraction, worst draws, per requirement of the design every
draw that breaks it, and every draw as a row) and
``OUT/timings.json`` (workers, scheduler, wall time: not reproducible), and
prints a short table.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import math
import os
import sys
import time
from pathlib import Path
from typing import Any

from fsmbench.cli.args import default_noted
from fsmbench.cli.inputs import bench_of, print_document
from fsmbench.cli.options import add_bench, add_json, add_out, add_params, add_seed, add_timestamp
from fsmbench.cli.runfolder import check_inputs_first, run_folder

__all__ = ["register", "run"]

# Bytes of montecarlo.json per draw (a row of ~45 numbers, indent 2): measured 3.0 kB.
_BYTES_PER_DRAW = 4e3


def _count(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"{text!r} must be at least 1")
    return value


def _seconds(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number of seconds") from None
    if not math.isfinite(value) or value < 0:
        raise argparse.ArgumentTypeError(f"{text!r} is not a finite number of seconds >= 0")
    return value


def register(sub: Any) -> None:
    """Add ``montecarlo`` to the sub-commands ``sub``."""
    p = sub.add_parser("montecarlo", help="the closed-loop repeatability experiment over random "
                                          "plants within their uncertainty (Dask)")
    p.add_argument("data", metavar="DATA", nargs="?", default=None,
                   help="folder of recordings: fsmbench's controller is designed on the plant "
                        "identified from it")
    p.add_argument("--twin", action="store_true",
                   help="no recordings: draw around the packaged twin and design fsmbench's "
                        "controller on the nominal physical plant")
    add_bench(p, help="draw around the bench identified in DIR (the output of fsmbench "
                      "identify or study) and design fsmbench's controller on its plant")
    add_out(p)
    p.add_argument("--n", metavar="N", type=_count, default=1000,
                   help="number of draws (default 1000)")
    add_seed(p, help="root seed of the draws (default 0); the same seed gives the same rows "
                     "whatever the workers")
    p.add_argument("--scheduler", metavar="ADDRESS", default=None,
                   help="a running dask.distributed scheduler, e.g. tcp://host:8786")
    p.add_argument("--workers", metavar="N", type=_count, default=None,
                   help="local worker processes (default: all cores); 1: in this process, "
                        "without Dask")
    p.add_argument("--batch-size", metavar="N", type=_count, default=None,
                   help="draws per Dask task (default: about 4 tasks per worker, at most 20)")
    p.add_argument("--ranges", metavar="TOML", default=None,
                   help="ranges of the draws (default: the design's robust set, gains ±3 %%, "
                        "delays ± 0.1 ms)")
    p.add_argument("--controller", metavar="FILE[::NAME]", default=None,
                   help="run this controller (controllers.mat, controllers_sos.json or a design "
                        "folder; ::NAME picks one) instead of designing fsmbench's")
    p.add_argument("--duration", metavar="S", type=_seconds, default=6.0,
                   help="record length [s] (default 6: 4 whole periods after settling)")
    p.add_argument("--settle", metavar="S", type=_seconds, default=2.0,
                   help="start left out of the metrics [s] (default 2: 36 of the nominal "
                        "loop's slowest time constants, 1 s after the sine starts)")
    add_params(p)
    add_timestamp(p, where="run.json")
    add_json(p, help="print montecarlo.json's content on stdout instead of the table")
    p.set_defaults(func=run)


# ----------------------------------------------------------------------------- the command's inputs


def _drawn_bench(args: argparse.Namespace, bench: Any, say: Any) -> Any:
    """The bench the draws move: the packaged twin, or the one identified (DATA or --bench)."""
    if args.twin:
        return bench
    if args.bench_dir is not None:
        from fsmbench.twin.identified import identified_bench

        return identified_bench(args.bench_dir, bench=bench)
    from fsmbench.io.folder import load_recordings
    from fsmbench.stages import choose_plant, simulation_bench

    data = Path(args.data)
    if not data.is_dir():
        raise ValueError(f"{data}: no such folder of recordings")
    conv = bench.nominal.converter
    loaded = load_recordings(data, progress=say, fs_hz=conv.fs_hz, adc_range_v=conv.range_v,
                             adc_bits=conv.bits)
    plant = choose_plant(dict(loaded.recordings), bench=bench, progress=say, source=str(data))
    sim = simulation_bench(bench=bench, is_twin=False, identification=plant.identification,
                           label=f"the bench identified from the recordings in {data}")
    if sim.bench is None:
        raise ValueError(f"{data}: the bench cannot be identified from these recordings "
                         f"({sim.reason}); the draws would move the packaged twin instead, "
                         "which is not your bench: fix the recordings, or use --twin on purpose")
    return sim.bench


def _controller(args: argparse.Namespace, bench: Any, drawn: Any, say: Any) -> Any:
    from fsmbench.scale.montecarlo_run import designed_controller, loaded_controller

    if args.controller is not None:
        path, _sep, name = str(args.controller).partition("::")
        return loaded_controller(path, name=name or None, bench=bench)
    if drawn.model is None:
        say("designing fsmbench's controller on the nominal physical plant")
        return designed_controller(bench)
    plant = drawn.model.plant
    say(f"designing fsmbench's controller on the plant of {drawn.label}")
    return designed_controller(bench, plant=plant, plant_source=f"identified ({drawn.label})")


def run(args: argparse.Namespace) -> int:
    """The draws; the table (or montecarlo.json) is the result."""
    from fsmbench.jsonutil import stamped
    from fsmbench.scale.montecarlo import MonteCarloSetup, Ranges, run_montecarlo
    from fsmbench.scale.montecarlo_run import dask_client, format_table, read_ranges

    given = [x for x in (args.data is not None, args.twin, args.bench_dir is not None) if x]
    if len(given) != 1:
        raise ValueError("give one of a DATA folder, --bench DIR or --twin")
    # Its own inputs (``FILE::NAME`` as FILE), beside DATA, --bench and --params.
    controller = (None if args.controller is None
                  else str(args.controller).partition("::")[0])
    args.more_inputs = [("--controller", controller), ("--ranges", args.ranges)]
    check_inputs_first(args, args.out, args.data)  # before anything is read or computed
    from fsmbench.twin.experiments import esrf_experiments, with_duration

    # A record too short for the repeatability experiments: one line, before any work.
    with_duration([e for e in esrf_experiments() if e.name in ("data_rep_h", "data_rep_v")],
                  duration_s=args.duration)
    if args.settle >= args.duration:
        settle = default_noted(args, "settle", f"--settle {args.settle:g} s")
        duration = default_noted(args, "duration", f"--duration {args.duration:g} s")
        raise ValueError(f"{settle} leaves nothing of a {duration} record")
    start = time.perf_counter()

    def say(msg: str) -> None:
        print(f"[{time.perf_counter() - start:6.1f} s] {msg}", file=sys.stderr, flush=True)

    bench = bench_of(args)
    ranges = Ranges() if args.ranges is None else read_ranges(args.ranges)
    workers = args.workers or os.cpu_count() or 1
    if args.workers is None and args.scheduler is None and importlib.util.find_spec(
            "distributed") is None:
        say("dask.distributed is not installed: running in this process "
            "(pip install 'fsmbench[dask]' to use every core)")
        workers = 1
    with run_folder(args, args.out, data=args.data,
                    need_bytes=args.n * _BYTES_PER_DRAW) as folder:
        drawn = _drawn_bench(args, bench, say)
        say(f"draws around {drawn.label}")
        setup = MonteCarloSetup(bench=drawn, controller=_controller(args, bench, drawn, say),
                                ranges=ranges, duration_s=args.duration, settle_s=args.settle)
        where = (f"scheduler {args.scheduler}" if args.scheduler else
                 "this process" if workers == 1 else f"{workers} local worker processes")
        say(f"running {args.n} draws on {where}")
        t0 = time.perf_counter()
        with dask_client(scheduler=args.scheduler, workers=workers) as client:
            result = run_montecarlo(setup, n=args.n, seed=args.seed, client=client,
                                    batch_size=args.batch_size, progress=say)
        elapsed = time.perf_counter() - t0
        path = folder.staging / "montecarlo.json"
        path.write_text(json.dumps(result.to_json(), indent=2, allow_nan=False) + "\n")
        (folder.staging / "timings.json").write_text(json.dumps(stamped(
            {"seconds": {"montecarlo": elapsed}, "draws": args.n,
             "workers": None if args.scheduler else workers, "scheduler": args.scheduler},
            format="fsmbench.timings", version=1), indent=2) + "\n")
    print(f"wrote {folder.final_path(path)}", file=sys.stderr)
    if args.json:
        print_document(folder, [path], "montecarlo.json")
    else:
        print(format_table(result))
    return 0
