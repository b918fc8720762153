"""One bench's physical parameters: :class:`IndBench`.

Frames and signs (indsim's own, stated once here and used everywhere)
--------------------------------------------------------------------
* **Lab beam frame** at the 4QD: ``z`` along the beam towards the diode, ``x``
  horizontal, ``y`` vertical, right-handed. Its sense is *defined by the
  Newport*: a positive Newport command tilts the Newport mirror by a positive
  angle ``psi`` and the beam by ``+newport_beam_factor * psi`` along ``+x``
  (``Unh``) or ``+y`` (``Unv``). The beam angles ``b = (b_x, b_y)`` [rad] are
  the beam's deflections in this frame.
* **Sercalo mirror frame**: hinge axes ``a`` (driven by the horizontal coil)
  and ``b`` (vertical coil); a positive coil current turns the mirror by a
  positive angle ``phi_a`` / ``phi_b`` [rad] about its axis. The mirror is seen
  ``sercalo_beam_factor`` times by the beam (four reflections); how it is
  mounted decides the sense: ``b_x = mount_h * 4 * phi_a``,
  ``b_y = mount_v * 4 * phi_b`` (``mount = +1`` or ``-1``).
* **4QD frame**: the diode's axes ``(u, w)`` are the lab's ``(x, y)`` turned by
  ``qd_rotation_rad`` (counter-clockwise looking along ``-z``, towards the
  source): ``d_u = cos θ b_x + sin θ b_y``, ``d_w = -sin θ b_x + cos θ b_y``.
  Output ``Vph = qd_polarity_h * g_h * d_u`` and ``Vpv = qd_polarity_v * g_v * d_w``
  (``g`` the gain magnitude [V/rad]); ``Vph`` is the diode's ``u`` channel.
* Voltages are the recorded ones (``Uch`` … ``Vnv``); the coil-voltage monitor
  ``Vc`` reads ``+vc_gain`` times the voltage across the coil, the Newport's
  metrology reads ``+psi / newport_metrology_rad_per_v``.

Per-axis values are :class:`HV` pairs (h: horizontal axis ``a``/``x``/``u``,
v: vertical ``b``/``y``/``w``).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields
from typing import Any

__all__ = ["HV", "IndBench"]


@dataclass(frozen=True)
class HV:
    """A horizontal / vertical pair of one quantity (unit: the field's)."""

    h: float
    v: float

    def __iter__(self):
        return iter((self.h, self.v))

    def scaled(self, fh: float, fv: float | None = None) -> HV:
        """The pair times ``fh`` (h) and ``fv`` (v, default ``fh``)."""
        return HV(self.h * fh, self.v * (fh if fv is None else fv))


@dataclass(frozen=True)
class IndBench:
    """Every physical parameter of one simulated bench (SI units in the names).

    Defaults are the "plain" bench: the values of the user's bench file
    (``default_bench.toml``, its ``[nominal]`` section) in indsim's frames.
    """

    name: str = "plain"
    description: str = "close to the bench file's nominal values, same signs"
    # --- converters (real-time target) ---------------------------------------
    fs_hz: float = 10000.0
    converter_bits: int = 16
    converter_span_v: float = 20.0  # ±10 V
    dac_transport_samples: int = 1  # the command computed at sample k leaves at k+1
    dac_latency_s: float = 0.0  # computation time after the clock edge (fraction of a sample)
    # --- Sercalo: first modes ------------------------------------------------
    sercalo_resonance_hz: HV = HV(411.13, 252.5)
    sercalo_damping_ratio: HV = HV(0.0009141096903985803, 0.0008222735566507275)
    sercalo_gain_rad_per_a: HV = HV(0.6145525535191302, 0.4958321738620254)
    sercalo_mount_sign: HV = HV(-1.0, 1.0)
    sercalo_beam_factor: float = 4.0
    sercalo_mode_angle_rad: HV = HV(0.0, 0.0)  # mode shapes turned in the mirror plane
    sercalo_torque_crosstalk: HV = HV(0.0, 0.0)  # coil h's torque about b; coil v's about a
    # --- Sercalo: second (flexural) modes, 0 Hz = absent -----------------------
    sercalo_second_mode_hz: HV = HV(0.0, 0.0)
    sercalo_second_mode_damping_ratio: HV = HV(0.01, 0.01)
    sercalo_second_mode_relative_gain: HV = HV(0.0, 0.0)
    sercalo_second_mode_angle_rad: HV = HV(0.0, 0.0)
    back_emf_v_s_per_rad: HV = HV(0.0, 0.0)
    # --- coil and current amplifier ---------------------------------------------
    r_coil_ohm: HV = HV(9.3, 8.3)
    l_coil_h: HV = HV(1.0e-4, 1.0e-4)
    r_amp_ohm: HV = HV(41.0, 41.0)
    r_series_ohm: HV = HV(0.0, 0.0)  # unmodelled buffer output resistance
    # --- coil-voltage monitor (voltage amplifier) -------------------------------
    vc_gain: float = 1000.0
    vc_cutoff_hz: float = 1000.0
    vc_noise_rms_v: float = 1.0e-3
    # --- Newport FSM-300 ------------------------------------------------------------
    newport_gain_rad_per_v: HV = HV(2.62e-3, 2.62e-3)
    newport_natural_freq_hz: HV = HV(1076.706455916, 1076.706455916)
    newport_damping_ratio: HV = HV(1.106173492, 1.106173492)
    newport_internal_delay_s: float = 3.5e-4
    newport_beam_factor: float = 2.0
    newport_metrology_rad_per_v: float = 2.62e-3
    newport_angle_noise_rms_rad: float = 3.0e-6
    newport_metrology_noise_rms_rad: float = 0.5e-6
    # --- 4-quadrant diode ---------------------------------------------------------
    qd_gain_v_per_rad: HV = HV(31.0, 36.3)  # magnitudes
    qd_polarity: HV = HV(-1.0, 1.0)
    qd_rotation_rad: float = 0.0
    qd_amp_order: int = 0  # 0: no amplifier lag, 1 or 2: low-pass of that order
    qd_amp_bandwidth_hz: float = 10000.0
    qd_amp_damping_ratio: float = 0.7071067811865476  # second order only (Butterworth)
    qd_noise_rms_v: HV = HV(1.0e-3, 1.0e-3)  # white, per sample
    qd_flicker_asd_v_per_rthz: HV = HV(0.0, 0.0)  # 1/f noise ASD at 1 Hz
    qd_flicker_min_hz: float = 1.0e-3
    qd_offset_v: HV = HV(0.0, 0.0)
    qd_compression: float = 0.0  # fraction short of linear at qd_compression_swing_rad
    qd_compression_swing_rad: float = 0.0106
    # --- Attocube Va and its environment ----------------------------------------
    va_noise_rms_m: float = 0.5e-9
    va_resolution_m: float = 1.0e-12
    va_geometric_m_per_rad2: float = 0.05  # L/2 with L = 0.1 m (ESRF study 11.3)
    sercalo_spot_offset_m: float = 1.0e-4
    newport_spot_offset_m: float = 2.0e-4
    beam_path_m: float = 0.1
    frame_length_m: float = 0.05
    frame_expansion_per_k: float = 23.0e-6
    frame_time_constant_s: float = 900.0
    air_index_per_k: float = -0.93e-6
    air_index_per_pa: float = 2.7e-9
    air_index_per_pct: float = -1.0e-8
    room_temperature_rms_k: float = 0.05
    room_temperature_tau_s: float = 600.0
    room_pressure_rms_pa: float = 20.0
    room_pressure_tau_s: float = 600.0
    room_humidity_rms_pct: float = 1.0
    room_humidity_tau_s: float = 900.0
    beam_path_temperature_rms_k: float = 0.005
    beam_path_temperature_tau_s: float = 1.0
    shielding_attenuation: float = 5.0
    ecu_temperature_error_k: float = 0.005
    ecu_pressure_error_pa: float = 5.0
    ecu_humidity_error_pct: float = 0.2
    ecu_error_tau_s: float = 30.0

    def __post_init__(self) -> None:
        nyquist = self.fs_hz / 2.0
        for name in ("sercalo_mount_sign", "qd_polarity"):
            if any(abs(abs(s) - 1.0) > 0 for s in getattr(self, name)):
                raise ValueError(f"{name} must be +1 or -1 per axis")
        if self.qd_amp_order not in (0, 1, 2):
            raise ValueError("qd_amp_order must be 0, 1 or 2")
        if self.dac_transport_samples < 1:
            raise ValueError("the real-time target writes the DAC one sample later at least")
        if not 0.0 <= self.dac_latency_s < 1.0 / self.fs_hz:
            raise ValueError("dac_latency_s must be within one sample")
        for f in (*self.sercalo_resonance_hz, *self.newport_natural_freq_hz):
            if not 0.0 < f < nyquist:
                raise ValueError(f"mode at {f} Hz is not below the Nyquist frequency")
        for f in self.sercalo_second_mode_hz:
            if f and not max(self.sercalo_resonance_hz) < f < nyquist:
                raise ValueError(f"second mode at {f} Hz outside (first modes, Nyquist)")
        for z in (*self.sercalo_damping_ratio, *self.newport_damping_ratio):
            if not 0.0 < z < 5.0:
                raise ValueError("damping ratios must be positive and below 5")
        if abs(self.qd_amp_damping_ratio - 1.0) < 1e-3 and self.qd_amp_order == 2:
            raise ValueError("a critically damped amplifier has a defective pole pair")
        for v in (*self.sercalo_gain_rad_per_a, *self.qd_gain_v_per_rad,
                  *self.newport_gain_rad_per_v, *self.r_coil_ohm, *self.l_coil_h,
                  *self.r_amp_ohm):
            if not v > 0.0:
                raise ValueError("gains, resistances and inductances are positive magnitudes")
        if not 0.0 <= self.qd_compression < 0.2:
            raise ValueError("qd_compression is a mild cubic: 0 to 20 % at the swing")

    @property
    def dt_s(self) -> float:
        """Sample period [s]."""
        return 1.0 / self.fs_hz

    @property
    def lsb_v(self) -> float:
        """Converter step [V]."""
        return self.converter_span_v / 2.0**self.converter_bits

    @property
    def r_total_ohm(self) -> HV:
        """Resistance of each coil circuit, amplifier + series + coil [Ω]."""
        return HV(*(a + s + c for a, s, c in zip(self.r_amp_ohm, self.r_series_ohm,
                                                  self.r_coil_ohm, strict=True)))

    @property
    def current_amp_gain_a_per_v(self) -> HV:
        """Static current-amplifier gain ``1 / (R + R_series + R_coil)`` [A/V]."""
        return HV(*(1.0 / r for r in self.r_total_ohm))

    @property
    def qd_cubic_per_rad2(self) -> float:
        """Cubic coefficient ``c`` of ``d -> d (1 - c d²)`` [1/rad²]."""
        return self.qd_compression / self.qd_compression_swing_rad**2

    @property
    def qd_amp_group_delay_s(self) -> float:
        """Group delay of the 4QD amplifier at low frequency [s] (0 without one)."""
        w = 2.0 * math.pi * self.qd_amp_bandwidth_hz
        return {0: 0.0, 1: 1.0 / w, 2: 2.0 * self.qd_amp_damping_ratio / w}[self.qd_amp_order]

    def as_dict(self) -> dict[str, Any]:
        """Every parameter, pairs as ``{"h": …, "v": …}`` (JSON-ready)."""
        return {f.name: asdict(v) if isinstance(v := getattr(self, f.name), HV) else v
                for f in fields(self)}
