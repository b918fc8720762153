"""Shared fixtures: the default bench, its plants, short twin runs, and real parts.

The real parts (PyTango's own database server, fsmbench server and IOC processes, for
``tests/live`` and ``tune --device``) start on free ports in temporary folders and are
stopped by the test that started them (CI has no running service); their helpers reach the
tests through the ``parts`` fixture (tests are imported with ``--import-mode=importlib``, so
they cannot import this module). Waits poll with a wall-clock timeout that fails saying what
they waited for.
"""

from __future__ import annotations

import os
import re
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest

from fsmbench.bench.blocks import PlantModel, physical_plant
from fsmbench.bench.params import Bench, default_bench
from fsmbench.io.matwrite import save_mat
from fsmbench.study import StudyResult, run_study
from fsmbench.twin import TwinRun, simulate_bench, write_twin


@pytest.fixture(scope="session")
def bench() -> Bench:
    """The packaged Sercalo bench."""
    return default_bench()


@pytest.fixture(scope="session")
def true_plant(bench: Bench) -> PlantModel:
    """Physical plant with the twin's true parameters."""
    return physical_plant(bench.true, source="physical (true)")


@pytest.fixture(scope="session")
def nominal_plant(bench: Bench) -> PlantModel:
    """Physical plant with the nominal parameters."""
    return physical_plant(bench.nominal, source="physical (nominal)")


@pytest.fixture(scope="session")
def short_twin() -> TwinRun:
    """All thirteen experiments, 5 s each (the shortest every protocol accepts)."""
    return simulate_bench(seed=1, duration_s=5.0)


@pytest.fixture(scope="session")
def ident_twin() -> TwinRun:
    """The six identification experiments at the ESRF study's lengths (11–33 s)."""
    return simulate_bench(seed=0, experiments=["data_cal_pd_h", "data_cal_pd_v", "data_uch",
                                               "data_ucv", "data_unh", "data_unv"])


@pytest.fixture(scope="session")
def twin_study(tmp_path_factory: pytest.TempPathFactory) -> StudyResult:
    """The whole study on the twin, 5 s records: report, summary and every stage's files."""
    return run_study(out_dir=tmp_path_factory.mktemp("twin-study"), duration_s=5.0)


@pytest.fixture(scope="session")
def broken_study(short_twin: TwinRun, tmp_path_factory: pytest.TempPathFactory) -> StudyResult:
    """The study on recorded data where ``data_unh.mat`` holds a NaN in ``Vph``."""
    data = tmp_path_factory.mktemp("broken-data")
    write_twin(TwinRun(recordings={k: v for k, v in short_twin.recordings.items()
                                   if k != "data_unh"},
                       truth=short_twin.truth, seed=short_twin.seed,
                       experiments=short_twin.experiments), data)
    (data / "twin_truth.json").unlink()  # recorded data: no truth beside it
    ds = short_twin.recordings["data_unh"]
    bad = {"t": ds["t"].values, **{str(k): ds[k].values.copy() for k in ds.data_vars}}
    bad["Vph"][123] = np.nan
    save_mat(data / "data_unh.mat", bad)
    return run_study(out_dir=tmp_path_factory.mktemp("broken-study"), data_dir=data)


# ------------------------------------------------------------------ real parts

WAIT_S = 90.0  # wall-clock seconds a server may take to start on 2 busy cores
SERVE = [sys.executable, "-m", "fsmbench.cli", "serve"]


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def wait_until(check: Callable[[], Any], what: str, *, timeout_s: float = WAIT_S,
               poll_s: float = 0.05, detail: Callable[[], str] | None = None) -> Any:
    """``check()`` once it is true; a failure naming ``what`` (and ``detail()``) if never."""
    deadline = time.monotonic() + timeout_s
    while True:
        value = check()
        if value:
            return value
        if time.monotonic() > deadline:
            seen = f": {detail()}" if detail is not None else ""
            pytest.fail(f"timed out after {timeout_s:g} s (wall clock) waiting for {what}{seen}")
        time.sleep(poll_s)


class Server:
    """A process whose output goes to files (read them while it runs, never blocking)."""

    def __init__(self, args: Sequence[str], *, env: dict[str, str], folder: Path,
                 name: str) -> None:
        self.args = list(args)
        self.out = folder / f"{name}.out"
        self.err = folder / f"{name}.err"
        with open(self.out, "w") as out, open(self.err, "w") as err:
            self.proc = subprocess.Popen(self.args, stdout=out, stderr=err, env=env,
                                         cwd=folder)

    def text(self) -> str:
        return self.out.read_text(errors="replace") + self.err.read_text(errors="replace")

    def wait_for(self, words: str) -> str:
        def seen() -> bool:
            if self.proc.poll() is not None and words not in self.text():
                pytest.fail(f"{self.args[3:]} exited with status {self.proc.returncode}: "
                            f"{self.text()[-2000:]}")
            return words in self.text()

        wait_until(seen, f"{words!r} from {' '.join(self.args[3:])}")
        return self.text()

    def stop(self, sig: int = signal.SIGTERM) -> int:
        if self.proc.poll() is None:
            self.proc.send_signal(sig)
            try:
                self.proc.wait(timeout=WAIT_S)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(timeout=WAIT_S)
                pytest.fail(f"{self.args[3:]} ignored signal {sig}: killed")
        return int(self.proc.returncode)


def start(args: Sequence[str], *, env: dict[str, str], folder: Path, name: str,
          ready: str) -> Server:
    """``fsmbench serve ARGS`` (or another command), waiting for ``ready`` in its output."""
    server = Server(args, env=env, folder=folder, name=name)
    try:
        server.wait_for(ready)
    except BaseException:
        server.stop(signal.SIGKILL)
        raise
    return server


def run_cli(args: Sequence[str], *, env: dict[str, str], cwd: Path) -> tuple[int, str]:
    """A command that must end by itself: its status and its stderr."""
    done = subprocess.run(list(args), capture_output=True, text=True, env=env, cwd=cwd,
                          timeout=WAIT_S, check=False)
    return done.returncode, done.stderr


@contextmanager
def tango_database(folder: Path) -> Iterator[str]:
    """PyTango's own database server (``DataBaseds``, sqlite) on a free port: TANGO_HOST."""
    env = {**os.environ, "PYTANGO_DATABASE_NAME": str(folder / "tango_database.db")}
    env.pop("TANGO_HOST", None)
    db = Server([sys.executable, "-m", "tango.databaseds.database", "--host", "127.0.0.1",
                 "--port", "0", "--print-host-port", "2"], env=env, folder=folder,
                name="databaseds")
    try:
        text = db.wait_for("Ready to accept request")
        port = re.search(r"port=(\d+)", text)
        assert port, text
        yield f"127.0.0.1:{port.group(1)}"
    finally:
        db.stop()


@pytest.fixture(scope="session")
def parts() -> SimpleNamespace:
    """The real-parts helpers: free_port, start, run_cli, tango_database, wait_until."""
    return SimpleNamespace(WAIT_S=WAIT_S, free_port=free_port, start=start, run_cli=run_cli,
                           tango_database=tango_database, wait_until=wait_until, Server=Server)
