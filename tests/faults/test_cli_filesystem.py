"""Filesystem faults of ``--out``: one verdict line, status 2, checked before computing.

Each test makes the fault, runs the command and asserts: exit status 2, the
last line ``fsmbench <cmd>: error: <file>: <problem>`` naming the file and the
problem, no traceback, the output folder the complete old run (or absent),
nothing left behind (no hidden staging folder, no ``.part``), inputs unchanged.

Read-only and full filesystems are real where this process may mount a tmpfs
in a private mount namespace (root in a container: ``unshare -m``); they are
also simulated at the system-call wrapper (``os.mkdir`` raising errno 30,
``shutil.disk_usage`` reporting little space, ``os.fsync`` raising errno 28 as
a delayed-allocation write does), which needs no privilege: root ignores
permission bits, so ``chmod`` cannot make a folder read-only for the tests.
"""

from __future__ import annotations

import errno
import os
import shlex
from collections.abc import Callable
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pytest

SIM = ("--experiments", "data_cal_pd_h", "--duration", "3")


@pytest.fixture
def no_computation(monkeypatch: pytest.MonkeyPatch) -> list[str]:
    """Replace the twin's simulation by a recorder: the tests prove it never ran."""
    calls: list[str] = []

    def simulate_bench(*_args: Any, **_kwargs: Any) -> None:
        calls.append("simulate_bench")
        raise AssertionError("the computation started before the output folder was checked")

    monkeypatch.setattr("fsmbench.twin.simulate.simulate_bench", simulate_bench)
    return calls


def test_out_under_a_regular_file(kit: SimpleNamespace, tmp_path: Path, run_cli: Callable[..., Any],
                                  no_computation: list[str]) -> None:
    blocker = tmp_path / "notes.txt"
    blocker.write_text("mine\n")
    r = run_cli("simulate", blocker / "sub" / "out", *SIM)
    kit.assert_one_line_verdict(r, "simulate", str(blocker), "is a file, not a folder")
    assert blocker.read_text() == "mine\n" and no_computation == []
    assert kit.leftovers(tmp_path) == []


def test_out_is_a_file(kit: SimpleNamespace, tmp_path: Path, run_cli: Callable[..., Any],
                       no_computation: list[str]) -> None:
    out = tmp_path / "out"
    out.write_text("mine\n")
    r = run_cli("simulate", out, *SIM)
    kit.assert_one_line_verdict(r, "simulate", str(out), "exists and is a file")
    assert out.read_text() == "mine\n" and no_computation == []


def test_out_is_a_users_folder(kit: SimpleNamespace, tmp_path: Path, run_cli: Callable[..., Any],
                               no_computation: list[str]) -> None:
    out = tmp_path / "thesis"
    out.mkdir()
    (out / "chapter1.tex").write_text("text\n")
    before = kit.hashes(out)
    r = run_cli("params", "--out", out)
    kit.assert_one_line_verdict(r, "params", str(out), "holds no fsmbench run")
    assert kit.hashes(out) == before and list(before) == ["chapter1.tex"]


def test_a_foreign_file_in_a_previous_run_is_kept(kit: SimpleNamespace, old_run: Path,
                                                  run_cli: Callable[..., Any]) -> None:
    (old_run / "my_notes.txt").write_text("keep me\n")
    before = kit.hashes(old_run)
    r = run_cli("params", "--out", old_run)
    kit.assert_one_line_verdict(r, "params", str(old_run / "my_notes.txt"), "not part of")
    assert kit.hashes(old_run) == before


def test_out_must_not_contain_the_data(kit: SimpleNamespace, data_copy: Path,
                                       run_cli: Callable[..., Any]) -> None:
    before = kit.hashes(data_copy)
    r = run_cli("identify", data_copy, "--out", data_copy.parent)
    kit.assert_one_line_verdict(r, "identify", str(data_copy.parent), "contains the data folder")
    r = run_cli("identify", data_copy, "--out", data_copy / "out")
    kit.assert_one_line_verdict(r, "identify", "inside the data folder")
    assert kit.hashes(data_copy) == before


def test_a_new_run_replaces_a_previous_run_whole(kit: SimpleNamespace, old_run: Path,
                                                 run_cli: Callable[..., Any]) -> None:
    r = run_cli("simulate", old_run, *SIM)
    assert r.status == 0, r.err
    assert sorted(kit.hashes(old_run)) == ["data_cal_pd_h.mat", "run.json", "twin_truth.json"]
    assert kit.leftovers(old_run.parent) == []
    assert str(old_run / "data_cal_pd_h.mat") in r.out.splitlines()


