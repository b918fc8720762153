"""Figures of the identification (seed Figs. 10, 12–14, 17–22, 25–28)."""

from __future__ import annotations

from collections.abc import Mapping

import matplotlib

matplotlib.use("Agg")  # the report renders off-screen

import matplotlib.pyplot as plt
import numpy as np
import xarray as xr
from matplotlib.figure import Figure as MplFigure

from fsmbench.bench.params import BenchParams
from fsmbench.ident.calibration import CurrentAmplifierGain, QdCalibration, trim_recording
from fsmbench.ident.delay import remove_delay
from fsmbench.ident.frf import FrequencyResponse
from fsmbench.ident.sercalo import NewportIdentification, SercaloIdentification

__all__ = [
    "coherence_figure",
    "current_amplifier_figure",
    "delay_figure",
    "frf_matrix_figure",
    "qd_regression_figure",
    "weights_figure",
]

_AXIS_SIGNALS = {"h": ("Vph", "Vnh", "data_cal_pd_h"), "v": ("Vpv", "Vnv", "data_cal_pd_v")}


def qd_regression_figure(qd: Mapping[str, QdCalibration],
                         recordings: Mapping[str, xr.Dataset]) -> MplFigure:
    """Fig. 10: 4QD voltage against beam angle with the fitted line, per axis."""
    fig, axes = plt.subplots(1, len(qd), figsize=(10, 4), squeeze=False)
    for ax, (axis, cal) in zip(axes[0], qd.items(), strict=True):
        vp, vn, exp = _AXIS_SIGNALS[axis]
        ds = trim_recording(recordings[exp], t0_s=cal.trim_s)
        x = cal.beam_factor * cal.metrology_gain_rad_per_v * ds[vn].values
        y = ds[vp].values
        step = max(1, x.size // 4000)
        ax.plot(1e6 * x[::step], y[::step], ".", ms=2, alpha=0.4, label="measured")
        xx = np.linspace(x.min(), x.max(), 2)
        ax.plot(1e6 * xx, cal.gain_v_per_rad * xx + cal.offset_v, "k-", lw=1.2,
                label=f"fit: {cal.gain_v_per_rad:.2f} V/rad, R² = {cal.r_squared:.5f}")
        ax.set_xlabel("Beam angle [µrad]")
        ax.set_ylabel(f"{vp} [V]")
        ax.set_title(f"{'Horizontal' if axis == 'h' else 'Vertical'}")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.tight_layout()
    return fig


def current_amplifier_figure(gi: Mapping[str, CurrentAmplifierGain],
                             measured: Mapping[str, FrequencyResponse],
                             nominal: BenchParams) -> MplFigure:
    """Figs. 12–14: ``|Uc → Vc|`` measured, theoretical and identified; ``Gi`` over the band."""
    from fsmbench.ident.calibration import known_ga_zc

    fig, axes = plt.subplots(2, 1, figsize=(9, 7))
    for axis, g in gi.items():
        est = measured[axis]
        f = est.frequency_hz[1:]
        h = np.abs(est.frf.values[1:, 0, 0])
        line, = axes[0].loglog(f, h, lw=0.8, alpha=0.7, label=f"{axis}: measured")
        gazc = known_ga_zc(nominal, axis=axis, f_hz=f)
        axes[0].loglog(f, gazc * g.theoretical_a_per_v, "--", color=line.get_color(), lw=1,
                       label=f"{axis}: Ga Zc Gi, Gi = 1/(R+Rc) = {1e3 * g.theoretical_a_per_v:.2f}"
                             " mA/V")
        axes[0].loglog(f, gazc * g.gain_a_per_v, "-", color="k", lw=0.8,
                       label=f"{axis}: Ga Zc Gi, Gi identified = {1e3 * g.gain_a_per_v:.3f} mA/V")
        axes[1].semilogx(g.frequency_hz, 1e3 * np.asarray(g.gi_response_a_per_v), ".", ms=3,
                         color=line.get_color(), label=f"{axis}: |Ga Zc Gi| / |Ga Zc|")
        axes[1].axhline(1e3 * g.gain_a_per_v, color=line.get_color(), lw=1)
    axes[0].set_xlim(1, 5000)
    axes[0].set_xlabel("Frequency [Hz]")
    axes[0].set_ylabel("|Vc/Uc| [V/V]")
    axes[1].set_xlabel("Frequency [Hz]")
    axes[1].set_ylabel("Gi [mA/V]")
    for ax in axes:
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=7)
    fig.tight_layout()
    return fig


