"""``fsmbench serve``: the live bench as a Tango device server or an EPICS IOC (the
twin by default; :mod:`fsmbench.live.serve`)."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from fsmbench.cli.args import drift_rate, factor, port, seconds
from fsmbench.cli.options import add_bench, add_json, add_out, add_params, add_seed
from fsmbench.live.serve import ServeOptions, serve

__all__ = ["register", "run"]


def register(sub: Any) -> None:
    """Add ``serve`` to the sub-commands ``sub``."""
    p = sub.add_parser("serve", help="the bench live as a Tango device or an EPICS IOC "
                                     "(the twin by default)",
                       description="Serve the live bench (the twin by default) as the Tango "
                                   "device FsmBench, or as an EPICS IOC.")
    p.add_argument("instance", nargs="?", default="fsmbench", metavar="INSTANCE",
                   help="Tango server instance: the server is FsmBench/INSTANCE (default "
                        "fsmbench)")
    p.add_argument("--device", metavar="NAME", default="fsmbench/bench/1",
                   help="Tango device name (default fsmbench/bench/1)")
    p.add_argument("--protocol", choices=("tango", "epics"), default="tango",
                   help="tango (default) or epics (a Channel Access IOC; the epics extra)")
    p.add_argument("--prefix", metavar="PREFIX", default="",
                   help="PV prefix with --protocol epics: PREFIX:BeamAngleH, ...")
    p.add_argument("--backend", nargs="+", metavar=("twin|playback", "DIR"), default=None,
                   help="twin (default), or playback DIR: replay a folder of recordings")
    # Defaults None: an option not given leaves the database's property as it is.
    add_params(p)
    add_bench(p, help="the twin simulates the bench identified in DIR (the output of "
                      "fsmbench identify or study) instead of the packaged one")
    add_seed(p, help="twin seed (default 0)", default=None)
    p.add_argument("--speed", metavar="X", type=factor, default=None,
                   help="bench seconds per wall-clock second, 0.01 to 100 (default 1: real "
                        "time)")
    p.add_argument("--watchdog", metavar="S", type=factor, default=None,
                   help="wall-clock seconds without a bench block that make the device FAULT "
                        "(default 5)")
    p.add_argument("--drift-rate", metavar="PCT_PER_H", dest="drift_rate", type=drift_rate,
                   default=None, help="twin: the Sercalo resonance (both axes) drifts this fast "
                                      "[%%/h] (default 0), what the loop's watch (WatchVerdict, "
                                      "WatchCause) is for")
    p.add_argument("--drift-start", metavar="S", dest="drift_start", type=seconds,
                   default=None, help="with --drift-rate: the bench time the drift starts [s] "
                                      "(default 0)")
    p.add_argument("--nodb", action="store_true", help="Tango without a database")
    p.add_argument("--port", metavar="N", type=port, default=10000,
                   help="TCP port with --nodb (default 10000)")
    add_out(p, required=False, help="where RunExperiment and Record write (default "
                                    "fsmbench-live)")
    p.add_argument("--controllers", metavar="DIR", default=None,
                   help="the only folder LoadController reads controller files from (a "
                        "relative path is taken inside it; default: the --out folder)")
    p.add_argument("--access-security", metavar="FILE.acf", default=None,
                   dest="access_security",
                   help="EPICS: an access-security file for the IOC's records (ASG DEFAULT: "
                        "the users and hosts that may put; everyone else reads)")
    add_json(p, help="say where it serves as one JSON line (format fsmbench.serve: protocol, "
                     "address, backend, speed, folders) instead of a sentence")
    p.set_defaults(func=run)


_OPTION_PROPERTY = {"backend": "Backend", "params": "ParamsFile", "bench_dir": "BenchFolder",
                    "seed": "Seed", "speed": "Speed", "out": "OutputFolder",
                    "watchdog": "WatchdogSeconds", "drift_rate": "DriftRate",
                    "drift_start": "DriftStart", "controllers": "ControllersFolder"}


def run(args: argparse.Namespace) -> int:
    """Serve until stopped (its address on stdout once it serves); the exit status."""
    from fsmbench.live.states import MAX_SPEED, MIN_SPEED

    kind, *rest = args.backend or ["twin"]
    if kind not in ("twin", "playback") or (kind == "twin" and rest) or len(rest) > 1:
        raise ValueError("--backend must be 'twin' or 'playback DIR'")
    given = {prop for opt, prop in _OPTION_PROPERTY.items() if getattr(args, opt) is not None}
    if kind == "playback":
        given.add("PlaybackFolder")
    speed = 1.0 if args.speed is None else args.speed
    if not MIN_SPEED <= speed <= MAX_SPEED:
        raise ValueError(f"--speed {speed:g} is outside [{MIN_SPEED:g}, {MAX_SPEED:g}]")
    if args.protocol == "epics":
        if not args.prefix:
            raise ValueError("--protocol epics needs --prefix PREFIX (the PVs are "
                             "PREFIX:BeamAngleH, ...)")
        if args.nodb or args.device != "fsmbench/bench/1" or args.instance != "fsmbench":
            raise ValueError("INSTANCE, --device and --nodb are Tango's; an IOC is named by "
                             "--prefix")
    elif args.prefix:
        raise ValueError("--prefix is for --protocol epics")
    elif args.access_security:
        raise ValueError("--access-security is for --protocol epics (Tango's own access "
                         "control is the TangoAccessControl device: README)")
    if args.device.count("/") != 2 or not all(args.device.split("/")):
        raise ValueError(f"--device {args.device!r} is not a Tango device name "
                         "(domain/family/member)")
    return serve(ServeOptions(
        backend=kind, playback_folder=Path(rest[0]) if rest else None,
        params_file=Path(args.params) if args.params else None,
        seed=0 if args.seed is None else args.seed, speed=speed, nodb=args.nodb,
        port=args.port, output_folder=Path(args.out or "fsmbench-live"),
        bench_folder=Path(args.bench_dir) if args.bench_dir else None,
        device_name=args.device.lower(), instance=args.instance, protocol=args.protocol,
        prefix=args.prefix, watchdog_s=5.0 if args.watchdog is None else args.watchdog,
        drift_pct_per_h=0.0 if args.drift_rate is None else args.drift_rate,
        drift_start_s=0.0 if args.drift_start is None else args.drift_start,
        controllers_folder=Path(args.controllers) if args.controllers else None,
        access_security=Path(args.access_security) if args.access_security else None,
        given=frozenset(given), announce_json=args.json))
