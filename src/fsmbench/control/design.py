"""fsmbench's own decentralised controller, shaped per axis on a plant with its delay.

Each axis gets (``u = -K y``, ``K`` from ``Rh, Rv`` to ``Uch, Ucv``)

    K(s) = k ((s + wi)/s)^n (1/s) (1 + s h/wz)/(1 + s/(wz h)) wl^2/(s^2 + 2 zl wl s + wl^2)

* ``n + 1`` integrators below ``wi``: the 6.1 objective asks for
  ``|L(j 2 pi 1 Hz)| > 5e3`` with a crossover of a few tens of Hz, a 40 dB
  per decade slope or more between them;
* slope -1 and a lead around the crossover for the phase margin;
* a second-order roll-off that **phase-stabilises** the lightly damped mirror
  mode: its Nyquist circle must point into the right half-plane. A notch
  (the ESRF study's "inversion" of 9.2) cannot stay robust here: with ξ ≈ 1e-3 a
  ±5 % shift of the resonance leaves a residue ~0.1/(2ξ) = 50 times the
  baseline loop gain on one side or the other of the notch.

The gain ``k`` puts ``|L| = 1`` at the crossover parameter. The remaining
six parameters are tuned by Nelder–Mead to maximise the smallest normalised
slack of {gain margin, gain-reduction margin, phase margin, modulus margin,
``|S(1 Hz)|``} over the robust set: the plant with its lightly damped modes
shifted ±5 % and their damping ×0.5 and ×2 (all combinations), each
candidate also required stable by a Nyquist count (exact delays).

:func:`perturbed_plants` builds that set by moving the modes of the plant's
``Gc`` block (physical or identified alike); :func:`robustness` verifies a
controller over it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import control as ct
import numpy as np
from scipy import optimize

from fsmbench.bench.blocks import PlantModel, assemble_plant
from fsmbench.bench.sections import zpk_cascade
from fsmbench.control.analysis import ControlObjective
from fsmbench.control.freq import frequency_grid, plain_json, plant_response
from fsmbench.control.loops import AXES, LoopAnalysis, LoopOptions, analyse_loop

__all__ = [
    "AxisShape",
    "DesignOptions",
    "FsmDesign",
    "Robustness",
    "design_controller",
    "perturb_modes",
    "perturbed_plants",
    "phase_travel",
    "robustness",
]


# ----------------------------------------------------------------------------- perturbations


def perturb_modes(sys: ct.StateSpace, *, frequency_scale: float = 1.0,
                  damping_scale: float = 1.0, damping_max: float = 0.05) -> ct.StateSpace:
    """Move the lightly damped modes of ``sys``: ``wn × frequency_scale``, ``ξ × damping_scale``.

    The model is brought to real modal form (a 2×2 block ``[[σ, ω], [-ω, σ]]``
    per complex pair). Each pair with damping below ``damping_max`` gets its new
    eigenvalue ``λ'``, and its residue is scaled by ``λ'/λ`` so that the mode's
    static contribution ``-2 Re(r/λ)`` stays the same (as a change of
    stiffness and mass at constant ``α/k`` does). Other modes are untouched.
    """
    a, b, c, d = (np.asarray(x, dtype=float) for x in (sys.A, sys.B, sys.C, sys.D))
    lam, vec = np.linalg.eig(a)
    cols: list[np.ndarray] = []
    blocks: list[tuple[int, complex]] = []
    for i in np.argsort(-lam.imag):
        li = lam[i]
        if li.imag > 0:
            blocks.append((len(cols), complex(li)))
            cols += [vec[:, i].real, vec[:, i].imag]
        elif li.imag == 0:
            cols.append(vec[:, i].real)
    t = np.column_stack(cols)
    if t.shape != a.shape or np.linalg.cond(t) > 1e10:
        raise ValueError("perturb_modes needs a diagonalisable model with a well-conditioned "
                         "eigenvector basis")
    a_r = np.linalg.solve(t, a @ t)
    b_r = np.linalg.solve(t, b)
    c_r = c @ t
    for j, li in blocks:
        wn = abs(li)
        zeta = -li.real / wn
        if zeta >= damping_max:
            continue
        z2 = min(zeta * damping_scale, 0.99)
        wn2 = wn * frequency_scale
        l2 = complex(-z2 * wn2, wn2 * math.sqrt(1 - z2**2))
        a_r[j:j + 2, :] = 0.0
        a_r[:, j:j + 2] = 0.0
        a_r[j:j + 2, j:j + 2] = [[l2.real, l2.imag], [-l2.imag, l2.real]]
        bz = (b_r[j] - 1j * b_r[j + 1]) * (l2 / li)
        b_r[j], b_r[j + 1] = bz.real, -bz.imag
    return ct.ss(a_r, b_r, c_r, d, inputs=list(sys.input_labels),
                 outputs=list(sys.output_labels), name=sys.name)


def perturbed_plants(plant: PlantModel, *, frequency_scales: Sequence[float] = (0.95, 1.0, 1.05),
                     damping_scales: Sequence[float] = (0.5, 1.0, 2.0),
                     damping_max: float = 0.05) -> list[tuple[str, PlantModel]]:
    """The plant with its Sercalo modes (``Gc``) perturbed, all combinations.

    Returns ``(label, plant)`` pairs, e.g. ``("f×1.05 ξ×0.5", ...)``; the
    unperturbed plant is included as ``"f×1 ξ×1"``.
    """
    out = []
    bl = plant.blocks
    for fs in frequency_scales:
        for ds in damping_scales:
            gc = perturb_modes(bl["Gc"], frequency_scale=fs, damping_scale=ds,
                               damping_max=damping_max)
            label = f"f×{fs:g} ξ×{ds:g}"
            out.append((label, assemble_plant(gi=bl["Gi"], zc=bl["Zc"], ga=bl["Ga"], gc=gc,
                                              gn=bl["Gn"], gd=bl["Gd"],
                                              input_delay_s=plant.input_delay_s,
                                              source=f"{plant.source}, {label}")))
    return out


# ----------------------------------------------------------------------------- controller shape


@dataclass(frozen=True)
class AxisShape:
    """One axis of the fsmbench controller (see the module docstring for ``K(s)``).

    Attributes
    ----------
    crossover_hz : float
        Where ``|L| = 1`` on the design plant [Hz]; sets ``gain``.
    integrator_hz : float
        Corner ``wi / 2 pi`` of the extra integrators [Hz].
    extra_integrators : int
        ``n``: the controller has ``n + 1`` integrators.
    lead_hz, lead_ratio : float
        Centre [Hz] and ratio ``h`` of the lead (zero at ``lead_hz/h``, pole at ``lead_hz h``).
    lowpass_hz, lowpass_damping : float
        Roll-off natural frequency [Hz] and damping [1].
    gain : float
        ``k`` [V/rad · (rad/s)^(n+1)], signed so that ``K G > 0`` at low frequency.
    """

    crossover_hz: float
    integrator_hz: float
    extra_integrators: int
    lead_hz: float
    lead_ratio: float
    lowpass_hz: float
    lowpass_damping: float
    gain: float = 1.0

    def zpk(self) -> tuple[list[complex], list[complex], float]:
        """Zeros, poles [rad/s] and leading coefficient of ``K``."""
        wi, wz, wl = (2 * np.pi * x for x in (self.integrator_hz, self.lead_hz, self.lowpass_hz))
        h, zl = self.lead_ratio, self.lowpass_damping
        zeros = [complex(-wi)] * self.extra_integrators + [complex(-wz / h)]
        lp = [complex(r) for r in np.roots([1.0, 2 * zl * wl, wl**2])]
        poles = [0j] * (self.extra_integrators + 1) + [complex(-wz * h), *lp]
        return zeros, poles, self.gain * h**2 * wl**2

    def response(self, s: np.ndarray) -> np.ndarray:
        """``K(s)`` at complex ``s`` [rad/s], evaluated from the factors."""
        s = np.asarray(s, dtype=complex)
        wi, wz, wl = (2 * np.pi * x for x in (self.integrator_hz, self.lead_hz, self.lowpass_hz))
        h, zl = self.lead_ratio, self.lowpass_damping
        return (self.gain * ((s + wi) / s) ** self.extra_integrators / s
                * (1 + s * h / wz) / (1 + s / (wz * h)) * wl**2 / (s**2 + 2 * zl * wl * s + wl**2))

    def realise(self, *, input_name: str, output_name: str) -> ct.StateSpace:
        """Cascade realisation (:func:`fsmbench.bench.sections.zpk_cascade`)."""
        z, p, k = self.zpk()
        return zpk_cascade(z, p, k, input_name=input_name, output_name=output_name)

    def to_json(self) -> dict[str, Any]:
        """Plain numbers."""
        return plain_json(self.__dict__)


@dataclass(frozen=True)
class DesignOptions:
    """Requirements and search settings of :func:`design_controller`.

    Attributes
    ----------
    gain_margin_db, phase_margin_deg : float
        Required over the robust set (6 dB, 30°).
    gain_reduction_margin_db : float
        Required for the conditionally stable low-frequency crossing [dB].
    modulus_margin : float
        Required ``min |1 + L|`` (0.4: ``|S| < 8 dB``).
    objective_factor : float
        ``|S(f0)|`` must stay below ``objective_factor × bound``.
    frequency_scales, damping_scales : sequence of float
        The robust set (all combinations).
    gain_scales : sequence of float
        Loop-gain factors added to the robust set (e.g. (0.7, 1, 1.4) for a
        plant whose gain is uncertain); default only 1.
    extra_integrators : sequence of int
        Values of ``n`` tried.
    max_iterations : int
        Nelder–Mead iterations per start.
    per_decade : int
        Density of the search grid.
    """

    gain_margin_db: float = 6.0
    phase_margin_deg: float = 30.0
    gain_reduction_margin_db: float = 6.0
    modulus_margin: float = 0.4
    objective_factor: float = 1.0
    frequency_scales: tuple[float, ...] = (0.95, 1.0, 1.05)
    damping_scales: tuple[float, ...] = (0.5, 1.0, 2.0)
    gain_scales: tuple[float, ...] = (1.0,)
    extra_integrators: tuple[int, ...] = (2, 3)
    max_iterations: int = 250
    per_decade: int = 60

    def to_json(self) -> dict[str, Any]:
        """Plain numbers."""
        return plain_json(self.__dict__)


@dataclass(frozen=True, eq=False)
class FsmDesign:
    """The designed controller and how the search ended.

    Attributes
    ----------
    controller : control.StateSpace
        ``Rh, Rv -> Uch, Ucv``, diagonal, cascade-realised.
    shapes : dict axis -> AxisShape
    scores : dict axis -> float
        Smallest normalised slack on the search grid (> 0: every requirement met).
    evaluations : dict axis -> int
    options : DesignOptions
    """

    controller: ct.StateSpace
    shapes: dict[str, AxisShape]
    scores: dict[str, float]
    evaluations: dict[str, int]
    options: DesignOptions = field(default_factory=DesignOptions)

    def to_json(self) -> dict[str, Any]:
        """Shapes, scores and options."""
        return plain_json({"shapes": {a: s.to_json() for a, s in self.shapes.items()},
                           "scores": self.scores, "evaluations": self.evaluations,
                           "options": self.options.to_json()})


def phase_travel(angle_rad: np.ndarray) -> np.ndarray:
    """The unwrapped phase's change from first to last point of each row [rad].

    ``np.unwrap(angle_rad, axis=1)[:, -1] - [:, 0]`` without building the unwrapped
    rows: a step of π or more is a wrap, the same rule as ``np.unwrap``'s; only the
    (few) wraps are corrected. It agrees with unwrap's to round-off (~1e-12 rad over
    thousands of points), so a count of half-turns is the same integer.

    Parameters
    ----------
    angle_rad : ndarray, shape (rows, points)
        Wrapped phases [rad], each row along a frequency grid.
    """
    step = np.diff(angle_rad, axis=1)
    rows, cols = np.nonzero(np.abs(step) >= np.pi)
    wrapped = step[rows, cols]
    unwrapped = np.mod(wrapped + np.pi, 2 * np.pi) - np.pi
    unwrapped[(unwrapped == -np.pi) & (wrapped > 0)] = np.pi
    correction = np.zeros(angle_rad.shape[0])
    np.add.at(correction, rows, unwrapped - wrapped)
    return np.asarray(angle_rad[:, -1] - angle_rad[:, 0] + correction, dtype=float)


# Search bounds of the shape parameters (log-space box, clipped inside the objective).
_LO = np.log([5.0, 0.03, 1.0, 0.3, 1.2, 0.15])
_HI = np.log([300.0, 0.6, 8.0, 3.0, 30.0, 1.5])


def _shape(x: np.ndarray, n: int) -> AxisShape:
    fc, ri, h, rz, rl, zl = np.exp(np.clip(x, _LO, _HI))
    return AxisShape(crossover_hz=float(fc), integrator_hz=float(ri * fc), extra_integrators=n,
                     lead_hz=float(rz * fc), lead_ratio=float(h), lowpass_hz=float(rl * fc),
                     lowpass_damping=float(zl))


class _AxisProblem:
    """Pre-computed plant responses of one axis over the robust set."""

    sigma = 1e-3  # contour shift of the Nyquist count [rad/s]

    def __init__(self, design: PlantModel, plants: Sequence[PlantModel], axis: int,
                 objective: ControlObjective, opts: DesignOptions) -> None:
        self.inp, self.out = ("Uch", "Ucv")[axis], ("Rh", "Rv")[axis]
        poles = np.concatenate([p.subsystem(outputs=[self.out], inputs=[self.inp]).poles()
                                for p in plants])
        self.f = frequency_grid(poles, f_min_hz=1e-2, f_max_hz=1e4, per_decade=opts.per_decade,
                                points_per_mode=61)
        w_low = np.concatenate([[0.0], np.logspace(-7, np.log10(2 * np.pi * self.f[0]), 120)[:-1]])
        self.s_low = self.sigma + 1j * w_low
        self.s = self.sigma + 2j * np.pi * self.f
        resp = [plant_response(p, self.s, outputs=[self.out], inputs=[self.inp])[:, 0, 0]
                for p in plants]
        dc = [plant_response(p, np.zeros(1), outputs=[self.out],
                             inputs=[self.inp])[0, 0, 0].real for p in plants]
        gains = np.asarray(opts.gain_scales, dtype=float)
        self.g = (np.array(resp)[None] * gains[:, None, None]).reshape(-1, self.f.size)
        self.g_low = (np.array(dc)[None] * gains[:, None]).reshape(-1)
        self.design = design
        self.sign = float(np.sign(dc[0]))
        self.s0 = 2j * np.pi * objective.frequency_hz
        self.g0 = plant_response(design, np.array([self.s0]), outputs=[self.out],
                                 inputs=[self.inp])[0, 0, 0]
        self.bound = objective.sensitivity_bound * opts.objective_factor
        self.opts = opts
        self.evaluations = 0
        # The design path once as arrays: normalised() evaluates it at one point per call
        # (thousands of calls), where building the sub-system each time cost more than
        # the solve.
        path = design.subsystem(outputs=[self.out], inputs=[self.inp])
        self._path = tuple(np.asarray(x, dtype=float) for x in (path.A, path.B, path.C, path.D))
        self._path_delay_s = float(design.input_delay_s.get(self.inp, 0.0))

    def design_response(self, s: complex) -> complex:
        """The design plant's path (with its input delay) at one complex ``s`` [rad/s]."""
        a, b, c, d = self._path
        x = np.linalg.solve(s * np.eye(a.shape[0]) - a, b.astype(complex))
        return complex((c @ x + d)[0, 0] * np.exp(-s * self._path_delay_s))

    def normalised(self, shape: AxisShape) -> AxisShape:
        sc = 2j * np.pi * shape.crossover_hz
        gc = self.design_response(sc)
        unit = replace(shape, gain=1.0)
        return replace(shape, gain=self.sign / abs(gc * complex(unit.response(np.array([sc]))[0])))

    def score(self, shape: AxisShape) -> float:
        self.evaluations += 1
        o = self.opts
        k = shape.response(self.s)
        lv = self.g * k[None]
        l_low = self.g_low[:, None] * shape.response(self.s_low)[None]
        travel = phase_travel(np.angle(1.0 + np.concatenate([l_low, lv], axis=1)))
        winding = np.rint(travel / np.pi)
        if np.any(winding != 0):
            return -10.0 - float(np.count_nonzero(winding))
        mag = np.abs(lv)
        cross = np.diff(np.sign(mag - 1.0), axis=1) != 0
        pm = float(np.min(180.0 - np.abs(np.degrees(np.angle(lv[:, :-1][cross]))),
                          initial=180.0))
        neg = (np.diff(np.sign(lv.imag), axis=1) != 0) & (lv.real[:, :-1] < 0) & (
            lv.real[:, 1:] < 0)
        at = mag[:, :-1][neg]
        gm = float(np.min(-20 * np.log10(at[at < 1]), initial=60.0))
        gr = float(np.min(20 * np.log10(at[at >= 1]), initial=60.0))
        mm = float(np.min(np.abs(1.0 + lv)))
        s1 = abs(1.0 / (1.0 + self.g0 * complex(shape.response(np.array([self.s0]))[0])))
        return min((gm - o.gain_margin_db) / o.gain_margin_db,
                   (gr - o.gain_reduction_margin_db) / o.gain_reduction_margin_db,
                   (pm - o.phase_margin_deg) / o.phase_margin_deg,
                   (mm - o.modulus_margin) / o.modulus_margin,
                   math.log(self.bound / s1) / math.log(2.0))

    def resonance_hz(self) -> float:
        g = self.design.subsystem(outputs=[self.out], inputs=[self.inp])
        p = g.poles()
        light = p[(p.imag > 0) & (-p.real < 0.05 * np.abs(p))]
        return float(np.min(np.abs(light)) / (2 * np.pi)) if light.size else 300.0


