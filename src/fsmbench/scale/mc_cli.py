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
:func:`read_ranges`)::

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
import contextlib
import dataclasses
import importlib.util
import json
import math
import os
import sys
import time
import tomllib
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

from fsmbench.cli_args import default_noted, seed

# The CLI builds its parser with this module: the model, numba and Dask load only when
# the command runs.
if TYPE_CHECKING:
    from fsmbench.bench.params import Bench
    from fsmbench.scale.montecarlo import ControllerChoice, Ranges

__all__ = ["add_montecarlo_command", "dask_client", "designed_controller", "format_table",
           "loaded_controller", "read_montecarlo", "read_ranges"]

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


def add_montecarlo_command(sub: Any) -> None:
    """Add ``montecarlo`` to the CLI's sub-commands (``sub`` from ``add_subparsers``)."""
    p = sub.add_parser("montecarlo", help="the closed-loop repeatability experiment over random "
                                          "plants within their uncertainty (Dask)")
    p.add_argument("data", metavar="DATA", nargs="?", default=None,
                   help="folder of recordings: fsmbench's controller is designed on the plant "
                        "identified from it")
    p.add_argument("--twin", action="store_true",
                   help="no recordings: draw around the packaged twin and design fsmbench's "
                        "controller on the nominal physical plant")
    p.add_argument("--bench", metavar="DIR", default=None, dest="bench_dir",
                   help="draw around the bench identified in DIR (the output of fsmbench "
                        "identify or study) and design fsmbench's controller on its plant")
    p.add_argument("--out", metavar="DIR", required=True, help="output folder")
    p.add_argument("--n", metavar="N", type=_count, default=1000,
                   help="number of draws (default 1000)")
    p.add_argument("--seed", metavar="S", type=seed, default=0,
                   help="root seed of the draws (default 0); the same seed gives the same "
                        "rows whatever the workers")
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
    p.add_argument("--params", metavar="FILE", default=None,
                   help="bench parameters (TOML); default: the packaged Sercalo bench")
    p.add_argument("--timestamp", action="store_true",
                   help="write the wall-clock time into run.json (default: none)")
    p.set_defaults(func=_command)


# ----------------------------------------------------------------------------- the command's inputs


def read_ranges(path: str | Path) -> Ranges:
    """Read ``--ranges``: a TOML file of ranges; keys left out keep their default.

    The file holds top-level ``key = [low, high]`` pairs, keys as the
    attributes, e.g. ``resonance_scale = [0.9, 1.1]`` or
    ``dac_delay_s = [0, 0]``.

    Raises
    ------
    ValueError
        One line naming the file and the key: not TOML, unknown key, not a
        pair of numbers, or an invalid range.
    """
    from fsmbench.scale.montecarlo import Ranges

    p = Path(path)
    try:
        data = tomllib.loads(p.read_text("utf-8"))
    except FileNotFoundError:
        raise ValueError(f"{p}: no such ranges file") from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise ValueError(f"{p}: not valid TOML ({exc})") from None
    names = [f.name for f in dataclasses.fields(Ranges)]
    unknown = sorted(set(data) - set(names))
    if unknown:
        raise ValueError(f"{p}: unknown range(s) {', '.join(unknown)}; known: "
                         f"{', '.join(names)}")
    values: dict[str, tuple[float, float]] = {}
    for key, raw in data.items():
        ok = (isinstance(raw, list) and len(raw) == 2
              and all(isinstance(x, int | float) and not isinstance(x, bool) for x in raw))
        if not ok:
            raise ValueError(f"{p}: '{key}' must be a pair [low, high] of numbers, got {raw!r}")
        values[key] = (float(raw[0]), float(raw[1]))
    try:
        return dataclasses.replace(Ranges(), **values)
    except ValueError as exc:
        raise ValueError(f"{p}: {exc}") from None


