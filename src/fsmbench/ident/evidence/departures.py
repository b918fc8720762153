"""The identified values as bench-file keys: the departures, and the bench file that matches.

Every value the identification determines has a counterpart in the bench file
(the 4QD gain ``nominal.quad_diode.gain_v_per_rad.h``, the Sercalo's resonance,
the current amplifier's series resistance …). :func:`measured_keys` maps them
onto those keys; :func:`departures` names the ones the records put away from
the bench file by more than what matters and more than their own uncertainty
(a :class:`~fsmbench.checks.Finding` each: a fact about the user's bench, not a
fault); :func:`matching_params` is the bench file with every measured key set,
which a rerun with ``--params`` accepts without a departure.

What matters is the identification's own tolerance (the issue's: resonances
0.5 %, damping 25 %, gains 3 %, the 4QD gain 1 %, delays half a sample):
closer than that, the bench file describes the bench as well as the records
can tell.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any, Final

import numpy as np

from fsmbench.bench.blocks import newport_beam_matrix
from fsmbench.bench.params import BenchParams, Datasheet, NewportDatasheet
from fsmbench.checks import Check, Finding

__all__ = ["MeasuredKey", "datasheet_departures", "departures", "get_key", "matching_datasheet",
           "matching_params", "measured_keys", "merged_findings", "set_key"]

#: The Newport's datasheet checks (ident.newport.newport_checks) by their datasheet key.
_DATASHEET_KEYS: Final = {"newport_amplitude_bandwidth": "amplitude_bandwidth_hz",
                          "newport_phase_bandwidth": "phase_bandwidth_hz",
                          "newport_peaking": "peaking_max_db"}

#: Relative departure below which a value agrees with the bench file, by key (the
#: identification's tolerance: a closer bench file describes the bench as well as the
#: records tell). Delays are absolute: half a sample (set per rate in :func:`departures`).
_RELATIVE: Final = {
    "sercalo.resonance_hz": 0.005, "sercalo.damping_ratio": 0.25,
    "sercalo.dc_gain_rad_per_a": 0.03, "quad_diode.gain_v_per_rad": 0.01,
    "current_amplifier.r_buffer_ohm": 0.03, "current_amplifier.r_ohm": 0.03,
    "newport.gain_rad_per_v": 0.03, "newport.natural_freq_hz": 0.005,
    "newport.damping_ratio": 0.25, "converter.fs_hz": 0.01,
}
#: Keys whose departure is absolute in samples of the records' rate.
_SAMPLES: Final = {"converter.dac_extra_delay_s": 0.5, "newport.internal_delay_s": 0.5}
#: Departures are beyond this many standard deviations of the measured value too.
_SIGMAS: Final = 3.0


@dataclass(frozen=True)
class MeasuredKey:
    """One identified value as a bench-file key.

    Attributes
    ----------
    key : str
        ``nominal.<section>.<field>[.h|.v]``.
    value, std : float
        The records' value and its standard deviation, in the key's unit.
    unit : str
    records : str
        The records it rests on.
    what : str
        The quantity in words.
    """

    key: str
    value: float
    std: float
    unit: str
    records: str
    what: str


def _split(key: str) -> tuple[str, str, str | None]:
    parts = key.split(".")
    if parts[0] == "nominal":
        parts = parts[1:]
    axis = parts[2] if len(parts) > 2 else None
    return parts[0], parts[1], axis


def get_key(params: BenchParams, key: str) -> float:
    """The value of a ``nominal.<section>.<field>[.h|.v]`` key in ``params``."""
    section, name, axis = _split(key)
    value = getattr(getattr(params, section), name)
    return float(value[axis]) if axis is not None else float(value)


def set_key(params: BenchParams, key: str, value: float) -> BenchParams:
    """``params`` with one ``nominal.<section>.<field>[.h|.v]`` key set."""
    section, name, axis = _split(key)
    part = getattr(params, section)
    old = getattr(part, name)
    if axis is not None:
        new: Any = dataclasses.replace(old, **{axis: float(value)})
    elif isinstance(old, int) and not isinstance(old, bool):
        new = round(value)
    else:
        new = float(value)
    return dataclasses.replace(params, **{section: dataclasses.replace(part, **{name: new})})


def _std(js: Mapping[str, Any], path: str) -> float:
    node: Any = js.get("uncertainty", {})
    for part in path.split("."):
        if not isinstance(node, Mapping) or part not in node:
            return math.nan
        node = node[part]
    return float(node.get("std", math.nan)) if isinstance(node, Mapping) else math.nan


def _mean_std(values: Sequence[tuple[float, float]]) -> tuple[float, float]:
    v = np.array([x for x, _ in values], dtype=float)
    s = np.array([y for _, y in values], dtype=float)
    return float(np.mean(v)), float(np.sqrt(np.nansum(s**2)) / len(values))


def _amplifier_keys(js: Mapping[str, Any], *, params: BenchParams) -> list[MeasuredKey]:
    """The current amplifier's resistances from the identified ``Gi`` (1/Gi − R − Rc)."""
    out: list[MeasuredKey] = []
    for a, gi in (js.get("current_amp_gain_a_per_v") or {}).items():
        amp = params.current_amplifier
        r_fixed = amp.r_ohm[a] + params.sercalo.r_coil_ohm[a]
        total = 1.0 / abs(float(gi))
        std = _std(js, f"current_amp_gain_a_per_v.{a}") / float(gi) ** 2
        records = f"data_uc{a}.mat"
        if total - r_fixed >= 0.0:
            out.append(MeasuredKey(f"nominal.current_amplifier.r_buffer_ohm.{a}",
                                   total - r_fixed, std, "Ohm", records,
                                   "the current amplifier's series resistance (1/Gi − R − Rc)"))
        else:  # less than R + Rc in all: R itself is smaller than the bench file's
            out.append(MeasuredKey(f"nominal.current_amplifier.r_ohm.{a}",
                                   total - params.sercalo.r_coil_ohm[a], std, "Ohm", records,
                                   "the current amplifier's resistor (1/Gi − Rc)"))
            out.append(MeasuredKey(f"nominal.current_amplifier.r_buffer_ohm.{a}", 0.0, 0.0,
                                   "Ohm", records, "the current amplifier's series resistance"))
    return out


