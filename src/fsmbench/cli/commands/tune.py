"""``fsmbench tune``: one guarded tuning step with the loop closed.

    fsmbench tune (--twin [--bench DIR] | --device ADDRESS) --out DIR
                  [--drift-resonance PCT] [--running seed|fsmbench|PATH[::NAME]]
                  [--max-error-urad U] [--better-by-pct P] [--watch-s S]
                  [--rollback-tolerance-pct P] [--periods N] [--seed N] [--params TOML]
                  [--drift-rate PCT_PER_H [--watch-duration S]]

One guarded procedure (:func:`fsmbench.tune.guarded.tune_guarded`) on one of two targets:
the digital twin (:class:`fsmbench.tune.targets.TwinTarget`; with ``--bench DIR`` the twin
simulates the bench identified in DIR, as ``simulate --bench``) or the live device at
ADDRESS (:class:`fsmbench.tune.device.DeviceTarget`, through its commands, the loop closed):
the Tango device ``tango://HOST:PORT/dom/fam/member`` or the EPICS IOC ``ca://PREFIX`` of
``fsmbench serve --protocol epics --prefix PREFIX`` (Channel Access,
:mod:`fsmbench.tune.ca_device`), with the same transaction. Measure the running controller,
identify the Sercalo with the loop closed, design (the same study as ``fsmbench design``),
verify, compare, load only a better controller, watch it, roll back when it does worse than
predicted. Writes ``DIR/tune.json``, ``DIR/identification/`` (the closed-loop
identification, a ``--bench DIR`` for other commands) and ``DIR/report.html``; with
``--device``, the excitations and controllers played through the device are kept in
``DIR-device/`` (the device remembers the loaded controller's file; the controllers go to a
``DIR-device/`` in the device's controllers folder, ``ControllersPath``, when DIR is not in
it). On the device the load is a transaction (:mod:`fsmbench.tune.transaction`):
``DIR/tune.json`` holds the measurement and the decision before anything is loaded, then the
outcome (``loaded``, ``rolled_back``, ``interrupted``, ``loop_opened`` after a trip);
Ctrl-C, SIGTERM, a lost connection, a refusal or any error once the load has started rolls
the device back to the controller it ran before through its ``LoadController``, and the
output says which controller the device is left on (exit status 130 for Ctrl-C, 143 for
SIGTERM). With ``--drift-rate`` (twin) the controller that runs afterwards is watched while
the resonance drifts (:mod:`fsmbench.tune.watch_twin`), the warnings in ``tune.json``'s
``watch``; the device watches itself (``WatchVerdict``, ``WatchCause``).
"""

from __future__ import annotations

import argparse
import functools
import math
import sys
from pathlib import Path
from typing import Any

from fsmbench.cli.args import drift_rate, positive, seconds
from fsmbench.cli.inputs import print_document, sim_bench
from fsmbench.cli.options import (
    add_bench,
    add_json,
    add_max_error,
    add_out,
    add_params,
    add_seed,
    add_timestamp,
)
from fsmbench.cli.runfolder import check_inputs_first, run_folder
from fsmbench.cli.status import EXIT_SIGINT, EXIT_SIGTERM, Terminated

__all__ = ["register", "run"]


