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

from fsmbench.cli_args import drift_rate, positive, seconds, seed

__all__ = ["add_closed_loop_options", "add_tune_command", "closed_loop_simulation",
           "write_tune_json"]

#: A controller pole closer than this to z = -1 counts as on it [1]: its Tustin pre-image
#: would lie beyond 4 / (T 1e-6) rad/s (6e5 times the sample rate), no roll-off of a
#: physical loop, and a double pole on -1 is located only to ~sqrt(eps) = 1.5e-8.
_AT_NYQUIST = 1e-6


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


def add_tune_command(sub: Any) -> None:
    """Add ``tune`` to the CLI's sub-commands (``sub`` from ``add_subparsers``)."""
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
    p.add_argument("--bench", metavar="DIR", dest="bench_dir", default=None,
                   help="with --twin: the twin simulates the bench identified in DIR (the "
                        "output of fsmbench identify or study), the model tune starts from")
    p.add_argument("--out", metavar="DIR", required=True, help="output folder")
    p.add_argument("--drift-resonance", metavar="PCT", type=_percent, default=0.0,
                   dest="drift_pct", help="move the twin's Sercalo resonance (both axes) by "
                                          "this much from the bench file [%%] (default 0)")
    p.add_argument("--running", metavar="seed|fsmbench|PATH[::NAME]", default="seed",
                   help="the controller running when tune starts: the ESRF study's (9.2, "
                        "default), fsmbench's designed on the bench file before the drift, or "
                        "one from a controllers file (controllers_sos.json or "
                        "controllers.mat, e.g. the one a previous tune loaded; ::NAME picks "
                        "one of several): the device names it 'NAME (FILE)'")
    p.add_argument("--max-error-urad", metavar="U", dest="max_error_urad",
                   type=functools.partial(positive, unit="µrad"), default=30.0,
                   help="rms beam error the measurement may add [µrad] (default 30)")
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
    p.add_argument("--seed", metavar="N", type=seed, default=0, help="random seed (default 0)")
    p.add_argument("--params", metavar="TOML", default=None,
                   help="bench parameters (TOML); default the packaged Sercalo bench")
    p.add_argument("--drift-rate", metavar="PCT_PER_H", dest="drift_rate", type=drift_rate,
                   default=None, help="after tuning, watch the controller that runs while the "
                                      "resonance drifts this fast [%%/h] (the loop that "
                                      "watches itself; tune.json's watch)")
    p.add_argument("--watch-duration", metavar="S", dest="watch_duration", type=seconds,
                   default=300.0, help="with --drift-rate: how long [s] (default 300)")
    p.set_defaults(func=_command)


def _running(kind: str, bench: Any) -> Any:
    from fsmbench.bench.blocks import physical_plant
    from fsmbench.control.seed import seed_decentralised_controller
    from fsmbench.tune.guarded import loop_of

    ts = bench.true.converter.ts_s
    gd = bench.nominal.quad_diode.gain_v_per_rad
    if kind not in ("seed", "fsmbench"):
        return _running_file(kind, bench)
    if kind == "seed":
        return loop_of(seed_decentralised_controller(), name="the ESRF study's controller (9.2)",
                       ts_s=ts, gd_v_per_rad=(float(gd.h), float(gd.v)))
    from fsmbench.control.study import design_study

    study = design_study(physical_plant(bench.nominal, source="the bench file"), bench=bench)
    return loop_of(study.controllers["fsmbench_controller"],
                   name="fsmbench's controller (designed on the bench file)", ts_s=ts,
                   gd_v_per_rad=(float(gd.h), float(gd.v)))


