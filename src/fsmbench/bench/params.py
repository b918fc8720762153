"""Bench parameters: every number of the Sercalo test bench, with its unit and source.

Three views of the bench are kept apart (see ``docs/model.md``):

``datasheet``
    Numbers as the vendors document them (ESRF study Table 1, Figure 4). They are
    not used by the model directly; ``docs/model.md`` derives the nominal
    model parameters from them.
``nominal``
    The model parameters an engineer would use before identifying anything:
    datasheet derivations, measured component values and the ESRF study's own
    identified values where the ESRF study gives them (Table 2).
``true``
    What the digital twin simulates. It differs from ``nominal`` where the
    real bench did (the ESRF study's section 2.2 finds a current-amplifier gain far
    from ``1/(R+Rc)``) and, on purpose, by a few per cent elsewhere, so that an
    identification that merely echoes the nominal values fails its tests.

Numbers live in ``default_bench.toml``; units, sources and descriptions live
in the field metadata below, so ``fsmbench params`` and :func:`save_bench`
can always print them.
"""

from __future__ import annotations

import dataclasses
import tomllib
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from fsmbench.atomic import atomic_write_text
from fsmbench.bench.axes import ParamsError, PerAxis
from fsmbench.bench.paramfile import (
    build,
    check_features,
    check_ranges,
    emit_toml,
    packaged_mapping,
    resolve_base,
)

if TYPE_CHECKING:
    from fsmbench.bench.identified import IdentifiedModel

__all__ = [
    "PACKAGED_BENCHES",
    "AttocubeParams",
    "Bench",
    "BenchParams",
    "ConverterParams",
    "CurrentAmplifierParams",
    "Datasheet",
    "EnvironmentParams",
    "GeometryParams",
    "NewportDatasheet",
    "NewportParams",
    "ParamRow",
    "ParamsError",
    "PerAxis",
    "QuadDiodeParams",
    "ScalingParams",
    "SercaloDatasheet",
    "SercaloParams",
    "VoltageAmplifierParams",
    "default_bench",
    "load_bench",
    "param_rows",
    "real_bench",
    "save_bench",
    "walk_fields",
]


def _p(unit: str, source: str, doc: str, default: Any = dataclasses.MISSING) -> Any:
    """A parameter field: its unit, the ESRF study section it comes from and what it is.

    A ``default`` makes the key optional in a bench file: the real-bench
    features (docs/model.md) default to "off", so older files keep their meaning.
    """
    return field(default=default, metadata={"unit": unit, "source": source, "doc": doc})


_OFF = PerAxis(h=0.0, v=0.0)


# --------------------------------------------------------------------------- datasheets


@dataclass(frozen=True)
class SercaloDatasheet:
    """Sercalo mirror as documented by its vendor (ESRF study Table 1)."""

    max_stroke_deg: PerAxis = _p("deg", "ESRF study 1.2 Table 1", "maximum mechanical stroke")
    resonance_hz: PerAxis = _p("Hz", "ESRF study 1.2 Table 1", "resonance frequency")
    dc_gain_ma_per_deg: PerAxis = _p(
        "mA/deg", "ESRF study 1.2 Table 1", "coil current per mirror angle at DC"
    )
    gain_at_resonance_deg_per_v: PerAxis = _p(
        "deg/V", "ESRF study 1.2 Table 1", "mirror angle per volt at the resonance"
    )
    r_coil_ohm: float = _p("Ohm", "ESRF study 1.2 Table 1", "coil resistance (AX1; AX2 is blank)")


