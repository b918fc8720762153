"""Frequency-domain tools for loops with pure delays: responses, grids, margins, Nyquist.

A loop ``L = G K`` of the bench carries the plant's input delays
(:attr:`fsmbench.bench.blocks.PlantModel.input_delay_s`). Everything here
evaluates them exactly, as ``exp(-s tau)``, at any complex ``s``; no Padé
approximation is involved.

Conventions
-----------
* The loop is closed as ``u = -K y`` (``docs/model.md``), so ``L = G K``,
  ``S = (I + L)^-1`` and ``T = L (I + L)^-1``.
* Frequencies ``f`` are in Hz, Laplace variables ``s`` in rad/s.
* The phase margin is the distance, in degrees, from ``L(j w_c)`` to ``-1``
  along the unit circle, taken at every gain crossover (also the crossovers
  around a phase-stabilised resonance), so it is the smallest phase change
  that could move the Nyquist curve onto ``-1``. For a loop that is
  unstable it is reported negative.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import control as ct
import numpy as np
from scipy import optimize

from fsmbench.bench.blocks import PlantModel
from fsmbench.bench.blocks import ss_response as evaluate_ss
from fsmbench.jsonutil import plain_json

__all__ = [
    "Margins",
    "NyquistCount",
    "evaluate_ss",
    "frequency_grid",
    "loop_response",
    "nyquist_count",
    "plain_json",
    "plant_response",
    "siso_margins",
]

ResponseFn = Callable[[np.ndarray], np.ndarray]






def plant_response(plant: PlantModel, s: np.ndarray, *, outputs: Sequence[str],
                   inputs: Sequence[str]) -> np.ndarray:
    """Plant response with its exact input delays at complex ``s`` [rad/s], shape (n, p, m)."""
    s = np.asarray(s, dtype=complex).ravel()
    h = evaluate_ss(plant.subsystem(outputs=outputs, inputs=inputs), s)
    tau = np.array([plant.input_delay_s.get(name, 0.0) for name in inputs])
    return h * np.exp(-s[:, None, None] * tau[None, None, :])


def loop_response(plant: PlantModel, k: ct.StateSpace, s: np.ndarray) -> np.ndarray:
    """Output loop gain ``L = G K`` at complex ``s``, shape (n, p, p).

    ``G`` runs from the controller's outputs to its inputs (e.g. ``Uch, Ucv``
    to ``Rh, Rv``), with the plant's exact input delays.
    """
    g = plant_response(plant, s, outputs=list(k.input_labels), inputs=list(k.output_labels))
    return np.einsum("fij,fjk->fik", g, evaluate_ss(k, s))


def frequency_grid(poles: Sequence[complex] | np.ndarray = (), *, f_min_hz: float = 1e-2,
                   f_max_hz: float = 1e4, per_decade: int = 100, points_per_mode: int = 81,
                   damping_max: float = 0.2) -> np.ndarray:
    """Log grid [Hz] refined around lightly damped poles, sorted, shape (n,).

    Parameters
    ----------
    poles : sequence of complex
        Poles [rad/s] whose resonances must be resolved; those with damping
        ratio below ``damping_max`` get ``points_per_mode`` extra points at
        ``f0 + b tan(u)``, ``u`` uniform in (-1.56, 1.56), ``b`` the
        half-power half-bandwidth ``|Re p| / 2 pi`` [Hz]: dense at the peak,
        out to ±90 ``b``.
    f_min_hz, f_max_hz : float
        Range [Hz].
    per_decade : int
        Points per decade of the log grid.
    """
    n = max(2, int(np.ceil(per_decade * np.log10(f_max_hz / f_min_hz))) + 1)
    parts = [np.logspace(np.log10(f_min_hz), np.log10(f_max_hz), n)]
    u = np.tan(np.linspace(-1.56, 1.56, points_per_mode))
    for p in np.asarray(poles, dtype=complex).ravel():
        wn = abs(p)
        if p.imag <= 0 or wn == 0 or -p.real / wn >= damping_max:
            continue
        f0, b = p.imag / (2 * np.pi), max(abs(p.real), 1e-9 * wn) / (2 * np.pi)
        parts.append(f0 + b * u)
    f = np.concatenate(parts)
    return np.unique(f[(f >= f_min_hz) & (f <= f_max_hz)])


@dataclass(frozen=True)
class Margins:
    """Stability margins of a SISO loop ``L`` (closed as ``u = -K y``).

    Attributes
    ----------
    gain_margin_db : float
        Smallest factor [dB] by which the gain may grow before ``L`` passes
        through ``-1``: ``-20 log10 |L|`` at the negative-real-axis crossings
        with ``|L| < 1``; inf if there are none.
    gain_reduction_margin_db : float
        Same for a gain decrease (crossings with ``|L| > 1``, conditionally
        stable loops); inf if none.
    phase_margin_deg : float
        Smallest ``180 - |arg L|`` [deg] over all gain crossovers; negative
        when the loop is known to be unstable (see module notes).
    modulus_margin : float
        ``min |1 + L| = 1 / max |S|`` [1].
    crossover_hz : float
        First gain crossover [Hz] (the bandwidth); NaN if none.
    crossovers_hz : tuple of float
        All gain crossovers [Hz].
    phase_crossover_hz : float
        Frequency of the gain margin [Hz]; NaN if none.
    modulus_frequency_hz : float
        Frequency of ``min |1 + L|`` [Hz].
    gain_reduction_crossover_hz : float
        Frequency of the gain-reduction margin [Hz] (the negative-real-axis
        crossing with ``|L| > 1`` nearest to ``|L| = 1``); NaN if none.
    """

    gain_margin_db: float
    gain_reduction_margin_db: float
    phase_margin_deg: float
    modulus_margin: float
    crossover_hz: float
    crossovers_hz: tuple[float, ...]
    phase_crossover_hz: float
    modulus_frequency_hz: float
    gain_reduction_crossover_hz: float = math.nan

    def to_json(self) -> dict[str, Any]:
        """Plain floats; inf and NaN become None."""
        return plain_json(self.__dict__)


def _brentq(fun: Callable[[float], float], a: float, b: float) -> float:
    fa, fb = fun(a), fun(b)
    if fa == 0:
        return a
    if fb == 0 or np.sign(fa) == np.sign(fb):
        return b
    return float(optimize.brentq(fun, a, b, xtol=1e-12 * max(a, 1e-12), rtol=1e-12))


def siso_margins(loop: ResponseFn, f_hz: np.ndarray, *, refine: bool = True,
                 stable: bool | None = None) -> Margins:
    """Gain, phase and modulus margins of a SISO loop from its exact response.

    Parameters
    ----------
    loop : callable
        ``loop(f_hz) -> L(j 2 pi f)``, complex array of the same shape.
    f_hz : array, shape (n,)
        Increasing grid [Hz] that resolves the loop (see :func:`frequency_grid`).
    refine : bool
        Locate crossings with ``brentq`` and the ``|1 + L|`` minimum with a
        bounded search on ``loop`` itself; otherwise stay on the grid.
    stable : bool, optional
        Closed-loop stability, if known; ``False`` makes the phase margin negative.
    """
    f = np.asarray(f_hz, dtype=float)
    lv = np.asarray(loop(f), dtype=complex)
    mag = np.abs(lv)

    def at(x: float) -> complex:
        return complex(np.asarray(loop(np.array([x])), dtype=complex)[0])

    # Gain crossovers.
    idx = np.nonzero(np.diff(np.sign(mag - 1.0)) != 0)[0]
    fc_list = [(_brentq(lambda x: math.log(abs(at(x))), f[i], f[i + 1]) if refine
                else float(f[i])) for i in idx]
    pm_list = [180.0 - abs(math.degrees(np.angle(at(x) if refine else lv[i])))
               for x, i in zip(fc_list, idx, strict=True)]
    # Phase crossovers: Im L changes sign on the negative real half-axis.
    jdx = np.nonzero((np.diff(np.sign(lv.imag)) != 0) & (lv.real[:-1] < 0) & (lv.real[1:] < 0))[0]
    gm_up: list[tuple[float, float]] = []
    gm_down: list[tuple[float, float]] = []
    for j in jdx:
        x = (_brentq(lambda y: at(y).imag / max(abs(at(y)), 1e-300), f[j], f[j + 1]) if refine
             else float(f[j]))
        mag_x = abs(at(x)) if refine else float(mag[j])
        if mag_x <= 0:
            continue
        db = -20.0 * math.log10(mag_x)
        (gm_up if db > 0 else gm_down).append((db, x))
    gm, f_gm = min(gm_up, default=(math.inf, math.nan))
    gr, f_gr = min(((-db, x) for db, x in gm_down), default=(math.inf, math.nan))
    if not gm_up and gm_down:
        f_gm = min(gm_down, key=lambda t: -t[0])[1]
    # Modulus margin.
    dist = np.abs(1.0 + lv)
    k = int(np.argmin(dist))
    mm, f_mm = float(dist[k]), float(f[k])
    if refine and 0 < k < f.size - 1:
        res = optimize.minimize_scalar(lambda x: abs(1.0 + at(x)), bounds=(f[k - 1], f[k + 1]),
                                       method="bounded", options={"xatol": 1e-9 * f[k]})
        if res.fun < mm:
            mm, f_mm = float(res.fun), float(res.x)
    pm = min(pm_list, default=math.inf)
    if stable is False:
        pm = -pm
    return Margins(gain_margin_db=float(gm), gain_reduction_margin_db=float(gr),
                   phase_margin_deg=float(pm), modulus_margin=mm,
                   crossover_hz=float(fc_list[0]) if fc_list else math.nan,
                   crossovers_hz=tuple(float(x) for x in fc_list),
                   phase_crossover_hz=float(f_gm), modulus_frequency_hz=f_mm,
                   gain_reduction_crossover_hz=float(f_gr))


@dataclass(frozen=True)
class NyquistCount:
    """Generalised Nyquist criterion on ``det(I + L(s))``, delays exact.

    The contour runs along ``Re s = sigma`` (a small positive shift, so poles
    on the imaginary axis, e.g. integrators, count as stable) and closes at
    infinity, where a strictly proper delayed ``L`` vanishes.

    Attributes
    ----------
    winding : int
        Counter-clockwise encirclements of the origin by ``det(I + L)``.
    open_loop_unstable : int
        Open-loop poles of ``G`` and ``K`` right of the contour.
    closed_loop_unstable : int
        ``open_loop_unstable - winding``: closed-loop poles right of the contour.
    sigma_rad_s : float
        Contour shift [rad/s].
    max_phase_step_rad : float
        Largest phase step between grid points (the count is exact if < pi).
    """

    winding: int
    open_loop_unstable: int
    closed_loop_unstable: int
    sigma_rad_s: float
    max_phase_step_rad: float

    @property
    def stable(self) -> bool:
        """No closed-loop pole right of the contour."""
        return self.closed_loop_unstable == 0

    def to_json(self) -> dict[str, Any]:
        """Plain numbers."""
        return {**plain_json(self.__dict__), "stable": self.stable}


def nyquist_count(det_fn: ResponseFn, *, open_loop_poles: Sequence[complex] | np.ndarray,
                  sigma_rad_s: float = 1e-3, f_max_hz: float = 1e6, per_decade: int = 60,
                  max_rounds: int = 12) -> NyquistCount:
    """Count closed-loop poles right of ``Re s = sigma`` from ``det(I + L(s))``.

    Parameters
    ----------
    det_fn : callable
        ``det_fn(s) -> det(I + L(s))`` at complex ``s`` [rad/s].
    open_loop_poles : array of complex
        Poles of ``G`` and ``K`` [rad/s]; they set ``P`` and the grid refinement.
    sigma_rad_s : float
        Contour shift [rad/s]; closed-loop poles in ``(0, sigma)`` are missed.
    f_max_hz : float
        Upper end [Hz]; extended ×10 (up to 1e9 Hz) while ``|det - 1| > 0.5`` there.
    max_rounds : int
        Midpoint refinements where the phase steps by more than pi/4.
    """
    poles = np.asarray(open_loop_poles, dtype=complex).ravel()
    n_unstable = int(np.sum(poles.real > sigma_rad_s))
    f_hi = f_max_hz
    while True:
        w_top = 2 * np.pi * f_hi
        lo = np.log10(sigma_rad_s) - 4
        w = np.concatenate([[0.0], np.logspace(lo, np.log10(w_top),
                                               int(per_decade * (np.log10(w_top) - lo)) + 1)])
        w = np.unique(np.concatenate([w, 2 * np.pi * frequency_grid(
            poles, f_min_hz=w[1] / (2 * np.pi), f_max_hz=f_hi, per_decade=1)]))
        vals = np.asarray(det_fn(sigma_rad_s + 1j * w), dtype=complex)
        if abs(vals[-1] - 1.0) <= 0.5 or f_hi >= 1e9:
            break
        f_hi *= 10.0
    for _ in range(max_rounds):
        steps = np.abs(np.diff(np.unwrap(np.angle(vals))))
        bad = np.nonzero(steps > np.pi / 4)[0]
        if bad.size == 0:
            break
        mids = 0.5 * (w[bad] + w[bad + 1])
        mid_vals = np.asarray(det_fn(sigma_rad_s + 1j * mids), dtype=complex)
        w = np.concatenate([w, mids])
        vals = np.concatenate([vals, mid_vals])
        order = np.argsort(w)
        w, vals = w[order], vals[order]
    phase = np.unwrap(np.angle(vals))
    # Conjugate symmetry: the full contour turns twice the half-axis' phase change.
    winding = int(np.rint((phase[-1] - phase[0]) / np.pi))
    step = float(np.max(np.abs(np.diff(phase)))) if phase.size > 1 else 0.0
    return NyquistCount(winding=winding, open_loop_unstable=n_unstable,
                        closed_loop_unstable=n_unstable - winding, sigma_rad_s=sigma_rad_s,
                        max_phase_step_rad=step)
