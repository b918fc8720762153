"""The 4QD of a previous identification, for the limit check of an excitation.

A real bench's 4QD compresses away from its centre, and the packaged bench
model's 4QD is linear: ``fsmbench excite --identification DIR`` takes the 4QD
that ``identify`` measured (ESRF study 2.1, ``DIR/identification.json``): each
axis's small-signal gain ``a`` and cubic term ``c`` of ``V = b + a θ + c θ³``
over the calibration's swing. The bench model's single compression is the
larger of the two axes' at the wider half-swing ``θ_fs``,
``k = −(c/a) θ_fs²`` (> 0: less than linear). A straight-line calibration
(no significant cubic) gives a linear 4QD, which the limit report says.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

from fsmbench.bench.axes import PerAxis
from fsmbench.bench.params import BenchParams
from fsmbench.ident.load import read_identification_json
from fsmbench.io.errors import RecordingError

__all__ = ["quad_diode_from_identification", "with_identified_quad_diode"]


def _number(qd: dict, axis: str, key: str, path: Path) -> float:
    value = qd.get(axis, {}).get(key) if isinstance(qd.get(axis), dict) else None
    if not isinstance(value, (int, float)) or not math.isfinite(value):
        raise RecordingError(path, f"has no finite diagnostics.qd.{axis}.{key}; it was not "
                                   "written by this version of fsmbench identify")
    return float(value)


def with_identified_quad_diode(params: BenchParams, folder: str | Path, *,
                               option: str = "--bench") -> BenchParams:
    """``params`` with the 4QD's gains and compression from ``FOLDER/identification.json``
    (``option``: what named the folder, as the user typed it, for the messages).

    Raises
    ------
    RecordingError
        The folder holds no identification, or its 4QD was not calibrated
        (``data_cal_pd_h``/``data_cal_pd_v`` missing or failed), in one line.
    """

    path, ident = read_identification_json(folder, option=option)
    return quad_diode_from_identification(params, ident, path=path, option=option)


def quad_diode_from_identification(params: BenchParams, ident: dict, *, path: Path,
                                   option: str = "--bench") -> BenchParams:
    """``params`` with the 4QD of a parsed ``identification.json`` (``path`` names it in errors;
    ``option``, what named its folder as the user typed it)."""
    diagnostics = ident.get("diagnostics")
    qd = diagnostics.get("qd") if isinstance(diagnostics, dict) else None
    if not isinstance(qd, dict) or not all(a in qd for a in "hv"):
        raise RecordingError(path, "has no 4QD calibration of both axes (data_cal_pd_h and "
                                   "data_cal_pd_v were missing or failed); run identify with "
                                   f"them, or leave out {option}")
    gain = {a: _number(qd, a, "gain_v_per_rad", path) for a in "hv"}
    cubic = {a: _number(qd, a, "cubic_v_per_rad3", path) for a in "hv"}
    half_swing = max(_number(qd, a, "beam_angle_range_rad", path) / 2 for a in "hv")
    compression = max(-cubic[a] / gain[a] * half_swing**2 for a in "hv")
    quad = dataclasses.replace(
        params.quad_diode, gain_v_per_rad=PerAxis(h=gain["h"], v=gain["v"]),
        nonlinearity_pct=max(100.0 * compression, 0.0),
        nonlinearity_full_swing_rad=half_swing if half_swing > 0
        else params.quad_diode.nonlinearity_full_swing_rad)
    return dataclasses.replace(params, quad_diode=quad)
