"""A controller proven on a simulated bench: the repeatability experiment in closed loop,
measured on the simulated records, against the linear prediction from the model and the
noise model.

The bench simulated is the one :func:`verify_on_twin` is given: the packaged
twin (the truth of twin data) or a bench identified from the user's recordings
(:func:`fsmbench.twin.identified.identified_bench`); its label travels with the result.

Simulated ("measured" on the simulated records)
    The bench runs ``data_rep_h`` and ``data_rep_v`` (1 V, 1 Hz Newport sine
    from 1 s) at its converter rate with the controller executed every sample,
    its converters' quantisation and every noise source. The tracking error is
    what the 4QD reports, ``e = [Vph, Vpv] / Gd`` (the gains the real-time code
    divides by: the design plant's), after ``settle_s``; its rms per axis is
    taken in the experiment that moves that axis.

Predicted
    With ``G = ∂R/∂Uc`` and ``Gn = ∂R/∂Un`` from a plant model (exact delays)
    and the discrete controller ``K`` closed as ``Uc = −K R_meas``, each noise
    of the bench's noise model (:func:`fsmbench.control.validation.tracking_error_spectra`:
    the 4QD's white, 1/f, random-walk noise and mains lines, the Newport's angle
    noise, ADC and DAC quantisation as white ``q²/12``) is integrated over
    ``1/duration`` to ``fs/2``; the Newport's sine contributes its rms through ``S Gn``.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict, dataclass
from typing import Any

import control as ct
import numpy as np

from fsmbench.bench.blocks import PlantModel
from fsmbench.bench.esrf import tustin
from fsmbench.bench.params import Bench, PerAxis
from fsmbench.budget.propagation import loop_response
from fsmbench.control.validation import tracking_error_spectra
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
    bench : str
        The bench simulated, in words.
    bench_kind : {"packaged", "identified"}
    """

    measured_rms_rad: dict[str, float]
    predicted_rms_rad: dict[str, float]
    predicted_parts_rad: dict[str, dict[str, float]]
    ratio: dict[str, float]
    controller: str
    seed: int
    duration_s: float
    settle_s: float
    bench: str = ""
    bench_kind: str = "packaged"

    def to_json(self) -> dict[str, Any]:
        """Plain values (SI units)."""
        return asdict(self)


def predict_tracking(plant: PlantModel, k: ct.StateSpace, *, bench: Bench,
                     gd_used_v_per_rad: tuple[float, float] | None = None,
                     n_freq: int = 20000, f_min_hz: float | None = None
                     ) -> tuple[dict[str, float], dict[str, dict[str, float]]]:
    """Linear prediction of the 4QD tracking-error rms per axis [rad] (see module notes).

    Parameters
    ----------
    plant : PlantModel
        The model predicted with (identified or physical).
    k : control.StateSpace
        Controller ``Rh, Rv → Uch, Ucv``: continuous (Tustin-discretised at the
        converter rate, as the target runs it) or discrete.
    bench : Bench
        Its ``true`` parameters give the noise model (the packaged twin's, or
        the one fitted to the recordings) and the converters.
    gd_used_v_per_rad : (float, float), optional
        4QD gains the real-time code divides by [V/rad]; default the plant's ``Gd``.
    n_freq : int
        Points of the linear frequency grid up to fs/2 (fine enough for the
        ~0.5 Hz-wide resonances the loop may leave).
    f_min_hz : float, optional
        Lowest frequency integrated [Hz] (the record's ``1/duration``); default fs/2/n_freq.
    """
    p = bench.true
    fs = p.converter.fs_hz
    kd = k if k.dt else tustin(k, ts_s=p.converter.ts_s)
    gd = np.diag(np.asarray(plant.blocks["Gd"].D, dtype=float))
    used = (float(gd[0]), float(gd[1])) if gd_used_v_per_rad is None else gd_used_v_per_rad
    lo = fs / 2 / n_freq if f_min_hz is None else f_min_hz
    f = np.linspace(lo, fs / 2, n_freq)
    spectra = tracking_error_spectra(plant, kd, params=p, gd_used_v_per_rad=used, f_hz=f)
    variance = spectra.band_variance((lo, fs / 2))
    loop = loop_response(plant, params=p, f_hz=np.array([REP_FREQ_HZ]),
                         controller=_effective(kd, gd, used))
    sn = (loop.s @ loop.g_rn)[0]
    total: dict[str, float] = {}
    out_parts: dict[str, dict[str, float]] = {}
    for i, (axis, _exp, _un, _vp) in enumerate(_AXES):
        terms = {name: float(np.sqrt(max(v[i], 0.0))) for name, v in variance.items()}
        terms["newport_sine"] = float(abs(sn[i, i]) * REP_AMPLITUDE_V / np.sqrt(2))
        out_parts[axis] = terms
        total[axis] = float(np.sqrt(sum(t**2 for t in terms.values())))
    return total, out_parts


