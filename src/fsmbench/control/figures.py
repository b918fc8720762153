"""Figures of the control study (seed Figs. 41–43 and fsmbench's checks).

Every function returns a :class:`matplotlib.figure.Figure` (Agg backend);
:func:`design_figures` returns all of them for a :class:`DesignResult`, keyed
by a file-name stem.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import matplotlib

matplotlib.use("Agg")  # the report renders off-screen; no display is needed

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from fsmbench.control.analysis import PlantAnalysis
from fsmbench.control.design import Robustness
from fsmbench.control.iff import IffAnalysis
from fsmbench.control.loops import AXES, LoopAnalysis
from fsmbench.control.study import DesignResult, NewportToBeam

__all__ = [
    "bode_figure",
    "design_figures",
    "iff_figure",
    "loop_gain_figure",
    "newport_to_beam_figure",
    "nyquist_figure",
    "rga_figure",
    "robustness_figure",
    "sensitivity_figure",
]

_COLORS = {"h": "tab:blue", "v": "tab:orange"}


def _phase_deg(x: np.ndarray, *, f_hz: np.ndarray | None = None,
               anchor_hz: float = float("nan")) -> np.ndarray:
    """Unwrapped phase [deg], shifted by 360° steps to lie in (-360, 0] at ``anchor_hz``."""
    ph = np.degrees(np.unwrap(np.angle(x)))
    if f_hz is None or not np.isfinite(anchor_hz):
        return ph
    at = ph[int(np.argmin(np.abs(np.log(f_hz / anchor_hz))))]
    return ph - 360.0 * np.ceil(at / 360.0)


def _bode_axes(title: str) -> tuple[Figure, Axes, Axes]:
    fig, (ax_m, ax_p) = plt.subplots(2, 1, sharex=True, figsize=(7.5, 6.0),
                                     gridspec_kw={"height_ratios": [2, 1]})
    ax_m.set_title(title)
    ax_m.set_ylabel("magnitude [1]")
    ax_p.set_ylabel("phase [deg]")
    for ax in (ax_m, ax_p):
        ax.set_xlabel("frequency [Hz]")
        ax.grid(True, which="both", alpha=0.3)
    return fig, ax_m, ax_p


def loop_gain_figure(loops: Sequence[LoopAnalysis], *, title: str) -> Figure:
    """Bode of the diagonal loop gains ``L_ii`` of one or more loops (seed Figs. 41, 43)."""
    fig, ax_m, ax_p = _bode_axes(title)
    styles = ["-", "--", ":", "-."]
    for j, lp in enumerate(loops):
        for i, axis in enumerate(AXES[: lp.loop.shape[1]]):
            li = lp.loop[:, i, i]
            fc = lp.axes[axis].margins.crossover_hz
            label = f"{lp.name or 'L'} {axis} (fc = {fc:.1f} Hz)"
            ax_m.loglog(lp.f_hz, np.abs(li), styles[j % 4], color=_COLORS[axis], label=label)
            ax_p.semilogx(lp.f_hz, _phase_deg(li, f_hz=lp.f_hz, anchor_hz=fc), styles[j % 4],
                          color=_COLORS[axis])
    ax_m.axhline(1.0, color="k", lw=0.8)
    ax_p.axhline(-180.0, color="k", lw=0.8)
    ax_m.legend(fontsize=8)
    fig.tight_layout()
    return fig


def bode_figure(lp: LoopAnalysis) -> Figure:
    """Bode of each loop gain of one loop, with its margins in the legend."""
    fig, ax_m, ax_p = _bode_axes(f"Loop gain L = G K: {lp.name} on {lp.plant_source}")
    for i, axis in enumerate(AXES[: lp.loop.shape[1]]):
        m = lp.axes[axis].margins
        li = lp.loop[:, i, i]
        ax_m.loglog(lp.f_hz, np.abs(li), color=_COLORS[axis],
                    label=f"{axis}: GM {m.gain_margin_db:.1f} dB, PM {m.phase_margin_deg:.1f}°, "
                          f"fc {m.crossover_hz:.1f} Hz")
        ax_p.semilogx(lp.f_hz, _phase_deg(li, f_hz=lp.f_hz, anchor_hz=m.crossover_hz),
                      color=_COLORS[axis])
    ax_m.axhline(1.0, color="k", lw=0.8)
    ax_p.axhline(-180.0, color="k", lw=0.8)
    ax_m.legend(fontsize=8)
    fig.tight_layout()
    return fig


def nyquist_figure(lp: LoopAnalysis, *, radius: float = 3.0) -> Figure:
    """Nyquist plot of each ``L_ii`` near ``-1`` with the unit and modulus-margin circles."""
    fig, axes = plt.subplots(1, lp.loop.shape[1], figsize=(10.0, 4.8), squeeze=False)
    th = np.linspace(0, 2 * np.pi, 400)
    for i, (ax, axis) in enumerate(zip(axes[0], AXES, strict=False)):
        li = lp.loop[:, i, i]
        mm = lp.axes[axis].margins.modulus_margin
        ax.plot(li.real, li.imag, color=_COLORS[axis], label="L(jω), ω > 0")
        ax.plot(li.real, -li.imag, color=_COLORS[axis], alpha=0.35, label="ω < 0")
        ax.plot(np.cos(th), np.sin(th), "k:", lw=0.8, label="|L| = 1")
        ax.plot(-1 + mm * np.cos(th), mm * np.sin(th), "r--", lw=0.8,
                label=f"modulus margin {mm:.2f}")
        ax.plot([-1], [0], "r+", ms=10)
        ax.set_xlim(-radius, radius)
        ax.set_ylim(-radius, radius)
        ax.set_aspect("equal")
        ax.set_xlabel("Re L [1]")
        ax.set_ylabel("Im L [1]")
        ax.set_title(f"{lp.name} {axis}: {'stable' if lp.axes[axis].stable else 'UNSTABLE'}")
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=7, loc="lower left")
    fig.tight_layout()
    return fig


def sensitivity_figure(lp: LoopAnalysis) -> Figure:
    """``|S_ii|``, ``|T_ii|`` and ``sigma_max(S)``, with the 6.1 bound at ``f0``."""
    fig, ax = plt.subplots(figsize=(7.5, 4.8))
    for i, axis in enumerate(AXES[: lp.loop.shape[1]]):
        ax.loglog(lp.f_hz, np.abs(lp.sensitivity[:, i, i]), color=_COLORS[axis],
                  label=f"|S| {axis}")
        ax.loglog(lp.f_hz, np.abs(lp.complementary[:, i, i]), "--", color=_COLORS[axis],
                  label=f"|T| {axis}")
    smax = np.linalg.svd(lp.sensitivity, compute_uv=False)[:, 0]
    ax.loglog(lp.f_hz, smax, "k:", lw=1, label="σmax(S)")
    obj = lp.objective
    ax.plot([obj.frequency_hz], [obj.sensitivity_bound], "rv", ms=9,
            label=f"6.1 bound {obj.sensitivity_bound:.0e} at {obj.frequency_hz:g} Hz")
    ax.set_xlabel("frequency [Hz]")
    ax.set_ylabel("magnitude [1]")
    ax.set_title(f"Sensitivity and complementary sensitivity: {lp.name}")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    return fig


def newport_to_beam_figure(n2b: NewportToBeam) -> Figure:
    """Newport command to beam angle, open loop and with the Sercalo loops closed (Fig. 42)."""
    fig, axes = plt.subplots(1, 2, sharey=True, figsize=(10.0, 4.5))
    for i, (ax, axis) in enumerate(zip(axes, AXES, strict=True)):
        ax.loglog(n2b.f_hz, np.abs(n2b.open_loop[:, i, i]), "k", label="open loop")
        for name, resp in n2b.closed.items():
            ax.loglog(n2b.f_hz, np.abs(resp[:, i, i]), label=f"closed: {name}")
        ax.set_xlabel("frequency [Hz]")
        ax.set_title(f"U_n{axis} → R{axis}")
        ax.set_ylabel("beam angle per Newport command [rad/V]")
        ax.grid(True, which="both", alpha=0.3)
    axes[0].legend(fontsize=8)
    fig.tight_layout()
    return fig


def rga_figure(pa: PlantAnalysis) -> Figure:
    """RGA number (seed 7.2) and singular values of ``Uc -> R``."""
    fig, (ax1, ax2) = plt.subplots(2, 1, sharex=True, figsize=(7.5, 6.0))
    ax1.semilogx(pa.f_hz, pa.rga_number)
    ax1.set_ylabel("RGA number Σ|Λ − I| [1]")
    ax1.set_xlabel("frequency [Hz]")
    ax1.set_title("Plant interaction (Uch, Ucv → Rh, Rv)")
    ax2.loglog(pa.f_hz, pa.singular_values[:, 0], label="σmax")
    ax2.loglog(pa.f_hz, pa.singular_values[:, 1], label="σmin")
    ax2.set_ylabel("singular value [rad/V]")
    ax2.set_xlabel("frequency [Hz]")
    ax2.legend(fontsize=8)
    for ax in (ax1, ax2):
        ax.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    return fig


def robustness_figure(rob: Robustness, *, title: str = "") -> Figure:
    """Loop gains over the perturbed set and each case's margins."""
    fig, axes = plt.subplots(2, 2, figsize=(11.0, 7.5))
    for i, axis in enumerate(AXES):
        ax = axes[0, i]
        for lab, lp in zip(rob.labels, rob.loops, strict=True):
            ax.loglog(lp.f_hz, np.abs(lp.loop[:, i, i]), lw=0.8,
                      color="tab:red" if not lp.stable else None, label=lab)
        ax.axhline(1.0, color="k", lw=0.8)
        ax.set_xlabel("frequency [Hz]")
        ax.set_ylabel(f"|L_{axis}| [1]")
        ax.set_title(f"{title} {axis}: loop gain over the perturbed set".strip())
        ax.grid(True, which="both", alpha=0.3)
    axes[0, 1].legend(fontsize=6, ncol=2)
    x = np.arange(len(rob.labels))
    for j, (key, unit) in enumerate((("gain_margin_db", "dB"), ("phase_margin_deg", "deg"))):
        ax = axes[1, j]
        for k, axis in enumerate(AXES):
            vals = [getattr(lp.axes[axis].margins, key) for lp in rob.loops]
            vals = [v if np.isfinite(v) else np.nan for v in vals]
            ax.bar(x + 0.4 * k - 0.2, vals, width=0.4, color=_COLORS[axis], label=axis)
        ax.axhline(6.0 if j == 0 else 30.0, color="r", lw=0.8, ls="--", label="requirement")
        ax.set_xticks(x)
        ax.set_xticklabels(rob.labels, rotation=60, fontsize=7)
        ax.set_xlabel("perturbed plant (resonance × f, damping × ξ)")
        ax.set_ylabel(f"{key.split('_margin')[0]} margin [{unit}]")
        ax.grid(True, axis="y", alpha=0.3)
        ax.legend(fontsize=7)
    fig.tight_layout()
    return fig


