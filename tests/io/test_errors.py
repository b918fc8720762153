"""Bad input: every case raises a RecordingError naming the file and the variable.

Bad files are written with scipy.io.savemat (v5) or raw h5py in MATLAB's v7.3
layout (see conftest), never with fsmbench's own writers, which refuse them.
"""

from __future__ import annotations

import pickle
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from fsmbench.io.errors import RecordingError, SaturationWarning
from fsmbench.io.recording import make_recording, read_recording, validate_recording

N = 5000
T = np.arange(N) / 1e4  # s
LSB = 20.0 / 2**16  # V, the seed's 16-bit ±10 V ADC
RAW_FORMATS = ["mat5", "mat73"]


@pytest.fixture
def write_raw(
    write_v5: Callable[..., Path], write_v73_by_hand: Callable[..., Path]
) -> Callable[[str, Path, dict[str, Any]], Path]:
    def write(fmt: str, path: Path, variables: dict[str, Any]) -> Path:
        return (write_v5 if fmt == "mat5" else write_v73_by_hand)(path, variables)

    return write


def _signals(**changes: Any) -> dict[str, Any]:
    """t, Vph, Vpv (V) for N samples, with some variables replaced or removed (None)."""
    rng = np.random.default_rng(7)
    out: dict[str, Any] = {"t": T.copy(), "Vph": np.round(rng.standard_normal(N) * 3000) * LSB,
                           "Vpv": np.round(rng.standard_normal(N) * 3000) * LSB}
    for key, value in changes.items():
        if value is None:
            out.pop(key)
        else:
            out[key] = value
    return out


def _with(values: np.ndarray, index: Any, new: Any) -> np.ndarray:
    out = values.copy()
    out[index] = new
    return out


_VPH = _signals()["Vph"]
_NAN12 = _with(_VPH, [4031, *range(4100, 4111)], np.nan)
_SHIFTED = _with(T, slice(100, None), T[100:] + 0.5e-4)

# (case id, variables, variable named, message after "variable 'X' ")
CASES: list[tuple[str, dict[str, Any], str, str]] = [
    ("nan", _signals(Vph=_NAN12), "Vph",
     "holds 12 NaN values (first at index 4031, t = 0.4031 s)"),
    ("inf", _signals(Vpv=_with(_VPH, [10, 20], [np.inf, -np.inf])), "Vpv",
     "holds 2 Inf values (first at index 10, t = 0.001 s)"),
    ("nan-and-inf", _signals(Vph=_with(_VPH, [3, 9], [np.inf, np.nan])), "Vph",
     "holds 1 NaN and 1 Inf values (first at index 3, t = 0.0003 s)"),
    ("one-nan", _signals(Vph=_with(_VPH, 4999, np.nan)), "Vph",
     "holds 1 NaN value (first at index 4999, t = 0.4999 s)"),
    ("matrix", _signals(Vph=np.zeros((N, 2))), "Vph",
     "is a 5000x2 matrix, not a vector (N x 1 or 1 x N)"),
    ("text", _signals(Vpv="0.1 0.2"), "Vpv", "holds text ('0.1 0.2'), not samples"),
    ("complex", _signals(Vph=_VPH + 1j), "Vph",
     "holds complex values (dtype complex128); a signal must be real"),
    ("logical", _signals(Vph=_VPH > 0), "Vph", "holds logical (true/false) values, not numbers"),
    ("struct", _signals(Vph={"data": _VPH}), "Vph", "holds a struct (fields: data), not samples"),
    ("unequal", _signals(Vpv=_VPH[:-1]), "Vpv", "has 4999 samples but variable 't' has 5000"),
    ("t-missing", _signals(t=None), "t", "is missing: a recording needs its time vector t, in s"),
    ("t-decreasing", _signals(t=_with(T, 100, T[98])), "t",
     "is not increasing at index 100: t[99] = 0.0099 s, t[100] = 0.0098 s"),
    ("t-repeated", _signals(t=_with(T, 100, T[99])), "t",
     "is not increasing at index 100: t[99] = 0.0099 s, t[100] = 0.0099 s"),
    ("t-non-uniform", _signals(t=_SHIFTED), "t",
     "is not uniformly sampled at index 100: t[99] = 0.0099 s, t[100] = 0.01005 s, a step of "
     "0.00015 s where the median step is 0.0001 s (1.5 periods); t strays 46.2 µs (46.2 % of "
     "a period) from a uniform grid, more than clock jitter (0.1 %)"),
    ("t-nan", _signals(t=_with(T, 3, np.nan)), "t", "holds 1 NaN value (first at index 3)"),
    ("too-short", {"t": np.array([0.0]), "Vph": np.array([0.1])}, "t",
     "holds 1 sample; a recording needs at least 2"),
]


