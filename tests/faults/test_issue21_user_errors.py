"""Issue 21: "internal error … a bug in fsmbench" that users could cause, now one line.

Each case ended in a traceback and status 1 (``serve --seed -1``: status 0), or ran for
a quarter of an hour, or wrote a wrong file. Now each is one line, status 2, naming the
file or option and the problem, before anything is computed or written; the inputs'
SHA-256 are unchanged and no output folder appears.
"""

from __future__ import annotations

import os
import shutil
from collections.abc import Callable
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import h5py
import numpy as np
import pytest

from fsmbench.bench.params import ParamsError, default_bench, load_bench, walk_fields
from fsmbench.io.matwrite import save_mat

EXCITE = ("--input", "Uch", "--amplitude-rms", "0.015")


def _one_line(kit: SimpleNamespace, r: Any, command: str, *needles: str) -> None:
    kit.assert_one_line_verdict(r, command, *needles)
    assert len(r.err.strip().splitlines()) == 1, r.err
    assert "internal error" not in r.err


@pytest.fixture
def no_computation(monkeypatch: pytest.MonkeyPatch) -> None:
    """The twin's simulation and the excitation design fail the test if they start."""

    def never(*_args: Any, **_kwargs: Any) -> None:
        raise AssertionError("the computation started before the arguments were checked")

    for target in ("fsmbench.twin.simulate.simulate_bench", "fsmbench.twin.simulate.stream_bench",
                   "fsmbench.cli.commands.excite._design"):
        monkeypatch.setattr(target, never)


# ----------------------------------------------------------------- seeds and ports


SEEDS = [("simulate", ["{out}"]), ("design", ["{data}", "--out", "{out}"]),
         ("excite", ["{out}", *EXCITE]), ("montecarlo", ["--twin", "--out", "{out}"]),
         ("study", ["--out", "{out}"]), ("serve", ["--nodb", "--port", "0"])]


@pytest.mark.parametrize("seed", ["-1", "2.5", str(2**63)])
@pytest.mark.parametrize(("command", "argv"), SEEDS, ids=[c for c, _ in SEEDS])
def test_seed_out_of_range(kit: SimpleNamespace, run_cli: Callable[..., Any], tmp_path: Path,
                           huddle_data: Path, command: str, argv: list[str], seed: str) -> None:
    """``--seed -1`` was a ValueError deep in numpy (``serve``: a traceback, status 0)."""
    out = tmp_path / "out"
    r = run_cli(command, *[a.format(out=out, data=huddle_data) for a in argv], "--seed", seed)
    _one_line(kit, r, command, "argument --seed", repr(seed), "0 to 2**63 - 1")
    assert not out.exists()


@pytest.mark.parametrize("port", ["99999", "-1", "65536", "http"])
def test_serve_port_out_of_range(kit: SimpleNamespace, run_cli: Callable[..., Any],
                                 port: str) -> None:
    """``serve --port 99999`` was an OverflowError."""
    r = run_cli("serve", "--nodb", "--port", port)
    _one_line(kit, r, "serve", "argument --port", repr(port))


# ----------------------------------------------------------------- sizes


def test_simulate_longer_than_memory(kit: SimpleNamespace, run_cli: Callable[..., Any],
                                     tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                     no_computation: None) -> None:
    """``simulate --duration 3600`` in .mat ended in MemoryError: refused with the size
    and --format nexus (16 GB available here, whatever this machine has)."""
    monkeypatch.setattr("fsmbench.io.matfile.available_memory_bytes", lambda: 16_000_000_000)
    out = tmp_path / "out"
    r = run_cli("simulate", out, "--duration", "3600")
    _one_line(kit, r, "simulate", "--format mat5", "--duration 3600 s", "GB of memory",
              "16.0 GB available", "--format nexus")
    assert not out.exists() and kit.leftovers(tmp_path) == []
    r = run_cli("simulate", out, "--duration", "3600", "--format", "mat73")
    _one_line(kit, r, "simulate", "--format mat73")


