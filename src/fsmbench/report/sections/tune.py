"""Report: one ``fsmbench tune`` step (what was measured, designed, loaded and why).

Every number and curve comes from :class:`~fsmbench.tune.guarded.TuneResult`;
nothing is computed here but the formatting.
"""

from __future__ import annotations

from typing import Any

from fsmbench.report.figures.budget import asd_line
from fsmbench.report.figures.spec import H_COLOR, V_COLOR, Figure, Panel
from fsmbench.report.html import Block, Section, Table

__all__ = ["tune_figure", "tune_section"]

UM = 1e6
_AXES = (("h", "Rh", "horizontal", H_COLOR), ("v", "Rv", "vertical", V_COLOR))
_DECISION_WORDS = {"loaded": "loaded and kept", "refused": "refused (nothing loaded)",
                   "rolled_back": "loaded, then rolled back"}


def tune_figure(result: Any) -> Figure:
    """Measured tracking-error ASDs before and at the end, per axis."""
    panels = []
    end = "after loading" if result.decision == "loaded" else (
        "after the roll-back" if result.decision == "rolled_back" else "unchanged")
    for i, (_axis, name, words, color) in enumerate(_AXES):
        lines = [asd_line(result.psd_f_hz, result.psd_before[:, i], scale=UM,
                          name=f"before: {result.before.name}", color="#888888",
                          group="before", width=1.2),
                 asd_line(result.psd_f_hz, result.psd_after[:, i], scale=UM,
                          name=f"end ({end}): {result.after.name}", color=color, group="after",
                          width=1.5)]
        panels.append(Panel(tuple(lines), "Frequency [Hz]",
                            f"ASD of the tracking error {name} [µrad/√Hz]", x_log=True,
                            y_log=True, title=f"{name} ({words})"))
    opts = result.options
    return Figure(
        key="tune_tracking_error_asd",
        title="Tracking error before and after tune",
        caption=(f"Tracking error α = Vp/Gd measured on the running bench while the Newport "
                 f"plays a {opts.disturbance_v:g} V, 1 Hz sine on both axes, {opts.watch_s:g} s "
                 f"each (the first {opts.settle_s:g} s left out); Welch, 2 s segments."),
        panels=tuple(panels), columns=2)


def _cells(fig: Any, axis: str) -> tuple[str, ...]:
    measured = ("not run" if fig.measured_rms_rad is None
                else f"{fig.measured_rms_rad[axis] * UM:.3g}")
    robust = {True: "yes", False: "no", None: "not checked"}[fig.robust_stable]
    return (f"{fig.sensitivity_at_1hz[axis]:.3g}", f"{fig.gain_margin_db[axis]:.3g}",
            f"{fig.phase_margin_deg[axis]:.3g}", f"{fig.modulus_margin[axis]:.3g}",
            "yes" if fig.stable else "no", robust, f"{fig.predicted_rms_rad[axis] * UM:.3g}",
            measured)


def tune_section(result: Any) -> Section:
    """The tune step as a report section: decision, figures per controller, ASDs, log."""
    m = result.measurement
    added = m.tracking_added_rad()
    ident = m.identification.to_json().get("sercalo") or {}
    rows = []
    for label, fig in (("running", result.before), ("candidate", result.candidate)):
        for axis, _n, words, _c in _AXES:
            rows.append((f"{label}: {fig.name}", words, *_cells(fig, axis)))
    blocks: list[Block] = [
        (f"Decision: {_DECISION_WORDS[result.decision]}. {result.reason[0].upper()}"
         f"{result.reason[1:]}."),
        (f"The Sercalo was identified with the loop closed: {m.duration_s:g} s of "
         f"beam-bounded excitation at the controller's output, which added "
         + " and ".join(f"{added[a] * UM:.3g} µrad" for a in ("h", "v"))
         + f" rms to the beam error (h and v; bound {m.options.max_error_rad * UM:.3g} µrad). "
         + " ".join(f"Axis {a}: resonance {v['resonance_hz']:.2f} Hz, damping "
                    f"{v['damping_ratio']:.2e}." for a, v in ident.items())
         + (f" The twin's resonance was moved by {result.drift_pct:+g} % from the bench file."
            if result.drift_pct else "")),
        Table(caption="The controllers on the identified bench (margins, |S(1 Hz)|, predicted "
                      "tracking error) and on the running bench (measured)",
              header=("controller", "axis", "|S(1 Hz)| [1]", "gain margin [dB]",
                      "phase margin [°]", "modulus margin [1]", "stable", "robustly stable",
                      "predicted rms [µrad]", "measured rms [µrad]"),
              rows=tuple(rows),
              note=f"The 6.1 objective: |S(1 Hz)| below {result.objective_bound:.3g}."),
        tune_figure(result),
        Table(caption="What tune did, in order", header=("step",),
              rows=tuple((line,) for line in result.log)),
    ]
    return Section(title="Tuning with the loop closed", anchor="tune", blocks=tuple(blocks))
