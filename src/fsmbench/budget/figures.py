"""Figures of seed sections 3, 4 and 11 (Figs. 29–32, 34–35, 44–52) and of the budget.

:func:`budget_figures` returns :class:`BudgetFigure` records (title, seed
reference, caption, matplotlib figure) for what the result holds; the caller
renders them (e.g. ``fsmbench.report.html.figure_from_matplotlib``, which
also closes them). Long time records are drawn through the report's min/max
envelope.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import matplotlib

matplotlib.use("Agg")  # off-screen rendering; no display needed

import matplotlib.pyplot as plt
import numpy as np
import xarray as xr
from matplotlib.axes import Axes
from matplotlib.figure import Figure as MplFigure

from fsmbench.bench.geometry import seed_theta_range, small_angle_law, trace_bench
from fsmbench.budget.huddle import trim_huddle
from fsmbench.budget.optics import SEED_4_1
from fsmbench.budget.repeatability import RepeatabilityRecord, align_periods
from fsmbench.budget.spectra import cumulative_power, first_order_lowpass
from fsmbench.budget.study import BudgetResult
from fsmbench.report.plots import envelope

__all__ = ["BudgetFigure", "budget_figures"]

NM = 1e9


@dataclass(frozen=True)
class BudgetFigure:
    """One figure for the report: title, the seed's figure number, caption, the figure."""

    title: str
    seed_ref: str
    caption: str
    figure: MplFigure


def _asd_panel(ax: Axes, cum_ax: Axes, f: np.ndarray, psd: np.ndarray, *, label: str,
               scale: float) -> None:
    sel = f > 0
    asd = np.sqrt(psd[sel]) * scale
    ax.loglog(f[sel], asd, lw=0.8, label=label)
    ys = np.concatenate([np.asarray(ln.get_ydata(), dtype=float) for ln in ax.lines])
    pos = ys[ys > 0]
    if pos.size:  # exact zeros (a Tustin controller at fs/2) would stretch the log axis
        ax.set_ylim(bottom=max(float(pos.min()), 1e-7 * float(pos.max())) / 2)
    cum_ax.semilogx(f[sel], np.sqrt(cumulative_power(f, psd))[sel] * scale, lw=0.8, label=label)


def _huddle_figures(result: BudgetResult, recordings: Mapping[str, xr.Dataset]
                    ) -> list[BudgetFigure]:
    h = result.huddle
    if h is None:
        return []
    out = []
    fig, ax = plt.subplots(figsize=(9, 3.6))
    fig2, axes2 = plt.subplots(2, 1, figsize=(9, 5.5), sharex=True)
    for rec in h.records.values():
        sig = trim_huddle(recordings[rec.name], name=rec.name)
        t, va = sig["t"], sig["Va"] - sig["Va"].mean()
        vaf = first_order_lowpass(va, cutoff_hz=50.0, fs_hz=rec.fs_hz)
        line = ax.plot(*envelope(t, va * NM), lw=0.3, alpha=0.4)[0]
        ax.plot(*envelope(t, vaf * NM), lw=0.8, color=line.get_color(), label=f"test {rec.number}")
        for a, v in zip(axes2, ("Vph", "Vpv"), strict=True):
            a.plot(*envelope(t, (sig[v] - sig[v].mean()) * 1e3), lw=0.4,
                   label=f"test {rec.number}")
    ax.set(xlabel="Time [s]", ylabel="Va, mean removed [nm]",
           title="Attocube during the huddle tests (light: raw, dark: 50 Hz low pass)")
    ax.legend(fontsize=8, ncol=5)
    ax.grid(True, alpha=0.3)
    fig.tight_layout()
    for a, v in zip(axes2, ("Vph", "Vpv"), strict=True):
        a.set(ylabel=f"{v}, mean removed [mV]")
        a.grid(True, alpha=0.3)
    axes2[0].legend(fontsize=8, ncol=5)
    axes2[1].set_xlabel("Time [s]")
    fig2.tight_layout()
    out += [BudgetFigure("Attocube during the huddle tests", "Fig. 29",
                         "Va after the seed's trimming (t ≥ 1 s, 100 s), mean removed; "
                         "configurations of Table 3.", fig),
            BudgetFigure("4QD during the huddle tests", "Fig. 30",
                         "Vph and Vpv, mean removed.", fig2)]
    fig3, (a1, a2) = plt.subplots(2, 1, figsize=(9, 6), sharex=True)
    fig4, axs = plt.subplots(2, 2, figsize=(11, 6), sharex=True)
    for rec in h.records.values():
        lab = f"test {rec.number}"
        _asd_panel(a1, a2, rec.f_hz, rec.psd_va_m2_per_hz, label=lab, scale=NM)
        _asd_panel(axs[0, 0], axs[1, 0], rec.f_hz, rec.psd_vph_v2_per_hz, label=lab, scale=1e6)
        _asd_panel(axs[0, 1], axs[1, 1], rec.f_hz, rec.psd_vpv_v2_per_hz, label=lab, scale=1e6)
    a1.set(ylabel="ASD of Va [nm/√Hz]", title="Attocube, huddle tests")
    a2.set(xlabel="Frequency [Hz]", ylabel="Cumulative rms [nm]")
    for i, v in enumerate(("Vph", "Vpv")):
        axs[0, i].set(ylabel=f"ASD of {v} [µV/√Hz]", title=v)
        axs[1, i].set(xlabel="Frequency [Hz]", ylabel="Cumulative rms [µV]")
    for a in (a1, a2, *axs.ravel()):
        a.grid(True, which="both", alpha=0.3)
        a.legend(fontsize=7)
    fig3.tight_layout()
    fig4.tight_layout()
    out += [BudgetFigure("Spectrum of the Attocube in the huddle tests", "Fig. 31",
                         "Welch estimate with the seed's 1 s Hann window, and the cumulative "
                         "rms from 0 Hz.", fig3),
            BudgetFigure("Spectrum of the 4QD in the huddle tests", "Fig. 32",
                         "Welch estimate with the seed's 1 s Hann window, and the cumulative "
                         "rms.", fig4)]
    return out


