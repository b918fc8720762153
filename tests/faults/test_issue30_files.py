"""Files that cost nothing to refuse, through ``fsmbench identify`` (issue 30, item 7).

The thirteen twin records are stamped as a real-time target does (each ``t`` off its
grid by up to 50 ns), one record is followed by 20 GiB of zeros (a sparse hole), and
one has its ``fsmbench convert`` archive beside it. The identification must be the one
of the exact records, and ``identification.json`` must say what was found in each file.
"""

from __future__ import annotations

import json
import os
import shutil
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import scipy.io

from fsmbench.io.lazy import convert_recording

GIB = 1 << 30


def _stamped(src: Path, dst: Path) -> Path:
    """``src``'s records with ``t`` late by 0 to 50 ns each (uniform), same samples."""
    dst.mkdir()
    rng = np.random.default_rng(30)
    for path in sorted(src.glob("*.mat")):
        v = {k: x for k, x in scipy.io.loadmat(path).items() if not k.startswith("__")}
        t = v["t"].ravel()
        # Late only: a stamp never crosses the grid point before it, so the t-based trims
        # (t >= 1 s) keep the very samples they keep on the exact grid.
        v["t"] = (t + rng.uniform(0.0, 50e-9, t.size)).reshape(-1, 1)
        scipy.io.savemat(dst / path.name, v, do_compression=True)
    shutil.copy(src / "twin_truth.json", dst)
    return dst


def _uncertain(tree: Any, path: str = "") -> dict[str, tuple[float, float]]:
    """Every (value, std) of identification.json's uncertainty tree, by path."""
    if isinstance(tree, dict) and "value" in tree and "std" in tree:
        return {path: (float(tree["value"]), float(tree["std"]))}
    out: dict[str, tuple[float, float]] = {}
    for key, sub in (tree.items() if isinstance(tree, dict) else ()):
        out.update(_uncertain(sub, f"{path}/{key}"))
    return out


@pytest.fixture(scope="module")
def exact_identification(stage_data: Path, tmp_path_factory: pytest.TempPathFactory
                         ) -> dict[str, Any]:
    from fsmbench.cli import main

    out = tmp_path_factory.mktemp("exact") / "out"
    assert main(["identify", str(stage_data), "--out", str(out)]) == 0
    return dict(json.loads((out / "identification.json").read_text()))


def test_stamps_padding_and_a_copy_identify_as_the_exact_records(
        run_cli: Callable[..., Any], stage_data: Path, tmp_path: Path,
        exact_identification: dict[str, Any]) -> None:
    data = _stamped(stage_data, tmp_path / "data")
    convert_recording(data / "data_uch.mat", data / "data_uch.h5", created=0.0)
    size = (data / "data_ucv.mat").stat().st_size
    os.truncate(data / "data_ucv.mat", size + 20 * GIB)
    r = run_cli("identify", data, "--out", tmp_path / "out")
    assert r.status == 0, r.err
    # Before: "no recording in this folder can be used: …" (4 KB, every t refused).
    assert "note: data_uch.mat: read instead of data_uch.h5" in r.err
    got = json.loads((tmp_path / "out" / "identification.json").read_text())
    kinds: dict[str, list[str]] = {}
    for notice in got["notices"]:
        kinds.setdefault(notice["kind"], []).append(notice["subject"])
    assert kinds["file_choice"] == ["data_uch.mat"]
    assert kinds["trailing_bytes"] == ["data_ucv.mat"]
    assert set(kinds["time_jitter"]) == {f"{n}.mat: t" for n in (
        "data_cal_pd_h", "data_cal_pd_v", "data_uch", "data_ucv", "data_unh", "data_unv")}
    want, have = _uncertain(exact_identification["uncertainty"]), _uncertain(got["uncertainty"])
    assert set(have) == set(want) and "/sercalo/h/resonance_hz" in want
    for key, (value, std) in want.items():
        # The samples and the rate are the exact records'; t itself enters a few fits as a
        # regressor, where 50 ns stamps moved a value by at most 2e-5 of its std (measured).
        assert abs(have[key][0] - value) <= 1e-3 * std, key
