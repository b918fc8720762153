"""The Newport's identified model in words and tables (section 2.4 of the report).

Its dynamics fitted jointly with the delay against the FSM-300 datasheet,
what the ESRF study's constant gain leaves out at 1 kHz, or, when the
dynamics could not be fitted, its signed constant gains. Internal to
:mod:`fsmbench.report.sections.ident`, which assembles the section.
"""

from __future__ import annotations

import numpy as np

from fsmbench.bench.params import NewportDatasheet
from fsmbench.ident.newport import NewportDynamics, NewportIdentification
from fsmbench.report.html import Note, Table

__all__: list[str] = []  # internal to fsmbench.report.sections.ident

# Each axis's Newport command and 4QD output.
_NEWPORT_PATHS = (("h", "Unh", "Vph"), ("v", "Unv", "Vpv"))


def _newport_dynamics_table(n: NewportIdentification, dyn: NewportDynamics, *,
                            datasheet: NewportDatasheet) -> Table:
    """Each identified axis's second order and delay (± one std) against the datasheet.

    Parameters
    ----------
    n : NewportIdentification
        The Newport identification.
    dyn : NewportDynamics
        Its fitted dynamics (``n.dynamics``).
    datasheet : NewportDatasheet
        The FSM-300 datasheet's bandwidths [Hz] and peaking [dB], shown in brackets.
    """
    rows = []
    for a, inp, out in _NEWPORT_PATHS:
        if a not in n.identified_axes:
            continue  # its record was missing: the bench file's model stood in
        fit = dyn.axes[a]
        rows.append((
            f"{inp} → {out}", f"{fit.gain_v_per_v:.5f} ± {fit.gain_std_v_per_v:.1g}",
            f"{n.seed_gain_v_per_v[a]:.5f}",
            f"{fit.natural_freq_hz:.1f} ± {fit.natural_freq_std_hz:.1g}",
            f"{fit.damping_ratio:.3f} ± {fit.damping_std:.1g}",
            f"{1e3 * fit.delay_s:.4f} ± {1e3 * fit.delay_std_s:.1g}",
            f"{1e3 * dyn.internal_delay_s(a):.4f}",
            f"{dyn.amplitude_bandwidth_hz[a]:.0f} ({datasheet.amplitude_bandwidth_hz:g})",
            f"{dyn.phase_bandwidth_hz[a]:.0f} ({datasheet.phase_bandwidth_hz:g})",
            f"{dyn.peaking_db[a]:.2f} (≤ {datasheet.peaking_max_db:g})"))
    return Table(
        caption=("Newport dynamics fitted jointly with the delay (± one standard "
                 "deviation), against the FSM-300 datasheet in brackets; the phase "
                 f"bandwidth is where the poles' lag and the internal lag reach "
                 f"{dyn.phase_lag_deg:g}°, after removing the converter's share of the delay "
                 f"(the Sercalo path's, {1e3 * dyn.converter_delay_s:.3f} ms)"),
        header=("path", "static gain [V/V]", "ESRF study's constant gain [V/V]",
                "natural frequency [Hz]", "damping ratio", "delay [ms]",
                "internal lag [ms]", "−3 dB bandwidth [Hz]", "60° phase bandwidth [Hz]",
                "peaking [dB]"),
        rows=tuple(rows))


def _newport_constant_gain_note(n: NewportIdentification, dyn: NewportDynamics) -> Note:
    """What the ESRF study's constant gain leaves out: the fitted response at 1 kHz."""
    at_1k = {a: abs(dyn.axes[a].response(np.array([1000.0]), delay=False)[0])
             / abs(n.gain_v_per_v[a]) for a in n.identified_axes}
    return Note(
        "The ESRF study models the Newport as a constant gain (its mean over 10–100 Hz); the "
        "fitted response at 1 kHz is "
        + " and ".join(f"{v:.2f} ({a})" for a, v in at_1k.items())
        + " of the static gain, so the identified plant carries the Newport's dynamics "
        "instead.", ref="errata E19")


def _newport_gains_table(n: NewportIdentification) -> Table:
    """The signed constant gain of each identified axis and the band it is averaged on."""
    return Table(
        caption="Newport gains (signed)",
        header=("path", "gain [V/V]", "averaging band [Hz]"),
        rows=tuple((f"{inp} → {out}", f"{n.gain_v_per_v[a]:.5f}",
                    f"{n.band_hz[0]:g}–{n.band_hz[1]:g}")
                   for a, inp, out in _NEWPORT_PATHS if a in n.identified_axes))
