"""The report's control section (seed sections 5–10) and the twin's verdict."""

from __future__ import annotations

from typing import Any

import matplotlib

from fsmbench.report.html import Section, Table, figure_from_matplotlib

__all__ = ["design_section"]

_SEED_REFS = {"fig41_seed_loop_gain": "Fig. 41", "fig42_newport_to_beam": "Fig. 42",
              "fig43_newport_loop_gain": "Fig. 43"}
_TITLES = {
    "fig41_seed_loop_gain": "Loop gains with the seed's decentralised controller",
    "fig42_newport_to_beam": "Newport command to beam angle, closed loop",
    "fig43_newport_loop_gain": "Newport loop gains",
    "loop_gains_compared": "Loop gains: the seed's controller and fsmbench's",
    "rga_singular_values": "RGA number and singular values of the plant",
    "robustness_fsmbench": "fsmbench's controller over the perturbed plants",
    "robustness_seed": "The seed's controller over the perturbed plants",
    "iff": "Integral force feedback (active damping)",
}


def _fmt(x: Any, spec: str = ".3g") -> str:
    return "-" if x is None else format(x, spec)


def design_section(stage: Any, *, plant_source: str) -> Section:
    """Margins of every loop, the objective, IFF, robustness, twin check and figures.

    ``stage`` is a :class:`fsmbench.stages.DesignStage`.
    """
    from fsmbench.control.figures import design_figures

    p = stage.payload
    objective = p["objective"]
    rows = []
    for name in ("seed_controller", "fsmbench_controller", "newport_controller"):
        loop = p[name]
        for axis in ("h", "v"):
            a = loop[axis]
            rows.append((name.replace("_", " "), axis, "yes" if a["stable"] else "NO",
                         _fmt(a["gain_margin_db"], ".1f"), _fmt(a["phase_margin_deg"], ".1f"),
                         _fmt(a["modulus_margin"], ".2f"), _fmt(a["crossover_hz"], ".1f"),
                         _fmt(a["sensitivity_at_1hz"], ".2e"),
                         "yes" if loop["meets_objective"] else "no"))
    tables = [Table(caption="Loops on the plant (exact delays): stability, margins, crossover, "
                            "|S| at 1 Hz against the objective of 6.1",
                    header=("controller", "axis", "stable", "GM [dB]", "PM [deg]",
                            "modulus margin", "crossover [Hz]", "|S(1 Hz)|", "meets 6.1"),
                    rows=tuple(rows))]
    iff = p["iff"]
    tables.append(Table(caption="Active damping by integral force feedback (8)",
                        header=("axis", "damping open loop", "damping with IFF"),
                        rows=tuple((a, _fmt(iff[a]["damping_ratio_open"], ".3e"),
                                    _fmt(iff[a]["damping_ratio_closed"], ".3e"))
                                   for a in ("h", "v"))))
    rob = p["robustness"]
    twin = p["closed_loop_twin"]
    tables.append(Table(
        caption="fsmbench's controller on the twin: repeatability experiment at 10 kHz with "
                "16-bit converters and every noise, against the linear prediction",
        header=("axis", "tracking error [µrad rms]", "predicted [µrad rms]",
                "measured / predicted"),
        rows=tuple((a, f"{1e6 * twin['tracking_error_rms_rad'][a]:.3g}",
                    f"{1e6 * twin['predicted_rms_rad'][a]:.3g}",
                    f"{twin['measured_over_predicted'][a]:.3f}") for a in ("h", "v"))))
    paragraphs = (
        f"Plant: {plant_source}. Objective of 6.1: |S| at "
        f"{_fmt(objective.get('frequency_hz'))} Hz below "
        f"{_fmt(objective['sensitivity_bound_at_1hz'])}.",
        f"Robustness of fsmbench's controller over the perturbed plants (resonances ±5 %, "
        f"damping ×0.5 and ×2): worst gain margin {_fmt(rob['worst_gain_margin_db'], '.1f')} dB,"
        f" worst phase margin {_fmt(rob['worst_phase_margin_deg'], '.1f')} deg.",
        "controllers.mat holds every controller, continuous (K) and discretised by Tustin at "
        "1e-4 s (Kd), with signal names; controllers_sos.json the second-order sections for a "
        "real-time target.",
    )
    with matplotlib.rc_context({"figure.max_open_warning": 0}):  # rendered, then closed
        figures = tuple(
            figure_from_matplotlib(fig, title=_TITLES.get(key, key.replace("_", " ")),
                                   seed_ref=_SEED_REFS.get(key, ""), caption="")
            for key, fig in design_figures(stage.result).items())
    return Section(title="6. Control: analysis, controllers, verification", anchor="control",
                   paragraphs=paragraphs, tables=tuple(tables), figures=figures)
