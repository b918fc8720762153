"""Chapter 2 of the report: identification of the system dynamics (ESRF study section 2).

Subsections follow the ESRF study: 2.1 4QD calibration, 2.2 current amplifier,
2.3 Sercalo, 2.4 Newport, 2.5 full system. Each shows the recordings it
uses (time plots), then what was identified from them; a step that did not
run says why in words and still shows the recordings that exist.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import xarray as xr

from fsmbench.bench.params import Bench
from fsmbench.ident.fit.quality import MAX_DIRECT_FIT_ERROR, MIN_DIRECT_VAF
from fsmbench.ident.newport import NewportIdentification
from fsmbench.ident.result import ESRF_TRIMS_S, Identification
from fsmbench.ident.sercalo import SercaloIdentification
from fsmbench.io.signals import EXPERIMENTS
from fsmbench.report.figures.ident import (
    PHASE_MIN_RUN,
    PHASE_STD_MAX_DEG,
    coherence_figure,
    current_amplifier_figure,
    estimator_description,
    frf_matrix_figure,
    newport_delay_figure,
    newport_model,
    qd_regression_figure,
    sercalo_model,
    weights_figure,
)
from fsmbench.report.figures.ident_model import model_band_figure, model_compare_figure
from fsmbench.report.figures.spec import Figure
from fsmbench.report.figures.time import SEED_TIME_FIGURES, experiment_figure
from fsmbench.report.html import Block, Note, Section, Table
from fsmbench.report.sections.delay_tables import sensor_note, sercalo_delay_blocks
from fsmbench.report.sections.ident_newport import (
    _newport_constant_gain_note,
    _newport_dynamics_table,
    _newport_gains_table,
)
from fsmbench.report.sections.ident_uncertainty import total_cells, uncertainty_table
from fsmbench.twin.compare import TARGETS, ComparisonRow, comparison_rows, quantity

# How the FRF figures draw the phase, for their captions.
PHASE_WORDS = (f"The phase is unwrapped along the line and drawn only where it is known to "
               f"±{PHASE_STD_MAX_DEG:g}° (one standard deviation: from the coherence and the "
               "number of averages, or the estimator's noise variance) on at least "
               f"{PHASE_MIN_RUN} neighbouring lines; elsewhere it is left out, and an "
               "element with no such lines and no model to follow shows it as faint dots")

__all__ = ["comparison_table", "identification_section", "quantity"]

_AXIS = {"h": "h (horizontal)", "v": "v (vertical)"}
_STEP = {"qd": "the 4QD calibration", "current_amp": "the current-amplifier identification",
         "sercalo": "the Sercalo identification", "newport": "the Newport identification",
         "mode_refinement": "the refinement of the Sercalo modes on the time records"}
_BLOCKS = {"Gi": "Gi, current amplifier", "Zc": "Zc, coil impedance",
           "Ga": "Ga, voltage amplifier", "Gc": "Gc, Sercalo", "Gn": "Gn, Newport",
           "Gd": "Gd, 4QD"}
_BLOCK_SOURCE = {"Gi": "2.2", "Gc": "2.3", "Gn": "2.4", "Gd": "2.1"}
_INPUTS = {"Uch": "Sercalo command, h (Uch)", "Ucv": "Sercalo command, v (Ucv)",
           "Unh": "Newport command, h (Unh)", "Unv": "Newport command, v (Unv)"}
_DIRECT = {"h": ("Ich", "Vph"), "v": ("Icv", "Vpv")}


def _target(row: ComparisonRow) -> tuple[str, str]:
    """(target, difference) in words with units."""
    kind, tol = TARGETS[row.key]
    _name, unit, scale = quantity(row.key)
    if row.tolerance_abs is not None:
        diff = (row.identified - row.reference) * scale
        what = f" ({tol:g} sample)" if kind == "samples" else ""
        return (f"±{row.tolerance_abs * scale:.3g} {unit}".strip() + what,
                f"{diff:+.3g} {unit}".strip())
    return f"±{100 * tol:.3g} %", f"{100 * row.relative_difference:+.3f} %"


def comparison_table(result: Identification, *, bench: Bench,
                     truth: Mapping[str, Any] | None) -> Table | None:
    """Identified values against the twin's truth (when given) or the nominal model."""
    rows = comparison_rows(result.to_json(), reference=truth, bench=bench)
    if not rows:
        return None
    out = []
    for r in rows:
        name, _unit, scale = quantity(r.key)
        target, diff = _target(r)
        total, largest = total_cells(result.uncertain(r.key), scale)
        cells = [name, f"{r.identified * scale:.6g}", total, largest,
                 f"{r.reference * scale:.6g}", diff]
        if truth is not None:
            cells += [target, {True: "yes", False: "no", None: "–"}[r.within_target]]
        out.append(tuple(cells))
    uncertainty = ("± total", "largest part of the uncertainty (share of the variance)")
    if truth is not None:
        met = sum(1 for r in rows if r.within_target)
        return Table(caption=("Identified values against the twin's true values; ± is the "
                              "total uncertainty (one standard deviation, every part)"),
                     header=("quantity", "identified", *uncertainty, "true value (twin)",
                             "difference", "accuracy target", "within target"),
                     rows=tuple(out),
                     note=f"{met} of {len(rows)} values within their accuracy targets.")
    return Table(caption=("Identified values against the nominal model; ± is the total "
                          "uncertainty (one standard deviation, every part)"),
                 header=("quantity", "identified", *uncertainty, "nominal value",
                         "difference"),
                 rows=tuple(out),
                 note=("The nominal values come from datasheets, measured components and the "
                       "ESRF study's Table 2: the difference is how far this bench is from them, "
                       "not "
                       "an error of the identification."))


