"""The report's control chapters (ESRF study 5–10): text, tables and figures in reading order.

Entry point: :func:`control_sections`, from the design stage
(:class:`fsmbench.stages.DesignStage`): its ``result`` (a
:class:`~fsmbench.control.study.DesignResult`) and ``twin_check`` (a
:class:`~fsmbench.twin.verify.TrackingCheck`). Numbers in the text come from
the run; where they differ from the ESRF study, a note names the errata entry
(docs/seed-errata.md).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from fsmbench.control.analysis import CoprimeFactors
from fsmbench.control.design import Robustness
from fsmbench.control.loops import AXES, LoopAnalysis
from fsmbench.control.study import DesignResult
from fsmbench.report.figures.control import (
    AXIS_WORDS,
    ESRF_COLOR,
    FSM_COLOR,
    controllers_figure,
    iff_figure,
    loop_gain_figure,
    newport_to_beam_figure,
    nyquist_figure,
    perturbation_factors,
    plant_figure,
    robustness_figure,
    scaled_plant_figure,
    sensitivity_figure,
)
from fsmbench.report.html import Block, Note, Section, Table
from fsmbench.report.sections.antiwindup import antiwindup_blocks
from fsmbench.report.sections.responses import response_blocks
from fsmbench.twin.verify import TrackingCheck

__all__ = ["control_sections"]

_PARTS = {"qd_noise": "4QD noise (white, 1/f, drift)", "adc_quantisation": "ADC quantisation",
          "newport_angle_noise": "Newport angle noise",
          "sercalo_dac_quantisation": "Sercalo DAC quantisation",
          "newport_dac_quantisation": "Newport DAC quantisation", "mains": "mains lines",
          "newport_sine": "Newport 1 Hz sine (1 V), through S Gn"}
# An RGA number below this is rounding of a diagonal plant, not interaction.
_RGA_ROUNDING = 1e-12


def _g(x: float, spec: str = ".3g") -> str:
    return format(x, spec) if np.isfinite(x) else "∞"


def _list(values: Any) -> str:
    return ", ".join(f"{x:g}" for x in values)


def _yes(flag: bool) -> str:
    return "yes" if flag else "no"


def _stability(lp: LoopAnalysis) -> str:
    """Stable/unstable in words with the reason (poles with Padé delays, Nyquist exact)."""
    slowest = float(np.max(lp.poles.real))
    ny = lp.nyquist
    if lp.stable and ny.stable:
        return (f"The closed loop is stable: all its poles (delays as Padé approximants of order "
                f"{lp.pade_order}) lie in the left half-plane, the slowest at "
                f"Re s = {slowest:.3g} rad/s, and the Nyquist count with the exact delays agrees "
                f"(no open-loop unstable pole, no encirclement of −1).")
    return (f"The closed loop is UNSTABLE: the rightmost closed-loop pole is at "
            f"Re s = {slowest:.3g} rad/s, and det(I + L) with the exact delays encircles the "
            f"origin {abs(ny.winding)} times, i.e. {ny.closed_loop_unstable} closed-loop poles "
            f"in the right half-plane.")


def _margins_table(lp: LoopAnalysis, *, who: str, objective: bool = True) -> Table:
    """Margins per axis in words with units; the 6.1 verdict when ``objective``."""
    ax = [lp.axes[a] for a in AXES]
    obj = lp.objective
    rows: list[tuple[str, ...]] = [
        ("this loop alone closed is stable", *(_yes(a.stable) for a in ax)),
        ("gain margin [dB]", *(_g(a.margins.gain_margin_db, ".1f") for a in ax)),
        ("gain-reduction margin [dB] (∞: no crossing of −180° with |L| > 1)",
         *(_g(a.margins.gain_reduction_margin_db, ".1f") for a in ax)),
        ("phase margin [deg]", *(f"{a.margins.phase_margin_deg:.1f}" for a in ax)),
        ("modulus margin min |1 + L| [1]", *(f"{a.margins.modulus_margin:.2f}" for a in ax)),
        ("crossover [Hz]", *(f"{a.margins.crossover_hz:.1f}" for a in ax)),
    ]
    if objective:
        rows += [
            (f"|L({obj.frequency_hz:g} Hz)| [1]", *(f"{a.loop_gain_at_f0:.3g}" for a in ax)),
            (f"|S({obj.frequency_hz:g} Hz)| [1]", *(f"{a.sensitivity_at_f0:.2e}" for a in ax)),
            (f"meets the objective of 6.1 (|S({obj.frequency_hz:g} Hz)| ≤ "
             f"{obj.sensitivity_bound:.0e})", *(_yes(a.meets_objective) for a in ax)),
        ]
    req = (f"requirements: gain margin ≥ {6:g} dB, phase margin ≥ {30:g}°")
    return Table(caption=f"Margins of {who} on each axis ({req})",
                 header=("quantity", "h", "v"), rows=tuple(rows))


def _verdict(lp: LoopAnalysis, *, who: str) -> str:
    """The 6.1 verdict of one controller in a sentence."""
    obj = lp.objective
    s = {a: lp.axes[a].sensitivity_at_f0 for a in AXES}
    ratio = {a: s[a] / obj.sensitivity_bound for a in AXES}
    bound = f"{obj.sensitivity_bound:.0e}"
    if lp.meets_objective:
        return (f"Objective of 6.1: {who} meets it. |S({obj.frequency_hz:g} Hz)| is "
                f"{s['h']:.2e} (h) and {s['v']:.2e} (v), below the bound {bound}; the MIMO "
                f"value σmax(S) is {lp.sensitivity_at_f0:.2e}.")
    return (f"Objective of 6.1: {who} does NOT meet it. |S({obj.frequency_hz:g} Hz)| is "
            f"{s['h']:.2e} (h) and {s['v']:.2e} (v), {ratio['h']:.1f} and {ratio['v']:.1f} times "
            f"the bound {bound}: its loop gain at {obj.frequency_hz:g} Hz is "
            f"{lp.axes['h'].loop_gain_at_f0:.0f} (h) and {lp.axes['v'].loop_gain_at_f0:.0f} (v), "
            f"where at least {obj.loop_gain_necessary:.0f} is needed.")


def _robustness_blocks(rob: Robustness, res: DesignResult, *, who: str, key: str,
                       title: str) -> list[Block]:
    """Small multiples, a table of the nine cases and the unstable cases explained."""
    opts = res.options.design
    factors = perturbation_factors(rob, frequency_scales=opts.frequency_scales,
                                   damping_scales=opts.damping_scales)
    rows = []
    unstable = []
    for (fs, ds), lp in zip(factors, rob.loops, strict=True):
        ok = lp.stable and lp.nyquist.stable
        m = {a: lp.axes[a].margins for a in AXES}
        rows.append((f"×{fs:g}", f"×{ds:g}", "stable" if ok else "UNSTABLE",
                     *(x for a in AXES for x in (_g(m[a].gain_margin_db, ".1f"),
                                                 f"{m[a].phase_margin_deg:.1f}")),
                     f"{min(m[a].modulus_margin for a in AXES):.2f}"))
        if not ok:
            bad = [a for a in AXES if not lp.axes[a].stable] or list(AXES)
            why = "; ".join(
                f"{a}: the loop gain crosses |L| = 1 at "
                f"{', '.join(f'{f:.1f}' for f in lp.axes[a].margins.crossovers_hz)} Hz and the "
                f"phase margin is {lp.axes[a].margins.phase_margin_deg:.1f}°"
                for a in bad)
            unstable.append(f"resonances ×{fs:g} with damping ×{ds:g} ({why})")
    n = len(rob.loops)
    modes = [m.frequency_hz_open for m in res.iff.modes.values()]
    # Half the lowest to twice the highest resonance: where the perturbed loops differ.
    band = (0.5 * min(modes), 2.0 * max(modes)) if modes else (float(rob.loops[0].f_hz[0]),
                                                              float(rob.loops[0].f_hz[-1]))
    figure = robustness_figure(
        rob, factors=factors, band_hz=band, key=key, title=title,
        caption=(f"Loop-gain magnitude |L| of {who} on the {n} perturbed plants: the Sercalo's "
                 f"resonance frequencies scaled by {_list(opts.frequency_scales)} (one column "
                 f"each) and their damping ratios by {_list(opts.damping_scales)} (one curve "
                 f"each); rows: h "
                 f"and v; the dotted line is |L| = 1. Drawn from {band[0]:.0f} to "
                 f"{band[1]:.0f} Hz, around the resonances: elsewhere the nine loops coincide "
                 f"(the perturbation moves only the Sercalo's modes), and their crossovers are "
                 f"in the table below. A closed loop that is unstable is drawn thick, dashed "
                 f"and red."))
    table = Table(
        caption=f"Stability and margins over the perturbed plants: {who}",
        header=("resonances", "damping", "closed loop", "gain margin h [dB]",
                "phase margin h [deg]", "gain margin v [dB]", "phase margin v [deg]",
                "modulus margin, worse axis [1]"),
        rows=tuple(rows))
    if unstable:
        text = (f"{len(unstable)} of the {n} perturbed plants are unstable with {who}: "
                + "; ".join(unstable) + ". The controller's notch sits on the nominal "
                "resonance; once the resonance moves off it, the lightly damped peak rises "
                "above |L| = 1 with the wrong phase and the loop is no longer robust.")
    else:
        text = (f"All {n} perturbed plants are stable with {who}: worst gain margin "
                f"{rob.worst_gain_margin_db:.1f} dB, worst phase margin "
                f"{rob.worst_phase_margin_deg:.1f}°, worst modulus margin "
                f"{rob.worst_modulus_margin:.2f}; the worst |S(1 Hz)| is "
                f"{rob.worst_sensitivity_at_f0:.2e}.")
    return [figure, text, table]


def _section5(res: DesignResult) -> Section:
    pa = res.plant
    k_seed, k_fsm = res.seed.generalized_stability_margin, res.fsmbench.generalized_stability_margin
    # b(G, K) is 0 for a loop that is unstable
    ratio = (f"fsmbench's {k_fsm / k_seed:.0f} times the ESRF study's" if k_seed > 0
             else "the ESRF study's loop is unstable (b = 0)")
    def margin(factors: CoprimeFactors | None, field: str) -> str:
        return "not computed" if factors is None else f"{getattr(factors, field):.3f}"

    table = Table(
        caption="Normalised left coprime factorisation G = M⁻¹ N (5.1) and stability margins",
        header=("quantity", "value [1]"),
        rows=(("largest stabilisable coprime-factor uncertainty b_max of Gc Gi (Uc → Vpc, V/V)",
               margin(pa.coprime, "b_max")),
              ("same, from the two Riccati solutions (independent check)",
               margin(pa.coprime, "b_max_riccati")),
              ("b_max of the scaled plant (Uc / 10 V → R / 10 µrad)",
               margin(pa.coprime_scaled, "b_max")),
              ("stability margin b(G, K) of the ESRF study's controller (units of 5.1: Uc → Vp)",
               f"{k_seed:.2e}"),
              ("stability margin b(G, K) of fsmbench's controller (units of 5.1: Uc → Vp)",
               f"{k_fsm:.2e}")))
    failed = [c for c in pa.checks if not c.passed]
    if pa.coprime is None:
        comparison = (f"b(G, K) is the coprime-factor uncertainty a given loop tolerates: "
                      f"{k_seed:.1e} for the ESRF study's controller and {k_fsm:.1e} for "
                      "fsmbench's "
                      f"({ratio}); b_max itself could not be computed on this plant.")
    else:
        comparison = (f"b(G, K) is the coprime-factor uncertainty a given loop tolerates. Both "
                      f"controllers are far below b_max ({k_seed:.1e} and {k_fsm:.1e} against "
                      f"{pa.coprime.b_max:.2f}), {ratio}: measured this way, neither loop "
                      f"tolerates much unstructured uncertainty.")
    return Section(title="5. Plant uncertainty", anchor="plant-uncertainty", blocks=(
        "The ESRF study factorises the Sercalo's electrical-to-mechanical path Gc Gi with MATLAB's "
        "lncf (5.1) and stops there. fsmbench computes the same normalised left coprime factors "
        "(Zhou, Doyle & Glover, 13.6) on a balanced minimal realisation of the plant, and the "
        "largest coprime-factor uncertainty any controller could stabilise, "
        "b_max = √(1 − ‖[N M]‖²_H), twice: from the factors' Gramians and from the two "
        "Riccati equations.",
        table,
        *(Note(f"Not computed for {c.subject}: {c.advice}.") for c in failed),
        comparison + " That measure treats every frequency and direction alike, while this "
        "bench's uncertainty is structured (the Sercalo's resonance frequencies and damping), "
        "so robustness is checked against exactly that in section 9."))


def _disturbance_sentence(pa: Any, bw_text: str) -> str:
    """Where the scaled Newport path stays above 1, and why, from the plant's own Newport."""
    roll = pa.disturbance_rolloff_hz
    if np.isfinite(roll):
        why = (f"the model's Newport rolls off above {roll:.3g} Hz (its second order, 2.4), "
               f"but Table 5's scaling (1 V of command against 10 µrad of error) puts its "
               f"low-frequency gain so high that the roll-off reaches 1 only there")
    else:
        why = ("the model's Newport path is a constant gain with a delay (ESRF study 2.4), so it "
               "does not roll off")
    nyq = (f"the Nyquist frequency ({pa.nyquist_hz:g} Hz), above which the sampled loop acts "
           "on nothing")
    if pa.inputs_suffice:
        verdict = f"yes, at every frequency up to {nyq}"
    else:
        verdict = (f"no, from {pa.inputs_short_from_hz:.3g} Hz up to {nyq}: there the "
                   "smallest singular value of the scaled plant falls below the scaled "
                   "Newport gain minus 1")
    return (f"The scaled Newport path exceeds 1 up to {bw_text}: {why}. Do the commands "
            f"suffice to cancel the perturbation? {verdict}.")


