"""Where each term of the error budget comes from, and what would change it.

Every row of the budget is one of

``measured``
    its input spectrum was measured in the recordings (the 4QD noise of the
    open-loop huddle tests, the Sercalo DAC's error in the closed-loop ones);
``derived``
    computed from measured or exactly known quantities (quantisation from the
    converters' resolution, the geometric cross terms);
``assumed``
    a bench-file value no recording checked (the Newport's angle noise from its
    datasheet, the room's drifts, the frame's expansion, the Attocube's noise).

An assumed row names the measurement that would replace it. The limiting
row's *remedies* are computed, not written: each scales that row as the
change would (an invar frame, a DAC two bits finer …) and gives the total it
would leave, so the verdict's next step carries a number.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from fsmbench.budget.table import BudgetRow

__all__ = ["PROVENANCE_KINDS", "Remedy", "RowProvenance", "remedies", "row_provenance"]

#: The kinds a reported number can have, in the order a reader trusts them.
PROVENANCE_KINDS = ("measured", "derived", "predicted", "assumed")

# Thermal expansion of invar 36 and of the aluminium the seed's frame is made of [1/K]
# (seed 4.4: "≈1 µm/K (aluminium), 60 nm/K (invar)" for the 50 mm frame).
_INVAR_PER_K = 1.2e-6


@dataclass(frozen=True)
class RowProvenance:
    """One budget row's origin.

    Attributes
    ----------
    kind : {"measured", "derived", "assumed"}
    detail : str
        What it comes from, in words.
    replace_by : str
        For an assumed row: the measurement that would replace it; else empty.
    """

    kind: str
    detail: str
    replace_by: str = ""


def row_provenance(name: str, spectra_origin: Mapping[str, str], *,
                   frame_expansion_per_k: float) -> RowProvenance:
    """The origin of the budget row ``name`` (see the module notes).

    Parameters
    ----------
    name : str
        The row's display name (:data:`fsmbench.budget.table.SOURCE_IDS`).
    spectra_origin : mapping
        ``ErrorBudget.spectra_origin``: where the 4QD and Sercalo DAC spectra came from,
        and (``newport_angle``, ``attocube``) the noise levels the noise model measured.
    frame_expansion_per_k : float
        The bench file's frame expansion [1/K] (named in the detail).
    """
    qd = spectra_origin.get("qd", "")
    dac = spectra_origin.get("sercalo_dac", "")
    if name == "4QD electronic noise":
        if qd.startswith("huddle tests"):
            return RowProvenance("measured", f"4QD noise spectrum of the {qd}")
        return RowProvenance("assumed", "the bench file's white 4QD noise",
                             "an open-loop huddle test (data_huddle_test_1, 2 or 4)")
    if name == "Sercalo DAC quantisation":
        if dac.startswith("measured"):
            return RowProvenance("measured", f"the DAC's error {dac}")
        return RowProvenance("derived", "white q²/12 from the DAC's resolution (bench file)")
    if name in ("ADC quantisation (4QD channels)", "Newport DAC quantisation"):
        return RowProvenance("derived", "white q²/12 from the converters' resolution")
    if name == "geometric cross terms between angle sources":
        return RowProvenance("derived", "the angle sources combined through the path geometry")
    if name == "Newport angle noise":
        if spectra_origin.get("newport_angle", "").startswith("measured"):
            return RowProvenance("measured", spectra_origin["newport_angle"])
        return RowProvenance("assumed", "the FSM-300 datasheet's noise-equivalent angle "
                                        "(bench file)",
                             "the Newport's metrology outputs Vnh, Vnv recorded with the mirror "
                             "still (a huddle test with Vnh, Vnv)")
    if name == "air refractive index":
        return RowProvenance("assumed", "the bench file's room temperature, pressure and "
                                        "humidity drifts and sensor errors",
                             "the compensation unit's temperature, pressure and humidity "
                             "logged during a huddle test")
    if name == "metrology frame expansion":
        return RowProvenance("assumed", "the bench file's room temperature drift and frame "
                                        f"expansion ({frame_expansion_per_k:.3g}/K)",
                             "a huddle test of at least 1 h (several frame time constants) or "
                             "a temperature log of the frame")
    if name == "Attocube noise":
        if spectra_origin.get("attocube", "").startswith("measured"):
            return RowProvenance("measured", spectra_origin["attocube"])
        return RowProvenance("assumed", "the bench file's Attocube noise",
                             "Va of a huddle test above 100 Hz (the interferometer's floor)")
    if name == "Attocube resolution":
        return RowProvenance("assumed", "the Attocube's output resolution (bench file)")
    return RowProvenance("derived", "computed from the other rows")


@dataclass(frozen=True)
class Remedy:
    """A change that shrinks one row, and the total it would leave.

    Attributes
    ----------
    row : str
        The row it acts on.
    change : str
        The change, in words.
    row_after_m, total_after_m : float
        That row and the budget's total after the change [m rms].
    """

    row: str
    change: str
    row_after_m: float
    total_after_m: float

    def sentence(self) -> str:
        """One clause a user reads."""
        return (f"{self.change} would bring the total to {self.total_after_m * 1e9:.3g} nm "
                f"({self.row} {self.row_after_m * 1e9:.3g} nm)")


def _after(row: BudgetRow, amplitude: float) -> float:
    """The row's rms when its source's amplitude is scaled by ``amplitude``.

    A linear row scales with it; an angle source's piston part too, its
    geometric (quadratic) part with its square.
    """
    if row.quadratic_rms_m is None or row.perpendicular_rms_m is None:
        return row.rms_m * amplitude
    return math.hypot(row.perpendicular_rms_m * amplitude, row.quadratic_rms_m * amplitude**2)


def remedies(rows: Sequence[BudgetRow], row: str, *, frame_expansion_per_k: float,
             bits: int) -> list[Remedy]:
    """The standard changes that act on ``row``, each with the total it would leave.

    Parameters
    ----------
    rows : sequence of BudgetRow
        The budget's rows.
    row : str
        The row to act on (usually the limiting one).
    frame_expansion_per_k : float
        The frame's expansion now [1/K].
    bits : int
        The converters' resolution now [bit].

    Notes
    -----
    The geometric cross terms between angle sources are left as they are
    (a change of one source moves them by less than the row it acts on).
    """
    by_name = {r.name: r for r in rows}
    if row not in by_name:
        return []
    target = by_name[row]
    out: list[Remedy] = []

    def add(change: str, amplitude: float) -> None:
        after = _after(target, amplitude)
        total = math.sqrt(sum(r.rms_m**2 for r in rows if r.name != row) + after**2)
        out.append(Remedy(row, change, after, total))

    if row == "metrology frame expansion" and frame_expansion_per_k > _INVAR_PER_K:
        add(f"an invar frame ({_INVAR_PER_K:.2g}/K instead of {frame_expansion_per_k:.3g}/K)",
            _INVAR_PER_K / frame_expansion_per_k)
    elif row in ("Sercalo DAC quantisation", "ADC quantisation (4QD channels)",
                 "Newport DAC quantisation"):
        # The quantisation step, and the error it leaves, halve with every bit.
        which = "DAC" if "DAC" in row else "ADC"
        add(f"a {bits + 2}-bit {which} instead of {bits} bits", 0.25)
    elif row == "4QD electronic noise":
        add("a 4QD amplifier with half the noise", 0.5)
    return out