def _trims(result: Identification | None) -> Mapping[str, float]:
    return result.options.trims_s if result is not None else ESRF_TRIMS_S


def _time_figure(name: str, recordings: Mapping[str, xr.Dataset], *, bench: Bench,
                 trims: Mapping[str, float]) -> list[Figure]:
    if name not in recordings:
        return []
    key, ref, title = SEED_TIME_FIGURES[name]
    trim = float(trims.get(name, 0.0))
    info = EXPERIMENTS[name]
    caption = f"Record {name}. {info.description}; the whole record."
    if trim > 0:
        caption += f" Grey: the first {trim:g} s, which the ESRF study's processing removes."
    return [experiment_figure(recordings[name], key=key, title=title,
                              caption=caption, seed_ref=ref,
                              gn0_rad_per_v=bench.nominal.newport.metrology_gain_rad_per_v,
                              trim_s=trim)]


def _not_run(step: str, experiments: Sequence[str], *, result: Identification | None,
             recordings: Mapping[str, xr.Dataset], skipped: Mapping[str, str]) -> str | None:
    """Why a step produced nothing, in words; None when it ran."""
    if result is not None and step not in result.skipped:
        return None
    reason = result.skipped[step] if result is not None else "the identification did not run"
    text = f"Not identified: {_STEP[step]} gave no result. Reason: {reason}."
    gone = [f"{e} (not loaded: {skipped[e]})" if e in skipped else f"{e} (not in the data)"
            for e in experiments if e not in recordings]
    if gone:
        text += " Missing recordings: " + "; ".join(gone) + "."
    text += " The study uses the nominal block instead."
    return text