@dataclass(frozen=True)
class NewportDatasheet:
    """Newport FSM-300 as documented by its vendor (ESRF study Figure 4)."""

    range_rad: float = _p("rad", "ESRF study Fig. 4", "mechanical angular range for the full "
                                                      "command")
    range_v: float = _p("V", "ESRF study Fig. 4", "command giving the full angular range")
    amplitude_bandwidth_hz: float = _p(
        "Hz", "ESRF study Fig. 4", "closed-loop amplitude bandwidth (-3 dB, 10 mV)"
    )
    phase_bandwidth_hz: float = _p("Hz", "ESRF study Fig. 4", "closed-loop phase bandwidth")
    phase_bandwidth_lag_deg: float = _p(
        "deg", "ESRF study Fig. 4", "phase lag defining the phase bandwidth"
    )
    peaking_max_db: float = _p("dB", "ESRF study Fig. 4", "maximum response peaking")
    noise_equivalent_angle_rad: float = _p(
        "rad rms", "ESRF study Fig. 4", "noise-equivalent angle, 1 Hz to 10 kHz, mechanical"
    )
    local_sensor_resolution_rad: float = _p(
        "rad", "ESRF study Fig. 4", "resolution of the local position sensor"
    )
    repeatability_rad: float = _p("rad rms", "ESRF study Fig. 4", "repeatability, mechanical")
    thermal_drift_rad_per_k: float = _p("rad/K", "ESRF study Fig. 4", "mirror thermal drift")


@dataclass(frozen=True)
class Datasheet:
    """Vendor numbers; ``docs/model.md`` derives the nominal model from them."""

    sercalo: SercaloDatasheet
    newport: NewportDatasheet


# --------------------------------------------------------------------------- model parameters


@dataclass(frozen=True)
class ConverterParams:
    """ADC and DAC of the real-time target (ESRF study 1.6 and 4.5a)."""

    fs_hz: float = _p("Hz", "ESRF study 1.6", "sampling frequency of ADC, DAC and controller")
    range_v: float = _p("V", "ESRF study 1.6", "full span of ADC and DAC (-10 V to +10 V)")
    bits: int = _p("bit", "ESRF study 1.6", "resolution of ADC and DAC")
    dac_delay_samples: int = _p(
        "sample",
        "ESRF study 2.3d",
        "samples between a command being computed and the DAC applying it",
    )
    dac_extra_delay_s: float = _p(
        "s", "fsmbench (real bench)",
        "further latency of every DAC command, any fraction of a sample (computation time)",
        0.0,
    )

    @property
    def ts_s(self) -> float:
        """Sampling period [s]."""
        return 1.0 / self.fs_hz

    @property
    def lsb_v(self) -> float:
        """Quantisation step q = range / 2**bits [V]."""
        return self.range_v / 2**self.bits

    @property
    def quantisation_psd_v2_per_hz(self) -> float:
        """One-sided-equivalent PSD, q**2 / (12 fs) [V**2/Hz] (ESRF study eq. 12)."""
        return self.lsb_v**2 / (12.0 * self.fs_hz)


@dataclass(frozen=True)
class SercaloParams:
    """Sercalo voice-coil mirror: one mass-spring-damper per axis (ESRF study 1.2)."""

    resonance_hz: PerAxis = _p("Hz", "ESRF study 1.2, 9.2", "undamped natural frequency of each "
                                                            "axis")
    damping_ratio: PerAxis = _p("1", "ESRF study 1.2", "modal damping ratio of each axis")
    dc_gain_rad_per_a: PerAxis = _p(
        "rad/A", "ESRF study 1.2 Table 1", "mechanical mirror angle per coil current at DC"
    )
    r_coil_ohm: PerAxis = _p("Ohm", "ESRF study 1.2, 2.2", "coil DC resistance Rc (measured)")
    l_coil_h: PerAxis = _p("H", "ESRF study 1.2, 2.2", "coil inductance Lc (measured)")
    coupling_h_to_v: float = _p(
        "1", "fsmbench", "torque on the v axis per h-coil current, relative to the v coil"
    )
    coupling_v_to_h: float = _p(
        "1", "fsmbench", "torque on the h axis per v-coil current, relative to the h coil"
    )
    beam_angle_per_mirror_angle: PerAxis = _p(
        "rad/rad",
        "ESRF study 4.1, 4.5c",
        "beam angle at the 4QD per Sercalo mirror angle (two reflections: 4, signed)",
    )
    max_stroke_rad: float = _p("rad", "ESRF study 1.2 Table 1", "maximum mechanical stroke")
    mode_shape_angle_rad: PerAxis = _p(
        "rad", "fsmbench (real bench)",
        "rotation of each axis's mode shape in the mirror plane (coupling through the modes)",
        _OFF,
    )
    second_mode_hz: PerAxis = _p(
        "Hz", "fsmbench (real bench)", "natural frequency of a second, weaker mode (0: none)",
        _OFF,
    )
    second_mode_damping_ratio: PerAxis = _p(
        "1", "fsmbench (real bench)", "damping ratio of the second mode", _OFF,
    )
    second_mode_relative_gain: PerAxis = _p(
        "1", "fsmbench (real bench)",
        "DC gain of the second mode relative to the first mode's dc_gain_rad_per_a", _OFF,
    )
    second_mode_shape_angle_rad: PerAxis = _p(
        "rad", "fsmbench (real bench)", "rotation of the second mode's shape", _OFF,
    )


