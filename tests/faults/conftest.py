"""Shared helpers of the CLI fault tests: run the command, hash folders, check verdicts.

The helpers reach the tests through the ``kit`` fixture (tests are imported
with ``--import-mode=importlib``, so they cannot import this module).
"""

from __future__ import annotations

import hashlib
import os
import shutil
import subprocess
import sys
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from types import SimpleNamespace

import pytest

from fsmbench.cli import main
from fsmbench.twin import TwinRun, write_twin


@dataclass(frozen=True)
class Outcome:
    """What one ``fsmbench`` invocation did."""

    status: int
    out: str
    err: str

    def verdict(self) -> str:
        """The last stderr line (the one-line verdict of a failed run)."""
        lines = self.err.strip().splitlines()
        return lines[-1] if lines else ""


def hashes(folder: Path) -> dict[str, str]:
    """sha256 of every file under ``folder``, by relative path (empty if absent)."""
    if not folder.exists():
        return {}
    return {p.relative_to(folder).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file()}


def leftovers(parent: Path) -> list[str]:
    """Hidden staging/old folders or ``.part`` files fsmbench may have left in ``parent``."""
    return sorted(p.name for p in parent.rglob("*")
                  if ".fsmbench-" in p.name or p.name.endswith(".part"))


def assert_one_line_verdict(outcome: Outcome, command: str, *needles: str,
                            status: int = 2) -> None:
    """Exit ``status``, no traceback, the last line the verdict naming every needle."""
    assert outcome.status == status, outcome.err
    assert "Traceback" not in outcome.err and "Traceback" not in outcome.out
    line = outcome.verdict()
    assert line.startswith(f"fsmbench {command}: error: "), outcome.err
    for needle in needles:
        assert needle in line, (needle, line)


@pytest.fixture
def run_cli(capsys: pytest.CaptureFixture[str]) -> Callable[..., Outcome]:
    """Run ``fsmbench`` in this process; returns its status and output."""

    def run(*argv: str | Path) -> Outcome:
        capsys.readouterr()
        status = main([str(a) for a in argv])
        captured = capsys.readouterr()
        return Outcome(status, captured.out, captured.err)

    return run


def cli_command(*argv: str | Path, prelude: str = "") -> list[str]:
    """The argv of a separate Python process running ``fsmbench`` (after ``prelude``)."""
    script = (f"import sys\n{prelude}\nfrom fsmbench.cli import main\n"
              f"sys.exit(main({[str(a) for a in argv]!r}))\n")
    return [sys.executable, "-c", script]


def in_mount_namespace(script: str, *, timeout_s: float = 120) -> subprocess.CompletedProcess[str]:
    """Run a shell ``script`` in a private mount namespace (``unshare -m``).

    The script may mount filesystems (a read-only or a tiny tmpfs); they vanish
    with the process and no other process sees them.
    """
    return subprocess.run(["unshare", "--mount", "--propagation", "private", "sh", "-c",
                           script], capture_output=True, text=True, timeout=timeout_s,
                          check=False)


@pytest.fixture(scope="session")
def can_mount(tmp_path_factory: pytest.TempPathFactory) -> bool:
    """Whether this process may mount a tmpfs in a private namespace (root in a container)."""
    if shutil.which("unshare") is None:
        return False
    d = tmp_path_factory.mktemp("mount-probe")
    try:
        probe = in_mount_namespace(f"mount -t tmpfs -o size=64k tmpfs {d} && touch {d}/x",
                                   timeout_s=20)
    except (OSError, subprocess.TimeoutExpired):
        return False
    return probe.returncode == 0


@pytest.fixture(scope="session")
def can_chattr(tmp_path_factory: pytest.TempPathFactory) -> bool:
    """Whether ``chattr +i`` works here (root and a filesystem with attributes)."""
    if shutil.which("chattr") is None:
        return False
    d = tmp_path_factory.mktemp("chattr-probe") / "x"
    d.mkdir()
    ok = subprocess.run(["chattr", "+i", str(d)], capture_output=True, check=False)
    if ok.returncode != 0:
        return False
    subprocess.run(["chattr", "-i", str(d)], check=True)
    return True


@pytest.fixture
def immutable() -> Iterator[Callable[[Path], None]]:
    """Make folders immutable (``chattr +i``) for one test; undone afterwards."""
    done: list[Path] = []

    def make(path: Path) -> None:
        subprocess.run(["chattr", "+i", str(path)], check=True)
        done.append(path)

    yield make
    for path in done:
        subprocess.run(["chattr", "-i", str(path)], check=False)


@pytest.fixture(scope="session")
def stage_data(short_twin: TwinRun, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A data folder with all thirteen twin records, 5 s each, and ``twin_truth.json``."""
    data = tmp_path_factory.mktemp("stage-data")
    write_twin(short_twin, data)
    return data


@pytest.fixture(scope="session")
def huddle_data(short_twin: TwinRun, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Only the huddle tests and repeatability records (no identification experiments)."""
    data = tmp_path_factory.mktemp("huddle-data")
    subset = {k: v for k, v in short_twin.recordings.items()
              if k.startswith(("data_huddle", "data_rep"))}
    write_twin(TwinRun(recordings=subset, truth=short_twin.truth, seed=short_twin.seed,
                       experiments=short_twin.experiments), data)
    return data


@pytest.fixture
def data_copy(stage_data: Path, tmp_path: Path) -> Path:
    """A private copy of :func:`stage_data` a test may damage."""
    copy = tmp_path / "data"
    shutil.copytree(stage_data, copy)
    return copy


@pytest.fixture
def old_run(tmp_path: Path, run_cli: Callable[..., Outcome]) -> Path:
    """A previous fsmbench run (``params --out``) a new run must replace or keep whole."""
    out = tmp_path / "out"
    assert run_cli("params", "--out", out).status == 0
    assert sorted(os.listdir(out)) == ["bench.toml", "run.json"]
    return out


@pytest.fixture(scope="session")
def kit() -> SimpleNamespace:
    """The helpers of this module: Outcome, hashes, leftovers, assert_one_line_verdict,
    cli_command, in_mount_namespace."""
    return SimpleNamespace(Outcome=Outcome, hashes=hashes, leftovers=leftovers,
                           assert_one_line_verdict=assert_one_line_verdict,
                           cli_command=cli_command, in_mount_namespace=in_mount_namespace)