def _qd(result: Identification | None, *, recordings: Mapping[str, xr.Dataset], bench: Bench,
        skipped: Mapping[str, str]) -> Section:
    exps = ("data_cal_pd_h", "data_cal_pd_v")
    blocks: list[Block] = [
        "The 4QD is calibrated against the Newport's metrology: the Newport sweeps the beam "
        "slowly while its metrology reads the mirror angle "
        f"(gn0 = {bench.nominal.newport.metrology_gain_rad_per_v * 1e3:.2f} mrad/V). The beam "
        "angle is twice the mirror angle, and a linear regression of the 4QD voltage on it "
        "gives the 4QD gain in V/rad.",
    ]
    for name in exps:
        blocks += _time_figure(name, recordings, bench=bench, trims=_trims(result))
    why = _not_run("qd", exps, result=result, recordings=recordings, skipped=skipped)
    if why or result is None:
        blocks.append(why or "")
    else:
        if all(c.experiment in recordings for c in result.qd.values()):
            blocks.append(qd_regression_figure(result.qd, recordings))
        blocks.append(Table(
            caption="4QD gains from the linear regression (ESRF study Table 2)",
            header=("axis", "gain [V/rad]", "± total [V/rad]", "sensitivity [µrad/mV]",
                    "offset [mV]", "R² [1]", "residual rms [mV]", "beam-angle range [mrad]",
                    "samples"),
            rows=tuple((_AXIS[a], f"{c.gain_v_per_rad:.4f}",
                        f"{_total(result, 'qd_gain_v_per_rad.' + a, c.gain_std_v_per_rad):.2g}",
                        f"{c.sensitivity_urad_per_mv:.2f}", f"{1e3 * c.offset_v:.3f}",
                        f"{c.r_squared:.6f}", f"{1e3 * c.residual_rms_v:.3f}",
                        f"{1e3 * c.beam_angle_range_rad:.3f}", str(c.n_samples))
                       for a, c in result.qd.items())))
        blocks.append(Note("The ESRF study calls the slope a gain in rad/V and quotes 0.032 rad/V; "
                           "the slope is in V/rad (its Table 2), and its inverse is the "
                           "sensitivity in µrad/mV (1/36.3 V/rad is 27.5 µrad/mV, not 27.6).",
                           ref="errata E6, E7"))
    return Section(title="2.1 Calibration of the 4-quadrant diode (4QD)", blocks=tuple(blocks))


def _current_amp(result: Identification | None, *, recordings: Mapping[str, xr.Dataset],
                 bench: Bench, skipped: Mapping[str, str]) -> Section:
    exps = ("data_uch", "data_ucv")
    band = result.options.current_amp_band_hz if result is not None else (20.0, 200.0)
    blocks: list[Block] = [
        "Noise on the Sercalo's commands Uc drives the current amplifier; the amplified coil "
        "voltage Vc is recorded with the 4QD outputs. The same records serve 2.3. From "
        "Uc → Vc = Ga·Zc·Gi, with the voltage amplifier Ga and the coil impedance Zc taken as "
        f"known, Gi is fitted over {band[0]:g}–{band[1]:g} Hz with the path as the converters "
        "sample it (the DAC's hold and the delay): the ESRF study's ratio to the continuous "
        "|Ga Zc| is biased by the hold by twenty times its noise.",
    ]
    for name in exps:
        blocks += _time_figure(name, recordings, bench=bench, trims=_trims(result))
    why = _not_run("current_amp", exps, result=result, recordings=recordings, skipped=skipped)
    if why or result is None:
        blocks.append(why or "")
    else:
        # The estimates the identification fitted: the report estimates nothing again.
        drawn = {a: g for a, g in result.current_amp.items() if g.frf is not None}
        if drawn:
            blocks.append(current_amplifier_figure(drawn, bench.nominal))
        blocks.append(Table(
            caption="Current-amplifier gains",
            header=("axis", "identified Gi [mA/V]", "± total [mA/V]", "1/(R + Rc) [mA/V]",
                    "identified / theoretical [1]", "fitted band [Hz]"),
            rows=tuple((_AXIS[a], f"{1e3 * g.gain_a_per_v:.4f}",
                        "%.2g" % (1e3 * _total(result, "current_amp_gain_a_per_v." + a,
                                               g.gain_std_a_per_v)),
                        f"{1e3 * g.theoretical_a_per_v:.4f}",
                        f"{g.ratio_to_theoretical:.4f}", f"{g.band_hz[0]:g}–{g.band_hz[1]:g}")
                       for a, g in result.current_amp.items())))
        blocks.append("The ESRF study finds the same kind of mismatch with the theoretical gain "
                      "and "
                      "keeps the identified one, the voltage amplifier being accurately known.")
        blocks.append(Note("The ESRF study says it removes the first seconds of these records but "
                           "its "
                           "code estimates on the whole record; fsmbench removes the first "
                           "second, when the Sercalo is off, as in 2.1 and 2.3.",
                           ref="errata E13"))
    return Section(title="2.2 Sercalo impedance, current amplifier and voltage amplifier",
                   blocks=tuple(blocks))