def read_montecarlo(path: str | Path) -> dict[str, Any]:
    """Read a ``montecarlo.json`` (or the folder holding it) for the study's report.

    Raises
    ------
    ValueError
        One line naming the file: missing, not JSON, not ``fsmbench.montecarlo``, or a
        version without ``requirements`` (before 3: run ``fsmbench montecarlo`` again).
    """
    from fsmbench.scale.montecarlo import MONTECARLO_FORMAT

    p = Path(path)
    p = p / "montecarlo.json" if p.is_dir() else p
    try:
        doc = json.loads(p.read_text("utf-8"))
    except FileNotFoundError:
        raise ValueError(f"{p}: no such file (the output of fsmbench montecarlo)") from None
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise ValueError(f"{p}: not valid JSON ({exc})") from None
    name, version = MONTECARLO_FORMAT
    found = (doc.get("format"), doc.get("format_version")) if isinstance(doc, dict) else None
    if found is None or found[0] != name:
        raise ValueError(f"{p}: not a {name} file (format {None if found is None else found[0]})")
    if found[1] != version:
        raise ValueError(f"{p}: {name} version {found[1]}, this fsmbench reads version "
                         f"{version} (it lists the draws that break each requirement): run "
                         "fsmbench montecarlo again")
    return doc


def designed_controller(bench: Bench, *, plant: Any = None,
                        plant_source: str = "physical (nominal)") -> ControllerChoice:
    """fsmbench's controller designed on ``plant`` (default the nominal physical plant),
    with the 6.1 objective of ``bench.nominal``, Tustin at the converter rate.

    ``fsmbench design`` designs on the plant :func:`fsmbench.stages.choose_plant`
    picks: the identified one when the recordings allow it, else this nominal model.
    """
    import numpy as np

    from fsmbench.bench.blocks import physical_plant
    from fsmbench.control.analysis import control_objective
    from fsmbench.control.design import design_controller
    from fsmbench.control.seed import tustin
    from fsmbench.scale.montecarlo import ControllerChoice

    model = physical_plant(bench.nominal, source=plant_source) if plant is None else plant
    k = design_controller(model, objective=control_objective(bench.nominal)).controller
    ts = bench.true.converter.ts_s
    kd = tustin(k, ts_s=ts)
    return ControllerChoice(name="fsmbench controller", a=np.asarray(kd.A, dtype=float),
                            b=np.asarray(kd.B, dtype=float), c=np.asarray(kd.C, dtype=float),
                            d=np.asarray(kd.D, dtype=float), ts_s=ts,
                            gd_v_per_rad=bench.nominal.quad_diode.gain_v_per_rad,
                            source=f"designed on the {plant_source} plant, Tustin at {1/ts:g} Hz",
                            continuous=k)


def loaded_controller(path: str | Path, *, name: str | None, bench: Bench) -> ControllerChoice:
    """A controller of a ``controllers.mat`` / ``controllers_sos.json`` / design folder.

    ``name`` picks it (default fsmbench's, :func:`fsmbench.control.load.select_controller`);
    its recorded 4QD gain is used if the file has one, else ``bench.nominal``'s.
    """
    import numpy as np

    from fsmbench.bench.params import PerAxis
    from fsmbench.control.load import load_controllers, select_controller
    from fsmbench.scale.montecarlo import ControllerChoice

    ts = bench.true.converter.ts_s
    chosen = select_controller(load_controllers(path, ts_s=ts), name)
    gd = chosen.qd_gain_v_per_rad
    gains = bench.nominal.quad_diode.gain_v_per_rad if gd is None else PerAxis(h=gd[0], v=gd[1])
    return ControllerChoice(name=chosen.name, a=np.asarray(chosen.a), b=np.asarray(chosen.b),
                            c=np.asarray(chosen.c), d=np.asarray(chosen.d), ts_s=chosen.ts_s,
                            gd_v_per_rad=gains, source=str(chosen.source_path))


