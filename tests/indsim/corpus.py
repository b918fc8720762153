"""Named benches covering the variations fsmbench must diagnose.

Every bench is checked when its model is built (:func:`indsim.model.bench_model`):
physically consistent parameters (:class:`indsim.bench.IndBench`) and the
study's 9.2 loop stable on it (closed-loop poles inside the unit circle).
Gains are multiples of the bench file's nominal values: Sercalo 0.6146 / 0.4958
rad/A, current amplifier 1/(R + R_c) = 0.0199 / 0.0203 A/V, 4QD 31 / 36.3 V/rad,
Newport 2.62e-3 rad/V.
"""

from __future__ import annotations

from dataclasses import replace

from .bench import HV, IndBench

__all__ = ["corpus"]

_PLAIN = IndBench()


def _amp_for_gain(factor: float, base: IndBench = _PLAIN) -> HV:
    """Amplifier resistors giving ``factor`` times ``base``'s current gain [Ω]."""
    return HV(*((a + c) / factor - c for a, c in zip(base.r_amp_ohm, base.r_coil_ohm,
                                                      strict=True)))


def _seed_identified(**kw: object) -> IndBench:
    """The bench the study's identification points to (its Tables and 9.2 notches)."""
    return replace(
        _PLAIN,
        sercalo_resonance_hz=HV(411.5, 251.2), sercalo_damping_ratio=HV(1.2e-3, 1.0e-3),
        sercalo_gain_rad_per_a=HV(0.64, 0.476), r_series_ohm=HV(28.13, 23.06),
        newport_gain_rad_per_v=HV(2.65e-3, 2.59e-3), qd_gain_v_per_rad=HV(31.4, 35.9),
        qd_rotation_rad=0.015, sercalo_torque_crosstalk=HV(0.02, 0.015),
        newport_angle_noise_rms_rad=2.5e-6, qd_noise_rms_v=HV(0.9e-3, 1.1e-3), **kw)


