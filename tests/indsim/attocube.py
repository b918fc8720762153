"""The Attocube's distance ``Va`` [m]: noise, air, frame, geometry, perpendicular motion.

Parts (ESRF study section 4), each referred to the record's first sample so
that ``Va`` reads a displacement since the interferometer was zeroed:

* **noise**: white, ``va_noise_rms_m``; the output is on a ``va_resolution_m`` grid.
* **air**: the beam path ``beam_path_m`` times the air's index change
  ``K_T ΔT + K_P ΔP + K_H ΔH`` (4.3). The room's slow temperature, pressure and
  humidity (OU processes) are seen whole without the compensation unit and
  only through its sensors' slow errors with it; the beam path's own fast
  temperature fluctuation (1 s) is divided by ``shielding_attenuation`` under
  the aluminium (test 4, 5) and is never compensated.
* **frame**: ``frame_length_m`` × expansion × the frame's temperature, the
  room's through a ``frame_time_constant_s`` lag (4.4).
* **geometric**: ``va_geometric_m_per_rad2`` × |beam angle|² (4.1, 11.3).
* **perpendicular**: the spots' offsets from the hinge axes times the
  mirrors' angles (4.2): ``e_s (phi_a + phi_b) + e_n (psi_a + psi_b)``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from .bench import IndBench
from .noise import first_order, ou, quantise, slow_ou

__all__ = ["attocube"]

Array = NDArray[np.float64]


def attocube(bench: IndBench, rng: np.random.Generator, t_s: Array, beam_rad: Array,
             phi_rad: Array, psi_rad: Array, compensation_unit: bool,
             shielding: bool) -> tuple[Array, dict[str, Array]]:
    """Return ``Va`` [m] on its resolution grid and its parts [m].

    Parameters
    ----------
    bench : IndBench
        The bench.
    rng : numpy.random.Generator
        Noise source.
    t_s : ndarray, shape (N,)
        Sample times [s], uniform.
    beam_rad, phi_rad, psi_rad : ndarray, shape (N, 2)
        Beam angles (lab), Sercalo and Newport mirror angles [rad].
    compensation_unit, shielding : bool
        The huddle test's configuration (study Table 3).
    """
    b = bench
    n = len(t_s)
    dt = b.dt_s
    # Room temperature and the frame's lagged copy on a 10 Hz grid, warmed up
    # over five frame time constants so the frame starts in its stationary state.
    step = 0.1
    tc = np.arange(-5.0 * b.frame_time_constant_s, float(t_s[-1]) + 2 * step, step)
    room_c = ou(rng, len(tc), step, b.room_temperature_rms_k, b.room_temperature_tau_s)
    frame_c = first_order(room_c, step, b.frame_time_constant_s, room_c[0])
    room_t, frame_t = np.interp(t_s, tc, room_c), np.interp(t_s, tc, frame_c)
    room_p = slow_ou(rng, t_s, b.room_pressure_rms_pa, b.room_pressure_tau_s)
    room_h = slow_ou(rng, t_s, b.room_humidity_rms_pct, b.room_humidity_tau_s)
    beam_t = ou(rng, n, dt, b.beam_path_temperature_rms_k, b.beam_path_temperature_tau_s)
    if shielding:
        beam_t = beam_t / b.shielding_attenuation
    if compensation_unit:
        dT = slow_ou(rng, t_s, b.ecu_temperature_error_k, b.ecu_error_tau_s)
        dP = slow_ou(rng, t_s, b.ecu_pressure_error_pa, b.ecu_error_tau_s)
        dH = slow_ou(rng, t_s, b.ecu_humidity_error_pct, b.ecu_error_tau_s)
    else:
        dT, dP, dH = room_t, room_p, room_h
    index = (b.air_index_per_k * (dT + beam_t) + b.air_index_per_pa * dP
             + b.air_index_per_pct * dH)
    parts = {
        "noise": rng.standard_normal(n) * b.va_noise_rms_m,
        "air": b.beam_path_m * (index - index[0]),
        "frame": b.frame_length_m * b.frame_expansion_per_k * (frame_t - frame_t[0]),
        "geometric": b.va_geometric_m_per_rad2 * np.sum(beam_rad**2, axis=1),
        "perpendicular": (b.sercalo_spot_offset_m * phi_rad.sum(axis=1)
                          + b.newport_spot_offset_m * psi_rad.sum(axis=1)),
    }
    total = sum(parts.values())
    return quantise(total, b.va_resolution_m), parts