def _section6(res: DesignResult) -> Section:
    obj, pa = res.objective, res.plant
    table = Table(
        caption="The control objective of 6.1",
        header=("quantity", "value"),
        rows=(("frequency of the expected stroke f0 [Hz]", f"{obj.frequency_hz:g}"),
              ("expected beam stroke y_max [rad]", f"{obj.stroke_max_rad:.3g}"),
              ("largest wanted error e_max [µrad]", f"{1e6 * obj.error_max_rad:.3g}"),
              ("bound on |S(f0)| = e_max / y_max [1]", f"{obj.sensitivity_bound:.2e}"),
              ("|L(f0)| that suffices whatever its phase, 1/bound + 1 [1]",
               f"{obj.loop_gain_sufficient:.0f}"),
              ("|L(f0)| below which the bound cannot be met, 1/bound − 1 [1]",
               f"{obj.loop_gain_necessary:.0f}"),
              ("the ESRF study's rounded requirement on |L(f0)| [1]", f"{obj.seed_loop_gain:.0f}"),
              ("beam stroke of Table 5's 1 V Newport perturbation [rad]",
               f"{obj.table5_stroke_rad:.3g}"),
              ("bound on |S(f0)| with that stroke [1]", f"{obj.table5_sensitivity_bound:.2e}")))
    bw = pa.disturbance_bandwidth_hz
    bw_text = f"{bw:.3g} Hz" if np.isfinite(bw) else "beyond 1 MHz"
    return Section(title="6. Plant scaling and control objective", anchor="plant-scaling",
                   blocks=(
        "Table 5 scales the plant: commands by their largest use (10 V), the Newport "
        "perturbation by its expected size (1 V), the beam angle by the largest wanted error "
        "(10 µrad). In these units a scaled gain above 1 is what matters.",
        scaled_plant_figure(
            pa, key="scaled_plant_and_disturbance",
            title="Scaled plant and scaled Newport disturbance",
            caption=("Smallest singular value of the Sercalo path and largest of the Newport "
                     "path, both scaled by Table 5, delays included. Where the disturbance "
                     "curve is above 1, feedback is needed to keep a 1 V Newport perturbation "
                     "within 10 µrad; where the plant curve is above the disturbance curve "
                     "minus 1, a 10 V command can cancel it.")),
        _disturbance_sentence(pa, bw_text),
        f"The objective of 6.1: the Newport swings the beam by y_max = "
        f"{obj.stroke_max_rad:g} rad at {obj.frequency_hz:g} Hz, and the error must stay below "
        f"e_max = {1e6 * obj.error_max_rad:g} µrad, so the sensitivity must satisfy "
        f"|S(j2π·{obj.frequency_hz:g} Hz)| ≤ {obj.sensitivity_bound:.0e}. fsmbench tests |S| "
        f"itself on each axis and as σmax(S).",
        table,
        Note("6.1 writes y_max = 3 mm; it is an angle, 3° = 5.24e-2 rad, the beam swing of the "
             "Newport's full ±10 V. Table 5's 1 V perturbation would give a 10× looser bound "
             f"({obj.table5_sensitivity_bound:.1e}); fsmbench keeps 6.1's.", ref="errata E22"),
        Note("e_max / y_max is exactly 2e-4, so the bound is ≤, not <; |L| > 5e3 is the |L| ≫ 1 "
             f"approximation of it (sufficient {obj.loop_gain_sufficient:.0f}, necessary "
             f"{obj.loop_gain_necessary:.0f}).", ref="errata E23")))