def iff_figure(iff: IffAnalysis) -> Figure:
    """``Uch, Ucv -> Vph, Vpv`` without and with IFF (seed 8.2's Bode plot)."""
    fig, ax_m, ax_p = _bode_axes("Integral force feedback: Uc → Vp without and with Kppf")
    for i, axis in enumerate(AXES):
        ax_m.loglog(iff.f_hz, np.abs(iff.open_loop[:, i, i]), color=_COLORS[axis],
                    label=f"{axis} open loop")
        ax_m.loglog(iff.f_hz, np.abs(iff.closed_loop[:, i, i]), "--", color=_COLORS[axis],
                    label=f"{axis} with IFF ({'stable' if iff.loop_stable else 'unstable'})")
        ax_p.semilogx(iff.f_hz, _phase_deg(iff.open_loop[:, i, i]), color=_COLORS[axis])
        ax_p.semilogx(iff.f_hz, _phase_deg(iff.closed_loop[:, i, i]), "--",
                      color=_COLORS[axis])
    ax_m.set_ylabel("magnitude [V/V]")
    ax_m.legend(fontsize=8)
    fig.tight_layout()
    return fig


def design_figures(result: DesignResult) -> Mapping[str, Figure]:
    """All figures of a study, keyed by a file-name stem (e.g. ``"fig41_seed_loop_gain"``)."""
    figs: dict[str, Figure] = {
        "fig41_seed_loop_gain": loop_gain_figure(
            [result.seed], title="Fig. 41: loop gains with the seed's diagonal controller"),
        "fig42_newport_to_beam": newport_to_beam_figure(result.newport_to_beam),
        "fig43_newport_loop_gain": loop_gain_figure(
            [result.newport], title="Fig. 43: Newport loop gains (10.2)"),
        "loop_gains_compared": loop_gain_figure(
            [result.seed, result.fsmbench], title="Loop gains: seed vs fsmbench controller"),
        "rga_singular_values": rga_figure(result.plant),
        "robustness_fsmbench": robustness_figure(result.robustness, title="fsmbench"),
        "iff": iff_figure(result.iff),
    }
    if result.seed_robustness is not None:
        figs["robustness_seed"] = robustness_figure(result.seed_robustness, title="seed")
    for key, lp in result.loops.items():
        figs[f"bode_{key}"] = bode_figure(lp)
        figs[f"nyquist_{key}"] = nyquist_figure(lp)
        figs[f"sensitivity_{key}"] = sensitivity_figure(lp)
    return figs
