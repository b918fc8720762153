"""Issue 21: inputs never destroyed or overwritten, and what varies between identical runs.

Every input a command line names (DATA, ``--params``, ``--bench``/``--identification``,
``--controller``, ``--excitation``, ``--ranges``, convert's IN) is checked against the
output before anything runs; a file fsmbench did not write (another recording, a file
edited by hand since the run) is never overwritten. Each refusal is one line, status 2,
naming the file and the option, with the inputs' SHA-256 unchanged and nothing left
behind.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
from collections.abc import Callable
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import h5py
import numpy as np
import pytest
import scipy.io

EXCITE = ("--input", "Uch", "--amplitude-rms", "0.015", "--band", "1", "200")
MC = ("--n", "2", "--workers", "1", "--duration", "4.5", "--settle", "2")


@pytest.fixture(scope="module")
def ident_dir(stage_data: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A real ``fsmbench identify`` folder (identification.json, plant.mat, frf.mat)."""
    from fsmbench.cli import main

    out = tmp_path_factory.mktemp("ident") / "I"
    assert main(["identify", str(stage_data), "--out", str(out)]) == 0
    return out


@pytest.fixture(scope="module")
def design_dir(huddle_data: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A real ``fsmbench design`` folder (controllers.mat, controllers_sos.json, ...)."""
    from fsmbench.cli import main

    out = tmp_path_factory.mktemp("design") / "D"
    assert main(["design", str(huddle_data), "--out", str(out)]) == 0
    assert (out / "controllers.mat").is_file()
    return out


@pytest.fixture
def old_ident(ident_dir: Path, tmp_path: Path) -> Path:
    """A private copy of :func:`ident_dir`, a previous run a test may point --out at."""
    out = tmp_path / "ident-run"
    shutil.copytree(ident_dir, out)
    return out


@pytest.fixture(scope="module")
def nexus_record(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A twin record fsmbench wrote as NeXus (not a conversion)."""
    from fsmbench.cli import main

    out = tmp_path_factory.mktemp("nexus") / "tw"
    assert main(["simulate", str(out), "--experiments", "data_cal_pd_h", "--duration", "3",
                 "--format", "nexus"]) == 0
    return out / "data_cal_pd_h.h5"


# ----------------------------------------------------------------- inputs inside --out


def test_montecarlo_controller_of_the_design_folder_it_would_replace(
        kit: SimpleNamespace, run_cli: Callable[..., Any], design_dir: Path,
        tmp_path: Path) -> None:
    """``montecarlo --out D --controller D/controllers.mat`` deleted the design folder."""
    d = tmp_path / "D"
    shutil.copytree(design_dir, d)
    before = kit.hashes(d)
    for controller in (d / "controllers.mat", f"{d / 'controllers.mat'}::fsmbench_controller",
                       d):
        r = run_cli("montecarlo", "--twin", "--out", d, "--controller", controller, *MC)
        what = "is the --out folder" if controller == d else "is inside --out"
        kit.assert_one_line_verdict(r, "montecarlo", str(controller).partition("::")[0],
                                    "--controller", what, "choose another --out")
        assert len(r.err.strip().splitlines()) == 1
        assert kit.hashes(d) == before
    assert kit.leftovers(tmp_path) == []


def test_simulate_into_the_excitation_folder_it_plays(kit: SimpleNamespace,
                                                      run_cli: Callable[..., Any],
                                                      tmp_path: Path) -> None:
    """``simulate EXC --excitation EXC`` deleted excitation.mat and excitation.json."""
    exc = tmp_path / "EXC"
    assert run_cli("excite", exc, *EXCITE).status == 0
    before = kit.hashes(exc)
    assert {"excitation.mat", "excitation.json"} <= set(before)
    # The output folder was typed as simulate's OUT, so the message names OUT (issue 30).
    for source, what in ((exc, "is the OUT folder"),
                         (exc / "excitation.json", "is inside OUT")):
        r = run_cli("simulate", exc, "--excitation", source, "--duration", "5")
        kit.assert_one_line_verdict(r, "simulate", str(source), "--excitation", what)
        assert len(r.err.strip().splitlines()) == 1
        assert kit.hashes(exc) == before
    assert kit.leftovers(tmp_path) == []


# Every input option of every writing command, pointing into a previous run that --out
# would replace: `{o}` a `params` run and `{f}` the file it lists (bench.toml), or `{i}` an
# `identify` run (what --bench reads; it is read before the check, harmlessly).
CASES = [
    ("params", ["--params", "{f}", "--out", "{o}"], "--params"),
    ("simulate", ["{o}", "--params", "{f}"], "--params"),
    ("simulate", ["{o}", "--excitation", "{f}"], "--excitation"),
    ("simulate", ["{i}", "--bench", "{i}"], "--bench"),
    ("excite", ["{o}", *EXCITE, "--params", "{f}"], "--params"),
    ("excite", ["{i}", *EXCITE, "--bench", "{i}"], "--bench"),
    ("identify", ["{data}", "--out", "{o}", "--params", "{f}"], "--params"),
    ("budget", ["{data}", "--out", "{i}", "--bench", "{i}"], "--bench"),
    ("design", ["{data}", "--out", "{i}", "--identification", "{i}"], "--identification"),
    ("study", ["--out", "{o}", "--params", "{f}"], "--params"),
    ("montecarlo", ["--twin", "--out", "{o}", "--ranges", "{f}", *MC], "--ranges"),
    ("montecarlo", ["--twin", "--out", "{o}", "--params", "{f}", *MC], "--params"),
    ("montecarlo", ["--twin", "--out", "{o}", "--controller", "{f}::x", *MC], "--controller"),
    ("montecarlo", ["--out", "{i}", "--bench", "{i}", *MC], "--bench"),
]


@pytest.mark.parametrize(("command", "argv", "option"), CASES,
                         ids=[f"{c}-{o}-{i}" for i, (c, _a, o) in enumerate(CASES)])
def test_every_input_is_checked_against_out(kit: SimpleNamespace, run_cli: Callable[..., Any],
                                            old_run: Path, old_ident: Path, stage_data: Path,
                                            command: str, argv: list[str],
                                            option: str) -> None:
    values = {"o": str(old_run), "f": str(old_run / "bench.toml"), "i": str(old_ident),
              "data": str(stage_data)}
    run = old_ident if "{i}" in argv else old_run
    before = kit.hashes(run)
    r = run_cli(command, *[a.format(**values) for a in argv])
    # simulate and excite take the output folder as OUT too: the message names what was typed.
    out_word = "--out" if "--out" in argv else "OUT"
    kit.assert_one_line_verdict(r, command, option, str(run), "which this run replaces",
                                f"choose another {out_word}")
    assert len(r.err.strip().splitlines()) == 1, r.err
    assert kit.hashes(run) == before
    assert kit.leftovers(run.parent) == []


def test_out_inside_an_input_folder(kit: SimpleNamespace, run_cli: Callable[..., Any],
                                    old_ident: Path) -> None:
    """An output never goes into an input's folder (it would become part of that run)."""
    before = kit.hashes(old_ident)
    r = run_cli("simulate", old_ident / "sub", "--bench", old_ident, "--duration", "5")
    kit.assert_one_line_verdict(r, "simulate", str(old_ident / "sub"), "--bench folder",
                                "never writes into its inputs' folders")
    assert kit.hashes(old_ident) == before


# ----------------------------------------------------------------- files fsmbench did not write


def test_hand_edited_identification_is_not_replaced(kit: SimpleNamespace,
                                                    run_cli: Callable[..., Any],
                                                    ident_dir: Path, stage_data: Path,
                                                    tmp_path: Path) -> None:
    out = tmp_path / "I"
    shutil.copytree(ident_dir, out)
    edited = out / "identification.json"
    payload = json.loads(edited.read_text())
    payload["note"] = "gains checked by hand"
    edited.write_text(json.dumps(payload, indent=2))
    before = kit.hashes(out)
    r = run_cli("identify", stage_data, "--out", out)
    kit.assert_one_line_verdict(r, "identify", str(edited), "was changed after fsmbench wrote",
                                "SHA-256", "run.json", "move this file away")
    assert len(r.err.strip().splitlines()) == 1
    assert kit.hashes(out) == before
    # Moved away, the run goes on.
    edited.rename(tmp_path / "mine.json")
    assert run_cli("params", "--out", out).status == 0


def test_edited_file_of_the_same_size_is_caught(kit: SimpleNamespace,
                                                run_cli: Callable[..., Any],
                                                old_run: Path) -> None:
    """The size is not enough: the SHA-256 tells an edit that keeps it."""
    f = old_run / "bench.toml"
    text = f.read_text()
    f.write_text(text.replace("fs_hz = 10000.0", "fs_hz = 20000.0", 1))
    assert len(f.read_text()) == len(text) and f.read_text() != text
    before = kit.hashes(old_run)
    r = run_cli("params", "--out", old_run)
    kit.assert_one_line_verdict(r, "params", str(f), "was changed after fsmbench wrote")
    assert kit.hashes(old_run) == before


@pytest.fixture
def recordings(stage_data: Path, tmp_path: Path) -> Path:
    folder = tmp_path / "rec"
    folder.mkdir()
    for name in ("data_uch.mat", "data_ucv.mat"):
        shutil.copy(stage_data / name, folder / name)
    return folder


@pytest.mark.parametrize(("dest", "needles"), [
    ("data_ucv.mat", ("exists and is not an archive fsmbench convert made from",)),
    ("other.h5", ("exists and is not an archive fsmbench convert made from",)),
    ("data_uch.mat", ("is IN itself", "inputs are never modified")),
    ("new.mat", ("name OUT new.h5", ".h5 or .nxs")),
    ("sub", ("is a folder",)),
])
def test_convert_never_overwrites_what_it_did_not_write(
        kit: SimpleNamespace, run_cli: Callable[..., Any], recordings: Path, nexus_record: Path,
        dest: str, needles: tuple[str, ...]) -> None:
    """``convert data_uch.mat data_ucv.mat`` (a typo) overwrote another recording."""
    (recordings / "sub").mkdir()
    shutil.copy(nexus_record, recordings / "other.h5")  # fsmbench's, not a conversion
    before = kit.hashes(recordings)
    r = run_cli("convert", recordings / "data_uch.mat", recordings / dest)
    kit.assert_one_line_verdict(r, "convert", str(recordings / dest), *needles)
    assert len(r.err.strip().splitlines()) == 1
    assert kit.hashes(recordings) == before
    assert kit.leftovers(recordings) == []


def test_convert_replaces_its_own_conversion_with_the_same_bytes(
        kit: SimpleNamespace, run_cli: Callable[..., Any], recordings: Path) -> None:
    """Its own earlier output of the same IN may be replaced; the archive holds no wall
    clock (no ``file_time``, and a note why), so the bytes are the same."""
    src, dest = recordings / "data_uch.mat", recordings / "data_uch.h5"
    assert run_cli("convert", src, dest).status == 0
    first = kit.hashes(recordings)
    assert run_cli("convert", src, dest).status == 0
    assert kit.hashes(recordings) == first
    with h5py.File(dest, "r") as f:
        assert "file_time" not in f.attrs and "reproducible" in f.attrs["file_time_note"]
        assert f.attrs["converted_from"] == str(src.resolve())
    # Another IN may not replace it.
    r = run_cli("convert", recordings / "data_ucv.mat", dest)
    kit.assert_one_line_verdict(r, "convert", str(dest), "not an archive fsmbench convert "
                                "made from")
    assert kit.hashes(recordings) == first
    stamped = recordings / "stamped.h5"
    assert run_cli("convert", src, stamped, "--timestamp").status == 0
    with h5py.File(stamped, "r") as f:
        assert not f.attrs["file_time"].startswith("1970")


# ----------------------------------------------------------------- what varies between runs


def test_montecarlo_run_json_differs_only_in_the_timings_entry(
        run_cli: Callable[..., Any], tmp_path: Path) -> None:
    """Documented (README "Reproducibility", docs/results.md run.json): identical runs
    differ in timings.json and in run.json's entry for it (sha256, size_bytes), nothing
    else."""
    manifests = []
    for name in ("a", "b"):
        out = tmp_path / name
        r = run_cli("montecarlo", "--twin", "--out", out, *MC)
        assert r.status == 0, r.err
        manifests.append(json.loads((out / "run.json").read_text()))
    a, b = manifests
    assert a["not_reproducible"] == b["not_reproducible"] == ["timings.json"]
    assert (tmp_path / "a" / "montecarlo.json").read_bytes() == \
        (tmp_path / "b" / "montecarlo.json").read_bytes()

    def without_timings(m: dict[str, Any]) -> dict[str, Any]:
        files = [f if f["path"] != "timings.json" else {"path": f["path"]} for f in m["files"]]
        return {**m, "files": files}

    assert without_timings(a) == without_timings(b)
    assert {f["path"] for f in a["files"]} == {"montecarlo.json", "timings.json"}


@pytest.mark.machine_sensitive
def test_identify_with_one_blas_thread_is_equal_within_rounding(
        kit: SimpleNamespace, ident_dir: Path, stage_data: Path, tmp_path: Path) -> None:
    """Documented (README "Reproducibility"): one BLAS thread changes the order OpenBLAS
    sums in, so a few diagnostics differ in the last digits; the MAT files and every
    number are equal within 1e-12 relative (measured: 6e-16), or 1e-15 absolute for
    numbers near zero (a correlation that is zero to rounding: a few eps of its O(1)
    terms)."""
    out = tmp_path / "one-thread"
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1",
           "NUMBA_NUM_THREADS": "1"}
    done = subprocess.run(kit.cli_command("identify", stage_data, "--out", out), env=env,
                          capture_output=True, text=True, timeout=300, check=False)
    assert done.returncode == 0, done.stderr

    def numbers(x: Any, path: str = "") -> dict[str, Any]:
        if isinstance(x, dict):
            items = [(f"{path}.{key}", val) for key, val in x.items()]
        elif isinstance(x, list):
            items = [(f"{path}[{i}]", val) for i, val in enumerate(x)]
        else:
            return {path: x}
        return {k: v for sub, val in items for k, v in numbers(val, sub).items()}

    a = numbers(json.loads((ident_dir / "identification.json").read_text()))
    b = numbers(json.loads((out / "identification.json").read_text()))
    assert a.keys() == b.keys()
    for key, value in a.items():
        if isinstance(value, float) and isinstance(b[key], float):
            assert b[key] == pytest.approx(value, rel=1e-12, abs=1e-15), key
        else:
            assert b[key] == value, key
    for name in ("plant.mat", "frf.mat"):
        ma = scipy.io.loadmat(ident_dir / name, simplify_cells=True)
        mb = scipy.io.loadmat(out / name, simplify_cells=True)
        _close(ma, mb, name)


def _close(a: Any, b: Any, where: str) -> None:
    if isinstance(a, dict):
        assert a.keys() == b.keys(), where
        for k in a:
            if not k.startswith("__"):
                _close(a[k], b[k], f"{where}.{k}")
    elif isinstance(a, np.ndarray) and a.dtype.kind in "fc":
        np.testing.assert_allclose(b, a, rtol=1e-12, atol=0, err_msg=where)
    elif isinstance(a, np.ndarray):
        assert a.shape == b.shape, where
    elif isinstance(a, float):
        assert b == pytest.approx(a, rel=1e-12), where
    else:
        assert type(a) is type(b), where
