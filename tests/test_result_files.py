"""What the commands write is what docs/results.md promises a script.

On the twin study's folder (``twin_study``) and the stage commands run on its recordings
(``identify``, ``budget --bench``, ``excite``, ``simulate --excitation``, ``montecarlo``,
``params``, ``params --json``): every JSON file starts with ``format`` then ``format_version``;
``identify --json`` gives its targets as numbers; the study and ``identify`` + ``budget
--bench`` give the same budget on the same recordings; the doc's Python examples run on
the study's files.
"""

from __future__ import annotations

import contextlib
import io
import json
import math
import os
import re
from pathlib import Path
from typing import Any

import pytest

from fsmbench.cli import main
from fsmbench.study import StudyResult

DOC = Path(__file__).resolve().parents[1] / "docs" / "results.md"


@pytest.fixture(scope="module")
def runs(twin_study: StudyResult, tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """The stage commands on the study's twin records (5 s each), each in its folder."""
    root = tmp_path_factory.mktemp("result-files")
    study = Path(twin_study.out_dir)
    data = str(study / "twin-data")
    # design's files are the study's (design.json, controllers_sos.json): not run again.
    folders = {name: root / name for name in ("identify", "budget", "excite", "simulate",
                                              "montecarlo", "params")}
    out = {k: str(v) for k, v in folders.items()}
    stdout = io.StringIO()
    with contextlib.redirect_stdout(stdout):
        assert main(["identify", data, "--out", out["identify"], "--json"]) == 0
    # What identify --json prints is a document too: kept as a file to be walked.
    (root / "identify_stdout.json").write_text(stdout.getvalue())
    stdout = io.StringIO()
    with contextlib.redirect_stdout(stdout):
        assert main(["params", "--json"]) == 0
    (root / "params_stdout.json").write_text(stdout.getvalue())
    stdout = io.StringIO()
    with contextlib.redirect_stdout(stdout):
        assert main(["budget", data, "--bench", out["identify"], "--out", out["budget"],
                     "--json"]) == 0
    # budget --json prints budget.json as written.
    assert stdout.getvalue() == (folders["budget"] / "budget.json").read_text(encoding="utf-8")
    commands = [
        ["excite", out["excite"], "--input", "Uch", "--amplitude-rms", "0.015", "--band", "1",
         "200"],
        ["simulate", out["simulate"], "--excitation", out["excite"], "--duration", "5"],
        ["montecarlo", "--twin", "--out", out["montecarlo"], "--n", "2", "--workers", "1",
         "--duration", "4.5", "--settle", "2"],
        ["params", "--out", out["params"]],
    ]
    for args in commands:
        with contextlib.redirect_stdout(io.StringIO()):
            assert main(args) == 0, args
    return {"study": study, "root": root, **folders}


def _json_files(runs: dict[str, Path]) -> list[Path]:
    return sorted({*runs["study"].rglob("*.json"), *runs["root"].rglob("*.json")})


def test_every_json_written_starts_with_format_then_version(runs: dict[str, Path]) -> None:
    files = _json_files(runs)
    names = {p.name for p in files}
    # The commands' own files are among those walked (the walk found the folders).
    assert {"identification.json", "budget.json", "design.json", "controllers_sos.json",
            "summary.json", "study.json", "timings.json", "run.json", "twin_truth.json",
            "excitation.json", "montecarlo.json", "identify_stdout.json",
            "params_stdout.json"} <= names, names
    bad = []
    for path in files:
        doc = json.loads(path.read_text(encoding="utf-8"))
        keys = list(doc) if isinstance(doc, dict) else []
        ok = (keys[:2] == ["format", "format_version"]
              and str(doc["format"]).startswith("fsmbench.")
              and type(doc["format_version"]) is int and doc["format_version"] >= 1)
        if not ok:
            bad.append(f"{path.relative_to(path.parents[1])}: {keys[:3]}")
    assert bad == []


def test_identify_json_gives_targets_as_numbers(runs: dict[str, Path]) -> None:
    doc = json.loads((runs["root"] / "identify_stdout.json").read_text())
    assert (doc["format"], doc["format_version"]) == ("fsmbench.identify_comparison", 2)
    assert doc["reference"] == "true" and doc["rows"]  # the twin: its truth is the reference
    for row in doc["rows"]:
        relative, absolute = row["target_relative"], row["target_abs"]
        assert (relative is None) != (absolute is None), row  # one kind of target per key
        target = relative if relative is not None else absolute
        assert isinstance(target, float) and target > 0, row
        # Judged against the truth: a boolean, the same as the numbers say.
        err = (abs(row["relative_difference"]) if relative is not None
               else abs(row["identified"] - row["reference"]))
        assert row["within_target"] is (err <= target), row
        assert row["within_target_reason"] == ""
        if row["target_samples"] is not None:  # one sample at the twin's 10 kHz
            assert absolute == pytest.approx(row["target_samples"] / 1e4, rel=1e-12)


def test_against_the_bench_file_a_target_is_not_judged_and_says_why(bench: Any) -> None:
    from fsmbench.twin.compare import comparison_json
    from fsmbench.twin.truth import model_values

    doc = comparison_json(model_values(bench.true), reference=None, bench=bench)
    assert doc["reference"] == "nominal" and doc["rows"]
    for row in doc["rows"]:
        assert row["within_target"] is None and "bench file" in row["within_target_reason"]
        assert isinstance(row["target_relative"] or row["target_abs"], float)


def test_study_and_stage_commands_give_the_same_budget(runs: dict[str, Path]) -> None:
    study = json.loads((runs["study"] / "budget.json").read_text())
    stage = json.loads((runs["budget"] / "budget.json").read_text())
    ident_study = json.loads((runs["study"] / "identification.json").read_text())
    ident_stage = json.loads((runs["identify"] / "identification.json").read_text())
    # Same recordings, same identification: the budget's inputs are the same numbers ...
    assert ident_stage["noise_model"] == ident_study["noise_model"]
    assert ident_stage["sercalo"] == ident_study["sercalo"]
    # ... so budget --bench uses the measured noise and the recorded loop's gains as the
    # study does (it used the bench file's: 2.24 against 2.19 nm on the records).
    # Same arithmetic on the same numbers: equal to rounding.
    assert stage["budget"]["total_rms_m"] == pytest.approx(study["budget"]["total_rms_m"],
                                                           rel=1e-9)
    assert stage["controller"] == study["controller"]
    rows = {r["id"]: r["provenance"] for r in stage["budget"]["rows"]}
    assert rows == {r["id"]: r["provenance"] for r in study["budget"]["rows"]}
    # The one difference, stated: the study also quotes fsmbench's controller.
    assert study["recommended"] is not None and "recommended_skipped" not in study
    assert stage["recommended"] is None and "study's verdict" in stage["recommended_skipped"]
    summary = json.loads((runs["study"] / "summary.json").read_text())
    row = {r["name"]: r for r in summary["requirements"]}["distance_error_budget"]
    assert row["values"]["total"] == study["recommended"]["budget"]["total_rms_m"]


def test_summary_values_are_in_the_unit_of_their_limits(runs: dict[str, Path]) -> None:
    summary = json.loads((runs["study"] / "summary.json").read_text())
    design = json.loads((runs["study"] / "design.json").read_text())
    by = {r["name"]: r for r in summary["requirements"]}
    row = by["closed_loop_simulation"]
    assert (row["quantity"], row["unit"]) == ("simulated_over_predicted", "1")
    twin = design["closed_loop_twin"]
    assert row["values"] == twin["measured_over_predicted"]
    assert row["other_values"]["simulated_rms_rad"] == twin["tracking_error_rms_rad"]
    for req in summary["requirements"]:
        assert req["quantity"] and req["unit"], req["name"]
        assert all(v is None or isinstance(v, float) for v in req["values"].values())
        assert set(req["limits"]) <= {"min", "max"}


def _python_blocks(text: str) -> list[str]:
    return re.findall(r"```python\n(.*?)```", text, flags=re.DOTALL)


def test_the_docs_python_examples_run_on_the_files(runs: dict[str, Path], tmp_path: Path,
                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    blocks = _python_blocks(DOC.read_text(encoding="utf-8"))
    assert len(blocks) >= 3
    # The doc names the study's output folder OUT.
    os.symlink(runs["study"], tmp_path / "OUT")
    monkeypatch.chdir(tmp_path)
    namespace: dict[str, Any] = {"math": math}
    with contextlib.redirect_stdout(io.StringIO()):
        for block in blocks:  # in order: a later block uses an earlier one's names
            exec(compile(block, str(DOC), "exec"), namespace)


def test_format_text_puts_the_stamp_first_and_sorts_the_rest() -> None:
    from fsmbench.jsonutil import format_text, stamped

    payload = stamped({"b": {"z": 1, "a": [{"y": 2, "x": float("nan")}]}, "a": 0},
                      format="fsmbench.x", version=2)
    text = format_text(payload, sort_keys=True)
    assert list(json.loads(text)) == ["format", "format_version", "a", "b"]
    # Sorted at every depth (lists of objects too), NaN as null, one line feed at the end.
    assert json.dumps(json.loads(text)["b"]) == '{"a": [{"x": null, "y": 2}], "z": 1}'
    assert text.endswith("}\n")
    with pytest.raises(ValueError, match="format"):
        format_text({"a": 1})
