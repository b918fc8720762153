"""Time-domain figures of one experiment, as the ESRF study draws them (Figs. 8, 9, 15, 16, 23 …).

One panel per recorded signal, all sharing the time axis, so no signal hides
another (``Vph`` and ``Vpv`` each get their own); horizontal signals are
blue, vertical orange. Records are long (10^5–10^6 samples): every line is
marked ``decimate=True`` and drawn as a min/max envelope, which keeps every
extreme. The part of the record the ESRF study's processing removes (its ``t0``)
is shaded.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import xarray as xr

from fsmbench.report.figures.spec import H_COLOR, PALETTE, V_COLOR, Figure, Line, Panel

__all__ = ["SEED_TIME_FIGURES", "SignalPanel", "experiment_figure", "signal_panels"]


@dataclass(frozen=True)
class SignalPanel:
    """How one recorded signal is drawn.

    Attributes
    ----------
    signal : str
        Variable name in the recording (the ESRF study's name, e.g. ``"Vph"``).
    title : str
        What the signal is, in words (panel title).
    y_label : str
        Quantity and display unit (``"Beam angle [mrad]"``).
    scale : float
        Display units per recorded unit (0 for the metrology signals, whose
        scale is the Newport metrology gain, see :func:`signal_panels`).
    color : str
    remove_mean : bool
        Draw the signal minus its mean (the Attocube's absolute distance is
        not what the figure is about).
    """

    signal: str
    title: str
    y_label: str
    scale: float
    color: str
    remove_mean: bool = False


def signal_panels(gn0_rad_per_v: float) -> tuple[SignalPanel, ...]:
    """Every signal the ESRF study records, in the order the figures stack them.

    Parameters
    ----------
    gn0_rad_per_v : float
        Newport metrology gain [rad/V] (ESRF study 2.1: 2.62e-3): ``Vnh``/``Vnv``
        are drawn as the beam angle ``2·gn0·Vn`` (one reflection doubles the
        mirror angle) in mrad.
    """
    beam_mrad = 2.0 * gn0_rad_per_v * 1e3
    return (
        SignalPanel("Unh", "Newport command, horizontal (Unh)", "Command [V]", 1.0, H_COLOR),
        SignalPanel("Unv", "Newport command, vertical (Unv)", "Command [V]", 1.0, V_COLOR),
        SignalPanel("Uch", "Sercalo command, horizontal (Uch)", "Command [V]", 1.0, H_COLOR),
        SignalPanel("Ucv", "Sercalo command, vertical (Ucv)", "Command [V]", 1.0, V_COLOR),
        SignalPanel("Vnh", "Beam angle from the Newport metrology, horizontal (2·gn0·Vnh)",
                    "Beam angle [mrad]", beam_mrad, H_COLOR),
        SignalPanel("Vnv", "Beam angle from the Newport metrology, vertical (2·gn0·Vnv)",
                    "Beam angle [mrad]", beam_mrad, V_COLOR),
        SignalPanel("Vch", "Amplified coil voltage, horizontal (Vch)", "Voltage [V]", 1.0,
                    H_COLOR),
        SignalPanel("Vcv", "Amplified coil voltage, vertical (Vcv)", "Voltage [V]", 1.0,
                    V_COLOR),
        SignalPanel("Vph", "4QD output, horizontal (Vph)", "Voltage [V]", 1.0, H_COLOR),
        SignalPanel("Vpv", "4QD output, vertical (Vpv)", "Voltage [V]", 1.0, V_COLOR),
        SignalPanel("Va", "Attocube distance, mean removed (Va)", "Distance [nm]", 1e9,
                    PALETTE[2], remove_mean=True),
    )


# The seed's time-domain figures of the identification experiments:
# experiment -> (figure key, seed figure, title in words).
SEED_TIME_FIGURES: dict[str, tuple[str, str, str]] = {
    "data_cal_pd_h": ("fig8_cal_pd_h_time", "Fig. 8",
                      "4QD calibration, horizontal: the recorded signals"),
    "data_cal_pd_v": ("fig9_cal_pd_v_time", "Fig. 9",
                      "4QD calibration, vertical: the recorded signals"),
    "data_uch": ("fig15_uch_time", "Fig. 15",
                 "Noise on the Sercalo's horizontal command: the recorded signals"),
    "data_ucv": ("fig16_ucv_time", "Fig. 16",
                 "Noise on the Sercalo's vertical command: the recorded signals"),
    "data_unh": ("fig23_unh_time", "Fig. 23",
                 "Noise on the Newport's horizontal command: the recorded signals"),
    "data_unv": ("fig24_unv_time", "Fig. 24",
                 "Noise on the Newport's vertical command: the recorded signals"),
}


def experiment_figure(ds: xr.Dataset, *, key: str, title: str, caption: str, seed_ref: str,
                      gn0_rad_per_v: float, trim_s: float) -> Figure:
    """The ESRF study's time-domain figure of one experiment: one panel per signal.

    Parameters
    ----------
    ds : xarray.Dataset
        A recording: coordinate ``t`` [s], shape (n,), and any of the ESRF study's
        signals (``Uch … Va``, V or m); other variables are not drawn.
    key, title, caption, seed_ref : str
        As for :class:`~fsmbench.report.figures.spec.Figure`.
    gn0_rad_per_v : float
        Newport metrology gain [rad/V], to draw ``Vnh``/``Vnv`` as beam angles.
    trim_s : float
        The ESRF study's ``t0`` [s]: ``t < trim_s`` is shaded (0: nothing shaded).

    Raises
    ------
    ValueError
        The recording holds none of the ESRF study's signals (the message names it).
    """
    t = np.asarray(ds["t"].values, dtype=float)
    panels = []
    for spec in signal_panels(gn0_rad_per_v):
        if spec.signal not in ds:
            continue
        y = np.asarray(ds[spec.signal].values, dtype=float)
        if spec.remove_mean:
            y = y - np.nanmean(y)
        shade = (float(t[0]), float(trim_s)) if trim_s > t[0] else None
        panels.append(Panel(
            traces=(Line(t, spec.scale * y, name=spec.signal, color=spec.color, width=1.0,
                         decimate=True, legend=False),),
            x_label="Time [s]", y_label=spec.y_label, title=spec.title, shade=shade))
    if not panels:
        name = ds.attrs.get("experiment", "recording")
        raise ValueError(f"{name}: none of the ESRF study's signals to plot (has "
                         f"{', '.join(str(v) for v in ds.data_vars) or 'nothing'})")
    return Figure(key=key, title=title, caption=caption, panels=tuple(panels),
                  seed_ref=seed_ref, share_x=True, height_px=max(360, 100 + 165 * len(panels)))
