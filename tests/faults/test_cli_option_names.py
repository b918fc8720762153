"""Messages name the option the user typed (issue 30, item 7).

``--bench`` and its older name ``--identification`` are one option of budget, design
and excite; ``simulate`` and ``excite`` take their output folder as ``OUT``; an option
left at its default is not presented as typed. Each case runs ``fsmbench.cli.main``
and reads the one-line verdict, which must hold the option typed and not the other name.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pytest

EXCITE = ("--input", "Uch", "--amplitude-rms", "0.015")


@pytest.fixture
def no_identification(tmp_path: Path) -> Path:
    """A folder without identification.json."""
    folder = tmp_path / "empty"
    folder.mkdir()
    return folder


@pytest.fixture
def data(tmp_path: Path) -> Path:
    folder = tmp_path / "data"
    folder.mkdir()
    return folder


@pytest.fixture
def no_computation(monkeypatch: pytest.MonkeyPatch) -> None:
    """The twin's simulation and the excitation design fail the test if they start."""

    def never(*_args: Any, **_kwargs: Any) -> None:
        raise AssertionError("the computation started before the arguments were checked")

    for target in ("fsmbench.twin.simulate.simulate_bench", "fsmbench.twin.simulate.stream_bench",
                   "fsmbench.cli.commands.excite._design"):
        monkeypatch.setattr(target, never)


TYPED = [
    (["--bench", "{d}"], "--bench", "--identification"),
    (["--identification", "{d}"], "--identification", "--bench"),
    (["--identification={d}"], "--identification", "--bench"),
    (["--ident", "{d}"], "--identification", "--bench"),  # argparse's abbreviation, spelt out
]


@pytest.mark.parametrize("command", ["budget", "design"])
@pytest.mark.parametrize(("argv", "typed", "other"), TYPED, ids=[t[0][0] for t in TYPED])
def test_a_missing_identification_names_the_alias_typed(
        kit: SimpleNamespace, run_cli: Callable[..., Any], tmp_path: Path, data: Path,
        no_identification: Path, command: str, argv: list[str], typed: str,
        other: str) -> None:
    # Before: "--identification must be a folder …" whichever was typed.
    r = run_cli(command, data, "--out", tmp_path / "out",
                *[a.format(d=no_identification) for a in argv])
    kit.assert_one_line_verdict(r, command, f"does not exist; {typed} must be a folder")
    assert other not in r.verdict()


@pytest.mark.parametrize(("option", "other"), [("--bench", "--identification"),
                                               ("--identification", "--bench")])
def test_an_identification_without_sercalo_says_run_without_the_option_typed(
        kit: SimpleNamespace, run_cli: Callable[..., Any], tmp_path: Path, data: Path,
        option: str, other: str) -> None:
    ident = tmp_path / "ident"
    ident.mkdir()
    (ident / "identification.json").write_text(json.dumps({"diagnostics": {}}))
    r = run_cli("budget", data, "--out", tmp_path / "out", option, ident)
    kit.assert_one_line_verdict(r, "budget", "has no identified Sercalo",
                                f"run without {option} to use the nominal model")
    assert other not in r.verdict()


@pytest.mark.parametrize(("option", "other"), [("--bench", "--identification"),
                                               ("--identification", "--bench")])
def test_excite_names_the_alias_typed(kit: SimpleNamespace, run_cli: Callable[..., Any],
                                      tmp_path: Path, no_identification: Path, option: str,
                                      other: str, no_computation: None) -> None:
    a_file = tmp_path / "bench.toml"
    a_file.write_text("")
    r = run_cli("excite", tmp_path / "out", *EXCITE, option, a_file)
    kit.assert_one_line_verdict(r, "excite", f"is a file; {option} needs a folder")
    assert other not in r.verdict()
    r = run_cli("excite", tmp_path / "out", *EXCITE, option, no_identification)
    kit.assert_one_line_verdict(r, "excite", f"{option} must be a folder")
    assert other not in r.verdict()


def test_simulate_with_only_bench_never_says_identification(
        kit: SimpleNamespace, run_cli: Callable[..., Any], tmp_path: Path,
        no_identification: Path, no_computation: None) -> None:
    r = run_cli("simulate", tmp_path / "out", "--bench", no_identification)
    kit.assert_one_line_verdict(r, "simulate", "--bench must be a folder")
    assert "--identification" not in r.verdict()


@pytest.mark.parametrize(("argv", "typed", "other"),
                         [(["{f}"], "choose another OUT", "--out"),
                          (["--out", "{f}"], "choose another --out", "OUT")])
def test_simulate_names_its_output_folder_as_typed(
        kit: SimpleNamespace, run_cli: Callable[..., Any], tmp_path: Path, argv: list[str],
        typed: str, other: str, no_computation: None) -> None:
    a_file = tmp_path / "a_file"
    a_file.write_text("x")
    r = run_cli("simulate", *[a.format(f=a_file) for a in argv], "--duration", "5")
    kit.assert_one_line_verdict(r, "simulate", "exists and is a file, not a folder", typed)
    assert other not in r.verdict()
    assert a_file.read_text() == "x"


def test_excite_names_its_output_folder_out(kit: SimpleNamespace, run_cli: Callable[..., Any],
                                            tmp_path: Path, no_computation: None) -> None:
    out = tmp_path / "out"
    out.mkdir()
    (out / "bench.toml").write_text("")
    r = run_cli("excite", out, *EXCITE, "--params", out / "bench.toml")
    kit.assert_one_line_verdict(r, "excite", "--params is inside OUT", "choose another OUT")
    assert "--out" not in r.verdict()


def test_a_default_is_not_presented_as_typed(kit: SimpleNamespace, run_cli: Callable[..., Any],
                                             tmp_path: Path,
                                             monkeypatch: pytest.MonkeyPatch,
                                             no_computation: None) -> None:
    # Before: "--format mat5: …" for a command line without --format.
    monkeypatch.setattr("fsmbench.io.matfile.available_memory_bytes", lambda: 16_000_000_000)
    r = run_cli("simulate", tmp_path / "out", "--duration", "3600")
    kit.assert_one_line_verdict(r, "simulate", "--format mat5 (the default): --duration 3600 s")
    r = run_cli("simulate", tmp_path / "out", "--duration", "3600", "--format", "mat73")
    kit.assert_one_line_verdict(r, "simulate", "--format mat73: --duration 3600 s")
    r = run_cli("montecarlo", "--twin", "--out", tmp_path / "mc", "--settle", "7")
    kit.assert_one_line_verdict(r, "montecarlo", "--settle 7 s leaves nothing of a --duration "
                                                 "6 s (the default) record")


def test_the_device_names_its_property_not_an_option(no_identification: Path) -> None:
    # The Tango device reads the folder from its BenchFolder property: no option was typed.
    from fsmbench.bench.params import load_bench
    from fsmbench.io.errors import RecordingError
    from fsmbench.twin.identified import identified_bench

    with pytest.raises(RecordingError) as err:
        identified_bench(no_identification, bench=load_bench(None),
                         option="the BenchFolder property")
    assert "the BenchFolder property must be a folder" in str(err.value)
    assert "--" not in str(err.value)
