"""What the Attocube measures: the distance signal ``Va`` and its error sources.

``Va`` [m] is the one-way distance the interferometer reports (half the
round-trip optical path change, ESRF study 4.2). The twin builds it from the
sources of the ESRF study's error budget (section 4):

geometric (4.1)
    the exact ray trace of :mod:`fsmbench.bench.geometry` for the Sercalo's
    angle error in each plane; the error is the beam angle in the table frame
    divided by the Sercalo's beam factor (4: two reflections);
perpendicular (4.2)
    each mirror's surface moves along its normal by its spot offset times its
    angle (a repeatable, angle-dependent piston);
air (4.3)
    refractive-index change along the measured distance, from room drift and
    local convection (reduced by the aluminium shield); with the compensation
    unit on, only the local part and the unit's sensor errors remain;
frame (4.4)
    thermal expansion of the metrology frame following the room temperature
    with the frame's time constant;
noise
    the interferometer's own white noise; the output is rounded to its resolution.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from fsmbench.bench.air import sensitivities
from fsmbench.bench.geometry import closed_form_path_error
from fsmbench.bench.params import BenchParams
from fsmbench.sim.noise import GaussMarkovStream, LagStream, WhiteStream

__all__ = [
    "AirSensitivity",
    "AttocubeStream",
    "VaComponents",
    "air_sensitivity",
    "attocube_distance",
]


@dataclass(frozen=True)
class AirSensitivity:
    """Refractive-index sensitivities at the bench's operating point.

    Attributes
    ----------
    dn_dt_per_k, dn_dp_per_pa, dn_drh_per_pct : float
        [1/K], [1/Pa], [1/%RH]
    """

    dn_dt_per_k: float
    dn_dp_per_pa: float
    dn_drh_per_pct: float


def air_sensitivity(p: BenchParams) -> AirSensitivity:
    """Sensitivities of the air index at the reference conditions and laser wavelength."""
    env = p.environment
    s = sensitivities(temperature_c=env.reference_temperature_c,
                      pressure_pa=env.reference_pressure_pa,
                      humidity_pct=env.reference_humidity_pct,
                      wavelength_m=p.attocube.wavelength_m)
    return AirSensitivity(dn_dt_per_k=float(s.dn_dt_per_k), dn_dp_per_pa=float(s.dn_dp_per_pa),
                          dn_drh_per_pct=float(s.dn_drh_per_pct))


@dataclass(frozen=True)
class VaComponents:
    """Each error source's contribution to ``Va`` [m], arrays of shape (n,)."""

    geometric_m: np.ndarray
    perpendicular_m: np.ndarray
    air_m: np.ndarray
    frame_m: np.ndarray
    noise_m: np.ndarray
    total_m: np.ndarray

    def std_m(self) -> dict[str, float]:
        """Standard deviation (rms about the mean) of each component [m]."""
        return {name: float(np.std(getattr(self, f"{name}_m")))
                for name in ("geometric", "perpendicular", "air", "frame", "noise", "total")}


