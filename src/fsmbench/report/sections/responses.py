"""Report: closed-loop step and sample-motion responses (chapter 9).

Every number and curve comes from the design stage's
:class:`~fsmbench.control.responses.ClosedLoopResponses`; nothing is computed here.
"""

from __future__ import annotations

from fsmbench.control.study import DesignResult
from fsmbench.report.figures.responses import step_response_figure
from fsmbench.report.html import Block

__all__ = ["response_blocks"]


def response_blocks(res: DesignResult, *, colors: tuple[str, str]) -> list[Block]:
    """Text and figure of the closed-loop step and sample-motion responses of both controllers.

    Parameters
    ----------
    res : DesignResult
        Its ``responses`` (empty: nothing is said).
    colors : (str, str)
        Colours of the ESRF study's controller and of fsmbench's.
    """
    pairs = [(res.responses[n], c) for n, c in zip(("seed_controller", "fsmbench_controller"),
                                                   colors, strict=True)
             if n in res.responses]
    if not pairs:
        return []
    over = "; ".join(f"{r.name}: {100 * r.overshoot()[0]:.0f} % (h), "
                     f"{100 * r.overshoot()[1]:.0f} % (v)" for r, _ in pairs)
    r0 = pairs[0][0]
    return [
        "How does the beam follow a step of its reference, and how does it reject a step of "
        "the sample motion? The two controllers closed around the plant (both axes together), "
        f"in time and in frequency. Overshoot of the reference step: {over}.",
        step_response_figure(
            pairs, key="closed_loop_step_responses",
            title="Closed-loop step and sample-motion responses",
            caption=(f"Top: the beam angle after a unit step of its reference (u = K (r − R)) "
                     f"and after a 1 V step of the Newport command (the bench's sample motion, "
                     f"Sercalo loop closed, and open for comparison), over "
                     f"{1e3 * float(r0.t_s[-1]):g} ms; delays as Padé approximants of order "
                     f"{r0.pade_order}, integrated exactly for a step. Bottom: the same paths in "
                     f"frequency, |T| and |S Gn| in dB, delays exact, "
                     f"from {float(r0.f_hz[0]):.3g} Hz to {float(r0.f_hz[-1]):.4g} Hz. The "
                     f"dashed lines are the final values: T(0) = 1 (integral action) and 0 for "
                     f"the disturbance.")),
    ]