def _section7(res: DesignResult) -> Section:
    pa = res.plant
    g0, dec = pa.g0, pa.decoupler
    k = int(np.argmax(pa.rga_number))
    table = Table(
        caption="Static gain G(0) of Uch, Ucv → Rh, Rv (7.3) and its inverse",
        header=("quantity", "first input", "second input"),
        rows=(("G(0) from Uch, Ucv to Rh [mrad/V]", f"{1e3 * g0[0, 0] + 0.0:.4g}",
               f"{1e3 * g0[0, 1] + 0.0:.4g}"),
              ("G(0) from Uch, Ucv to Rv [mrad/V]", f"{1e3 * g0[1, 0] + 0.0:.4g}",
               f"{1e3 * g0[1, 1] + 0.0:.4g}"),
              ("static decoupler G(0)⁻¹ to Uch, from Rh and Rv [V/rad]",
               f"{dec[0, 0] + 0.0:.4g}", f"{dec[0, 1] + 0.0:.4g}"),
              ("static decoupler G(0)⁻¹ to Ucv, from Rh and Rv [V/rad]",
               f"{dec[1, 0] + 0.0:.4g}", f"{dec[1, 1] + 0.0:.4g}"),
              ("relative static coupling, off-diagonal [1]", f"{pa.coupling[0, 1] + 0.0:.3g}",
               f"{pa.coupling[1, 0] + 0.0:.3g}")))
    return Section(title="7. Plant analysis", anchor="plant-analysis", blocks=(
        "How much do the two axes interact? The relative gain array Λ = G ∘ (G⁻¹)ᵀ and its "
        "number Σ|Λ − I| (7.2) are 0 for a diagonal plant; the singular values show the "
        "plant's gain in its strongest and weakest direction.",
        plant_figure(
            pa, key="plant_rga_singular_values",
            title="Interaction and gain of the Sercalo path Uch, Ucv → Rh, Rv",
            caption=(f"RGA number and singular values of the plant, delays included; plant: "
                     f"{res.plant_source}. The RGA number peaks at {pa.rga_number[k]:.2g} near "
                     f"{pa.f_hz[k]:.4g} Hz" + (
                         ": values this small are rounding, the axes do not interact."
                         if pa.rga_number[k] < _RGA_ROUNDING else ".")),
            note=("The ESRF study computes Λ with G.*inv(G)' — MATLAB's ' is the conjugate "
                  "transpose; the RGA needs .' (errata E24). fsmbench uses the transpose.")),
        f"The rotation of the 4QD frame that would explain the static coupling (7.3) is "
        f"{1e3 * pa.rotation_rad:.3g} mrad; the static condition number is "
        f"{np.linalg.cond(g0):.3g}. A diagonal (decentralised) controller is therefore "
        f"appropriate, as the ESRF study concludes in section 9.",
        table))


