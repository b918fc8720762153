"""Bench parameter files: TOML in and out, files based on a packaged bench, feature checks.

The dataclasses of :mod:`fsmbench.bench.params` carry every value's unit and
source; this module turns TOML tables into them (naming the file and key of
anything wrong) and them back into TOML.
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
from importlib import resources
from typing import TYPE_CHECKING, Any, get_args, get_origin, get_type_hints

from fsmbench.bench.axes import ParamsError, PerAxis

if TYPE_CHECKING:
    from fsmbench.bench.params import BenchParams

__all__ = ["build", "check_features", "check_ranges", "emit_toml", "packaged_mapping",
           "resolve_base"]

#: Magnitudes a bench file's non-zero numbers may have, in their SI units. The packaged
#: benches span 1e-12 (the Attocube's 1 pm resolution) to 1.0e5 (air pressure in Pa); this
#: window is 1000x wider on each side, and keeps the products of parameters the model forms
#: (and their squares in the noise PSDs) inside float64, where 1e300 overflowed the plant's
#: matrices to inf (numba then failed to compile the loop).
MAGNITUDE_MIN = 1e-15
MAGNITUDE_MAX = 1e9


def _toml_value(value: Any) -> str:
    if isinstance(value, PerAxis):
        return f"{{ h = {_toml_value(value.h)}, v = {_toml_value(value.v)} }}"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if math.isnan(value):
            return "nan"
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        return repr(value)  # repr round-trips a float exactly
    if isinstance(value, tuple):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    if isinstance(value, str):
        escaped = value.replace("\\", "\\\\").replace('"', '\\"')
        return f'"{escaped}"'
    raise TypeError(f"cannot write {type(value).__name__} to TOML")


def emit_toml(obj: Any, prefix: str, lines: list[str]) -> None:
    """Append dataclass ``obj`` as TOML tables under ``[prefix]`` to ``lines``, values commented.

    Parameters
    ----------
    obj : dataclass instance
    prefix : str
        Dotted table name (``nominal``, ``true.sercalo``, ...).
    lines : list of str
        Appended to in place.
    """
    scalars = []
    children = []
    for f in dataclasses.fields(obj):
        value = getattr(obj, f.name)
        if dataclasses.is_dataclass(value) and not isinstance(value, PerAxis):
            children.append((f.name, value))
        else:
            scalars.append((f, value))
    if scalars:
        lines.append("")
        lines.append(f"[{prefix}]")
        for f, value in scalars:
            meta = f.metadata
            lines.append(f"# {meta['doc']} [{meta['unit']}] ({meta['source']})")
            lines.append(f"{f.name} = {_toml_value(value)}")
    for name, child in children:
        emit_toml(child, f"{prefix}.{name}", lines)


def build(cls: type, data: Any, where: str, origin: str, base: Any = None) -> Any:
    """Build dataclass ``cls`` from a TOML table.

    Parameters
    ----------
    cls : dataclass type
    data : dict
        The TOML table.
    where : str
        Dotted name of the table (for messages).
    origin : str
        The file (for messages).
    base : instance of ``cls``, optional
        Supplies the keys ``data`` lacks; without it a missing key takes the
        field's default, and a field without one is an error.

    Raises
    ------
    ParamsError
        A key is missing, unknown, or of the wrong type (the message names file and key).
    """
    if not isinstance(data, dict):
        raise ParamsError(f"{origin}: [{where}] must be a table")
    hints = get_type_hints(cls)
    names = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(set(data) - names)
    if unknown:
        raise ParamsError(f"{origin}: unknown key(s) {unknown} in [{where}]")
    kwargs: dict[str, Any] = {}
    for f in dataclasses.fields(cls):
        key = f"{where}.{f.name}"
        typ = hints[f.name]
        if f.name not in data:
            if base is not None:
                kwargs[f.name] = getattr(base, f.name)
            elif f.default is not dataclasses.MISSING:
                kwargs[f.name] = f.default
            else:
                raise ParamsError(f"{origin}: missing key '{key}'")
            continue
        raw = data[f.name]
        sub_base = None if base is None else getattr(base, f.name)
        if typ is PerAxis:
            if isinstance(raw, dict):
                merged = {} if sub_base is None else {"h": sub_base.h, "v": sub_base.v}
                merged.update(raw)
                if set(merged) != {"h", "v"}:
                    raise ParamsError(f"{origin}: '{key}' needs exactly the keys h and v")
                kwargs[f.name] = PerAxis(h=_number(merged["h"], key, origin),
                                         v=_number(merged["v"], key, origin))
            else:
                raise ParamsError(f"{origin}: '{key}' must be a table {{ h = ..., v = ... }}")
        elif dataclasses.is_dataclass(typ):
            kwargs[f.name] = build(typ, raw, key, origin, sub_base)  # type: ignore[arg-type]
        elif typ is int:
            if not isinstance(raw, int) or isinstance(raw, bool):
                raise ParamsError(f"{origin}: '{key}' must be an integer, got {raw!r}")
            kwargs[f.name] = raw
        elif typ is float:
            kwargs[f.name] = _number(raw, key, origin)
        elif get_origin(typ) is tuple and get_args(typ) == (float, Ellipsis):
            if not isinstance(raw, list):
                raise ParamsError(f"{origin}: '{key}' must be an array of numbers, got {raw!r}")
            kwargs[f.name] = tuple(_number(v, key, origin) for v in raw)
        else:  # pragma: no cover - every field type is handled above
            raise ParamsError(f"{origin}: unsupported type for '{key}'")
    return cls(**kwargs)


def _number(raw: Any, key: str, origin: str) -> float:
    if isinstance(raw, bool) or not isinstance(raw, int | float):
        raise ParamsError(f"{origin}: '{key}' must be a number, got {raw!r}")
    try:
        value = float(raw)
    except OverflowError:  # a TOML integer beyond float64
        value = math.inf
    if not math.isfinite(value):
        raise ParamsError(f"{origin}: '{key}' must be finite, got {raw!r}")
    if value != 0 and not MAGNITUDE_MIN <= abs(value) <= MAGNITUDE_MAX:
        raise ParamsError(f"{origin}: '{key}' = {value:g} is not a physical value of this "
                          f"bench: non-zero values must lie within {MAGNITUDE_MIN:g} to "
                          f"{MAGNITUDE_MAX:g} in magnitude (SI units, the unit is in the key's "
                          "name)")
    return value


#: Highest sampling rate: 100x the seed's 10 kHz real-time target; the engine simulates
#: every sample, so a record's memory and time grow with the rate.
FS_MAX_HZ = 1e6
#: Most converter bits: no ADC or DAC resolves more than 32 bits, and the quantiser's codes
#: (+-2**(bits-1)) stay exact in float64 up to 53.
BITS_MAX = 32
#: Longest delay in samples (DAC latency, the Newport's internal lag): each sample of delay
#: is a state of the discrete plant; 1000 samples (0.1 s at 10 kHz) is 500x the seed's path
#: delay and keeps the plant's matrices small.
DELAY_MAX_SAMPLES = 1000

# Physical ranges, by key (section.name): what each must be and what it is, for the message.
_POSITIVE = {
    "converter.fs_hz": "a sampling rate", "converter.range_v": "a converter span",
    "sercalo.resonance_hz": "a resonance", "sercalo.r_coil_ohm": "a resistance",
    "sercalo.l_coil_h": "an inductance", "sercalo.max_stroke_rad": "a stroke",
    "current_amplifier.r_ohm": "a resistance", "voltage_amplifier.cutoff_hz": "a cut-off",
    "newport.natural_freq_hz": "a resonance",
    "environment.room_temperature_tau_s": "a correlation time",
    "environment.room_pressure_tau_s": "a correlation time",
    "environment.room_humidity_tau_s": "a correlation time",
    "environment.beam_path_temperature_tau_s": "a correlation time",
    "environment.ecu_error_tau_s": "a correlation time",
    "environment.frame_time_constant_s": "a time constant",
}
_NON_NEGATIVE = {
    "sercalo.damping_ratio": "a damping ratio", "newport.damping_ratio": "a damping ratio",
    "sercalo.second_mode_damping_ratio": "a damping ratio",
    "current_amplifier.r_buffer_ohm": "a resistance",
    "converter.dac_extra_delay_s": "a delay", "newport.internal_delay_s": "a delay",
    "attocube.resolution_m": "a resolution",
    "quad_diode.flicker_asd_v_per_rthz": "a noise density",
    "quad_diode.offset_random_walk_v_per_rts": "a random walk",
    "quad_diode.mains_phase_wander_rad_per_rts": "a random walk",
}
_NON_ZERO = {
    "sercalo.dc_gain_rad_per_a": "a gain", "sercalo.beam_angle_per_mirror_angle": "a gain",
    "voltage_amplifier.gain": "a gain", "newport.gain_rad_per_v": "a gain",
    "newport.metrology_gain_rad_per_v": "a gain",
    "newport.beam_angle_per_mirror_angle": "a gain", "quad_diode.gain_v_per_rad": "a gain",
}

_SIGNS = {
    "current_amplifier.sign": "a sign", "voltage_amplifier.sign": "a sign",
    "newport.metrology_sign": "a sign",
}


def _values(p: Any, prefix: str = "") -> list[tuple[str, Any]]:
    """(``section.name[.h|.v|[i]]``, value) of every number of a BenchParams."""
    out: list[tuple[str, Any]] = []
    for f in dataclasses.fields(p):
        value = getattr(p, f.name)
        key = f"{prefix}{f.name}"
        if isinstance(value, PerAxis):
            out += [(f"{key}.h", value.h), (f"{key}.v", value.v)]
        elif dataclasses.is_dataclass(value):
            out += _values(value, f"{key}.")
        elif isinstance(value, tuple):
            out += [(f"{key}[{i}]", v) for i, v in enumerate(value)]
        else:
            out.append((key, value))
    return out


def check_ranges(p: BenchParams, where: str, origin: str) -> None:
    """Refuse values outside their physical range, naming the file, the key and the value.

    Resistances, inductances, resonances, cut-offs, spans and time constants
    are > 0; damping ratios, noises (``*noise*``, ``*_rms_*``), delays and
    resolutions >= 0; gains non-zero; ``bits`` 1 to :data:`BITS_MAX`; the
    sampling rate at most :data:`FS_MAX_HZ`; delays at most
    :data:`DELAY_MAX_SAMPLES` samples. Every number is finite and within
    :data:`MAGNITUDE_MIN`..:data:`MAGNITUDE_MAX` already (checked as read).

    Raises
    ------
    ParamsError
        The first value out of range.
    """
    conv = p.converter
    for key, value in _values(p):
        base = key.split("[")[0].removesuffix(".h").removesuffix(".v")
        name = f"'{where}.{key}' = {value:g}"
        if base in _POSITIVE and not value > 0:
            raise ParamsError(f"{origin}: {name} must be > 0 ({_POSITIVE[base]})")
        noise = "noise" in base or "_rms_" in base
        if (base in _NON_NEGATIVE or noise) and not value >= 0:
            what = _NON_NEGATIVE.get(base, "a noise level")
            raise ParamsError(f"{origin}: {name} must be >= 0 ({what})")
        if base in _NON_ZERO and value == 0:
            raise ParamsError(f"{origin}: {name} must be non-zero ({_NON_ZERO[base]}: 0 "
                              "would cut the signal path)")
        if base in _SIGNS and value not in (-1.0, 1.0):
            raise ParamsError(f"{origin}: {name} must be +1 or -1 ({_SIGNS[base]})")
    if not 1 <= conv.bits <= BITS_MAX:
        raise ParamsError(f"{origin}: '{where}.converter.bits' = {conv.bits} must be a whole "
                          f"number from 1 to {BITS_MAX} (the converters' resolution)")
    if conv.fs_hz > FS_MAX_HZ:
        raise ParamsError(f"{origin}: '{where}.converter.fs_hz' = {conv.fs_hz:g} Hz is above "
                          f"{FS_MAX_HZ:g} Hz, 100x the ESRF study's real-time target")
    if not 0 <= conv.dac_delay_samples <= DELAY_MAX_SAMPLES:
        raise ParamsError(f"{origin}: '{where}.converter.dac_delay_samples' = "
                          f"{conv.dac_delay_samples} must be from 0 to {DELAY_MAX_SAMPLES}")
    for key, delay in (("converter.dac_extra_delay_s", conv.dac_extra_delay_s),
                       ("newport.internal_delay_s", p.newport.internal_delay_s)):
        if delay * conv.fs_hz > DELAY_MAX_SAMPLES:
            raise ParamsError(f"{origin}: '{where}.{key}' = {delay:g} s is "
                              f"{delay * conv.fs_hz:g} samples at {conv.fs_hz:g} Hz, more "
                              f"than {DELAY_MAX_SAMPLES}")


def _merged(base: dict[str, Any], over: dict[str, Any]) -> dict[str, Any]:
    """``base`` with ``over``'s tables merged in key by key (``over`` wins)."""
    out = dict(base)
    for key, value in over.items():
        if isinstance(value, dict) and isinstance(out.get(key), dict):
            out[key] = _merged(out[key], value)
        else:
            out[key] = value
    return out


