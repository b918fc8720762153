"""fsmbench.io.matfile (detection, reading) and fsmbench.io.matwrite (writing): MAT v4/v5/v7.3."""

from __future__ import annotations

import io
import zlib
from collections.abc import Callable
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import pytest
import scipy.io

from fsmbench.io import matwrite
from fsmbench.io.errors import RecordingError
from fsmbench.io.matfile import HDF5_SIGNATURE, detect_format, load_mat
from fsmbench.io.matwrite import mat5_header, mat73_header, save_mat

VERSIONS = ["5", "7.3"]


# --------------------------------------------------------------------------- detection
@pytest.mark.parametrize(("version", "expected"), [("5", "mat5"), ("7.3", "mat73")])
def test_detect_written_versions(tmp_path: Path, version: str, expected: str) -> None:
    path = save_mat(tmp_path / "x.bin", {"a": np.arange(3.0)}, version=version)  # type: ignore[arg-type]
    assert detect_format(path) == expected


def test_detect_v4_v5_hand_v73_and_plain_hdf5(
    tmp_path: Path, write_v73_by_hand: Callable[..., Path]
) -> None:
    scipy.io.savemat(tmp_path / "v4.mat", {"a": np.arange(3.0)}, format="4")
    scipy.io.savemat(tmp_path / "v5.mat", {"a": np.arange(3.0)}, format="5")
    write_v73_by_hand(tmp_path / "v73.mat", {"a": np.arange(3.0)})
    with h5py.File(tmp_path / "plain.mat", "w") as f:
        f["a"] = np.arange(3.0)
    assert detect_format(tmp_path / "v4.mat") == "mat4"
    assert detect_format(tmp_path / "v5.mat") == "mat5"
    assert detect_format(tmp_path / "v73.mat") == "mat73"
    assert detect_format(tmp_path / "plain.mat") == "hdf5"


def test_detect_missing_file_is_file_not_found(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError):
        detect_format(tmp_path / "nope.mat")


# --------------------------------------------------------------------------- round trips
def _same(a: Any, b: Any) -> None:
    """Exact equality: type, dtype, shape and bytes for arrays."""
    assert type(a) is type(b), (a, b)
    if isinstance(a, np.ndarray):
        assert a.dtype == b.dtype and a.shape == b.shape
        if a.dtype == object:
            for x, y in zip(a.ravel(), b.ravel(), strict=True):
                _same(x, y)
        else:
            assert a.tobytes(order="F") == b.tobytes(order="F")
    elif isinstance(a, dict):
        assert list(a) == list(b)
        for k in a:
            _same(a[k], b[k])
    elif isinstance(a, list):
        assert len(a) == len(b)
        for x, y in zip(a, b, strict=True):
            _same(x, y)
    else:
        assert a == b


SPECIAL = np.array([0.0, -0.0, 5e-324, 1e308, -np.pi, 1 / 3, np.nextafter(1.0, 2.0)])

ROUND_TRIPS: list[tuple[str, Any, Any]] = [
    ("column", SPECIAL, SPECIAL.reshape(-1, 1)),
    ("matrix", np.arange(6.0).reshape(2, 3), np.arange(6.0).reshape(2, 3)),
    ("row", np.arange(4.0).reshape(1, 4), np.arange(4.0).reshape(1, 4)),
    ("scalar", 2.5, np.array([[2.5]])),
    ("int16", np.int16(-3), np.array([[-3]], dtype=np.int16)),
    ("uint8_vec", np.arange(4, dtype=np.uint8), np.arange(4, dtype=np.uint8).reshape(-1, 1)),
    ("single", np.float32(1.5), np.array([[1.5]], dtype=np.float32)),
    ("complex", np.array([1 + 2j, -3.5 - 0.25j]), np.array([[1 + 2j], [-3.5 - 0.25j]])),
    ("complex_mat", np.array([[1j, 2], [3, 4j]]), np.array([[1j, 2], [3, 4j]])),
    ("logical", np.array([True, False, True]), np.array([[True], [False], [True]])),
    ("text", "Vph [V]", "Vph [V]"),
    ("empty_text", "", ""),
    ("names", ["Vph", "Vpv", "Va"], ["Vph", "Vpv", "Va"]),
    ("empty_cell", [], []),
    ("mixed_cell", ["a", np.array([1.0, 2.0])], ["a", np.array([[1.0], [2.0]])]),
    ("empty_matrix", np.zeros((0, 3)), np.zeros((0, 3))),
    (
        "struct",
        {"fs": 1e4, "unit": "rad/V", "G": np.array([[1.0, 2.0]]), "sub": {"z": 1j}},
        {"fs": np.array([[1e4]]), "unit": "rad/V", "G": np.array([[1.0, 2.0]]),
         "sub": {"z": np.array([[1j]])}},
    ),
]


