"""The study's thirteen recordings, run on one bench as a careful experimenter would.

Protocols (ESRF study sections 2, 3, 11): each record starts with a quiet
lead-in (the Sercalo being switched on, study 2.1's ``t0``), then

* ``data_cal_pd_h/v`` (2.1): a slow 0.2 Hz Newport sine on one axis, ``Vnh``
  / ``Vnv`` recorded with the 4QD;
* ``data_uch/ucv`` (2.2, 2.3): white noise on one Sercalo command; its level is
  small because the coil monitor ``Vc`` (gain ~1000 on ``R_c / R_tot``) must
  not clip and the spot must stay within the 4QD's linear range;
* ``data_unh/unv`` (2.4): white noise on one Newport command;
* huddle tests 1–5 (3): nothing commanded, 101 s; 3 and 5 with the 9.2 loop
  closed; the compensation unit from 2 on, the aluminium on 4 and 5;
* ``data_rep_h/v`` (11): the loop closed, a 1 Hz Newport sine on one axis, 42 s.

Levels: every noise excitation is Gaussian, clipped at 4.5 sigma, its rms
chosen from the exact stationary rms of the bench's outputs so that 5 sigma
of every recorded ADC channel stays below 8 V and 5 sigma of the beam within
the 4QD's linear range ``qd_compression_swing_rad``; sines likewise. The
commands are on the DAC's grid, so the recorded command is what was played.

Closed loops (:mod:`indsim.control`): the converters' rounding inside the
loop is additive uniform noise of one step, and the recorded ``Uc``/``Vp``
are rounded to the grid; the 4QD's cubic compression is left out there (the
loop holds the beam within tens of µrad, where it is below 1e-5 relative:
``realized.<record>.qd_compression_max`` says how much).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .attocube import attocube
from .control import CL_INPUTS, CL_OUTPUTS
from .lti import delayed_inputs, simulate
from .model import BenchModel, output_rms_per_unit_input, qd_amp_response
from .noise import flicker, quantise, uniform_lsb
from .plant import INPUTS, OUTPUTS

__all__ = ["EXPERIMENTS", "Protocol", "Record", "run_experiment"]

Array = NDArray[np.float64]

_HUDDLE = ("t", "Vph", "Vpv", "Va")
_HUDDLE_CL = ("t", "Uch", "Ucv", "Vph", "Vpv", "Va")
_REPEAT = ("t", "Uch", "Ucv", "Unh", "Unv", "Vph", "Vpv", "Vnh", "Vnv", "Va")

ADC_PEAK_V = 8.0  # what the experimenter allows a channel: 2 V of margin to the rails
CREST = 5.0  # sigma of a stationary output kept under ADC_PEAK_V
CLIP_SIGMA = 4.5  # the excitation generator's clipping
MIN_DURATION_S = 3.0


@dataclass(frozen=True)
class Protocol:
    """One recording of the study.

    Parameters
    ----------
    name : str
        File stem.
    variables : tuple of str
        Variables the file holds, ``t`` first.
    duration_s : float
        Length at the study's scale [s].
    section : str
        Study section.
    description : str
        What is done.
    closed_loop : bool
        The 9.2 loop runs.
    excite : str
        Commanded channel (``""`` none).
    kind : str
        ``"noise"``, ``"sine"`` or ``""``.
    freq_hz : float
        Sine frequency [Hz].
    compensation_unit, shielding : bool
        Huddle configuration (study Table 3); the compensation unit is on from
        test 2 on, and stays on for the repeatability runs.
    """

    name: str
    variables: tuple[str, ...]
    duration_s: float
    section: str
    description: str
    closed_loop: bool = False
    excite: str = ""
    kind: str = ""
    freq_hz: float = 0.0
    compensation_unit: bool = True
    shielding: bool = False


EXPERIMENTS: dict[str, Protocol] = {p.name: p for p in (
    Protocol("data_cal_pd_h", ("t", "Vph", "Vpv", "Vnh"), 11.0, "2.1",
             "4QD calibration: slow Newport sine on Unh", excite="Unh", kind="sine",
             freq_hz=0.2),
    Protocol("data_cal_pd_v", ("t", "Vph", "Vpv", "Vnv"), 11.0, "2.1",
             "4QD calibration: slow Newport sine on Unv", excite="Unv", kind="sine",
             freq_hz=0.2),
    Protocol("data_uch", ("t", "Uch", "Vch", "Vph", "Vpv"), 31.0, "2.2, 2.3",
             "white noise on Uch", excite="Uch", kind="noise"),
    Protocol("data_ucv", ("t", "Ucv", "Vcv", "Vph", "Vpv"), 31.0, "2.2, 2.3",
             "white noise on Ucv", excite="Ucv", kind="noise"),
    Protocol("data_unh", ("t", "Unh", "Vph", "Vpv"), 33.0, "2.4",
             "white noise on Unh", excite="Unh", kind="noise"),
    Protocol("data_unv", ("t", "Unv", "Vph", "Vpv"), 32.0, "2.4",
             "white noise on Unv", excite="Unv", kind="noise"),
    Protocol("data_huddle_test_1", _HUDDLE, 101.0, "3", "huddle test 1: open loop",
             compensation_unit=False),
    Protocol("data_huddle_test_2", _HUDDLE, 101.0, "3",
             "huddle test 2: open loop, compensation unit"),
    Protocol("data_huddle_test_3", _HUDDLE_CL, 101.0, "3",
             "huddle test 3: closed loop, compensation unit", closed_loop=True),
    Protocol("data_huddle_test_4", _HUDDLE, 101.0, "3",
             "huddle test 4: open loop, compensation unit, aluminium", shielding=True),
    Protocol("data_huddle_test_5", _HUDDLE_CL, 101.0, "3",
             "huddle test 5: closed loop, compensation unit, aluminium",
             closed_loop=True, shielding=True),
    Protocol("data_rep_h", _REPEAT, 42.0, "11",
             "repeatability: loop closed, 1 Hz Newport sine on Unh", closed_loop=True,
             excite="Unh", kind="sine", freq_hz=1.0),
    Protocol("data_rep_v", _REPEAT, 42.0, "11",
             "repeatability: loop closed, 1 Hz Newport sine on Unv", closed_loop=True,
             excite="Unv", kind="sine", freq_hz=1.0),
)}


@dataclass(frozen=True)
class Record:
    """One simulated recording.

    Parameters
    ----------
    name : str
        File stem.
    signals : dict
        Variable -> samples (``t`` [s], ``Va`` [m], the rest [V]).
    protocol : dict
        What was run (durations, excitation level), JSON-ready.
    realized : dict
        Noise levels and ``Va`` parts measured on this record, JSON-ready.
    """

    name: str
    signals: dict[str, Array]
    protocol: dict[str, Any]
    realized: dict[str, Any] = field(default_factory=dict)


def durations(protocol: Protocol, duration_scale: float) -> tuple[float, float]:
    """Record length and quiet lead-in [s] at ``duration_scale``."""
    total = max(protocol.duration_s * duration_scale, MIN_DURATION_S)
    lead = min(1.0, max(0.3, 1.0 * duration_scale))
    return total, lead


def _noise_level(model: BenchModel, channel: str) -> tuple[float, str]:
    """Rms of a white excitation on ``channel`` that keeps every record in range [V].

    Returns the level and what limits it.
    """
    b = model.bench
    per_unit = output_rms_per_unit_input(model.sampled, channel)
    limits = {channel: ADC_PEAK_V / CREST}  # the DAC itself
    for out in ("Vph", "Vpv", "Vch", "Vcv"):
        limits[out] = ADC_PEAK_V / CREST / max(per_unit[OUTPUTS.index(out)], 1e-30)
    for out, vn in (("psi_a", "Vnh"), ("psi_b", "Vnv")):  # metrology: Vn = psi / gn0
        limits[vn] = (ADC_PEAK_V * b.newport_metrology_rad_per_v / CREST
                      / max(per_unit[OUTPUTS.index(out)], 1e-30))
    for out in ("d_u", "d_w"):
        limits[f"4QD linear range ({out})"] = (b.qd_compression_swing_rad / CREST
                                               / max(per_unit[OUTPUTS.index(out)], 1e-30))
    if channel.startswith("Un"):
        limits["the study's 1 V expected perturbation (Table 5)"] = 1.0
    what = min(limits, key=limits.__getitem__)
    return float(limits[what]), what


def _sine_amplitude(model: BenchModel, channel: str, freq_hz: float,
                    closed: bool) -> tuple[float, str]:
    """Peak of a Newport sine that keeps the records in range [V], and what limits it."""
    b = model.bench
    j = INPUTS.index(channel)
    H = np.abs(model.plant.freqresp(np.array([freq_hz]))[0])
    ax = j - 2

    def per_volt(out: str) -> float:
        return max(float(H[OUTPUTS.index(out), j]), 1e-30)

    vn = ("Vnh", "Vnv")[ax]
    limits = {"the study's sweep (2 V) or perturbation (1 V)": 1.0 if closed else 2.0,
              vn: ADC_PEAK_V * b.newport_metrology_rad_per_v / per_volt(("psi_a", "psi_b")[ax])}
    if closed:
        # The loop turns the Sercalo against the Newport: Uc = beam / (Uc -> beam).
        uc_to_beam = float(H[OUTPUTS.index("b_x") + ax, ax])
        limits[("Uch", "Ucv")[ax]] = 4.0 * uc_to_beam / per_volt(("b_x", "b_y")[ax])
    else:
        for out in ("Vph", "Vpv"):
            limits[out] = 0.75 * ADC_PEAK_V / per_volt(out)
        for out in ("d_u", "d_w"):
            limits[f"4QD linear range ({out})"] = 0.95 * b.qd_compression_swing_rad / per_volt(out)
    what = min(limits, key=limits.__getitem__)
    return float(limits[what]), what


def _commands(model: BenchModel, p: Protocol, rng: np.random.Generator, n: int,
              lead_s: float) -> tuple[Array, dict[str, Any]]:
    """The held commands (N, 4) on the DAC grid, and the excitation's description."""
    b = model.bench
    u = np.zeros((n, 4))
    info: dict[str, Any] = {}
    if not p.excite:
        return u, info
    k0 = round(lead_s * b.fs_hz)
    t = (np.arange(n - k0)) / b.fs_hz
    j = INPUTS.index(p.excite)
    if p.kind == "noise":
        level, what = _noise_level(model, p.excite)
        x = np.clip(rng.standard_normal(n - k0), -CLIP_SIGMA, CLIP_SIGMA) * level
        info = {"channel": p.excite, "kind": "white noise", "amplitude_v": level,
                "amplitude_is": "rms before clipping at 4.5 sigma", "freq_hz": None,
                "limited_by": what}
    else:
        level, what = _sine_amplitude(model, p.excite, p.freq_hz, p.closed_loop)
        x = level * np.sin(2.0 * math.pi * p.freq_hz * t)
        info = {"channel": p.excite, "kind": "sine", "amplitude_v": level,
                "amplitude_is": "peak", "freq_hz": p.freq_hz, "limited_by": what}
    info["start_s"] = k0 / b.fs_hz
    u[k0:, j] = x
    return quantise(u, b.lsb_v, b.converter_span_v), info