@dataclass(frozen=True)
class CurrentAmplifierParams:
    """Buffer and series resistor that drive the Sercalo coils (ESRF study 2.2, Fig. 11)."""

    r_ohm: PerAxis = _p("Ohm", "ESRF study 2.2", "series resistor R that sets the gain")
    r_buffer_ohm: PerAxis = _p(
        "Ohm",
        "ESRF study 2.2",
        "buffer output and wiring resistance in series with R and Rc (zero in the schematic)",
    )
    sign: PerAxis = _p(
        "1", "fsmbench (evidence)",
        "sign of the coil current per command volt: +1 as in ESRF study Fig. 11, -1 for an "
        "inverting amplifier or a coil whose two wires are the other way round",
        PerAxis(h=1.0, v=1.0),
    )


@dataclass(frozen=True)
class VoltageAmplifierParams:
    """Amplifier of the voltage across the Sercalo coil (ESRF study 2.2)."""

    gain: float = _p("V/V", "ESRF study 2.2", "DC gain Ga0 (60 dB)")
    cutoff_hz: float = _p("Hz", "ESRF study 2.2", "first-order cut-off frequency")
    noise_rms_v: float = _p("V rms", "fsmbench", "white noise at the amplifier output")
    sign: PerAxis = _p(
        "1", "fsmbench (evidence)",
        "sign of the monitor Vch, Vcv against the voltage across the coil (-1: its input or "
        "output cable the other way round)",
        PerAxis(h=1.0, v=1.0),
    )


@dataclass(frozen=True)
class NewportParams:
    """Newport FSM-300 used as a disturbance generator (ESRF study 1.4, 2.1, 2.4, 4.5)."""

    gain_rad_per_v: PerAxis = _p(
        "rad/V", "ESRF study 1.4, Fig. 4", "mechanical mirror angle per command volt"
    )
    metrology_gain_rad_per_v: float = _p(
        "rad/V", "ESRF study 2.1 (gn0)", "mirror angle per volt of the metrology outputs Vnh, Vnv"
    )
    natural_freq_hz: float = _p(
        "Hz", "docs/model.md from Fig. 4", "natural frequency of the second-order response"
    )
    damping_ratio: float = _p(
        "1", "docs/model.md from Fig. 4", "damping ratio of the second-order response"
    )
    internal_delay_s: float = _p(
        "s",
        "ESRF study 2.4 and Fig. 4",
        "transport lag inside the FSM electronics (path total with DAC and hold: ESRF study's 0.5 "
        "ms)",
    )
    beam_angle_per_mirror_angle: float = _p(
        "rad/rad", "ESRF study 2.1", "beam angle at the 4QD per Newport mirror angle"
    )
    angle_noise_rms_rad: float = _p(
        "rad rms", "ESRF study Fig. 4, 4.5a", "mechanical angle noise (noise-equivalent angle)"
    )
    metrology_noise_rms_rad: float = _p(
        "rad rms", "ESRF study Fig. 4", "noise of the local position sensor behind Vnh, Vnv"
    )
    concave_radius_m: float = _p("m", "ESRF study 4.5a", "radius of the concave Newport mirror")
    metrology_sign: PerAxis = _p(
        "1", "fsmbench (evidence)",
        "sign of each metrology output Vnh, Vnv against the mirror's angle (-1: that output "
        "reads the other way)",
        PerAxis(h=1.0, v=1.0),
    )