@pytest.mark.parametrize("version", VERSIONS)
@pytest.mark.parametrize(("name", "value", "expected"), ROUND_TRIPS,
                         ids=[r[0] for r in ROUND_TRIPS])
def test_round_trip(tmp_path: Path, version: str, name: str, value: Any, expected: Any) -> None:
    path = save_mat(tmp_path / "x.mat", {name: value}, version=version)  # type: ignore[arg-type]
    _same(load_mat(path), {name: expected})


@pytest.mark.parametrize("version", VERSIONS)
def test_round_trip_many_variables_and_subset(tmp_path: Path, version: str) -> None:
    variables = {"a": np.arange(3.0), "b": "x", "c": {"d": 1.0}}
    path = save_mat(tmp_path / "x.mat", variables, version=version)  # type: ignore[arg-type]
    assert sorted(load_mat(path)) == ["a", "b", "c"]
    _same(load_mat(path, variables=["b"]), {"b": "x"})
    with pytest.raises(RecordingError, match=r"x\.mat: variable 'zz' is missing \(the file "
                       r"holds: b\)"):
        load_mat(path, variables=["b", "zz"])


@pytest.mark.parametrize("version", VERSIONS)
@pytest.mark.parametrize("compress", [True, False])
def test_compress_option_is_bit_exact(
    tmp_path: Path, version: str, compress: bool, adc_noise: Callable[..., np.ndarray]
) -> None:
    x = adc_noise(300_000)  # above the 512 KiB size where v5 samples compressibility
    path = save_mat(tmp_path / "x.mat", {"x": x}, version=version,  # type: ignore[arg-type]
                    compress=compress)
    assert load_mat(path)["x"].ravel().tobytes() == x.tobytes()
    small = path.stat().st_size < 0.8 * x.nbytes
    assert small == compress  # ADC data compress to ~0.4 of their size


def test_v5_incompressible_variable_is_stored_plain(tmp_path: Path) -> None:
    noise = np.random.default_rng(1).standard_normal(300_000)
    path = save_mat(tmp_path / "x.mat", {"x": noise, "t": np.arange(300_000) / 1e4})
    assert scipy.io.loadmat(path)["x"].ravel().tobytes() == noise.tobytes()
    assert path.stat().st_size > noise.nbytes  # the noise is stored plain, t compressed


# --------------------------------------------------------------------------- v5 layout
def test_v5_is_what_scipy_and_matlab_read(tmp_path: Path) -> None:
    x = np.linspace(-1, 1, 1000)
    path = save_mat(tmp_path / "x.mat", {"t": x, "names": ["Vph", "Vpv"]})
    assert scipy.io.matlab.matfile_version(path) == (1, 0)
    assert dict((n, (s, c)) for n, s, c in scipy.io.whosmat(path)) == {
        "t": ((1000, 1), "double"), "names": ((1, 2), "cell"),
    }
    raw = scipy.io.loadmat(path)
    assert raw["t"].dtype == np.float64 and raw["t"].shape == (1000, 1)
    assert raw["t"].ravel().tobytes() == x.tobytes()
    # compressed: the data element is an miCOMPRESSED (15) tag
    tag = np.frombuffer(path.read_bytes()[128:132], dtype=np.uint32)[0]
    assert tag == 15


def test_v5_reads_integer_valued_doubles_as_double(tmp_path: Path) -> None:
    # MATLAB stores integer-valued doubles in small integer types; load gives double.
    scipy.io.savemat(tmp_path / "x.mat", {"a": np.array([[1.0, 2.0, 3.0]])})
    a = load_mat(tmp_path / "x.mat")["a"]
    assert a.dtype == np.float64


