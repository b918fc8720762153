"""Atomic writes: complete file or none, never a half-written one."""

from __future__ import annotations

import os
import stat
from pathlib import Path

import pytest

from fsmbench.atomic import atomic_path, atomic_write_bytes, atomic_write_text


def test_interrupted_write_leaves_the_old_file_and_no_temporary(tmp_path: Path) -> None:
    dest = atomic_write_text(tmp_path / "out.json", "old\n")
    with pytest.raises(KeyboardInterrupt), atomic_path(dest) as tmp:
        tmp.write_text("half of the new")
        raise KeyboardInterrupt  # what Ctrl-C raises mid-write
    assert dest.read_text() == "old\n"
    assert [p.name for p in tmp_path.iterdir()] == ["out.json"]


def test_new_file_gets_the_umask_mode(tmp_path: Path) -> None:
    old = os.umask(0o027)
    try:
        dest = atomic_write_bytes(tmp_path / "x.bin", b"abc")
    finally:
        os.umask(old)
    assert stat.S_IMODE(dest.stat().st_mode) == 0o640  # 0666 & ~0027, as open() would
    assert dest.read_bytes() == b"abc"


def test_missing_folder_is_named(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match=r"output folder .*nope does not exist"):
        atomic_write_text(tmp_path / "nope" / "x.txt", "x")