def _geometry_figures(result: BudgetResult) -> list[BudgetFigure]:
    g = result.geometry
    th = seed_theta_range()
    trace = trace_bench(th, h_m=g.h_m, l_m=g.l_m).path_error_m
    law = small_angle_law(h_m=g.h_m, l_m=g.l_m)
    fig, ax = plt.subplots(figsize=(7, 4.5))
    ax.loglog(th * 1e6, trace, "o", ms=3, label="exact ray trace (round trip)")
    ax.loglog(th * 1e6, law.path_error_m(th), "-",
              label=f"k·δθc², k = {law.k_m_per_rad2:.3g} m/rad²")
    ax.loglog(th * 1e6, 0.5 * trace, "--", label="measured by the Attocube (half)")
    st = np.asarray(SEED_4_1["table4_theta_rad"])
    ax.loglog(st * 1e6, SEED_4_1["table4_error_m"], "kx", ms=8, label="seed Table 4")
    ax.set(xlabel="Sercalo angle error δθc [µrad]", ylabel="Distance error [m]",
           title="Effect of the Sercalo angle error on the distance")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    d = g.figure
    fig2, ax2 = plt.subplots(figsize=(6, 5))
    ax2.plot(d.nominal_beam[:, 0] * 1e3, d.nominal_beam[:, 1] * 1e3, "k:", label="nominal")
    ax2.plot(d.beam[:, 0] * 1e3, d.beam[:, 1] * 1e3, "r-",
             label=f"δθc = {np.degrees(d.theta_rad):g}°")
    for seg, lab in ((d.sercalo_mirror, "Sercalo"), (d.newport_mirror, "Newport"),
                     (d.attocube_plane, "Attocube plane")):
        ax2.plot(seg[:, 0] * 1e3, seg[:, 1] * 1e3, lw=2, label=lab)
    for name, pt in zip(d.labels, d.beam, strict=True):
        ax2.annotate(name, pt * 1e3, textcoords="offset points", xytext=(4, 4))
    ax2.set(xlabel="x [mm]", ylabel="y [mm]", aspect="equal", title="Beam path, large angle")
    ax2.legend(fontsize=7)
    fig2.tight_layout()
    return [BudgetFigure("Distance error against the Sercalo angle error", "Fig. 34",
                         f"Fitted k = {g.fit.k_fit_m_per_rad2:.6g} m/rad² against the derived "
                         f"12H + 8L = {law.k_m_per_rad2:.6g}; the seed's Table 4 is 1000× the "
                         "trace (errata E15).", fig),
            BudgetFigure("Beam path at a large angle error", "Fig. 35",
                         "Exact trace O → S → Y → M → T at 2°.", fig2)]


