"""The delay tables of ESRF study 2.3 and 2.4: phase-only and joint estimates, the 4QD amplifier."""

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
            f"{d.input} → {d.output}", _us(d.delay_s, d.std_s),
            "–" if joint is None else _us(joint.delay_s, joint.delay_std_s),
            "–" if joint is None else ("a weaker mode" if "weaker mode" in joint.method
                                       else "a constant"),
            f"{d.band_hz[0]:.0f}–{d.band_hz[1]:.0f}"))
    removed = ("delay removed before the vector fit" if not s.joint_delays else
               "delay removed before the vector fit (the 4QD amplifier's lag in)")
    rows.append((removed, _us(s.delay_s, s.delay_std_s), "–", "–", "–"))
    blocks: list[Block] = [Table(
        caption=("Sercalo delays: from the phase alone (Bode's gain–phase relation), and fitted "
                 "jointly with each path's own poles, the hold, a fractional delay and the 4QD "
                 "amplifier as the converters sample them (± one standard deviation)"),
        header=("path", "phase only [µs]", "joint fit [µs]", "modes above the band",
                "band [Hz]"),
        rows=tuple(rows))]
    if s.joint_delays:
        est = s.joint_delays[0].sensor
        lowpass = est.lowpass
        whose = ("the 4QD amplifier resolved on the Newport's paths" if est.source == "Newport"
                 else "the bench file's 4QD amplifier")
        amp = (f"{whose} ({lowpass.bandwidth_hz:.0f} Hz, "
               f"{'first order' if lowpass.order == 1 else 'Butterworth'}) is kept apart "
               f"from it: the pure delay is {1e6 * s.pure_delay_s:.1f} µs, and the plant model, "
               f"which has no sensor block, uses {1e6 * s.delay_s:.1f} µs"
               if lowpass.limited else
               "the bench file has no 4QD amplifier (its bandwidth is resolved, when the data "
               "can, on the Newport's paths below), so its lag, if any, is in the delay")
        blocks.append(Note(
            "The joint fit models the modes' approach to their asymptotes, which the "
            f"phase-only estimate reads as extra lag; {amp}. A 125 kHz coil pole lags like "
            "1.3 µs of delay and is counted in."))
    elif s.joint_delay_skipped:
        blocks.append(Note(f"No joint delay fit ({s.joint_delay_skipped})."))
    return blocks


def _us(value_s: float, std_s: float) -> str:
    """``151.4 ± 0.1`` [µs]."""
    return f"{1e6 * value_s:.1f} ± {1e6 * std_s:.1g}"


def sensor_note(dyn: NewportDynamics) -> Note:
    """What the Newport's lines say of the 4QD amplifier, one sentence per axis."""
    parts = [f"{axis}: {fit.sensor.sentence()}" for axis, fit in dyn.axes.items()
             if fit.sensor is not None]
    return Note("The 4QD amplifier in the Newport fits (its coherent band reaches twice the "
                "Sercalo's): " + "; ".join(parts) + ". The delays in the table are the pure "
                "ones; the internal lag compares effective delays (the amplifier's lag in) of "
                "the Newport and Sercalo paths, which share the amplifier.")