def _running_file(spec: str, bench: Any) -> Any:
    """The controller ``PATH[::NAME]`` of a controllers file, as the device runs it.

    The file holds it discrete at the converter rate (Tustin per section, prewarped);
    ``Loop.k`` is its exact continuous pre-image under plain Tustin (``z = -1`` is no
    pole of it), so that the loop the twin and the predictions run is the file's, line
    for line. Named ``'NAME (FILE)'``, as ``LoadController`` names it on the device.
    """
    import control as ct
    import numpy as np

    from fsmbench.control.load import load_controllers, select_controller
    from fsmbench.tune.guarded import loop_of

    ts = bench.true.converter.ts_s
    path, sep, name = spec.partition("::")
    chosen = select_controller(load_controllers(path, ts_s=ts), name if sep else None)
    if not chosen.maps(("Rh", "Rv"), ("Uch", "Ucv")):
        raise ValueError(f"{path}: controller {chosen.name!r} maps {list(chosen.input_names)} "
                         f"to {list(chosen.output_names)}, not Rh, Rv to Uch, Ucv")
    n = chosen.a.shape[0]
    m = np.eye(n) + chosen.a
    # Tustin maps s = infinity, and only it, to z = -1: a pole there has no pre-image. Decided
    # on the poles themselves. det(I + A) against |I + A|^n refused fsmbench's own files: the
    # delta realisation of their integrator sections puts entries of ~1e12 in A beside exact
    # poles at z = 1 (|I + A|^14 ~ 1e120), with no pole near -1 (|1 + z| >= 1.9). A pole just
    # inside -1 is legitimate: Tustin's image of a real lowpass far above Nyquist, at
    # s = -(2/T)(1 - z)/(1 + z) (1e-3 from -1 is a roll-off at 640 times the sample rate).
    poles = np.linalg.eigvals(chosen.a) if n else np.zeros(0)
    if n and float(np.min(np.abs(1.0 + poles))) < _AT_NYQUIST:
        raise ValueError(f"{path}: controller {chosen.name!r} has a pole at z = -1 (Nyquist): "
                         "it has no continuous-time equivalent")
    # z = (1 + s T/2) / (1 - s T/2) substituted in C (zI - A)^-1 B + D, with M = I + A:
    # Ac = (2/T) M^-1 (A - I), Bc = M^-1 B, Cc = (4/T) C M^-1, Dc = D - C M^-1 B.
    minv = np.linalg.inv(m) if n else np.zeros((0, 0))
    k = ct.ss((2.0 / ts) * minv @ (chosen.a - np.eye(n)), minv @ chosen.b,
              (4.0 / ts) * chosen.c @ minv, chosen.d - chosen.c @ minv @ chosen.b,
              inputs=["Rh", "Rv"], outputs=["Uch", "Ucv"], name=chosen.name)
    nominal = bench.nominal.quad_diode.gain_v_per_rad
    gd = chosen.qd_gain_v_per_rad or (float(nominal.h), float(nominal.v))
    return loop_of(k, name=f"{chosen.name} ({Path(chosen.source_path).name})", ts_s=ts,
                   gd_v_per_rad=(float(gd[0]), float(gd[1])))


def _command(args: argparse.Namespace) -> int:
    if args.device is None:
        return _tune(args, None)
    twin_only = [name for name, given in (("--drift-resonance", args.drift_pct != 0.0),
                                          ("--drift-rate", args.drift_rate is not None),
                                          ("--bench", args.bench_dir is not None)) if given]
    if twin_only:
        raise ValueError(f"{', '.join(twin_only)}: for --twin; the device runs the bench it "
                         "serves (fsmbench serve --bench, --drift-rate)")
    from fsmbench.cli import EXIT_SIGINT, EXIT_SIGTERM, Terminated
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
    from fsmbench.bench.params import load_bench
    from fsmbench.ident.closed_loop import write_closed_loop_identification
    from fsmbench.io.outdir import check_inputs, output_transaction
    from fsmbench.progress import Reporter
    from fsmbench.report.html import write_report
    from fsmbench.report.sections.tune import tune_section
    from fsmbench.tune.guarded import TuneOptions, tune_twin
    from fsmbench.tune.measure import MeasurementOptions
    from fsmbench.twin.experiments import REP_AMPLITUDE_V

    inputs = [("--params", args.params), ("--bench", args.bench_dir)]
    if args.running not in ("seed", "fsmbench"):
        inputs.append(("--running", args.running.partition("::")[0]))
    check_inputs(args.out, inputs)
    bench = load_bench(args.params)
    if args.bench_dir is not None:
        from fsmbench.sim.identified import identified_bench

        bench = identified_bench(args.bench_dir, bench=bench)
    say = Reporter()
    opts = TuneOptions(better_by=args.better_by_pct / 100.0, watch_s=args.watch_s,
                       rollback_tolerance=args.rollback_pct / 100.0,
                       # The device measures what runs: no Newport sine is played there.
                       disturbance_v=REP_AMPLITUDE_V if args.device is None else 0.0,
                       measurement=MeasurementOptions(max_error_rad=args.max_error_urad * 1e-6,
                                                      periods=int(args.periods)))
    running = _running(args.running, bench)
    out = str(args.out)
    argv = [("." if a == out else a) for a in getattr(args, "argv", [])]
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
        journal = _Journal(out, arguments=argv, inputs=inputs)
        try:
            result = tune_guarded(target=target, bench=bench, running=running, options=opts,
                                  seed=args.seed, progress=say, journal=journal)
        except BaseException as exc:
            return _interrupted(exc, journal, out, target=target)
    payload = result.to_json()
    if args.drift_rate is not None:
        payload["watch"] = _watch(args, bench, result, running, say)
    with output_transaction(out, command="tune", arguments=argv, need_bytes=2**23,
                            inputs=inputs) as run:
        paths = [write_tune_json(run.staging / "tune.json", payload)]
        paths += write_closed_loop_identification(result.measurement.identification,
                                                  run.staging / "identification")
        paths.append(write_report(run.staging / "report.html",
                                  title=f"fsmbench tune on {result.target}",
                                  sections=[tune_section(result)],
                                  meta=[f"bench: {bench.label}"]))
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
    for path in paths:
        print(f"wrote {run.final_path(Path(path))}", file=sys.stderr)
    return 0