def test_v5_complex_inside_struct_and_cell(tmp_path: Path) -> None:
    value = {"G": np.array([1 + 1j, 2]), "c": [np.array([3j]), "s"], "r": np.array([1.0])}
    path = save_mat(tmp_path / "x.mat", {"s": value, "re": np.array([4.0])})
    _same(load_mat(path), {
        "s": {"G": np.array([[1 + 1j], [2 + 0j]]), "c": [np.array([[3j]]), "s"],
              "r": np.array([[1.0]])},
        "re": np.array([[4.0]]),
    })


def test_v4_file_reads(tmp_path: Path) -> None:
    scipy.io.savemat(tmp_path / "x.mat", {"a": np.arange(4.0)}, format="4", oned_as="column")
    _same(load_mat(tmp_path / "x.mat"), {"a": np.arange(4.0).reshape(-1, 1)})


# --------------------------------------------------------------------------- v7.3 layout
def test_mat73_header_layout() -> None:
    header = mat73_header(platform="GLNXA64", created=0.0)
    assert len(header) == 128
    assert header.startswith(b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: ")
    assert header[:116].rstrip(b" ").endswith(b" HDF5 schema 1.00 .")
    assert header[116:124] == b"\x00" * 8
    assert header[124:128] == b"\x00\x02IM"
    assert b"Thu Jan 01 00:00:00 1970" in header[:116]  # an explicit time is UTC


def test_mat5_header_matches_scipy_layout(tmp_path: Path) -> None:
    header = mat5_header(platform="posix", created=86400.0)
    buf = io.BytesIO()
    scipy.io.savemat(buf, {"a": 1.0})
    reference = buf.getvalue()[:128]
    assert len(header) == 128
    assert header.startswith(b"MATLAB 5.0 MAT-file, Platform: posix, Created on: Fri Jan 02")
    assert header[116:] == reference[116:]  # subsys offset, version, endian: as scipy writes


@pytest.mark.parametrize("version", ["5", "7.3"])
def test_fixed_creation_time_gives_identical_bytes(tmp_path: Path, version: str) -> None:
    data = {"t": np.arange(5000) / 1e4, "Vph": np.sin(np.arange(5000.0))}
    a = save_mat(tmp_path / "a.mat", data, version=version, created=0.0)  # type: ignore[arg-type]
    b = save_mat(tmp_path / "b.mat", data, version=version, created=0.0)  # type: ignore[arg-type]
    assert a.read_bytes() == b.read_bytes()
    loaded = load_mat(a)
    for name, values in data.items():
        np.testing.assert_array_equal(loaded[name], values.reshape(-1, 1))


def test_mat73_file_layout(tmp_path: Path) -> None:
    n = 1000
    x = np.arange(n) / 1e4
    path = save_mat(tmp_path / "x.mat", {"t": x, "c": np.array([1j, 2]), "s": "ab",
                                         "names": ["Vph", "Vpv"], "st": {"a": 1.0}},
                    version="7.3")
    raw = path.read_bytes()
    assert raw.startswith(b"MATLAB 7.3 MAT-file, Platform: ")
    assert raw[124:128] == b"\x00\x02IM"
    assert raw[128:512] == b"\x00" * 384
    assert raw[512:520] == HDF5_SIGNATURE
    assert scipy.io.matlab.matfile_version(path) == (2, 0)
    with h5py.File(path, "r") as f:
        assert f.userblock_size == 512
        assert f["t"].shape == (1, n) and f["t"].dtype == np.float64
        assert f["t"].attrs["MATLAB_class"] == b"double"
        assert f["t"][0].tobytes() == x.tobytes()
        assert f["c"].dtype.names == ("real", "imag") and f["c"].shape == (1, 2)
        assert f["s"].dtype == np.uint16 and f["s"].shape == (2, 1)
        assert f["s"].attrs["MATLAB_class"] == b"char"
        assert f["s"].attrs["MATLAB_int_decode"] == 2
        assert f["names"].attrs["MATLAB_class"] == b"cell"
        assert f["names"].shape == (2, 1)  # 1x2 cell, reversed
        assert f["names"].dtype == h5py.ref_dtype
        assert f["st"].attrs["MATLAB_class"] == b"struct"
        assert [b"".join(x) for x in f["st"].attrs["MATLAB_fields"]] == [b"a"]
        assert "#refs#" in f


def test_reads_a_v73_file_laid_out_like_matlab(
    tmp_path: Path, write_v73_by_hand: Callable[..., Path]
) -> None:
    x = np.arange(5) / 1e4
    path = write_v73_by_hand(tmp_path / "m.mat", {
        "t": x, "row": x.reshape(1, -1), "m": np.arange(6.0).reshape(2, 3),
        "c": np.array([1 - 1j, 2j]), "b": np.array([True, False]), "s": "Vph",
        "st": {"a": np.array([[7.0]]), "u": "V"},
    })
    with h5py.File(path, "r") as f:  # check the fixture: MATLAB's (1, N) column
        assert f["t"].shape == (1, 5) and f["row"].shape == (5, 1)
    _same(load_mat(path), {
        "b": np.array([[True], [False]]),
        "c": np.array([[1 - 1j], [2j]]),
        "m": np.arange(6.0).reshape(2, 3),
        "row": x.reshape(1, -1),
        "s": "Vph",
        "st": {"a": np.array([[7.0]]), "u": "V"},
        "t": x.reshape(-1, 1),
    })


def test_reads_matlab_struct_array_and_cell(
    tmp_path: Path, write_v73_by_hand: Callable[..., Path]
) -> None:
    path = write_v73_by_hand(tmp_path / "m.mat", {})
    with h5py.File(path, "r+") as f:
        refs = f.create_group("#refs#")
        for i, v in enumerate([1.0, 2.0, 3.0]):
            refs[f"r{i}"] = np.array([[v]])
            refs[f"r{i}"].attrs["MATLAB_class"] = np.bytes_("double")
        # 1x2 struct array s(1).a = 1, s(2).a = 2: field 'a' is a (2, 1) array of refs
        g = f.create_group("s")
        g.attrs["MATLAB_class"] = np.bytes_("struct")
        g.create_dataset("a", data=np.array([[refs["r0"].ref], [refs["r1"].ref]],
                                            dtype=h5py.ref_dtype))
        # 1x1 cell {3}
        cell = f.create_dataset("c", data=np.array([[refs["r2"].ref]], dtype=h5py.ref_dtype))
        cell.attrs["MATLAB_class"] = np.bytes_("cell")
    _same(load_mat(path), {"c": [np.array([[3.0]])],
                           "s": [{"a": np.array([[1.0]])}, {"a": np.array([[2.0]])}]})


def test_matlab_empty_arrays(tmp_path: Path, write_v73_by_hand: Callable[..., Path]) -> None:
    path = write_v73_by_hand(tmp_path / "m.mat", {})
    with h5py.File(path, "r+") as f:
        for name, cls, dims in [("e", "double", [0, 3]), ("s", "char", [0, 0])]:
            ds = f.create_dataset(name, data=np.array(dims, dtype=np.uint64))
            ds.attrs["MATLAB_class"] = np.bytes_(cls)
            ds.attrs["MATLAB_empty"] = np.uint8(1)
    _same(load_mat(path), {"e": np.zeros((0, 3)), "s": ""})


def test_matlab_objects_are_refused_or_skipped(
    tmp_path: Path, write_v73_by_hand: Callable[..., Path]
) -> None:
    path = write_v73_by_hand(tmp_path / "plant.mat", {"Gi": np.array([[1.0]])})
    with h5py.File(path, "r+") as f:
        obj = f.create_dataset("G", data=np.zeros((1, 6), dtype=np.uint32))
        obj.attrs["MATLAB_class"] = np.bytes_("ss")
        obj.attrs["MATLAB_object_decode"] = np.int32(3)
    with pytest.raises(RecordingError, match=r"plant\.mat: variable 'G' holds a MATLAB object "
                       r"of class 'ss'.*only MATLAB can read"):
        load_mat(path)
    with pytest.warns(UserWarning, match=r"plant\.mat: variable 'G' left out"):
        out = load_mat(path, skip_unreadable=True)
    _same(out, {"Gi": np.array([[1.0]])})


# --------------------------------------------------------------------------- bad input
@pytest.mark.parametrize(
    ("variables", "error", "match"),
    [
        ({"_x": 1.0}, ValueError, "'_x' is not a valid MATLAB variable"),
        ({"1x": 1.0}, ValueError, "'1x' is not a valid MATLAB variable"),
        ({"a" * 64: 1.0}, ValueError, "at most 63 characters"),
        ({"s": {"bad field": 1.0}}, ValueError, "'bad field' is not a valid MATLAB"),
        ({"x": None}, TypeError, "variable 'x': cannot store NoneType"),
        ({"x": np.float16(1.0)}, TypeError, "variable 'x': cannot store"),
    ],
)
@pytest.mark.parametrize("version", VERSIONS)
def test_save_rejects(tmp_path: Path, version: str, variables: dict[str, Any],
                      error: type[Exception], match: str) -> None:
    with pytest.raises(error, match=match):
        save_mat(tmp_path / "x.mat", variables, version=version)  # type: ignore[arg-type]
    assert list(tmp_path.iterdir()) == []


def test_save_rejects_unknown_version(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="unknown MAT-file version '7'"):
        save_mat(tmp_path / "x.mat", {"a": 1.0}, version="7")  # type: ignore[arg-type]


# --------------------------------------------------------------------------- atomicity
def _fail_after_first(monkeypatch: pytest.MonkeyPatch, target: Any, attr: str,
                      exc: BaseException) -> None:
    original = getattr(target, attr)
    calls = {"n": 0}

    def failing(*args: Any, **kwargs: Any) -> Any:
        calls["n"] += 1
        if calls["n"] > 1:
            raise exc
        return original(*args, **kwargs)

    monkeypatch.setattr(target, attr, failing)


@pytest.mark.parametrize("exc", [OSError("disk full"), KeyboardInterrupt()])
@pytest.mark.parametrize(
    ("version", "target", "attr"),
    [("5", matwrite, "_deflate"), ("7.3", matwrite._H5Writer, "_numeric")],
)
def test_interrupted_write_leaves_nothing(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, version: str, target: Any, attr: str,
    exc: BaseException, adc_noise: Callable[..., np.ndarray],
) -> None:
    variables = {f"v{i}": adc_noise(1000) for i in range(4)}
    _fail_after_first(monkeypatch, target, attr, exc)
    with pytest.raises(type(exc)):
        save_mat(tmp_path / "x.mat", variables, version=version)  # type: ignore[arg-type]
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("version", VERSIONS)
def test_failed_overwrite_keeps_the_old_file(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, version: str,
    snapshot: Callable[[Path], tuple[bytes, int]],
) -> None:
    path = save_mat(tmp_path / "x.mat", {"a": np.arange(3.0)}, version=version)  # type: ignore[arg-type]
    before = snapshot(path)
    if version == "5":
        monkeypatch.setattr(matwrite, "_deflate", _raise(zlib.error("boom")))
    else:
        monkeypatch.setattr(matwrite._H5Writer, "_numeric", _raise(OSError("boom")))
    with pytest.raises((zlib.error, OSError)):
        save_mat(path, {"a": np.arange(5.0), "b": np.arange(4.0)}, version=version)  # type: ignore[arg-type]
    assert snapshot(path) == before
    assert [p.name for p in tmp_path.iterdir()] == ["x.mat"]


def _raise(exc: BaseException) -> Callable[..., Any]:
    def fail(*args: Any, **kwargs: Any) -> Any:
        raise exc

    return fail


@pytest.mark.parametrize("version", VERSIONS)
def test_reading_leaves_the_file_untouched(
    tmp_path: Path, version: str, snapshot: Callable[[Path], tuple[bytes, int]]
) -> None:
    path = save_mat(tmp_path / "x.mat", {"a": np.arange(3.0), "s": {"b": "c"}},
                    version=version)  # type: ignore[arg-type]
    before = snapshot(path)
    load_mat(path)
    assert snapshot(path) == before
    assert [p.name for p in tmp_path.iterdir()] == ["x.mat"]
