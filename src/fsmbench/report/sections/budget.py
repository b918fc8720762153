"""Report section 4: the error budget (ESRF study section 4, 4.1–4.5)."""

from __future__ import annotations

from fsmbench.budget.environment import SEED_4_3, DriftTerm
from fsmbench.budget.result import BudgetResult
from fsmbench.budget.table import BudgetRow, ErrorBudget
from fsmbench.report.figures.budget import (
    angle_asd_figure,
    beam_path_figure,
    distance_cumulative_figure,
    path_error_figure,
)
from fsmbench.report.html import Block, Note, Section, Table

__all__ = ["budget_section", "budget_table"]

NM = 1e9
UM = 1e6
PM = 1e12

# Short errata next to the budget rows they explain (docs/seed-errata.md).
_ROW_NOTE = {
    "ADC quantisation (4QD channels)":
        "E28–E29: one LSB is 9.8 µrad (h) of beam angle, not 0.46; the law is quadratic",
    "4QD electronic noise":
        "E28–E29: 1 mV is 32 µrad (h); the ESRF study's 1.5 nm uses a linear 10⁻⁶ gain",
    "Sercalo DAC quantisation":
        "E30: in closed loop the rounding drives the notched modes; mirror piston",
    "geometric cross terms between angle sources": "(Σ α)² has cross products (4.1)",
    "air refractive index":
        "E16, E31: Ciddor at 1530 nm; eq. (11) combines full ranges, here residual drifts",
    "metrology frame expansion": "E34: 1.15 µm/K, not ≈1; frame drift over the record",
}


def _nm(x: float | None) -> str:
    return "-" if x is None else f"{x * NM:.3g}"


def _section_words(s: str) -> str:
    return "not in the ESRF study" if s in ("—", "") else s


def budget_table(b: ErrorBudget) -> Table:
    """The budget table: every source in nm rms, bias, the ESRF study's number and a short note."""
    def row(r: BudgetRow) -> tuple[str, ...]:
        note = _ROW_NOTE.get(r.name, "")
        seed = "; ".join(x for x in dict.fromkeys((r.seed_note, note)) if x)
        return (r.name[0].upper() + r.name[1:], _section_words(r.section), r.mechanism,
                _nm(r.rms_m), _nm(r.bias_m), _nm(r.seed_m), seed)
    rows = tuple(row(r) for r in sorted(b.rows, key=lambda r: -r.rms_m))
    rows += (("Total (root sum of squares)", "", "", _nm(b.total_rms_m), _nm(b.total_bias_m),
              "", ""),)
    window = ("stationary" if b.window_s is None
              else f"over a {b.window_s:g} s record with its mean removed")
    return Table(
        caption=f"Error budget of the Attocube distance, {b.configuration}, {window}",
        header=("source", "ESRF study section", "mechanism", "rms [nm]", "bias [nm]",
                "ESRF study's value [nm]", "ESRF study's number and note"),
        rows=rows,
        note="Bias: the mean shift the quadratic (geometric) term adds; it is not in the rms. "
             "Rows sorted by rms; the rows add in quadrature to the total exactly.")