def _section8(res: DesignResult) -> Section:
    iff = res.iff
    modes = {a: iff.modes[a] for a in AXES if a in iff.modes}

    def per_axis(fn: Any) -> tuple[str, ...]:
        return tuple(fn(modes[a]) if a in modes else "—" for a in AXES)

    limit = tuple(f"{iff.gain_limit[a]:.3g}" if np.isfinite(iff.gain_limit.get(a, np.nan))
                  else "— (no IFF on this axis)" for a in AXES)
    table = Table(
        caption="The Sercalo's modes without and with the ESRF study's IFF Kppf = −10000/s on h",
        header=("quantity", "h", "v"),
        rows=(("resonance frequency [Hz]", *per_axis(lambda m: f"{m.frequency_hz_open:.2f}")),
              ("damping ratio without IFF [1]",
               *per_axis(lambda m: f"{m.damping_ratio_open:.3e}")),
              ("damping ratio with IFF, plant's delays [1]",
               *per_axis(lambda m: f"{m.damping_ratio_closed:.3e}")),
              ("damping ratio with IFF, without delays [1]",
               *per_axis(lambda m: f"{m.damping_ratio_closed_without_delay:.3e}")),
              ("height of the resonance in the force sensor's path Uc → Vc, relative to its "
               "static gain [1]", *per_axis(lambda m: f"{m.sensor_peak_ratio:.3g}")),
              ("largest IFF gain g of −g/s that keeps the sensor loop stable [1/s]", *limit)))
    stable = ("stable" if iff.loop_stable else
              f"UNSTABLE ({iff.nyquist.closed_loop_unstable} closed-loop poles in the right "
              f"half-plane by the Nyquist count with exact delays; "
              f"{'stable' if iff.loop_stable_without_delay else 'unstable'} without the delays)")
    unchanged = all(np.isclose(m.damping_ratio_closed, m.damping_ratio_open, rtol=1e-6)
                    for m in modes.values())
    blocks: list[Block] = [
        "The ESRF study tries integral force feedback (8.2): the coil voltage Vc is fed back to "
        "the "
        "command through Kppf = −10000/s on the h axis, and the Bode plots of Uc → Vp with and "
        "without it are compared. The ESRF study concludes that active damping does not seem "
        "applicable (8.3). fsmbench computes why.",
        table,
        f"With the ESRF study's gain the IFF loop itself is {stable}.",
    ]
    if unchanged:
        blocks.append(
            "The damping ratios with IFF equal those without (to the digits shown, "
            "computed from the closed-loop poles): IFF cannot move these modes, because the "
            "force sensor does not see them (relative resonance height 0 in its path).")
    blocks += [
        Note("With the ESRF study's static coil impedance Zc (no back-EMF term) the Sercalo's "
             "modes "
             "are unobservable from Vc, so no IFF gain changes their damping; and −10000/s is "
             "far above the sensor loop's stable limit (the amplifier's 1 kHz pole, the coil "
             "inductance and the 0.15 ms delay), so it destabilises the loop it closes. With a "
             "back-EMF term IFF does add damping (×2 at a gain of 50–300 /s).",
             ref="errata E25"),
        iff_figure(
            iff, key="iff_uc_to_vp", title="Integral force feedback: Uc → Vp without and with IFF",
            caption=("The ESRF study's Bode plot of 8.2, one column per axis: the command-to-4QD "
                     "response without IFF and with the ESRF study's IFF closed. On h the sensor "
                     "loop changes the level and slope of the response, but the resonance "
                     "stays as sharp: its damping is unchanged. On v the ESRF study's Kppf is "
                     "zero, "
                     "so the two curves coincide."),
            note=("With IFF the closed loop is unstable, so its frequency response is a "
                  "formal one: no steady state follows it on the bench (errata E25)."
                  if not iff.loop_stable else "")),
    ]
    return Section(title="8. Active damping", anchor="active-damping", blocks=tuple(blocks))


