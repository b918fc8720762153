"""``fsmbench serve``: the live bench as a Tango device server or an EPICS IOC.

Tango (the default protocol):

- with a database (``TANGO_HOST``): ``fsmbench serve INSTANCE [--device NAME]``
  registers the device ``NAME`` (default ``fsmbench/bench/1``) of the server
  ``FsmBench/INSTANCE`` if it is not registered yet, writes the properties
  the database lacks (the command line's values, else the defaults) and
  never overwrites one an administrator set: a command-line value that
  differs from the database's is refused. A second start of a running
  instance (or of a device another instance serves) is refused before the
  database is touched. An unreachable database is one line and status 2.
  Starter (Astor) launches the same server as ``FsmBench INSTANCE``
  (:func:`fsmbench.cli.starter.main`), reading everything from the database;
- without one (``--nodb``): a Tango *file database* in a temporary folder holds
  the one device and its properties; clients use
  ``tango://<host>:<port>/<device>#dbase=no``.

EPICS: ``fsmbench serve --protocol epics --prefix PREFIX`` serves the same
bench as a Channel Access (and PV Access) IOC (:mod:`fsmbench.live.epics`).
"""

from __future__ import annotations

import os
import socket
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from fsmbench.live.announce import announce

__all__ = ["SERVER", "ServeOptions", "file_database", "refuse_second_start", "serve",
           "tango_database"]

SERVER = "FsmBench"
_CONTACT_MS = 2000  # timeout of the database and ping calls before the server starts