def test_study_longer_than_memory(kit: SimpleNamespace, run_cli: Callable[..., Any],
                                  tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                  no_computation: None) -> None:
    """``study --duration`` simulates and analyses in memory: refused with the size and the
    streamed way (simulate --format nexus, then budget), before anything runs."""
    monkeypatch.setattr("fsmbench.io.matfile.available_memory_bytes", lambda: 16_000_000_000)
    out = tmp_path / "out"
    r = run_cli("study", "--out", out, "--duration", "3600")
    _one_line(kit, r, "study", "--duration 3600 s", "GB of memory", "16.0 GB available",
              "--format nexus")
    assert not out.exists() and kit.leftovers(tmp_path) == []


def test_simulate_size_estimate_fits_a_short_run(monkeypatch: pytest.MonkeyPatch) -> None:
    """What fits is not refused: the estimate of the default run (1.78 GB) is within 20 %
    of the measured peak (1.52 GB), and 5 s records need well under 1 GB."""
    from fsmbench.twin.sizes import simulation_memory_bytes

    def need(**kw: Any) -> float:
        return simulation_memory_bytes(default_bench(), **kw)

    monkeypatch.setattr("os.cpu_count", lambda: 2)
    assert 1.52e9 < need() < 1.2 * 1.52e9 + 0.1e9
    assert simulation_memory_bytes(default_bench(), duration_s=5.0) < 0.5e9


def _fake_huge_mat73(path: Path, samples: int) -> None:
    """A v7.3 file whose datasets claim ``samples`` samples, none of them stored."""
    t = np.arange(1000) / 1e4
    save_mat(path, {"t": t, "Uch": t, "Vch": t, "Vph": t, "Vpv": t}, version="7.3")
    with h5py.File(path, "r+") as f:
        for name in ("t", "Uch", "Vch", "Vph", "Vpv"):
            del f[name]
            dset = f.create_dataset(name, shape=(1, samples), dtype="f8", chunks=(1, 1 << 16))
            dset.attrs["MATLAB_class"] = np.bytes_("double")


def test_hdf5_mat_claiming_more_than_memory(kit: SimpleNamespace, run_cli: Callable[..., Any],
                                            tmp_path: Path) -> None:
    """An HDF5 .mat whose datasets claim 4e9 samples ended in MemoryError: its sizes are
    checked against the memory before anything is read."""
    data = tmp_path / "data"
    data.mkdir()
    fake = data / "data_uch.mat"
    _fake_huge_mat73(fake, 4_000_000_000)
    assert fake.stat().st_size < 1_000_000
    before = kit.hashes(data)
    r = run_cli("identify", data, "--out", tmp_path / "out")
    # The folder's verdict quotes the file's (after the progress line "reading data_uch.mat").
    kit.assert_one_line_verdict(r, "identify", str(data), "no recording in this folder",
                                str(fake), "its datasets claim 149.0 GiB",
                                "has shape (1, 4000000000)", "GiB this machine has available")
    assert [ln for ln in r.err.splitlines() if "error" in ln] == [r.verdict()]
    assert kit.hashes(data) == before and not (tmp_path / "out").exists()


# ----------------------------------------------------------------- bench files