def _controller_blocks(lp: LoopAnalysis, *, who: str, prefix: str, seed_ref: str,
                       bode_key: str) -> list[Block]:
    """Loop gains, margins, Nyquist, S and T of one Sercalo controller."""
    return [
        loop_gain_figure(
            lp, key=bode_key, seed_ref=seed_ref,
            title=f"Loop gains with {who}",
            caption=(f"Bode plot of L = G K on each axis with {who}; plant: "
                     f"{lp.plant_source}, delays exact; phase unwrapped and placed in "
                     f"(−360°, 0] at the crossover. The legend gives each axis' margins.")),
        _stability(lp),
        _margins_table(lp, who=who),
        _verdict(lp, who=who),
        nyquist_figure(
            lp, key=f"{prefix}_nyquist", title=f"Nyquist plots with {who}",
            caption=("Each axis' loop gain in a fixed window of ±1.5 around the critical "
                     "point −1 (equal scales on both axes): the distance to −1 is the modulus "
                     "margin (dashed circle), the crossing of the unit circle gives the phase "
                     "margin, the crossing of the negative real axis the gain margin.")),
        sensitivity_figure(
            lp, key=f"{prefix}_sensitivity", title=f"Sensitivity and complementary sensitivity "
                                                   f"with {who}",
            caption=(f"|S| = |1/(1 + L)| (disturbance to error) and |T| = |L/(1 + L)| "
                     f"(sensor noise to beam angle) on each axis; the red dot is the "
                     f"objective of 6.1. The largest |S| over frequency and both axes is "
                     f"{lp.sensitivity_peak:.2f}.")),
    ]


