"""Continuous paths as a converter samples them: hold, fractional delay and a sensor's low pass.

A DAC holds each command for one sample ``T``; the path responds ``τ_p`` later
(transport, latency, any fraction of a sample); an analog sensor amplifier
(the 4QD's) low-passes the output before the ADC samples it. The frequency
response the converters measure is then exactly (modified z-transform, as
:func:`fsmbench.sim.discretize.zoh_with_delays` simulates it)::

    H(z) = C (zI − Φ)^-1 (Γ0 + Γ1 z^-1) z^-m,    τ_p = (m + α) T,
    Φ = e^{AT},  Γ0 = ∫_0^{(1−α)T} e^{Aη} dη B,  Γ1 = e^{A(1−α)T} ∫_0^{αT} e^{Aη} dη B

for the continuous path ``(A, B, C)`` in series with the sensor. It is
continuous in ``τ_p`` across whole samples, so a fit can move the delay freely.
Delays follow the seed's convention: ``delay_s`` counts the hold's half
sample, ``τ_p = delay_s − T/2``.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.linalg import expm, matrix_balance

from fsmbench.bench.params import BenchParams

__all__ = ["SensorLowpass", "mode_sum", "sampled_response", "second_order", "series"]

FloatArray = NDArray[np.float64]
StateSpace3 = tuple[FloatArray, FloatArray, FloatArray]
# Beyond it the eigenvectors of Φ are nearly parallel (a repeated pole) and the
# diagonal form loses digits; the line-by-line solve is exact there.
_MAX_EIGENVECTOR_CONDITION = 1e8


@dataclass(frozen=True)
class SensorLowpass:
    """The sensor amplifier's low pass in front of the ADC (unit DC gain).

    Attributes
    ----------
    bandwidth_hz : float
        −3 dB frequency [Hz]; 0 for an unlimited sensor.
    order : int
        1 (``1/(1 + s/wb)``) or 2 (Butterworth, ``1/(1 + √2 s/wb + s²/wb²)``).
    """

    bandwidth_hz: float = 0.0
    order: int = 1

    def __post_init__(self) -> None:
        if not (math.isfinite(self.bandwidth_hz) and self.bandwidth_hz >= 0):
            raise ValueError(f"bandwidth_hz must be >= 0 (0: unlimited), got {self.bandwidth_hz}")
        if self.order not in (1, 2):
            raise ValueError(f"order must be 1 or 2, got {self.order}")

    @classmethod
    def from_params(cls, p: BenchParams) -> SensorLowpass:
        """The 4QD amplifier of a bench model (``quad_diode.bandwidth_hz``, ``bandwidth_order``)."""
        return cls(bandwidth_hz=float(p.quad_diode.bandwidth_hz),
                   order=int(p.quad_diode.bandwidth_order))

    @property
    def limited(self) -> bool:
        """A finite bandwidth."""
        return self.bandwidth_hz > 0

    @property
    def group_delay_s(self) -> float:
        """Low-frequency group delay [s]: ``1/wb`` (first order), ``√2/wb`` (Butterworth)."""
        if not self.limited:
            return 0.0
        wb = 2 * math.pi * self.bandwidth_hz
        return (1.0 if self.order == 1 else math.sqrt(2.0)) / wb

    def state_space(self) -> StateSpace3 | None:
        """``(A, B, C)`` of the low pass, or None when unlimited."""
        if not self.limited:
            return None
        wb = 2 * math.pi * self.bandwidth_hz
        if self.order == 1:
            return np.array([[-wb]]), np.array([wb]), np.array([1.0])
        return (np.array([[0.0, 1.0], [-wb * wb, -math.sqrt(2.0) * wb]]),
                np.array([0.0, wb * wb]), np.array([1.0, 0.0]))

    def response(self, f_hz: FloatArray) -> NDArray[np.complex128]:
        """Continuous response at ``f_hz`` [Hz]."""
        if not self.limited:
            return np.ones(np.shape(f_hz), dtype=np.complex128)
        x = 1j * np.asarray(f_hz, dtype=float) / self.bandwidth_hz
        den = 1 + x if self.order == 1 else 1 + math.sqrt(2.0) * x + x * x
        return np.asarray(1 / den, dtype=np.complex128)

    def summary(self) -> dict[str, Any]:
        """JSON-ready values."""
        return {"bandwidth_hz": self.bandwidth_hz, "order": self.order,
                "group_delay_s": self.group_delay_s}


def second_order(*, gain: float, natural_freq_hz: float, damping_ratio: float) -> StateSpace3:
    """``K wn² / (s² + 2ζ wn s + wn²)`` as ``(A, B, C)``."""
    wn = 2 * math.pi * natural_freq_hz
    return (np.array([[0.0, 1.0], [-wn * wn, -2 * damping_ratio * wn]]),
            np.array([0.0, gain * wn * wn]), np.array([1.0, 0.0]))


def mode_sum(*, natural_freq_hz: FloatArray, damping_ratio: FloatArray,
             numerator: FloatArray, direct: float = 0.0, direct_pole_hz: float = 0.0
             ) -> StateSpace3:
    """``Σ_k (c1_k s + c0_k) / (s² + 2ζ_k wn_k s + wn_k²)`` (+ a direct term) as ``(A, B, C)``.

    Parameters
    ----------
    natural_freq_hz, damping_ratio : array, shape (K,)
        Each pole pair [Hz], [1].
    numerator : array, shape (K, 2)
        ``(c0_k, c1_k)`` [unit of the path · rad²/s², · rad/s].
    direct : float
        A constant term [unit of the path], carried by a first-order pole at
        ``direct_pole_hz`` (a held, delayed input has no exact constant path:
        its output would jump by whole samples as the delay moves).
    direct_pole_hz : float
        That pole [Hz]; required when ``direct`` is not 0.
    """
    k = len(natural_freq_hz)
    n = 2 * k + (1 if direct else 0)
    a, b, c = np.zeros((n, n)), np.zeros(n), np.zeros(n)
    for i in range(k):
        wn = 2 * math.pi * float(natural_freq_hz[i])
        a[2 * i:2 * i + 2, 2 * i:2 * i + 2] = [[0.0, 1.0], [-wn * wn,
                                                            -2 * float(damping_ratio[i]) * wn]]
        b[2 * i + 1] = 1.0
        c[2 * i], c[2 * i + 1] = numerator[i][0], numerator[i][1]
    if direct:
        if not direct_pole_hz > 0:
            raise ValueError("a direct term needs direct_pole_hz > 0")
        wd = 2 * math.pi * direct_pole_hz
        a[-1, -1], b[-1], c[-1] = -wd, wd, direct
    return a, b, c


def series(first: StateSpace3, then: StateSpace3 | None) -> StateSpace3:
    """``then ∘ first`` (SISO): the output of ``first`` drives ``then``."""
    if then is None:
        return first
    a1, b1, c1 = first
    a2, b2, c2 = then
    n1, n2 = a1.shape[0], a2.shape[0]
    a = np.zeros((n1 + n2, n1 + n2))
    a[:n1, :n1], a[n1:, n1:], a[n1:, :n1] = a1, a2, np.outer(b2, c1)
    return a, np.concatenate([b1, np.zeros(n2)]), np.concatenate([np.zeros(n1), c2])


def _gamma(a: FloatArray, b: FloatArray, h_s: float) -> tuple[FloatArray, FloatArray]:
    n = a.shape[0]
    aug = np.zeros((n + 1, n + 1))
    aug[:n, :n], aug[:n, n] = a * h_s, b * h_s
    e = expm(aug)
    return e[:n, :n], e[:n, n]


def sampled_response(path: StateSpace3, *, f_hz: FloatArray, fs_hz: float, delay_s: float,
                     sensor: SensorLowpass | None = None) -> NDArray[np.complex128]:
    """The path (then the sensor) as the converters sample it, at ``f_hz`` (see the module).

    Parameters
    ----------
    path : (A, B, C)
        Continuous SISO path, shapes (n, n), (n,), (n,); strictly proper.
    f_hz : array, shape (F,)
        Frequencies [Hz].
    fs_hz : float
        Converter rate [Hz].
    delay_s : float
        Delay including the hold's half sample [s]; the pure delay
        ``delay_s − T/2`` is clipped at 0.
    sensor : SensorLowpass, optional
        Low pass between the path and the ADC.

    Returns
    -------
    ndarray, complex, shape (F,)
    """
    a, b, c = series(path, None if sensor is None else sensor.state_space())
    t = 1.0 / fs_hz
    pure = max(delay_s - 0.5 * t, 0.0)
    whole = math.floor(pure / t + 1e-12)
    frac = min(max(pure / t - whole, 0.0), 1.0)
    theta = 2 * np.pi * np.asarray(f_hz, dtype=float) * t
    z = np.exp(1j * theta)
    modes = _modes(np.ascontiguousarray(a, dtype=float).tobytes(), a.shape[0])
    if modes is not None:
        scale, lam, vec = modes
        b, c = b / scale, c * scale
        # Modal form: Φ, Γ0 and Γ1 are diagonal in closed form and C (zI − Φ)^-1 g
        # at every line is a weighted sum of 1/(z − e^{λT}); no matrix exponential.
        bt = np.linalg.solve(vec, b.astype(complex))
        ct = c @ vec
        g0 = _phi(lam, (1 - frac) * t) * bt
        g1 = np.exp(lam * (1 - frac) * t) * _phi(lam, frac * t) * bt
        inv = 1.0 / (z[:, None] - np.exp(lam * t)[None, :])
        h = inv @ (ct * g0) + (inv @ (ct * g1)) / z
    else:  # repeated poles (ζ = 1): matrix exponentials and one solve per line
        phi, _ = _gamma(a, b, t)
        e_rest, g0r = _gamma(a, b, (1 - frac) * t)
        _, g_part = _gamma(a, b, frac * t)
        g = g0r[None, :] + (e_rest @ g_part)[None, :] / z[:, None]
        lhs = z[:, None, None] * np.eye(a.shape[0])[None] - phi[None]
        h = np.linalg.solve(lhs, g[..., None])[..., 0] @ c
    return np.asarray(h * np.exp(-1j * whole * theta), dtype=np.complex128)


@functools.lru_cache(maxsize=256)
def _modes(a_bytes: bytes, n: int
           ) -> tuple[FloatArray, NDArray[np.complex128], NDArray[np.complex128]] | None:
    """The balanced ``A``'s scaling, eigenvalues and eigenvectors, or None when they are
    too ill-conditioned for the modal form (repeated poles).

    Kept by ``A``'s bytes: a delay's fit asks again for the same path at every delay
    tried (the same arithmetic on the same matrix, so the same values).
    """
    a = np.frombuffer(a_bytes, dtype=float).reshape(n, n)
    # Balanced first: a series of a mode (numerators ~1e7) and a fast sensor puts
    # entries 1e15 apart in A, and the eigenvectors' conditioning with them.
    a_bal, (scale, _) = matrix_balance(a, permute=False, separate=True)
    lam, vec = np.linalg.eig(a_bal)
    if not np.linalg.cond(vec) < _MAX_EIGENVECTOR_CONDITION:
        return None
    for arr in (scale, lam, vec):
        arr.flags.writeable = False  # shared by every call with this A
    return scale, lam, vec


def _phi(lam: NDArray[np.complex128], h_s: float) -> NDArray[np.complex128]:
    """``(e^{λh} − 1)/λ``, ``h`` at ``λ = 0``: the hold's integral on one mode."""
    small = np.abs(lam * h_s) < 1e-8
    safe = np.where(small, 1.0, lam)
    return np.where(small, h_s * (1 + lam * h_s / 2), np.expm1(lam * h_s) / safe)
