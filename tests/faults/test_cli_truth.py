"""A damaged optional ``twin_truth.json``: one line naming it, before anything is written."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pytest

from fsmbench.io.errors import RecordingError
from fsmbench.io.truth import read_twin_truth


def test_absent_truth_is_none(tmp_path: Path) -> None:
    assert read_twin_truth(tmp_path) is None
    assert read_twin_truth(tmp_path / "twin_truth.json") is None


def test_valid_truth_reads_back(stage_data: Path) -> None:
    truth = read_twin_truth(stage_data)
    assert truth == json.loads((stage_data / "twin_truth.json").read_text())
    assert truth is not None and truth["seed"] == 1


@pytest.mark.parametrize(("damage", "problem"), [
    (lambda text: text[: len(text) // 2], "the file is truncated"),
    (lambda text: "", "the file is truncated"),
    (lambda text: "[1, 2]", "holds a JSON list, not an object"),
    (lambda text: text.replace(":", "=", 1), "is not valid JSON"),
])
def test_damaged_truth_names_the_file(tmp_path: Path, stage_data: Path,
                                      damage: Callable[[str], str], problem: str) -> None:
    path = tmp_path / "twin_truth.json"
    path.write_text(damage((stage_data / "twin_truth.json").read_text()))
    with pytest.raises(RecordingError) as info:
        read_twin_truth(path)
    assert str(info.value).startswith(f"{path}: ") and problem in str(info.value)


def test_truth_not_utf8(tmp_path: Path) -> None:
    path = tmp_path / "twin_truth.json"
    path.write_bytes(b'{"seed": "\xff"}')
    with pytest.raises(RecordingError, match="not UTF-8"):
        read_twin_truth(path)


def _truncate(data: Path) -> Path:
    path = data / "twin_truth.json"
    text = path.read_text()
    path.write_text(text[: len(text) // 2])
    return path


@pytest.mark.parametrize("command", ["identify", "study"])
def test_truncated_truth_stops_the_command_cleanly(
        kit: SimpleNamespace, data_copy: Path, run_cli: Callable[..., Any], command: str
        ) -> None:
    truth = _truncate(data_copy)
    before = kit.hashes(data_copy)
    out = data_copy.parent / "out"
    argv = ("identify", data_copy) if command == "identify" else ("study", "--data", data_copy)
    r = run_cli(*argv, "--out", out)
    kit.assert_one_line_verdict(r, command, str(truth), "is not valid JSON", "truncated")
    assert not out.exists()  # nothing written: no outputs of a run that failed
    assert kit.leftovers(data_copy.parent) == []
    assert kit.hashes(data_copy) == before