def _delay_table(part: SercaloIdentification | NewportIdentification, *, caption: str) -> Table:
    rows = [(f"{d.input} → {d.output}", f"{1e3 * d.delay_s:.4f}", f"{1e3 * d.std_s:.2g}",
             f"{d.band_hz[0]:.0f}–{d.band_hz[1]:.0f}") for d in part.delays]
    rows.append(("common delay removed", f"{1e3 * part.delay_s:.4f}",
                 f"{1e3 * part.delay_std_s:.2g}", "–"))
    return Table(caption=caption, header=("path", "delay [ms]", "± [ms]", "band [Hz]"),
                 rows=tuple(rows))


def _vaf(result: Identification, key: str) -> str:
    out, inp = key.split("/")
    for v in result.validation:
        if v.output == out and v.input == inp:
            return f"{100 * v.vaf:.3f}"
    return "–"


def _fit_words(result: Identification) -> str:
    """The fitted FRF in words: "the 1 s Welch estimate", "the LPM estimate" …"""
    frf = result.sercalo.frf if result.sercalo is not None else None
    if frf is None or frf.estimator == "welch":
        return f"the {result.options.window_s:g} s Welch estimate"
    return {"lpm": "the local-polynomial estimate",
            "periodic": "the period-averaged estimate"}.get(frf.estimator, "the estimate")


def _total(result: Identification, key: str, fallback: float) -> float:
    """The total std of ``key`` (every part), else ``fallback`` (a part alone)."""
    u = result.uncertain(key)
    return u.std if u is not None else float(fallback)


def _modes_table(result: Identification) -> Table:
    modes = {a: {**m, "resonance_hz_std": _total(result, f"sercalo.{a}.resonance_hz",
                                                   m["resonance_hz_std"]),
                 "damping_ratio_std": _total(result, f"sercalo.{a}.damping_ratio",
                                             m["damping_ratio_std"])}
             for a, m in result.sercalo_modes().items()}
    fit = _fit_words(result)
    if result.modes is not None:
        initial = result.modes.initial
        return Table(
            caption=("Sercalo modes, re-estimated on the full records (frequency-domain output "
                     f"error), against the vector fit of {fit}; ± is the total uncertainty, one "
                     "standard deviation"),
            header=("axis", "resonance [Hz]", "± [Hz]", "damping ratio [1]", "± [1]",
                    "damping ratio from the fit [1]", "fit / re-estimated [1]"),
            rows=tuple((_AXIS[a], f"{m['resonance_hz']:.4f}", f"{m['resonance_hz_std']:.2g}",
                        f"{m['damping_ratio']:.4e}", f"{m['damping_ratio_std']:.2g}",
                        f"{initial[a][1]:.4e}", f"{initial[a][1] / m['damping_ratio']:.2f}")
                       for a, m in modes.items()))
    return Table(caption=f"Sercalo modes from the vector fit of {fit} (not re-estimated on the "
                         "full records); ± is the total uncertainty, one standard deviation",
                 header=("axis", "resonance [Hz]", "± [Hz]", "damping ratio [1]", "± [1]"),
                 rows=tuple((_AXIS[a], f"{m['resonance_hz']:.4f}", f"{m['resonance_hz_std']:.2g}",
                             f"{m['damping_ratio']:.4e}", f"{m['damping_ratio_std']:.2g}")
                            for a, m in modes.items()))


