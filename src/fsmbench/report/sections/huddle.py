"""Report section 3: the huddle tests (ESRF study section 3)."""

from __future__ import annotations

from collections.abc import Mapping

import xarray as xr

from fsmbench.budget.huddle import HUDDLE_CONFIGS, HuddleRecord
from fsmbench.budget.result import BudgetResult
from fsmbench.report.figures.budget import (
    huddle_attocube_asd_figure,
    huddle_attocube_time_figure,
    huddle_config_words,
    huddle_qd_asd_figure,
    huddle_qd_time_figure,
)
from fsmbench.report.figures.stability import allan_figure, drift_figure, time_axis
from fsmbench.report.html import Block, Note, Section, Table

__all__ = ["huddle_section"]

NM = 1e9
MV = 1e3
_NAMES = tuple(f"data_huddle_test_{n}" for n in sorted(HUDDLE_CONFIGS))


def _config_table(present: set[int]) -> Table:
    rows = []
    for n, (closed, comp, alu) in sorted(HUDDLE_CONFIGS.items()):
        rows.append((str(n), "closed loop" if closed else "open loop", "on" if comp else "off",
                     "yes" if alu else "no", "yes" if n in present else "no"))
    return Table(caption="Table 3: configurations of the huddle tests",
                 header=("test", "loop", "compensation unit", "aluminium shielding",
                         "recorded here"),
                 rows=tuple(rows))


def _missing_paragraph(result: BudgetResult) -> str:
    absent = [f"{n}.mat" for n in _NAMES
              if result.skipped.get(n, "not in the recordings").startswith("not in the recordings")]
    bad = [f"{n}.mat ({result.skipped[n]})" for n in _NAMES if n in result.skipped
           and not result.skipped[n].startswith("not in the recordings")]
    parts = []
    if absent:
        parts.append("missing from the recordings: " + ", ".join(absent))
    if bad:
        parts.append("not usable: " + "; ".join(bad))
    return ("No huddle test could be analysed, so this section has no figure; "
            + "; ".join(parts) + ". The error budget (section 4) then uses the nominal white "
            "4QD noise and the white DAC quantisation model.")


def _lengths(recs: list[HuddleRecord]) -> str:
    lengths = sorted({r.duration_s for r in recs})
    divisor, label = time_axis(max(lengths))
    unit = label.split("[")[1].rstrip("]")
    return " and ".join(f"{d / divisor:.3g} {unit}" for d in lengths)


def _stability_blocks(result: BudgetResult, recs: list[HuddleRecord]) -> list[Block]:
    """Beyond the ESRF study: drift and Allan deviation over the whole of each record."""
    stab = result.stability
    if not stab:
        why = next((v for k, v in result.skipped.items() if "Allan" in k), "")
        return [f"Drift and Allan deviation are not shown: {why}."] if why else []
    longest = max(s.duration_s for s in stab.values())
    divisor, label = time_axis(longest)
    unit = label.split("[")[1].rstrip("]")
    out: list[Block] = [
        f"Beyond the ESRF study: what the records show over their whole length "
        f"({longest / divisor:.3g} {unit} for the longest). A long record is analysed out of "
        "core, chunk by chunk, and its time plots show the minimum and maximum of each bin. "
        "The Allan deviation separates white noise, flicker, random walk and drift by their "
        "slope; the drift plot follows the 4QD's offset and the distance over the record.",
        allan_figure(stab),
    ]
    rows = []
    for n in sorted(stab):
        s = stab[n]
        for key, words in (("Va", "Attocube distance Va"), ("Rh", "4QD beam angle, horizontal"),
                           ("Rv", "4QD beam angle, vertical")):
            regions = s.allan[key].regions()
            text = "; ".join(r.describe() for r in regions) or "no region with a clear slope"
            drift = s.drift[key]
            scale, u = (1e9, "nm") if drift.unit == "m" else (1e6, "µrad")
            rows.append((str(n), words, f"{drift.peak_to_peak * scale:.3g} {u}", text))
    out.append(Table(
        caption="Noise types of the Allan deviation and drift over each record",
        header=("test", "signal", "drift: range of the ≥ 1 s means",
                "Allan deviation regions (level at 1 s, slope, range of τ)"),
        rows=tuple(rows)))
    out.append(drift_figure(stab))
    return out