def coherence_figure(frf: FrequencyResponse, *, title: str) -> MplFigure:
    """Figs. 17, 25: coherence of every path."""
    fig, axes = plt.subplots(len(frf.output_names), len(frf.input_names), figsize=(10, 6),
                             sharex=True, sharey=True, squeeze=False)
    f = frf.frequency_hz
    for i, out in enumerate(frf.output_names):
        for j, inp in enumerate(frf.input_names):
            ax = axes[i, j]
            ax.semilogx(f[1:], frf.coherence.sel(output=out, input=inp).values[1:], lw=0.7)
            ax.set_title(f"{inp} → {out}", fontsize=9)
            ax.set_ylim(0, 1.05)
            ax.grid(alpha=0.3, which="both")
            if i == len(frf.output_names) - 1:
                ax.set_xlabel("Frequency [Hz]")
            if j == 0:
                ax.set_ylabel("Coherence [-]")
    fig.suptitle(title)
    fig.tight_layout()
    return fig


def frf_matrix_figure(frf: FrequencyResponse, *, delay_s: float, model: np.ndarray | None,
                      part: str, title: str, f_max_hz: float = 5000.0) -> MplFigure:
    """Figs. 18/19/21/22/26/27: magnitude or phase of each path, fit over it.

    ``model`` (F, p, m) is on ``frf``'s grid, delay-free; the measured FRF is
    shown with its delay removed, as the seed fits it.
    """
    clean = remove_delay(frf, delay_s)
    f = clean.frequency_hz
    sel = (f > 0) & (f <= f_max_hz)
    fig, axes = plt.subplots(len(frf.output_names), len(frf.input_names), figsize=(10, 7),
                             sharex=True, squeeze=False)
    for i, out in enumerate(frf.output_names):
        for j, inp in enumerate(frf.input_names):
            ax = axes[i, j]
            h = clean.frf.sel(output=out, input=inp).values[sel]
            if part == "magnitude":
                ax.loglog(f[sel], np.abs(h), lw=0.7, label="measured (delay removed)")
                if model is not None:
                    ax.loglog(f[sel], np.abs(model[sel, i, j]), "k--", lw=0.9, label="fit")
                ax.set_ylabel(f"|{out}/{inp}| [V/V]")
            else:
                ax.semilogx(f[sel], np.degrees(np.angle(h)), lw=0.7, label="measured")
                if model is not None:
                    ax.semilogx(f[sel], np.degrees(np.angle(model[sel, i, j])), "k--", lw=0.9,
                                label="fit")
                ax.set_ylim(-185, 185)
                ax.set_yticks([-180, -90, 0, 90, 180])
                ax.set_ylabel(f"∠{out}/{inp} [deg]")
            ax.set_title(f"{inp} → {out}", fontsize=9)
            ax.grid(alpha=0.3, which="both")
            if i == len(frf.output_names) - 1:
                ax.set_xlabel("Frequency [Hz]")
    axes[0, 0].legend(fontsize=8)
    fig.suptitle(title)
    fig.tight_layout()
    return fig


def weights_figure(sercalo: SercaloIdentification) -> MplFigure:
    """Fig. 20: the seed's fit weights of each path."""
    fig, ax = plt.subplots(figsize=(9, 4))
    f = sercalo.frf.frequency_hz
    for out in sercalo.frf.output_names:
        for inp in sercalo.frf.input_names:
            ax.semilogx(f[1:], sercalo.weights.sel(output=out, input=inp).values[1:], lw=0.8,
                        label=f"{inp} → {out}")
    ax.set_xlabel("Frequency [Hz]")
    ax.set_ylabel("Weight [-]")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)
    fig.tight_layout()
    return fig


def delay_figure(newport: NewportIdentification) -> MplFigure:
    """Fig. 28: Newport phase with and without the identified delay."""
    fig, axes = plt.subplots(1, 2, figsize=(10, 4), sharey=True)
    f = newport.frf.frequency_hz
    sel = (f > 0) & (f <= 2000)
    clean = remove_delay(newport.frf, newport.delay_s)
    for ax, (out, inp) in zip(axes, (("Vph", "Unh"), ("Vpv", "Unv")), strict=True):
        raw = np.unwrap(np.angle(newport.frf.frf.sel(output=out, input=inp).values[sel]))
        ax.semilogx(f[sel], np.degrees(raw), lw=0.8, label="measured")
        fixed = np.unwrap(np.angle(clean.frf.sel(output=out, input=inp).values[sel]))
        ax.semilogx(f[sel], np.degrees(fixed), lw=0.8,
                    label=f"delay {1e3 * newport.delay_s:.3f} ms removed")
        ax.set_title(f"{inp} → {out}", fontsize=9)
        ax.set_xlabel("Frequency [Hz]")
        ax.grid(alpha=0.3, which="both")
    axes[0].set_ylabel("Phase [deg]")
    axes[0].legend(fontsize=8)
    fig.tight_layout()
    return fig
