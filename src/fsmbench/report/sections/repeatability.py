"""Report section 11: measurement of the non-repeatability (ESRF study section 11)."""

from __future__ import annotations

from collections.abc import Mapping

from fsmbench.budget.repeatability import SEED_11, RepeatabilityRecord
from fsmbench.budget.result import BudgetResult
from fsmbench.report.figures.budget import huddle_config_words
from fsmbench.report.figures.repeatability import (
    direction_words,
    nonrep_contributions_figure,
    nonrep_part_figure,
    periods_figure,
    repeatability_time_figure,
    tracking_asd_figure,
    tracking_distance_figure,
    tracking_vs_distance_figure,
)
from fsmbench.report.html import Block, Note, Section, Table

__all__ = ["repeatability_section"]

NM = 1e9
UM = 1e6
_NAMES = ("data_rep_h", "data_rep_v")


def _nm(x: float | None) -> str:
    return "-" if x is None else f"{x * NM:.3g}"


def _alignment(result: BudgetResult, reps: Mapping[str, RepeatabilityRecord],
               recs: list[RepeatabilityRecord]) -> Section:
    """11.1-11.2: where each record starts, what was not analysed, the time signals."""
    missing = [n for n in _NAMES if n in result.skipped]
    s1: list[Block] = [
        "As the ESRF study's 11.1, each record starts one second after the first non-zero Newport "
        "command and keeps whole periods only: "
        + "; ".join(f"{direction_words(r)}: from {r.start_s:.3g} s, {r.n_periods} periods of "
                    f"{r.period_s:g} s" for r in recs) + "."]
    if missing:
        s1.append("Not analysed: " + "; ".join(f"{n} ({result.skipped[n]})" for n in missing)
                  + ".")
    s1.append(repeatability_time_figure(reps))
    return Section("11.1–11.2 Alignment and time signals", blocks=tuple(s1))


def _tracking(result: BudgetResult, reps: Mapping[str, RepeatabilityRecord],
              recs: list[RepeatabilityRecord]) -> Section:
    """11.3: the tracking error, in angle and as the distance it makes."""
    gd = result.noise.qd_gain_v_per_rad
    s3: tuple[Block, ...] = (
        "The 4QD measures the beam angle the loop leaves, α = Vp/Gd(0) with Gd(0) = "
        f"{gd[0]:.4g} V/rad (h) and {gd[1]:.4g} V/rad (v). Tracking error: "
        + "; ".join(f"{direction_words(r)}: {r.tracking_rms_rad[0] * UM:.3g} µrad rms (h), "
                    f"{r.tracking_rms_rad[1] * UM:.3g} µrad rms (v)" for r in recs)
        + ". The ESRF study turns it into a distance with ΔL = L·α²/2 (L = 0.1 m); the traced "
          "path gives (6H + 4L)/16·α².",
        Note("L·α²/2 is one straight leg tilted by α; in the traced path the two H legs add "
             "12H·δθc² as the second hit point slides along the Sercalo: (6H + 4L)/16·α² = "
             "0.031·α² for H = L = 50 mm, not 0.05·α².", ref="errata E17"),
        tracking_distance_figure(reps),
        tracking_asd_figure(reps),
        "Compared with the spectrum of the measured distance (ESRF study Fig. 47):",
        tracking_vs_distance_figure(reps),
    )
    return Section("11.3 Tracking error", blocks=s3)


def _parts(reps: Mapping[str, RepeatabilityRecord],
           recs: list[RepeatabilityRecord]) -> Section:
    """11.4: the repeatable and non-repeatable parts of Va."""
    r0 = recs[0]
    s4: tuple[Block, ...] = (
        "Va is cut into its 1 s periods; the mean over periods at each instant is the "
        "repeatable part, the rest the non-repeatable part (ESRF study 11.4). Its rms: "
        + "; ".join(f"{direction_words(r)}: {r.nonrep_rms_m * NM:.3g} nm "
                    f"(ESRF study {SEED_11[f'{r.direction}_nonrep_rms_m'] * NM:g} "
                    "nm)" for r in recs)
        + f". With only {r0.n_periods} periods the mean is taken from the same periods, which "
          "biases this estimate low by √((n − 1)/n); corrected: "
        + "; ".join(f"{r.nonrep_rms_unbiased_m * NM:.3g} nm ({r.direction})" for r in recs)
        + ". The figure shows both parts over the period.",
        periods_figure(reps),
    )
    return Section("11.4 Repeatable and non-repeatable parts", blocks=s4)


