"""The ESRF study's huddle tests as a protocol (its section 3): the five configurations,
the records' names, the trimming its 3.2 applies, and the bands' JSON ids.

Below both the identification (which fits the noise to these records,
:mod:`fsmbench.ident.noise_model`) and the budget (which analyses them,
:mod:`fsmbench.budget.huddle`).
"""

from __future__ import annotations

import math
import re

import numpy as np
import xarray as xr
from numpy.typing import NDArray

__all__ = ["HUDDLE_CONFIGS", "HUDDLE_NAME", "band_id", "huddle_number", "trim_huddle"]

FloatArray = NDArray[np.float64]

#: Seed Table 3: test number → (closed loop, compensation unit, aluminium shielding).
HUDDLE_CONFIGS: dict[int, tuple[bool, bool, bool]] = {
    1: (False, False, False), 2: (False, True, False), 3: (True, True, False),
    4: (False, True, True), 5: (True, True, True),
}
#: A huddle test's record name; its group is the test number.
HUDDLE_NAME = re.compile(r"^data_huddle_test_(\d+)$")


def band_id(name: str) -> str:
    """A band's JSON id: ``"drift"``, ``"total"``, ``"3–50 Hz"`` → ``"band_3_50_hz"``.

    Decimal points become ``p`` (``"0.5–3 Hz"`` → ``"band_0p5_3_hz"``).
    """
    slug = re.sub(r"[^0-9a-z]+", "_", name.lower().replace(".", "p")).strip("_")
    return f"band_{slug}" if slug[:1].isdigit() else slug


def huddle_number(name: str) -> int:
    """Test number of ``data_huddle_test_<n>`` (1–5, ESRF study Table 3); ValueError otherwise."""
    m = HUDDLE_NAME.match(name)
    if m is None or int(m.group(1)) not in HUDDLE_CONFIGS:
        raise ValueError(f"{name!r} is not a huddle test of ESRF study Table 3 "
                         "(data_huddle_test_1..5)")
    return int(m.group(1))


def trim_huddle(ds: xr.Dataset, *, name: str, t0_s: float = 1.0,
                duration_s: float | None = None) -> dict[str, FloatArray]:
    """The ESRF study's 3.2 trimming: drop ``t < t0``, restart t at 0, keep ``tend·fs`` samples.

    ``duration_s`` None keeps the whole rest of the record (the ESRF study's
    records hold 100 s after the trim, its ``tend``).

    Returns ``t`` [s], ``Vph``, ``Vpv`` [V] and ``Va`` [m] (not mean-removed),
    each shape (N,). ValueError (naming ``name``) if a signal is missing or
    fewer than two seconds remain (two of the ESRF study's 1 s Welch windows).
    """
    missing = [v for v in ("Vph", "Vpv", "Va") if v not in ds]
    if missing:
        raise ValueError(f"{name}: missing {missing} (ESRF study 3.1 loads t, Vph, Vpv, Va)")
    fs = float(ds.attrs["fs_hz"])
    t = np.asarray(ds["t"].values, dtype=float)
    keep = t >= t0_s
    n = int(keep.sum()) if duration_s is None else min(int(keep.sum()), round(duration_s * fs))
    if n < 2 * math.ceil(fs):
        raise ValueError(f"{name}: {n / fs:.3g} s left after removing t < {t0_s:g} s; the "
                         f"huddle analysis needs at least 2 s (two 1 s Welch windows)")
    out = {"t": t[keep][:n] - t[keep][0]}
    for v in ("Vph", "Vpv", "Va"):
        out[v] = np.asarray(ds[v].values, dtype=float)[keep][:n]
    return out
