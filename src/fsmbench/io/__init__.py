"""Recordings in and out: MATLAB MAT-files (v4, v5/v7, v7.3) and NeXus archives.

A recording is an ``xarray.Dataset`` with one float64 variable per signal on
the dimension ``"t"`` (see :mod:`fsmbench.io.recording`); the signals and the
ESRF study's experiments are described in :mod:`fsmbench.io.signals`. Every write
is atomic (:mod:`fsmbench.atomic`); every bad input raises a
:class:`RecordingError` naming the file and the variable.
"""

from fsmbench.atomic import atomic_path, atomic_write_bytes, atomic_write_text
from fsmbench.io.errors import RecordingError, SaturationWarning
from fsmbench.io.matfile import FileFormat, detect_format, load_mat
from fsmbench.io.matwrite import MatVersion, mat5_header, mat73_header, save_mat
from fsmbench.io.nexus import is_nexus, read_nexus, write_nexus
from fsmbench.io.recording import (
    RecordingFormat,
    find_experiments,
    make_recording,
    read_recording,
    validate_recording,
    write_recording,
)
from fsmbench.io.signals import (
    ADC_SIGNALS,
    DAC_SIGNALS,
    EXPERIMENTS,
    SIGNALS,
    TIME,
    ExperimentInfo,
    SignalInfo,
)
from fsmbench.io.trailing import TrailingBytesWarning

__all__ = [
    "ADC_SIGNALS",
    "DAC_SIGNALS",
    "EXPERIMENTS",
    "SIGNALS",
    "TIME",
    "ExperimentInfo",
    "FileFormat",
    "MatVersion",
    "RecordingError",
    "RecordingFormat",
    "SaturationWarning",
    "SignalInfo",
    "TrailingBytesWarning",
    "atomic_path",
    "atomic_write_bytes",
    "atomic_write_text",
    "detect_format",
    "find_experiments",
    "is_nexus",
    "load_mat",
    "make_recording",
    "mat5_header",
    "mat73_header",
    "read_nexus",
    "read_recording",
    "save_mat",
    "validate_recording",
    "write_nexus",
    "write_recording",
]
