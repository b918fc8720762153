"""Time-domain validation of a fitted model: does it reproduce the records?

The fitted ``Uc → Vp`` model (with its identified delay) is driven by the
recorded command of each experiment and its output compared with the
recorded 4QD voltages. The figure of merit is the variance accounted for,

    VAF = 1 − var(y − ŷ) / var(y),

per path (1 is perfect, 0 is no better than the mean). The simulation is
exact for the held (ZOH) command: the model is discretised with
:func:`fsmbench.sim.discretize.zoh_with_delays`, whose hold contributes half
a sample, so the discrete input delay is ``τ/Ts − 1/2``. Both records have
their mean removed, and the first ``settle_s`` seconds are left out because
the model starts at rest while the bench was already moving (the lightly
damped modes ring for ~1/(ζω) ≈ 0.3–0.6 s).

Where the coherence is low (the cross paths), noise bounds the VAF: a path
with coherence γ² at every frequency cannot exceed a VAF of about γ².
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict, dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
import xarray as xr

from fsmbench.ident.calibration import trim_recording
from fsmbench.sim.discretize import zoh_with_delays
from fsmbench.sim.engine import Quantiser, run_loop

if TYPE_CHECKING:
    from fsmbench.ident.sercalo import SercaloIdentification

__all__ = ["PathValidation", "simulate_fit", "validate_sercalo", "variance_accounted_for"]


@dataclass(frozen=True)
class PathValidation:
    """VAF of one path of one experiment.

    Attributes
    ----------
    experiment, input, output : str
    vaf : float
        Variance accounted for (dimensionless, ≤ 1).
    residual_rms_v, output_rms_v : float
        Rms of ``y − ŷ`` and of ``y`` over the compared span [V].
    settle_s : float
        Seconds left out after the trim.
    """

    experiment: str
    input: str
    output: str
    vaf: float
    residual_rms_v: float
    output_rms_v: float
    settle_s: float

    def to_json(self) -> dict[str, Any]:
        """Plain values."""
        return asdict(self)


def variance_accounted_for(y: np.ndarray, y_hat: np.ndarray) -> float:
    """``1 − var(y − ŷ)/var(y)`` of two equal-length records."""
    y = np.asarray(y, dtype=float)
    var = float(np.var(y))
    if var == 0.0:
        return float("nan")
    return 1.0 - float(np.var(y - np.asarray(y_hat, dtype=float))) / var


def simulate_fit(a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray, *,
                 u: np.ndarray, delay_s: float, ts_s: float) -> np.ndarray:
    """Response of ``(A, B, C, D)`` with input delay ``delay_s`` to held commands ``u``.

    Parameters
    ----------
    a, b, c, d : arrays (n, n), (n, m), (p, n), (p, m)
        Continuous model.
    u : array (N, m)
        Commands, one per sample [input units].
    delay_s : float
        Measured delay of the path (ZOH half sample included) [s].
    ts_s : float

    Returns
    -------
    array (N, p)
    """
    m = b.shape[1]
    hold_delay = max(delay_s / ts_s - 0.5, 0.0)
    plant = zoh_with_delays(a, b, c, ts_s=ts_s, input_delay_samples=[hold_delay] * m,
                            input_names=[f"u{i}" for i in range(m)],
                            output_names=[f"y{i}" for i in range(c.shape[0])])
    p = c.shape[0]
    ideal = Quantiser(range_v=1.0, bits=0)
    res = run_loop(plant, u_ext=np.ascontiguousarray(u, dtype=float),
                   adc_noise=np.zeros((u.shape[0], p)), adc=ideal, dac=ideal, n_adc=p)
    shift = round(delay_s / ts_s)
    u_delayed = np.zeros_like(u)
    u_delayed[shift:] = u[: u.shape[0] - shift]
    return np.asarray(res.adc) + u_delayed @ np.asarray(d, dtype=float).T


def validate_sercalo(recordings: Mapping[str, xr.Dataset], *, sercalo: SercaloIdentification,
                     trims_s: Mapping[str, float], settle_s: float = 2.0
                     ) -> tuple[PathValidation, ...]:
    """VAF of the fitted ``Uc → Vp`` model on ``data_uch`` and ``data_ucv``."""
    sys = sercalo.fit.to_statespace()
    a, b, c, d = (np.asarray(x, dtype=float) for x in (sys.A, sys.B, sys.C, sys.D))
    out = []
    for j, (experiment, signal) in enumerate((("data_uch", "Uch"), ("data_ucv", "Ucv"))):
        ds = trim_recording(recordings[experiment], t0_s=trims_s.get(experiment, 0.0))
        fs = float(ds.attrs["fs_hz"])
        u = np.asarray(ds[signal].values, dtype=float)
        u = u - u.mean()
        y_hat = simulate_fit(a, b[:, [j]], c, d[:, [j]], u=u[:, None], delay_s=sercalo.delay_s,
                             ts_s=1.0 / fs)
        start = round(settle_s * fs)
        for i, name in enumerate(sercalo.frf.output_names):
            y = np.asarray(ds[name].values, dtype=float)
            y = y - y.mean()
            yy, yh = y[start:], y_hat[start:, i] - y_hat[start:, i].mean()
            out.append(PathValidation(
                experiment=experiment, input=signal, output=name,
                vaf=variance_accounted_for(yy, yh),
                residual_rms_v=float(np.std(yy - yh)), output_rms_v=float(np.std(yy)),
                settle_s=float(settle_s)))
    return tuple(out)