@dataclass(frozen=True)
class QuadDiodeParams:
    """Four-quadrant photodiode and its amplifier (ESRF study 1.5, 2.1 Table 2, 4.5b)."""

    gain_v_per_rad: PerAxis = _p(
        "V/rad", "ESRF study 2.1 Table 2", "4QD output voltage per beam angle (signed)"
    )
    rotation_rad: float = _p(
        "rad", "fsmbench", "rotation of the 4QD axes relative to the mirror axes"
    )
    noise_rms_v: PerAxis = _p(
        "V rms", "ESRF study 4.5b", "white electronic noise of the 4QD outputs Vph, Vpv"
    )
    bandwidth_hz: float = _p(
        "Hz", "fsmbench (real bench)", "-3 dB bandwidth of the 4QD amplifier (0: unlimited)", 0.0,
    )
    bandwidth_order: int = _p(
        "1", "fsmbench (real bench)",
        "order of the 4QD amplifier's low pass: 1, or 2 (Butterworth)", 1,
    )
    flicker_asd_v_per_rthz: PerAxis = _p(
        "V/sqrt(Hz) at 1 Hz", "fsmbench (real bench)",
        "1/f noise of the 4QD outputs: amplitude spectral density at 1 Hz", _OFF,
    )
    flicker_min_hz: float = _p(
        "Hz", "fsmbench (real bench)", "frequency below which the 1/f noise flattens", 1.0e-3,
    )
    mains_freq_hz: float = _p("Hz", "fsmbench (real bench)", "mains frequency", 50.0)
    mains_amplitude_v: tuple[float, ...] = _p(
        "V peak", "fsmbench (real bench)",
        "mains lines on the 4QD outputs: amplitude of the fundamental, 2nd, 3rd, ... harmonic",
        (),
    )
    mains_phase_wander_rad_per_rts: float = _p(
        "rad/sqrt(s)", "fsmbench (real bench)",
        "random walk of the mains phase (0: fixed phase)", 0.0,
    )
    offset_drift_v_per_s: PerAxis = _p(
        "V/s", "fsmbench (real bench)", "linear drift of the 4QD offsets", _OFF,
    )
    offset_random_walk_v_per_rts: PerAxis = _p(
        "V/sqrt(s)", "fsmbench (real bench)", "random walk of the 4QD offsets", _OFF,
    )
    nonlinearity_pct: float = _p(
        "%", "fsmbench (real bench)",
        "compression of the 4QD response at full swing (cubic; >0: less than linear)", 0.0,
    )
    nonlinearity_full_swing_rad: float = _p(
        "rad", "fsmbench (real bench)",
        "beam angle at which the compression is nonlinearity_pct (the calibration's swing)",
        0.0106,
    )


@dataclass(frozen=True)
class AttocubeParams:
    """Attocube interferometer measuring the beam path (ESRF study 2, 3, 4)."""

    noise_rms_m: float = _p("m rms", "fsmbench", "white noise of the displacement output Va")
    resolution_m: float = _p("m", "fsmbench", "output resolution of Va")
    wavelength_m: float = _p("m", "fsmbench", "laser wavelength (for the refractive index)")