def _qd_noise(model: BenchModel, rng: np.random.Generator, n: int) -> Array:
    """4QD output noise (N, 2): white + 1/f + offset [V]."""
    b = model.bench
    cols = []
    for ax in ("h", "v"):
        cols.append(rng.standard_normal(n) * getattr(b.qd_noise_rms_v, ax)
                    + flicker(rng, n, b.fs_hz, getattr(b.qd_flicker_asd_v_per_rthz, ax),
                              b.qd_flicker_min_hz)
                    + getattr(b.qd_offset_v, ax))
    return np.column_stack(cols)


def _nu(model: BenchModel, rng: np.random.Generator, n: int) -> Array:
    """Held white noise (N, 2) driving the Newport's angle noise [rad]."""
    b = model.bench
    return np.column_stack([rng.standard_normal(n) * b.newport_angle_noise_rms_rad * s
                            for s in model.nu_per_rad])


def _compression(model: BenchModel, d: Array) -> Array:
    """What the cubic compression takes off the 4QD outputs (N, 2) [V].

    The residual ``-g c d³`` happens at the diode, before its amplifier: it
    passes the amplifier's continuous response line by line
    (:func:`indsim.model.qd_amp_response`), so the compression stays the
    memoryless law it is at every frequency.
    """
    b = model.bench
    c = b.qd_cubic_per_rad2
    if c == 0.0:
        return np.zeros_like(d)
    g = np.array([b.qd_polarity.h * b.qd_gain_v_per_rad.h,
                  b.qd_polarity.v * b.qd_gain_v_per_rad.v])
    r = -g * c * d**3
    n = r.shape[0]
    response = qd_amp_response(b, np.fft.rfftfreq(n, b.dt_s))
    if response is None:
        return r
    return np.fft.irfft(np.fft.rfft(r, axis=0) * response[:, None], n=n, axis=0)