def _geometry(result: BudgetResult) -> Section:
    g = result.geometry
    t4 = g.table4
    rows = tuple((f"{th * UM:g}", f"{p * PM:.3g}", f"{m * PM:.3g}", f"{s * NM:g}")
                 for th, p, m, s in zip(t4.theta_rad, t4.path_error_m, t4.measured_error_m,
                                        [1e-9, 25e-9, 100e-9], strict=True))
    blocks: tuple[Block, ...] = (
        "An angle error δθc of the Sercalo (from its ideal 45°) lengthens the beam path. The "
        "ESRF study traces the path O → S → Y → M → T for H = L = 50 mm; the same exact trace is "
        f"done here for the bench's H = {g.h_m * 1e3:g} mm, L = {g.l_m * 1e3:g} mm.",
        f"The round-trip path grows as k·δθc² with k = 12H + 8L = "
        f"{g.path_error_m_per_rad2:.4g} m/rad² (fit to the trace: {g.fit.k_fit_m_per_rad2:.6g}; "
        f"the trace departs from the law by at most {g.max_check_relative_difference:.1e} "
        "relative up to 0.1 mrad over H, L from 20 to 100 mm). The Attocube reads half the "
        f"round trip: {g.measured_error_m_per_rad2:.4g} m/rad² of Sercalo angle, "
        f"{g.measured_error_m_per_beam_rad2:.4g} m/rad² of beam angle (α = 4δθc).",
        path_error_figure(g),
        Table(caption="Table 4 recomputed: distance error for a Sercalo angle error",
              header=("angle error δθc [µrad]", "round-trip path [pm]",
                      "measured by the Attocube [pm]", "ESRF study's Table 4 [nm]"),
              rows=rows),
        Note("Eq. (8) δL = δθc² holds only for H = L = 50 mm and its coefficient has units "
             "(m/rad²); 1 µrad gives 1 pm of path, 0.5 pm measured: the ESRF study's Table 4 is "
             "1000× too large.", ref="errata E15"),
        "Figure 35 checks the trace at a large angle, where the deviation is visible.",
        beam_path_figure(g),
    )
    return Section(title="4.1 Angle error of the Sercalo and the measured distance",
                   blocks=blocks)


def _perpendicular(result: BudgetResult) -> Section:
    g = result.geometry
    sm, nm_ = g.sercalo_motion, g.newport_motion
    ratio_s = float(sm.path_change_m[0] / sm.shift_m[0])
    ratio_n = float(nm_.path_change_m[0] / nm_.shift_m[0])
    blocks: tuple[Block, ...] = (
        "A mirror moving along its normal changes the path directly. From the trace: a "
        f"Sercalo shift δdc changes the round-trip path by {ratio_s:+.3g}·δdc (two reflections "
        f"at 45°), a Newport shift δdn by {ratio_n:+.3g}·δdn (normal incidence); the Attocube "
        f"reads half: {abs(ratio_s) / 2:.3g} and {abs(ratio_n) / 2:.3g} nm per nm.",
        Note("Eq. (9) δL = 2·δdc misses the 45° incidence: each of the two reflections adds "
             "2·δd·cos 45°, so δL = 2√2·δdc (√2·δdc measured). Eq. (10) for the Newport is "
             "right.", ref="errata E18"),
        "In the budget this is the piston term: the beam hits each mirror off its rotation "
        "axis, so every mirror angle the noise causes also moves the mirror surface along the "
        "beam. It is linear in the angle, unlike the geometric term of 4.1, and carried by "
        "every angle source in 4.5.",
    )
    return Section(title="4.2 Motion of the mirrors perpendicular to their surface",
                   blocks=blocks)


def _term_row(t: DriftTerm) -> tuple[str, ...]:
    return (t.name[0].upper() + t.name[1:], f"{t.m_per_unit * NM:.3g}", f"{t.rms_unit:g}",
            f"{t.tau_s:g}", f"{t.stationary_rms_m * NM:.3g}", f"{t.window_rms_m * NM:.3g}")