@dataclass(frozen=True)
class GeometryParams:
    """Beam-path geometry (ESRF study 4.1, 4.2, 4.4, 11.3)."""

    h_m: float = _p("m", "ESRF study 4.1", "distance Sercalo to Newport (H)")
    l_m: float = _p("m", "ESRF study 4.1", "distance Attocube to Sercalo (L)")
    sercalo_spot_offset_m: float = _p(
        "m", "ESRF study 4.2", "beam spot offset from the Sercalo rotation axis (piston per angle)"
    )
    newport_spot_offset_m: float = _p(
        "m", "ESRF study 4.2", "beam spot offset from the Newport rotation axis (piston per angle)"
    )
    frame_length_m: float = _p("m", "ESRF study 4.4", "metrology-frame length Attocube head to "
                                                      "target")
    frame_expansion_per_k: float = _p(
        "1/K", "ESRF study 4.4", "linear thermal expansion of the frame (aluminium)"
    )

    @property
    def measured_distance_m(self) -> float:
        """One-way distance the Attocube measures, L + H [m] (ESRF study 4.3: 100 mm)."""
        return self.l_m + self.h_m


@dataclass(frozen=True)
class EnvironmentParams:
    """Air and temperature disturbances of the huddle-test configurations (ESRF study 3, 4.3, 4.4).

    Each drift is a stationary first-order Gauss-Markov process with the given
    standard deviation and correlation time, so its rms is well defined.
    """

    room_temperature_rms_k: float = _p("K", "ESRF study 4.3", "room air temperature drift")
    room_temperature_tau_s: float = _p("s", "fsmbench", "correlation time of the room drift")
    room_pressure_rms_pa: float = _p("Pa", "ESRF study 4.3", "room pressure drift")
    room_pressure_tau_s: float = _p("s", "fsmbench", "correlation time of the pressure drift")
    room_humidity_rms_pct: float = _p("%RH", "ESRF study 4.3", "room relative-humidity drift")
    room_humidity_tau_s: float = _p("s", "fsmbench", "correlation time of the humidity drift")
    beam_path_temperature_rms_k: float = _p(
        "K", "ESRF study 3, 4.3", "local air-temperature fluctuation along the beam (convection)"
    )
    beam_path_temperature_tau_s: float = _p(
        "s", "fsmbench", "correlation time of the local fluctuation"
    )
    shielding_attenuation: float = _p(
        "1", "ESRF study 3 Table 3", "factor by which the aluminium shield reduces the local "
                                     "fluctuation"
    )
    ecu_temperature_error_k: float = _p(
        "K", "ESRF study 4.3", "error of the compensation unit's temperature reading"
    )
    ecu_pressure_error_pa: float = _p(
        "Pa", "ESRF study 4.3", "error of the compensation unit's pressure reading"
    )
    ecu_humidity_error_pct: float = _p(
        "%RH", "ESRF study 4.3", "error of the compensation unit's humidity reading"
    )
    ecu_error_tau_s: float = _p("s", "fsmbench", "correlation time of the sensor errors")
    frame_time_constant_s: float = _p(
        "s", "ESRF study 4.4", "thermal time constant of the metrology frame"
    )
    reference_temperature_c: float = _p("degC", "ESRF study 4.3", "mean air temperature")
    reference_pressure_pa: float = _p("Pa", "ESRF study 4.3", "mean air pressure")
    reference_humidity_pct: float = _p("%RH", "ESRF study 4.3", "mean relative humidity")


@dataclass(frozen=True)
class ScalingParams:
    """Plant scaling and control objective (ESRF study Table 5 and 6.1)."""

    un_max_v: float = _p("V", "ESRF study Table 5", "expected Newport perturbation command")
    uc_max_v: float = _p("V", "ESRF study Table 5", "maximum Sercalo command")
    error_max_rad: float = _p("rad", "ESRF study Table 5, 6.1", "maximum wanted beam-angle error")
    noise_rad: float = _p("rad", "ESRF study Table 5", "measured beam-angle noise")
    stroke_max_rad: float = _p("rad", "ESRF study 6.1", "maximum expected beam stroke at f0")
    objective_freq_hz: float = _p("Hz", "ESRF study 6.1", "frequency of the stroke, f0")


