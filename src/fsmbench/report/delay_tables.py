"""The delay tables of seed 2.3 and 2.4: phase-only and joint estimates, and the 4QD amplifier."""

from __future__ import annotations

from fsmbench.ident.newport import NewportDynamics
from fsmbench.ident.sercalo import SercaloIdentification
from fsmbench.report.html import Block, Note, Table

__all__ = ["sensor_note", "sercalo_delay_blocks"]


def sercalo_delay_blocks(s: SercaloIdentification) -> list[Block]:
    """The Sercalo's delays: each path's phase-only and joint estimates, and what was removed."""
    rows = []
    for k, d in enumerate(s.delays):
        joint = s.joint_delays[k] if k < len(s.joint_delays) else None
        rows.append((
            f"{d.input} → {d.output}",
            f"{1e3 * d.delay_s:.4f} ± {1e3 * d.std_s:.1g}",
            "–" if joint is None else f"{1e3 * joint.delay_s:.4f} ± {1e3 * joint.delay_std_s:.1g}",
            "–" if joint is None else ("a weaker mode" if "weaker mode" in joint.method
                                       else "a constant"),
            f"{d.band_hz[0]:.0f}–{d.band_hz[1]:.0f}"))
    removed = ("delay removed before the vector fit" if not s.joint_delays else
               "delay removed before the vector fit (the 4QD amplifier's lag in)")
    rows.append((removed, f"{1e3 * s.delay_s:.4f} ± {1e3 * s.delay_std_s:.1g}", "–", "–", "–"))
    blocks: list[Block] = [Table(
        caption=("Sercalo delays: from the phase alone (Bode's gain–phase relation), and fitted "
                 "jointly with each path's own poles, the hold, a fractional delay and the 4QD "
                 "amplifier as the converters sample them (± one standard deviation)"),
        header=("path", "phase only [ms]", "joint fit [ms]", "modes above the band",
                "band [Hz]"),
        rows=tuple(rows))]
    if s.joint_delays:
        blocks.append(Note(
            "The joint fit keeps the 4QD amplifier's lag apart from the delay: "
            f"{s.joint_delays[0].sensor.sentence()}. Its pure delay is "
            f"{1e3 * s.pure_delay_s:.4f} ms; the plant model, which has no sensor block, "
            f"uses {1e3 * s.delay_s:.4f} ms. The phase-only estimate reads the modes' "
            "approach to their asymptotes as extra lag; the joint fit models them."))
    elif s.joint_delay_skipped:
        blocks.append(Note(f"No joint delay fit ({s.joint_delay_skipped})."))
    return blocks


def sensor_note(dyn: NewportDynamics) -> Note:
    """What the Newport's lines say of the 4QD amplifier, one sentence per axis."""
    parts = [f"{axis}: {fit.sensor.sentence()}" for axis, fit in dyn.axes.items()
             if fit.sensor is not None]
    return Note("The 4QD amplifier in the Newport fits (its coherent band reaches twice the "
                "Sercalo's): " + "; ".join(parts) + ". The delays in the table are the pure "
                "ones; the internal lag compares effective delays (the amplifier's lag in) of "
                "the Newport and Sercalo paths, which share the amplifier.")