def corpus() -> dict[str, IndBench]:
    """The named benches, ``name -> IndBench`` (at least one per variation)."""
    p = _PLAIN
    benches = [
        p,
        replace(p, name="sercalo_h_flipped",
                description="Sercalo mounted the other way on h: Ich -> Vph negative",
                sercalo_mount_sign=HV(1.0, 1.0)),
        replace(p, name="sercalo_v_flipped_qd_h_flipped",
                description="Sercalo v mounted the other way, 4QD h polarity reversed",
                sercalo_mount_sign=HV(-1.0, -1.0), qd_polarity=HV(1.0, 1.0)),
        replace(p, name="qd_v_flipped",
                description="4QD v polarity reversed: calibration and both v paths negative",
                qd_polarity=HV(-1.0, -1.0)),
        replace(p, name="all_flipped",
                description="every mount and polarity reversed: Sercalo paths as plain, "
                            "calibration and Newport signs opposite",
                sercalo_mount_sign=HV(1.0, -1.0), qd_polarity=HV(1.0, -1.0)),
        replace(p, name="hot",
                description="gains up: Sercalo x3, current amplifier x2.5, 4QD x5, Newport x2",
                sercalo_gain_rad_per_a=p.sercalo_gain_rad_per_a.scaled(3.0),
                r_amp_ohm=_amp_for_gain(2.5), qd_gain_v_per_rad=p.qd_gain_v_per_rad.scaled(5.0),
                newport_gain_rad_per_v=p.newport_gain_rad_per_v.scaled(2.0)),
        replace(p, name="weak",
                description="gains down: Sercalo x0.3, current amplifier x0.2, 4QD x0.2, "
                            "Newport x0.5; Sercalo h flipped",
                sercalo_gain_rad_per_a=p.sercalo_gain_rad_per_a.scaled(0.3),
                r_amp_ohm=_amp_for_gain(0.2), qd_gain_v_per_rad=p.qd_gain_v_per_rad.scaled(0.2),
                newport_gain_rad_per_v=p.newport_gain_rad_per_v.scaled(0.5),
                sercalo_mount_sign=HV(1.0, 1.0)),
        _seed_identified(name="seed_identified",
                         description="the study's identified bench: series resistance, "
                                     "4QD turned 15 mrad, torque crosstalk, shifted modes"),
        replace(p, name="qd_amp1_2k",
                description="4QD amplifier first order at 2 kHz; 4QD h polarity reversed",
                qd_amp_order=1, qd_amp_bandwidth_hz=2000.0, qd_polarity=HV(1.0, 1.0)),
        replace(p, name="qd_amp2_5k",
                description="4QD amplifier second order (Butterworth) at 5 kHz, 2 % cubic "
                            "compression, 1/f noise, offsets",
                qd_amp_order=2, qd_amp_bandwidth_hz=5000.0, qd_compression=0.02,
                qd_flicker_asd_v_per_rthz=HV(4.5e-5, 4.5e-5), qd_offset_v=HV(3e-3, -2e-3)),
        replace(p, name="newport_underdamped",
                description="Newport under-damped (zeta 0.4 at 450 Hz: 2.7 dB peaking), "
                            "internal delay 0.6 ms",
                newport_natural_freq_hz=HV(450.0, 470.0), newport_damping_ratio=HV(0.4, 0.42),
                newport_internal_delay_s=6.0e-4),
        replace(p, name="newport_overdamped",
                description="Newport over-damped (zeta 1.6 at 1.8 kHz), internal delay 0.2 ms",
                newport_natural_freq_hz=HV(1800.0, 1800.0), newport_damping_ratio=HV(1.6, 1.6),
                newport_internal_delay_s=2.0e-4),
        replace(p, name="delay_split",
                description="DAC written 35 us after the clock (0.35 sample), Newport "
                            "internal delay 0.12 ms",
                dac_latency_s=3.5e-5, newport_internal_delay_s=1.2e-4),
        replace(p, name="flexural",
                description="second (flexural) Sercalo modes at 1850 / 1420 Hz, 1 % gain",
                sercalo_second_mode_hz=HV(1850.0, 1420.0),
                sercalo_second_mode_relative_gain=HV(0.01, 0.01)),
        replace(p, name="rotated_modes",
                description="mode shapes turned 20 / -15 mrad (coupling at the resonances), "
                            "4QD turned 30 mrad",
                sercalo_mode_angle_rad=HV(0.02, -0.015), qd_rotation_rad=0.03),
        replace(p, name="back_emf",
                description="coil back-EMF (6e-5 / 8e-5 V s/rad): electrical damping "
                            "roughly doubles the modes' damping; Vc sees the motion",
                back_emf_v_s_per_rad=HV(6.0e-5, 8.0e-5)),
        replace(p, name="fs5k", description="target at 5 kHz", fs_hz=5000.0),
        replace(p, name="fs20k",
                description="target at 20 kHz, DAC 0.35 sample late, 4QD amplifier second "
                            "order at 10 kHz",
                fs_hz=20000.0, dac_latency_s=1.75e-5, qd_amp_order=2,
                qd_amp_bandwidth_hz=10000.0),
        _seed_identified(
            name="real_like",
            description="the identified bench with every real-bench feature: latency, "
                        "turned and second modes, 4QD amplifier, 1/f noise, compression",
            dac_latency_s=3.5e-5, sercalo_mode_angle_rad=HV(0.02, -0.015),
            sercalo_second_mode_hz=HV(1850.0, 1420.0),
            sercalo_second_mode_relative_gain=HV(0.01, 0.01),
            sercalo_second_mode_angle_rad=HV(0.05, -0.04), qd_amp_order=2,
            qd_amp_bandwidth_hz=10000.0, qd_flicker_asd_v_per_rthz=HV(4.5e-5, 4.5e-5),
            qd_compression=0.02),
    ]
    out = {b.name: b for b in benches}
    assert len(out) == len(benches), "bench names must be unique"
    return out