def _discrete_table(res: DesignResult) -> Table:
    rows = []
    for who, lp in (("the ESRF study's controller", res.seed), ("fsmbench's "
                                                                "controller", res.fsmbench),
                    ("the Newport controller", res.newport)):
        d = lp.discrete
        if d is None:
            continue
        for a in AXES:
            c, t = lp.axes[a].margins, d.margins[a]
            rows.append((who, a, _g(c.gain_margin_db, ".2f"), _g(t.gain_margin_db, ".2f"),
                         f"{c.phase_margin_deg:.2f}", f"{t.phase_margin_deg:.2f}",
                         f"{100 * d.max_relative_error:.3g}"))
    ts = res.options.loop.ts_s
    return Table(
        caption=(f"Continuous controller K against its plain Tustin discretisation at "
                 f"{1e3 * ts:g} ms (the ESRF study's c2d)"),
        header=("controller", "axis", "gain margin with K [dB]", "gain margin with Kd [dB]",
                "phase margin with K [deg]", "phase margin with Kd [deg]",
                "largest |Kd − K| / |K| below 1 kHz [%]"),
        rows=tuple(rows))


def _section9(res: DesignResult, check: TrackingCheck | None, *,
              skipped: str = "") -> Section:
    seed, fsm = res.seed, res.fsmbench
    seed_rob = res.seed_robustness
    shapes = res.design.shapes
    shape_rows = tuple(
        (label, *(fn(shapes[a]) for a in AXES)) for label, fn in (
            ("crossover [Hz]", lambda s: f"{s.crossover_hz:.1f}"),
            ("integrators [1]", lambda s: f"{s.extra_integrators + 1}"),
            ("corner of the extra integrators [Hz]", lambda s: f"{s.integrator_hz:.2f}"),
            ("lead centre [Hz]", lambda s: f"{s.lead_hz:.1f}"),
            ("lead ratio [1]", lambda s: f"{s.lead_ratio:.2f}"),
            ("roll-off frequency [Hz]", lambda s: f"{s.lowpass_hz:.1f}"),
            ("roll-off damping [1]", lambda s: f"{s.lowpass_damping:.2f}")))
    shift = "; ".join(f"{a:.1f} Hz → {b:.1f} Hz" for a, b in
                      (seed.discrete.notch_shifts_hz if seed.discrete else ()))
    blocks: list[Block] = [
        "The ESRF study designs a diagonal controller with SISOTOOL (9.2): on each axis two "
        "integrators, a lead and a notch on the Sercalo's resonance. fsmbench closes it around "
        "the plant with the plant's delays and verifies it.",
        *_controller_blocks(seed, who="the ESRF study's controller", prefix="seed_controller",
                            seed_ref="Fig. 41", bode_key="fig41_seed_loop_gain"),
        Note(_seed_verdict(seed, seed_rob), ref="errata E27"),
    ]
    if seed_rob is not None:
        blocks += [
            "Is the ESRF study's controller robust? The Sercalo's resonances move with temperature "
            "and mounting and their damping is poorly known (errata E21): fsmbench closes the "
            "same controller around nine perturbed plants.",
            *_robustness_blocks(seed_rob, res, who="the ESRF study's controller",
                                key="seed_controller_robustness",
                                title="The ESRF study's controller over the perturbed plants"),
        ]
    blocks += [
        "fsmbench's own controller: on each axis a loop shape with "
        f"{shapes['h'].extra_integrators + 1} integrators (the objective needs |L(1 Hz)| ≈ "
        "5000 with a crossover of a few tens of Hz, hence a slope of 40 dB per decade or more "
        "between them), a lead at the crossover and a second-order roll-off, and no notch. "
        "The roll-off phase-stabilises the lightly damped mirror mode: where its peak rises "
        "above |L| = 1, the loop's phase turns the mode's Nyquist circle away from −1, so a "
        "shifted or less damped resonance cannot destabilise the loop. A notch cannot stay "
        "robust here: with a damping ratio near 1e-3 a 5 % shift puts the peak beside it. The "
        "gain puts |L| = 1 at the crossover; the six other parameters are tuned (Nelder–Mead) "
        "to maximise the smallest normalised slack of the gain margin (6 dB), gain-reduction "
        "margin (6 dB), phase margin (30°), modulus margin (0.4) and |S(1 Hz)| (2e-4) over "
        "the nine perturbed plants, each candidate also checked stable by a Nyquist count.",
        Table(caption="fsmbench's controller: the loop shape of each axis",
              header=("quantity", "h", "v"), rows=shape_rows),
        controllers_figure(
            (("the ESRF study's controller", res.controllers["seed_controller"], ESRF_COLOR),
             ("fsmbench's controller", res.controllers["fsmbench_controller"], FSM_COLOR)),
            f_hz=np.union1d(seed.f_hz, fsm.f_hz), key="controllers_compared",
            title="The two controllers",
            caption=("Magnitude of each axis' controller, beam angle to Sercalo command. The "
                     "ESRF study's controller inverts the resonance with a notch; fsmbench's has "
                     "more gain at low frequency (the objective of 6.1) and rolls off smoothly "
                     "instead, leaving the resonance in the loop.")),
        *_controller_blocks(fsm, who="fsmbench's controller", prefix="fsmbench_controller",
                            seed_ref="", bode_key="fsmbench_controller_loop_gain"),
        *response_blocks(res, colors=(ESRF_COLOR, FSM_COLOR)),
        *_robustness_blocks(res.robustness, res, who="fsmbench's controller",
                            key="fsmbench_controller_robustness",
                            title="fsmbench's controller over the perturbed plants"),
        "Both controllers are implemented at 10 kHz (9.3). The table compares the margins of the "
        "loop sampled with the ESRF study's plain Tustin c2d with the continuous ones; the Kd that "
        "fsmbench exports (controllers.mat, controllers_sos.json) is instead Tustin prewarped "
        "at each notch, section by section.",
        _discrete_table(res),
        *antiwindup_blocks(res),
    ]
    if shift:
        blocks.append(Note(f"Without prewarping Tustin moves the ESRF study's notches ({shift}); "
                           "at "
                           f"the h notch that is about two notch half-bandwidths, which is the "
                           f"large relative difference above. Prewarping at the notch keeps it "
                           f"in place: the exported Kd has its notches at the continuous "
                           f"frequencies.", ref="errata E26"))
    blocks += _twin_blocks(check, skipped=skipped)
    return Section(title="9. Decentralised control of the Sercalo", anchor="sercalo-control",
                   blocks=tuple(blocks))


