"""Multisine lines on mains harmonics: the rule for odd grids, the warning, --skip-mains."""

from __future__ import annotations

import json
import math
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fsmbench.cli import main
from fsmbench.excite.design import crest_factor, design_multisine, grid_lines, multisine_period
from fsmbench.excite.files import read_excitation, write_excitation
from fsmbench.excite.mains import (
    mains_free_resolution,
    mains_hits,
    mains_warning,
    odd_grids_avoid_mains,
)

FS_HZ = st.sampled_from([5000.0, 10000.0, 20000.0])
MAINS_HZ = st.sampled_from([50.0, 60.0])


def _hits_on_grid(*, fs_hz: float, n: int, mains_hz: float, grid: str) -> int:
    """Excited lines on harmonics over the whole band below Nyquist."""
    res = fs_hz / n
    k = grid_lines(band_hz=(res / 2, fs_hz / 2), resolution_hz=res, fs_hz=fs_hz,
                   grid=grid)  # type: ignore[arg-type]
    return int(mains_hits(k * res, resolution_hz=res, mains_hz=mains_hz).sum())


@settings(max_examples=200, deadline=None)
@given(fs=FS_HZ, mains=MAINS_HZ, n=st.integers(min_value=20, max_value=200_000))
def test_odd_grids_avoid_mains_exactly_when_the_rule_says(fs: float, mains: float,
                                                          n: int) -> None:
    res = fs / n
    q = Fraction(int(mains)) * n / int(fs)  # F / r, exactly
    avoid = odd_grids_avoid_mains(resolution_hz=res, mains_hz=mains)
    assert avoid == (q.denominator == 1 and q.numerator % 2 == 0)
    if avoid:
        for grid in ("odd", "odd-odd"):
            assert _hits_on_grid(fs_hz=fs, n=n, mains_hz=mains, grid=grid) == 0
    else:
        # Some harmonic m <= 2 b (q = a / b) is within half a line of an odd line (module
        # notes); checked on odd lines past Nyquist too, the band's limit aside.
        top = math.ceil(2 * q.denominator * q) + 2
        odd = np.arange(1, top + 1, 2) * res
        assert mains_hits(odd, resolution_hz=res, mains_hz=mains).any()
    if q.denominator == 1 and q.numerator % 2 == 1 and mains < fs / 2:
        # An odd q: harmonic 1 is on line q, an odd line.
        assert _hits_on_grid(fs_hz=fs, n=n, mains_hz=mains, grid="odd") > 0


@settings(max_examples=100, deadline=None)
@given(fs=FS_HZ, mains=MAINS_HZ, n=st.integers(min_value=20, max_value=100_000))
def test_the_suggested_resolution_avoids_every_harmonic(fs: float, mains: float,
                                                        n: int) -> None:
    res = fs / n
    r = mains_free_resolution(resolution_hz=res, mains_hz=mains, fs_hz=fs)
    assert r is not None and r <= res * (1 + 1e-12)
    n_new = round(fs / r)
    assert abs(fs / r - n_new) < 1e-6  # a whole number of samples per period
    assert odd_grids_avoid_mains(resolution_hz=r, mains_hz=mains)
    if n_new <= 400_000:  # the grid over the whole band, kept small enough to build
        assert _hits_on_grid(fs_hz=fs, n=n_new, mains_hz=mains, grid="odd") == 0


def test_full_grid_warning_names_the_harmonics_and_the_fix() -> None:
    d = design_multisine(input="Uch", band_hz=(1.0, 2000.0), resolution_hz=1.0,
                         amplitude_rms_v=0.005, fs_hz=10000.0, mains_hz=50.0,
                         phase_method="schroeder")
    assert mains_warning(d) == (
        "Uch multisine: 40 excited lines on harmonics of the 50 Hz mains (50, 100, …, 2000 Hz),"
        " where the bench's mains pickup stays as a bias after averaging; --odd puts every "
        "harmonic of 50 Hz on a non-excited line (50 Hz is 50 lines of 1 Hz, an even number), "
        "or --skip-mains leaves them out")
    odd = design_multisine(input="Uch", band_hz=(1.0, 2000.0), resolution_hz=1.0,
                           amplitude_rms_v=0.005, fs_hz=10000.0, mains_hz=50.0, grid="odd",
                           phase_method="schroeder")
    assert mains_warning(odd) is None
    # 60 Hz at 1 Hz: 60 lines, even; at 2 Hz, 50 Hz is 25 lines: the odd grid is hit on 50,
    # 150, ... and the fix is a resolution.
    coarse = design_multisine(input="Ucv", band_hz=(1.0, 1000.0), resolution_hz=2.0,
                              amplitude_rms_v=0.005, fs_hz=10000.0, mains_hz=50.0,
                              grid="odd", phase_method="schroeder")
    w = mains_warning(coarse)
    assert w is not None and w.startswith("Ucv multisine: 10 excited lines on harmonics of the "
                                          "50 Hz mains (50, 150, …, 950 Hz)")
    assert "--odd with --resolution 1.92308 puts every harmonic of 50 Hz on a non-excited line "\
           "(50 Hz is 26 lines, an even number; at 2 Hz it is 25)" in w
    assert mains_warning(design_multisine(
        input="Uch", band_hz=(1.0, 2000.0), resolution_hz=1.0, amplitude_rms_v=0.005,
        fs_hz=10000.0, mains_hz=0.0, phase_method="schroeder")) is None