def _air(result: BudgetResult) -> Section:
    a = result.air
    s = a.sensitivity
    header = ("variation", "error, Ciddor [nm]", "ESRF study [nm]")
    blocks: tuple[Block, ...] = (
        f"The Attocube measures {a.path_m * 1e3:g} mm of air at {s.wavelength_m * 1e9:g} nm. "
        f"Ciddor's refractive index at {s.temperature_c:g} °C, {s.pressure_pa / 100:g} hPa and "
        f"{s.humidity_pct:g} %RH gives ∂n/∂T = {s.ppm_per_k:.4g} ppm/K, ∂n/∂P = "
        f"{s.ppm_per_hpa:.4g} ppm/hPa and ∂n/∂RH = {s.dn_drh_per_pct * 1e6:.3g} ppm/%RH "
        f"(ESRF study: {SEED_4_3['k_t_ppm_per_k']:g}, {SEED_4_3['k_p_ppm_per_hpa']:g} and "
        f"{SEED_4_3['k_rh_ppm_per_pct']:g}, signs not given).",
        Table(caption="Air variations without the compensation unit",
              header=header,
              rows=tuple((v.label, f"{v.error_m * NM:+.3g}", f"{v.seed_m * NM:g}")
                         for v in a.without_compensation)),
        Table(caption="Residual ranges with the environmental compensation unit",
              header=header,
              rows=tuple((v.label, f"±{abs(v.error_m) * NM:.3g}", f"±{v.seed_m * NM:g}")
                         for v in a.with_compensation)),
        f"The ESRF study's eq. (11) combines the compensated full ranges to 54 nm; with Ciddor "
        f"that is {a.eq11_full_range_rss_m * NM:.3g} nm (half ranges: "
        f"{a.eq11_half_range_rss_m * NM:.3g} nm).",
        Note("The ESRF study's ±25 nm for ±1 hPa contradicts its own 0.27 ppm/hPa (±27 nm); Ciddor "
             "gives 94.5 nm/K (the ESRF study: 100), 26.5 nm/hPa (27) and 8.7 nm per 10 %RH (10).",
             ref="errata E16, E31"),
        "Eq. (11) is a range, not what a record sees. The budget uses drifts: each residual "
        "error of the compensation unit (and the beam-path temperature under the shielding) "
        "as a first-order random process of the given rms and correlation time, of which a "
        "record with its mean removed keeps only the part faster than the record.",
        Table(caption=f"Air terms of the budget ({'with' if a.compensation_unit else 'without'}"
                      f" compensation unit, {'with' if a.shielding else 'without'} shielding)",
              header=("drift", "sensitivity [nm per unit]", "rms [unit]",
                      "correlation time [s]", "stationary rms [nm]",
                      "rms over the record [nm]"),
              rows=tuple(_term_row(t) for t in a.terms),
              note="Units: K for temperatures, Pa for pressure, %RH for humidity."),
        f"Total air term: {a.window_rms_m * NM:.3g} nm rms over the record "
        f"({a.stationary_rms_m * NM:.3g} nm stationary).",
    )
    return Section(title="4.3 Refractive index of the air", blocks=blocks)


def _frame(result: BudgetResult) -> Section:
    f = result.frame
    blocks: tuple[Block, ...] = (
        f"The {f.frame_length_m * 1e3:g} mm of aluminium frame between the Attocube head and "
        f"its reflector expand by {f.aluminium_m_per_k * 1e6:.3g} µm/K "
        f"(α = {f.expansion_per_k * 1e6:g}·10⁻⁶/K); invar would give "
        f"{f.invar_m_per_k * NM:.3g} nm/K. Within the ESRF study's 0.1 K: "
        f"{f.aluminium_at_max_dt_m * NM:.3g} nm (aluminium), {f.invar_at_max_dt_m * NM:.3g} nm "
        "(invar).",
        Note("0.05 m × 23·10⁻⁶/K is 1.15 µm/K, 13 % more than the ESRF study's ≈1 µm/K.",
             ref="errata E34"),
        f"The budget takes the frame temperature as a slow drift of "
        f"{f.frame_temperature_stationary_rms_k * 1e3:.3g} mK rms: "
        f"{f.stationary_rms_m * NM:.3g} nm stationary, "
        + ("" if f.window_s is None else f"{f.window_rms_m * NM:.3g} nm over a "
                                         f"{f.window_s:g} s record with its mean removed."),
    )
    return Section(title="4.4 Thermal expansion of the metrology frame", blocks=blocks)


