"""What the commands print on stdout: tables in words and units, from a stage's document."""

from __future__ import annotations

import math
from typing import Any

__all__ = ["design_table"]

_CONTROLLER_NAMES = {"seed_controller": "the study's controller (9.2)",
                     "fsmbench_controller": "fsmbench's controller",
                     "newport_controller": "Newport alignment (10.2)"}


def _num(value: Any, fmt: str, unit: str = "") -> str:
    """A rounded value with its unit; "none" when absent, "∞" when infinite."""
    if value is None:
        return "none"
    x = float(value)
    if math.isinf(x):
        return "∞" if x > 0 else "-∞"
    return f"{x:{fmt}}{unit}"


def design_table(payload: dict[str, Any]) -> list[str]:
    """What ``fsmbench design`` prints: each loop's margins in words and units, the verdicts.

    The 1 Hz objective of ESRF study 6.1 (|S| ≤ e_max / y_max) is the Sercalo loop's: the
    Newport's alignment loop (10.2) is shown with its margins only.
    """
    bound = payload.get("objective", {}).get("sensitivity_bound_at_1hz")
    head = ["controller", "axis", "stable", "gain margin", "phase margin", "crossover",
            "|S(1 Hz)|", "objective 6.1"]
    body = []
    for name, words in _CONTROLLER_NAMES.items():
        loop = payload.get(name)
        if not loop:
            continue
        sercalo = name != "newport_controller"
        for a in ("h", "v"):
            ax = loop[a]
            verdict = ("–" if not sercalo or bound is None else
                       "met" if ax.get("sensitivity_at_1hz", math.inf) <= bound else "missed")
            body.append([words, a, "yes" if ax.get("stable") else "NO",
                         _num(ax.get("gain_margin_db"), ".1f", " dB"),
                         _num(ax.get("phase_margin_deg"), ".1f", "°"),
                         _num(ax.get("crossover_hz"), ".1f", " Hz"),
                         _num(ax.get("sensitivity_at_1hz"), ".2e"), verdict])
    widths = [max(len(str(x)) for x in col) for col in zip(head, *body, strict=True)]
    lines = ["  ".join(str(c).ljust(w) for c, w in zip(row, widths, strict=True)).rstrip()
             for row in (head, *body)]
    if bound is not None:
        lines.append(f"Objective 6.1 (the Sercalo loop): |S(1 Hz)| ≤ {bound:.0e}; the Newport "
                     "loop aligns, it does not reject the sample motion.")
    twin = payload.get("closed_loop_twin")
    if twin is None:
        lines.append(f"fsmbench's controller not simulated: {payload.get('closed_loop_skipped')}")
    else:
        lines.append(
            f"fsmbench's controller simulated on {twin['bench']}: tracking error "
            + ", ".join(f"{a} {1e6 * v:.3g} µrad rms (linear prediction "
                        f"{1e6 * twin['predicted_rms_rad'][a]:.3g} µrad)"
                        for a, v in twin["tracking_error_rms_rad"].items()))
    return lines