BENCH_CASES = [
    ("true.sercalo", "dc_gain_rad_per_a = { h = 1e300, v = 0.5 }",
     "'true.sercalo.dc_gain_rad_per_a' = 1e+300 is not a physical value"),
    ("nominal.converter", "fs_hz = 1e300", "'nominal.converter.fs_hz' = 1e+300"),
    ("true.converter", "fs_hz = 2e6", "'true.converter.fs_hz' = 2e+06 Hz is above 1e+06 Hz"),
    ("nominal.converter", "bits = 0", "'nominal.converter.bits' = 0 must be a whole number "
                                      "from 1 to 32"),
    ("true.converter", "bits = 64", "'true.converter.bits' = 64"),
    ("true.sercalo", "damping_ratio = { h = -0.001, v = 0.001 }",
     "'true.sercalo.damping_ratio.h' = -0.001 must be >= 0 (a damping ratio)"),
    ("true.sercalo", "r_coil_ohm = { h = 0.0, v = 8.3 }",
     "'true.sercalo.r_coil_ohm.h' = 0 must be > 0 (a resistance)"),
    ("true.sercalo", "l_coil_h = { h = 1e-300, v = 1e-4 }", "'true.sercalo.l_coil_h' = 1e-300"),
    ("nominal.sercalo", "resonance_hz = { h = -411.0, v = 252.5 }",
     "'nominal.sercalo.resonance_hz.h' = -411 must be > 0 (a resonance)"),
    ("true.quad_diode", "gain_v_per_rad = { h = 0.0, v = 35.9 }",
     "'true.quad_diode.gain_v_per_rad.h' = 0 must be non-zero (a gain"),
    ("true.newport", "internal_delay_s = 1.0", "'true.newport.internal_delay_s' = 1 s is 10000 "
                                              "samples at 10000 Hz, more than 1000"),
    ("true.converter", "dac_delay_samples = 100000000000000000000",
     "'true.converter.dac_delay_samples' = 100000000000000000000 must be from 0 to 1000"),
]


@pytest.mark.parametrize(("table", "line", "needle"), BENCH_CASES,
                         ids=[c[1].split(" =")[0] + "-" + c[0] for c in BENCH_CASES])
def test_bench_value_out_of_range(kit: SimpleNamespace, run_cli: Callable[..., Any],
                                  tmp_path: Path, table: str, line: str, needle: str,
                                  no_computation: None) -> None:
    """A bench file with 1e300 ended in numba's TypingError: the value is checked on load,
    naming the file and the key."""
    toml = tmp_path / "b.toml"
    toml.write_text(f'base = "default"\n[{table}]\n{line}\n')
    before = kit.hashes(tmp_path)
    r = run_cli("simulate", tmp_path / "out", "--params", toml, "--duration", "5",
                "--experiments", "data_uch")
    _one_line(kit, r, "simulate", f"{toml}: ", needle)
    assert kit.hashes(tmp_path) == before


def test_every_bench_number_at_1e300_is_refused_on_load(tmp_path: Path) -> None:
    """Every number of [nominal] and [true], at 1e300 and at -1e300: refused as read."""
    bench = default_bench()
    toml = tmp_path / "b.toml"
    for section in ("nominal", "true"):
        for key, value, _field in walk_fields(getattr(bench, section), ""):
            table, name = key.rsplit(".", 1)
            for big in ("1e300", "-1e300"):
                text = (f"{{ h = {big}, v = {big} }}" if hasattr(value, "h")
                        else f"[{big}]" if isinstance(value, tuple) else big)
                toml.write_text(f'base = "default"\n[{section}.{table}]\n{name} = {text}\n')
                with pytest.raises(ParamsError) as err:
                    load_bench(toml)
                assert f"'{section}.{key}" in str(err.value), str(err.value)


def test_packaged_and_test_benches_pass_the_ranges() -> None:
    for name in ("default_bench.toml", "real_bench.toml"):
        load_bench(name)
    for path in sorted((Path(__file__).parents[1] / "data" / "benches").glob("*.toml")):
        load_bench(path)


# ----------------------------------------------------------------- paths that are not UTF-8


@pytest.mark.parametrize(("command", "argv", "option"), [
    ("identify", ["{bad}", "--out", "{out}"], "DATA"),
    ("study", ["--data", "{bad}", "--out", "{out}"], "--data"),
    ("budget", ["{bad}", "--out", "{out}"], "DATA"),
    ("simulate", ["{out}", "--params", "{badfile}"], "--params"),
])
def test_path_that_is_not_utf8(kit: SimpleNamespace, run_cli: Callable[..., Any],
                               stage_data: Path, tmp_path: Path, command: str, argv: list[str],
                               option: str) -> None:
    """A Latin-1 folder name ended in UnicodeEncodeError in identify and study."""
    root = os.fsencode(tmp_path)
    bad = os.fsdecode(root + b"/d\xe9j\xe0")  # "déjà" in Latin-1
    os.symlink(stage_data, bad)
    badfile = os.fsdecode(root + b"/b\xe9nch.toml")
    shutil.copy(Path(__file__).parents[1] / "data" / "benches" / "stiff_bench.toml", badfile)
    before = kit.hashes(stage_data)
    out = tmp_path / "out"
    r = run_cli(command, *[a.format(bad=bad, badfile=badfile, out=out) for a in argv])
    shown = "d\\xe9j\\xe0" if option != "--params" else "b\\xe9nch.toml"
    _one_line(kit, r, command, shown, f"the {option} path is not valid UTF-8", "byte 0xe9")
    assert kit.hashes(stage_data) == before and not out.exists()