def _newport_keys(js: Mapping[str, Any], *, params: BenchParams,
                  gd: Mapping[str, float]) -> list[MeasuredKey]:
    """The Newport's gain per axis, and its dynamics as the mean of the axes."""
    out: list[MeasuredKey] = []
    mn = newport_beam_matrix(params)
    for a, gn in (js.get("newport_gain_v_per_v") or {}).items():
        per = gd[a] * mn["hv".index(a), "hv".index(a)]
        out.append(MeasuredKey(f"nominal.newport.gain_rad_per_v.{a}", float(gn) / per,
                               abs(_std(js, f"newport_gain_v_per_v.{a}") / per), "rad/V",
                               f"data_un{a}.mat", "the Newport's gain (mirror angle per "
                                                  "command volt)"))
    dyn = js.get("newport") or {}
    if dyn and all(a in dyn for a in "hv"):
        for field, unit, what in (("natural_freq_hz", "Hz", "the Newport's natural frequency "
                                   "(mean of the axes)"),
                                  ("damping_ratio", "1", "the Newport's damping ratio (mean of "
                                   "the axes)"),
                                  ("internal_delay_s", "s", "the Newport's internal lag (mean "
                                   "of the axes)")):
            value, std = _mean_std([(float(dyn[a][field]), _std(js, f"newport.{a}.{field}"))
                                    for a in "hv"])
            out.append(MeasuredKey(f"nominal.newport.{field}", value, std, unit,
                                   "data_unh.mat, data_unv.mat", what))
    return out


def measured_keys(js: Mapping[str, Any], *, params: BenchParams) -> list[MeasuredKey]:
    """The identified values of ``identification.json`` as bench-file keys.

    Parameters
    ----------
    js : mapping
        ``Identification.to_json()`` (values and ``uncertainty``).
    params : BenchParams
        The nominal parameters the identification modelled the bench with (the
        bench file with the signs the records gave): the beam factors, the
        resistances and the converter a measured value is divided by.

    Returns
    -------
    list of MeasuredKey
        Only the keys whose value was identified.
    """
    out: list[MeasuredKey] = []
    qd = js.get("qd_gain_v_per_rad") or {}
    gd = {a: float(qd.get(a, params.quad_diode.gain_v_per_rad[a])) for a in "hv"}
    for a in qd:
        out.append(MeasuredKey(f"nominal.quad_diode.gain_v_per_rad.{a}", float(qd[a]),
                               _std(js, f"qd_gain_v_per_rad.{a}"), "V/rad",
                               f"data_cal_pd_{a}.mat", "the 4QD gain"))
    out += _amplifier_keys(js, params=params)
    beam = params.sercalo.beam_angle_per_mirror_angle
    for a, node in (js.get("sercalo") or {}).items():
        records = f"data_uc{a}.mat"
        out.append(MeasuredKey(f"nominal.sercalo.resonance_hz.{a}", float(node["resonance_hz"]),
                               _std(js, f"sercalo.{a}.resonance_hz"), "Hz", records,
                               "the Sercalo's resonance"))
        out.append(MeasuredKey(f"nominal.sercalo.damping_ratio.{a}",
                               float(node["damping_ratio"]),
                               _std(js, f"sercalo.{a}.damping_ratio"), "1", records,
                               "the Sercalo's damping ratio"))
        # Ich → Vph static = Gd · beam · g0 (the mode's static gain, rad per A).
        per = gd[a] * beam[a]
        out.append(MeasuredKey(f"nominal.sercalo.dc_gain_rad_per_a.{a}",
                               abs(float(node["dc_gain_v_per_a"]) / per),
                               abs(_std(js, f"sercalo.{a}.dc_gain_v_per_a") / per), "rad/A",
                               records, "the Sercalo's static gain (mirror angle per coil "
                                        "current)"))
    out += _newport_keys(js, params=params, gd=gd)
    pure = (js.get("delay_s") or {}).get("sercalo")
    if pure is not None:
        conv = params.converter
        extra = float(pure) - (conv.dac_delay_samples + 0.5) / conv.fs_hz
        if extra >= -0.25 / conv.fs_hz:  # a whole sample less is another DAC, not a latency
            out.append(MeasuredKey("nominal.converter.dac_extra_delay_s", max(extra, 0.0),
                                   _std(js, "delay_s.sercalo"), "s",
                                   "data_uch.mat, data_ucv.mat",
                                   "the converter's latency beyond its whole-sample delay and "
                                   "half a sample of hold"))
    return out


