"""``--identification DIR``: plant.mat read back, and bad folders as one line."""

from __future__ import annotations

import json
import shutil
from collections.abc import Callable
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest

from fsmbench.bench.blocks import PlantModel
from fsmbench.ident.export import write_plant_mat
from fsmbench.ident.load import BLOCK_NAMES, load_identified_plant, read_plant_mat
from fsmbench.io.errors import RecordingError
from fsmbench.io.matwrite import save_mat


def _max_relative_error(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.max(np.abs(a - b)) / np.max(np.abs(a)))


@pytest.mark.parametrize("which", ["true_plant", "nominal_plant"])
def test_plant_mat_round_trip(which: str, request: pytest.FixtureRequest,
                              tmp_path: Path) -> None:
    plant: PlantModel = request.getfixturevalue(which)
    loaded = read_plant_mat(write_plant_mat(tmp_path / "plant.mat", plant))
    f = np.logspace(-1, np.log10(5000.0), 400)
    # 1e-12: the MAT-file stores the float64 matrices exactly; only the order of
    # the floating-point operations of the two evaluations may differ.
    assert _max_relative_error(plant.frequency_response(f).values,
                               loaded.frequency_response(f).values) < 1e-12
    assert dict(loaded.input_delay_s) == pytest.approx(dict(plant.input_delay_s), rel=0, abs=0)
    for name in BLOCK_NAMES:
        a = plant.blocks[name]
        b = loaded.blocks[name]
        assert list(b.input_labels) == list(a.input_labels)
        assert list(b.output_labels) == list(a.output_labels)
        ha = np.stack([np.asarray(a(2j * np.pi * x)).reshape(a.noutputs, a.ninputs) for x in f])
        hb = np.stack([np.asarray(b(2j * np.pi * x)).reshape(b.noutputs, b.ninputs) for x in f])
        assert _max_relative_error(ha, hb) < 1e-12  # same reason as above
    assert loaded.source == plant.source


@pytest.fixture
def ident_dir(tmp_path: Path, true_plant: PlantModel) -> Path:
    """A folder shaped like ``fsmbench identify`` output: identification.json, plant.mat."""
    d = tmp_path / "ident"
    d.mkdir()
    write_plant_mat(d / "plant.mat", true_plant)
    (d / "identification.json").write_text(json.dumps(
        {"source": "test", "sercalo": {}, "diagnostics": {"warnings": []}}))
    return d


def test_load_identified_plant(ident_dir: Path, true_plant: PlantModel) -> None:
    choice = load_identified_plant(ident_dir)
    assert choice.source == f"identified (from {ident_dir / 'identification.json'})"
    assert choice.identification is None
    f = np.array([1.0, 100.0, 411.0])
    assert _max_relative_error(true_plant.frequency_response(f).values,
                               choice.plant.frequency_response(f).values) < 1e-12  # as above


def _damage_json(d: Path, text: str) -> None:
    (d / "identification.json").write_text(text)


@pytest.mark.parametrize(("damage", "file", "problem"), [
    (lambda d: shutil.rmtree(d), ".", "does not exist"),
    (lambda d: (d / "plant.mat").unlink(), "plant.mat", "does not exist"),
    (lambda d: (d / "identification.json").unlink(), "identification.json", "does not exist"),
    (lambda d: _damage_json(d, '{"sercalo": '), "identification.json", "is not valid JSON"),
    (lambda d: _damage_json(d, '{"source": "x"}'), "identification.json",
     "has no identified Sercalo"),
    (lambda d: _damage_json(d, '{"sercalo": {}, "diagnostics": {"warnings": ["bad fit"]}}'),
     "identification.json", "raised warnings (bad fit)"),
    (lambda d: (d / "plant.mat").write_bytes(b"not a mat file"), "plant.mat",
     "not a readable MAT-file"),
    (lambda d: save_mat(d / "plant.mat", {"sys": {"A": 1.0}}), "plant.mat",
     "lacks the variable(s) Gi"),
])
def test_bad_identification_folder(ident_dir: Path, damage: Callable[[Path], object],
                                   file: str, problem: str) -> None:
    damage(ident_dir)
    with pytest.raises(RecordingError) as info:
        load_identified_plant(ident_dir)
    expected = ident_dir if file == "." else ident_dir / file
    assert str(info.value).startswith(f"{expected}: ") and problem in str(info.value)