@pytest.mark.parametrize("fmt", RAW_FORMATS)
@pytest.mark.parametrize(("case", "variables", "variable", "problem"), CASES,
                         ids=[c[0] for c in CASES])
def test_bad_content(
    tmp_path: Path, write_raw: Callable[[str, Path, dict[str, Any]], Path], fmt: str,
    case: str, variables: dict[str, Any], variable: str, problem: str,
) -> None:
    path = write_raw(fmt, tmp_path / f"{case}.mat", variables)
    with pytest.raises(RecordingError) as err:
        read_recording(path)
    assert str(err.value).startswith(f"{path}: variable '{variable}' {problem}")
    assert err.value.variable == variable
    assert err.value.file == str(path)


@pytest.mark.parametrize("fmt", RAW_FORMATS)
def test_cell_is_not_a_signal(
    tmp_path: Path, write_raw: Callable[[str, Path, dict[str, Any]], Path], fmt: str
) -> None:
    if fmt == "mat5":
        cell = np.empty((1, 2), dtype=object)
        cell[0, 0], cell[0, 1] = "a", "b"
        path = write_raw(fmt, tmp_path / "rec.mat", _signals(Vph=cell))
    else:
        from fsmbench.io.matwrite import save_mat  # a v7.3 cell needs references

        path = save_mat(tmp_path / "rec.mat", _signals(Vph=["a", "b"]), version="7.3")
    with pytest.raises(RecordingError, match=rf"^{path}: variable 'Vph' holds a cell array of "
                       r"2 elements, not samples$"):
        read_recording(path)


@pytest.mark.parametrize("fmt", RAW_FORMATS)
def test_missing_required_variable_lists_the_present_ones(
    tmp_path: Path, write_raw: Callable[[str, Path, dict[str, Any]], Path], fmt: str
) -> None:
    path = write_raw(fmt, tmp_path / "data_uch.mat", _signals(Uch=_VPH))  # no Vch
    with pytest.raises(RecordingError) as err:
        read_recording(path)
    msg = str(err.value)
    assert msg.startswith(f"{path}: variable 'Vch' is missing; data_uch needs "
                          "t, Uch, Vch, Vph, Vpv (the file holds: ")
    held = msg.split("the file holds: ")[1].rstrip(")").split(", ")
    assert sorted(held) == ["Uch", "Vph", "Vpv", "t"]


@pytest.mark.parametrize("fmt", RAW_FORMATS)
@pytest.mark.parametrize(("relative_error", "ok"), [(0.9e-3, True), (1.1e-3, False)])
def test_time_step_tolerance_is_1e3_of_the_median_step(
    tmp_path: Path, write_raw: Callable[[str, Path, dict[str, Any]], Path], fmt: str,
    relative_error: float, ok: bool,
) -> None:
    t = _with(T, slice(100, None), T[100:] + relative_error * 1e-4)
    path = write_raw(fmt, tmp_path / "rec.mat", _signals(t=t))
    if ok:
        assert read_recording(path).sizes["t"] == N
    else:
        with pytest.raises(RecordingError, match=r"variable 't' is not uniformly sampled at "
                           r"index 100"):
            read_recording(path)


@pytest.mark.parametrize("fmt", RAW_FORMATS)
def test_integer_classes_are_numbers(
    tmp_path: Path, write_raw: Callable[[str, Path, dict[str, Any]], Path], fmt: str
) -> None:
    codes = (np.arange(N) % 11 - 5).astype(np.int16)  # -5 .. 5 V: inside the ADC range
    if fmt == "mat73":  # the hand writer knows double only: store int16 as MATLAB would
        path = write_raw(fmt, tmp_path / "rec.mat", _signals())
        import h5py

        with h5py.File(path, "r+") as f:
            del f["Vph"]
            f.create_dataset("Vph", data=codes.reshape(1, -1))
            f["Vph"].attrs["MATLAB_class"] = np.bytes_("int16")
    else:
        path = write_raw(fmt, tmp_path / "rec.mat", _signals(Vph=codes))
    ds = read_recording(path)
    assert ds["Vph"].dtype == np.float64
    assert np.array_equal(ds["Vph"].values, codes.astype(np.float64))


# --------------------------------------------------------------------------- not a MAT-file
@pytest.mark.parametrize(
    ("content", "problem"),
    [
        (b"", "is empty (0 bytes), not a MAT-file or HDF5 file"),
        (b"t,Vph\n0,0.1\n", "is not a MAT-file (v4, v5/v7, v7.3) or HDF5 file: it holds text "
                            "('t,Vph\\n0,0.1\\n')"),
        (b"\x89PNG\r\n\x1a\n" + bytes(200), "is not a MAT-file (v4, v5/v7, v7.3) or HDF5 file: "
                                           "it holds a PNG image"),
        (b"%PDF-1.7\n" + bytes(50), "is not a MAT-file (v4, v5/v7, v7.3) or HDF5 file: it "
                                   "holds a PDF document"),
        (bytes(range(1, 256)), "is not a MAT-file (v4, v5/v7, v7.3) or HDF5 file: it holds "
                               "unrecognised binary data"),
    ],
    ids=["empty", "csv", "png", "pdf", "binary"],
)
def test_not_a_mat_file(tmp_path: Path, content: bytes, problem: str) -> None:
    path = tmp_path / "data_uch.mat"
    path.write_bytes(content)
    with pytest.raises(RecordingError) as err:
        read_recording(path)
    assert str(err.value).startswith(f"{path}: {problem}")
    assert err.value.variable is None