def design_controller(plant: PlantModel, *, objective: ControlObjective,
                      options: DesignOptions | None = None) -> FsmDesign:
    """Shape and tune the fsmbench controller on ``plant`` (delays included).

    Parameters
    ----------
    plant : PlantModel
        Design plant (nominal, true or identified); its ``Uch, Ucv -> Rh, Rv``
        diagonal paths are shaped, the coupling is left to the verification.
    objective : ControlObjective
        The 6.1 bound.
    options : DesignOptions, optional

    Returns
    -------
    FsmDesign
        ``controller`` has inputs ``Rh, Rv`` and outputs ``Uch, Ucv``; close it as ``u = -K y``.
    """
    opts = options or DesignOptions()
    plants = [p for _, p in perturbed_plants(plant, frequency_scales=opts.frequency_scales,
                                             damping_scales=opts.damping_scales)]
    shapes: dict[str, AxisShape] = {}
    scores: dict[str, float] = {}
    evals: dict[str, int] = {}
    for i, axis in enumerate(AXES):
        prob = _AxisProblem(plant, plants, i, objective, opts)
        f_res = prob.resonance_hz()
        starts = [np.log([f_res / 8, 0.2, 2.0, 1.0, 3.0, 0.6]),
                  np.log([f_res / 12, 0.25, 1.5, 1.5, 2.5, 0.7])]
        best: tuple[float, AxisShape] | None = None
        for n in opts.extra_integrators:
            def cost(x: np.ndarray, n: int = n, prob: _AxisProblem = prob) -> float:
                return -prob.score(prob.normalised(_shape(x, n)))
            for x0 in starts:
                res = optimize.minimize(cost, x0, method="Nelder-Mead",
                                        options={"maxiter": opts.max_iterations,
                                                 "xatol": 1e-3, "fatol": 1e-4})
                cand = prob.normalised(_shape(res.x, n))
                sc = prob.score(cand)
                if best is None or sc > best[0]:
                    best = (sc, cand)
        assert best is not None
        scores[axis], shapes[axis] = best
        evals[axis] = prob.evaluations
    parts = [shapes[a].realise(input_name=m, output_name=c)
             for a, m, c in zip(AXES, ("Rh", "Rv"), ("Uch", "Ucv"), strict=True)]
    k = ct.append(*parts)
    k = ct.ss(k.A, k.B, k.C, k.D, inputs=["Rh", "Rv"], outputs=["Uch", "Ucv"], name="Kfsm")
    return FsmDesign(controller=k, shapes=shapes, scores=scores, evaluations=evals, options=opts)