def _seed_verdict(seed: LoopAnalysis, seed_rob: Robustness | None) -> str:
    """What the ESRF study's controller misses, each claim from its own result."""
    claims = []
    s = {a: seed.axes[a].sensitivity_at_f0 for a in AXES}
    bound = seed.objective.sensitivity_bound
    if not seed.meets_objective:
        claims.append(f"it misses the objective (|S(1 Hz)| {s['h']:.1e} and {s['v']:.1e} "
                      f"against {bound:.0e})")
    weak = [f"{a} phase margin {seed.axes[a].margins.phase_margin_deg:.1f}° (< 30°)"
            for a in AXES if seed.axes[a].margins.phase_margin_deg < 30.0]
    if weak:
        claims.append("its " + " and ".join(weak))
    if seed_rob is not None:
        n = len(seed_rob.loops)
        bad = sum(1 for lp in seed_rob.loops if not lp.stable)
        if bad:
            claims.append(f"{bad} of the {n} perturbed plants are unstable with it (below)")
        else:
            claims.append(f"it stays stable over all {n} perturbed plants, but with a worst "
                          f"gain margin of {seed_rob.worst_gain_margin_db:.1f} dB (below)")
    if not claims:
        return "The ESRF study's controller meets the objective of 6.1 with these margins."
    return "The ESRF study's controller is not the answer to 6.1: " + "; ".join(claims) + "."


