"""A folder whose every file fails in the same way: one line naming the files (issue 30).

Before, the thirteen files' problems were joined into one line of kilobytes.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import scipy.io

from fsmbench.io.errors import RecordingError
from fsmbench.io.folder import load_recordings
from fsmbench.io.signals import EXPERIMENTS

NAMES = [f"{name}.mat" for name in EXPERIMENTS]


def _refusal(folder: Path) -> str:
    with pytest.raises(RecordingError) as err:
        load_recordings(folder)
    text = str(err.value)
    assert "\n" not in text and len(text) < 1000, len(text)
    return text


def test_text_files_named_mat_are_one_phrase(tmp_path: Path) -> None:
    for name in NAMES:
        (tmp_path / name).write_text(f"{name} exported as text\n")
    text = _refusal(tmp_path)
    assert (f"is not a MAT-file (v4, v5/v7, v7.3) or HDF5 file in {len(NAMES)} files "
            f"({', '.join(NAMES)}); the first, {tmp_path / NAMES[0]}: is not a MAT-file") in text


def test_files_without_t_are_one_phrase(tmp_path: Path) -> None:
    for name in NAMES:
        scipy.io.savemat(tmp_path / name, {"x": np.zeros((10, 1))})
    text = _refusal(tmp_path)
    assert f"variable 't' is missing in {len(NAMES)} files ({', '.join(NAMES)})" in text


def test_different_problems_stay_apart(tmp_path: Path) -> None:
    (tmp_path / "data_uch.mat").write_text("text")
    (tmp_path / "data_ucv.mat").write_bytes(b"")
    text = _refusal(tmp_path)
    assert f"{tmp_path / 'data_uch.mat'}: is not a MAT-file" in text
    assert f"{tmp_path / 'data_ucv.mat'}: is empty (0 bytes)" in text
    assert " files (" not in text