def test_plant_mat_with_nan(ident_dir: Path, true_plant: PlantModel) -> None:
    from fsmbench.ident.export import plant_variables

    variables = plant_variables(true_plant)
    variables["sys"]["A"] = np.full_like(variables["sys"]["A"], np.nan)
    save_mat(ident_dir / "plant.mat", variables)
    with pytest.raises(RecordingError, match=r"variable 'sys\.A' holds NaN or Inf"):
        load_identified_plant(ident_dir)


@pytest.mark.parametrize("command", ["budget", "design"])
def test_commands_refuse_a_bad_identification_in_one_line(
        kit: SimpleNamespace, command: str, stage_data: Path, ident_dir: Path,
        run_cli: Callable[..., Any]) -> None:
    (ident_dir / "plant.mat").unlink()
    before = kit.hashes(stage_data)
    out = ident_dir.parent / "out"
    r = run_cli(command, stage_data, "--out", out, "--identification", ident_dir)
    kit.assert_one_line_verdict(r, command, str(ident_dir / "plant.mat"), "does not exist")
    assert "reading" not in r.err  # refused before reading the recordings
    assert not out.exists() and kit.hashes(stage_data) == before


def test_budget_reuses_an_identification(kit: SimpleNamespace, stage_data: Path,
                                         ident_dir: Path, run_cli: Callable[..., Any]) -> None:
    out = ident_dir.parent / "budget"
    r = run_cli("budget", stage_data, "--out", out, "--identification", ident_dir)
    assert r.status == 0, r.err
    source = f"identified (from {ident_dir / 'identification.json'})"
    assert f"plant: {source}" in r.err and "identifying the plant first" not in r.err
    assert json.loads((out / "budget.json").read_text())["plant_source"] == source


def test_design_prints_rounded_values_with_units() -> None:
    from fsmbench.report.text import design_table

    axis = {"gain_margin_db": 14.467792213829014, "phase_margin_deg": 52.74239733270343,
            "crossover_hz": 36.90111458340814, "sensitivity_at_1hz": 0.00011787110436707398,
            "stable": True}
    loop = {"h": axis, "v": {**axis, "gain_margin_db": float("inf"),
                             "phase_margin_deg": None, "sensitivity_at_1hz": 3e-4}}
    lines = design_table({"objective": {"sensitivity_bound_at_1hz": 2e-4},
                          "fsmbench_controller": loop, "newport_controller": loop,
                          "closed_loop_twin": None, "closed_loop_skipped": "no bench"})
    rows = [line.split() for line in lines[1:5]]
    # Rounded values with their units; the objective only where it applies (the Sercalo loop).
    assert rows[0][2:] == ["h", "yes", "14.5", "dB", "52.7°", "36.9", "Hz", "1.18e-04", "met"]
    assert rows[1][2:] == ["v", "yes", "∞", "none", "36.9", "Hz", "3.00e-04", "missed"]
    assert rows[2][-1] == "–" and rows[3][-1] == "–"
    assert lines[-1] == "fsmbench's controller not simulated: no bench"


def test_a_step_the_estimator_cannot_do_says_the_fix(run_cli: Callable[..., Any],
                                                     data_copy: Path, tmp_path: Path) -> None:
    """``--frf periodic`` on records whose input does not repeat (the twin's noise): the
    table names the step in words, why, and the option that identifies it."""
    r = run_cli("identify", data_copy, "--out", tmp_path / "out", "--frf", "periodic")
    assert r.status == 0, r.err
    lines = [x for x in r.out.splitlines() if x.startswith("not identified: Newport (2.4)")]
    assert len(lines) == 1 and "is not periodic" in lines[0]
    assert lines[0].endswith("run identify with --frf auto (periods averaged where the input "
                             "repeats, the LPM elsewhere)")


def test_an_unreadable_file_is_named_not_called_missing(run_cli: Callable[..., Any],
                                                        data_copy: Path, tmp_path: Path) -> None:
    """A truncated data_uch.mat: the steps it feeds say the file was not used and why
    (to correct it or record it again), never "missing ... record data_uch"."""
    path = data_copy / "data_uch.mat"
    path.write_bytes(path.read_bytes()[:5000])
    r = run_cli("identify", data_copy, "--out", tmp_path / "out")
    assert r.status == 0, r.err
    lines = [x for x in r.out.splitlines() if x.startswith("not identified: current amplifiers")]
    assert len(lines) == 1, r.out
    assert "data_uch was not used (" in lines[0] and "data_uch.mat" in lines[0]
    assert lines[0].endswith("correct it or record it again") and "missing" not in lines[0]