def _relevant(key: str, fs_hz: float) -> tuple[float, bool]:
    """(threshold, relative?) below which a departure does not matter."""
    base = ".".join(_split(key)[:2])
    if base in _SAMPLES:
        return _SAMPLES[base] / fs_hz, False
    return _RELATIVE.get(base, 0.03), True


def departures(measured: Iterable[MeasuredKey], *, bench_file: BenchParams,
               fs_hz: float) -> list[Finding]:
    """The measured keys away from the bench file by more than matters and than their std.

    Parameters
    ----------
    measured : iterable of MeasuredKey
    bench_file : BenchParams
        The user's bench file's nominal parameters (before the records' signs).
    fs_hz : float
        The records' rate [Hz] (a delay's half sample).
    """
    out = []
    for m in measured:
        bench = get_key(bench_file, m.key)
        threshold, relative = _relevant(m.key, fs_hz)
        diff = m.value - bench
        limit = threshold * abs(bench) if relative and bench != 0 else threshold
        if abs(diff) <= limit or (np.isfinite(m.std) and abs(diff) <= _SIGMAS * m.std):
            continue
        ratio = (f"{m.value / bench:.3g}× the bench file's" if relative and bench != 0
                 else f"{diff:+.3g} {m.unit} from the bench file's")
        out.append(Finding(m.key, bench, m.value, m.unit, m.records,
                           f"{m.what} is {ratio}", m.std if np.isfinite(m.std) else 0.0))
    return out


def matching_params(bench_file: BenchParams, measured: Iterable[MeasuredKey],
                    signs: Iterable[Finding] = ()) -> BenchParams:
    """The bench file with every measured key and sign set: what the records describe
    (findings on other tables than ``nominal``, the datasheet's, are left out)."""
    out = bench_file
    for f in signs:
        if f.key.startswith("nominal."):
            out = set_key(out, f.key, f.measured)
    for m in measured:
        out = set_key(out, m.key, m.value)
    return out



def datasheet_departures(checks: Iterable[Check], *, datasheet: NewportDatasheet
                         ) -> list[Finding]:
    """The Newport's datasheet checks that failed, as findings on ``datasheet.newport.*``.

    A mirror whose bandwidth or peaking is off its datasheet's is this bench's mirror
    (its tuning, or another unit): a finding with the value the records give (the axes'
    mean; each axis's in the words), not a fault of the records.
    """
    by_name: dict[str, list[Check]] = {}
    for c in checks:
        if not c.passed and c.name in _DATASHEET_KEYS and isinstance(c.value, float):
            by_name.setdefault(c.name, []).append(c)
    out = []
    for name, failed in by_name.items():
        field = _DATASHEET_KEYS[name]
        bench = float(getattr(datasheet, field))
        value = float(np.mean([float(c.value) for c in failed if isinstance(c.value, float)]))
        unit = failed[0].unit
        axes = "; ".join(f"{c.subject} {c.value_words()}" for c in failed)
        out.append(Finding(f"datasheet.newport.{field}", bench, value, unit,
                           "data_unh.mat, data_unv.mat",
                           f"the Newport departs from its FSM-300 datasheet ({failed[0].title}: "
                           f"{axes}): its controller's tuning, or another unit; check it before "
                           "trusting a closed-loop prediction that assumes the datasheet"))
    return out


def matching_datasheet(datasheet: Datasheet, findings: Iterable[Finding]) -> Datasheet:
    """The datasheet tables with the ``datasheet.newport.*`` findings' values."""
    newport = datasheet.newport
    for f in findings:
        if f.key.startswith("datasheet.newport."):
            newport = dataclasses.replace(newport, **{f.key.rsplit(".", 1)[1]: f.measured})
    return dataclasses.replace(datasheet, newport=newport)


def merged_findings(signs: tuple[Finding, ...], values: list[Finding]) -> tuple[Finding, ...]:
    """One finding per key: a value's departure on a key whose sign the records also gave
    keeps the sign's words and alternatives."""
    by_key = {f.key: f for f in signs}
    for f in values:
        sign = by_key.get(f.key)
        by_key[f.key] = f if sign is None else replace(
            f, message=f"{sign.message}; {f.message}", alternatives=sign.alternatives)
    return tuple(by_key.values())