def _parameter_std_table(result: Identification) -> Table | None:
    """The variance-weighted fit's parameters with their propagated standard deviations."""
    ps = result.sercalo.parameter_std if result.sercalo is not None else None
    if ps is None:
        return None

    def pm(value: float, std: float, fmt: str) -> str:
        return f"{value:{fmt}} ± {std:.2g}" if math.isfinite(std) else f"{value:{fmt}}"

    rows = tuple((_AXIS[a], pm(v["resonance_hz"], ps.std[a]["resonance_hz"], ".4f"),
                  pm(v["damping_ratio"], ps.std[a]["damping_ratio"], ".4e"),
                  pm(v["dc_gain_v_per_a"], ps.std[a]["dc_gain_v_per_a"], ".3f"))
                 for a, v in ps.value.items())
    held = (" The poles were replaced by the re-estimated modes, so only the gain's standard "
            "deviation comes from this fit." if ps.fixed_poles else "")
    return Table(
        caption=("Sercalo parameters of the fit weighted by the inverse standard deviation of "
                 "each line; ± is one standard deviation propagated from the lines' variances "
                 f"(reduced chi-square of the fit {ps.chi2_per_dof:.2f}; the current-amplifier "
                 "gain and the delay taken as known)." + held),
        header=("axis", "resonance [Hz]", "damping ratio [1]", "static gain [V/A]"),
        rows=rows)


def _sercalo(result: Identification | None, *, recordings: Mapping[str, xr.Dataset],
             skipped: Mapping[str, str]) -> Section:
    blocks: list[Block] = [
        "The same noise records give the frequency-response matrix from the Sercalo's "
        "commands Uc to the 4QD outputs Vp (Welch estimate, 1 s Hann window; the records are "
        "shown in 2.2). The pure delay is estimated from the phase and removed, and a rational "
        "model is fitted by weighted vector fitting; each mode's frequency and damping are "
        "then re-estimated on the full records, which the 1 s window cannot resolve. Dividing "
        "by the identified Gi gives Gc, from coil current to 4QD voltage.",
    ]
    why = _not_run("sercalo", ("data_uch", "data_ucv"), result=result, recordings=recordings,
                   skipped=skipped)
    if why or result is None or result.sercalo is None:
        blocks.append(why or "Not identified: the Sercalo identification did not run. The "
                      "study uses the nominal block instead.")
        return Section(title="2.3 Sercalo dynamics", blocks=tuple(blocks))
    s = result.sercalo
    how = estimator_description(s.frf)
    blocks.append(f"Frequency response estimated by {how}.")
    blocks.append(coherence_figure(
        s.frf, key="fig17_sercalo_coherence", title="Sercalo: coherence of Uc → Vp",
        caption=(f"Coherence of each element ({how}; for a non-Welch estimate the coherence "
                 "a noise-free input would give with the estimated output noise)"
                 + ("; the fit weights it (Fig. 20)." if s.options.weights == "seed" else ".")),
        seed_ref="Fig. 17"))
    blocks.append(frf_matrix_figure(
        s.frf, delay_s=s.delay_s, model=sercalo_model(s), key="fig18_22_sercalo_frf",
        title="Sercalo: frequency-response matrix Uc → Vp and its fit",
        caption=(f"Measured (colour; {how}) with the delay of {1e3 * s.delay_s:.4f} ms removed, "
                 f"and the fitted model (dashed, {s.fit.n_poles} poles"
                 + (", modes re-estimated on the full records" if result.modes is not None
                    else "") + "); magnitude above phase for each element. " + PHASE_WORDS
                 + (f"; thin lines: the {100 * s.frf.confidence:g} % confidence bounds of each "
                    "line" if s.frf.frf_variance is not None else
                    "; no per-line variance with this estimator, so no bounds drawn") + "."),
        seed_ref="Figs. 18, 19, 21, 22"))
    blocks.extend(sercalo_delay_blocks(s))
    blocks.append(Note("The ESRF study removes one sample (0.1 ms). The DAC applies a command one "
                       "sample after it is computed and holds it for a sample, which adds half "
                       "a sample: the path's delay is 1.5 samples (0.15 ms), as estimated here.",
                       ref="errata E20"))
    blocks.append(weights_figure(s))
    blocks.append(_modes_table(result))
    if (std_table := _parameter_std_table(result)) is not None:
        blocks.append(std_table)
    if result.modes is not None:
        blocks.append(Note("A mode with a damping ratio near 1e-3 has a half-power bandwidth "
                           "below 1 Hz, finer than the 1 s window resolves: the vector fit of "
                           "the Welch estimate overestimates the damping (the last column). The "
                           "re-estimate on the full records does not have that bias.",
                           ref="errata E21"))
    else:
        blocks.append(Note("The damping ratios above come from the 1 s Welch estimate, which "
                           "overestimates a damping near 1e-3 (the re-estimate on the full "
                           f"records was skipped: {result.skipped.get('mode_refinement', '')}).",
                           ref="errata E21"))
    blocks.append(Table(
        caption=("Fit quality: rms relative magnitude error over 10 Hz–1 kHz where the "
                 "coherence exceeds 0.9, and the share of each recorded output's variance the "
                 "model reproduces in the time domain"),
        header=("path", "rms relative error [%]", "variance accounted for [%]"),
        rows=tuple((k.split("/")[1] + " → " + k.split("/")[0], f"{100 * v:.2f}", _vaf(result, k))
                   for k, v in s.fit_error.items()),
        note=(f"Limits for the direct paths: error ≤ {100 * MAX_DIRECT_FIT_ERROR:g} %, "
              f"variance accounted for ≥ {100 * MIN_DIRECT_VAF:g} %.")))
    return Section(title="2.3 Sercalo dynamics", blocks=tuple(blocks))