def test_read_only_filesystem_simulated(kit: SimpleNamespace, tmp_path: Path,
                                        run_cli: Callable[..., Any],
                                        monkeypatch: pytest.MonkeyPatch,
                                        no_computation: list[str]) -> None:
    ro = tmp_path / "ro"
    ro.mkdir()
    real_mkdir = os.mkdir

    def mkdir(path: Any, *args: Any, **kwargs: Any) -> None:
        if Path(os.fsdecode(path)).resolve().is_relative_to(ro.resolve()):
            raise OSError(errno.EROFS, os.strerror(errno.EROFS), os.fsdecode(path))
        real_mkdir(path, *args, **kwargs)

    monkeypatch.setattr(os, "mkdir", mkdir)
    r = run_cli("simulate", ro / "out", *SIM)
    kit.assert_one_line_verdict(r, "simulate", str(ro), "Read-only file system")
    assert no_computation == [] and not (ro / "out").exists()


def test_read_only_filesystem_real(kit: SimpleNamespace, tmp_path: Path, can_mount: bool) -> None:
    if not can_mount:
        pytest.skip("no permission to mount a read-only tmpfs here")
    ro = tmp_path / "ro"
    ro.mkdir()
    cmd = shlex.join(kit.cli_command("params", "--out", ro / "out"))
    p = kit.in_mount_namespace(f"mount -t tmpfs -o ro,size=16m tmpfs {ro} && exec {cmd}")
    kit.assert_one_line_verdict(kit.Outcome(p.returncode, p.stdout, p.stderr), "params",
                                str(ro), "Read-only file system")
    assert p.stdout == ""  # refused before the table was computed and printed


def test_immutable_folder(kit: SimpleNamespace, old_run: Path, run_cli: Callable[..., Any],
                          can_chattr: bool, immutable: Callable[[Path], None],
                          no_computation: list[str]) -> None:
    if not can_chattr:
        pytest.skip("chattr +i is not available here")
    before = kit.hashes(old_run)
    immutable(old_run)
    r = run_cli("simulate", old_run, *SIM)
    kit.assert_one_line_verdict(r, "simulate", str(old_run), "cannot be replaced",
                            "Operation not permitted")
    assert kit.hashes(old_run) == before and no_computation == []
    assert kit.leftovers(old_run.parent) == []


def test_immutable_parent_folder(kit: SimpleNamespace, tmp_path: Path, run_cli: Callable[..., Any],
                                 can_chattr: bool, immutable: Callable[[Path], None],
                                 no_computation: list[str]) -> None:
    if not can_chattr:
        pytest.skip("chattr +i is not available here")
    parent = tmp_path / "locked"
    parent.mkdir()
    immutable(parent)
    r = run_cli("simulate", parent / "out", *SIM)
    kit.assert_one_line_verdict(r, "simulate", str(parent), "Operation not permitted")
    assert no_computation == [] and list(parent.iterdir()) == []


def test_full_disk_detected_before_computing(kit: SimpleNamespace, old_run: Path,
                                             run_cli: Callable[..., Any],
                                             monkeypatch: pytest.MonkeyPatch,
                                             no_computation: list[str]) -> None:
    import shutil

    real = shutil.disk_usage

    def disk_usage(path: Any) -> Any:
        return real(path)._replace(free=50_000)

    monkeypatch.setattr("fsmbench.io.outdir.shutil.disk_usage", disk_usage)
    before = kit.hashes(old_run)
    r = run_cli("simulate", old_run, *SIM)
    kit.assert_one_line_verdict(r, "simulate", str(old_run.parent), "only 50.0 kB free",
                            "writes about")
    assert kit.hashes(old_run) == before and no_computation == []


def test_full_disk_real(kit: SimpleNamespace, tmp_path: Path, can_mount: bool) -> None:
    if not can_mount:
        pytest.skip("no permission to mount a small tmpfs here")
    small = tmp_path / "small"
    small.mkdir()
    cmd = shlex.join(kit.cli_command("params", "--out", small / "out"))
    p = kit.in_mount_namespace(f"mount -t tmpfs -o size=256k tmpfs {small} && exec {cmd}")
    kit.assert_one_line_verdict(kit.Outcome(p.returncode, p.stdout, p.stderr), "params",
                                str(small), "only 262.1 kB free on this filesystem")
    assert p.stdout == ""


def test_disk_full_while_writing(kit: SimpleNamespace, old_run: Path, run_cli: Callable[..., Any],
                                 monkeypatch: pytest.MonkeyPatch) -> None:
    def fsync(_fd: int) -> None:
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(os, "fsync", fsync)
    before = kit.hashes(old_run)
    r = run_cli("simulate", old_run, *SIM)
    kit.assert_one_line_verdict(r, "simulate", str(old_run / "data_cal_pd_h.mat"),
                            "No space left on device")
    assert ".fsmbench-new-" not in r.err  # the final path, not the staging folder's
    assert kit.hashes(old_run) == before and kit.leftovers(old_run.parent) == []