def _twin_blocks(check: Any, *, skipped: str = "") -> list[Block]:
    """The closed loop simulated on the study's bench against the linear prediction."""
    if check is None:
        return [f"Does the design hold on the bench? It is not simulated here: {skipped}. "
                "fsmbench does not run a controller on a bench other than the one the "
                "recordings came from."]
    rows = tuple((AXIS_WORDS[a], f"{1e6 * check.measured_rms_rad[a]:.2f}",
                  f"{1e6 * check.predicted_rms_rad[a]:.2f}", f"{check.ratio[a]:.3f}")
                 for a in AXES)
    parts = check.predicted_parts_rad
    names = list(dict.fromkeys(k for a in AXES for k in parts[a]))
    part_rows = tuple((_PARTS.get(k, k.replace("_", " ")),
                       *(f"{1e6 * parts[a].get(k, 0.0):.2f}" for a in AXES)) for k in names)
    worst = max(abs(check.ratio[a] - 1.0) for a in AXES)
    bench = check.bench or "the packaged twin"
    return [
        f"Does the design hold on the bench? fsmbench runs the repeatability experiment "
        f"(1 V, 1 Hz Newport sine) on {bench} in closed loop with fsmbench's controller, "
        f"discretised and executed every sample with the converters' quantisation and every "
        f"noise source of its noise model, for {check.duration_s:g} s (the first "
        f"{check.settle_s:g} s left out). The tracking error is what the 4QD reports in that "
        f"simulation, and it is compared with the linear prediction from the plant model: each "
        f"source through S (or S G for the DAC).",
        Table(caption=f"fsmbench's controller simulated on {bench}: tracking error, simulated "
                      "and predicted",
              header=("axis", "simulated [µrad rms]", "linear prediction [µrad rms]",
                      "simulated / predicted [1]"), rows=rows),
        Table(caption="The prediction's terms", header=("source", "h [µrad rms]",
                                                         "v [µrad rms]"), rows=part_rows),
        f"Simulated and predicted agree within {100 * worst:.1f} %: the linear analysis above "
        f"(loop gains, S, the margins) describes the sampled, quantised closed loop, so its "
        f"verdicts carry over to the implementation. The reported error is dominated by the "
        f"4QD's own noise: above the crossover S ≈ 1, so the sensor's noise appears in its own "
        f"reading, and feedback cannot remove it. The Newport's "
        f"1 Hz sine, the disturbance the objective of 6.1 is about, leaves only "
        f"{1e6 * parts['h'].get('newport_sine', np.nan):.2f} µrad rms (h) and "
        f"{1e6 * parts['v'].get('newport_sine', np.nan):.2f} µrad rms (v).",
    ]


def _section10(res: DesignResult) -> Section:
    n2b, newport = res.newport_to_beam, res.newport
    f0 = res.objective.frequency_hz
    att = {name: n2b.attenuation_at(f0, name) for name in n2b.closed}
    words = {"seed_controller": "the ESRF study's controller",
             "fsmbench_controller": "fsmbench's controller"}
    att_text = "; ".join(f"with {words.get(n, n)}: {h:.2e} (h), {v:.2e} (v)"
                         for n, (h, v) in att.items())
    opts = res.options
    return Section(title="10. Newport control", anchor="newport-control", blocks=(
        "The Newport's rotation is the disturbance of the Sercalo loop. With the Sercalo loop "
        "closed, the Newport command reaches the beam through S Gn (ESRF study Fig. 42).",
        newport_to_beam_figure(
            n2b, key="fig42_newport_to_beam", seed_ref="Fig. 42",
            title="Newport command to beam angle, Sercalo loop open and closed",
            caption=("|Un → R| on each axis with the Sercalo loop open and closed by each "
                     "controller: the closed-loop curve is the open one times |S|.")),
        f"Attenuation of the Newport's motion at {f0:g} Hz, closed over open: {att_text}.",
        f"The Newport loop (10) aligns the 4QD: the Newport is driven from the beam angle so "
        f"that the beam hits the 4QD's centre. The ESRF study's controller has two integrators and "
        f"a lead of ratio {opts.newport_lead_ratio:g} at a crossover of "
        f"{opts.newport_crossover_hz:g} Hz, scaled by the inverse static gain of the Newport "
        f"path.",
        loop_gain_figure(
            newport, key="fig43_newport_loop_gain", seed_ref="Fig. 43",
            title="Loop gains of the Newport alignment loop",
            caption=(f"Bode plot of L = Gn Kn on each axis with the ESRF study's Newport controller"
                     f"; plant: {newport.plant_source}, the Newport's 0.5 ms delay "
                     f"exact; phase unwrapped and placed in (−360°, 0] at the crossover.")),
        _stability(newport),
        _margins_table(newport, who="the Newport controller", objective=False),
    ))


def control_sections(res: DesignResult, *, twin_check: TrackingCheck | None,
                     skipped: str = "", plant_source: str) -> list[Section]:
    """The six control chapters: "5. Plant uncertainty" … "10. Newport control".

    Parameters
    ----------
    res : DesignResult
        The design study (``DesignStage.result``).
    twin_check : TrackingCheck or None
        fsmbench's controller run on the simulated bench; None when there was none
        (``skipped`` says why).
    skipped : str
    plant_source : str
        Where the plant comes from, in words (identified, nominal …).

    Returns
    -------
    list of Section
        In the ESRF study's order, each a sequence of text, tables and figures.
    """
    sec5 = _section5(res)
    intro = (f"Plant of the control chapters: {plant_source}. Every loop below is closed "
             f"around it with its input delays exact.")
    sec5 = Section(title=sec5.title, anchor=sec5.anchor, blocks=(intro, *sec5.blocks))
    return [sec5, _section6(res), _section7(res), _section8(res),
            _section9(res, twin_check, skipped=skipped),
            _section10(res)]
