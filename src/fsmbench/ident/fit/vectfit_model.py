"""Result types of :func:`fsmbench.ident.fit.vectfit.vector_fit`:
options, modes, pole-residue model.

The model is the common-pole pole-residue form used by vector fitting
(Gustavsen & Semlyen 1999)::

    H(s) = sum_n R_n / (s - a_n) + D + s E,     s = j 2 pi f,

with ``R_n`` complex ``(p, m)`` residue matrices, ``a_n`` poles in rad/s
(complex poles in conjugate pairs, the pole with positive imaginary part first,
its conjugate next), ``D`` and ``E`` real ``(p, m)``. This module holds no
fitting code: it evaluates, converts and serialises a fitted model.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Literal

import control
import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["Mode", "VectorFit", "VectorFitOptions"]

_ASYMPTOTES = ("none", "d", "de")
_INITIAL = ("auto", "log", "peaks", "aaa")
JSON_FORMAT = "fsmbench.vectfit/1"


@dataclass(frozen=True)
class VectorFitOptions:
    """Options of :func:`~fsmbench.ident.fit.vectfit.vector_fit`.

    Attributes
    ----------
    n_poles : int or None
        Model order (number of poles, a complex pair counts two). ``None``:
        chosen automatically (start from the FRF peaks, add poles while the
        error improves significantly, then remove the poles that are not
        needed), at most ``max_poles``.
    max_poles : int
        Upper bound on the automatically chosen order.
    stable : bool
        Flip poles with positive real part into the left half-plane after each
        pole relocation.
    relax : bool
        Relaxed non-triviality constraint (Gustavsen 2006); when the relaxed
        solution is ill-conditioned (``|d~|`` below 1e-8 or above 1e8) the
        iteration falls back to the classical constraint ``d~ = 1``.
    asymptote : {"none", "d", "de"}
        Fit no asymptote, the constant ``D``, or ``D`` and the proportional ``s E``.
    max_iterations : int
        Maximum number of pole relocations per fit.
    tolerance : float
        Convergence threshold on the largest relative pole movement
        ``|a_new - a_old| / |a_old|`` between two relocations (dimensionless).
    initial_poles : {"auto", "log", "peaks", "aaa"}
        Starting poles: ``"peaks"`` lightly damped (1 %) pairs at the peaks of
        the mean log-magnitude, ``"log"`` log-spaced 1 %-damped pairs over the
        band, ``"aaa"`` the poles of an AAA rational approximation
        (:class:`scipy.interpolate.AAA`), ``"auto"`` the peaks completed by
        log-spaced pairs (AAA when there is no peak and no order is given).
    """

    n_poles: int | None = None
    max_poles: int = 30
    stable: bool = True
    relax: bool = True
    asymptote: Literal["none", "d", "de"] = "d"
    max_iterations: int = 50
    tolerance: float = 1e-6
    initial_poles: Literal["auto", "log", "peaks", "aaa"] = "auto"

    def __post_init__(self) -> None:
        if self.n_poles is not None and not 1 <= self.n_poles <= self.max_poles:
            raise ValueError(
                f"n_poles must be in [1, max_poles={self.max_poles}] or None, got {self.n_poles}"
            )
        if self.max_poles < 1:
            raise ValueError(f"max_poles must be >= 1, got {self.max_poles}")
        if self.max_iterations < 1:
            raise ValueError(f"max_iterations must be >= 1, got {self.max_iterations}")
        if not (self.tolerance > 0.0 and math.isfinite(self.tolerance)):
            raise ValueError(f"tolerance must be a positive finite number, got {self.tolerance}")
        if self.asymptote not in _ASYMPTOTES:
            raise ValueError(f"asymptote must be one of {_ASYMPTOTES}, got {self.asymptote!r}")
        if self.initial_poles not in _INITIAL:
            raise ValueError(f"initial_poles must be one of {_INITIAL}, got {self.initial_poles!r}")


@dataclass(frozen=True)
class Mode:
    """One lightly damped mode (complex pole pair) of a fitted model.

    Attributes
    ----------
    resonance_hz : float
        Undamped natural frequency ``|a| / (2 pi)``, Hz.
    damping_ratio : float
        ``-Re(a) / |a|`` (dimensionless, negative for an unstable pole).
    resonance_hz_std, damping_ratio_std : float
        Standard errors (one sigma) from the linearised weighted least-squares
        problem (see :func:`~fsmbench.ident.fit.vectfit.vector_fit`), same units;
        NaN when they could not be estimated.
    """

    resonance_hz: float
    damping_ratio: float
    resonance_hz_std: float
    damping_ratio_std: float


def pole_groups(poles: NDArray[np.complex128]) -> list[tuple[int, bool]]:
    """``(index, is_pair)`` of each real pole or conjugate pair (pair: index of its first pole)."""
    groups: list[tuple[int, bool]] = []
    k = 0
    while k < poles.size:
        pair = bool(poles[k].imag != 0.0)
        groups.append((k, pair))
        k += 2 if pair else 1
    return groups


def real_basis(s: NDArray[np.complex128], poles: NDArray[np.complex128]) -> NDArray[np.complex128]:
    """Real-coefficient partial-fraction basis, shape ``(len(s), len(poles))``.

    A real pole ``a`` gives ``1/(s-a)``; a pair ``(a, conj(a))`` gives
    ``1/(s-a) + 1/(s-conj a)`` and ``j/(s-a) - j/(s-conj a)``, so that real
    coefficients ``(c', c'')`` stand for the residue ``c' + j c''`` of ``a``.
    """
    inv = 1.0 / (s[:, None] - poles[None, :])
    phi = np.empty_like(inv)
    for k, pair in pole_groups(poles):
        if pair:
            phi[:, k] = inv[:, k] + inv[:, k + 1]
            phi[:, k + 1] = 1j * (inv[:, k] - inv[:, k + 1])
        else:
            phi[:, k] = inv[:, k]
    return phi


def state_blocks(poles: NDArray[np.complex128]) -> tuple[NDArray[np.float64],
                                                         NDArray[np.float64]]:
    """Real block-diagonal ``A`` (n, n) and ``b`` (n,) with ``c (sI - A)^-1 b = real_basis @ c``.

    Real pole ``a``: block ``a``, ``b = 1``. Pair ``sigma +/- j omega``: block
    ``[[sigma, omega], [-omega, sigma]]``, ``b = [2, 0]`` (Gustavsen & Semlyen 1999).
    """
    n = poles.size
    a = np.zeros((n, n))
    b = np.zeros(n)
    for k, pair in pole_groups(poles):
        if pair:
            sig, om = poles[k].real, poles[k].imag
            a[k : k + 2, k : k + 2] = [[sig, om], [-om, sig]]
            b[k] = 2.0
        else:
            a[k, k] = poles[k].real
            b[k] = 1.0
    return a, b


def residues_from_coefficients(
    poles: NDArray[np.complex128], coef: NDArray[np.float64]
) -> NDArray[np.complex128]:
    """Complex residues ``(n, ...)`` from real-basis coefficients ``(n, ...)``."""
    res = coef.astype(complex)
    for k, pair in pole_groups(poles):
        if pair:
            res[k] = coef[k] + 1j * coef[k + 1]
            res[k + 1] = coef[k] - 1j * coef[k + 1]
    return res


def coefficients_from_residues(
    poles: NDArray[np.complex128], residues: NDArray[np.complex128]
) -> NDArray[np.float64]:
    """Inverse of :func:`residues_from_coefficients`."""
    coef = residues.real.copy()
    for k, pair in pole_groups(poles):
        if pair:
            coef[k + 1] = residues[k].imag
    return coef


def _readonly(a: NDArray[Any]) -> NDArray[Any]:
    a = np.array(a, copy=True)
    a.flags.writeable = False
    return a


def _cplx(a: NDArray[Any]) -> dict[str, Any]:
    return {"real": np.real(a).tolist(), "imag": np.imag(a).tolist()}


def _std(variance: float) -> float:
    """Square root of a variance; NaN if unknown, 0 if rounding made it slightly negative."""
    return math.sqrt(variance) if variance > 0.0 else (0.0 if variance <= 0.0 else math.nan)


def _nan_to_none(x: float) -> float | None:
    return None if not math.isfinite(x) else float(x)


@dataclass(frozen=True, eq=False)
class VectorFit:
    """A fitted common-pole model of a ``p x m`` frequency-response matrix.

    Attributes
    ----------
    poles : ndarray, complex, shape (n,)
        Poles ``a_n``, rad/s; real poles and conjugate pairs (positive
        imaginary part first, conjugate next), sorted by ``|a_n|``.
    residues : ndarray, complex, shape (n, p, m)
        Residue matrices ``R_n``, output units x input units x rad/s.
    d : ndarray, float, shape (p, m)
        Constant term ``D``, output units / input units.
    e : ndarray, float, shape (p, m)
        Proportional term ``E`` (of ``s E``), output units / input units x s.
    input_names, output_names : tuple of str
        Names of the ``m`` inputs (columns) and ``p`` outputs (rows).
    iterations : int
        Pole relocations made by the final fit.
    converged : bool
        Whether the largest relative pole movement fell below ``options.tolerance``.
    options : VectorFitOptions
        Options of the fit.
    rms_error : ndarray, float, shape (p, m)
        Weighted relative rms error per element,
        ``||w (H_fit - H)|| / ||w H||`` over the fitted points (dimensionless);
        NaN for an element without weighted points (its residues, ``D`` and
        ``E`` are then zero) or whose weighted response is zero.
    history : tuple of float
        Largest relative pole movement after each relocation of the final fit.
    pole_covariance : ndarray, float, shape (n, n)
        Covariance of the real pole parameters, (rad/s)^2, in the order of
        ``poles``: a real pole contributes its value, a pair ``(a, conj a)``
        contributes ``(Re a, Im a)``. NaN where it could not be estimated.
    frequency_range_hz : tuple of float
        Lowest and highest frequency with non-zero weight, Hz.
    """

    poles: NDArray[np.complex128]
    residues: NDArray[np.complex128]
    d: NDArray[np.float64]
    e: NDArray[np.float64]
    input_names: tuple[str, ...]
    output_names: tuple[str, ...]
    iterations: int
    converged: bool
    options: VectorFitOptions
    rms_error: NDArray[np.float64]
    history: tuple[float, ...]
    pole_covariance: NDArray[np.float64]
    frequency_range_hz: tuple[float, float]

    def __post_init__(self) -> None:
        n = self.poles.shape[0]
        p, m = len(self.output_names), len(self.input_names)
        if self.residues.shape != (n, p, m) or self.d.shape != (p, m) or self.e.shape != (p, m):
            raise ValueError(
                f"inconsistent shapes: poles {self.poles.shape}, residues {self.residues.shape}, "
                f"d {self.d.shape}, e {self.e.shape}, {p} output and {m} input name(s)"
            )
        for name in ("poles", "residues", "d", "e", "rms_error", "pole_covariance"):
            object.__setattr__(self, name, _readonly(getattr(self, name)))

    @property
    def n_poles(self) -> int:
        """Number of poles ``n`` (a complex pair counts two)."""
        return int(self.poles.shape[0])

    @property
    def shape(self) -> tuple[int, int]:
        """``(p, m)``: outputs x inputs."""
        return len(self.output_names), len(self.input_names)

    def response(self, frequency_hz: ArrayLike) -> NDArray[np.complex128]:
        """Evaluate the model.

        Parameters
        ----------
        frequency_hz : array_like, float, shape (F,) or scalar
            Frequencies, Hz.

        Returns
        -------
        ndarray, complex, shape (F, p, m)
            ``H(j 2 pi f)``, output units / input units.
        """
        f = np.atleast_1d(np.asarray(frequency_hz, dtype=float))
        if f.ndim != 1:
            raise ValueError(f"frequency_hz must be a scalar or 1-D, got shape {f.shape}")
        s = 2j * np.pi * f
        inv = 1.0 / (s[:, None] - self.poles[None, :])
        h = np.einsum("fn,npm->fpm", inv, self.residues)
        return h + self.d[None] + s[:, None, None] * self.e[None]

    def to_statespace(self) -> control.StateSpace:
        """Real state-space realisation with block-diagonal ``A``.

        Each input ``j`` gets its own copy of the poles (``n m`` states,
        Gustavsen's column realisation): a real pole ``a`` is the 1x1 block
        ``a`` with ``b = 1``; a pair ``sigma +/- j omega`` is the block
        ``[[sigma, omega], [-omega, sigma]]`` with ``b = [2, 0]`` and output
        columns ``[Re R, Im R]`` of the residue of ``sigma + j omega``.

        Returns
        -------
        control.StateSpace
            Continuous-time system, time unit s, named inputs, outputs and states.

        Raises
        ------
        ValueError
            If ``E != 0``: ``s E`` has no proper state-space realisation.
        """
        if np.any(self.e != 0.0):
            raise ValueError(
                "the model has a non-zero proportional term E (asymptote='de'), which has no "
                "proper state-space realisation; refit with asymptote='d' or 'none'"
            )
        n = self.n_poles
        m = len(self.input_names)
        a_blk, b_blk = state_blocks(self.poles)
        coef = coefficients_from_residues(self.poles, self.residues)  # (n, p, m)
        a = np.kron(np.eye(m), a_blk)
        b = np.kron(np.eye(m), b_blk[:, None])
        c = np.concatenate([coef[:, :, j].T for j in range(m)], axis=1)
        states = [f"{inp}.x{k}" for inp in self.input_names for k in range(n)]
        return control.ss(
            a, b, c, np.array(self.d), inputs=list(self.input_names),
            outputs=list(self.output_names), states=states,
        )

    def modes(self) -> list[Mode]:
        """Complex-pole modes sorted by resonance frequency, with standard errors.

        The standard errors propagate ``pole_covariance`` of ``(Re a, Im a)``
        through ``f = |a| / (2 pi)`` and ``zeta = -Re a / |a|`` to first order.
        """
        out: list[Mode] = []
        for k, pair in pole_groups(self.poles):
            if not pair:
                continue
            sig, om = float(self.poles[k].real), float(self.poles[k].imag)
            mag = math.hypot(sig, om)
            cov = self.pole_covariance[k : k + 2, k : k + 2]
            g_f = np.array([sig, om]) / (mag * 2.0 * np.pi)
            g_z = np.array([-(om**2), sig * om]) / mag**3
            out.append(Mode(
                resonance_hz=mag / (2.0 * np.pi),
                damping_ratio=-sig / mag,
                resonance_hz_std=_std(float(g_f @ cov @ g_f)),
                damping_ratio_std=_std(float(g_z @ cov @ g_z)),
            ))
        return sorted(out, key=lambda md: md.resonance_hz)

    def to_json(self) -> dict[str, Any]:
        """JSON-serialisable dict (complex arrays as ``{"real": ..., "imag": ...}``).

        NaN values are written as ``None``; :meth:`from_json` reads the dict back.
        """
        cov = [[_nan_to_none(v) for v in row] for row in self.pole_covariance.tolist()]
        return {
            "format": JSON_FORMAT,
            "poles_rad_per_s": _cplx(self.poles),
            "residues": _cplx(self.residues),
            "d": self.d.tolist(),
            "e": self.e.tolist(),
            "input_names": list(self.input_names),
            "output_names": list(self.output_names),
            "iterations": self.iterations,
            "converged": self.converged,
            "options": dataclasses.asdict(self.options),
            "rms_error": self.rms_error.tolist(),
            "history": list(self.history),
            "pole_covariance": cov,
            "frequency_range_hz": list(self.frequency_range_hz),
            "modes": [
                {k: _nan_to_none(v) for k, v in dataclasses.asdict(md).items()}
                for md in self.modes()
            ],
        }

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> VectorFit:
        """Rebuild a :class:`VectorFit` from :meth:`to_json` output."""
        if data.get("format") != JSON_FORMAT:
            raise ValueError(f"not a {JSON_FORMAT} document: format={data.get('format')!r}")

        def cplx(x: dict[str, Any]) -> NDArray[np.complex128]:
            return np.asarray(x["real"], dtype=float) + 1j * np.asarray(x["imag"], dtype=float)

        def arr(x: Sequence[Any]) -> NDArray[np.float64]:
            return np.asarray([[np.nan if v is None else v for v in row] for row in x],
                              dtype=float).reshape(len(x), -1)

        n = len(data["poles_rad_per_s"]["real"])
        p, m = len(data["output_names"]), len(data["input_names"])
        return cls(
            poles=cplx(data["poles_rad_per_s"]).reshape(n),
            residues=cplx(data["residues"]).reshape(n, p, m),
            d=arr(data["d"]),
            e=arr(data["e"]),
            input_names=tuple(data["input_names"]),
            output_names=tuple(data["output_names"]),
            iterations=int(data["iterations"]),
            converged=bool(data["converged"]),
            options=VectorFitOptions(**data["options"]),
            rms_error=arr(data["rms_error"]),
            history=tuple(float(v) for v in data["history"]),
            pole_covariance=arr(data["pole_covariance"]).reshape(n, n),
            frequency_range_hz=(float(data["frequency_range_hz"][0]),
                                float(data["frequency_range_hz"][1])),
        )
