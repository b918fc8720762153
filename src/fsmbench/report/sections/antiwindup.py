"""Report: the twin's saturating step without and with anti-windup (chapter 9).

Every number and curve comes from the design stage's
:class:`~fsmbench.control.antiwindup_loop.SaturatingStep` results; nothing is computed here.
"""

from __future__ import annotations

import math

from fsmbench.control.study import DesignResult
from fsmbench.report.figures.antiwindup import saturating_step_figure
from fsmbench.report.html import Block

__all__ = ["antiwindup_blocks"]

_WHO = (("fsmbench_controller", "fsmbench's controller"),
        ("seed_controller", "the ESRF study's controller"))


def _ms(x: float, *, after_s: float) -> str:
    return f"{1e3 * x:.0f} ms" if math.isfinite(x) else f"not within {1e3 * after_s:.0f} ms"


def antiwindup_blocks(res: DesignResult) -> list[Block]:
    """Text and figure of the saturating step (empty when the design ran no step).

    Parameters
    ----------
    res : DesignResult
        Its ``saturating_steps``.
    """
    steps = res.saturating_steps
    fsm = [steps[k] for k in ("fsmbench_controller/h", "fsmbench_controller/v") if k in steps]
    if not fsm:
        return []
    first = fsm[0]
    f32 = []
    for name, words in _WHO:
        if (loop := res.float32_loops.get(name)) is None:
            continue
        e_sos, e_ss = loop.response_error_sos, loop.response_error_state_space
        f32.append(
            f"{words}: the sections' response moves by at most {max(e_sos.values()):.2g} "
            f"(relative, h and v), controllers.mat's Kd by {max(e_ss.values()):.2g}; on the "
            f"twin the closed loop's poles move by at most {loop.pole_shift_sos:.2g} "
            f"(sections) and {loop.pole_shift_state_space:.2g} (Kd) in the z-plane, its "
            f"largest pole modulus goes from {loop.radius_float64:.6f} to "
            f"{loop.radius_float32_sos:.6f} (sections) and {loop.radius_float32_state_space:.6f}"
            f" (Kd): {'stable' if loop.sos_stable and loop.state_space_stable else 'UNSTABLE'}")
    float32_text = (
        ["Will the exported controllers run on a float32 target? fsmbench's sections' "
         "coefficients span many decades (the overall gain sits in the first section, the "
         "integrators' numerators are of order Ts²) and four poles per axis sit on z = 1. "
         "Rounding every "
         "coefficient to float32 (from 0.1 Hz to 0.9 of the Nyquist frequency): "
         + "; ".join(f32) + ". The integrators' denominators are exact in float32, so they "
         "stay integrators; the arithmetic's own roundoff was not simulated."] if f32 else [])
    said = []
    for name, words in _WHO:
        parts = []
        for axis in ("h", "v"):
            if (s := steps.get(f"{name}/{axis}")) is None:
                continue
            after = float(s.t_s[-1]) - s.hold_s
            parts.append(f"{axis}: {_ms(s.recovery_s['with'], after_s=after)} with, "
                         f"{_ms(s.recovery_s['without'], after_s=after)} without (ideal DAC "
                         f"{_ms(s.recovery_s['linear'], after_s=after)})")
        if parts:
            said.append(f"{words[0].upper()}{words[1:]}: " + "; ".join(parts))
    return [
        *float32_text,
        "What happens when the DAC saturates? fsmbench's controller has four integrators per "
        "axis and the ESRF study's two; while the command sits on the ±10 V rail they keep "
        "integrating. The exported controllers carry a back-calculation anti-windup "
        "(controllers_sos.json, implementation_note): the part of the command the rail clips "
        "off is fed back into the integrator sections' registers with tracking time "
        f"{1e3 * first.tracking_time_s:g} ms, and nothing changes while the command is inside "
        "the rails. On the twin, the beam's reference steps by an angle whose steady command "
        f"is 1.5 times the rail, is held {1e3 * first.hold_s:g} ms and steps back; the "
        f"recovery is the time after the step back until the beam stays within "
        f"{100 * first.band_rad / first.step_rad:g} % of the step. " + ". ".join(said) + ". "
        "Where the recovery with anti-windup stays well behind the ideal DAC's although the "
        "command has left the rail, what is left is not windup: a Sercalo resonance rung while "
        "the loop was open on the rail, which a notch that cancels it (the ESRF study's "
        "controller) hides from the loop, so it decays only at its own mechanical damping.",
        saturating_step_figure(
            fsm, key="saturating_step_antiwindup",
            title="A step beyond the DAC's reach, without and with anti-windup",
            caption=("fsmbench's controller on the twin (its true plant, 16-bit converters, no "
                     "noise). Top: the beam angle over the step's height; bottom: the command "
                     "the DAC applied, with its rails. Red: without anti-windup, the wound-up "
                     "integrators keep the command on the rails after the step back; blue: "
                     "with back-calculation; grey dotted: the same step with an ideal DAC "
                     "(no rails), the linear loop's own settling. The dashed vertical line is "
                     "the step back; the ripple while the command sits on a rail is the "
                     "Sercalo's resonance, rung by the loop opened by the rail.")),
    ]