@dataclass(frozen=True)
class BenchParams:
    """Every model parameter of the bench (one instance for ``nominal``, one for ``true``)."""

    converter: ConverterParams
    sercalo: SercaloParams
    current_amplifier: CurrentAmplifierParams
    voltage_amplifier: VoltageAmplifierParams
    newport: NewportParams
    quad_diode: QuadDiodeParams
    attocube: AttocubeParams
    geometry: GeometryParams
    environment: EnvironmentParams
    scaling: ScalingParams

    def current_amp_gain_a_per_v(self) -> PerAxis:
        """Static current-amplifier gain 1/(R + R_buffer + Rc) [A/V] (ESRF study 2.2 eq. 3)."""
        r_total = (
            self.current_amplifier.r_ohm.as_array()
            + self.current_amplifier.r_buffer_ohm.as_array()
            + self.sercalo.r_coil_ohm.as_array()
        )
        g = 1.0 / r_total
        return PerAxis(h=float(g[0]), v=float(g[1]))


@dataclass(frozen=True)
class Bench:
    """The bench: vendor numbers, the nominal model and what the engine simulates.

    Attributes
    ----------
    datasheet : Datasheet
    nominal : BenchParams
        The model before identification (the bench file's ``[nominal]``).
    true : BenchParams
        What the simulation engine reads: the packaged twin's ``[true]``, or for
        an identified bench the bench file's values with the identified 4QD and
        the noise fitted to the recordings (:func:`fsmbench.twin.identified.identified_bench`).
    origin : str
        The bench file it was read from, or the identification folder.
    model : IdentifiedModel or None
        None for a packaged bench (the engine simulates the physics of ``true``);
        for an identified bench, the identified plant the engine runs instead.
    """

    datasheet: Datasheet
    nominal: BenchParams
    true: BenchParams
    # Where a bench came from is not what it is: two benches with the same values are equal.
    origin: str = field(default="", compare=False)
    model: IdentifiedModel | None = field(default=None, compare=False)

    @property
    def is_identified(self) -> bool:
        """True when the engine runs an identified plant rather than the bench file's physics."""
        return self.model is not None

    @property
    def label(self) -> str:
        """Which bench a simulation runs, in words ("the packaged twin (default_bench.toml)")."""
        if self.model is not None:
            return self.model.label or f"the bench identified in {self.model.folder}"
        name = self.origin or "default_bench.toml"
        return (f"the packaged twin ({name})" if name in PACKAGED_BENCHES
                else f"the twin of {name}")

    def to_toml(self) -> str:
        """The bench as TOML text, every value commented with unit and source."""
        lines = [
            "# fsmbench bench parameters.",
            "# [datasheet]: vendor numbers; [nominal]: model before identification;",
            "# [true]: what the digital twin simulates (keys missing here default to nominal).",
        ]
        for name in ("datasheet", "nominal", "true"):
            emit_toml(getattr(self, name), name, lines)
        return "\n".join(lines) + "\n"

def _bench_from_mapping(data: dict[str, Any], origin: str) -> Bench:
    data = resolve_base(data, origin)
    for section in ("datasheet", "nominal"):
        if section not in data:
            raise ParamsError(f"{origin}: missing table [{section}]")
    unknown = sorted(set(data) - {"datasheet", "nominal", "true"})
    if unknown:
        raise ParamsError(f"{origin}: unknown top-level table(s) {unknown}")
    datasheet = build(Datasheet, data["datasheet"], "datasheet", origin)
    nominal = build(BenchParams, data["nominal"], "nominal", origin)
    true = build(BenchParams, data.get("true", {}), "true", origin, base=nominal)
    for section, p in (("nominal", nominal), ("true", true)):
        check_ranges(p, section, origin)  # physical ranges first: the features assume them
        check_features(p, section, origin)
    return Bench(datasheet=datasheet, nominal=nominal, true=true, origin=origin)


#: Bench files shipped with fsmbench; ``load_bench`` finds them by name.
PACKAGED_BENCHES = ("default_bench.toml", "real_bench.toml")