@pytest.mark.parametrize(("fmt", "kind"), [("mat5", "MATLAB v5/v7"), ("mat73", "MATLAB v7.3")])
def test_truncated_file(
    tmp_path: Path, write_raw: Callable[[str, Path, dict[str, Any]], Path], fmt: str, kind: str
) -> None:
    path = write_raw(fmt, tmp_path / "rec.mat", _signals())
    path.write_bytes(path.read_bytes()[: 2 * 1024])
    with pytest.raises(RecordingError, match=rf"^{path}: cannot be read as a {kind} file"):
        read_recording(path)


# --------------------------------------------------------------------------- saturation
def _rails(n_top: int, n_bottom: int, *, near: float = 1.0) -> np.ndarray:
    """Vph with n_top samples at +10 V - near*LSB and n_bottom at -10 V."""
    x = _VPH.copy()
    x[:n_top] = 10.0 - near * LSB
    x[n_top:n_top + n_bottom] = -10.0
    return x


@pytest.mark.parametrize("fmt", RAW_FORMATS)
def test_saturation_warns_with_the_fraction(
    tmp_path: Path, write_raw: Callable[[str, Path, dict[str, Any]], Path], fmt: str
) -> None:
    path = write_raw(fmt, tmp_path / "rec.mat", _signals(Vph=_rails(30, 7)))
    with pytest.warns(SaturationWarning) as caught:
        ds = read_recording(path)
    assert ds.sizes["t"] == N  # a warning, not an error
    [w] = [c.message for c in caught if isinstance(c.message, SaturationWarning)]
    assert isinstance(w, SaturationWarning)
    assert (w.file, w.variable, w.count, w.total) == (str(path), "Vph", 37, N)
    assert w.fraction == 37 / N
    assert str(w).startswith(f"{path}: variable 'Vph' has 37 of 5000 samples (0.74 %) at the "
                             "ADC rails (|v| >= 9.99954 V)")


@pytest.mark.parametrize(("near", "warns"), [(1.5, True), (1.6, False)])
def test_saturation_threshold_is_1_5_lsb_below_the_rail(near: float, warns: bool) -> None:
    x = _VPH.copy()
    x[0] = 10.0 - near * LSB
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        make_recording({"t": T, "Vph": x, "Vpv": -x}, experiment="x")
    sat = [c.message for c in caught if isinstance(c.message, SaturationWarning)]
    assert [(w.variable, w.count) for w in sat] == ([("Vph", 1), ("Vpv", 1)] if warns else [])


def test_saturation_only_for_adc_signals_and_follows_the_range() -> None:
    x = _rails(10, 10)
    with warnings.catch_warnings():
        warnings.simplefilter("error", SaturationWarning)
        ds = make_recording({"t": T, "Uch": x, "Va": x, "other": x}, experiment="x")
        make_recording({"t": T, "Vph": x}, experiment="x", adc_range_v=40.0)
    with pytest.warns(SaturationWarning, match=r"^mine: variable 'Vch' has 20 of 5000 samples "
                      r"\(0\.4 %\)"):
        validate_recording(ds.rename({"Uch": "Vch"}), origin="mine")


# --------------------------------------------------------------------------- the classes
def test_recording_error_is_a_value_error_and_pickles() -> None:
    err = RecordingError("data_uch.mat", "holds 12 NaN values (first at index 4031, "
                         "t = 0.4031 s)", variable="Vph")
    assert isinstance(err, ValueError)
    assert str(err) == ("data_uch.mat: variable 'Vph' holds 12 NaN values (first at index "
                        "4031, t = 0.4031 s)")
    back = pickle.loads(pickle.dumps(err))
    assert (str(back), back.file, back.variable, back.problem) == (
        str(err), err.file, err.variable, err.problem)
    plain = RecordingError(Path("x.mat"), "is empty")
    assert str(plain) == "x.mat: is empty"
    assert str(pickle.loads(pickle.dumps(plain))) == "x.mat: is empty"


def test_saturation_warning_pickles() -> None:
    w = SaturationWarning("x.mat", "Vph", 3, 12, 9.99954)
    assert issubclass(SaturationWarning, UserWarning)
    back = pickle.loads(pickle.dumps(w))
    assert (str(back), back.percent) == (str(w), 25.0)