def _adc(model: BenchModel, x: Array) -> Array:
    return quantise(x, model.bench.lsb_v, model.bench.converter_span_v)


def run_experiment(model: BenchModel, name: str, rng: np.random.Generator,
                   duration_scale: float = 1.0) -> Record:
    """Simulate one recording of the study on ``model``'s bench.

    Parameters
    ----------
    model : BenchModel
        The bench and its models.
    name : str
        Experiment (a key of ``EXPERIMENTS``).
    rng : numpy.random.Generator
        Noise source (the caller seeds it per experiment).
    duration_scale : float
        Fraction of the study's length (at least ``MIN_DURATION_S`` per file).
    """
    b = model.bench
    p = EXPERIMENTS[name]
    total, lead = durations(p, duration_scale)
    n = round(total * b.fs_hz)
    t = np.arange(n) / b.fs_hz
    cmd, exc = _commands(model, p, rng, n, lead)
    nu = _nu(model, rng, n)
    qd_noise = _qd_noise(model, rng, n)
    U = np.column_stack([cmd, nu])
    adc_seen = None
    if p.closed_loop:
        Y, uc, adc_seen = _closed(model, rng, U, qd_noise)
    else:
        W = delayed_inputs(U, model.sampled.n_whole, model.sampled.fractional)
        Y = simulate(model.sampled.system, W)
        uc = cmd[:, 0:2]
    col = {o: Y[:, i] for i, o in enumerate(OUTPUTS)}
    vp = Y[:, 0:2] + qd_noise
    if not p.closed_loop:
        vp = vp + _compression(model, Y[:, 8:10])
    vc_noise = rng.standard_normal((n, 2)) * b.vc_noise_rms_v
    met = rng.standard_normal((n, 2)) * b.newport_metrology_noise_rms_rad
    sig: dict[str, Array] = {"t": t}
    sig["Uch"], sig["Ucv"] = uc[:, 0], uc[:, 1]
    sig["Unh"], sig["Unv"] = cmd[:, 2], cmd[:, 3]
    # A real-time target records the reading its controller used: in closed loop the same
    # additive rounding the loop ran with (rounding it again would record a reading the
    # controller never saw, which no recorded controller could explain).
    vp_q = (np.clip(vp + adc_seen, -b.converter_span_v / 2, b.converter_span_v / 2)
            if adc_seen is not None else _adc(model, vp))
    sig["Vph"], sig["Vpv"] = vp_q[:, 0], vp_q[:, 1]
    vc_q = _adc(model, Y[:, 2:4] + vc_noise)
    sig["Vch"], sig["Vcv"] = vc_q[:, 0], vc_q[:, 1]
    vn_q = _adc(model, (Y[:, 4:6] + met) / b.newport_metrology_rad_per_v)
    sig["Vnh"], sig["Vnv"] = vn_q[:, 0], vn_q[:, 1]
    realized: dict[str, Any] = {
        "qd_noise_v": {"h": float(np.std(qd_noise[:, 0])), "v": float(np.std(qd_noise[:, 1]))},
        "newport_angle_noise_rad": {"h": float(np.std(nu[:, 0]) / model.nu_per_rad.h),
                                    "v": float(np.std(nu[:, 1]) / model.nu_per_rad.v)},
        "beam_rms_rad": {"h": float(np.std(col["b_x"])), "v": float(np.std(col["b_y"]))},
        "qd_compression_max": float(b.qd_cubic_per_rad2 * np.max(Y[:, 8:10] ** 2)),
    }
    if "Va" in p.variables:
        va, parts = attocube(b, rng, t, Y[:, 6:8], Y[:, 10:12], Y[:, 4:6],
                             p.compensation_unit, p.shielding)
        sig["Va"] = va
        realized["va_parts_rms_m"] = {k: float(np.std(v)) for k, v in parts.items()}
    protocol = {"description": p.description, "seed_section": p.section,
                "duration_s": total, "lead_in_s": lead, "n_samples": n,
                "closed_loop": p.closed_loop, "compensation_unit": p.compensation_unit,
                "shielding": p.shielding, "excitations": [exc] if exc else []}
    return Record(name, {v: sig[v] for v in p.variables}, protocol, realized)