def _budget_figures(result: BudgetResult) -> list[BudgetFigure]:
    b = result.budget
    fig, (a1, a2) = plt.subplots(2, 1, figsize=(9, 6.5), sharex=True)
    fig2, ax = plt.subplots(figsize=(9, 4.5))
    for name, s in b.sources.items():
        f = s.f_hz
        tr = np.real(np.einsum("fii->f", s.angle_psd))
        _asd_panel(a1, a2, f, tr, label=name, scale=1e6)
        dist = s.perpendicular_psd_m2_per_hz + s.quadratic.psd_m2_per_hz
        ax.semilogx(f, np.sqrt(cumulative_power(f, dist)) * NM, label=name)
    a1.set(ylabel="Beam-angle ASD, h + v [µrad/√Hz]",
           title=f"Beam-angle error per source ({b.configuration})")
    a2.set(xlabel="Frequency [Hz]", ylabel="Cumulative rms [µrad]")
    ax.set(xlabel="Frequency [Hz]", ylabel="Cumulative rms of the distance error [nm]",
           title="Distance error per angle source (piston + geometric)")
    for a in (a1, a2, ax):
        a.grid(True, which="both", alpha=0.3)
        a.legend(fontsize=7)
    fig.tight_layout()
    fig2.tight_layout()
    return [BudgetFigure("Beam-angle error per noise source", "4.5",
                         "Each source through the plant and the loop (U = −K R).", fig),
            BudgetFigure("Distance error per noise source", "4.5c",
                         "Piston (4.2, linear) plus geometric term (4.1, quadratic: "
                         "autoconvolution of the angle spectra).", fig2)]


def _rep_figures(result: BudgetResult, recordings: Mapping[str, xr.Dataset]
                 ) -> list[BudgetFigure]:
    reps = result.repeatability
    if not reps:
        return []
    out = []
    fig, axs = plt.subplots(3, len(reps), figsize=(5.5 * len(reps), 7), squeeze=False)
    fig2, axs2 = plt.subplots(1, len(reps), figsize=(5.5 * len(reps), 3.5), squeeze=False)
    for j, r in enumerate(reps.values()):
        al = align_periods(recordings[r.name], name=r.name)
        t = np.arange(al.signals["Va"].size) / r.fs_hz
        s = al.signals
        axs[0, j].plot(*envelope(t, s[r.channel]), lw=0.5)
        axs[0, j].set(ylabel=f"{r.channel} [V]", title=r.name)
        for v in ("Vph", "Vpv"):
            axs[1, j].plot(*envelope(t, s[v] * 1e3), lw=0.4, label=v)
        axs[1, j].set(ylabel="4QD [mV]")
        axs[1, j].legend(fontsize=7)
        axs[2, j].plot(*envelope(t, (s["Va"] - s["Va"].mean()) * NM), lw=0.5)
        axs[2, j].set(xlabel="Time after alignment [s]", ylabel="Va [nm]")
        gd = result.noise.qd_gain_v_per_rad
        for v, g in zip(("Vph", "Vpv"), gd, strict=True):
            axs2[0, j].plot(*envelope(t, s[v] / g * 1e6), lw=0.4, label=f"{v}/Gd")
        axs2[0, j].set(xlabel="Time after alignment [s]", ylabel="Tracking error [µrad]",
                       title=r.name)
        axs2[0, j].legend(fontsize=7)
    for a in (*axs.ravel(), *axs2.ravel()):
        a.grid(True, alpha=0.3)
    fig.tight_layout()
    fig2.tight_layout()
    out += [BudgetFigure("Repeatability measurement", "Fig. 44",
                         "Newport command, 4QD and Attocube after the seed's alignment (first "
                         "command + 1 s, whole periods).", fig),
            BudgetFigure("Tracking errors", "Fig. 45", "Beam angle R = Vp/Gd(0).", fig2)]
    fig3, a3 = plt.subplots(2, 1, figsize=(9, 6), sharex=True)
    fig4, a4 = plt.subplots(figsize=(9, 4.5))
    for r in reps.values():
        for i, ax_name in enumerate(("Rh", "Rv")):
            _asd_panel(a3[0], a3[1], r.f_hz, r.psd_tracking_rad2_per_hz[:, i],
                       label=f"{r.direction}: {ax_name}", scale=1e6)
        sel = r.f_hz > 0
        a4.loglog(r.f_hz[sel], np.sqrt(r.psd_va_m2_per_hz[sel]) * NM, lw=0.8,
                  label=f"{r.direction}: Va measured")
        a4.loglog(r.f_hz[sel], np.sqrt(r.psd_distance_m2_per_hz[sel]) * NM, lw=0.8,
                  label=f"{r.direction}: from tracking error, traced law")
        a4.loglog(r.f_hz[sel], np.sqrt(r.psd_distance_seed_m2_per_hz[sel].sum(axis=1)) * NM,
                  lw=0.6, ls="--", label=f"{r.direction}: from tracking error, seed's Lα²/2")
    a3[0].set(ylabel="ASD [µrad/√Hz]", title="Tracking errors")
    a3[1].set(xlabel="Frequency [Hz]", ylabel="Cumulative rms [µrad]")
    a4.set(xlabel="Frequency [Hz]", ylabel="ASD [nm/√Hz]",
           title="Distance-error equivalent of the tracking error and measured distance")
    for a in (*a3, a4):
        a.grid(True, which="both", alpha=0.3)
        a.legend(fontsize=7)
    fig3.tight_layout()
    fig4.tight_layout()
    out += [BudgetFigure("Spectrum of the tracking errors", "Fig. 46",
                         "Welch, 1 s Hann window.", fig3),
            BudgetFigure("Tracking error as distance against the measured distance", "Fig. 47",
                         "Σ cᵢ αᵢ² with c = (6H + 4L)/16 (errata E17), and the seed's L·α²/2 "
                         "(L = 0.1 m); both include the 4QD's own noise.", fig4)]
    out += [*_period_figures(reps, lpf=False), _nonrep_figure(result, recordings)]
    out += _period_figures(reps, lpf=True)
    return out


