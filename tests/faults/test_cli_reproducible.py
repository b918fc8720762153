"""Same inputs and ``--seed`` → byte-identical files, for every command.

Each command runs twice into two different folders (and the study once more
through the library, the session's ``twin_study``); every file is compared by
sha256, except those ``run.json`` lists as not reproducible (``timings.json``,
wall times). ``run.json`` itself is compared too: it holds no path of the
output folder and no time. No file may mention the hidden staging folder the
run was written in.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pytest
import scipy.io

SIM = ("--experiments", "data_cal_pd_h", "data_uch", "--duration", "3", "--seed", "4")


def _reproducible(kit: SimpleNamespace, out: Path) -> dict[str, str]:
    """Hashes of the run's files, minus those run.json lists as not reproducible."""
    manifest = json.loads((out / "run.json").read_text())
    listed = {f["path"]: f["sha256"] for f in manifest["files"]}
    found = kit.hashes(out)
    assert {k: v for k, v in found.items() if k != "run.json"} == listed  # manifest is exact
    assert set(manifest["not_reproducible"]) <= {"timings.json"}
    for path in out.rglob("*"):
        if path.is_file():
            assert b".fsmbench-new-" not in path.read_bytes(), path
    return {k: v for k, v in found.items() if k not in manifest["not_reproducible"]}


def _twice(kit: SimpleNamespace, run_cli: Callable[..., Any], tmp_path: Path,
           make_argv: Callable[[Path], tuple[Any, ...]]) -> tuple[dict[str, str], Any]:
    runs = []
    for name in ("a", "b"):
        out = tmp_path / name / "run"
        r = run_cli(*make_argv(out))
        assert r.status == 0, r.err
        runs.append((_reproducible(kit, out), r))
    assert runs[0][0] == runs[1][0]
    return runs[0]


def test_params(kit: SimpleNamespace, run_cli: Callable[..., Any], tmp_path: Path) -> None:
    files, _ = _twice(kit, run_cli, tmp_path, lambda out: ("params", "--out", out))
    assert sorted(files) == ["bench.toml", "run.json"]


@pytest.mark.parametrize("fmt", ["mat5", "mat73", "nexus"])
def test_simulate(kit: SimpleNamespace, run_cli: Callable[..., Any], tmp_path: Path,
                  fmt: str) -> None:
    files, r = _twice(kit, run_cli, tmp_path, lambda out: ("simulate", out, *SIM,
                                                            "--format", fmt))
    suffix = ".h5" if fmt == "nexus" else ".mat"
    assert sorted(files) == sorted([f"data_cal_pd_h{suffix}", f"data_uch{suffix}", "run.json",
                                    "twin_truth.json"])
    assert str(tmp_path / "a" / "run" / f"data_uch{suffix}") in r.out.splitlines()


def test_identify(kit: SimpleNamespace, run_cli: Callable[..., Any], tmp_path: Path,
                  stage_data: Path) -> None:
    files, r = _twice(kit, run_cli, tmp_path, lambda out: ("identify", stage_data,
                                                            "--out", out))
    assert {"identification.json", "plant.mat", "frf.mat", "run.json"} <= set(files)
    # Files on stderr, the readable table of what was identified on stdout.
    assert f"wrote {tmp_path / 'a' / 'run' / 'plant.mat'}" in r.err.splitlines()
    assert r.out.splitlines()[0].split()[:2] == ["quantity", "identified"]


def test_budget(kit: SimpleNamespace, run_cli: Callable[..., Any], tmp_path: Path,
                huddle_data: Path) -> None:
    files, r = _twice(kit, run_cli, tmp_path, lambda out: ("budget", huddle_data,
                                                            "--out", out))
    assert sorted(files) == ["budget.json", "run.json"]
    # The result on stdout, what the stage could not use on stderr.
    assert "limiting source" in r.out and "nominal physical model" in r.err
    assert json.loads((tmp_path / "a" / "run" / "budget.json").read_text()
                      )["budget"]["total_rms_m"] > 0


def test_design(kit: SimpleNamespace, run_cli: Callable[..., Any], tmp_path: Path,
                huddle_data: Path) -> None:
    files, r = _twice(kit, run_cli, tmp_path, lambda out: ("design", huddle_data, "--out", out,
                                                            "--seed", "3"))
    assert {"controllers.mat", "controllers_sos.json", "design.json", "run.json"} <= set(files)
    rows = [line.split() for line in r.out.splitlines()
            if line.startswith(("fsmbench's controller  ", "fsmbench's controller h",
                                "fsmbench's controller v"))]
    assert [(row[2], row[3], row[-1]) for row in rows] == [("h", "yes", "met"), ("v", "yes", "met")]
    # Without identification experiments the data's bench is unknown: no simulation claimed.
    assert "fsmbench's controller not simulated: no identification ran" in r.out
    controllers = scipy.io.loadmat(tmp_path / "a" / "run" / "controllers.mat",
                                   simplify_cells=True)
    k = controllers["fsmbench_controller"]
    assert list(k["K"]["InputName"]) == ["Rh", "Rv"] and k["Kd"]["Ts"] == pytest.approx(1e-4)
    # --json: design.json as written on stdout, the files on stderr.
    out = tmp_path / "json"
    r = run_cli("design", huddle_data, "--out", out, "--seed", "3", "--json")
    assert r.status == 0, r.err
    assert r.out == (out / "design.json").read_text(encoding="utf-8")
    assert f"wrote {out / 'design.json'}" in r.err.splitlines()


def test_study_cli_equals_the_library_run(kit: SimpleNamespace, run_cli: Callable[..., Any],
                                          tmp_path: Path, twin_study: Any) -> None:
    """``study --duration 5`` (random seed 0) writes the same bytes as ``run_study`` did."""
    out = tmp_path / "study"
    r = run_cli("study", "--out", out, "--duration", "5", "--json")
    assert r.status == 0, r.err
    files = _reproducible(kit, out)
    library = kit.hashes(Path(twin_study.out_dir))
    assert (out / "timings.json").is_file() and "timings.json" not in files
    assert {k: v for k, v in files.items() if k != "run.json"} == {
        k: v for k, v in library.items() if k != "timings.json"}
    assert any(k.startswith("twin-data/") for k in files)
    # --json: the verdict's document (summary.json, as written) on stdout, the report's
    # path with the progress on stderr.
    assert r.out == (out / "summary.json").read_text(encoding="utf-8")
    assert json.loads(r.out)["format"] == "fsmbench.summary"
    assert f"wrote {out / 'report.html'}" in r.err.splitlines()


def test_timestamp_puts_the_wall_clock_in_headers(run_cli: Callable[..., Any],
                                                  tmp_path: Path) -> None:
    year = time.gmtime().tm_year
    plain, stamped = tmp_path / "plain", tmp_path / "stamped"
    assert run_cli("params", "--out", plain).status == 0
    assert run_cli("params", "--out", stamped, "--timestamp").status == 0
    assert "created_utc" not in json.loads((plain / "run.json").read_text())
    assert json.loads((stamped / "run.json").read_text())["created_utc"].startswith(str(year))

    from fsmbench.io.matwrite import save_mat, wall_clock_headers

    fixed = save_mat(tmp_path / "fixed.mat", {"x": 1.0}).read_bytes()[:116]
    with wall_clock_headers(True):
        now = save_mat(tmp_path / "now.mat", {"x": 1.0}).read_bytes()[:116]
    assert b"Created on: Thu Jan 01 00:00:00 1970" in fixed
    assert str(year).encode() in now and b"1970" not in now
