"""Ctrl-C (SIGINT) and SIGTERM mid-run, and the exception boundary of ``fsmbench``.

The signal tests run ``fsmbench simulate`` in a separate process over a
previous run, wait until it is computing or has written its first file into
the staging folder (a hook in the child creates a marker file there and
sleeps, to hold the run at that point), send the signal, and check: exit
status 130 (SIGINT) or 143 (SIGTERM), one verdict line, no traceback, the
output folder byte for byte the previous run, nothing left beside it.
"""

from __future__ import annotations

import os
import signal
import subprocess
import time
from collections.abc import Callable
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest

from fsmbench import __version__

# The child holds still at the chosen point (marker written, then a long sleep);
# the parent signals it as soon as the marker exists. 60 s only bounds a hang.
HOLD = """
import pathlib, signal, time
import fsmbench.twin.simulate as s
# Ctrl-C as a terminal delivers it to a foreground process: a test runner may hand its
# children SIGINT ignored (a background job) or blocked (a mask inherited from a thread).
signal.signal(signal.SIGINT, signal.default_int_handler)
signal.pthread_sigmask(signal.SIG_UNBLOCK, {{signal.SIGINT, signal.SIGTERM}})
MARK = pathlib.Path({mark!r})
def hold():
    MARK.write_text("ready")
    time.sleep(60)
if {phase!r} == "computing":
    def simulate_bench(*a, **k):
        hold()
    s.simulate_bench = simulate_bench
else:
    real = s.write_recording
    def write_recording(ds, path, **k):
        real(ds, path, **k)
        hold()
    s.write_recording = write_recording
"""


@pytest.mark.parametrize("phase", ["computing", "writing"])
@pytest.mark.parametrize(("signum", "status", "word"), [
    (signal.SIGINT, 130, "interrupted (Ctrl-C)"),
    (signal.SIGTERM, 143, "terminated (SIGTERM)"),
])
def test_signal_mid_run_keeps_the_old_run(kit: SimpleNamespace, old_run: Path, tmp_path: Path,
                                          signum: int, status: int, word: str,
                                          phase: str) -> None:
    before = kit.hashes(old_run)
    mark = tmp_path / "ready"
    argv = kit.cli_command("simulate", old_run, "--experiments", "data_cal_pd_h",
                           "data_cal_pd_v", "--duration", "3",
                           prelude=HOLD.format(mark=str(mark), phase=phase))
    child = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 120  # bounds a hang only (the machine may be loaded)
        while not mark.exists() and child.poll() is None and time.monotonic() < deadline:
            time.sleep(0.05)
        assert mark.exists(), child.communicate()[1]
        staging = [p for p in old_run.parent.iterdir() if ".fsmbench-new-" in p.name]
        assert len(staging) == 1  # the run is under way in its staging folder
        if phase == "writing":
            assert (staging[0] / "data_cal_pd_h.mat").is_file()
        child.send_signal(signum)
        out, err = child.communicate(timeout=120)
    finally:
        if child.poll() is None:
            child.kill()
    kit.assert_one_line_verdict(kit.Outcome(child.returncode, out, err), "simulate",
                                str(old_run), word, "left as it was", status=status)
    assert kit.hashes(old_run) == before
    assert kit.leftovers(old_run.parent) == []


def test_ctrl_c_in_process(kit: SimpleNamespace, old_run: Path, run_cli: Callable[..., Any],
                           monkeypatch: pytest.MonkeyPatch) -> None:
    def simulate_bench(*_a: Any, **_k: Any) -> None:
        raise KeyboardInterrupt

    monkeypatch.setattr("fsmbench.twin.simulate.simulate_bench", simulate_bench)
    before = kit.hashes(old_run)
    r = run_cli("simulate", old_run, "--duration", "3")
    kit.assert_one_line_verdict(r, "simulate", str(old_run), "interrupted", status=130)
    assert kit.hashes(old_run) == before and kit.leftovers(old_run.parent) == []


@pytest.mark.parametrize("error", [ZeroDivisionError("division by zero"), "numpy"])
def test_a_bug_shows_the_traceback_and_asks_for_a_report(
        kit: SimpleNamespace, old_run: Path, run_cli: Callable[..., Any],
        monkeypatch: pytest.MonkeyPatch, error: Any) -> None:
    def simulate_bench(*_a: Any, **_k: Any) -> None:
        if error == "numpy":
            np.zeros(3).reshape(2, 2)  # a ValueError raised inside numpy: a bug, not a verdict
        raise error

    monkeypatch.setattr("fsmbench.twin.simulate.simulate_bench", simulate_bench)
    before = kit.hashes(old_run)
    r = run_cli("simulate", old_run, "--duration", "3")
    assert r.status == 1
    assert "Traceback (most recent call last)" in r.err
    last = r.err.strip().splitlines()[-1]
    assert last.startswith("fsmbench simulate: internal error") and "please report it" in last
    assert f"fsmbench {__version__}" in last
    assert kit.hashes(old_run) == before and kit.leftovers(old_run.parent) == []


def test_fsmbench_own_value_error_is_a_verdict(kit: SimpleNamespace, tmp_path: Path,
                                              run_cli: Callable[..., Any]) -> None:
    r = run_cli("simulate", tmp_path / "out", "--duration", "1")
    kit.assert_one_line_verdict(r, "simulate", "--duration 1 s is too short")
    assert not (tmp_path / "out").exists() and kit.leftovers(tmp_path) == []


def test_sigkill_leftovers_are_removed_by_the_next_run(kit: SimpleNamespace, old_run: Path,
                                                       tmp_path: Path) -> None:
    # SIGKILL cannot be caught: the killed run's staging folder stays beside --out. The
    # next run into the same --out removes it, but never a live run's.
    mark = tmp_path / "ready"
    argv = kit.cli_command("simulate", old_run, "--experiments", "data_cal_pd_h",
                           "--duration", "3",
                           prelude=HOLD.format(mark=str(mark), phase="writing"))
    child = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 120  # bounds a hang only
        while not mark.exists() and child.poll() is None and time.monotonic() < deadline:
            time.sleep(0.05)
        assert mark.exists(), child.communicate()[1]
        child.kill()
        child.communicate(timeout=60)
    finally:
        if child.poll() is None:
            child.kill()
    killed = [p for p in old_run.parent.iterdir() if ".fsmbench-new-" in p.name]
    assert len(killed) == 1 and f"-new-{child.pid}-" in killed[0].name
    live = old_run.parent / f".{old_run.name}.fsmbench-new-{os.getpid()}-live"
    live.mkdir()  # a run under way in this very process: must be kept
    argv = kit.cli_command("simulate", old_run, "--experiments", "data_cal_pd_h",
                           "--duration", "3")
    done = subprocess.run(argv, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert not killed[0].exists() and live.is_dir()
    assert sorted(kit.hashes(old_run)) == ["data_cal_pd_h.mat", "run.json", "twin_truth.json"]
    live.rmdir()
    assert kit.leftovers(old_run.parent) == []