def _newport_frf_figure(n: NewportIdentification) -> Figure:
    """The Newport's frequency-response matrix, with the fitted second order of each axis
    (or, without the dynamics, the signed constant gains) dashed."""
    nhow = estimator_description(n.frf)
    dyn = n.dynamics
    first = n.identified_axes[0]
    model_words = ("dashed: each axis's fitted second order with the hold's droop, over the "
                   f"{dyn.axes[first].band_hz[0]:.3g}–{dyn.axes[first].band_hz[1]:.4g} Hz band it "
                   "was fitted on" if dyn is not None else
                   f"dashed: the signed constant gains over the {n.band_hz[0]:g}–"
                   f"{n.band_hz[1]:g} Hz band they are averaged on")
    return frf_matrix_figure(
        n.frf, delay_s=n.delay_s, model=newport_model(n), key="fig26_27_newport_frf",
        title="Newport: frequency-response matrix Un → Vp",
        caption=(f"Measured ({nhow}) with the delay of {1e3 * n.delay_s:.4f} ms removed; "
                 + model_words + ". " + PHASE_WORDS
                 + (f"; thin lines: {100 * n.frf.confidence:g} % confidence bounds"
                    if n.frf.frf_variance is not None else "") + "."),
        seed_ref="Figs. 26, 27",
        model_name="second order (model)" if dyn is not None else "constant gain (model)")