def _percent(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a percentage") from None
    if not (math.isfinite(value) and -50.0 < value < 50.0):
        raise argparse.ArgumentTypeError(f"{text!r}: give a drift between -50 and 50 %")
    return value


def _periods(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number of periods") from None
    if not 2 <= value <= 100:
        raise argparse.ArgumentTypeError(f"{text!r}: give 2 to 100 periods")
    return value


def _fraction_pct(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a percentage") from None
    if not (math.isfinite(value) and 0.0 <= value < 100.0):
        raise argparse.ArgumentTypeError(f"{text!r}: give a percentage in [0, 100)")
    return value


def register(sub: Any) -> None:
    """Add ``tune`` to the sub-commands ``sub``."""
    p = sub.add_parser("tune", help="identify with the loop closed, design, and load a better "
                                    "controller only if it is (the twin or the live device)")
    where = p.add_mutually_exclusive_group(required=True)
    where.add_argument("--twin", action="store_true", help="tune the digital twin")
    where.add_argument("--device", metavar="ADDRESS", default=None,
                       help="tune the live device at ADDRESS through its commands, the loop "
                            "closed: the Tango device tango://HOST:PORT/dom/fam/member "
                            "(#dbase=no without a database), or the EPICS IOC ca://PREFIX of "
                            "fsmbench serve --protocol epics --prefix PREFIX (Channel Access, "
                            "found through EPICS_CA_ADDR_LIST); it must share this filesystem")
    add_bench(p, help="with --twin: the twin simulates the bench identified in DIR (the "
                      "output of fsmbench identify or study), the model tune starts from")
    add_out(p)
    p.add_argument("--drift-resonance", metavar="PCT", type=_percent, default=0.0,
                   dest="drift_pct", help="move the twin's Sercalo resonance (both axes) by "
                                          "this much from the bench file [%%] (default 0)")
    p.add_argument("--running", metavar="seed|fsmbench|PATH[::NAME]", default="seed",
                   help="the controller running when tune starts: the ESRF study's (9.2, "
                        "default), fsmbench's designed on the bench file before the drift, or "
                        "one from a controllers file (controllers_sos.json or "
                        "controllers.mat, e.g. the one a previous tune loaded; ::NAME picks "
                        "one of several): the device names it 'NAME (FILE)'")
    add_max_error(p, default=30.0, help="rms beam error the measurement may add [µrad] "
                                        "(default 30)")
    p.add_argument("--better-by-pct", metavar="P", dest="better_by_pct", type=_fraction_pct,
                   default=10.0, help="a candidate is loaded only if its predicted tracking "
                                      "error is this much below the running one's measured "
                                      "[%%] (default 10)")
    p.add_argument("--rollback-tolerance-pct", metavar="P", dest="rollback_pct",
                   type=functools.partial(positive, unit="percent"), default=25.0,
                   help="roll back when the loaded controller's measured tracking error "
                        "exceeds its prediction by more than this [%%] (default 25)")
    p.add_argument("--watch-s", metavar="S", dest="watch_s", type=seconds, default=10.0,
                   help="how long each controller is watched [s] (default 10)")
    p.add_argument("--periods", metavar="N", type=_periods, default=6,
                   help="measured periods of 4 s per command and stage (default 6)")
    add_seed(p, help="random seed (default 0)")
    add_params(p)
    add_timestamp(p)
    p.add_argument("--drift-rate", metavar="PCT_PER_H", dest="drift_rate", type=drift_rate,
                   default=None, help="after tuning, watch the controller that runs while the "
                                      "resonance drifts this fast [%%/h] (the loop that "
                                      "watches itself; tune.json's watch)")
    p.add_argument("--watch-duration", metavar="S", dest="watch_duration", type=seconds,
                   default=300.0, help="with --drift-rate: how long [s] (default 300)")
    add_json(p, help="print tune.json's content on stdout instead of the decision's lines")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """One tune; the decision (or tune.json) is the result."""
    if args.device is None:
        return _tune(args, None)
    twin_only = [name for name, given in (("--drift-resonance", args.drift_pct != 0.0),
                                          ("--drift-rate", args.drift_rate is not None),
                                          ("--bench", args.bench_dir is not None)) if given]
    if twin_only:
        raise ValueError(f"{', '.join(twin_only)}: for --twin; the device runs the bench it "
                         "serves (fsmbench serve --bench, --drift-rate)")
    from fsmbench.tune.proxy import device_proxy, release_proxy

    # The device first, before the numerics load: an address that does not answer is said
    # in the connection's time (3 s for an absent IOC), not after seconds of imports.
    try:
        proxy = device_proxy(args.device)
    except (KeyboardInterrupt, Terminated) as exc:
        print(f"fsmbench tune: error: {args.out}: {_stop_words(exc)} while connecting to "
              f"{args.device}: no command was sent to it, nothing was changed",
              file=sys.stderr)
        return EXIT_SIGINT if isinstance(exc, KeyboardInterrupt) else EXIT_SIGTERM
    try:
        return _tune(args, proxy)
    except (KeyboardInterrupt, Terminated) as exc:
        # Stopped while tune loaded its models, before it sent the device a command (once
        # it has, _interrupted answers): what the device runs, read now.
        sentence = _still_runs(proxy, args.device)
        print(f"decision: none: stopped before a decision; {sentence}")
        print(f"fsmbench tune: error: {args.out}: {_stop_words(exc)} before a decision; "
              f"{sentence}", file=sys.stderr)
        return EXIT_SIGINT if isinstance(exc, KeyboardInterrupt) else EXIT_SIGTERM
    finally:
        release_proxy(proxy)  # the EPICS channels, before pyepics' exit handler


def _stop_words(exc: BaseException) -> str:
    return "interrupted (Ctrl-C)" if isinstance(exc, KeyboardInterrupt) else \
        "terminated (SIGTERM)"


def _still_runs(proxy: Any, address: str) -> str:
    """What the device runs, in a sentence, read with Ctrl-C held (nothing was loaded)."""
    from fsmbench.tune.reads import read_valid
    from fsmbench.tune.transaction import ctrl_c_held

    with ctrl_c_held(lambda line: print(line, file=sys.stderr), "reading what the device runs"):
        try:
            holds = read_valid(proxy, "Controller", device=address, wait_s=5.0)
        except Exception as exc:
            return (f"Nothing was loaded; the device could not be read afterwards "
                    f"({' '.join(str(exc).split())}): check its Controller")
    return f"Nothing was loaded: the device still runs {holds}, as before tune."


def _tune(args: argparse.Namespace, proxy: Any) -> int:
    """One tune on the twin (``proxy`` None) or on the device ``proxy`` reaches."""
    from fsmbench.ident.closed_loop import write_closed_loop_identification
    from fsmbench.progress import Reporter
    from fsmbench.report.html import write_report
    from fsmbench.report.sections.tune import tune_section
    from fsmbench.tune.guarded import TuneOptions, tune_twin
    from fsmbench.tune.measure import MeasurementOptions
    from fsmbench.tune.running import running_loop, write_tune_json
    from fsmbench.twin.experiments import REP_AMPLITUDE_V

    if args.running not in ("seed", "fsmbench"):
        args.more_inputs = [("--running", args.running.partition("::")[0])]
    check_inputs_first(args, args.out, None)
    bench = sim_bench(args)
    say = Reporter()
    opts = TuneOptions(better_by=args.better_by_pct / 100.0, watch_s=args.watch_s,
                       rollback_tolerance=args.rollback_pct / 100.0,
                       # The device measures what runs: no Newport sine is played there.
                       disturbance_v=REP_AMPLITUDE_V if args.device is None else 0.0,
                       measurement=MeasurementOptions(max_error_rad=args.max_error_urad * 1e-6,
                                                      periods=int(args.periods)))
    running = running_loop(args.running, bench)
    out = str(args.out)
    if args.device is None:
        result = tune_twin(bench=bench, running=running, drift_pct=args.drift_pct,
                           options=opts, seed=args.seed, progress=say)
    else:
        from fsmbench.tune.device import DeviceTarget
        from fsmbench.tune.guarded import tune_guarded

        out_dir = Path(args.out).resolve()
        target = DeviceTarget(proxy, bench=bench, running=running,
                              folder=out_dir.with_name(out_dir.name + "-device"),
                              address=args.device, running_source=args.running)
        journal = _Journal(args)
        try:
            result = tune_guarded(target=target, bench=bench, running=running, options=opts,
                                  seed=args.seed, progress=say, journal=journal)
        except BaseException as exc:
            return _interrupted(exc, journal, out, target=target)
    payload = result.to_json()
    if args.drift_rate is not None:
        payload["watch"] = _watch(args, bench, result, running, say)
    with run_folder(args, out, data=None, need_bytes=2**23) as folder:
        paths = [write_tune_json(folder.staging / "tune.json", payload)]
        paths += write_closed_loop_identification(result.measurement.identification,
                                                  folder.staging / "identification")
        paths.append(write_report(folder.staging / "report.html",
                                  title=f"fsmbench tune on {result.target}",
                                  sections=[tune_section(result)],
                                  meta=[f"bench: {bench.label}"]))
    for path in paths:
        print(f"wrote {folder.final_path(Path(path))}", file=sys.stderr)
    if args.json:
        print_document(folder, paths, "tune.json")
        return 0
    print(f"decision: {result.decision.replace('_', ' ')}: {result.reason}")
    if result.transaction is not None:
        print(result.transaction["sentence"])
    for label, fig in (("before", result.before), ("after", result.after)):
        s1 = ", ".join(f"{a} {v:.3g}" for a, v in fig.sensitivity_at_1hz.items())
        meas = ("" if fig.measured_rms_rad is None else "; measured tracking error " + ", ".join(
            f"{a} {1e6 * v:.3g} µrad" for a, v in fig.measured_rms_rad.items()))
        print(f"{label}: {fig.name}: |S(1 Hz)| {s1} (objective below "
              f"{result.objective_bound:.3g}){meas}")
    for event in (payload.get("watch") or {}).get("events", []):
        print(f"watch: {event['time_s']:g} s: {event['level']}: {event['cause']}")
    return 0


class _Journal:
    """``tune.json`` in ``--out`` as the loop change goes (``tune_guarded``'s journal).

    Each record is a complete run of its own (:func:`fsmbench.io.outdir.output_transaction`:
    ``tune.json`` written to a temporary file and renamed, the folder swapped in one
    rename, ``run.json`` listing it), so ``--out`` holds either the previous record or the
    new one, and the run's final write replaces it as a whole.

    Parameters
    ----------
    args : argparse.Namespace
        The command line (``--out``, the inputs, ``run.json``'s arguments).
    """

    def __init__(self, args: argparse.Namespace) -> None:
        self.args, self.out = args, str(args.out)
        self.last: Any = None

    def __call__(self, result: Any) -> None:
        from fsmbench.tune.running import write_tune_json

        payload = result.to_json()
        with run_folder(self.args, self.out, data=None, need_bytes=2**20) as folder:
            write_tune_json(folder.staging / "tune.json", payload)
        self.last = result


def _interrupted(exc: BaseException, journal: _Journal, out: str, *,
                 target: Any = None) -> int:
    """After an interrupted loop change: its outcome on stdout, the exit status (130 for
    Ctrl-C, 143 for SIGTERM); an error is raised again (its message says the same).

    Stopped before any decision (measuring, identifying, designing) on the device:
    tune's excitation and record are stopped (Ctrl-C held meanwhile) and the output says
    what the device runs, which tune never changed."""
    from fsmbench.tune.transaction import ctrl_c_held

    last = journal.last
    if last is None or last.decision != "interrupted":
        if target is None:
            raise exc
        with ctrl_c_held(lambda line: print(line, file=sys.stderr), "stopping tune's work"):
            try:
                sentence = target.stand_down()
            except Exception as again:
                sentence = (f"Nothing was loaded; the device could not be read afterwards "
                            f"({' '.join(str(again).split())}): check its Controller")
        print(f"decision: none: stopped before a decision; {sentence}")
        if isinstance(exc, KeyboardInterrupt):
            print(f"fsmbench tune: error: {out}: interrupted (Ctrl-C) before a decision; "
                  f"{sentence}", file=sys.stderr)
            return EXIT_SIGINT
        if isinstance(exc, Terminated):
            print(f"fsmbench tune: error: {out}: terminated (SIGTERM) before a decision; "
                  f"{sentence}", file=sys.stderr)
            return EXIT_SIGTERM
        raise exc
    print(f"decision: interrupted: {last.reason}")
    where = f"{Path(out) / 'tune.json'} records the decision and the outcome"
    if isinstance(exc, KeyboardInterrupt):
        print(f"fsmbench tune: error: {out}: interrupted (Ctrl-C); {where}", file=sys.stderr)
        return EXIT_SIGINT
    if isinstance(exc, Terminated):
        print(f"fsmbench tune: error: {out}: terminated (SIGTERM); {where}", file=sys.stderr)
        return EXIT_SIGTERM
    raise exc


def _watch(args: argparse.Namespace, bench: Any, result: Any, running: Any,
           say: Any) -> dict[str, Any]:
    """``--drift-rate``: the controller that runs after tune, watched while the resonance drifts."""
    from fsmbench.tune.watch_twin import watch_twin
    from fsmbench.twin.closed_loop import drifted_bench

    loop = result.candidate_loop if result.decision == "loaded" else running
    base = drifted_bench(bench, resonance_pct=args.drift_pct)
    run = watch_twin(bench=base, loop=loop, drift_pct_per_h=args.drift_rate,
                     duration_s=args.watch_duration, seed=args.seed + 7, progress=say)
    opts = run.watch.options
    return {"controller": loop.name, "drift_rate_pct_per_h": args.drift_rate,
            "duration_s": args.watch_duration, "drift_start_s": run.drift_start_s,
            "first_warning_s": run.first_warning_s,
            "drift_at_warning_pct": run.drift_at_warning_pct,
            "options": {"window_s": opts.window_s, "raise_sigma": opts.raise_sigma,
                        "clear_sigma": opts.clear_sigma, "raise_windows": opts.raise_windows,
                        "clear_windows": opts.clear_windows,
                        "baseline_windows": opts.baseline_windows},
            "events": [{"time_s": e.time_s, "level": e.level, "cause": e.cause}
                       for e in run.events]}