def _noise(result: BudgetResult) -> Section:
    n = result.noise
    b = result.budget
    limiting = next(r for r in b.rows if r.name == b.limiting)
    share = (limiting.rms_m / b.total_rms_m) ** 2
    origin = b.spectra_origin
    blocks: list[Block] = [
        f"Sources (ESRF study 4.5a): the converters' quantisation, {n.lsb_v * 1e3:.3g} mV per step "
        f"({n.bits} bits over {n.range_v:g} V), white at q²/(12 fs) = "
        f"{n.adc_psd_v2_per_hz:.3g} V²/Hz two-sided; the Newport's DAC, "
        f"{n.newport_dac_angle_rms_rad * UM:.2g} µrad rms of mirror angle; the Newport's own "
        f"angle noise, {n.newport_angle_noise_rms_rad * UM:g} µrad rms "
        f"({n.newport_beam_angle_rms_rad * UM:g} µrad of beam); the 4QD's electronic noise; "
        f"and in closed loop the Sercalo's DAC. 4QD noise: {origin.get('qd', '-')}; Sercalo "
        f"DAC: {origin.get('sercalo_dac', '-')}.".replace("data_huddle_test_", ""),
        f"One step on Vph is {n.qd_lsb_angle_rad[0] * UM:.3g} µrad of beam angle (h), "
        f"{n.qd_lsb_angle_rad[1] * UM:.3g} µrad (v) (ESRF study: "
        f"{n.seed_qd_lsb_angle_rad * UM:.2g}); "
        f"1 mV is {n.qd_angle_per_volt_rad_per_v[0] * 1e-3 * UM:.3g} µrad (h) "
        f"(ESRF study: {n.seed_qd_angle_rad * UM:.2g} µrad).",
        Note("G = 0.03 rad/V is already 1/|Gd|; dividing again by ΣV = 20 V makes the angle "
             "21× too small.", ref="errata E28"),
        Note("No fixed gain turns an angle error into a distance error: the law is quadratic "
             "(4.1). A zero-mean beam angle of variance σ² per axis gives a bias c·σ² and a "
             "standard deviation √2·c·σ² per axis, c = (6H + 4L)/16. The budget propagates "
             "every spectrum through that law (autoconvolution), and adds the piston term of "
             "4.2.", ref="errata E29"),
        f"Plant: {result.plant_source}. Controller: {result.controller}. Each source goes "
        "through the plant and the loop to the beam angle at the 4QD:",
        angle_asd_figure(b),
        "and from the angle to the Attocube distance, piston plus geometric term:",
        distance_cumulative_figure(b),
        Note(f"The ESRF study's procedure (open loop, 10 Hz–1 kHz, linear 10⁻⁶ gain) gives "
             f"{n.seed_method_sercalo_dac_distance_rms_m:.3g} m here (the ESRF study: "
             "1.647·10⁻¹¹ m): it is set by the 411 Hz mode's damping. In closed loop the 9.2 "
             "controller notches the modes, the DAC's rounding drives them, and as mirror "
             "piston this becomes the largest angle source: the ESRF study's Important 9 "
             "(\"does not limit\") does not hold.",
             ref="errata E30"),
        budget_table(b),
        f"Total {b.total_rms_m * NM:.3g} nm rms ({b.configuration}); the limiting source is "
        f"{b.limiting} ({limiting.rms_m * NM:.3g} nm rms, {share:.0%} of the variance), "
        f"followed by {_second(b)}.",
    ]
    if result.skipped:
        blocks.append("Not used here: " + "; ".join(f"{k} ({v})"
                                                    for k, v in result.skipped.items()) + ".")
    return Section(title="4.5 Noise, beam angle and distance: the budget",
                   blocks=tuple(blocks))


def _second(b: ErrorBudget) -> str:
    rows = sorted(b.rows, key=lambda r: -r.rms_m)[1:3]
    return " and ".join(f"{r.name} ({r.rms_m * NM:.3g} nm)" for r in rows)


def budget_section(result: BudgetResult, *, plant_source: str) -> Section:
    """ESRF study section 4: the sources of error and the budget table.

    Parameters
    ----------
    result : BudgetResult
        From :func:`fsmbench.budget.study.budget_study`.
    plant_source : str
        Where the plant came from, in words (e.g. "identified from the recordings").
    """
    b = result.budget
    window = "" if b.window_s is None else f", over records of {b.window_s:g} s"
    intro = (
        "Every source of error of the Attocube distance, propagated to the measurement and "
        f"summed, for the configuration of the repeatability measurement ({b.configuration}"
        f"{window}). Plant: {plant_source}. Angle sources (4.5) reach the distance twice: "
        "through the geometry of the beam path (4.1, quadratic) and as mirror piston (4.2, "
        "linear); the air (4.3) and the frame (4.4) add linearly.")
    return Section(title="4. Error budget", anchor="budget", blocks=(intro,),
                   subsections=(_geometry(result), _perpendicular(result), _air(result),
                                _frame(result), _noise(result)))
