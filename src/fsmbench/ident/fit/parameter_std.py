"""Standard deviations of the Sercalo's identified parameters from the FRF's per-line variance.

The rational model of :func:`fsmbench.ident.fit.vectfit.vector_fit` (common poles,
real partial-fraction coefficients per element, constant ``D``) is treated as
the weighted nonlinear least-squares estimate

    theta_hat = argmin sum_{f, i, j} |w_fij (H_model(theta; f)_ij - H_fij)|^2

with ``w = 1 / std(H)`` from the FRF estimator (periodic averaging, LPM; for
Welch the Bendat & Piersol variance). When the lines' errors are independent
and circular with those variances, the weighted residuals have unit variance
and, to first order in the noise (Gauss–Newton; Pintelon & Schoukens,
*System Identification*, ch. 7–9, the covariance of a weighted least-squares
estimator),

    cov(theta_hat) = s2 (J^T J)^-1,     J = d(weighted residual)/d theta,

with ``s2 = max(1, SSR / dof)``: 1 when the model fits to within the noise
(``SSR / dof`` is then ~1), inflated by the reduced chi-square when the model
misses the data by more than the noise (a Birge-ratio correction, so the
standard deviations are not optimistic for a misfit). The derived quantities
``g(theta)`` — resonance ``|a| / 2 pi`` and damping ``-Re a / |a|`` of the
pole pair of each axis, and the static gain ``Gc(0)_jj = H_model(0)_jj / Gi_j``
— get ``cov g = G cov(theta) G^T`` with ``G = dg/dtheta``.

``J`` and ``G`` are central finite differences (steps 1e-6 relative to each
parameter's scale): the model is cheap and this avoids a second, analytic
derivation that could disagree with the model's evaluation. The
current-amplifier gain ``Gi`` and the delay are taken as known: their own
uncertainty (``current_amp.*.gain_std_a_per_v``, ``delay_std_s``) is reported
separately. With ``fixed_poles`` (the modes replaced by the time-domain
refinement) only the linear coefficients are free and the resonance and
damping standard deviations are NaN (the refinement gives its own).

Lines must be nearly independent for this to hold: the periodic estimator's
lines are; the LPM's are once strided by the window width (what the
identification uses); adjacent Welch bins with a Hann window overlap: the
variances are multiplied by the lines one window correlates
(``correlated_lines``, 1.5 for Hann: its equivalent noise bandwidth in
bins), as the Newport's fit does (the static gain's std was 1.6–1.8×
optimistic without).

When the weights are not the inverse standard deviations (the seed's
coherence recipe), the covariance is the sandwich ``A⁻¹ Jᵀ Σ J A⁻¹`` with
``A = JᵀJ`` of the weighted residuals and ``Σ`` their noise covariance from
the lines' variances; ``variance_parts`` splits it into the parts of each
line's variance (noise, distortion, leakage), each propagated alone.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from fsmbench.ident.fit.vectfit_model import (
    VectorFit,
    coefficients_from_residues,
    pole_groups,
    real_basis,
)

__all__ = ["ParameterStd", "sercalo_parameter_std"]

_STEP = 1e-6  # relative finite-difference step: ~sqrt(eps) of float64 for central differences
QUANTITIES = ("resonance_hz", "damping_ratio", "dc_gain_v_per_a")


@dataclass(frozen=True)
class ParameterStd:
    """Identified parameters per axis and their standard deviations.

    Attributes
    ----------
    value : dict axis -> dict quantity -> float
        ``resonance_hz`` [Hz], ``damping_ratio`` [1], ``dc_gain_v_per_a`` [V/A]
        of the fitted model, axes ``"h"`` and ``"v"``.
    std : dict axis -> dict quantity -> float
        One-sigma standard deviations, same units; NaN when not estimated.
    chi2_per_dof : float
        ``SSR / dof`` of the weighted fit, real and imaginary parts counted
        separately (~1 when the weights are the inverse noise std and the
        model fits to within the noise).
    dof : int
        Real residuals minus free real parameters.
    fixed_poles : bool
        Whether the poles were held fixed (resonance/damping std NaN).
    parts : dict axis -> dict quantity -> dict part -> float
        The standard deviation each part of the lines' variance contributes,
        and ``misfit`` (same units as ``std``; they add in quadrature to it).
    """

    value: dict[str, dict[str, float]] = field(default_factory=dict)
    std: dict[str, dict[str, float]] = field(default_factory=dict)
    chi2_per_dof: float = float("nan")
    dof: int = 0
    fixed_poles: bool = False
    parts: dict[str, dict[str, dict[str, float]]] = field(default_factory=dict)

    def to_json(self) -> dict[str, object]:
        """Plain values: ``{h: {resonance_hz, resonance_hz_std, ...}, ..., chi2_per_dof}``."""
        out: dict[str, object] = {
            axis: {**{q: v for q, v in vals.items()},
                   **{f"{q}_std": s for q, s in self.std[axis].items()}}
            for axis, vals in self.value.items()}
        out.update(chi2_per_dof=self.chi2_per_dof, dof=self.dof, fixed_poles=self.fixed_poles,
                   parts=self.parts)
        return out


def _pole_params(poles: NDArray[np.complex128]) -> NDArray[np.float64]:
    out: list[float] = []
    for k, pair in pole_groups(poles):
        out += [poles[k].real, poles[k].imag] if pair else [poles[k].real]
    return np.array(out)


def _poles_from(params: NDArray[np.float64], template: NDArray[np.complex128]
                ) -> NDArray[np.complex128]:
    poles = np.empty_like(template)
    i = 0
    for k, pair in pole_groups(template):
        if pair:
            a = complex(params[i], params[i + 1])
            poles[k], poles[k + 1] = a, a.conjugate()
            i += 2
        else:
            poles[k] = params[i]
            i += 1
    return poles


def sercalo_parameter_std(
    fit: VectorFit,
    frequency_hz: NDArray[np.float64],
    response: NDArray[np.complex128],
    weights: NDArray[np.float64],
    *,
    resonances_hz: Mapping[str, float],
    gi_a_per_v: Sequence[float] | NDArray[np.float64],
    fixed_poles: bool = False,
    variance_parts: Mapping[str, NDArray[np.float64]] | None = None,
    correlated_lines: float = 1.0,
) -> ParameterStd:
    """Propagate the FRF's per-line variance to the Sercalo's resonance, damping and gain.

    Parameters
    ----------
    fit : VectorFit
        The fitted ``Uc -> Vp`` model (asymptote ``D``), inputs ``(Uch, Ucv)``,
        outputs ``(Vph, Vpv)``.
    frequency_hz : ndarray, shape (F,)
        Lines of the fit, Hz (> 0).
    response : ndarray, complex, shape (F, 2, 2)
        The delay-free FRF that was fitted, V/V.
    weights : ndarray, shape (F, 2, 2)
        The fit's weights, ``1 / std(H)`` per line and element, V/V^-1 (0 drops a line).
    resonances_hz : mapping input -> Hz
        Detected resonance of each column; the pole pair nearest to it is the
        axis's mode (``Uch`` -> ``h``, ``Ucv`` -> ``v``).
    gi_a_per_v : sequence of 2 float
        Current-amplifier gains ``(h, v)``, A/V.
    fixed_poles : bool
        Hold the poles fixed (only residues and ``D`` free).
    variance_parts : mapping str -> ndarray (F, 2, 2), optional
        What each line's error variance is made of [(V/V)²] (``noise``,
        ``distortion``, ``leakage`` …). Default: ``{"noise": 1/weights²}`` (the
        weights are the inverse std). With other weights (the seed's), the
        covariance is the sandwich ``A⁻¹ Jᵀ Σ J A⁻¹`` of the weighted fit.
    correlated_lines : float
        Adjacent lines one estimate correlates (≥ 1; Welch's Hann window: 1.5):
        every variance grows by it.

    Returns
    -------
    ParameterStd
        ``std`` total; ``parts`` per quantity: each variance part's share and
        ``misfit`` (the reduced chi-square's inflation above 1).
    """
    poles0 = np.asarray(fit.poles)
    coef0 = coefficients_from_residues(poles0, np.asarray(fit.residues))  # (n, p, m)
    lin0 = np.concatenate([coef0, np.asarray(fit.d)[None]], axis=0).reshape(-1)  # (n+1)*p*m
    pp0 = _pole_params(poles0)
    theta0 = lin0 if fixed_poles else np.concatenate([pp0, lin0])
    w = np.asarray(weights, dtype=float)
    keep = w > 0.0
    problem = _WeightedFit(
        poles0=poles0, shape=coef0.shape, n_pole_params=pp0.size, fixed_poles=fixed_poles,
        s=2j * np.pi * np.asarray(frequency_hz, dtype=float), w=w, keep=keep,
        h=np.asarray(response), resonances_hz=resonances_hz, gi_a_per_v=gi_a_per_v)
    scale = np.maximum(np.abs(theta0), np.max(np.abs(theta0)) * 1e-9)
    r0 = problem.residual(theta0)
    j_mat = _central_jacobian(problem.residual, theta0, scale=scale, size=r0.size)
    dof = int(r0.size - theta0.size)
    part_var = _residual_variances(variance_parts, w=w, keep=keep)
    chi2 = _reduced_chi2(r0, part_var, dof=dof)
    q0 = problem.quantities(theta0)
    g = _central_jacobian(problem.quantities, theta0, scale=scale, size=q0.size)
    part_sd, sd = _propagated_std(j_mat, g, part_var, chi2=chi2,
                                  correlated_lines=correlated_lines)
    return _by_axis(q0, sd, part_sd, chi2=chi2, dof=dof, fixed_poles=fixed_poles)


@dataclass(frozen=True, eq=False)
class _WeightedFit:
    """The vector fit's model as a function of its real parameters, and its weighted residual.

    ``theta`` holds the poles' real and imaginary parts (one per real pole; absent
    with ``fixed_poles``), then the real partial-fraction coefficients and ``D``,
    shape ``(n + 1, p, m)`` flattened. ``s`` = j 2π f [rad/s] of the fitted lines;
    ``w`` their weights (F, p, m) [V/V⁻¹]; ``h`` the FRF fitted [V/V].
    """

    poles0: NDArray[np.complex128]
    shape: tuple[int, ...]
    n_pole_params: int
    fixed_poles: bool
    s: NDArray[np.complex128]
    w: NDArray[np.float64]
    keep: NDArray[np.bool_]
    h: NDArray[np.complex128]
    resonances_hz: Mapping[str, float]
    gi_a_per_v: Sequence[float] | NDArray[np.float64]

    def split(self, theta: NDArray[np.float64]
              ) -> tuple[NDArray[np.complex128], NDArray[np.float64]]:
        """Poles [rad/s] and the coefficients, shape (n + 1, p, m), of ``theta``."""
        n, p, m = self.shape
        if self.fixed_poles:
            return self.poles0, theta.reshape(n + 1, p, m)
        return (_poles_from(theta[: self.n_pole_params], self.poles0),
                theta[self.n_pole_params:].reshape(n + 1, p, m))

    def model(self, theta: NDArray[np.float64], s_val: NDArray[np.complex128]
              ) -> NDArray[np.complex128]:
        """The model's response at ``s_val`` [rad/s], shape (S, p, m) [V/V]."""
        n = self.shape[0]
        poles, lin = self.split(theta)
        return np.einsum("fn,npm->fpm", real_basis(s_val, poles), lin[:n]) + lin[n][None]

    def residual(self, theta: NDArray[np.float64]) -> NDArray[np.float64]:
        """Real and imaginary parts of the weighted residual of the kept lines [1]."""
        # sqrt 2: a circular error of complex variance var puts var/2 on each of its real and
        # imaginary parts, so sqrt(2) w makes every real residual of unit variance
        r = (np.sqrt(2.0) * self.w * (self.model(theta, self.s) - self.h))[self.keep]
        return np.concatenate([r.real, r.imag])

    def quantities(self, theta: NDArray[np.float64]) -> NDArray[np.float64]:
        """Resonance [Hz], damping ratio and static gain [V/A] of ``h`` then ``v``."""
        poles, _ = self.split(theta)
        dc = self.model(theta, np.zeros(1, dtype=complex))[0].real
        out = []
        for j, inp in enumerate(("Uch", "Ucv")):
            upper = poles[poles.imag > 0]
            a = upper[np.argmin(np.abs(np.abs(upper) / (2 * np.pi) - self.resonances_hz[inp]))]
            out += [abs(a) / (2 * np.pi), -a.real / abs(a), dc[j, j] / self.gi_a_per_v[j]]
        return np.array(out)


def _central_jacobian(fun: Callable[[NDArray[np.float64]], NDArray[np.float64]],
                      theta0: NDArray[np.float64], *, scale: NDArray[np.float64],
                      size: int) -> NDArray[np.float64]:
    """``d fun / d theta`` at ``theta0`` by central differences of ``_STEP * scale``.

    ``size`` is the length of ``fun``'s output; the result has shape (size, theta0.size).
    """
    cols = []
    for k in range(theta0.size):
        step = np.zeros_like(theta0)
        step[k] = _STEP * scale[k]
        cols.append((fun(theta0 + step) - fun(theta0 - step)) / (2 * step[k]))
    return np.array(cols).T.reshape(size, theta0.size)


def _residual_variances(variance_parts: Mapping[str, NDArray[np.float64]] | None, *,
                        w: NDArray[np.float64], keep: NDArray[np.bool_]
                        ) -> dict[str, NDArray[np.float64]]:
    """Each variance part of every real weighted residual (real parts, then imaginary) [1].

    Without ``variance_parts`` the weights are the inverse std: one part, ``noise``.
    """
    if variance_parts is None:
        with np.errstate(divide="ignore"):
            variance_parts = {"noise": np.where(w > 0, 1.0 / np.where(w > 0, w, 1.0) ** 2, 0.0)}
    # Variance of each real residual per part: (sqrt 2 w)^2 var / 2 = w^2 var.
    return {k: np.concatenate([np.where(w > 0, w**2 * np.nan_to_num(
        np.asarray(v, dtype=float)), 0.0)[keep]] * 2) for k, v in variance_parts.items()}


def _reduced_chi2(r0: NDArray[np.float64], part_var: Mapping[str, NDArray[np.float64]], *,
                  dof: int) -> float:
    """``SSR / dof`` of the residuals normalised by their total variance (NaN for no dof)."""
    total_var = np.sum(list(part_var.values()), axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        normalised = np.where(total_var > 0, r0 / np.sqrt(np.where(total_var > 0, total_var,
                                                                    1.0)), 0.0)
    ssr = float(normalised @ normalised)
    return ssr / dof if dof > 0 else float("nan")


def _propagated_std(j_mat: NDArray[np.float64], g: NDArray[np.float64],
                    part_var: Mapping[str, NDArray[np.float64]], *, chi2: float,
                    correlated_lines: float
                    ) -> tuple[dict[str, NDArray[np.float64]], NDArray[np.float64]]:
    """The quantities' std from each variance part and ``misfit``, and their total.

    ``j_mat`` is the weighted residual's Jacobian (residuals, parameters), ``g`` the
    quantities' (quantities, parameters); the sandwich ``G A⁻¹ Jᵀ Σ J A⁻¹ Gᵀ`` per part.
    """
    # columns normalised before the pseudo-inverse: parameters span many decades
    norm = np.linalg.norm(j_mat, axis=0)
    norm[norm == 0.0] = 1.0
    jn = j_mat / norm
    bread = np.linalg.pinv(jn.T @ jn) / np.outer(norm, norm)
    gb = g @ bread @ j_mat.T  # (q, residuals): the quantities' sensitivity to each residual
    part_sd = {k: np.sqrt(np.maximum(np.einsum("qr,r,qr->q", gb, v, gb), 0.0)
                          * max(correlated_lines, 1.0))
               for k, v in part_var.items()}
    var = sum(sd**2 for sd in part_sd.values())
    part_sd["misfit"] = np.sqrt(var * max(chi2 - 1.0, 0.0)) if np.isfinite(chi2) else 0 * var
    sd = np.sqrt(var * max(1.0, chi2 if np.isfinite(chi2) else 1.0))
    return part_sd, sd


def _by_axis(q0: NDArray[np.float64], sd: NDArray[np.float64],
             part_sd: Mapping[str, NDArray[np.float64]], *, chi2: float, dof: int,
             fixed_poles: bool) -> ParameterStd:
    """The quantities (``h`` then ``v``, :data:`QUANTITIES` each), their stds and parts by axis.

    With ``fixed_poles`` the resonance and damping stds are NaN (the poles were not fitted).
    """
    value: dict[str, dict[str, float]] = {}
    std: dict[str, dict[str, float]] = {}
    parts: dict[str, dict[str, dict[str, float]]] = {}
    for j, axis in enumerate(("h", "v")):
        value[axis] = {q: float(q0[3 * j + i]) for i, q in enumerate(QUANTITIES)}
        std[axis] = {q: float(sd[3 * j + i]) for i, q in enumerate(QUANTITIES)}
        parts[axis] = {q: {k: float(v[3 * j + i]) for k, v in part_sd.items()}
                       for i, q in enumerate(QUANTITIES)}
        if fixed_poles:
            std[axis].update(resonance_hz=float("nan"), damping_ratio=float("nan"))
    return ParameterStd(value=value, std=std, chi2_per_dof=chi2, dof=dof,
                        fixed_poles=fixed_poles, parts=parts)
