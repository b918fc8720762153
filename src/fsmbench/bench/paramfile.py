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

__all__ = ["build", "check_features", "emit_toml", "packaged_mapping", "resolve_base"]

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
    value = float(raw)
    if not math.isfinite(value):
        raise ParamsError(f"{origin}: '{key}' must be finite, got {raw!r}")
    return value


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