def _tables(result: BudgetResult, recs: list[HuddleRecord]) -> list[Block]:
    """The rms of every test (with the budget's prediction) and the effect of each
    configuration change."""
    h = result.huddle
    assert h is not None
    blocks: list[Block] = []
    rows = []
    for r in recs:
        pred = result.predicted_huddle_va_rms_m.get(r.number)
        rows.append((str(r.number), huddle_config_words(r), f"{r.va_rms_m * NM:.3g}",
                     f"{r.va_lpf_rms_m * NM:.3g}", f"{r.vph_rms_v * MV:.3g}",
                     f"{r.vpv_rms_v * MV:.3g}", "-" if pred is None else f"{pred * NM:.3g}"))
    blocks.append(Table(
        caption="Huddle tests: rms after the ESRF study's processing (mean removed)",
        header=("test", "configuration", "Va rms [nm]", "Va rms, 50 Hz low pass [nm]",
                "Vph rms [mV]", "Vpv rms [mV]", "Va rms predicted by the budget [nm]"),
        rows=tuple(rows),
        note="Predicted: the error budget of section 4 for the test's configuration and "
             "length."))
    if h.comparisons:
        bands = list(h.comparisons[0].ratios)
        blocks.append(Table(
            caption="Effect of one configuration change on the rms of Va (ratio of rms; * "
                    "significant at two standard deviations)",
            header=("change", "tests compared", *(f"ratio, {b}" for b in bands)),
            rows=tuple((c.effect, f"{c.numerator.rsplit('_', 1)[-1]} / "
                                  f"{c.denominator.rsplit('_', 1)[-1]}",
                        *(f"{c.ratios[b]:.2f}{' *' if c.significant.get(b) else ''}"
                          for b in bands)) for c in h.comparisons)))
    return blocks


def huddle_section(result: BudgetResult, *, recordings: Mapping[str, xr.Dataset]) -> Section:
    """ESRF study section 3: configurations, time plots, spectra, the table and the conclusion.

    Parameters
    ----------
    result : BudgetResult
        From :func:`fsmbench.budget.study.budget_study`.
    recordings : mapping of str to xarray.Dataset
        The same recordings (the time plots are drawn from them).
    """
    h = result.huddle
    intro = ("The huddle tests measure the noise of the 4QD and of the Attocube "
             "interferometer while nothing is commanded: the Newport is at rest and, in closed "
             "loop, the Sercalo holds the beam on the 4QD. Five configurations (ESRF study Table "
             "3) vary "
             "the loop, the Attocube's environmental compensation unit and an aluminium "
             "shielding of the beam path.")
    if h is None:
        return Section(title="3. Huddle test", anchor="huddle",
                       blocks=(intro, _missing_paragraph(result)))
    recs = [h.records[n] for n in sorted(h.records)]
    fs = recs[0].fs_hz
    blocks: list[Block] = [intro, _config_table(set(h.records))]
    missing = [n for n in _NAMES if n in result.skipped]
    if missing:
        blocks.append("Not analysed: " + "; ".join(f"{n} ({result.skipped[n]})"
                                                   for n in missing) + ".")
    blocks.append(Note("The ESRF study analyses tests 1 to 4 only (test 5 is commented out in its "
                       "3.1); here every test present is analysed the same way.",
                       ref="ESRF study 3.1"))
    blocks += [
        f"Processing as the ESRF study's 3.2–3.3: samples before t = 1 s are dropped and the rest "
        f"is kept (the ESRF study's records hold 100 s; {_lengths(recs)} here, at {fs:g} Hz), the "
        "mean is removed, and Va is low-passed by a first-order filter at 50 Hz. Figure 29 "
        "shows Va of each test on its own scale; Figure 30 the 4QD signals, horizontal and "
        "vertical apart.",
        huddle_attocube_time_figure(h, recordings, stability=result.stability),
        huddle_qd_time_figure(h, recordings, stability=result.stability),
        "Spectra (ESRF study 3.5): Welch estimates with a 1 s Hann window. The cumulative rms from "
        "0 Hz shows which band makes the rms.",
        huddle_attocube_asd_figure(h),
        huddle_qd_asd_figure(h),
    ]
    if any(r.closed_loop for r in recs):
        blocks.append(Note(
            "In closed loop the 9.2 controller notches the Sercalo modes, so the DAC's rounding "
            "of the command drives them: the peak near 411 Hz in the 4QD spectra of the "
            "closed-loop tests. The same rounding, as mirror piston, is the largest source of "
            "the error budget (4.5).", ref="errata E30"))
    blocks += _tables(result, recs)
    blocks.append("Conclusion (ESRF study 3.6). " + h.conclusion)
    blocks += _stability_blocks(result, recs)
    if h.qd_noise is not None:
        q = h.qd_noise
        blocks.append(
            f"The open-loop tests ({', '.join(n.rsplit('_', 1)[-1] for n in q.tests)}) give "
            f"the 4QD's own noise for the budget: {q.rms_v[0] * MV:.3g} mV rms on Vph and "
            f"{q.rms_v[1] * MV:.3g} mV on Vpv once the ADC quantisation "
            f"({q.adc_rms_v * MV:.3g} mV) and the Newport's angle noise are taken out.")
    return Section(title="3. Huddle test", anchor="huddle", blocks=tuple(blocks))