def write_tune_json(path: Path, payload: dict[str, Any]) -> Path:
    """Write ``tune.json`` (``TuneResult.to_json()``, ``watch`` added) atomically.

    ``format`` and ``format_version`` come first, every other key sorted at every depth
    (reproducible files).

    Parameters
    ----------
    path : Path
        The file to write.
    payload : dict
        Its content, stamped ``fsmbench.tune``.

    Returns
    -------
    Path
        ``path``.
    """
    from fsmbench.io.atomic import atomic_write_text
    from fsmbench.jsonutil import format_text

    return atomic_write_text(path, format_text(payload, sort_keys=True))


class _Journal:
    """``tune.json`` in ``--out`` as the loop change goes (``tune_guarded``'s journal).

    Each record is a complete run of its own (:func:`fsmbench.io.outdir.output_transaction`:
    ``tune.json`` written to a temporary file and renamed, the folder swapped in one
    rename, ``run.json`` listing it), so ``--out`` holds either the previous record or the
    new one, and the run's final write replaces it as a whole.

    Parameters
    ----------
    out : str
        The ``--out`` folder.
    arguments : list of str
        The command line, for ``run.json``.
    inputs : list of (str, str or None)
        The command line's inputs (never inside ``--out``).
    """

    def __init__(self, out: str, *, arguments: list[str], inputs: list[Any]) -> None:
        self.out, self.arguments, self.inputs = out, arguments, inputs
        self.last: Any = None

    def __call__(self, result: Any) -> None:
        from fsmbench.io.outdir import output_transaction

        payload = result.to_json()
        with output_transaction(self.out, command="tune", arguments=self.arguments,
                                need_bytes=2**20, inputs=self.inputs) as run:
            write_tune_json(run.staging / "tune.json", payload)
        self.last = result


def _interrupted(exc: BaseException, journal: _Journal, out: str, *,
                 target: Any = None) -> int:
    """After an interrupted loop change: its outcome on stdout, the exit status (130 for
    Ctrl-C, 143 for SIGTERM); an error is raised again (its message says the same).

    Stopped before any decision (measuring, identifying, designing) on the device:
    tune's excitation and record are stopped (Ctrl-C held meanwhile) and the output says
    what the device runs, which tune never changed."""
    from fsmbench.cli import EXIT_SIGINT, EXIT_SIGTERM, Terminated
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


def add_closed_loop_options(p: argparse.ArgumentParser) -> None:
    """``simulate --closed-loop CONTROLLER [--at output|reference] [--max-error-urad U]``."""
    p.add_argument("--closed-loop", metavar="CONTROLLER", dest="closed_loop", default=None,
                   help="play the excitations with the loop closed by CONTROLLER (seed: the "
                        "ESRF study's; or a controllers file or fsmbench design folder, "
                        "PATH[::NAME]) and write data_cl_uch, data_cl_ucv; without "
                        "--excitation, beam-bounded multisines designed on the bench")
    p.add_argument("--at", choices=("output", "reference"), default="output",
                   help="with --closed-loop: add the excitation to the controller's output "
                        "(default) or to the loop's reference"
                        + "; at the reference the controller's notch removes it at the "
                          "Sercalo's resonances, which then come out poorly")
    p.add_argument("--max-error-urad", metavar="U", dest="max_error_urad",
                   type=functools.partial(positive, unit="µrad"), default=30.0,
                   help="with --closed-loop and no --excitation: the rms beam error the "
                        "designed multisines may add [µrad] (default 30)")


def closed_loop_simulation(args: argparse.Namespace, bench: Any, out_dir: Path,
                           progress: Any) -> list[Path]:
    """``simulate --closed-loop``: the records, written to ``out_dir``."""
    from fsmbench.sim.loaded import running_controller
    from fsmbench.twin.closed_loop import simulate_closed_loop
    from fsmbench.twin.simulate import write_twin

    if args.experiments:
        raise ValueError("--closed-loop writes data_cl_uch and data_cl_ucv only; run the "
                         "ESRF study's experiments (--experiments) in another simulate")
    controller = running_controller(args.closed_loop, bench=bench)
    run = simulate_closed_loop(bench=bench, controller=controller, sources=args.excitation,
                               at=args.at, max_error_rad=args.max_error_urad * 1e-6,
                               seed=args.seed, duration_s=args.duration, progress=progress)
    return write_twin(run, out_dir, format=args.format)