# ----------------------------------------------------------------------------- robustness


@dataclass(frozen=True, eq=False)
class Robustness:
    """A controller verified over the perturbed set.

    Attributes
    ----------
    labels : tuple of str
        One per perturbed plant.
    loops : tuple of LoopAnalysis
        The verification of each.
    all_stable : bool
        Closed-loop poles (Padé) and Nyquist count agree on stability for every plant.
    worst_gain_margin_db, worst_phase_margin_deg, worst_modulus_margin : float
        Smallest over plants and axes.
    worst_sensitivity_at_f0 : float
        Largest ``sigma_max(S(j 2 pi f0))``.
    """

    labels: tuple[str, ...]
    loops: tuple[LoopAnalysis, ...]
    all_stable: bool
    worst_gain_margin_db: float
    worst_phase_margin_deg: float
    worst_modulus_margin: float
    worst_sensitivity_at_f0: float

    def to_json(self) -> dict[str, Any]:
        """Worst cases and one line per plant."""
        cases = [{"label": lab, "stable": lp.stable, "nyquist_stable": lp.nyquist.stable,
                  **{a: {"gain_margin_db": ax.margins.gain_margin_db,
                         "phase_margin_deg": ax.margins.phase_margin_deg,
                         "modulus_margin": ax.margins.modulus_margin,
                         "crossover_hz": ax.margins.crossover_hz}
                     for a, ax in lp.axes.items()}}
                 for lab, lp in zip(self.labels, self.loops, strict=True)]
        return plain_json({"all_stable": self.all_stable,
                           "worst_gain_margin_db": self.worst_gain_margin_db,
                           "worst_phase_margin_deg": self.worst_phase_margin_deg,
                           "worst_modulus_margin": self.worst_modulus_margin,
                           "worst_sensitivity_at_1hz": self.worst_sensitivity_at_f0,
                           "cases": cases})


def robustness(plant: PlantModel, k: ct.StateSpace, *, objective: ControlObjective,
               frequency_scales: Sequence[float] = (0.95, 1.0, 1.05),
               damping_scales: Sequence[float] = (0.5, 1.0, 2.0),
               options: LoopOptions | None = None) -> Robustness:
    """Verify ``u = -K y`` on every plant of :func:`perturbed_plants`."""
    opts = options or LoopOptions(per_decade=60)
    labels, loops = [], []
    for label, p in perturbed_plants(plant, frequency_scales=frequency_scales,
                                     damping_scales=damping_scales):
        labels.append(label)
        loops.append(analyse_loop(p, k, objective=objective, name=label, options=opts))
    axes = [ax for lp in loops for ax in lp.axes.values()]
    return Robustness(
        labels=tuple(labels), loops=tuple(loops),
        all_stable=all(lp.stable and lp.nyquist.stable for lp in loops),
        worst_gain_margin_db=min(a.margins.gain_margin_db for a in axes),
        worst_phase_margin_deg=min(a.margins.phase_margin_deg for a in axes),
        worst_modulus_margin=min(a.margins.modulus_margin for a in axes),
        worst_sensitivity_at_f0=max(lp.sensitivity_at_f0 for lp in loops))

