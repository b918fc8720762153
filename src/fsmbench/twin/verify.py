"""A controller proven on the twin: the repeatability experiment in closed loop,
measured, against the linear prediction from the model and the noise budget.

Measured
    The twin runs ``data_rep_h`` and ``data_rep_v`` (1 V, 1 Hz Newport sine
    from 1 s) at 10 kHz with the controller executed every sample, 16-bit
    converters and every noise source. The tracking error is what the 4QD
    reports, ``e = [Vph, Vpv] / Gd`` (the calibrated gains), after
    ``settle_s``; its rms per axis is taken in the experiment that moves
    that axis.

Predicted
    With ``G = ∂R/∂Uc`` and ``Gn = ∂R/∂Un`` from a plant model (exact delays)
    and the controller ``K`` closed as ``Uc = −K R_meas``, the measured error
    is ``e = S (Gn Un + d) + S n_s`` with ``S = (I + G K)⁻¹``: the Newport's
    sine through ``S Gn``, the Newport angle noise ``d`` (beam angle, 2× the
    mirror's), the 4QD's noise and ADC quantisation ``n_s`` (volts over
    ``Gd``), and the DAC's quantisation entering through ``S G``. White
    sources have one-sided PSD ``σ²/(fs/2)``; each contributes
    ``∫ |transfer|² PSD df`` over 0–fs/2. The sine contributes its rms.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict, dataclass
from typing import Any

import control as ct
import numpy as np

from fsmbench.bench.blocks import PlantModel, ss_frequency_response
from fsmbench.bench.params import Bench
from fsmbench.sim.controller import feedback_controller
from fsmbench.twin.experiments import REP_AMPLITUDE_V, REP_FREQ_HZ
from fsmbench.twin.simulate import simulate_bench

__all__ = ["TrackingCheck", "measure_tracking", "predict_tracking", "verify_on_twin"]

_AXES = (("h", "data_rep_h", "Unh", "Vph"), ("v", "data_rep_v", "Unv", "Vpv"))


@dataclass(frozen=True)
class TrackingCheck:
    """Tracking-error rms per axis, measured on the twin and predicted [rad].

    Attributes
    ----------
    measured_rms_rad, predicted_rms_rad : dict axis -> float
    predicted_parts_rad : dict axis -> dict source -> float
        The prediction's terms (sine, Newport noise, 4QD noise, ADC, DAC).
    ratio : dict axis -> float
        Measured over predicted.
    controller : str
    seed : int
    duration_s, settle_s : float
    """

    measured_rms_rad: dict[str, float]
    predicted_rms_rad: dict[str, float]
    predicted_parts_rad: dict[str, dict[str, float]]
    ratio: dict[str, float]
    controller: str
    seed: int
    duration_s: float
    settle_s: float

    def to_json(self) -> dict[str, Any]:
        """Plain values (SI units)."""
        return asdict(self)


def _loop(plant: PlantModel, k: ct.StateSpace, f_hz: np.ndarray
          ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``S = (I + G K)^-1``, ``G = ∂R/∂Uc`` and ``Gn = ∂R/∂Un`` at ``f_hz``, each (F, 2, 2)."""
    g = plant.frequency_response(f_hz, outputs=["Rh", "Rv"], inputs=["Uch", "Ucv"]).values
    gn = plant.frequency_response(f_hz, outputs=["Rh", "Rv"], inputs=["Unh", "Unv"]).values
    s = np.linalg.inv(np.eye(2)[None] + g @ ss_frequency_response(k, f_hz))
    return s, g, gn