def _closed(model: BenchModel, rng: np.random.Generator, U: Array,
            qd_noise: Array) -> tuple[Array, Array, Array]:
    """Run the closed loop; return the plant outputs (N, 14), the DAC commands (N, 2) and the
    ADC's rounding the controller's reading carried (N, 2) [V].

    The ADC's rounding is additive uniform noise of one step (the 4QD's own noise, several
    steps rms, dithers it). The DAC's is not: a loop's command moves by less than a step per
    sample, and its rounding then is a dead band, not white noise; the loop is run sample by
    sample with the command rounded to the DAC's grid (and clipped to its rails).
    """
    b = model.bench
    n = U.shape[0]
    sp = model.sampled
    W6 = delayed_inputs(U, sp.n_whole, sp.fractional)
    m = U.shape[1]
    w = np.zeros((n, len(CL_INPUTS)))
    for name, src in (("Unh_d", 2), ("Unv_d", 3), ("nu_a", 4), ("nu_b", 5),
                      ("Unh_d1", m + 2), ("Unv_d1", m + 3)):
        w[:, CL_INPUTS.index(name)] = W6[:, src]
    w[:, CL_INPUTS.index("qd_noise_h"):CL_INPUTS.index("qd_noise_h") + 2] = qd_noise
    adc = uniform_lsb(rng, (n, 2), b.lsb_v)
    w[:, CL_INPUTS.index("adc_h"):CL_INPUTS.index("adc_h") + 2] = adc
    sys = model.closed.system
    k = len(OUTPUTS)
    assert CL_OUTPUTS[k] == "Uch"
    dac = [CL_INPUTS.index("dac_h"), CL_INPUTS.index("dac_v")]
    # The command rows carry the DAC's rounding as an input (its column); the command
    # before the DAC is those rows without it.
    bw = w @ sys.B.T
    dw = w @ sys.D.T
    b_dac, d_dac = sys.B[:, dac], sys.D[:, dac]
    c_u, dw_u = sys.C[k:k + 2], dw[:, k:k + 2]
    a, c = sys.A, sys.C
    lsb, top = b.lsb_v, b.converter_span_v / 2.0 - b.lsb_v
    x = np.zeros(a.shape[0])
    y = np.empty((n, c.shape[0]))
    for i in range(n):
        u = c_u @ x + dw_u[i]
        q = np.clip(np.round(u / lsb) * lsb, -top - lsb, top)
        e = q - u
        y[i] = c @ x + dw[i] + d_dac @ e
        x = a @ x + bw[i] + b_dac @ e
    uc = y[:, k:k + 2]
    return y[:, :k], uc, adc
