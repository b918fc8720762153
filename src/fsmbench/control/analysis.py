"""Plant analysis before control design (ESRF study sections 5, 6 and 7).

* :func:`control_objective`: the 6.1 requirement, ``|S(j 2 pi f0)| < e_max / y_max``,
  and the loop gain it needs.
* :func:`normalized_coprime_factors`: the left normalised coprime factorisation
  ``G = M^-1 N`` of 5.1 (MATLAB's ``lncf``) and the largest normalised
  coprime-factor stability margin ``b_max = sqrt(1 - ||[N M]||_H^2)``.
* :func:`analyse_plant`: RGA number and singular values over frequency (7.2),
  the static gain and its rotation (7.3), the Table 5 scaling (6).

The ESRF study's 6.1 text has slips (see ``ControlObjective``): the stroke
"3 mm ≈ 5e-2 rad" is an angle (3° = 5.24e-2 rad, the beam swing of the
Newport's full ±10 V command, 2 × 26.2 mrad), "``< 2e-4``" is an equality,
and ``|L| > 5e3`` is the ``|L| >> 1`` approximation of ``|1 + L| > 1/|S|``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import control as ct
import numpy as np
from scipy import linalg

from fsmbench.bench.blocks import PlantModel, ss_response
from fsmbench.bench.params import BenchParams
from fsmbench.checks import Check
from fsmbench.control.freq import evaluate_ss, frequency_grid, plain_json, plant_response

__all__ = [
    "SEED_LOOP_GAIN_AT_F0",
    "AnalysisError",
    "ControlObjective",
    "CoprimeFactors",
    "PlantAnalysis",
    "analyse_plant",
    "balanced_minimal",
    "control_objective",
    "normalized_coprime_factors",
    "rga",
    "rga_number",
]

SEED_LOOP_GAIN_AT_F0 = 5e3  # seed 6.1: "|L(j w0)| > 5e3"


@dataclass(frozen=True)
class ControlObjective:
    """The control objective of ESRF study 6.1 from the Table 5 values.

    Attributes
    ----------
    frequency_hz : float
        ``f0`` [Hz], where the stroke is expected (1 Hz).
    error_max_rad : float
        ``e_max`` [rad], the largest wanted beam-angle error (10 µrad).
    stroke_max_rad : float
        ``y_max`` [rad], the expected beam stroke at ``f0`` (5e-2 rad).
    sensitivity_bound : float
        ``e_max / y_max`` [1]: the objective is ``|S(j 2 pi f0)| <`` this.
    loop_gain_sufficient : float
        ``1/b + 1``: any loop with ``|L| >`` this meets the bound, whatever its phase.
    loop_gain_necessary : float
        ``1/b - 1``: no loop with ``|L| <`` this meets it.
    seed_loop_gain : float
        The ESRF study's rounded requirement, 5e3.
    table5_stroke_rad : float
        Beam stroke of Table 5's "expected perturbation" ``Un = 1 V``:
        ``2 gn un_max`` [rad] (5.24e-3 rad, ten times below 6.1's stroke).
    table5_sensitivity_bound : float
        ``e_max / table5_stroke_rad`` [1].
    """

    frequency_hz: float
    error_max_rad: float
    stroke_max_rad: float
    sensitivity_bound: float
    loop_gain_sufficient: float
    loop_gain_necessary: float
    seed_loop_gain: float
    table5_stroke_rad: float
    table5_sensitivity_bound: float

    def met_by(self, sensitivity: float) -> bool:
        """Whether ``|S(j 2 pi f0)| = sensitivity`` meets the bound."""
        return bool(sensitivity < self.sensitivity_bound)

    def to_json(self) -> dict[str, Any]:
        """Plain floats; ``sensitivity_bound_at_1hz`` is the bound at ``f0``."""
        return plain_json({"sensitivity_bound_at_1hz": self.sensitivity_bound,
                           **self.__dict__})


def control_objective(params: BenchParams) -> ControlObjective:
    """The 6.1 objective from ``params.scaling`` (Table 5) and the Newport gain."""
    sc = params.scaling
    bound = sc.error_max_rad / sc.stroke_max_rad
    gn = float(np.mean(params.newport.gain_rad_per_v.as_array()))
    stroke5 = params.newport.beam_angle_per_mirror_angle * gn * sc.un_max_v
    return ControlObjective(
        frequency_hz=sc.objective_freq_hz, error_max_rad=sc.error_max_rad,
        stroke_max_rad=sc.stroke_max_rad, sensitivity_bound=bound,
        loop_gain_sufficient=1.0 / bound + 1.0, loop_gain_necessary=1.0 / bound - 1.0,
        seed_loop_gain=SEED_LOOP_GAIN_AT_F0, table5_stroke_rad=stroke5,
        table5_sensitivity_bound=sc.error_max_rad / stroke5)


# ----------------------------------------------------------------------------- RGA


def rga(g: np.ndarray) -> np.ndarray:
    """Relative gain array ``G .* inv(G)^T`` of square matrices, shape (..., n, n)."""
    g = np.asarray(g)
    return g * np.swapaxes(np.linalg.inv(g), -1, -2)


def rga_number(g: np.ndarray) -> np.ndarray:
    """``sum |RGA - I|`` (ESRF study 7.2), shape (...)."""
    lam = rga(g)
    return np.sum(np.abs(lam - np.eye(lam.shape[-1])), axis=(-1, -2))


# ----------------------------------------------------------------------------- coprime factors


@dataclass(frozen=True, eq=False)
class CoprimeFactors:
    """Left normalised coprime factorisation ``G = M^-1 N`` (ESRF study 5.1, MATLAB ``lncf``).

    Attributes
    ----------
    n, m : control.StateSpace
        Stable factors with ``N N~ + M M~ = I``; ``n`` has the plant's inputs,
        ``m`` the plant's outputs as inputs.
    b_max : float
        ``sqrt(1 - ||[N M]||_H^2)`` [1]: the largest normalised coprime-factor
        uncertainty any controller can stabilise (MATLAB ``ncfmargin`` of the
        best controller).
    hankel_norm : float
        ``||[N M]||_H`` from the factors' Gramians.
    b_max_riccati : float
        ``1 / sqrt(1 + rho(X Z))`` from the two Riccati solutions (same number).
    """

    n: ct.StateSpace
    m: ct.StateSpace
    b_max: float
    hankel_norm: float
    b_max_riccati: float

    def to_json(self) -> dict[str, Any]:
        """The margins (the factors are models, not numbers)."""
        return plain_json({"b_max": self.b_max, "hankel_norm": self.hankel_norm,
                           "b_max_riccati": self.b_max_riccati,
                           "n_states": int(self.n.nstates)})


class AnalysisError(ValueError):
    """An optional analysis that cannot be computed on this plant; the message says why."""


def balanced_minimal(sys: ct.StateSpace, *, rtol: float = 1e-12) -> ct.StateSpace:
    """Square-root balanced realisation of a stable model, without its negligible states.

    The identified plants are realised column by column, so each mode appears
    once per input: a non-minimal model whose uncontrollable or unobservable
    copies of ~1 Hz-wide modes put eigenvalues of every Riccati equation's
    Hamiltonian within 0.3 % of the imaginary axis (scipy and SLICOT both refuse
    them, ``benchmarks/bench_coprime.py``). States whose Hankel singular value is
    below ``rtol`` times the largest carry no input–output behaviour and are
    dropped; the rest are balanced, so the equations that follow are well scaled.

    Parameters
    ----------
    sys : control.StateSpace
        Continuous, asymptotically stable (every pole in the open left half-plane).
    rtol : float
        Hankel singular values below ``rtol`` × the largest are removed [1]: the
        duplicated modes' are ~1e-17 of it (rounding), a real but fast state's
        (the 125 kHz coil pole beside the 1 Hz-wide modes) ~1e-8. The reduced
        model is checked against the original on a frequency grid (relative
        1e-9 of its peak); if it misses, the original is returned.

    Returns
    -------
    control.StateSpace
        Same inputs, outputs and D; states ``x0, x1, ...``.

    Raises
    ------
    AnalysisError
        The model is not stable (its Gramians do not exist).
    """
    a, b, c, d = (np.asarray(x, dtype=float) for x in (sys.A, sys.B, sys.C, sys.D))
    labels = {"inputs": list(sys.input_labels), "outputs": list(sys.output_labels)}
    if a.shape[0] == 0:
        return ct.ss(a, b, c, d, **labels)
    # A diagonal similarity first: the coil current (A/V) and the mirror angles (rad) differ
    # by orders of magnitude, which the Gramians' square roots would not resolve.
    a, (scale_d, _perm) = linalg.matrix_balance(a, permute=False, separate=True)
    b = b / scale_d[:, None]
    c = c * scale_d[None, :]
    poles = np.linalg.eigvals(a)
    if np.any(poles.real >= 0):
        raise AnalysisError(f"the model has {int(np.sum(poles.real >= 0))} pole(s) in the closed "
                            "right half-plane; a balanced realisation needs a stable model")
    wc = linalg.solve_continuous_lyapunov(a, -b @ b.T)
    wo = linalg.solve_continuous_lyapunov(a.T, -c.T @ c)

    def factor(w: np.ndarray) -> np.ndarray:
        # Gramians of a non-minimal model are singular: a symmetric square root
        # (negative rounding clipped) instead of a Cholesky factor.
        vals, vecs = np.linalg.eigh((w + w.T) / 2)
        return np.asarray(vecs * np.sqrt(np.clip(vals, 0.0, None)))

    lc, lo = factor(wc), factor(wo)
    u, hsv, vt = np.linalg.svd(lo.T @ lc)
    if hsv.size == 0 or hsv[0] == 0.0:
        return ct.ss(np.zeros((0, 0)), np.zeros((0, b.shape[1])), np.zeros((c.shape[0], 0)),
                     d, **labels)
    k = int(np.sum(hsv > rtol * hsv[0]))
    if k == a.shape[0]:
        # Minimal already: the transformation would only add rounding (a 125 kHz coil pole
        # beside 1 Hz-wide modes spans ten decades of Hankel singular values).
        return ct.ss(a, b, c, d, **labels)
    scale = hsv[:k] ** -0.5
    t = (lc @ vt[:k].T) * scale
    t_inv = scale[:, None] * (u[:, :k].T @ lo.T)
    reduced = ct.ss(t_inv @ a @ t, t_inv @ b, c @ t, d, **labels)
    # The reduction must not change the model: compare on a grid spanning its poles.
    w = np.abs(poles)
    s = 1j * np.concatenate([[0.0], np.geomspace(max(w.min(), 1e-3) / 10, w.max() * 10, 400),
                             w])
    full = ss_response(ct.ss(a, b, c, d), s)
    err = np.max(np.abs(ss_response(reduced, s) - full)) / np.max(np.abs(full))
    if not err <= 1e-9:
        return ct.ss(a, b, c, d, **labels)
    return reduced


def normalized_coprime_factors(sys: ct.StateSpace) -> CoprimeFactors:
    """Left normalised coprime factors of a continuous, delay-free, stable model.

    The model is first brought to a balanced minimal realisation
    (:func:`balanced_minimal`). With ``R = I + D D^T``, ``Z`` solves the filter
    Riccati equation
    ``A Z + Z A^T - (Z C^T + B D^T) R^-1 (C Z + D B^T) + B B^T = 0`` and
    ``H = -(B D^T + Z C^T) R^-1``; then (Zhou, Doyle & Glover, sec. 13.6)

        N = [A + H C | B + H D; R^-1/2 C | R^-1/2 D]
        M = [A + H C | H;       R^-1/2 C | R^-1/2]

    Parameters
    ----------
    sys : control.StateSpace
        ``p`` outputs, ``m`` inputs; stable.

    Raises
    ------
    AnalysisError
        The model is unstable, or a Riccati equation has no stabilising
        solution even on the balanced minimal realisation (named).
    """
    minimal = balanced_minimal(sys)
    a, b, c, d = (np.asarray(x, dtype=float) for x in (minimal.A, minimal.B, minimal.C,
                                                        minimal.D))
    p, m = d.shape
    r = np.eye(p) + d @ d.T
    s_in = np.eye(m) + d.T @ d
    try:
        # Filter ARE as the dual control ARE of scipy: A^T X + X A - (X B + S) R^-1 (...)^T + Q = 0.
        z = linalg.solve_continuous_are(a.T, c.T, b @ b.T, r, s=b @ d.T)
        x = linalg.solve_continuous_are(a, b, c.T @ c, s_in, s=c.T @ d)
    except (np.linalg.LinAlgError, ValueError) as exc:
        raise AnalysisError(f"the Riccati equation of the coprime factors has no stabilising "
                            f"solution on the {a.shape[0]}-state balanced realisation ({exc})"
                            ) from exc
    h = -(b @ d.T + z @ c.T) @ np.linalg.inv(r)
    r_isqrt = np.real(linalg.inv(linalg.sqrtm(r)))
    af = a + h @ c
    n_f = ct.ss(af, b + h @ d, r_isqrt @ c, r_isqrt @ d, inputs=list(sys.input_labels),
                outputs=list(sys.output_labels), name="N")
    m_f = ct.ss(af, h, r_isqrt @ c, r_isqrt, inputs=list(sys.output_labels),
                outputs=list(sys.output_labels), name="M")
    bb = np.hstack([b + h @ d, h])
    cc = r_isqrt @ c
    wc = linalg.solve_continuous_lyapunov(af, -bb @ bb.T)
    wo = linalg.solve_continuous_lyapunov(af.T, -cc.T @ cc)
    hankel = float(np.sqrt(np.max(np.real(np.linalg.eigvals(wc @ wo)), initial=0.0)))
    rho = float(np.max(np.real(np.linalg.eigvals(x @ z)), initial=0.0))
    if not (np.isfinite(hankel) and np.isfinite(rho)):
        raise AnalysisError("the coprime factors' Gramians are not finite")
    return CoprimeFactors(n=n_f, m=m_f, b_max=float(np.sqrt(max(0.0, 1.0 - hankel**2))),
                          hankel_norm=hankel, b_max_riccati=float(1.0 / np.sqrt(1.0 + rho)))


# ----------------------------------------------------------------------------- plant analysis


@dataclass(frozen=True, eq=False)
class PlantAnalysis:
    """ESRF study sections 5 to 7 on one plant.

    Attributes
    ----------
    f_hz : array, shape (n,)
        Frequencies [Hz], up to ``nyquist_hz`` by default.
    g : array, complex, shape (n, 2, 2)
        ``Uch, Ucv -> Rh, Rv`` [rad/V], delays included.
    rga_number : array, shape (n,)
        ``sum |RGA - I|`` [1].
    singular_values : array, shape (n, 2)
        Of ``g`` [rad/V], largest first.
    g0 : array, shape (2, 2)
        Static gain [rad/V].
    decoupler : array, shape (2, 2)
        ``inv(g0)`` [V/rad], the static decoupler.
    rotation_rad : float
        Angle of the orthogonal polar factor of ``g0 diag(g0)^-1`` [rad]: the
        part of the coupling a rotation of the 4QD frame explains.
    coupling : array, shape (2, 2)
        ``g0 diag(g0)^-1 - I`` [1], relative static coupling.
    scaled_min_singular_value : array, shape (n,)
        ``sigma_min(G uc_max / e_max)`` [1], the Table 5-scaled plant.
    scaled_disturbance_gain : array, shape (n,)
        ``sigma_max(Gn un_max / e_max)`` [1], the scaled Newport disturbance.
    disturbance_bandwidth_hz : float
        Highest frequency where the scaled disturbance gain exceeds 1 [Hz]
        (searched up to 1 MHz; NaN beyond): where feedback would have to act
        to hold Table 5's 1 V Newport perturbation within ``e_max``.
    inputs_suffice : bool
        ``sigma_min(Gs) >= sigma_max(Gds) - 1`` wherever ``sigma_max(Gds) > 1``
        on the grid up to ``nyquist_hz``: a 10 V command can cancel a 1 V
        Newport disturbance (the sampled loop acts on nothing above).
    disturbance_rolloff_hz : float
        Lowest natural frequency of the Newport block ``Gn`` [Hz], where its
        response starts to fall; NaN when the model's Newport is a constant gain.
    coprime : CoprimeFactors or None
        Of ``Gc Gi`` (``Uch, Ucv -> Vpch, Vpcv``, V/V), as ESRF study 5.1; None when
        it cannot be computed (``checks`` says why).
    coprime_scaled : CoprimeFactors or None
        Of the scaled plant ``Uc/uc_max -> R/e_max``; None likewise.
    objective : ControlObjective
    checks : tuple of Check
        One per optional analysis: passed when computed, failed with the reason.
    nyquist_hz : float
        Half the sampling frequency of the converters and the controller [Hz].
    inputs_short_from_hz : float
        Lowest grid frequency [Hz] where ``inputs_suffice`` fails; NaN when it holds.
    """

    f_hz: np.ndarray
    g: np.ndarray
    rga_number: np.ndarray
    singular_values: np.ndarray
    g0: np.ndarray
    decoupler: np.ndarray
    rotation_rad: float
    coupling: np.ndarray
    scaled_min_singular_value: np.ndarray
    scaled_disturbance_gain: np.ndarray
    disturbance_bandwidth_hz: float
    inputs_suffice: bool
    coprime: CoprimeFactors | None
    coprime_scaled: CoprimeFactors | None
    objective: ControlObjective
    checks: tuple[Check, ...] = ()
    disturbance_rolloff_hz: float = float("nan")
    nyquist_hz: float = float("inf")
    inputs_short_from_hz: float = float("nan")

    def to_json(self) -> dict[str, Any]:
        """Scalars and the static matrices; the curves are left out."""
        k = int(np.argmax(self.rga_number))
        return plain_json({
            "g0_rad_per_v": self.g0, "decoupler_v_per_rad": self.decoupler,
            "rotation_rad": self.rotation_rad, "static_coupling": self.coupling,
            "rga_number_dc": float(rga_number(self.g0)),
            "rga_number_max": float(self.rga_number[k]),
            "rga_number_max_at_hz": float(self.f_hz[k]),
            "condition_number_dc": float(np.linalg.cond(self.g0)),
            "disturbance_bandwidth_hz": self.disturbance_bandwidth_hz,
            "disturbance_rolloff_hz": self.disturbance_rolloff_hz,
            "inputs_suffice": self.inputs_suffice,
            "inputs_short_from_hz": self.inputs_short_from_hz,
            "coprime": None if self.coprime is None else self.coprime.to_json(),
            "coprime_scaled": None if self.coprime_scaled is None
            else self.coprime_scaled.to_json(),
            "objective": self.objective.to_json(),
        })


def analyse_plant(plant: PlantModel, *, params: BenchParams,
                  f_hz: np.ndarray | None = None,
                  inputs: Sequence[str] = ("Uch", "Ucv"),
                  outputs: Sequence[str] = ("Rh", "Rv"),
                  disturbances: Sequence[str] = ("Unh", "Unv")) -> PlantAnalysis:
    """RGA, singular values, static decoupling, scaling and coprime factors of a plant.

    Parameters
    ----------
    plant : PlantModel
        Physical or identified.
    params : BenchParams
        Supplies Table 5 (``scaling``) and the Newport gain of the objective.
    f_hz : array, optional
        Frequencies [Hz]; default 0.01 Hz to the Nyquist frequency of
        ``params.converter`` (5 kHz at 10 kHz), refined at the plant's modes.
    inputs, outputs, disturbances : sequence of str
        Command, measurement and disturbance signals.
    """
    nyquist_hz = 0.5 * params.converter.fs_hz
    f = (frequency_grid(plant.sys.poles(), f_min_hz=1e-2, f_max_hz=nyquist_hz, per_decade=60)
         if f_hz is None else np.asarray(f_hz, dtype=float))
    s = 2j * np.pi * f
    g = plant_response(plant, s, outputs=outputs, inputs=inputs)
    gd = plant_response(plant, s, outputs=outputs, inputs=disturbances)
    g0 = np.real(evaluate_ss(plant.subsystem(outputs=outputs, inputs=inputs), np.zeros(1))[0])
    norm = g0 @ np.diag(1.0 / np.diag(g0))
    u_polar, _ = linalg.polar(norm)
    sc = params.scaling
    gs_min = np.linalg.svd(g * sc.uc_max_v / sc.error_max_rad, compute_uv=False)[:, -1]
    gds_max = np.linalg.svd(gd * sc.un_max_v / sc.error_max_rad, compute_uv=False)[:, 0]
    # Only where the sampled loop can act: a frequency above Nyquist is not in its band.
    above = (gds_max > 1.0) & (f <= nyquist_hz)
    short = above & (gs_min < gds_max - 1.0)
    band = _disturbance_bandwidth(plant, outputs, disturbances, sc.un_max_v / sc.error_max_rad)
    gcgi = ct.series(plant.blocks["Gi"], plant.blocks["Gc"])
    gcgi = ct.ss(gcgi.A, gcgi.B, gcgi.C, gcgi.D, inputs=list(inputs),
                 outputs=["Vpch", "Vpcv"])
    delay_free = plant.subsystem(outputs=outputs, inputs=inputs)
    scaled = ct.ss(delay_free.A, delay_free.B * sc.uc_max_v, delay_free.C / sc.error_max_rad,
                   delay_free.D * sc.uc_max_v / sc.error_max_rad, inputs=list(inputs),
                   outputs=list(outputs))
    coprime, check_gcgi = _coprime_or_check(gcgi, subject="Gc Gi (Uc → Vpc, V/V)")
    coprime_scaled, check_scaled = _coprime_or_check(
        scaled, subject="the Table 5-scaled plant (Uc/uc_max → R/e_max)")
    return PlantAnalysis(
        f_hz=f, g=g, rga_number=rga_number(g),
        singular_values=np.linalg.svd(g, compute_uv=False), g0=g0,
        decoupler=np.linalg.inv(g0),
        rotation_rad=float(np.arctan2(u_polar[1, 0], u_polar[0, 0])),
        coupling=norm - np.eye(2), scaled_min_singular_value=gs_min,
        scaled_disturbance_gain=gds_max, disturbance_bandwidth_hz=band,
        inputs_suffice=not bool(np.any(short)),
        inputs_short_from_hz=float(f[short][0]) if np.any(short) else float("nan"),
        coprime=coprime, coprime_scaled=coprime_scaled,
        objective=control_objective(params), checks=(check_gcgi, check_scaled),
        disturbance_rolloff_hz=_rolloff_hz(plant.blocks["Gn"]), nyquist_hz=nyquist_hz)



def _rolloff_hz(block: ct.StateSpace) -> float:
    """Lowest natural frequency of a block's poles [Hz]; NaN for a static block."""
    poles = (np.linalg.eigvals(np.asarray(block.A, dtype=float)) if block.nstates
             else np.zeros(0))
    w = [abs(p) for p in poles if abs(p) > 0]
    return float(min(w) / (2 * np.pi)) if w else float("nan")


def _coprime_or_check(sys: ct.StateSpace, *, subject: str
                      ) -> tuple[CoprimeFactors | None, Check]:
    """The coprime factors of ``sys``, or None and a failed check naming why."""
    try:
        factors = normalized_coprime_factors(sys)
    except AnalysisError as exc:
        return None, Check("coprime_factor_margin", False, None, "computable", subject=subject,
                           advice=f"{exc}; the margin b_max is left out, the rest of the "
                                  "analysis stands")
    return factors, Check("coprime_factor_margin", True, factors.b_max, "computable",
                          subject=subject)


def _disturbance_bandwidth(plant: PlantModel, outputs: Sequence[str],
                           disturbances: Sequence[str], scale: float) -> float:
    """Highest frequency [Hz] below 1 MHz where ``sigma_max(scale Gd) > 1``; NaN if above."""
    f = np.logspace(-2, 6, 801)
    gd = plant_response(plant, 2j * np.pi * f, outputs=outputs, inputs=disturbances)
    above = np.linalg.svd(gd * scale, compute_uv=False)[:, 0] > 1.0
    if not above.any():
        return 0.0
    if above[-1]:
        return float("nan")
    return float(f[np.nonzero(above)[0][-1]])