def test_disk_filled_by_another_process_while_running(kit: SimpleNamespace, tmp_path: Path,
                                                      can_mount: bool) -> None:
    if not can_mount:
        pytest.skip("no permission to mount a small tmpfs here")
    small = tmp_path / "small"
    small.mkdir()
    # Between the pre-flight check and the writes, something else fills the disk.
    prelude = (
        "import shutil, fsmbench.twin.simulate as s\n"
        "real = s.simulate_bench\n"
        "def filled(*a, **k):\n"
        "    run = real(*a, **k)\n"
        f"    free = shutil.disk_usage({str(small)!r}).free\n"
        f"    open({str(small / 'filler')!r}, 'wb').write(b'x' * (free - 8192))\n"
        "    return run\n"
        "s.simulate_bench = filled\n")
    cmd = shlex.join(kit.cli_command("simulate", small / "out", *SIM, prelude=prelude))
    p = kit.in_mount_namespace(f"mount -t tmpfs -o size=2m tmpfs {small} && {cmd}; rc=$?; "
                               f"ls -A {small} >&2; exit $rc")
    lines = p.stderr.strip().splitlines()
    assert lines[-1] == "filler", p.stderr  # no output folder, staging folder or .part left
    kit.assert_one_line_verdict(kit.Outcome(p.returncode, p.stdout, "\n".join(lines[:-1])),
                                "simulate", str(small / "out"), "No space left on device")


def test_params_is_a_folder(kit: SimpleNamespace, tmp_path: Path,
                            run_cli: Callable[..., Any]) -> None:
    r = run_cli("params", "--params", tmp_path)
    kit.assert_one_line_verdict(r, "params", str(tmp_path), "is a folder", "TOML file")
    r = run_cli("simulate", tmp_path / "out", "--params", tmp_path, *SIM)
    kit.assert_one_line_verdict(r, "simulate", str(tmp_path), "is a folder")
    assert not (tmp_path / "out").exists()


def test_params_not_text(kit: SimpleNamespace, tmp_path: Path, run_cli: Callable[..., Any]) -> None:
    bad = tmp_path / "bench.toml"
    bad.write_bytes(b"\xff\xfe\x00binary")
    r = run_cli("params", "--params", bad)
    kit.assert_one_line_verdict(r, "params", str(bad), "not UTF-8")


@pytest.mark.parametrize("value", ["inf", "nan", "-inf", "0", "-3", "1e999", "fast"])
@pytest.mark.parametrize("command", ["simulate", "study"])
def test_duration_not_a_finite_positive_number(kit: SimpleNamespace, command: str, value: str,
                                               tmp_path: Path, run_cli: Callable[..., Any]) -> None:
    out = tmp_path / "out"
    argv = ("simulate", out) if command == "simulate" else ("study", "--out", out)
    r = run_cli(*argv, f"--duration={value}")
    kit.assert_one_line_verdict(r, command, "argument --duration", repr(value))
    assert len(r.err.strip().splitlines()) == 1 and not out.exists()


def test_data_is_a_file(kit: SimpleNamespace, tmp_path: Path, run_cli: Callable[..., Any]) -> None:
    f = tmp_path / "data_uch.mat"
    f.write_bytes(b"")
    r = run_cli("identify", f, "--out", tmp_path / "out")
    kit.assert_one_line_verdict(r, "identify", str(f), "DATA must be a folder")
    assert not (tmp_path / "out").exists()


def test_sigterm_handler_is_restored(kit: SimpleNamespace, run_cli: Callable[..., Any]) -> None:
    import signal

    before = signal.getsignal(signal.SIGTERM)
    assert run_cli("params").status == 0
    assert signal.getsignal(signal.SIGTERM) == before


def test_inputs_inside_out_are_refused(kit: SimpleNamespace, old_run: Path,
                                       run_cli: Callable[..., Any]) -> None:
    before = kit.hashes(old_run)
    r = run_cli("params", "--params", old_run / "bench.toml", "--out", old_run)
    kit.assert_one_line_verdict(r, "params", str(old_run / "bench.toml"),
                                "--params is inside --out")
    assert kit.hashes(old_run) == before


def test_out_is_the_current_folder(kit: SimpleNamespace, old_run: Path,
                                   run_cli: Callable[..., Any],
                                   monkeypatch: pytest.MonkeyPatch) -> None:
    before = kit.hashes(old_run)
    monkeypatch.chdir(old_run)
    r = run_cli("params", "--out", ".")
    kit.assert_one_line_verdict(r, "params", str(old_run), "is the current folder")
    assert kit.hashes(old_run) == before


def test_swap_without_renameat2(kit: SimpleNamespace, old_run: Path,
                                run_cli: Callable[..., Any],
                                monkeypatch: pytest.MonkeyPatch) -> None:
    # Filesystems or kernels without RENAME_EXCHANGE: two renames, signals held between.
    monkeypatch.setattr("fsmbench.io.outdir._exchange", lambda _a, _b: False)
    r = run_cli("simulate", old_run, *SIM)
    assert r.status == 0, r.err
    assert sorted(kit.hashes(old_run)) == ["data_cal_pd_h.mat", "run.json", "twin_truth.json"]
    assert kit.leftovers(old_run.parent) == []