def _contributions(result: BudgetResult, reps: Mapping[str, RepeatabilityRecord]) -> Section:
    """11.5: where the non-repeatability comes from."""
    s5: list[Block] = [
        "Where it comes from (ESRF study 11.5): the non-repeatable part of Va against the "
        "non-repeatable part of the tracking error's distance equivalent and the noise of a "
        "huddle test, where nothing moves (test 5 when present, the same configuration; "
        "otherwise the highest-numbered test analysed)."]
    for d, nr in result.nonrep.items():
        huddle = ("" if nr.huddle_va_rms_m is None or nr.huddle_test is None else
                  f", huddle test {nr.huddle_test.rsplit('_', 1)[-1]}: "
                  f"{nr.huddle_va_rms_m * NM:.3g} nm")
        s5.append(f"{direction_words(reps[d])}: Va {nr.va_nonrep_rms_m * NM:.3g} nm rms, "
                  f"tracking error {nr.tracking_nonrep_rms_m * NM:.3g} nm{huddle}; the error "
                  f"budget predicts {nr.predicted_rms_m * NM:.3g} nm over the record's length.")
    configs = ({} if result.huddle is None else
               {r.name: huddle_config_words(r) for r in result.huddle.records.values()})
    s5.append(nonrep_contributions_figure(reps, result.nonrep, huddle_configs=configs))
    shares = [nr.tracking_nonrep_rms_m / nr.va_nonrep_rms_m for nr in result.nonrep.values()
              if nr.va_nonrep_rms_m > 0]
    if shares:
        share = max(shares)
        verdict = ("it does not limit, contrary to the ESRF study's Important 10" if share < 0.3
                   else "it is a real part of the non-repeatability")
        s5.append(Note(f"The tracking error's non-repeatable share is at most {share:.0%} of "
                       "the measured rms, and that is an upper bound (the 4QD's own noise is in "
                       f"it): {verdict}.", ref="errata E33"))
    return Section("11.5 Contributions to the non-repeatability", blocks=tuple(s5))


def _low_pass(reps: Mapping[str, RepeatabilityRecord],
              recs: list[RepeatabilityRecord]) -> Section:
    """11.6-11.7: the same after the ESRF study's 10 Hz low pass."""
    rows = []
    for r in recs:
        rows.append((direction_words(r), _nm(r.nonrep_rms_m), _nm(r.nonrep_rms_unbiased_m),
                     _nm(r.nonrep_rms_lpf_m), _nm(r.nonrep_rms_lpf_settled_m),
                     f"{SEED_11[f'{r.direction}_nonrep_rms_m'] * NM:g}",
                     f"{SEED_11[f'{r.direction}_nonrep_rms_lpf_m'] * NM:g}"))
    s6: tuple[Block, ...] = (
        "The ESRF study repeats the analysis after a first-order low pass at 10 Hz (lsim, from "
        "rest). A low pass (gain ≤ 1) cannot raise the rms of the non-repeatable part in "
        "steady state, yet the ESRF study's horizontal value rises from 19.6 to 22.9 nm: the "
        "filter starts from rest on a Va that is not mean-removed, and its start-up transient "
        "(time constant 16 ms) lands in the first period, which the mean over periods "
        "cannot remove. The settled value drops the first period after filtering.",
        Note("With the low pass: "
             + "; ".join(f"{r.direction}: {_nm(r.nonrep_rms_lpf_m)} nm as the ESRF study computes "
                         f"it, {_nm(r.nonrep_rms_lpf_settled_m)} nm settled" for r in recs)
             + ". The ESRF study's 22.9 nm (h) includes the lsim start-up transient; its identical "
               "vertical 13.9 nm is most likely 11.4's number repeated.", ref="errata E32"),
        nonrep_part_figure(reps),
        Table(caption="Non-repeatable rms of the measured distance per record",
              header=("record", "no filter [nm]", "no filter, bias-corrected [nm]",
                      "10 Hz low pass, as the ESRF study (all periods) [nm]",
                      "10 Hz low pass, settled (first period dropped) [nm]",
                      "ESRF study, no filter [nm]", "ESRF study, low pass [nm]"),
              rows=tuple(rows),
              note="The settled value needs at least three periods; '-' otherwise."),
    )
    return Section("11.6–11.7 With the 10 Hz low pass", blocks=s6)


def repeatability_section(result: BudgetResult) -> Section:
    """ESRF study section 11: alignment, tracking error, non-repeatable part, with the low pass.

    Parameters
    ----------
    result : BudgetResult
        From :func:`fsmbench.budget.study.budget_study`: every array the chapter
        draws (the periods' envelopes, the huddle test's window).
    """
    reps = result.repeatability
    intro = ("The Newport moves the beam in a 1 Hz sine (a 1 s period repeated), emulating "
             "a sample that returns to the same positions, while the Sercalo loop holds the "
             "beam on the 4QD. What the Attocube reads differently from one period to the next "
             "is the non-repeatability; every source of section 4 contributes to it.")
    title = "11. Measurement of the non-repeatability"
    if not reps:
        why = "; ".join(f"{n}.mat ({result.skipped[n]})" for n in _NAMES if n in result.skipped)
        return Section(title=title, anchor="repeatability", blocks=(
            intro, "No repeatability record could be analysed, so this section has no "
                   "figure: " + (why or ", ".join(f"{n}.mat" for n in _NAMES)) + "."))
    recs = list(reps.values())
    return Section(title=title, anchor="repeatability", blocks=(intro,), subsections=(
        _alignment(result, reps, recs), _tracking(result, reps, recs), _parts(reps, recs),
        _contributions(result, reps), _low_pass(reps, recs)))
