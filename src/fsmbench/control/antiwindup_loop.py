"""The twin's loop with back-calculation anti-windup, and the saturating step that shows it.

:func:`run_loop_antiwindup` runs the engine's sample (:mod:`fsmbench.sim.engine`:
ADC, controller, DAC, plant update, in that order and with the same
arithmetic) with one addition: after the controller's update, the part of
each command the DAC's rails clip off is fed back into the controller's
state, ``x[k+1] += L (u_applied - u)`` (:mod:`fsmbench.control.antiwindup`;
``u_applied`` is the command clipped to the rails, before quantisation, so
below the rails nothing changes, bit for bit). With ``L = 0`` it is the
engine's loop (the tests compare the two sample for sample).

:func:`saturating_step` closes a controller around the twin's plant and steps
the beam's reference on one axis by an amount whose transient needs more than
the DAC's ±10 V: once without and once with anti-windup. No noise: the
difference between the two runs is the windup alone.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import control as ct
import numpy as np
from numba import njit

from fsmbench.bench.params import Bench
from fsmbench.control.antiwindup import DEFAULT_TRACKING_TIME_S, antiwindup_channel
from fsmbench.control.export import DEFAULT_DISCRETISATION, discretise_channel
from fsmbench.sim.controller import sercalo_feedback
from fsmbench.sim.discretize import DiscretePlant
from fsmbench.sim.engine import DiscreteController, LoopResult, Quantiser
from fsmbench.sim.plant import ADC_CHANNELS, DAC_CHANNELS, INTERNAL_SIGNALS, bench_discrete

__all__ = [
    "AntiWindupFeedback",
    "SaturatingStep",
    "antiwindup_feedback",
    "recovery_time_s",
    "run_loop_antiwindup",
    "saturating_step",
]


@dataclass(frozen=True, eq=False)
class AntiWindupFeedback:
    """A controller wired into the twin with its back-calculation gain.

    Attributes
    ----------
    feedback : DiscreteController
        As the engine runs it (``u = -K Vp / Gd``, sign and scaling folded in).
    gain : numpy.ndarray, shape (nk, n_out)
        ``L`` in the engine's convention: ``x[k+1] += L (u_applied - u)`` [state per V].
    tracking_time_s : float
        ``Tt`` [s] (:func:`fsmbench.control.antiwindup.antiwindup_channel`).
    n_integrators : tuple of int
        Integrators per channel.
    """

    feedback: DiscreteController
    gain: np.ndarray = field(repr=False)
    tracking_time_s: float
    n_integrators: tuple[int, ...]


def antiwindup_feedback(k: ct.StateSpace, *, gd_v_per_rad: tuple[float, float], ts_s: float,
                        tracking_time_s: float = DEFAULT_TRACKING_TIME_S,
                        method: str = DEFAULT_DISCRETISATION,
                        name: str = "K") -> AntiWindupFeedback:
    """Wire a diagonal continuous ``K: [Rh, Rv] -> [Uch, Ucv]`` with anti-windup.

    Each channel is discretised into the exported sections
    (:func:`fsmbench.control.export.discretise_channel`), integrators last, in
    direct form II transposed: what a target running the export executes.

    Parameters
    ----------
    k : control.StateSpace
        Continuous, diagonal, inputs ``Rh, Rv`` [rad], outputs ``Uch, Ucv`` [V].
    gd_v_per_rad : (float, float)
        4QD gains the readings are divided by [V/rad].
    ts_s : float
        Sample time [s].
    tracking_time_s : float
        Back-calculation tracking time [s].
    method : str
        Discretisation (:data:`fsmbench.control.export.DISCRETISATIONS`).
    name : str
    """
    chans = [antiwindup_channel(np.array([s.sos for s in discretise_channel(
        k, ts_s=ts_s, output=i, input=i, method=method)]), ts_s=ts_s,
        tracking_time_s=tracking_time_s) for i in range(2)]
    n = [ch.a.shape[0] for ch in chans]
    a = np.zeros((sum(n), sum(n)))
    b = np.zeros((sum(n), 2))
    c = np.zeros((2, sum(n)))
    d = np.zeros((2, 2))
    gain = np.zeros((sum(n), 2))
    at = 0
    for i, ch in enumerate(chans):
        sl = slice(at, at + n[i])
        a[sl, sl], b[sl, i], c[i, sl], d[i, i] = ch.a, ch.b[:, 0], ch.c[0], ch.d[0, 0]
        # The engine applies u = -v: v_applied - v = -(u_applied - u).
        gain[sl, i] = -ch.gain
        at += n[i]
    fb = sercalo_feedback(a=a, b=b, c=c, d=d, gd_v_per_rad=gd_v_per_rad, name=name)
    return AntiWindupFeedback(feedback=fb, gain=gain, tracking_time_s=float(tracking_time_s),
                              n_integrators=tuple(ch.n_integrators for ch in chans))


@njit(cache=True, nogil=True, error_model="numpy")
def _quantise(x: float, lsb: float, lo: float, hi: float) -> float:
    if lsb <= 0.0:
        return x
    code = np.floor(x / lsb + 0.5)
    if code < lo:
        code = lo
    elif code > hi:
        code = hi
    return code * lsb


@njit(cache=True, nogil=True, error_model="numpy")
def _aw_loop(ab: np.ndarray, cz: np.ndarray, n_adc: int, adc_noise: np.ndarray,
             adc_lsb: float, adc_lo: float, adc_hi: float,
             ak: np.ndarray, bk: np.ndarray, ck: np.ndarray, dk: np.ndarray, lk: np.ndarray,
             k_in: np.ndarray, k_out: np.ndarray, u_ext: np.ndarray,
             dac_lsb: float, dac_lo: float, dac_hi: float, u_min: float, u_max: float,
             z0: np.ndarray, xk0: np.ndarray,
             out_adc: np.ndarray, out_dac: np.ndarray, out_int: np.ndarray) -> None:
    # The engine's sample with dense products: each row is summed from 0.0 in column order,
    # as the engine's sparse loop does (its skipped zeros add ±0.0), so the sums are equal.
    n_steps = u_ext.shape[0]
    nz = z0.shape[0]
    ny = cz.shape[0]
    nu = u_ext.shape[1]
    nk = ak.shape[0]
    ni = k_in.shape[0]
    no = k_out.shape[0]
    zu = np.zeros(nz + nu)
    for i in range(nz):
        zu[i] = z0[i]
    y = np.zeros(ny)
    z_next = np.zeros(nz)
    xk = np.zeros(nk)
    for i in range(nk):
        xk[i] = xk0[i]
    xk_next = np.zeros(nk)
    e = np.zeros(ni)
    for k in range(n_steps):
        for i in range(ny):
            acc = 0.0
            for j in range(nz):
                acc += cz[i, j] * zu[j]
            y[i] = acc
        for i in range(n_adc):
            out_adc[k, i] = _quantise(y[i] + adc_noise[k, i], adc_lsb, adc_lo, adc_hi)
        for i in range(n_adc, ny):
            out_int[k, i - n_adc] = y[i]
        for i in range(ni):
            e[i] = out_adc[k, k_in[i]]
        for i in range(nu):
            zu[nz + i] = u_ext[k, i]
        for i in range(no):
            acc = 0.0
            for j in range(nk):
                acc += ck[i, j] * xk[j]
            for j in range(ni):
                acc += dk[i, j] * e[j]
            zu[nz + k_out[i]] += acc
        for i in range(nk):
            acc = 0.0
            for j in range(nk):
                acc += ak[i, j] * xk[j]
            for j in range(ni):
                acc += bk[i, j] * e[j]
            xk_next[i] = acc
        # Back-calculation: only what the rails clip off; zero below them, so nothing moves.
        for i in range(no):
            u = zu[nz + k_out[i]]
            clipped = min(max(u, u_min), u_max)
            if clipped != u:
                for j in range(nk):
                    xk_next[j] += lk[j, i] * (clipped - u)
        for i in range(nk):
            xk[i] = xk_next[i]
        for i in range(nu):
            zu[nz + i] = _quantise(zu[nz + i], dac_lsb, dac_lo, dac_hi)
            out_dac[k, i] = zu[nz + i]
        for i in range(nz):
            acc = 0.0
            for j in range(nz + nu):
                acc += ab[i, j] * zu[j]
            z_next[i] = acc
        for i in range(nz):
            zu[i] = z_next[i]
    for i in range(nz):
        z0[i] = zu[i]
    for i in range(nk):
        xk0[i] = xk[i]


def _rails(q: Quantiser) -> tuple[float, float, float]:
    if q.bits == 0:
        return 0.0, -np.inf, np.inf
    return q.lsb_v, -(2.0 ** (q.bits - 1)), 2.0 ** (q.bits - 1) - 1.0


def run_loop_antiwindup(plant: DiscretePlant, *, u_ext: np.ndarray, adc_noise: np.ndarray,
                        adc: Quantiser, dac: Quantiser, controller: AntiWindupFeedback,
                        n_adc: int, enabled: bool = True, z0: np.ndarray | None = None,
                        xk0: np.ndarray | None = None) -> LoopResult:
    """The engine's loop (:func:`fsmbench.sim.engine.run_loop`) with back-calculation.

    Parameters
    ----------
    plant, u_ext, adc_noise, adc, dac, n_adc, z0, xk0
        As for :func:`~fsmbench.sim.engine.run_loop` (linear sensors only).
    controller : AntiWindupFeedback
    enabled : bool
        False runs the same controller without anti-windup (``L = 0``).

    Returns
    -------
    LoopResult
    """
    fb = controller.feedback
    n = u_ext.shape[0]
    if u_ext.shape[1] != plant.b.shape[1] or adc_noise.shape != (n, n_adc):
        raise ValueError("u_ext or adc_noise do not match the plant")
    d_lsb, d_lo, d_hi = _rails(dac)
    a_lsb, a_lo, a_hi = _rails(adc)
    # The rails the DAC clips to [V] (ideal converter: none).
    u_min, u_max = (-np.inf, np.inf) if dac.bits == 0 else (d_lo * d_lsb, d_hi * d_lsb)
    z = np.zeros(plant.a.shape[0]) if z0 is None else np.array(z0, dtype=float)
    xk = np.zeros(fb.a.shape[0]) if xk0 is None else np.array(xk0, dtype=float)
    gain = controller.gain if enabled else np.zeros_like(controller.gain)
    out_adc = np.zeros((n, n_adc))
    out_dac = np.zeros((n, plant.b.shape[1]))
    out_int = np.zeros((n, plant.c.shape[0] - n_adc))
    ak, bk, ck, dk, lk = (np.ascontiguousarray(x, dtype=float)
                          for x in (fb.a, fb.b, fb.c, fb.d, gain))
    _aw_loop(np.ascontiguousarray(np.hstack([plant.a, plant.b]), dtype=float),
             np.ascontiguousarray(plant.c, dtype=float), n_adc,
             np.ascontiguousarray(adc_noise, dtype=float), a_lsb, a_lo, a_hi, ak, bk, ck, dk, lk,
             np.asarray(fb.adc_inputs, dtype=np.int64), np.asarray(fb.dac_outputs, dtype=np.int64),
             np.ascontiguousarray(u_ext, dtype=float), d_lsb, d_lo, d_hi, u_min, u_max, z, xk,
             out_adc, out_dac, out_int)
    return LoopResult(adc=out_adc, dac=out_dac, internal=out_int, plant_state=z,
                      controller_state=xk)


def recovery_time_s(t_s: np.ndarray, error: np.ndarray, *, band: float) -> float:
    """First time after which ``|error|`` stays within ``band`` to the end [s]; inf if never.

    ``error`` and ``band`` in the same unit.
    """
    outside = np.flatnonzero(np.abs(np.asarray(error)) > band)
    if outside.size == 0:
        return float(t_s[0])
    if outside[-1] == len(t_s) - 1:
        return float("inf")
    return float(t_s[outside[-1] + 1])


@dataclass(frozen=True, eq=False)
class SaturatingStep:
    """A reference step beyond the DAC's reach on one axis of the twin, held, then removed.

    The step asks for a command ``demand_over_limit`` times the DAC's rail:
    the command sits on the rail while it is held and the integrators wind
    up; after the step back the beam's recovery is measured, once without and
    once with anti-windup, and once with an ideal DAC (no rails) as the
    linear loop's own settling.

    Attributes
    ----------
    name : str
        The controller, in words.
    axis : str
        ``"h"`` or ``"v"``.
    t_s : numpy.ndarray, shape (n,)
        Time after the step [s].
    step_rad : float
        Height of the reference step of the beam angle [rad].
    hold_s : float
        When the reference steps back to 0 [s].
    beam_rad : dict of str to numpy.ndarray
        Beam angle ``R`` on the stepped axis [rad]: ``"without"``, ``"with"``
        (anti-windup) and ``"linear"`` (ideal DAC).
    command_v : dict of str to numpy.ndarray
        The Sercalo command on that axis as the DAC applied it [V], same keys.
    dac_limit_v : float
        The DAC's positive rail [V].
    band_rad : float
        Recovery band around the reference [rad].
    recovery_s : dict of str to float
        Time after the step back until ``|R|`` stays within the band [s]
        (inf: not within the run), same keys.
    saturated_s : dict of str to float
        Time the command spent on a rail [s], same keys.
    tracking_time_s : float
        Back-calculation tracking time [s].
    """

    name: str
    axis: str
    t_s: np.ndarray = field(repr=False)
    step_rad: float
    hold_s: float
    beam_rad: dict[str, np.ndarray] = field(repr=False)
    command_v: dict[str, np.ndarray] = field(repr=False)
    dac_limit_v: float
    band_rad: float
    recovery_s: dict[str, float]
    saturated_s: dict[str, float]
    tracking_time_s: float

    def to_json(self) -> dict[str, Any]:
        """Numbers only (inf as None)."""
        def num(x: float) -> float | None:
            return float(x) if np.isfinite(x) else None
        return {"controller": self.name, "axis": self.axis, "step_rad": self.step_rad,
                "hold_s": self.hold_s, "duration_s": float(self.t_s[-1]),
                "dac_limit_v": self.dac_limit_v, "band_rad": self.band_rad,
                "tracking_time_s": self.tracking_time_s,
                "recovery_after_step_back_s": {k: num(v) for k, v in self.recovery_s.items()},
                "saturated_s": {k: float(v) for k, v in self.saturated_s.items()}}


def saturating_step(bench: Bench, k: ct.StateSpace, *, name: str, axis: str = "h",
                    demand_over_limit: float = 1.5, hold_s: float = 0.1,
                    duration_s: float = 0.4, band: float = 0.02,
                    tracking_time_s: float = DEFAULT_TRACKING_TIME_S) -> SaturatingStep:
    """Step the beam's reference on ``axis`` beyond the DAC's reach, hold it, step back.

    Parameters
    ----------
    bench : Bench
        The twin: its true plant and converters, its nominal 4QD gains.
    k : control.StateSpace
        Continuous diagonal controller ``Rh, Rv`` [rad] to ``Uch, Ucv`` [V].
    name : str
        The controller, in words.
    axis : {"h", "v"}
    demand_over_limit : float
        The step's steady command over the DAC's rail [1] (above 1: unreachable).
    hold_s : float
        How long the step is held [s].
    duration_s : float
        Run length [s].
    band : float
        Recovery band as a fraction of the step [1].
    tracking_time_s : float
        Back-calculation tracking time [s].
    """
    i = ("h", "v").index(axis)
    ts = bench.true.converter.ts_s
    plant = bench_discrete(bench)
    conv = Quantiser(range_v=bench.true.converter.range_v, bits=bench.true.converter.bits)
    ideal = Quantiser(range_v=bench.true.converter.range_v, bits=0)
    gd_nom = bench.nominal.quad_diode.gain_v_per_rad
    gd = (float(gd_nom.h), float(gd_nom.v))
    aw = antiwindup_feedback(k, gd_v_per_rad=gd, ts_s=ts, tracking_time_s=tracking_time_s,
                             name=name)
    n = round(duration_s / ts) + 1
    n_hold = round(hold_s / ts)
    n_adc = len(ADC_CHANNELS)
    u_ext = np.zeros((n, len(DAC_CHANNELS)))
    adc_ch = ADC_CHANNELS.index(("Vph", "Vpv")[i])
    dac_ch = DAC_CHANNELS.index(("Uch", "Ucv")[i])
    beam = INTERNAL_SIGNALS.index(("Rh", "Rv")[i])

    def run(step: float, conv_used: Quantiser, enabled: bool, length: int) -> LoopResult:
        noise = np.zeros((length, n_adc))
        # The reference enters where the ADC noise does: the controller reads Vp - Gd r.
        noise[:min(n_hold, length), adc_ch] = -gd[i] * step
        return run_loop_antiwindup(plant, u_ext=u_ext[:length], adc_noise=noise, adc=conv_used,
                                   dac=conv_used, controller=aw, n_adc=n_adc, enabled=enabled)

    # The command a held unit step settles to [V/rad] (integral action: the loop's DC gain).
    settle = run(1.0, ideal, False, n_hold)
    per_rad = float(settle.dac[-1, dac_ch])
    limit = (2 ** (conv.bits - 1) - 1) * conv.lsb_v
    step = demand_over_limit * limit / abs(per_rad)
    t = np.arange(n) * ts
    beam_rad: dict[str, np.ndarray] = {}
    command: dict[str, np.ndarray] = {}
    recovery: dict[str, float] = {}
    saturated: dict[str, float] = {}
    for label, used, on in (("without", conv, False), ("with", conv, True),
                            ("linear", ideal, False)):
        res = run(step, used, on, n)
        beam_rad[label] = res.internal[:, beam]
        command[label] = res.dac[:, dac_ch]
        recovery[label] = recovery_time_s(t[n_hold:] - t[n_hold], beam_rad[label][n_hold:],
                                          band=band * step)
        on_rail = np.abs(command[label]) >= limit - conv.lsb_v
        saturated[label] = float(np.count_nonzero(on_rail) * ts)
    return SaturatingStep(name=name, axis=axis, t_s=t, step_rad=float(step),
                          hold_s=float(n_hold * ts), beam_rad=beam_rad, command_v=command,
                          dac_limit_v=float(limit), band_rad=float(band * step),
                          recovery_s=recovery, saturated_s=saturated,
                          tracking_time_s=float(tracking_time_s))
