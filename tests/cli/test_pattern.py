"""Every command follows one pattern: registered by its module, the shared options defined
once, the result on stdout and, with ``--json``, as JSON."""

from __future__ import annotations

import ast
import contextlib
import io
import json
import re
from pathlib import Path

import pytest
import scipy.io

import fsmbench
from fsmbench.cli import main

SRC = Path(fsmbench.__file__).parent
COMMANDS_DIR = SRC / "cli" / "commands"
SHARED = ("--params", "--bench", "--seed", "--timestamp", "--out", "--json", "--max-error-urad",
          "--at")


def _help(argv: list[str]) -> str:
    """What ``fsmbench ARGV --help`` prints, with its exit status 0."""
    text = io.StringIO()
    with contextlib.redirect_stdout(text):
        assert main([*argv, "--help"]) == 0
    return text.getvalue()


def _commands() -> list[str]:
    """The sub-commands ``fsmbench --help`` lists."""
    listed = re.search(r"\{([a-z,]+)\}", _help([]))
    assert listed is not None
    return listed.group(1).split(",")


def _functions(path: Path) -> dict[str, ast.FunctionDef]:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    return {n.name: n for n in tree.body if isinstance(n, ast.FunctionDef)}


def test_every_command_is_a_module_with_register_and_run() -> None:
    modules = {p.stem: p for p in COMMANDS_DIR.glob("*.py") if p.stem != "__init__"}
    assert set(_commands()) == set(modules)  # no command registered another way
    for name, path in modules.items():
        functions = _functions(path)
        assert {"register", "run"} <= set(functions), name
        # register wires the command to its own run, and nothing else does.
        wired = [kw.value.id for node in ast.walk(functions["register"])
                 if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
                 and node.func.attr == "set_defaults"
                 for kw in node.keywords if kw.arg == "func" and isinstance(kw.value, ast.Name)]
        assert wired == ["run"], name


def _option_strings_added(path: Path) -> list[str]:
    """The option strings given literally to ``add_argument`` calls in ``path``."""
    found = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
                and node.func.attr == "add_argument"):
            found += [a.value for a in node.args
                      if isinstance(a, ast.Constant) and isinstance(a.value, str)]
    return found


def test_the_shared_options_are_defined_once() -> None:
    where: dict[str, list[str]] = {option: [] for option in SHARED}
    for path in SRC.rglob("*.py"):
        for option in _option_strings_added(path):
            if option in where:
                where[option].append(str(path.relative_to(SRC)))
    # --bench is added as *names (its alias) in the same function: no literal elsewhere.
    assert all(set(files) <= {"cli/options.py"} for files in where.values()), where
    assert {o for o, files in where.items() if files} == set(SHARED) - {"--bench"}


@pytest.mark.parametrize("command", _commands())
def test_every_command_has_json(command: str) -> None:
    # serve runs until it is stopped: its result is where it serves, said once it does.
    assert re.search(r"^\s+--json\b", _help([command]), flags=re.MULTILINE), command


def test_simulate_json_lists_the_files_it_wrote(tmp_path: Path,
                                                capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "twin"
    assert main(["simulate", str(out), "--duration", "3", "--experiments", "data_uch",
                 "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert (doc["format"], doc["format_version"], doc["command"]) == (
        "fsmbench.files", 1, "simulate")
    assert sorted(Path(f).name for f in doc["files"]) == ["data_uch.mat", "twin_truth.json"]
    assert all(Path(f).parent == out and Path(f).is_file() for f in doc["files"])


def test_excite_json_is_the_excitation_file(tmp_path: Path,
                                            capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "ex"
    assert main(["excite", "--out", str(out), "--input", "Uch", "--amplitude-rms", "0.01",
                 "--band", "1", "100", "--json"]) == 0
    printed = capsys.readouterr().out
    assert json.loads(printed) == json.loads((out / "excitation.json").read_text())


def test_convert_json_names_the_archive(tmp_path: Path,
                                        capsys: pytest.CaptureFixture[str]) -> None:
    src = tmp_path / "data_uch.mat"
    t = [[k * 1e-4] for k in range(2000)]
    scipy.io.savemat(src, {"t": t, "Uch": [[0.0]] * 2000, "Vph": [[0.0]] * 2000})
    dest = tmp_path / "data_uch.h5"
    assert main(["convert", str(src), str(dest), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["command"] == "convert" and [Path(f) for f in doc["files"]] == [dest]
    assert dest.is_file()