class AttocubeStream:
    """``Va`` for one record, delivered block by block (state kept between blocks).

    Parameters
    ----------
    p : BenchParams
        The bench's true parameters.
    compensation_unit, shielding : bool
        Table 3 configuration.
    fs_hz : float
    rng_for : callable
        Returns the generator of a named noise source (called once per source, here).
    """

    def __init__(self, p: BenchParams, *, compensation_unit: bool, shielding: bool,
                 fs_hz: float, rng_for: Callable[[str], np.random.Generator]) -> None:
        env = p.environment
        self._p = p
        self._compensation_unit = compensation_unit
        self._shielding = shielding
        self._sens = air_sensitivity(p)

        def gm(source: str, rms: float, tau: float) -> GaussMarkovStream:
            return GaussMarkovStream(rng_for(source), rms=rms, tau_s=tau, fs_hz=fs_hz)

        # Created in the order the whole-record version drew them; each has its own
        # generator, so the order only matters for readability.
        self._room_t = gm("room_temperature", env.room_temperature_rms_k,
                          env.room_temperature_tau_s)
        self._room_p = gm("room_pressure", env.room_pressure_rms_pa, env.room_pressure_tau_s)
        self._room_h = gm("room_humidity", env.room_humidity_rms_pct, env.room_humidity_tau_s)
        self._local_t = gm("beam_path_temperature", env.beam_path_temperature_rms_k,
                           env.beam_path_temperature_tau_s)
        # The unit's sensor errors run whether or not the unit is on, so that
        # switching it (the live bench) continues every process where it was.
        self._ecu = (
            gm("ecu_temperature_error", env.ecu_temperature_error_k, env.ecu_error_tau_s),
            gm("ecu_pressure_error", env.ecu_pressure_error_pa, env.ecu_error_tau_s),
            gm("ecu_humidity_error", env.ecu_humidity_error_pct, env.ecu_error_tau_s))
        self._frame = LagStream(tau_s=env.frame_time_constant_s, fs_hz=fs_hz)
        self._noise = WhiteStream(rng_for("attocube"), rms=p.attocube.noise_rms_m)

    def set_environment(self, *, compensation_unit: bool, shielding: bool) -> None:
        """Switch the compensation unit and the shielding from the next sample on."""
        self._compensation_unit = compensation_unit
        self._shielding = shielding

    def next(self, *, theta_c_rad: np.ndarray, theta_n_rad: np.ndarray) -> VaComponents:
        """``Va`` and its parts for the next block.

        Parameters
        ----------
        theta_c_rad, theta_n_rad : arrays (n, 2)
            Sercalo and Newport mirror angles (h, v) [rad], Newport noise included.
        """
        p = self._p
        n = theta_c_rad.shape[0]
        env = p.environment
        geo = p.geometry

        b_c = p.sercalo.beam_angle_per_mirror_angle.as_array()
        beam_table = theta_c_rad * b_c + p.newport.beam_angle_per_mirror_angle * theta_n_rad
        sercalo_error = beam_table / np.abs(b_c)
        geometric = 0.5 * (closed_form_path_error(sercalo_error[:, 0], h_m=geo.h_m, l_m=geo.l_m)
                           + closed_form_path_error(sercalo_error[:, 1], h_m=geo.h_m,
                                                    l_m=geo.l_m))

        perpendicular = (geo.sercalo_spot_offset_m * theta_c_rad.sum(axis=1)
                         + geo.newport_spot_offset_m * theta_n_rad.sum(axis=1))

        room_t = self._room_t.next(n)
        room_p = self._room_p.next(n)
        room_h = self._room_h.next(n)
        local_t = self._local_t.next(n)
        if self._shielding:
            local_t = local_t / env.shielding_attenuation
        sens = self._sens
        err_t, err_p, err_h = (g.next(n) for g in self._ecu)
        if self._compensation_unit:
            # The unit corrects for what its sensors read (room air, with their
            # errors); the beam's local fluctuation is invisible to it.
            dn = (sens.dn_dt_per_k * (local_t - err_t) - sens.dn_dp_per_pa * err_p
                  - sens.dn_drh_per_pct * err_h)
        else:
            dn = (sens.dn_dt_per_k * (room_t + local_t) + sens.dn_dp_per_pa * room_p
                  + sens.dn_drh_per_pct * room_h)
        air = geo.measured_distance_m * dn

        frame_t = self._frame.next(room_t)
        frame = geo.frame_expansion_per_k * geo.frame_length_m * frame_t

        noise = self._noise.next(n)
        raw = geometric + perpendicular + air + frame + noise
        res = p.attocube.resolution_m
        total = np.round(raw / res) * res if res > 0 else raw
        return VaComponents(geometric_m=geometric, perpendicular_m=perpendicular, air_m=air,
                            frame_m=frame, noise_m=noise, total_m=total)


def attocube_distance(p: BenchParams, *, theta_c_rad: np.ndarray, theta_n_rad: np.ndarray,
                      compensation_unit: bool, shielding: bool, fs_hz: float,
                      rng_for: Callable[[str], np.random.Generator]) -> VaComponents:
    """``Va`` for a whole record: one block of :class:`AttocubeStream` (see there)."""
    stream = AttocubeStream(p, compensation_unit=compensation_unit, shielding=shielding,
                            fs_hz=fs_hz, rng_for=rng_for)
    return stream.next(theta_c_rad=theta_c_rad, theta_n_rad=theta_n_rad)
