"""Time-domain figures of the seed's experiments (Figs. 8, 9, 15, 16, 23, 24, 29, 44).

Long records (10^6 samples) are drawn through a min/max envelope per pixel
column: every extreme stays visible, the PNG stays small. The data are not
changed; only what is drawn is.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import matplotlib

matplotlib.use("Agg")  # the report renders off-screen; no display is needed

import matplotlib.pyplot as plt
import numpy as np
import xarray as xr
from matplotlib.figure import Figure as MplFigure

__all__ = [
    "Trace",
    "envelope",
    "experiment_figure",
    "experiment_panels",
    "huddle_figure",
    "plot_traces",
]


@dataclass(frozen=True)
class Trace:
    """One signal on one axis: variable name, scale to display units, label."""

    signal: str
    scale: float
    label: str


def envelope(t: np.ndarray, y: np.ndarray, *, bins: int = 3000) -> tuple[np.ndarray, np.ndarray]:
    """Min/max envelope of ``y`` in ``bins`` columns, interleaved for a line plot."""
    n = y.size
    if n <= 2 * bins:
        return t, y
    per = n // bins
    m = per * bins
    yb = y[:m].reshape(bins, per)
    tb = t[:m].reshape(bins, per)
    lo_i = np.argmin(yb, axis=1)
    hi_i = np.argmax(yb, axis=1)
    first = np.minimum(lo_i, hi_i)
    second = np.maximum(lo_i, hi_i)
    rows = np.arange(bins)
    tt = np.column_stack([tb[rows, first], tb[rows, second]]).ravel()
    yy = np.column_stack([yb[rows, first], yb[rows, second]]).ravel()
    if m < n:  # the tail that did not fill a whole column
        tt = np.concatenate([tt, t[m:]])
        yy = np.concatenate([yy, y[m:]])
    return tt, yy


def plot_traces(ds: xr.Dataset, panels: Sequence[tuple[str, Sequence[Trace]]], *,
                title: str, trim_s: float = 0.0) -> MplFigure:
    """Stacked time plots sharing the time axis.

    Parameters
    ----------
    ds : xarray.Dataset
        A recording (coordinate ``t`` in s).
    panels : sequence of (y-label, traces)
        One axis per entry; traces whose signal is absent are skipped.
    title : str
    trim_s : float
        Shade ``t < trim_s``: the part the seed's processing removes.
    """
    present = [(ylabel, [tr for tr in traces if tr.signal in ds])
               for ylabel, traces in panels]
    present = [(ylabel, traces) for ylabel, traces in present if traces]
    fig, axes = plt.subplots(len(present), 1, sharex=True, figsize=(9, 2.2 * len(present) + 0.6),
                             squeeze=False)
    t = np.asarray(ds["t"].values)
    for ax, (ylabel, traces) in zip(axes[:, 0], present, strict=True):
        for tr in traces:
            tt, yy = envelope(t, np.asarray(ds[tr.signal].values) * tr.scale)
            ax.plot(tt, yy, lw=0.6, label=tr.label)
        ax.set_ylabel(ylabel)
        ax.grid(True, alpha=0.3)
        if len(traces) > 1:
            ax.legend(loc="upper right", fontsize=8)
        if trim_s > 0:
            ax.axvspan(t[0], trim_s, color="0.85", zorder=0)
    axes[-1, 0].set_xlabel("Time [s]")
    axes[-1, 0].set_xlim(t[0], t[-1])
    axes[0, 0].set_title(title)
    fig.tight_layout()
    return fig


# The seed's figures per experiment: which signals, in which units.
_NEWPORT_ANGLE = "Beam angle [mrad]"


def experiment_panels(name: str, gn0_rad_per_v: float) -> list[tuple[str, list[Trace]]]:
    """Panels of the seed's time-domain figure for experiment ``name``."""
    qd = ("4QD [V]", [Trace("Vph", 1.0, "Vph"), Trace("Vpv", 1.0, "Vpv")])
    beam = 2 * gn0_rad_per_v * 1e3  # beam angle = 2 x mirror angle (seed 2.1), in mrad
    if name.startswith("data_cal_pd"):
        angle = [Trace("Vnh", beam, "2 gn0 Vnh"), Trace("Vnv", beam, "2 gn0 Vnv")]
        return [(_NEWPORT_ANGLE, angle), qd]
    if name in ("data_uch", "data_ucv"):
        return [("Sercalo command [V]", [Trace("Uch", 1.0, "Uch"), Trace("Ucv", 1.0, "Ucv")]),
                ("Coil voltage [V]", [Trace("Vch", 1.0, "Vch"), Trace("Vcv", 1.0, "Vcv")]), qd]
    if name in ("data_unh", "data_unv"):
        return [("Newport command [V]", [Trace("Unh", 1.0, "Unh"), Trace("Unv", 1.0, "Unv")]), qd]
    if name.startswith("data_rep"):
        return [("Newport command [V]", [Trace("Unh", 1.0, "Unh"), Trace("Unv", 1.0, "Unv")]),
                ("Sercalo command [V]", [Trace("Uch", 1.0, "Uch"), Trace("Ucv", 1.0, "Ucv")]),
                qd, ("Attocube [nm]", [Trace("Va", 1e9, "Va")])]
    return [qd, ("Attocube [nm]", [Trace("Va", 1e9, "Va")]),
            ("Sercalo command [V]", [Trace("Uch", 1.0, "Uch"), Trace("Ucv", 1.0, "Ucv")])]


def experiment_figure(ds: xr.Dataset, *, gn0_rad_per_v: float, trim_s: float) -> MplFigure:
    """The seed's time-domain figure of one experiment."""
    name = str(ds.attrs.get("experiment", ""))
    return plot_traces(ds, experiment_panels(name, gn0_rad_per_v),
                       title=f"{name}: {ds.sizes['t']} samples at {ds.attrs.get('fs_hz', 0):g} Hz",
                       trim_s=trim_s)


def huddle_figure(records: Mapping[str, xr.Dataset], *, t0_s: float = 1.0,
                  duration_s: float = 100.0) -> MplFigure:
    """Seed Fig. 29: ``Va`` of each huddle test, trimmed as the seed does, mean removed."""
    fig, ax = plt.subplots(figsize=(9, 3.6))
    for name, ds in records.items():
        if "Va" not in ds:
            continue
        t = np.asarray(ds["t"].values)
        keep = t >= t0_s
        va = np.asarray(ds["Va"].values)[keep]
        tt = t[keep] - t[keep][0]
        fs = float(ds.attrs.get("fs_hz", 1.0 / np.median(np.diff(t))))
        n = min(va.size, round(duration_s * fs))
        va, tt = va[:n], tt[:n]
        x, y = envelope(tt, (va - va.mean()) * 1e9)
        ax.plot(x, y, lw=0.6, label=name.replace("data_huddle_test_", "test "))
    ax.set_xlabel("Time [s]")
    ax.set_ylabel("Va, mean removed [nm]")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8, ncol=5)
    ax.set_title("Attocube during the huddle tests")
    fig.tight_layout()
    return fig
