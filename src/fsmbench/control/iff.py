"""Active damping by integral force feedback (ESRF study section 8).

The ESRF study closes ``Kppf = blkdiag(-10000/s, 0)`` from the amplified coil
voltages ``Vch, Vcv`` to the commands ``Uch, Ucv`` with MATLAB's ``connect``,
which adds the controller output to the command: ``Uc = Uc_ext + Kppf Vc``,
i.e. ``u = -K y`` with ``K = -Kppf``.

:func:`iff_analysis` reports, for each Sercalo mode, the damping ratio before
and after from the closed-loop poles (delays as Padé approximants), the IFF
loop's own stability (poles, and a Nyquist count with exact delays), the
largest stable gain, and how much of the mode the sensor sees at all: in the
ESRF study's block diagram ``Vc = Ga Zc Gi Uc`` with a static ``Zc = Rc`` ("Important
2"), so the mirror's motion never reaches ``Vc``, the modes are unobservable
from it and IFF cannot move them. That is the ESRF study's conclusion of 8.3
("Active damping does not seem to be applicable here") derived from the model.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import Any

import control as ct
import numpy as np

from fsmbench.bench.blocks import PlantModel
from fsmbench.bench.esrf import iff_controller
from fsmbench.control.freq import (
    NyquistCount,
    evaluate_ss,
    loop_response,
    nyquist_count,
    plain_json,
    plant_response,
)
from fsmbench.control.loops import AXES, closed_loop_poles

__all__ = ["IffAnalysis", "ModeDamping", "iff_analysis", "lightly_damped_modes"]


@dataclass(frozen=True)
class ModeDamping:
    """One Sercalo mode with and without IFF.

    Attributes
    ----------
    axis : str
        ``"h"`` or ``"v"``: the mode with the highest resonance peak in ``Uc_i -> R_i``.
    frequency_hz_open, damping_ratio_open : float
        Open-loop natural frequency [Hz] and damping ratio [1].
    frequency_hz_closed, damping_ratio_closed : float
        Nearest closed-loop pole with the plant's delays (Padé) [Hz], [1].
    damping_ratio_closed_without_delay : float
        Same without the input delays (the ESRF study's delay-free model).
    sensor_peak_ratio : float
        ``|r| / (|Re λ| |Vc_i/Uc_i(0)|)``: height of the mode's resonance in
        the IFF sensor's path relative to that path's static gain [1] (for the
        beam path it is about ``1/(2ξ)``). Zero: the sensor does not see the mode.
    """

    axis: str
    frequency_hz_open: float
    damping_ratio_open: float
    frequency_hz_closed: float
    damping_ratio_closed: float
    damping_ratio_closed_without_delay: float
    sensor_peak_ratio: float

    def to_json(self) -> dict[str, Any]:
        """Plain floats."""
        return plain_json(self.__dict__)


@dataclass(frozen=True, eq=False)
class IffAnalysis:
    """IFF closed around a plant.

    Attributes
    ----------
    controller : control.StateSpace
        ``Kppf``, inputs ``Vch, Vcv``, outputs ``Uch, Ucv``, added to the commands.
    modes : dict axis -> ModeDamping
    loop_stable : bool
        Closed-loop poles with Padé delays all in the left half-plane.
    loop_stable_without_delay : bool
    nyquist : NyquistCount
        Exact-delay count for the IFF loop.
    gain_limit : dict axis -> float
        ``|g| / |L(f_180)|`` at the first negative-real-axis crossing of each
        active channel's loop: the gain of ``-g/s`` at which it loses stability
        [1/s] (NaN for an inactive channel).
    f_hz : array, shape (n,)
    open_loop, closed_loop : arrays, complex, shape (n, 2, 2)
        ``Uch, Ucv -> Vph, Vpv`` without and with IFF (the ESRF study's Bode plot of 8.2).
    """

    controller: ct.StateSpace
    modes: Mapping[str, ModeDamping]
    loop_stable: bool
    loop_stable_without_delay: bool
    nyquist: NyquistCount
    gain_limit: Mapping[str, float]
    f_hz: np.ndarray = field(repr=False)
    open_loop: np.ndarray = field(repr=False)
    closed_loop: np.ndarray = field(repr=False)

    def to_json(self) -> dict[str, Any]:
        """``{h,v}.{damping_ratio_open, damping_ratio_closed, ...}`` and the loop's stability."""
        return plain_json({**{a: m.to_json() for a, m in self.modes.items()},
                           "loop_stable": self.loop_stable,
                           "loop_stable_without_delay": self.loop_stable_without_delay,
                           "nyquist": self.nyquist.to_json(),
                           "gain_limit_per_s": dict(self.gain_limit)})


def lightly_damped_modes(sys: ct.StateSpace, *, damping_max: float = 0.05
                         ) -> list[tuple[complex, np.ndarray]]:
    """Poles ``λ`` (Im > 0) with damping below ``damping_max`` and their residues ``C v w^H B``."""
    a, b, c = (np.asarray(x, dtype=float) for x in (sys.A, sys.B, sys.C))
    lam, v = np.linalg.eig(a)
    w = np.linalg.inv(v)  # rows: left eigenvectors with w v = I
    out = []
    for i, li in enumerate(lam):
        if li.imag > 0 and -li.real / abs(li) < damping_max:
            out.append((complex(li), np.outer(c @ v[:, i], w[i] @ b)))
    return out


def _damping(p: complex) -> float:
    return float(-p.real / abs(p))


def iff_analysis(plant: PlantModel, *, controller: ct.StateSpace | None = None,
                 pade_order: int = 6, f_hz: np.ndarray | None = None) -> IffAnalysis:
    """Damping of the Sercalo modes with IFF (ESRF study 8.2).

    Parameters
    ----------
    plant : PlantModel
    controller : control.StateSpace, optional
        ``Vch, Vcv -> Uch, Ucv``, added to the commands; default the ESRF study's ``Kppf``.
    pade_order : int
        Padé order of the delays for the closed-loop poles.
    f_hz : array, optional
        Frequencies of the Bode data [Hz]; default 10 Hz–5 kHz.
    """
    kppf = iff_controller() if controller is None else controller
    k = ct.ss(kppf.A, kppf.B, -np.asarray(kppf.C), -np.asarray(kppf.D),
              inputs=list(kppf.input_labels), outputs=list(kppf.output_labels))
    cmds, meas = list(k.output_labels), list(k.input_labels)
    poles = closed_loop_poles(plant, k, pade_order=pade_order)
    no_delay = replace(plant, input_delay_s={n: 0.0 for n in plant.input_delay_s})
    poles_nd = closed_loop_poles(no_delay, k, pade_order=pade_order)
    beam = plant.subsystem(outputs=["Rh", "Rv"], inputs=cmds)
    sensor = plant.subsystem(outputs=meas, inputs=cmds)
    v0 = np.real(evaluate_ss(sensor, np.zeros(1))[0])
    sensor_modes = lightly_damped_modes(sensor, damping_max=1.0)
    modes: dict[str, ModeDamping] = {}
    candidates = lightly_damped_modes(beam)
    for i, axis in enumerate(AXES):
        if not candidates:
            break
        # The axis' mode: the highest resonance peak |r_ii| / |Re λ| in its own path.
        peaks = [abs(r[i, i]) / abs(pole.real) for pole, r in candidates]
        lam = candidates[int(np.argmax(peaks))][0]
        near = poles[np.argmin(np.abs(poles - lam))]
        near_nd = poles_nd[np.argmin(np.abs(poles_nd - lam))]
        # Same A for both paths, hence the same eigenvalues: match by distance.
        rs = (sensor_modes[int(np.argmin([abs(m[0] - lam) for m in sensor_modes]))][1]
              if sensor_modes else None)
        ratio = 0.0 if rs is None else float(
            abs(rs[i, i]) / (abs(lam.real) * max(abs(v0[i, i]), 1e-300)))
        modes[axis] = ModeDamping(axis=axis, frequency_hz_open=abs(lam) / (2 * np.pi),
                                  damping_ratio_open=_damping(lam),
                                  frequency_hz_closed=abs(near) / (2 * np.pi),
                                  damping_ratio_closed=_damping(near),
                                  damping_ratio_closed_without_delay=_damping(near_nd),
                                  sensor_peak_ratio=ratio)
    nyq = nyquist_count(lambda s: np.linalg.det(np.eye(2)[None] + loop_response(plant, k, s)),
                        open_loop_poles=np.concatenate([sensor.poles(), k.poles()]))
    f = np.logspace(1, np.log10(5e3), 600) if f_hz is None else np.asarray(f_hz, dtype=float)
    s = 2j * np.pi * f
    g_vp = plant_response(plant, s, outputs=["Vph", "Vpv"], inputs=cmds)
    # Uc = Uc_ext - K Vc  =>  Uc = (I + K G_vc)^-1 Uc_ext
    g_vc = plant_response(plant, s, outputs=meas, inputs=cmds)
    kk = evaluate_ss(k, s)
    closed = g_vp @ np.linalg.inv(np.eye(2)[None] + kk @ g_vc)
    return IffAnalysis(controller=kppf, modes=modes, loop_stable=bool(np.max(poles.real) < 0),
                       loop_stable_without_delay=bool(np.max(poles_nd.real) < 0), nyquist=nyq,
                       gain_limit=_gain_limits(plant, k), f_hz=f, open_loop=g_vp,
                       closed_loop=closed)


def _gain_limits(plant: PlantModel, k: ct.StateSpace) -> dict[str, float]:
    """Per active channel: the integral gain at the first -180° crossing of its loop."""
    out: dict[str, float] = {}
    f = np.logspace(0, 7, 7001)
    s = 2j * np.pi * f
    kk = evaluate_ss(k, s)
    g = plant_response(plant, s, outputs=list(k.input_labels), inputs=list(k.output_labels))
    for i in range(2):
        ki = kk[:, i, i]
        if not np.any(ki):
            out[AXES[i]] = math.nan
            continue
        lv = g[:, i, i] * ki
        cross = np.nonzero((np.diff(np.sign(lv.imag)) != 0) & (lv.real[:-1] < 0))[0]
        gain_now = abs(complex(ki[0] * s[0]))  # |g| of -g/s
        out[AXES[i]] = (float(gain_now / abs(lv[cross[0]])) if cross.size else math.inf)
    return out