def test_skip_mains_leaves_the_harmonics_out(tmp_path: Path) -> None:
    d = design_multisine(input="Uch", band_hz=(1.0, 500.0), resolution_hz=1.0,
                         amplitude_rms_v=0.005, fs_hz=10000.0, mains_hz=60.0, skip_mains=True)
    assert d.skipped_lines_hz == tuple(60.0 * m for m in range(1, 9))
    assert d.lines_hz.size == 500 - 8 and not set(d.lines_hz) & set(d.skipped_lines_hz)
    assert mains_warning(d) is None
    # Nothing on the skipped lines: exactly zero up to the FFT's rounding.
    spec = np.abs(np.fft.rfft(d.one_period())) / d.period_samples
    assert spec[[60 * m for m in range(1, 9)]].max() < 1e-12 * d.line_amplitude_v
    # The crest factor was minimised on the lines left: 1.39 (measured), Schroeder's
    # phases on them give 2.18, random ones 3.6; 1.6 fails if the optimisation was skipped.
    assert d.crest_factor < 1.6
    assert d.crest_factor == pytest.approx(crest_factor(multisine_period(
        harmonics=np.rint(d.lines_hz).astype(int), phases_rad=d.phases_rad,
        n_samples=d.period_samples, amplitude_v=1.0)), rel=1e-12)
    write_excitation(d, tmp_path)
    back = read_excitation(tmp_path)
    assert back.mains_hz == 60.0 and back.skipped_lines_hz == d.skipped_lines_hz
    meta = json.loads((tmp_path / "excitation.json").read_text())["multisine"]["mains"]
    assert meta["lines_on_harmonics_hz"] == [] and meta["warning"] is None


def test_nothing_left_is_refused() -> None:
    with pytest.raises(ValueError, match="every line between 49 and 51 Hz is on a harmonic"):
        design_multisine(input="Uch", band_hz=(49.0, 51.0), resolution_hz=5.0,
                         amplitude_rms_v=0.005, fs_hz=10000.0, mains_hz=50.0, skip_mains=True)


def test_cli_warns_once_and_stores_the_warning(tmp_path: Path,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "ms"
    assert main(["excite", str(out), "--input", "Uch", "--band", "1", "300",
                 "--amplitude-rms", "0.005", "--phases", "schroeder"]) == 0
    captured = capsys.readouterr()
    warnings = [x for x in captured.err.splitlines() if "warning" in x]
    assert warnings == ["fsmbench excite: warning: Uch multisine: 6 excited lines on harmonics "
                        "of the 50 Hz mains (50, 100, …, 300 Hz), where the bench's mains "
                        "pickup stays as a bias after averaging; --odd puts every harmonic of "
                        "50 Hz on a non-excited line (50 Hz is 50 lines of 1 Hz, an even "
                        "number), or --skip-mains leaves them out"]
    meta = json.loads((out / "excitation.json").read_text())
    assert warnings[0].endswith(meta["multisine"]["mains"]["warning"])
    assert meta["multisine"]["mains"]["lines_on_harmonics_hz"] == [50, 100, 150, 200, 250, 300]
    assert "4QD linear in this model: compression not limited" in captured.out
    skip = tmp_path / "skip"
    assert main(["excite", str(skip), "--input", "Uch", "--band", "1", "300",
                 "--amplitude-rms", "0.005", "--mains-hz", "60", "--skip-mains"]) == 0
    captured = capsys.readouterr()
    assert "warning" not in captured.err
    assert "5 lines on harmonics of the 60 Hz mains left out (60, 120, …, 300 Hz)" \
        in captured.out
    assert main(["excite", str(tmp_path / "x"), "--input", "Uch", "--amplitude-rms", "0.005",
                 "--mains-hz", "-50"]) == 2
    assert "is not 0 or a positive frequency in Hz" in capsys.readouterr().err