def _period_figures(reps: Mapping[str, RepeatabilityRecord], *, lpf: bool) -> list[BudgetFigure]:
    figs = []
    for subtract in (False, True):
        fig, axs = plt.subplots(1, len(reps), figsize=(5.5 * len(reps), 4), squeeze=False)
        for j, r in enumerate(reps.values()):
            va = r.va_lpf_periods_m if lpf else r.va_periods_m
            rep = r.repeatable_lpf_m if lpf else r.repeatable_m
            y = (va - rep) if subtract else va - va.mean()
            tp = np.arange(va.shape[1]) / r.fs_hz
            for k in range(va.shape[0]):
                axs[0, j].plot(tp, y[k] * NM, lw=0.3, alpha=0.5)
            if not subtract:
                axs[0, j].plot(tp, (rep - va.mean()) * NM, "k", lw=1.2, label="mean over periods")
                axs[0, j].legend(fontsize=7)
            rms = r.nonrep_rms_lpf_m if lpf else r.nonrep_rms_m
            axs[0, j].set(xlabel="Time in the period [s]", ylabel="Va [nm]",
                          title=f"{r.name}: non-repeatable {rms * NM:.3g} nm rms" if subtract
                          else r.name)
            axs[0, j].grid(True, alpha=0.3)
        fig.tight_layout()
        ref = ("Fig. 52" if subtract else "Fig. 51") if lpf else ("Fig. 49" if subtract
                                                                  else "Fig. 48")
        what = "after subtracting the mean over periods" if subtract else "every period"
        filt = " after the 10 Hz low pass (lsim from rest)" if lpf else ""
        figs.append(BudgetFigure(f"Repeatability{filt}, {what}", ref,
                                 f"Va over each 1 s period{filt}, {what}.", fig))
    return figs


def _nonrep_figure(result: BudgetResult, recordings: Mapping[str, xr.Dataset]) -> BudgetFigure:
    reps = result.repeatability
    fig, axs = plt.subplots(len(reps), 1, figsize=(9, 3.2 * len(reps)), squeeze=False)
    for i, (d, r) in enumerate(reps.items()):
        ax = axs[i, 0]
        t = np.arange(r.va_periods_m.size) / r.fs_hz
        va = (r.va_periods_m - r.repeatable_m).ravel()
        tr = (r.tracking_distance_periods_m - r.tracking_distance_periods_m.mean(axis=0)).ravel()
        nr = result.nonrep.get(d)
        if (nr is not None and nr.huddle_test is not None and nr.huddle_va_rms_m is not None
                and nr.huddle_test in recordings):
            sig = trim_huddle(recordings[nr.huddle_test], name=nr.huddle_test)
            hv = sig["Va"][: t.size] - sig["Va"][: t.size].mean()
            ax.plot(*envelope(t[: hv.size], hv * NM), lw=0.4, color="0.6",
                    label=f"{nr.huddle_test} ({nr.huddle_va_rms_m * NM:.3g} nm rms)")
        ax.plot(*envelope(t, va * NM), lw=0.4,
                label=f"Va non-repeatable ({r.nonrep_rms_m * NM:.3g} nm rms)")
        ax.plot(*envelope(t, tr * NM), lw=0.4, label="tracking error as distance "
                f"({r.tracking_distance_nonrep_rms_m * NM:.3g} nm rms)")
        ax.set(xlabel="Time [s]", ylabel="Distance [nm]", title=f"Non-repeatability, {d}")
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=7, loc="upper right")
    fig.tight_layout()
    return BudgetFigure("Non-repeatable contributions", "Fig. 50",
                        "Non-repeatable Va, the non-repeatable part of the tracking error's "
                        "distance equivalent, and the huddle-test noise.", fig)


def budget_figures(result: BudgetResult, recordings: Mapping[str, xr.Dataset]
                   ) -> list[BudgetFigure]:
    """Every figure the result supports, in the seed's order.

    Parameters
    ----------
    result : BudgetResult
        From :func:`~fsmbench.budget.study.budget_study`.
    recordings : mapping
        The same recordings (time plots are drawn from them).
    """
    return (_huddle_figures(result, recordings) + _geometry_figures(result)
            + _budget_figures(result) + _rep_figures(result, recordings))
