"""Fixtures for the fsmbench.io tests.

Bad files are written here *without* fsmbench's writers (scipy.io.savemat and
raw h5py), so a reader bug cannot hide behind the matching writer bug.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import pytest
import scipy.io
import xarray as xr

from fsmbench.io import SIGNALS, make_recording

FS_HZ = 1e4  # seed: fs = 1e4
N = 2000  # samples per test recording (0.2 s)
# A header as MATLAB R2020a on Linux writes it (hdf5storage docs quote the same form).
MATLAB_HEADER = (
    b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: Mon Sep 21 10:00:00 2020 "
    b"HDF5 schema 1.00 ."
)


def quantised(rng: np.random.Generator, n: int, *, scale_v: float = 1.0) -> np.ndarray:
    """ADC-like samples, in V: 16-bit steps of 20 V / 2**16 = 305 µV."""
    lsb = 20.0 / 2**16
    return np.round(rng.standard_normal(n) * scale_v / lsb) * lsb


@pytest.fixture
def fs_hz() -> float:
    """Sampling frequency of the test recordings, in Hz."""
    return FS_HZ


@pytest.fixture
def n_samples() -> int:
    """Samples per test recording."""
    return N


@pytest.fixture
def adc_noise(rng: np.random.Generator) -> Callable[..., np.ndarray]:
    """``adc_noise(n, scale_v=1.0)``: ADC-like samples, in V, shape (n,)."""

    def make(n: int = N, scale_v: float = 1.0) -> np.ndarray:
        return quantised(rng, n, scale_v=scale_v)

    return make


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(20200924)  # the seed's date


@pytest.fixture
def time_s() -> np.ndarray:
    """t = (0:N-1)/fs, in s, shape (N,)."""
    return np.arange(N) / FS_HZ


@pytest.fixture
def all_signals(rng: np.random.Generator) -> dict[str, np.ndarray]:
    """Every signal of the ESRF study's table, N samples each (V; Va in m)."""
    out = {name: quantised(rng, N) for name in SIGNALS}
    out["Va"] = rng.standard_normal(N) * 1e-9
    return out


@pytest.fixture
def recording(all_signals: dict[str, np.ndarray]) -> xr.Dataset:
    """A valid recording of all signals, experiment data_rep_h."""
    return make_recording(all_signals, fs_hz=FS_HZ, experiment="data_rep_h")


@pytest.fixture
def write_v5() -> Callable[..., Path]:
    """Write variables with scipy.io.savemat directly (v5, columns)."""

    def write(path: Path, variables: Mapping[str, Any], *, oned_as: str = "column") -> Path:
        scipy.io.savemat(path, dict(variables), oned_as=oned_as, do_compression=True)
        return path

    return write


def _matlab_dataset(group: h5py.Group, name: str, value: Any) -> None:
    """One variable as MATLAB -v7.3 stores it (value given in MATLAB's shape)."""
    if isinstance(value, str):
        # char 1xL: uint16 codes, HDF5 shape (L, 1)
        codes = np.array([ord(c) for c in value], dtype=np.uint16).reshape(-1, 1)
        ds = group.create_dataset(name, data=codes)
        ds.attrs["MATLAB_class"] = np.bytes_("char")
        ds.attrs["MATLAB_int_decode"] = np.int32(2)
        return
    if isinstance(value, dict):
        sub = group.create_group(name)
        sub.attrs["MATLAB_class"] = np.bytes_("struct")
        for key, item in value.items():
            _matlab_dataset(sub, key, item)
        return
    arr = np.asarray(value)
    if arr.ndim == 1:
        arr = arr.reshape(-1, 1)  # a MATLAB column vector
    data = np.ascontiguousarray(arr.T)  # HDF5 holds MATLAB's dims reversed
    cls = "double"
    if arr.dtype.kind == "c":
        pair = np.empty(data.shape, dtype=[("real", "<f8"), ("imag", "<f8")])
        pair["real"], pair["imag"] = data.real, data.imag
        data = pair
    elif arr.dtype.kind == "b":
        data, cls = data.astype(np.uint8), "logical"
    ds = group.create_dataset(name, data=data)
    ds.attrs["MATLAB_class"] = np.bytes_(cls)


@pytest.fixture
def write_v73_by_hand() -> Callable[..., Path]:
    """Write variables the way MATLAB -v7.3 does, with raw h5py.

    512-byte userblock holding the MAT header (text padded to 116 bytes,
    8 zero bytes, version 0x0200, 'IM'), one dataset per variable in
    MATLAB's reversed-axes layout with a MATLAB_class attribute. Values are
    given in MATLAB's shape; 1-D arrays are columns (HDF5 shape (1, N)).
    """

    def write(path: Path, variables: Mapping[str, Any]) -> Path:
        with h5py.File(path, "w", userblock_size=512) as f:
            for name, value in variables.items():
                _matlab_dataset(f, name, value)
        with open(path, "r+b") as fh:
            fh.write(MATLAB_HEADER.ljust(116, b" ") + b"\x00" * 8 + b"\x00\x02IM")
        return path

    return write


@pytest.fixture
def snapshot() -> Callable[[Path], tuple[bytes, int]]:
    """A file's bytes and modification time (ns), to prove it was not touched."""

    def take(path: Path) -> tuple[bytes, int]:
        return path.read_bytes(), os.stat(path).st_mtime_ns

    return take
