"""The identification's values with their total uncertainty and its largest part.

Every value of ``identification.json``'s ``uncertainty`` becomes a row: the
quantity in words, the value, its total standard deviation, the largest of
the parts it is made of (with its share of the variance) and, where the data
do not determine the value directly, how it is derived. The part names of
:mod:`fsmbench.ident.uncertainty` are shown in words.
"""

from __future__ import annotations

import math

from fsmbench.ident.result import Identification
from fsmbench.ident.uncertainty import Uncertain
from fsmbench.report.html import Table

__all__ = ["PART_WORDS", "display", "total_cells", "uncertainty_table"]

#: Each part of an uncertainty in words.
PART_WORDS = {
    "noise": "measurement noise",
    "misfit": "model misfit beyond the noise",
    "sampled_model": "sampled against continuous model",
    "leakage": "the Welch window's leakage near the modes",
    "transient": "a transient left in the periods",
    "compression": "the 4QD compression's correction",
    "distortion": "nonlinear distortion",
    "unresolved_lags": "lags a delay fit cannot tell from a delay (a bound)",
    "unresolved_sensor": "the 4QD amplifier's unknown order (a bound)",
    "qd_amplifier_lag": "the 4QD amplifier's measured lag",
    "definition": "the quantity's definition",
    "current_amp": "the current-amplifier gain",
    "calibration": "another calibration",
}

#: Display unit and scale (display units per SI unit) of each SI unit.
_DISPLAY = {"s": ("µs", 1e6), "A/V": ("mA/V", 1e3), "1": ("", 1.0)}


def display(u: Uncertain) -> tuple[str, float]:
    """The unit a reader sees and its scale: µs for delays, mA/V for the current amplifier."""
    return _DISPLAY.get(u.unit, (u.unit, 1.0))


def _fmt(x: float) -> str:
    return f"{x:.6g}" if math.isfinite(x) else "–"


def total_cells(u: Uncertain | None, scale: float) -> tuple[str, str]:
    """``(± total, largest part with its share of the variance)`` for a table row."""
    if u is None or not math.isfinite(u.std):
        return "–", "–"
    part = u.largest_part
    share = (float(u.parts[part]) ** 2 / u.std**2) if part and u.std > 0 else math.nan
    words = PART_WORDS.get(part, part)
    return (f"{u.std * scale:.2g}",
            f"{words} ({100 * share:.0f} %)" if math.isfinite(share) else words)


#: Rows in the order of the ESRF study's section 2 (2.1 4QD ... 2.4 Newport), then delays.
_SECTION_ORDER = ("qd_gain", "qd_diode_gain", "current_amp", "sercalo.", "newport_gain",
                  "newport.", "delay_s", "effective_delay_s")


def _order(key: str) -> tuple[int, str]:
    rank = next((i for i, p in enumerate(_SECTION_ORDER) if key.startswith(p)),
                len(_SECTION_ORDER))
    return rank, key


def uncertainty_table(result: Identification) -> Table | None:
    """Every identified value with its total std and its largest part (None when none)."""
    if not result.uncertainty:
        return None
    rows = []
    for _key, u in sorted(result.uncertainty.items(), key=lambda kv: _order(kv[0])):
        unit, scale = display(u)
        total, largest = total_cells(u, scale)
        name = u.quantity[0].upper() + u.quantity[1:]
        rows.append((f"{name} [{unit or '1'}]", _fmt(u.value * scale), total, largest,
                     u.derived or "measured"))
    return Table(
        caption=("Every identified value with its total uncertainty: ± is one standard "
                 "deviation, the root sum of squares of its parts (measurement noise and each "
                 "systematic error the identification can bound); the largest part is named "
                 "with its share of the variance"),
        header=("quantity", "value", "± total", "largest part (share of the variance)",
                "how the data give it"),
        rows=tuple(rows),
        note=("A bound (a lag a delay fit cannot tell from a delay) is a uniform interval; its "
              "standard deviation is its half-width over √3. identification.json holds every "
              "part (docs/results.md)."))
