"""``fsmbench serve``: run the ``FsmBench`` Tango device server.

Without a database (``--nodb``) the server reads its one device and its
properties from a Tango *file database* written to a temporary folder, and
listens on ``--port``; clients address it as
``tango://<host>:<port>/fsmbench/bench/1#dbase=no``. With a database
(``TANGO_HOST`` set) the device is registered if it is not yet, and the
command line's options are stored as its properties.
"""

from __future__ import annotations

import argparse
import os
import socket
import tempfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from fsmbench import cli_args

__all__ = ["ServeOptions", "add_serve_command", "file_database", "serve"]

SERVER = "FsmBench"


@dataclass(frozen=True)
class ServeOptions:
    """What ``fsmbench serve`` was asked for.

    Attributes
    ----------
    backend : {"twin", "playback"}
    playback_folder : Path or None
    params_file : Path or None
    bench_folder : Path or None
        An identification folder: the twin simulates the bench identified there.
    seed : int
    speed : float
        Bench seconds per wall-clock second.
    nodb : bool
    port : int
        TCP port without a database (0: any free port).
    output_folder : Path
    device_name : str
    instance : str
        Server instance name.
    """

    backend: str
    playback_folder: Path | None
    params_file: Path | None
    seed: int
    speed: float
    nodb: bool
    port: int
    output_folder: Path
    device_name: str = "fsmbench/bench/1"
    instance: str = "fsmbench"
    bench_folder: Path | None = None

    def properties(self) -> dict[str, str]:
        """The device properties, as text."""
        return {
            "Backend": self.backend,
            "PlaybackFolder": str(self.playback_folder.resolve()) if self.playback_folder
            else "",
            "ParamsFile": str(self.params_file.resolve()) if self.params_file else "",
            "BenchFolder": str(self.bench_folder.resolve()) if self.bench_folder else "",
            "Seed": str(self.seed),
            "Speed": repr(float(self.speed)),
            "OutputFolder": str(self.output_folder.resolve()),
        }


def _quoted(text: str) -> str:
    return '"' + text.replace("\\", "\\\\").replace('"', '\\"') + '"'


def file_database(options: ServeOptions, folder: Path) -> Path:
    """Write the Tango file database of the server (one device, its properties)."""
    lines = [f"{SERVER}/{options.instance}/DEVICE/{SERVER}: {_quoted(options.device_name)}"]
    lines += [f"{options.device_name}->{key}: {_quoted(value)}"
              for key, value in options.properties().items() if value != ""]
    path = folder / "fsmbench-tango.db"
    path.write_text("\n".join(lines) + "\n")
    return path


def _check_port(port: int) -> None:
    if port == 0:
        return
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        try:
            s.bind(("", port))
        except OSError as exc:
            raise ValueError(f"port {port} is not free ({exc.strerror}); choose another with "
                             "--port") from None


def serve(options: ServeOptions, *, ready: str = "") -> int:
    """Run the device server until it is stopped (Ctrl-C); returns the exit status."""
    try:
        import tango
    except ImportError:
        raise ValueError("fsmbench serve needs PyTango: pip install 'fsmbench[tango]'") from None
    from fsmbench.live.device import FsmBench

    if options.backend == "playback" and not options.playback_folder:
        raise ValueError("--backend playback needs the folder to play: --backend playback DIR")
    if options.playback_folder is not None and not options.playback_folder.is_dir():
        raise ValueError(f"{options.playback_folder}: no such folder of recordings")
    if options.params_file is not None and not options.params_file.is_file():
        raise ValueError(f"{options.params_file}: no such parameter file")
    if options.bench_folder is not None:
        if options.backend != "twin":
            raise ValueError("--bench DIR is the bench the twin simulates; it does not go with "
                             "--backend playback")
        from fsmbench.bench.params import load_bench
        from fsmbench.sim.identified import identified_bench

        # Bad folders are one line here, before the server starts.
        identified_bench(options.bench_folder, bench=load_bench(options.params_file))
    if options.nodb:
        _check_port(options.port)
        with tempfile.TemporaryDirectory(prefix="fsmbench-tango-") as tmp:
            db = file_database(options, Path(tmp))
            where = f"tango://{socket.gethostname()}:{options.port}/{options.device_name}" \
                    "#dbase=no"
            print(f"fsmbench serve: {options.device_name} ({options.backend}, speed "
                  f"{options.speed:g}) at {where}{ready}", flush=True)
            FsmBench.run_server(args=[SERVER, options.instance, f"-file={db}", "-ORBendPoint",
                                      f"giop:tcp::{options.port}"])
        return 0
    if not os.environ.get("TANGO_HOST"):
        raise ValueError("no Tango database: set TANGO_HOST=host:port, or run without one "
                         "with --nodb --port N")
    db_api = tango.Database()
    info = tango.DbDevInfo()
    info.name, info._class, info.server = (options.device_name, SERVER,
                                           f"{SERVER}/{options.instance}")
    db_api.add_device(info)
    db_api.put_device_property(options.device_name,
                               {k: [v] for k, v in options.properties().items()})
    print(f"fsmbench serve: {options.device_name} ({options.backend}, speed "
          f"{options.speed:g}) registered in {os.environ['TANGO_HOST']}{ready}", flush=True)
    FsmBench.run_server(args=[SERVER, options.instance])
    return 0


def add_serve_command(sub: Any, *, factor: Callable[[str], float]) -> None:
    """Add ``serve`` to the CLI's sub-commands (``factor`` parses ``--speed``)."""
    p = sub.add_parser("serve", help="the bench live as a Tango device (the twin by default)")
    p.add_argument("--backend", nargs="+", metavar=("twin|playback", "DIR"), default=["twin"],
                   help="twin (default), or playback DIR: replay a folder of recordings")
    p.add_argument("--params", metavar="FILE", default=None,
                   help="bench parameters (TOML); default: the packaged Sercalo bench")
    p.add_argument("--bench", metavar="DIR", default=None, dest="bench_dir",
                   help="the twin simulates the bench identified in DIR (the output of "
                        "fsmbench identify or study) instead of the packaged one")
    p.add_argument("--seed", metavar="N", type=cli_args.seed, default=0,
                   help="twin seed (default 0)")
    p.add_argument("--speed", metavar="X", type=factor, default=1.0,
                   help="bench seconds per wall-clock second (default 1: real time)")
    p.add_argument("--nodb", action="store_true", help="run without a Tango database")
    p.add_argument("--port", metavar="N", type=cli_args.port, default=10000,
                   help="TCP port with --nodb (default 10000)")
    p.add_argument("--out", metavar="DIR", default="fsmbench-live",
                   help="where RunExperiment and Record write (default fsmbench-live)")
    p.set_defaults(func=_command)


def _command(args: argparse.Namespace) -> int:
    kind, *rest = args.backend
    if kind not in ("twin", "playback") or (kind == "twin" and rest) or len(rest) > 1:
        raise ValueError("--backend must be 'twin' or 'playback DIR'")
    return serve(ServeOptions(
        backend=kind, playback_folder=Path(rest[0]) if rest else None,
        params_file=Path(args.params) if args.params else None, seed=args.seed,
        speed=args.speed, nodb=args.nodb, port=args.port, output_folder=Path(args.out),
        bench_folder=Path(args.bench_dir) if args.bench_dir else None))
