"""The Sercalo model's quality: the Welch window's leakage removed, and why not to trust a fit.

:func:`leakage_corrected` takes the Welch FRF's bias near the lightly damped modes out
(the fitted model's, its modes refined on the time records) and keeps the correction's
own error as a variance part; :func:`quality_warnings` names a fit not to design on;
:func:`sensor_shift_notices` says when the 4QD amplifier's unknown order outweighs the
noise on the Newport's natural frequency.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace

import numpy as np

from fsmbench.checks import Notice
from fsmbench.ident.fit.modes import ModeRefinement
from fsmbench.ident.frf.leakage import welch_leakage_bias
from fsmbench.ident.frf.response import FrequencyResponse, with_variance_part
from fsmbench.ident.newport import SensorShift
from fsmbench.ident.sercalo import SercaloIdentification
from fsmbench.ident.validate import PathValidation
from fsmbench.signal.welch import hanning

__all__ = ["MAX_DIRECT_FIT_ERROR", "MIN_DIRECT_VAF", "leakage_bias", "leakage_corrected",
           "quality_warnings", "sensor_shift_notices"]


def leakage_bias(sid: SercaloIdentification, window_s: float) -> np.ndarray:
    """``E[Ĥ] − H`` of the Welch estimate on ``sid.frf``'s lines for ``sid``'s model and
    delay (:func:`~fsmbench.ident.frf.leakage.welch_leakage_bias`), shape (F, p, m)."""
    frf = sid.frf
    delay = sid.delay_s

    def model(f_hz: np.ndarray) -> np.ndarray:
        return sid.fit.response(f_hz) * np.exp(-2j * np.pi * f_hz * delay)[:, None, None]

    f = frf.frequency_hz
    bias = np.zeros(frf.frf.shape, dtype=complex)
    sel = f > 0
    fit_out = list(sid.fit.output_names)
    fit_in = list(sid.fit.input_names)
    b = welch_leakage_bias(model, f[sel], fs_hz=frf.fs_hz,
                           window=hanning(int(np.ceil(window_s * frf.fs_hz))))
    rows = [fit_out.index(o) for o in frf.output_names]
    cols = [fit_in.index(i) for i in frf.input_names]
    bias[sel] = b[:, rows][:, :, cols]
    return bias


def leakage_corrected(sid: SercaloIdentification, window_s: float, *,
                  unrefined: SercaloIdentification | None) -> FrequencyResponse:
    """The Sercalo's Welch FRF with its leakage bias near the modes removed, and the
    correction's uncertainty as a variance part (:mod:`fsmbench.ident.frf.leakage`).

    The bias is the fitted model's (its modes refined on the time records) with its delay.
    Removed, because a bias only widened still pulls the fit: the lines a few Hz from the
    vertical mode moved its static gain by +0.7 of its std on every seed (100
    twin seeds); subtracted, +0.04. The correction's own error is that of the model's
    modes: bounded by how much the bias changes from the fit's modes before the refinement
    (the FRF's, leakage-biased: 5-10 % in damping) to the refined ones; without a
    refinement, by the bias itself."""
    bias = leakage_bias(sid, window_s)
    spread = bias if unrefined is None else bias - leakage_bias(unrefined, window_s)
    frf = sid.frf
    corrected = replace(frf, frf=frf.frf.copy(data=np.asarray(frf.frf.values) - bias))
    return with_variance_part(corrected, "leakage", np.abs(spread) ** 2)


def sensor_shift_notices(shifts: Mapping[str, SensorShift], *, lag_s: float,
                          noise: Mapping[str, float]) -> list[Notice]:
    """Advice where the amplifier's unknown order outweighs the noise on the Newport's
    natural frequency: the bench file can state it."""
    out = []
    for axis, shift in shifts.items():
        width = shift.half_width["natural_freq_hz"]
        if width <= noise[axis]:
            continue
        out.append(Notice(
            "other", f"Newport {axis}",
            f"the delays measure a 4QD amplifier lag of {lag_s * 1e6:.3g} µs that the bench "
            f"model lacks and the Newport's lines do not resolve; its order moves the "
            f"Newport's natural frequency by up to {width:.3g} Hz (noise {noise[axis]:.2g} "
            f"Hz): state quad_diode.bandwidth_hz and bandwidth_order in the bench file's "
            f"[nominal] to remove it"))
    return out


# Quality limits: the identification issue's 5 % fit target on direct paths;
# a direct path whose model explains < 90 % of the recorded variance, or a
# modal fit that did not converge, is not a model to design a controller on.
MAX_DIRECT_FIT_ERROR = 0.05
MIN_DIRECT_VAF = 0.9


def quality_warnings(*, sercalo: SercaloIdentification | None, modes: ModeRefinement | None,
                     validation: tuple[PathValidation, ...]) -> tuple[str, ...]:
    """Why a Sercalo model should not be trusted, one sentence each (empty when good)."""
    out: list[str] = []
    if sercalo is None:
        return ()
    if not sercalo.fit.converged:
        out.append(f"vector fitting did not converge in {sercalo.fit.iterations} iterations; "
                   "the poles may be wrong — check the weights and the excitation")
    for path in ("Vph/Uch", "Vpv/Ucv"):
        err = sercalo.fit_error.get(path, float("nan"))
        if not np.isfinite(err):
            out.append(f"{path}: no bin with coherence > 0.9 between 10 Hz and 1 kHz; the "
                       "excitation is too weak for this path — raise its level or lengthen "
                       "the record")
        elif err > MAX_DIRECT_FIT_ERROR:
            out.append(f"{path}: the fit misses the measured FRF by {err:.1%} rms "
                       f"(limit {MAX_DIRECT_FIT_ERROR:.0%}); more poles or other weights needed")
    for v in validation:
        if v.output[-1] == v.input[-1] and v.vaf < MIN_DIRECT_VAF:
            out.append(f"{v.experiment}: the model explains {v.vaf:.1%} of {v.output}'s "
                       f"variance (limit {MIN_DIRECT_VAF:.0%})")
    if modes is not None:
        for axis, est in modes.estimates.items():
            if not est.converged:
                out.append(f"modal estimate of axis {axis} did not converge; its damping is "
                           "unreliable")
    return tuple(out)
