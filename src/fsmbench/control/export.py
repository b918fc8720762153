"""Controllers for MATLAB and for a real-time target (ESRF study 9.3, 10.3).

* :func:`write_controllers_mat`: ``controllers.mat`` with one struct per
  controller, each holding the continuous ``K`` and the discrete ``Kd`` as
  structs of state-space matrices (``A, B, C, D, InputName, OutputName, Ts``),
  as the ESRF study's ``save('mat/K_diag.mat', 'K', 'Kd')`` keeps them, plus an
  ``fsmbench`` struct saying how ``Kd`` was made and the 4QD gain.
  ``fsmbench_load.m`` (shipped with the package) turns them into ``ss``.
* :func:`sos_document` / :func:`write_sos_json`: each diagonal channel as
  discrete second-order sections, the form an IIR filter on the real-time
  target runs, with the signals, their units, the scaling from the measured
  4QD voltage to the controller's input and the response the sections must
  reproduce at a few frequencies.

Discretisation (:data:`DISCRETISATIONS`): by default ``"tustin_prewarp"``:
each continuous section (:func:`fsmbench.bench.sections.sections_from_zpk`)
is discretised by Tustin prewarped at its own notch (or resonance) frequency,
so every notch stays exactly in place; plain Tustin (the ESRF study's
``c2d(K, 1e-4, 'tustin')``) moves the ESRF study's 411.5 Hz notch to 409.3 Hz
(errata E26). ``"tustin"`` gives the ESRF study's version.

Sign: every controller here is closed as ``u = -K y`` (the ESRF study's
``connect(sys, -K, ...)``); a target computes the sections' output and
applies its negative.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import control as ct
import numpy as np
from scipy import signal
from scipy.linalg import eigvals

from fsmbench.atomic import atomic_write_text
from fsmbench.bench.esrf import ESRF_TS_S, tustin
from fsmbench.bench.sections import (
    DiscreteSection,
    Section,
    section_response,
    sections_from_zpk,
    structural_states,
    tustin_cascade,
    tustin_section,
    warped_frequency_rad_s,
)
from fsmbench.control.antiwindup import DEFAULT_TRACKING_TIME_S, antiwindup_channel
from fsmbench.control.export_check import float32_sos_check, float32_state_space_check
from fsmbench.io.matwrite import save_mat
from fsmbench.version import __version__

__all__ = [
    "DAC_RAILS_V",
    "DEFAULT_DISCRETISATION",
    "DISCRETISATIONS",
    "SOS_FORMAT",
    "SOS_FORMAT_VERSION",
    "InputScaling",
    "channel_sections",
    "discretise",
    "discretise_channel",
    "implementation_note",
    "siso_zpk",
    "sos_document",
    "sos_response",
    "state_space_struct",
    "tustin_sos",
    "write_controllers_mat",
    "write_sos_json",
]

SOS_FORMAT = "fsmbench.controllers_sos"
SOS_FORMAT_VERSION = 2

DEFAULT_DISCRETISATION = "tustin_prewarp"
#: Discretisation methods and what the documents say about them.
DISCRETISATIONS: dict[str, str] = {
    "tustin_prewarp": "Tustin (bilinear) per second-order section, each prewarped at its own "
                      "notch frequency (lightly damped complex zero pair, damping ratio < 0.2) "
                      "or else resonance frequency (lightly damped complex pole pair), so the "
                      "section's discrete response equals its continuous one exactly there and "
                      "every notch stays in place; other sections: plain Tustin",
    "tustin": "Tustin (bilinear), no prewarping (the ESRF study's c2d(K, Ts, 'tustin')); "
              "notches move down in frequency (errata E26)",
}

AXES = ("h", "v")
# What a real-time target reads, per controller input: the 4QD output.
_MEASURED = {"Rh": "Vph", "Rv": "Vpv"}
_SIGNALS: dict[str, tuple[str, str]] = {
    "Rh": ("rad", "beam angle, horizontal"),
    "Rv": ("rad", "beam angle, vertical"),
    "Vph": ("V", "4QD output, horizontal"),
    "Vpv": ("V", "4QD output, vertical"),
    "Uch": ("V", "Sercalo command (DAC output), horizontal"),
    "Ucv": ("V", "Sercalo command (DAC output), vertical"),
    "Unh": ("V", "Newport command (DAC output), horizontal"),
    "Unv": ("V", "Newport command (DAC output), vertical"),
    "Vch": ("V", "Sercalo force-sensor voltage, horizontal"),
    "Vcv": ("V", "Sercalo force-sensor voltage, vertical"),
}
#: The DAC's rails the commands are clipped to [V] (ESRF study 1.6: 16 bit over -10 .. +10 V).
DAC_RAILS_V = (-10.0, 10.0)
_CHECK_F_HZ = (1.0, 10.0, 100.0, 1000.0)  # response stated at these, plus each prewarp frequency


@dataclass(frozen=True)
class InputScaling:
    """From the measured 4QD voltage to the controllers' input, ``R = Vp / Gd``.

    Attributes
    ----------
    qd_gain_v_per_rad : tuple of 2 floats
        Diagonal of ``Gd`` (h, v) [V/rad], sign included, of the plant the
        controllers were designed on.
    plant_source : str
        That plant, e.g. ``"identified (...)"`` or ``"physical (nominal)"``.
    """

    qd_gain_v_per_rad: tuple[float, float]
    plant_source: str

    @property
    def plant_kind(self) -> str:
        """``"identified"``, ``"nominal"`` or the plant source itself."""
        src = self.plant_source.lower()
        if src.startswith("identified"):
            return "identified"
        return "nominal" if "nominal" in src else self.plant_source

    def to_json(self) -> dict[str, Any]:
        """Gains, their inverse and where they come from, h/v as ``{"h": …, "v": …}``."""
        gd = dict(zip(AXES, (float(x) for x in self.qd_gain_v_per_rad), strict=True))
        return {
            "rule": "R [rad] = Vp [V] / Gd [V/rad]: multiply the measured 4QD output by "
                    "input_scale_rad_per_v before the first section",
            "qd_gain_v_per_rad": gd,
            "input_scale_rad_per_v": {a: 1.0 / g for a, g in gd.items()},
            "qd_gain_from": self.plant_kind,
            "plant_source": self.plant_source,
        }


def _check_method(method: str) -> None:
    if method not in DISCRETISATIONS:
        raise ValueError(f"unknown discretisation {method!r}; use one of "
                         + ", ".join(repr(m) for m in DISCRETISATIONS))


def state_space_struct(sys: ct.StateSpace, *, description: str = "") -> dict[str, Any]:
    """MATLAB struct fields of a state-space model: ``A, B, C, D, InputName, OutputName, Ts``.

    ``Ts`` is 0 for a continuous model (MATLAB's convention).
    """
    dt = sys.dt
    ts = 0.0 if dt in (None, 0) or dt is True else float(dt)
    n = sys.nstates
    return {
        "A": np.asarray(sys.A, dtype=float).reshape(n, n),
        "B": np.asarray(sys.B, dtype=float).reshape(n, sys.ninputs),
        "C": np.asarray(sys.C, dtype=float).reshape(sys.noutputs, n),
        "D": np.asarray(sys.D, dtype=float).reshape(sys.noutputs, sys.ninputs),
        "InputName": [str(x) for x in sys.input_labels],
        "OutputName": [str(x) for x in sys.output_labels],
        "Ts": ts,
        "Description": description,
    }


def siso_zpk(sys: ct.StateSpace, *, output: int = 0,
             input: int = 0) -> tuple[np.ndarray, np.ndarray, float]:
    """Zeros, poles [rad/s] and leading coefficient of one channel of a continuous model.

    The channel keeps only the states structurally reachable from its input
    and observable from its output (exact for block-diagonal controllers such
    as ``control.append`` of SISO cascades, with no numerical cancellation).
    Zeros are the finite generalised eigenvalues of its system pencil; roots
    within 1e-7 of the largest root's modulus from the origin are set to 0
    (integrators); the gain is matched at one point away from every root.
    """
    a_full = np.asarray(sys.A, dtype=float)
    keep = structural_states(a_full, np.asarray(sys.B, dtype=float)[:, input],
                              np.asarray(sys.C, dtype=float)[output, :])
    a = a_full[np.ix_(keep, keep)]
    b = np.asarray(sys.B, dtype=float)[keep][:, [input]]
    c = np.asarray(sys.C, dtype=float)[[output]][:, keep]
    d = np.asarray(sys.D, dtype=float)[[output]][:, [input]]
    n = a.shape[0]
    if n == 0:
        return np.zeros(0, dtype=complex), np.zeros(0, dtype=complex), float(d[0, 0])
    poles = np.linalg.eigvals(a).astype(complex)
    pencil = np.block([[a, b], [c, d]])
    e = np.zeros_like(pencil)
    e[:n, :n] = np.eye(n)
    z = eigvals(pencil, e)
    zeros = z[np.isfinite(z) & (np.abs(z) < 1e12)].astype(complex)
    scale = float(np.max(np.abs(np.concatenate([poles, zeros, [1.0]]))))
    poles[np.abs(poles) < 1e-7 * scale] = 0.0
    zeros[np.abs(zeros) < 1e-7 * scale] = 0.0
    s0 = 1j * 1.2345 * scale
    val = complex((c @ np.linalg.solve(s0 * np.eye(n) - a, b) + d)[0, 0])
    k = val * np.prod(s0 - poles) / np.prod(s0 - zeros)
    if abs(k.imag) > 1e-6 * abs(k):
        raise ValueError(f"channel gain is not real: {k}")
    return zeros, poles, float(k.real)


def channel_sections(sys: ct.StateSpace, *, output: int = 0, input: int = 0) -> list[Section]:
    """Continuous first- and second-order sections of one channel (gain in the first).

    A static or zero channel gives one section without roots.
    """
    z, p, k = siso_zpk(sys, output=output, input=input)
    sections = sections_from_zpk(list(z), list(p), k) if len(p) else []
    return sections or [Section(zeros=(), poles=(), gain=k)]


def discretise_channel(sys: ct.StateSpace, *, ts_s: float = ESRF_TS_S, output: int = 0,
                       input: int = 0,
                       method: str = DEFAULT_DISCRETISATION) -> list[DiscreteSection]:
    """Discrete sections of one channel of a continuous model.

    Parameters
    ----------
    sys : control.StateSpace
        Continuous model.
    ts_s : float
        Sample time [s].
    output, input : int
        Channel.
    method : {"tustin_prewarp", "tustin"}
        See :data:`DISCRETISATIONS`.
    """
    _check_method(method)
    return [tustin_section(sec, ts_s=ts_s, prewarp=method == "tustin_prewarp")
            for sec in channel_sections(sys, output=output, input=input)]


def tustin_sos(sys: ct.StateSpace, *, ts_s: float = ESRF_TS_S, output: int = 0,
               input: int = 0, method: str = DEFAULT_DISCRETISATION) -> np.ndarray:
    """Second-order sections ``[b0, b1, b2, 1, a1, a2]`` of one discretised channel.

    Returns
    -------
    array, shape (n_sections, 6)
        In ``z^-1``; the overall gain sits in the first section (scipy's convention).
    """
    secs = discretise_channel(sys, ts_s=ts_s, output=output, input=input, method=method)
    return np.array([s.sos for s in secs], dtype=float)


def discretise(k: ct.StateSpace, *, ts_s: float = ESRF_TS_S,
               method: str = DEFAULT_DISCRETISATION) -> ct.StateSpace:
    """Discrete controller with ``k``'s signal names (``dt = ts_s``).

    ``"tustin"`` discretises the whole model (:func:`fsmbench.bench.esrf.tustin`);
    ``"tustin_prewarp"`` cascades each diagonal channel's prewarped sections
    (off-diagonal channels must be zero).
    """
    _check_method(method)
    if method == "tustin":
        return tustin(k, ts_s=ts_s)
    _check_diagonal(k, str(k.name))
    parts = [tustin_cascade(channel_sections(k, output=i, input=i), ts_s=ts_s, prewarp=True)
             for i in range(k.ninputs)]
    kd = ct.append(*parts) if len(parts) > 1 else parts[0]
    return ct.ss(kd.A, kd.B, kd.C, kd.D, ts_s, inputs=list(k.input_labels),
                 outputs=list(k.output_labels), name=f"{k.name}d" if k.name else None)


def write_controllers_mat(path: str | Path, controllers: Mapping[str, ct.StateSpace], *,
                          ts_s: float = ESRF_TS_S, method: str = DEFAULT_DISCRETISATION,
                          descriptions: Mapping[str, str] | None = None,
                          scaling: InputScaling | None = None) -> Path:
    """Write ``controllers.mat``: per controller a struct ``{K, Kd}``, plus ``fsmbench`` meta.

    Parameters
    ----------
    path : str or Path
        Destination (written atomically).
    controllers : mapping of name to control.StateSpace
        Continuous controllers; names must be MATLAB identifiers.
    ts_s : float
        Sample time of ``Kd`` [s].
    method : {"tustin_prewarp", "tustin"}
        Discretisation of ``Kd`` (:data:`DISCRETISATIONS`).
    descriptions : mapping of name to str, optional
    scaling : InputScaling, optional
        The 4QD gain, recorded in the meta struct.
    """
    _check_method(method)
    desc = dict(descriptions or {})
    variables: dict[str, Any] = {}
    float32: dict[str, Any] = {}
    for name, k in controllers.items():
        text = desc.get(name, "")
        kd = discretise(k, ts_s=ts_s, method=method)
        variables[name] = {"K": state_space_struct(k, description=text),
                           "Kd": state_space_struct(kd, description=text)}
        # Each diagonal channel of Kd rounded to float32 (the MAT-file is for float64 tools).
        float32[name] = {
            str(kd.output_labels[i]): float32_state_space_check(
                kd.A, np.asarray(kd.B)[:, [i]], np.asarray(kd.C)[[i]],
                np.asarray(kd.D)[[i]][:, [i]], ts_s=ts_s).sentence()
            for i in range(min(kd.ninputs, kd.noutputs))}
    meta: dict[str, Any] = {"version": __version__, "Ts": float(ts_s),
                            "discretisation": method,
                            "discretisation_text": DISCRETISATIONS[method],
                            "feedback": "u = -K y", "controllers": list(controllers),
                            "float32_Kd": float32,
                            "implementation_note": "Kd is for float64 tools (MATLAB, Octave); "
                                                   "a real-time target runs controllers_sos.json "
                                                   "(its implementation_note: section order, "
                                                   "float32 check, anti-windup)"}
    if scaling is not None:
        meta["qd_gain_v_per_rad"] = {a: float(g) for a, g in
                                     zip(AXES, scaling.qd_gain_v_per_rad, strict=True)}
        meta["plant_source"] = scaling.plant_source
    variables["fsmbench"] = meta
    return save_mat(path, variables)


def _signal(name: str) -> dict[str, str]:
    unit, words = _SIGNALS.get(name, ("", name))
    return {"name": name, "unit": unit, "description": words}


def _complex_lists(h: np.ndarray) -> dict[str, list[float]]:
    return {"real": [float(x) for x in h.real], "imag": [float(x) for x in h.imag]}


def _channel_entry(k: ct.StateSpace, i: int, *, ts_s: float, method: str,
                   scaling: InputScaling, tracking_time_s: float) -> dict[str, Any]:
    inp, outp = str(k.input_labels[i]), str(k.output_labels[i])
    if inp not in _MEASURED:
        raise ValueError(f"controller input {inp!r} is not a beam angle (Rh, Rv); the SOS "
                         "document scales from the 4QD output")
    secs = discretise_channel(k, ts_s=ts_s, output=i, input=i, method=method)
    sos = np.array([s.sos for s in secs], dtype=float)
    warps = [s.prewarp_rad_s for s in secs]
    nyq = 0.5 / ts_s
    f = np.array(sorted({*(x for x in _CHECK_F_HZ if x < nyq),
                         *(w / (2 * np.pi) for w in warps if w is not None)}))
    w = 2 * np.pi * f
    # Stated discrete response from the continuous sections at their warped frequencies
    # (H_d(exp(j w Ts)) = H_c(j w')): independent of the coefficients it describes.
    hd = np.ones(len(f), dtype=complex)
    for s in secs:
        hd = hd * section_response(s.continuous,
                                   1j * warped_frequency_rad_s(w, ts_s=ts_s,
                                                               prewarp_rad_s=s.prewarp_rad_s))
    a, b, c, d = (np.asarray(x, dtype=float) for x in (k.A, k.B, k.C, k.D))
    n = a.shape[0]
    hc = np.array([(c[i] @ np.linalg.solve(1j * x * np.eye(n) - a, b[:, i]) if n else 0.0)
                   + d[i, i] for x in w])
    scale = 1.0 / float(scaling.qd_gain_v_per_rad[i])
    return {
        "measured_signal": _signal(_MEASURED[inp]),
        "input_signal": _signal(inp),
        "input_scale_rad_per_v": scale,
        "output_signal": _signal(outp),
        "steps": f"x = {scale:.9g} rad/V * {_MEASURED[inp]}; y = sections(x) in order; "
                 f"{outp} = -y (u = -K y)",
        "n_sections": len(secs),
        "sos": [list(s.sos) for s in secs],
        "prewarp_frequency_hz": [None if x is None else x / (2 * np.pi) for x in warps],
        "response_v_per_rad": {"f_hz": [float(x) for x in f],
                               "discrete": _complex_lists(hd),
                               "continuous": _complex_lists(hc)},
        "float32": float32_sos_check(sos, ts_s=ts_s).to_json(),
        "antiwindup": antiwindup_channel(sos, ts_s=ts_s,
                                         tracking_time_s=tracking_time_s).to_json(),
    }


def sos_document(controllers: Mapping[str, ct.StateSpace], *, scaling: InputScaling,
                 ts_s: float = ESRF_TS_S, method: str = DEFAULT_DISCRETISATION,
                 descriptions: Mapping[str, str] | None = None,
                 dac_rails_v: tuple[float, float] = DAC_RAILS_V,
                 tracking_time_s: float = DEFAULT_TRACKING_TIME_S) -> dict[str, Any]:
    """JSON-ready SOS description of the diagonal channels of each controller.

    Parameters
    ----------
    controllers : mapping of name to control.StateSpace
        Continuous, ``Rh, Rv`` [rad] to two commands [V], off-diagonal channels zero.
    scaling : InputScaling
        The 4QD gain of the plant they were designed on.
    ts_s : float
        Sample time [s].
    method : {"tustin_prewarp", "tustin"}
        See :data:`DISCRETISATIONS`.
    descriptions : mapping of name to str, optional
    dac_rails_v : (float, float)
        The DAC's rails [V], where the anti-windup acts.
    tracking_time_s : float
        Back-calculation tracking time [s] (:mod:`fsmbench.control.antiwindup`).

    Returns
    -------
    dict
        ``format``, ``format_version``, ``discretisation``, ``input_scaling``,
        ``dac_rails_v``, per controller and axis (``h``, ``v``) the signals,
        ``sos``, ``prewarp_frequency_hz``, ``response_v_per_rad`` (the sections'
        response and the continuous controller's at a few frequencies),
        ``float32`` (:class:`fsmbench.control.export_check.Float32Check`) and
        ``antiwindup`` (the sections reordered integrators last and the
        back-calculation gain on their registers); and ``implementation_note``
        (list of lines: :func:`implementation_note`).
    """
    _check_method(method)
    desc = dict(descriptions or {})
    out: dict[str, Any] = {
        "format": SOS_FORMAT, "format_version": SOS_FORMAT_VERSION,
        "fsmbench_version": __version__, "sample_time_s": float(ts_s),
        "discretisation": {"method": method, "description": DISCRETISATIONS[method]},
        "section_layout": ["b0", "b1", "b2", "a0", "a1", "a2"],
        "difference_equation": "a0 y[k] = b0 x[k] + b1 x[k-1] + b2 x[k-2] - a1 y[k-1] - a2 y[k-2]",
        "feedback": "u = -K y: apply the negative of the cascade's output to the command",
        "input_scaling": scaling.to_json(),
        "dac_rails_v": {"min": float(dac_rails_v[0]), "max": float(dac_rails_v[1])},
        "controllers": {},
    }
    for name, k in controllers.items():
        _check_diagonal(k, name)
        if k.ninputs != len(AXES):
            raise ValueError(f"controller {name!r} has {k.ninputs} inputs; expected h and v")
        entry: dict[str, Any] = {"description": desc.get(name, "")}
        for i, axis in enumerate(AXES):
            entry[axis] = _channel_entry(k, i, ts_s=ts_s, method=method, scaling=scaling,
                                         tracking_time_s=tracking_time_s)
        out["controllers"][name] = entry
    out["implementation_note"] = implementation_note(
        out, dac_rails_v=dac_rails_v, tracking_time_s=tracking_time_s)
    return out


def write_sos_json(path: str | Path, controllers: Mapping[str, ct.StateSpace], *,
                   scaling: InputScaling, ts_s: float = ESRF_TS_S,
                   method: str = DEFAULT_DISCRETISATION,
                   descriptions: Mapping[str, str] | None = None,
                   dac_rails_v: tuple[float, float] = DAC_RAILS_V,
                   tracking_time_s: float = DEFAULT_TRACKING_TIME_S) -> Path:
    """Write :func:`sos_document` as JSON, atomically."""
    doc = sos_document(controllers, scaling=scaling, ts_s=ts_s, method=method,
                       descriptions=descriptions, dac_rails_v=dac_rails_v,
                       tracking_time_s=tracking_time_s)
    return atomic_write_text(path, json.dumps(doc, indent=1, allow_nan=False) + "\n")


def _check_diagonal(k: ct.StateSpace, name: str) -> None:
    n = min(k.ninputs, k.noutputs)
    f = np.array([1.0, 37.0, 400.0])
    s = 2j * np.pi * f
    a = np.asarray(k.A, dtype=float)
    b = np.asarray(k.B, dtype=float)
    c = np.asarray(k.C, dtype=float)
    d = np.asarray(k.D, dtype=float)
    for x in s:
        h = c @ np.linalg.solve(x * np.eye(a.shape[0]) - a, b) + d if a.size else d
        off = h - np.diag(np.diag(h[:n, :n]))
        if np.max(np.abs(off)) > 1e-12 * max(np.max(np.abs(h)), 1e-300):
            raise ValueError(f"controller {name!r} is not diagonal; SOS export needs SISO channels")


def sos_response(sos: Sequence[Sequence[float]], f_hz: np.ndarray, *,
                 ts_s: float = ESRF_TS_S) -> np.ndarray:
    """Frequency response of a cascade of sections at ``f_hz`` (for checks), shape (n,)."""
    _, h = signal.sosfreqz(np.asarray(sos, dtype=float), worN=np.asarray(f_hz, dtype=float),
                           fs=1.0 / ts_s)
    return np.asarray(h)


def implementation_note(doc: Mapping[str, Any], *, dac_rails_v: tuple[float, float],
                        tracking_time_s: float) -> list[str]:
    """Lines a target's programmer reads first: form, rate, order, float32, anti-windup, rails.

    Parameters
    ----------
    doc : mapping
        A :func:`sos_document` with its ``controllers`` filled in.
    dac_rails_v : (float, float)
        The DAC's rails [V].
    tracking_time_s : float
        Back-calculation tracking time [s].
    """
    ts = float(doc["sample_time_s"])
    lines = [
        f"Form: cascaded second-order sections per axis, direct form II transposed "
        f"(scipy.signal.sosfilt's recursion: y = b0 w + s1; s1 <- s2 + b1 w - a1 y; "
        f"s2 <- b2 w - a2 y), at {1.0 / ts:g} Hz (Ts = {ts:g} s); the overall gain is in "
        "section 0; sections commute, so 'antiwindup.sos_integrators_last' is the same "
        "filter with the integrator sections (denominator 1 - 2 z^-1 + z^-2) last.",
        "State order: section by section in the listed order, two registers (s1, s2) each "
        "(one for a first-order section).",
        f"DAC limits: {dac_rails_v[0]:g} V .. {dac_rails_v[1]:g} V on every command.",
        f"Anti-windup (back-calculation): with the sections in 'sos_integrators_last' order, "
        f"compute v = the cascade's output, the command u = -v and u_applied = clip(u, "
        f"rails), what the DAC applies; after every section's usual update add each "
        f"integrator_registers entry's gain * (u - u_applied) to its register (zero while u "
        f"is within the rails). "
        f"Tracking time {tracking_time_s:g} s: saturated, the integrators' poles sit at "
        f"exp(-i Ts / Tt), i = 1..n.",
    ]
    for name, entry in doc["controllers"].items():
        for axis in ("h", "v"):
            f32 = entry[axis]["float32"]
            verdict = "passes" if f32["passes"] else "does NOT pass"
            bound = ("any |T|" if f32["t_peak_bound"] is None
                     else f"|T| < {f32['t_peak_bound']:.3g}")
            lines.append(
                f"float32, {name} {axis}: coefficients rounded to float32 give a response within "
                f"{f32['max_relative_error']:.2g} relative and {f32['max_phase_error_deg']:.2g} "
                f"deg of float64 ({f32['f_min_hz']:g}-{f32['f_max_hz']:.4g} Hz, worst at "
                f"{f32['worst_f_hz']:.3g} Hz); integrators stay on z = 1: "
                f"{'yes' if f32['integrators_exact'] else 'no'}; other poles stay inside the "
                f"unit circle: {'yes' if f32['stable_poles_kept'] else 'no'}; a loop with "
                f"{bound} stays stable; {verdict} the "
                f"{f32['tolerance']:g} tolerance. Arithmetic roundoff was not simulated.")
    return lines