def predict_tracking(plant: PlantModel, k: ct.StateSpace, *, bench: Bench,
                     n_freq: int = 20000) -> tuple[dict[str, float], dict[str, dict[str, float]]]:
    """Linear prediction of the 4QD tracking-error rms per axis [rad] (see module notes).

    Parameters
    ----------
    plant : PlantModel
        The model predicted with (identified or physical).
    k : control.StateSpace
        Continuous controller ``Rh, Rv → Uch, Ucv``.
    bench : Bench
        Noise levels: the twin's 4QD noise and the Newport's angle noise from
        ``bench.true`` (the budget's sources), converters from ``bench.nominal``.
    n_freq : int
        Points of the frequency grid (linear, 0–fs/2; fine enough for the
        ~0.5 Hz-wide resonances the loop may leave).
    """
    p_true, p_nom = bench.true, bench.nominal
    fs = p_nom.converter.fs_hz
    f = np.linspace(fs / 2 / n_freq, fs / 2, n_freq)
    df = f[1] - f[0]
    s, g, _ = _loop(plant, k, f)
    gd = np.abs(p_nom.quad_diode.gain_v_per_rad.as_array())
    lsb = p_nom.converter.lsb_v
    white = 1.0 / (fs / 2)  # one-sided PSD of unit-variance white noise
    psd_qd = np.array([p_true.quad_diode.noise_rms_v.h, p_true.quad_diode.noise_rms_v.v])**2 \
        / gd**2 * white
    psd_adc = (lsb**2 / 12) / gd**2 * white
    psd_beam = (p_true.newport.beam_angle_per_mirror_angle
                * p_true.newport.angle_noise_rms_rad) ** 2 * white
    psd_dac = lsb**2 / 12 * white

    def integral(transfer: np.ndarray, psd: np.ndarray | float) -> np.ndarray:
        # transfer (F, 2, 2) from independent per-channel sources of PSD psd
        power = np.abs(transfer) ** 2 * np.broadcast_to(psd, (2,))[None, None, :]
        return np.asarray(np.sum(power.sum(axis=2), axis=0) * df)

    parts = {
        "qd_noise": integral(s, psd_qd),
        "adc_quantisation": integral(s, psd_adc),
        "newport_angle_noise": integral(s, psd_beam),
        "dac_quantisation": integral(s @ g, psd_dac),
    }
    s1, _, gn1 = (x[0] for x in _loop(plant, k, np.array([REP_FREQ_HZ])))
    total: dict[str, float] = {}
    out_parts: dict[str, dict[str, float]] = {}
    for i, (axis, _exp, _un, _vp) in enumerate(_AXES):
        sine = abs((s1 @ gn1)[i, i]) * REP_AMPLITUDE_V / np.sqrt(2)
        terms = {name: float(np.sqrt(v[i])) for name, v in parts.items()}
        terms["newport_sine"] = float(sine)
        out_parts[axis] = terms
        total[axis] = float(np.sqrt(sum(t**2 for t in terms.values())))
    return total, out_parts


def measure_tracking(recordings: Mapping[str, Any], *, bench: Bench,
                     settle_s: float) -> dict[str, float]:
    """4QD tracking-error rms per axis [rad] in the experiment that moves that axis."""
    gd = bench.nominal.quad_diode.gain_v_per_rad
    out = {}
    for axis, exp, _un, vp in _AXES:
        ds = recordings[exp]
        t = np.asarray(ds["t"].values)
        e = np.asarray(ds[vp].values)[t >= t[0] + settle_s] / gd[axis]
        out[axis] = float(np.sqrt(np.mean((e - e.mean()) ** 2)))
    return out


def verify_on_twin(k: ct.StateSpace, *, bench: Bench, plant: PlantModel, name: str,
                   seed: int = 0, duration_s: float = 12.0, settle_s: float = 2.0
                   ) -> TrackingCheck:
    """Run the repeatability experiments on the twin with ``k`` and compare with the prediction.

    Parameters
    ----------
    k : control.StateSpace
        Continuous controller ``Rh, Rv → Uch, Ucv`` (Tustin-discretised at
        the converter rate for the twin).
    bench : Bench
    plant : PlantModel
        Model for the prediction.
    name : str
        Controller name for the report.
    seed : int
    duration_s, settle_s : float
        Record length and the start left out [s].

    Raises
    ------
    ValueError
        The controller does not stabilise the twin (named, with the spectral radius).
    """
    p = bench.true
    dk = feedback_controller(k, gd_v_per_rad=bench.nominal.quad_diode.gain_v_per_rad,
                             ts_s=p.converter.ts_s, name=name)
    run = simulate_bench(bench, seed=seed, duration_s=duration_s,
                         experiments=[exp for _a, exp, _u, _v in _AXES], controller=dk)
    measured = measure_tracking(run.recordings, bench=bench, settle_s=settle_s)
    predicted, parts = predict_tracking(plant, k, bench=bench)
    return TrackingCheck(measured_rms_rad=measured, predicted_rms_rad=predicted,
                         predicted_parts_rad=parts,
                         ratio={a: measured[a] / predicted[a] for a in measured},
                         controller=name, seed=seed, duration_s=duration_s, settle_s=settle_s)