def _newport(result: Identification | None, *, recordings: Mapping[str, xr.Dataset],
             bench: Bench, skipped: Mapping[str, str]) -> Section:
    exps = ("data_unh", "data_unv")
    blocks: list[Block] = [
        "Noise on the Newport's commands Un, one axis after the other, with the 4QD outputs "
        "recorded. The frequency-response matrix Un → Vp is nearly diagonal and flat up to "
        "a few hundred hertz; the ESRF study models it as a constant gain per axis (mean over "
        "10–100 Hz) after removing the delay, fsmbench fits each axis's second order and "
        "delay together and compares them with the FSM-300 datasheet.",
    ]
    for name in exps:
        blocks += _time_figure(name, recordings, bench=bench, trims=_trims(result))
    why = _not_run("newport", exps, result=result, recordings=recordings, skipped=skipped)
    if why or result is None or result.newport is None:
        blocks.append(why or "Not identified: the Newport identification did not run. The "
                      "study uses the nominal block instead.")
        return Section(title="2.4 Newport dynamics", blocks=tuple(blocks))
    n = result.newport
    blocks.append(coherence_figure(
        n.frf, key="fig25_newport_coherence", title="Newport: coherence of Un → Vp",
        caption=f"Coherence of each element ({estimator_description(n.frf)}).",
        seed_ref="Fig. 25"))
    blocks.append(_newport_frf_figure(n))
    blocks.append(newport_delay_figure(n))
    dyn = n.dynamics
    if dyn is not None:
        blocks.append(_newport_dynamics_table(n, dyn, datasheet=bench.datasheet.newport))
        blocks.append(_newport_constant_gain_note(n, dyn))
        blocks.append(sensor_note(dyn))
    else:
        blocks.append(_newport_gains_table(n))
        blocks.append(Note(f"The Newport's dynamics could not be fitted ({n.dynamics_skipped})."))
    blocks.append(_delay_table(n, caption="Newport delays estimated from the phase alone "
                                          "(cross-check)"))
    blocks.append(Note("The ESRF study averages |H| and so drops the sign; with a negative 4QD "
                       "gain "
                       "the path Unh → Vph is negative, and fsmbench keeps the sign. The "
                       "ESRF study's assumed 0.5 ms delay is confirmed by the phase.",
                       ref="errata E19, E20"))
    return Section(title="2.4 Newport dynamics", blocks=tuple(blocks))


def _system(result: Identification | None) -> Section:
    blocks: list[Block] = [
        "The blocks are assembled as the ESRF study's connect does: inputs Uch, Ucv, Unh, Unv; "
        "outputs the coil voltages, coil currents, beam angles and 4QD voltages. A block "
        "that could not be identified from the data is the nominal one.",
    ]
    if result is None:
        blocks.append("The identification did not run: the study uses the nominal model "
                      "(every block from the bench's parameters).")
        return Section(title="2.5 Full system", blocks=tuple(blocks))
    rows = []
    for block, status in result.plant_blocks.items():
        name = _BLOCKS.get(block, block)
        if status == "identified":
            rows.append((name, f"identified ({_BLOCK_SOURCE.get(block, 'section 2')})"))
        elif block in ("Zc", "Ga"):
            rows.append((name, "known: the bench's parameters, as the ESRF study takes it (2.2)"))
        else:
            rows.append((name, "nominal (the bench's parameters)"))
    blocks.append(Table(caption="Blocks of the assembled system", header=("block", "source"),
                        rows=tuple(rows)))
    if result.plant is not None:
        delays = result.plant.input_delay_s
        rows_d = []
        for inp, tau in delays.items():
            part = result.sercalo if inp.startswith("Uc") else result.newport
            rows_d.append((_INPUTS.get(inp, inp), f"{1e3 * tau:.4f}",
                           "identified" if part is not None else "nominal"))
        blocks.append(Table(caption="Pure delays of the assembled system",
                            header=("input", "delay [ms]", "source"), rows=tuple(rows_d)))
    if result.bode_band is not None:
        blocks.append(model_band_figure(result.bode_band))
    if result.comparison is not None and (fig := model_compare_figure(result.comparison)):
        blocks.append("The assembled model against the records it was identified from: each "
                      "open-loop record's command drives the model, and its outputs are "
                      "compared with the recorded ones (NRMSE fit, as MATLAB's compare).")
        blocks.append(fig)
    return Section(title="2.5 Full system", blocks=tuple(blocks))