def default_bench() -> Bench:
    """The Sercalo test bench of the ESRF study, from the packaged ``default_bench.toml``."""
    return _bench_from_mapping(packaged_mapping("default_bench.toml"), "default_bench.toml")


def real_bench() -> Bench:
    """The default bench with every real-bench feature on (packaged ``real_bench.toml``)."""
    return _bench_from_mapping(packaged_mapping("real_bench.toml"), "real_bench.toml")


def load_bench(path: str | Path | None = None) -> Bench:
    """Load bench parameters from a TOML file.

    Parameters
    ----------
    path : str or Path, optional
        TOML file with tables ``[datasheet.*]``, ``[nominal.*]`` and optionally
        ``[true.*]``; keys missing from ``[true]`` take the nominal value. With
        ``None`` the packaged default bench is returned. A file with the
        top-level key ``base = "default"`` (or ``"real"``) lists only its
        differences from that packaged bench. The name of a packaged bench (``real_bench.toml``)
        that is not a file in the current folder loads the packaged one.

    Raises
    ------
    ParamsError
        The path is a folder, the file is not UTF-8 text or not TOML, or a key is
        missing, unknown, or of the wrong type.
    """
    if path is None:
        return default_bench()
    p = Path(path)
    if not p.exists() and str(path) in PACKAGED_BENCHES:
        return _bench_from_mapping(packaged_mapping(str(path)), str(path))
    if p.is_dir():
        raise ParamsError(f"{p}: is a folder; a bench file is a TOML file (e.g. one written "
                          "by fsmbench params --out DIR)")
    try:
        data = tomllib.loads(p.read_text("utf-8"))
    except FileNotFoundError:
        raise ParamsError(f"{p}: no such parameter file") from None
    except UnicodeDecodeError as exc:
        raise ParamsError(f"{p}: is not UTF-8 text ({exc.reason} at byte {exc.start}); a "
                          "bench file is a TOML file") from None
    except tomllib.TOMLDecodeError as exc:
        raise ParamsError(f"{p}: not valid TOML ({exc})") from None
    return _bench_from_mapping(data, str(p))


def save_bench(bench: Bench, path: str | Path) -> Path:
    """Write ``bench`` as TOML to ``path`` atomically; returns the path."""

    return atomic_write_text(Path(path), bench.to_toml())


# --------------------------------------------------------------------------- tabulation


@dataclass(frozen=True)
class ParamRow:
    """One printable parameter: dotted key, nominal and true values, unit, source, description."""

    key: str
    nominal: str
    true: str
    unit: str
    source: str
    doc: str


def walk_fields(obj: Any, prefix: str) -> Iterator[tuple[str, Any, dataclasses.Field[Any]]]:
    for f in dataclasses.fields(obj):
        value = getattr(obj, f.name)
        key = f"{prefix}.{f.name}" if prefix else f.name
        if dataclasses.is_dataclass(value) and not isinstance(value, PerAxis):
            yield from walk_fields(value, key)
        else:
            yield key, value, f


def _fmt(value: Any) -> str:
    if isinstance(value, PerAxis):
        return f"h {_fmt(value.h)}, v {_fmt(value.v)}"
    if isinstance(value, float):
        return f"{value:.6g}"
    if isinstance(value, tuple):
        return "[" + ", ".join(_fmt(v) for v in value) + "]"
    return str(value)


def param_rows(bench: Bench) -> list[ParamRow]:
    """Every parameter as a row (datasheet rows have no ``true`` column)."""
    rows = [
        ParamRow(f"datasheet.{k}", _fmt(v), "", f.metadata["unit"], f.metadata["source"],
                 f.metadata["doc"])
        for k, v, f in walk_fields(bench.datasheet, "")
    ]
    true_values = {k: v for k, v, _ in walk_fields(bench.true, "")}
    for k, v, f in walk_fields(bench.nominal, ""):
        rows.append(ParamRow(k, _fmt(v), _fmt(true_values[k]), f.metadata["unit"],
                             f.metadata["source"], f.metadata["doc"]))
    return rows