def packaged_mapping(name: str) -> dict[str, Any]:
    """The TOML tables of the bench file ``name`` shipped in :mod:`fsmbench.bench`."""
    text = resources.files("fsmbench.bench").joinpath(name).read_text("utf-8")
    return tomllib.loads(text)


def check_features(p: BenchParams, where: str, origin: str) -> None:
    """Refuse real-bench feature values that cannot be simulated, in one line.

    Parameters
    ----------
    p : BenchParams
    where : str
        ``nominal`` or ``true`` (for the message).
    origin : str
        The file (for the message).

    Raises
    ------
    ParamsError
        The first problem found, naming the file and the key.
    """
    qd, s = p.quad_diode, p.sercalo
    problems = []
    if qd.bandwidth_hz < 0:
        problems.append(f"'{where}.quad_diode.bandwidth_hz' must be >= 0 (0: unlimited)")
    if qd.bandwidth_order not in (1, 2):
        problems.append(f"'{where}.quad_diode.bandwidth_order' must be 1 or 2, "
                        f"got {qd.bandwidth_order}")
    if qd.flicker_min_hz <= 0:
        problems.append(f"'{where}.quad_diode.flicker_min_hz' must be > 0")
    if qd.nonlinearity_full_swing_rad <= 0:
        problems.append(f"'{where}.quad_diode.nonlinearity_full_swing_rad' must be > 0")
    if not 0 <= qd.nonlinearity_pct < 30:
        problems.append(f"'{where}.quad_diode.nonlinearity_pct' must be in [0, 30) %, "
                        f"got {qd.nonlinearity_pct}")
    if p.converter.dac_extra_delay_s < 0:
        problems.append(f"'{where}.converter.dac_extra_delay_s' must be >= 0")
    for axis in ("h", "v"):
        if s.second_mode_hz[axis] < 0:
            problems.append(f"'{where}.sercalo.second_mode_hz.{axis}' must be >= 0 (0: none)")
        if s.second_mode_hz[axis] > 0 and s.second_mode_damping_ratio[axis] <= 0:
            problems.append(f"'{where}.sercalo.second_mode_damping_ratio.{axis}' must be > 0 "
                            "when the second mode is on")
        if s.second_mode_hz[axis] >= p.converter.fs_hz / 2:
            problems.append(f"'{where}.sercalo.second_mode_hz.{axis}' = "
                            f"{s.second_mode_hz[axis]:g} Hz is not below the Nyquist "
                            f"frequency {p.converter.fs_hz / 2:g} Hz")
    if problems:
        raise ParamsError(f"{origin}: {problems[0]}")


#: Values of a file's top-level ``base`` key and the packaged bench each names.
_BASES = {"default": "default_bench.toml", "real": "real_bench.toml"}


def resolve_base(data: dict[str, Any], origin: str) -> dict[str, Any]:
    """A file that lists only its differences from a packaged bench, merged over that bench."""
    if "base" not in data:
        return data
    base = data["base"]
    if base not in _BASES:
        raise ParamsError(f"{origin}: 'base' must be one of {sorted(_BASES)} (a packaged "
                          f"bench), got {base!r}")
    parent = resolve_base(packaged_mapping(_BASES[base]), _BASES[base])
    return _merged(parent, {k: v for k, v in data.items() if k != "base"})