# ----------------------------------------------------------------- excite


@pytest.mark.parametrize(("extra", "needles"), [
    (["--resolution", "0.0001"], ("--resolution 0.0001 Hz", "1e+08 samples",
                                  "longest is 1048576 samples", "--phases schroeder")),
    (["--resolution", "0.0001", "--phases", "schroeder"],
     ("--resolution 0.0001 Hz x 1 period", "longer than the 8388608 samples")),
    (["--resolution", "0.01", "--periods", "6", "--transient-periods", "3"],
     ("x 9 periods", "9e+06 samples")),
    (["--kind", "noise", "--duration", "1000"], ("--duration 1000 s x 1 period",)),
])
def test_excite_record_too_long(kit: SimpleNamespace, run_cli: Callable[..., Any],
                                tmp_path: Path, extra: list[str], needles: tuple[str, ...],
                                no_computation: None) -> None:
    """``excite --resolution 0.0001`` ran over 15 min at 4.3 GB: bounded by the record
    length it implies, refused before the design starts."""
    r = run_cli("excite", tmp_path / "out", *EXCITE, *extra)
    _one_line(kit, r, "excite", *needles)
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("band", [("1", "8000"), ("1", "5000"), ("6000", "7000")])
@pytest.mark.parametrize("kind", ["multisine", "noise", "chirp"])
def test_excite_band_above_nyquist(kit: SimpleNamespace, run_cli: Callable[..., Any],
                                   tmp_path: Path, band: tuple[str, str], kind: str,
                                   no_computation: None) -> None:
    """``excite --band 1 8000`` at 10 kHz stopped at 4999 Hz while the JSON said 8000."""
    r = run_cli("excite", tmp_path / "out", *EXCITE, "--band", *band, "--kind", kind)
    _one_line(kit, r, "excite", f"--band {band[0]} {band[1]}", "Nyquist frequency 5000 Hz",
              "below 5000 Hz")
    assert not (tmp_path / "out").exists()


def test_multisine_design_refuses_a_band_above_nyquist() -> None:
    from fsmbench.excite.design import design_multisine

    with pytest.raises(ValueError, match="must end below Nyquist"):
        design_multisine(input="Uch", band_hz=(1.0, 8000.0), resolution_hz=1.0,
                         amplitude_rms_v=0.01, fs_hz=1e4, phase_method="schroeder")


# ----------------------------------------------------------------- convert --fs


def test_convert_fs_contradicting_t(kit: SimpleNamespace, run_cli: Callable[..., Any],
                                    stage_data: Path, tmp_path: Path) -> None:
    """``convert --fs 5000`` on a 10 kHz file wrote fs 5000 beside a 10 kHz ``t``."""
    src = tmp_path / "data_uch.mat"
    shutil.copy(stage_data / "data_uch.mat", src)
    before = kit.hashes(tmp_path)
    dest = tmp_path / "data_uch.h5"
    r = run_cli("convert", src, dest, "--fs", "5000")
    _one_line(kit, r, "convert", str(src), "variable 't'", "sampled at 10000 Hz",
              "--fs is 5000 Hz")
    assert kit.hashes(tmp_path) == before and not dest.exists()
    assert kit.leftovers(tmp_path) == []
    # A rate that agrees with t (within the readers' 0.1 %) is what is written.
    assert run_cli("convert", src, dest, "--fs", "10000").status == 0
    with h5py.File(dest, "r") as f:
        assert f["entry"].attrs["fs_hz"] == 10000.0