@contextlib.contextmanager
def dask_client(*, scheduler: str | None, workers: int) -> Iterator[Any]:
    """A ``distributed.Client``: to ``scheduler``, or to a new ``LocalCluster`` of
    ``workers`` single-threaded processes; ``None`` for ``workers == 1`` and no scheduler.

    A running scheduler's workers keep their own settings; the local ones run
    without glibc trimming and without the profiler (see the comment below).
    """
    if scheduler is None and workers == 1:
        yield None
        return
    try:
        import dask
        from distributed import Client, LocalCluster
    except ImportError:
        raise ValueError("fsmbench montecarlo on Dask needs dask.distributed: pip install "
                         "'fsmbench[dask]' (or run in one process with --workers 1)") from None
    if scheduler is not None:
        try:
            client = Client(scheduler, timeout="20s")
        except OSError as exc:
            raise ValueError(f"--scheduler {scheduler}: cannot connect ({exc})") from None
        with client:
            yield client
        return
    # Worker settings for these tasks (measured on 2 workers, 16 draws: 0.44 s of CPU per
    # draw with Dask's defaults, 0.32 s without them, 0.28-0.33 s in one process): distributed
    # sets MALLOC_TRIM_THRESHOLD_=64 kB, so each record's ~10 MB arrays go back to the OS
    # and fault in again (+30 %), and its profiler samples every 10 ms (+10 %). A draw's
    # memory is a few tens of MB, so nothing needs trimming.
    environ = {k: v for k, v in dask.config.get("distributed.nanny.pre-spawn-environ").items()
               if k != "MALLOC_TRIM_THRESHOLD_"}
    with dask.config.set({"distributed.nanny.pre-spawn-environ": environ,
                          "distributed.worker.profile.enabled": False}), \
            LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                         dashboard_address=None) as cluster, Client(cluster) as client:
        yield client


#: Breaches printed in full per requirement; the rest are named by index (all in the JSON).
_BREACHES_SHOWN = 20


def _requirement_lines(result: Any) -> list[str]:
    """Per requirement: draws meeting it, then every draw that breaks it, named."""
    from fsmbench.scale.breaches import breach_sentence

    n = len(result.draws)
    lines = ["requirements over the draws (a draw passes when both axes do):"]
    for outcome in result.requirements():
        req = outcome.to_json()
        ok = n - outcome.n_broken
        lines.append(f"  {req['description']:<58} {ok:>4} of {n} ({100 * ok / n:.0f} %)")
        if not outcome.breaches:
            continue
        indices = ", ".join(str(b.index) for b in outcome.breaches)
        lines.append(f"    broken by {outcome.n_broken} of {n} ({100 * outcome.share:.0f} %): "
                     f"draws {indices}")
        lines += [f"    {breach_sentence(req, b)}" for b in req["breaches"][:_BREACHES_SHOWN]]
        if outcome.n_broken > _BREACHES_SHOWN:
            lines.append(f"    … {outcome.n_broken - _BREACHES_SHOWN} more in montecarlo.json "
                         "(requirements[].breaches)")
    return lines


def format_table(result: Any) -> str:
    """The short table: per requirement the draws that meet it and every draw that breaks
    it (with its factors), quantiles of each metric in display units, the worst draws."""
    from fsmbench.scale.breaches import factors_sentence
    from fsmbench.scale.montecarlo import METRICS, nested, summarise

    s = summarise(result)
    n = len(result.draws)
    lines = [f"{n} draws, random seed {result.seed}, controller {result.setup.controller.name}, "
             f"around {result.setup.bench.label}; not settled before the metrics: "
             f"{s['unsettled_draws']}", *_requirement_lines(result)]
    lines.append(f"{'metric':<50} {'unit':<9} {'5 %':>10} {'median':>10} {'95 %':>10} "
                 f"{'max':>10}")

    def num(x: float | None, factor: float) -> str:
        return "—" if x is None or not math.isfinite(x) else f"{x * factor:.4g}"

    for key, (words, unit, factor) in METRICS.items():
        q = s["quantiles"][key]
        lines.append(f"{words:<50} {unit:<9} " + " ".join(
            f"{num(q[k], factor):>10}" for k in ("p5", "p50", "p95", "max")))
    lines.append("worst draws (unstable first, then the larger tracking error):")
    for row in s["worst_draws"]:
        m, f = row.metrics, row.factors
        what = (f"unstable, spectral radius {num(m['spectral_radius'], 1.0)}" if not row.stable
                else f"tracking error h {num(m['tracking_error_rms_rad.h'], 1e6)}, "
                     f"v {num(m['tracking_error_rms_rad.v'], 1e6)} µrad rms")
        lines.append(f"  draw {row.index}: {what}; {factors_sentence(nested(f))}")
    return "\n".join(lines)


