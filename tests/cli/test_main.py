"""The ``fsmbench`` command line."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import scipy.io

from fsmbench.cli import main


def test_params_table_has_units_and_sources(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["params"]) == 0
    out = capsys.readouterr().out
    line = next(x for x in out.splitlines() if x.startswith("converter.fs_hz"))
    assert "10000" in line and "Hz" in line and "ESRF study 1.6" in line


def test_params_json_and_roundtrip(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["params", "--json", "--out", str(tmp_path)]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert list(doc)[:2] == ["format", "format_version"]
    assert (doc["format"], doc["format_version"]) == ("fsmbench.params", 1)
    rows = doc["parameters"]
    assert {"key", "nominal", "true", "unit", "source"} <= set(rows[0])
    assert main(["params", "--json", "--params", str(tmp_path / "bench.toml")]) == 0
    again = json.loads(capsys.readouterr().out)
    assert again["parameters"] == rows  # saved TOML reloads to the same
    assert again["bench"].endswith("bench.toml")


def test_a_reader_that_closes_the_pipe_ends_the_command_quietly(
        monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    """``fsmbench params --json | head -1``: the shell's SIGPIPE status, no error line."""
    import io

    from fsmbench.cli import EXIT_BROKEN_PIPE

    class ClosedPipe(io.StringIO):
        def write(self, text: str) -> int:
            raise BrokenPipeError(32, "Broken pipe")

    monkeypatch.setattr("sys.stdout", ClosedPipe())
    assert main(["params", "--json"]) == EXIT_BROKEN_PIPE == 128 + 13
    assert capsys.readouterr().err == ""


def test_simulate_writes_the_requested_records(tmp_path: Path,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["simulate", str(tmp_path), "--duration", "3", "--seed", "2",
                 "--experiments", "data_uch", "data_cal_pd_h"]) == 0
    names = sorted(p.name for p in tmp_path.iterdir())
    assert names == ["data_cal_pd_h.mat", "data_uch.mat", "run.json", "twin_truth.json"]
    data = scipy.io.loadmat(tmp_path / "data_uch.mat")
    assert data["Uch"].shape == (30000, 1)
    assert json.loads((tmp_path / "twin_truth.json").read_text())["seed"] == 2
    manifest = json.loads((tmp_path / "run.json").read_text())
    assert (manifest["format"], manifest["format_version"]) == ("fsmbench.run", 1)
    assert sorted(f["path"] for f in manifest["files"]) == [
        "data_cal_pd_h.mat", "data_uch.mat", "twin_truth.json"]


@pytest.mark.parametrize(("argv", "message"), [
    (["simulate", "OUT", "--duration", "1"], "too short"),
    (["simulate", "OUT", "--experiments", "data_nope"], "unknown experiment"),
    (["study", "--data", "NOWHERE", "--out", "OUT"], "NOWHERE"),
    (["params", "--params", "MISSING.toml"], "MISSING.toml"),
])
def test_errors_exit_2_with_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                     argv: list[str], message: str) -> None:
    argv = [str(tmp_path / a) if a.isupper() or a.endswith(".toml") else a for a in argv]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith(f"fsmbench {argv[0]}: error: ") and message in err[-1]


def test_bad_params_file_names_the_problem(tmp_path: Path,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["params", "--out", str(tmp_path)]) == 0
    bad = tmp_path / "bench.toml"
    text = bad.read_text()
    good = "(ESRF study 1.6)\nfs_hz = 10000.0"
    assert text.count(good) >= 1
    bad.write_text(text.replace(good, "(ESRF study 1.6)\nfs_hz = 'fast'", 1))
    assert main(["params", "--params", str(bad)]) == 2
    err = capsys.readouterr().err
    assert "bench.toml" in err and "fs_hz" in err


def test_identify_writes_its_outputs_and_compares_with_the_truth(
        ident_twin, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from fsmbench.twin import write_twin

    data = tmp_path / "data"
    data.mkdir()
    write_twin(ident_twin, data)
    out = tmp_path / "out"
    assert main(["identify", str(data), "--out", str(out)]) == 0
    captured = capsys.readouterr()
    assert sorted(p.name for p in out.iterdir()) == ["bench_identified.toml", "frf.mat",
                                                     "identification.json", "plant.mat",
                                                     "run.json"]
    # The readable table on stdout: quantities in words with units, the verdict per row.
    rows = {line[:37].strip(): line.split()[-1] for line in captured.out.splitlines()[1:]
            if line.startswith("Sercalo")}
    assert rows["Sercalo damping ratio, h [1]"] == "ok"
    assert rows["Sercalo resonance, v [Hz]"] == "ok"
    assert "sercalo.h.damping_ratio" not in captured.out + captured.err


def test_identify_refuses_to_write_into_the_data(tmp_path: Path,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["identify", str(tmp_path), "--out", str(tmp_path / "out")]) == 2
    assert "inside the data folder" in capsys.readouterr().err


# budget and design: tests/faults/test_cli_reproducible.py (run twice, byte-identical).


@pytest.mark.parametrize("command", ["budget", "design", "identify"])
def test_stage_commands_refuse_a_missing_folder(command: str, tmp_path: Path,
                                                capsys: pytest.CaptureFixture[str]) -> None:
    assert main([command, str(tmp_path / "nope"), "--out", str(tmp_path / "out")]) == 2
    assert "nope" in capsys.readouterr().err


@pytest.mark.parametrize("bad", ["-1", "0", "inf", "nan", "five"])
def test_a_distance_target_that_is_not_a_length_is_refused(
        bad: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["study", "--out", str(tmp_path / "out"), "--distance-target", bad]) == 2
    err = capsys.readouterr().err
    assert "--distance-target" in err and bad in err and "Traceback" not in err
    assert not (tmp_path / "out").exists()  # refused before anything ran


@pytest.mark.parametrize("rate", ["2e4", "nan", "fast"])
def test_serve_and_tune_read_a_drift_rate_alike(rate: str,
                                                capsys: pytest.CaptureFixture[str]) -> None:
    """One parser for ``--drift-rate``: the same limit and the same words on both commands."""
    errors = []
    for argv in (["serve", "--drift-rate", rate], ["tune", "--twin", "--drift-rate", rate,
                                                   "--out", "unused"]):
        assert main(argv) == 2
        errors.append(capsys.readouterr().err.split("--drift-rate", 1)[1].split(" (see ")[0])
    assert errors[0] == errors[1] and "drift rate" in errors[0]


@pytest.mark.parametrize("command", [
    ["excite", "{out}", "--input", "Uch", "--amplitude-rms", "0.01", "--band", "1", "100"],
    ["tune", "--twin", "--out", "{out}"],
    ["params"],
])
@pytest.mark.parametrize(("kind", "words"), [("folder", "is a folder"),
                                             ("binary", "is not UTF-8 text")])
def test_every_command_names_a_bench_file_that_is_not_one(
        command: list[str], kind: str, words: str, tmp_path: Path,
        capsys: pytest.CaptureFixture[str]) -> None:
    """A folder or a binary file given as ``--params``: one line naming it, status 2, on
    the commands that load the bench themselves as on the others."""
    bad = tmp_path / "bench"
    if kind == "folder":
        bad.mkdir()
    else:
        bad.write_bytes(b"\xff\xfe\x00 not text")
    argv = [a.format(out=tmp_path / "out") for a in command] + ["--params", str(bad)]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and str(bad) in err and words in err
    assert not (tmp_path / "out").exists()