def _status(result: Identification | None, *, recordings: Mapping[str, xr.Dataset],
            skipped: Mapping[str, str]) -> list[Block]:
    """What ran, what was skipped and whether the Sercalo model can be trusted."""
    if result is None:
        gone = [f"{e} ({skipped.get(e, 'not in the data')})" for e in ESRF_TRIMS_S
                if e not in recordings]
        text = "The identification did not run"
        text += (": missing " + "; ".join(gone) + "." if gone else ".")
        return [text + " The study uses the nominal model; the recordings that exist are "
                "shown below."]
    out: list[Block] = []
    steps = [f"{_STEP.get(k, k)} — {v}" for k, v in result.skipped.items()]
    if steps:
        out.append("Skipped: " + "; ".join(steps) + ".")
    failed = [c for c in result.checks if not c.passed]
    if failed:
        out.append(Note("Plausibility checks of the data that failed: " + " ".join(
            f"{c.subject}: {c.advice}." if c.advice else f"{c.subject}: {c.limit} not met."
            for c in failed)))
    if result.notices:
        out.append(Note("To know about the data: " + " ".join(
            f"{n.subject}: {n.message}." for n in result.notices)))
    if result.warnings:
        out.append(Note("Quality warnings, do not trust the affected results: "
                        + "; ".join(result.warnings) + "."))
    elif result.sercalo is not None and "sercalo" not in result.skipped:
        text = ("The Sercalo model passed its quality checks: the vector fit converged, and on "
                f"the direct paths it is within {100 * MAX_DIRECT_FIT_ERROR:g} % rms of the "
                f"measured response and reproduces more than {100 * MIN_DIRECT_VAF:g} % of the "
                "recorded variance")
        if result.modes is not None:
            text += "; the re-estimates of the modes converged"
        out.append(text + ".")
    return out


def identification_section(result: Identification | None, *,
                           recordings: Mapping[str, xr.Dataset], bench: Bench,
                           truth: Mapping[str, Any] | None,
                           skipped: Mapping[str, str]) -> Section:
    """"2. Identification of the system dynamics", with subsections 2.1–2.5.

    Parameters
    ----------
    result : Identification or None
        What :func:`fsmbench.ident.pipeline.identify` returned; None when it
        did not run.
    recordings : mapping experiment -> Dataset
        The records loaded (time plots, regression points, amplifier FRFs).
    bench : Bench
        Nominal values (the reference without truth, the known blocks).
    truth : mapping, optional
        The twin's ``twin_truth.json``; only then are values compared with
        true values.
    skipped : mapping experiment -> reason
        Experiments not loaded, with the reason in words.
    """
    blocks: list[Block] = [
        "Every block of the signal chain is identified from the recordings, as in the ESRF study's "
        "section 2: the 4QD against the Newport's metrology (2.1), the current amplifier from "
        "Uc → Vc with Ga and Zc known (2.2), the Sercalo from Uc → Vp by weighted vector "
        "fitting after removing the delay (2.3), the Newport's gains and delay (2.4); the "
        "blocks are then assembled (2.5).",
        *_status(result, recordings=recordings, skipped=skipped),
    ]
    if result is not None and (table := comparison_table(result, bench=bench, truth=truth)):
        blocks.append(table)
    if result is not None and (every := uncertainty_table(result)) is not None:
        blocks.append(every)
    subsections = (
        _qd(result, recordings=recordings, bench=bench, skipped=skipped),
        _current_amp(result, recordings=recordings, bench=bench, skipped=skipped),
        _sercalo(result, recordings=recordings, skipped=skipped),
        _newport(result, recordings=recordings, bench=bench, skipped=skipped),
        _system(result),
    )
    return Section(title="2. Identification of the system dynamics", blocks=tuple(blocks),
                   subsections=subsections, anchor="identification")
