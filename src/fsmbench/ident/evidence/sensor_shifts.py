"""What a 4QD amplifier the Newport's lines cannot resolve could do to its parameters.

The delays measure the amplifier's lag; nothing in the Newport's band gives
its shape. :func:`unresolved_sensor_shifts` refits each axis with a first- and
a second-order amplifier of that lag and bounds the parameters' shifts (a
bounded part of their uncertainty, :mod:`fsmbench.ident.totals`);
:func:`resolved_sensor` and :func:`sensor_notices` say what the fits did
resolve. Moved out of :mod:`fsmbench.ident.newport`, which fits the axes.
"""

from __future__ import annotations

import math

import numpy as np

from fsmbench.checks import Notice
from fsmbench.ident.delay.sampled import SensorLowpass
from fsmbench.ident.frf.response import FrequencyResponse
from fsmbench.ident.newport import (
    NEWPORT_PATHS,
    NewportDynamics,
    SensorShift,
    fit_newport_axis,
)

__all__ = ["resolved_sensor", "sensor_notices", "unresolved_sensor_shifts"]


_SHIFTED = ("gain_v_per_v", "natural_freq_hz", "damping_ratio")


def unresolved_sensor_shifts(frf: FrequencyResponse, dyn: NewportDynamics, *,
                             lag_s: float) -> dict[str, SensorShift]:
    """The parameter shifts an unresolved 4QD amplifier of group delay ``lag_s`` could cause.

    For each axis fitted without an amplifier (none in the bench model, none
    resolved by the lines), the fit again with a first-order and with a
    second-order (Butterworth) amplifier of that group delay, the bandwidth
    fixed: the delays measure the lag, not its shape, and on the Newport's
    band a second order fits the two shapes about equally well while moving
    its natural frequency by up to 1 % (a 22.5 µs lag: +1.8 Hz for the
    Butterworth the real-bench twin has, +28 Hz for a first order, on the
    exact response). A shift is a bounded part of the parameter's uncertainty
    (:mod:`fsmbench.ident.totals`).

    Parameters
    ----------
    frf : FrequencyResponse
        The Newport's matrix the axes were fitted on.
    dyn : NewportDynamics
    lag_s : float
        The amplifier's group delay [s]; ≤ 0 or NaN: no shift.

    Returns
    -------
    dict axis -> SensorShift
        Only the axes fitted without an amplifier.
    """
    out: dict[str, SensorShift] = {}
    if not (math.isfinite(lag_s) and lag_s > 0):
        return out
    for axis, fit in dyn.axes.items():
        if fit.sensor is None or fit.sensor.source != "unlimited":
            continue
        by_order = {}
        for order, per_rad in ((1, 1.0), (2, math.sqrt(2.0))):
            lowpass = SensorLowpass(bandwidth_hz=per_rad / (2 * math.pi * lag_s), order=order)
            refit = fit_newport_axis(frf, axis, sensor=lowpass, resolve_sensor=False)
            by_order[order] = {k: float(getattr(refit, k) - getattr(fit, k)) for k in _SHIFTED}
        out[axis] = SensorShift(axis=axis, lag_s=float(lag_s), by_order=by_order,
                                half_width={k: max(abs(v[k]) for v in by_order.values())
                                            for k in _SHIFTED})
    return out


def resolved_sensor(dyn: NewportDynamics) -> SensorLowpass | None:
    """The 4QD amplifier the Newport's lines resolved (the mean of the axes that did), or None.

    Both axes' amplifiers are taken as one, as the bench file has one bandwidth; the
    order is the better-fitting axis's (the larger likelihood ratio).
    """
    fitted = [a.sensor for a in dyn.axes.values()
              if a.sensor is not None and a.sensor.source == "fitted"]
    if not fitted:
        return None
    best = max(fitted, key=lambda e: e.likelihood_ratio)
    return SensorLowpass(bandwidth_hz=float(np.mean([e.bandwidth_hz for e in fitted])),
                         order=best.order)


def sensor_notices(dyn: NewportDynamics, *, model: SensorLowpass) -> list[Notice]:
    """A notice per axis whose lines resolve a 4QD amplifier bandwidth the bench model lacks.

    The run fits the Sercalo's delay again with it (:func:`resolved_sensor`); the bench
    file should carry it so that the twin and a design's checks use it too.
    """
    out = []
    for axis, fit in dyn.axes.items():
        est = fit.sensor
        if est is None or est.source != "fitted":
            continue
        if model.limited and abs(est.bandwidth_hz / model.bandwidth_hz - 1) <= (
                2 * est.bandwidth_std_hz / est.bandwidth_hz):
            continue  # the model's value is within two standard deviations
        out.append(Notice("other", f"{NEWPORT_PATHS[axis][1]} → {NEWPORT_PATHS[axis][0]}",
                          f"the 4QD amplifier is resolved as a "
                          f"{'first-order' if est.order == 1 else 'second-order (Butterworth)'}"
                          f" low pass at {est.bandwidth_hz:.4g} ± {est.bandwidth_std_hz:.2g} Hz"
                          f" (bench model: {model.bandwidth_hz:g} Hz, 0 = unlimited); set "
                          f"quad_diode.bandwidth_hz = {est.bandwidth_hz:.4g} and "
                          f"quad_diode.bandwidth_order = {est.order} in the bench file's "
                          f"[nominal] (this run used it for the Sercalo's delay; the file "
                          f"makes the twin and the checks of a design use it too)"))
    return out