def _drawn_bench(args: argparse.Namespace, bench: Any, say: Any) -> Any:
    """The bench the draws move: the packaged twin, or the one identified (DATA or --bench)."""
    if args.twin:
        return bench
    if args.bench_dir is not None:
        from fsmbench.sim.identified import identified_bench

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
    if args.controller is not None:
        path, _sep, name = str(args.controller).partition("::")
        return loaded_controller(path, name=name or None, bench=bench)
    if drawn.model is None:
        say("designing fsmbench's controller on the nominal physical plant")
        return designed_controller(bench)
    plant = drawn.model.plant
    say(f"designing fsmbench's controller on the plant of {drawn.label}")
    return designed_controller(bench, plant=plant, plant_source=f"identified ({drawn.label})")


def _inputs(args: argparse.Namespace) -> list[tuple[str, Any]]:
    """Every input path of the command line, with its option (``FILE::NAME`` as FILE)."""
    controller = (None if args.controller is None
                  else str(args.controller).partition("::")[0])
    return [("DATA", args.data), ("--bench", args.bench_dir), ("--controller", controller),
            ("--ranges", args.ranges), ("--params", args.params)]


def _command(args: argparse.Namespace) -> int:
    from fsmbench.bench.params import load_bench
    from fsmbench.io.outdir import check_inputs, output_transaction
    from fsmbench.jsonutil import stamped
    from fsmbench.scale.montecarlo import MonteCarloSetup, Ranges, run_montecarlo

    given = [x for x in (args.data is not None, args.twin, args.bench_dir is not None) if x]
    if len(given) != 1:
        raise ValueError("give one of a DATA folder, --bench DIR or --twin")
    check_inputs(args.out, _inputs(args))  # before anything is read or computed
    from fsmbench.twin.experiments import seed_experiments, with_duration

    # A record too short for the repeatability experiments: one line, before any work.
    with_duration([e for e in seed_experiments() if e.name in ("data_rep_h", "data_rep_v")],
                  duration_s=args.duration)
    if args.settle >= args.duration:
        settle = default_noted(args, "settle", f"--settle {args.settle:g} s")
        duration = default_noted(args, "duration", f"--duration {args.duration:g} s")
        raise ValueError(f"{settle} leaves nothing of a {duration} record")
    start = time.perf_counter()

    def say(msg: str) -> None:
        print(f"[{time.perf_counter() - start:6.1f} s] {msg}", file=sys.stderr, flush=True)

    bench = load_bench(args.params)
    ranges = Ranges() if args.ranges is None else read_ranges(args.ranges)
    workers = args.workers or os.cpu_count() or 1
    if args.workers is None and args.scheduler is None and importlib.util.find_spec(
            "distributed") is None:
        say("dask.distributed is not installed: running in this process "
            "(pip install 'fsmbench[dask]' to use every core)")
        workers = 1
    out = str(args.out)
    argv = [("." if a == out else a) for a in getattr(args, "argv", [])]
    with output_transaction(out, command="montecarlo", arguments=argv, data_dir=args.data,
                            need_bytes=int(args.n * _BYTES_PER_DRAW),
                            timestamp=args.timestamp, inputs=_inputs(args)) as run:
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
        path = run.staging / "montecarlo.json"
        path.write_text(json.dumps(result.to_json(), indent=2, allow_nan=False) + "\n")
        (run.staging / "timings.json").write_text(json.dumps(stamped(
            {"seconds": {"montecarlo": elapsed}, "draws": args.n,
             "workers": None if args.scheduler else workers, "scheduler": args.scheduler},
            format="fsmbench.timings", version=1), indent=2) + "\n")
    print(format_table(result))
    print(f"wrote {run.final_path(path)}", file=sys.stderr)
    return 0