@dataclass(frozen=True)
class ServeOptions:
    """What ``fsmbench serve`` was asked for.

    Attributes
    ----------
    backend : {"twin", "playback"}
    playback_folder, params_file, bench_folder : Path or None
        ``bench_folder``: an identification folder the twin simulates.
    seed : int
    speed : float
        Bench seconds per wall-clock second.
    nodb : bool
    port : int
        TCP port without a database (0: any free port).
    output_folder : Path
    controllers_folder : Path or None
        The only folder ``LoadController`` reads controller files from (None: the output
        folder).
    device_name : str
    instance : str
        Tango server instance (``FsmBench/<instance>``).
    protocol : {"tango", "epics"}
    prefix : str
        PV prefix (EPICS).
    watchdog_s : float
        Wall-clock seconds without a bench block that make the device FAULT.
    drift_pct_per_h : float
        Twin: the Sercalo resonance drifts this fast [%/h], from ``drift_start_s`` [s] of
        bench time.
    access_security : Path or None
        EPICS: an access-security file (``.acf``) for every record (ASG ``DEFAULT``):
        who may put (``UAG``/``HAG`` rules), everyone else reads.
    given : frozenset of str
        Properties the command line set explicitly (checked against the database).
    announce_json : bool
        Say where it serves as one JSON document (:func:`announce`) instead of a sentence.
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
    protocol: str = "tango"
    prefix: str = ""
    watchdog_s: float = 5.0
    drift_pct_per_h: float = 0.0
    drift_start_s: float = 0.0
    controllers_folder: Path | None = None
    access_security: Path | None = None
    given: frozenset[str] = field(default_factory=frozenset)
    announce_json: bool = False

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
            "ControllersFolder": str(self.controllers_folder.resolve())
            if self.controllers_folder else "",
            "WatchdogSeconds": repr(float(self.watchdog_s)),
            "DriftRate": repr(float(self.drift_pct_per_h)),
            "DriftStart": repr(float(self.drift_start_s)),
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


def _check_inputs(options: ServeOptions) -> None:
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
        from fsmbench.twin.identified import identified_bench

        # Bad folders are one line here, before the server starts.
        identified_bench(options.bench_folder, bench=load_bench(options.params_file))
    out = options.output_folder
    if out.exists() and not out.is_dir():
        raise ValueError(f"{out}: the output folder is a file")
    folder = options.controllers_folder
    if folder is not None and not folder.is_dir():
        raise ValueError(f"--controllers {folder}: no such folder (LoadController reads "
                         "controller files only from there)")


# ------------------------------------------------------------------ the Tango database


def tango_database() -> Any:
    """The Tango database of ``TANGO_HOST``, or one line saying why not."""
    import tango

    host = os.environ.get("TANGO_HOST", "")
    if not host:
        raise ValueError("no Tango database: set TANGO_HOST=host:port, or run without one "
                         "with --nodb --port N")
    try:
        db = tango.Database()
        db.set_timeout_millis(_CONTACT_MS)
        db.get_info()
    except tango.DevFailed as exc:
        why = " ".join(str(exc.args[-1].desc).split())[:200]
        raise ValueError(f"the Tango database at TANGO_HOST={host} does not answer ({why}); "
                         "start it or correct TANGO_HOST") from None
    return db


def _alive(name: str) -> bool:
    import tango

    try:
        proxy = tango.DeviceProxy(name)
        proxy.set_timeout_millis(_CONTACT_MS)
        proxy.ping()
    except tango.DevFailed:
        return False
    return True


def refuse_second_start(db: Any, instance: str, device: str | None) -> None:
    """Refuse, before writing anything, a server instance (or a device) already served."""
    import tango

    server = f"{SERVER}/{instance}"
    admin = f"dserver/{server}"
    try:
        info = db.get_device_info(admin)
    except tango.DevFailed:
        info = None
    if info is not None and info.exported and _alive(admin):
        raise ValueError(f"{server} is already running (pid {info.pid} on {info.host}, "
                         f"started {info.started_date}); stop it first, or start another "
                         "instance")
    if device is None:
        return
    try:
        dev = db.get_device_info(device)
    except tango.DevFailed:
        return
    if dev.ds_full_name.lower() != server.lower():
        raise ValueError(f"{device} belongs to the server {dev.ds_full_name} (class "
                         f"{dev.class_name}) in this database; choose another --device, or "
                         f"start that instance")


def _properties_to_write(db: Any, options: ServeOptions, *, registered: bool) -> dict[str, str]:
    """The properties the database lacks; refuse a command-line value that differs."""
    from fsmbench.live.device import PROPERTY_DEFAULTS

    mine = options.properties()
    have: dict[str, list[str]] = {}
    if registered:
        got = db.get_device_property(options.device_name, list(PROPERTY_DEFAULTS))
        have = {k: list(got[k]) for k in PROPERTY_DEFAULTS}
    conflicts = [f"{k} is {have[k][0]!r} there, the command line asks {mine[k]!r}"
                 for k in sorted(options.given) if have.get(k) and have[k][0] != mine[k]]
    if conflicts:
        raise ValueError(f"{options.device_name} keeps the properties an administrator set in "
                         f"the Tango database ({'; '.join(conflicts)}): drop those options, or "
                         "change the properties (Jive, or Database.put_device_property)")
    return {k: (mine[k] if k in options.given else PROPERTY_DEFAULTS[k])
            for k in PROPERTY_DEFAULTS if not have.get(k)}


def _serve_tango(options: ServeOptions, ready: str) -> int:
    try:
        import tango
    except ImportError:
        raise ValueError("fsmbench serve needs PyTango: pip install 'fsmbench[tango]'") from None
    from fsmbench.live.device import FsmBench

    if options.nodb:
        _check_port(options.port)
        with tempfile.TemporaryDirectory(prefix="fsmbench-tango-") as tmp:
            db_file = file_database(options, Path(tmp))
            where = f"tango://{socket.gethostname()}:{options.port}/{options.device_name}" \
                    "#dbase=no"
            announce(options, f"fsmbench serve: {options.device_name} ({options.backend}, "
                              f"speed {options.speed:g}) at {where}{ready}", address=where,
                     device=options.device_name, database=None)
            FsmBench.run_server(args=[options.instance, f"-file={db_file}",
                                      "-ORBendPoint", f"giop:tcp::{options.port}"])
        return 0
    db = tango_database()
    refuse_second_start(db, options.instance, options.device_name)
    try:
        registered = db.get_device_info(options.device_name) is not None
    except tango.DevFailed:
        registered = False
    write = _properties_to_write(db, options, registered=registered)
    if not registered:
        info = tango.DbDevInfo()
        info.name, info._class, info.server = (options.device_name, SERVER,
                                               f"{SERVER}/{options.instance}")
        db.add_device(info)
    if write:
        db.put_device_property(options.device_name, {k: [v] for k, v in write.items()})
    announce(options, f"fsmbench serve: {options.device_name} ({SERVER}/{options.instance}) "
                      f"{'registered' if not registered else 'found'} in "
                      f"{os.environ['TANGO_HOST']}"
                      f"{'; properties written: ' + ', '.join(sorted(write)) if write else ''}"
                      f"{ready}",
             address=f"tango://{os.environ['TANGO_HOST']}/{options.device_name}",
             device=options.device_name, database=os.environ["TANGO_HOST"],
             registered=not registered, properties_written=sorted(write))
    FsmBench.run_server(args=[options.instance])
    return 0


def serve(options: ServeOptions, *, ready: str = "") -> int:
    """Run the device server or the IOC until it is stopped; returns the exit status."""
    _check_inputs(options)
    if options.protocol == "epics":
        from fsmbench.live.epics import serve_epics

        return serve_epics(options, ready=ready)
    return _serve_tango(options, ready)