def _effective(kd: ct.StateSpace, gd: np.ndarray, used: tuple[float, float]) -> ct.StateSpace:
    """The controller as it acts on the model's beam angle: ``K diag(Gd / gd_used)``."""
    scale = np.diag(gd / np.asarray(used, dtype=float))
    return ct.ss(kd.A, np.asarray(kd.B) @ scale, kd.C, np.asarray(kd.D) @ scale, kd.dt,
                 inputs=["Rh", "Rv"], outputs=["Uch", "Ucv"])


def measure_tracking(recordings: Mapping[str, Any], *, bench: Bench, settle_s: float,
                     gd_v_per_rad: tuple[float, float] | None = None) -> dict[str, float]:
    """4QD tracking-error rms per axis [rad] in the experiment that moves that axis.

    ``gd_v_per_rad``: the 4QD gains the reading is divided by (default the bench
    file's nominal ones, what the seed's real-time code used).
    """
    gd = (bench.nominal.quad_diode.gain_v_per_rad.as_array() if gd_v_per_rad is None
          else np.asarray(gd_v_per_rad, dtype=float))
    out = {}
    for i, (axis, exp, _un, vp) in enumerate(_AXES):
        ds = recordings[exp]
        t = np.asarray(ds["t"].values)
        e = np.asarray(ds[vp].values)[t >= t[0] + settle_s] / gd[i]
        out[axis] = float(np.sqrt(np.mean((e - e.mean()) ** 2)))
    return out


def verify_on_twin(k: ct.StateSpace, *, bench: Bench, plant: PlantModel, name: str,
                   seed: int = 0, duration_s: float = 12.0, settle_s: float = 2.0,
                   gd_v_per_rad: tuple[float, float] | None = None) -> TrackingCheck:
    """Run the repeatability experiments on ``bench`` with ``k`` and compare with the prediction.

    Parameters
    ----------
    k : control.StateSpace
        Continuous controller ``Rh, Rv → Uch, Ucv`` (Tustin-discretised at
        the converter rate, as the target runs it).
    bench : Bench
        The bench simulated: packaged (its physics) or identified (its model).
    plant : PlantModel
        Model for the prediction; its ``Gd`` are the gains the controller divides by.
    name : str
        Controller name for the report.
    seed : int
    duration_s, settle_s : float
        Record length and the start left out [s].
    gd_v_per_rad : (float, float), optional
        The 4QD gains the real-time code divides by [V/rad]; default the plant's
        ``Gd`` (what fsmbench's export gives the target, ``controllers_sos.json``).

    Raises
    ------
    ValueError
        The controller does not stabilise the bench (named, with the spectral radius).
    """
    p = bench.true
    gd = np.diag(np.asarray(plant.blocks["Gd"].D, dtype=float))
    used = (float(gd[0]), float(gd[1])) if gd_v_per_rad is None else (
        float(gd_v_per_rad[0]), float(gd_v_per_rad[1]))
    dk = feedback_controller(k, gd_v_per_rad=PerAxis(h=used[0], v=used[1]),
                             ts_s=p.converter.ts_s, name=name)
    run = simulate_bench(bench, seed=seed, duration_s=duration_s,
                         experiments=[exp for _a, exp, _u, _v in _AXES], controller=dk)
    measured = measure_tracking(run.recordings, bench=bench, settle_s=settle_s,
                                gd_v_per_rad=used)
    predicted, parts = predict_tracking(plant, k, bench=bench, gd_used_v_per_rad=used,
                                        f_min_hz=1.0 / (duration_s - settle_s))
    return TrackingCheck(measured_rms_rad=measured, predicted_rms_rad=predicted,
                         predicted_parts_rad=parts,
                         ratio={a: measured[a] / predicted[a] for a in measured},
                         controller=name, seed=seed, duration_s=duration_s, settle_s=settle_s,
                         bench=bench.label,
                         bench_kind="identified" if bench.is_identified else "packaged")
