"""Noise through the plant and the closed loop to the beam angle, then to the distance (4.5).

The loop (ESRF study Fig. 38, 9.2): the controller reads the measured beam angle
``Rm = R + n`` and commands ``Uc = −K·Rm + d_u`` (``U = −K R``, docs/model.md).
With ``G = ∂R/∂Uc`` (``Rh, Rv ← Uch, Ucv`` of the plant, delays included),
``S = (I + GK)⁻¹``, ``T = I − S`` and ``Si = (I + KG)⁻¹``:

    R  = S·(d + G·d_u) − T·n
    Uc = −K·S·d + Si·d_u − K·S·n

``d`` is the beam-angle disturbance of the Newport (its DAC noise through
``Rh, Rv ← Unh, Unv``, or its mirror-angle noise times the beam matrix).
Open loop is ``K = 0``. Each source is a one-sided input PSD per channel;
the beam angle gets the 2×2 cross-spectral matrix ``H·Φ·Hᴴ``.

Distance (4.1, 4.2, 11.3). The Attocube reports
``Va = Σᵢ cᵢ·αᵢ² + p_c·Σ θc + p_n·Σ θn`` with α the beam angle in the table
frame (``R = rot(ρ)·α``), ``cᵢ = (k/2)/bᵢ²`` (``k = 12H + 8L`` m/rad² the
round-trip law, ``bᵢ = ±4`` the Sercalo's beam factor: the Sercalo angle
error is ``α/b``), and the perpendicular (piston) terms of the spot offsets
``p_c``, ``p_n`` [m/rad] as the twin models them.

The quadratic term is **not** a linear gain. For a zero-mean Gaussian α with
covariance ``r_ij(τ)``: ``E[y] = Σ cᵢ r_ii(0)``, ``Cov y(τ) = 2 Σ_ij cᵢcⱼ r_ij(τ)²``;
the two-sided PSD of y is ``2 Σ_ij cᵢcⱼ (P_ij ⋆ P_ij)(f)`` (autoconvolution of
the two-sided cross-spectra). One axis: mean ``cσ²``, standard deviation
``√2·cσ²``. Linear and quadratic terms of a zero-mean Gaussian are
uncorrelated (odd moments vanish), so their variances add.
"""

from __future__ import annotations

import hashlib
import weakref
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Literal

import control as ct
import numpy as np
from numpy.typing import NDArray
from scipy.fft import next_fast_len

from fsmbench.bench.blocks import (
    PlantModel,
    newport_beam_matrix,
    rotation,
    sercalo_beam_matrix,
    ss_frequency_response,
)
from fsmbench.bench.geometry import small_angle_law
from fsmbench.bench.params import BenchParams
from fsmbench.jsonutil import hv

__all__ = [
    "SOURCE_KINDS",
    "LoopResponse",
    "NoiseInput",
    "PropagatedSource",
    "QuadraticDistance",
    "budget_grid",
    "combined_quadratic",
    "controller_response",
    "distance_coefficients",
    "loop_response",
    "propagate",
    "quadratic_distance",
]

FloatArray = NDArray[np.float64]
ComplexArray = NDArray[np.complex128]
SourceKind = Literal["sensor", "sercalo_dac", "newport_dac", "newport_angle"]
SOURCE_KINDS: tuple[str, ...] = ("sensor", "sercalo_dac", "newport_dac", "newport_angle")
_CHUNK = 4096  # frequencies per batched solve: keeps (chunk, n, n) complex arrays ~10 MB


def budget_grid(*, fs_hz: float, df_hz: float = 0.1) -> FloatArray:
    """Uniform grid ``df, 2df, …, fs/2`` [Hz], shape (N,), ``N = fs/(2 df)``.

    ``df`` must divide ``fs/2``. The default 0.1 Hz puts ≥ 4 points in the
    half-power band of the Sercalo's modes (0.4–1 Hz wide); the rectangle rule
    used on this grid converges exponentially for such smooth peaks (error
    ~``exp(−2π·γ/df)`` for a Lorentzian of half-width γ: < 1e-5 here).
    """
    n = round(fs_hz / (2.0 * df_hz))
    if n < 2 or not np.isclose(n * df_hz, fs_hz / 2.0, rtol=1e-9):
        raise ValueError(f"df_hz={df_hz} must divide fs/2={fs_hz / 2} into at least 2 steps")
    return df_hz * np.arange(1, n + 1, dtype=float)


def _chunked(fn: object, f: FloatArray) -> ComplexArray:
    parts = [fn(f[i:i + _CHUNK]) for i in range(0, f.size, _CHUNK)]  # type: ignore[operator]
    return np.concatenate(parts, axis=0)


#: Responses on a grid, kept while the plant or controller they belong to lives: a study's
#: budget asks for the same plant's (and controller's) response on the same 50 000 lines
#: for each configuration, reference and controller it budgets.
_KEPT: dict[tuple[int, str, bytes], ComplexArray] = {}


def _kept(owner: object, what: str, f: FloatArray,
          compute: Callable[[], ComplexArray]) -> ComplexArray:
    """``compute()`` once per ``owner`` (by identity), ``what`` and grid ``f``; read-only."""
    key = (id(owner), what, hashlib.blake2b(f.tobytes(), digest_size=16).digest())
    found = _KEPT.get(key)
    if found is None:
        found = compute()
        found.flags.writeable = False
        _KEPT[key] = found
        weakref.finalize(owner, _KEPT.pop, key, None)
    return found


def _inv2(m: ComplexArray) -> ComplexArray:
    """Batched inverse of (F, 2, 2) matrices (closed form)."""
    det = m[:, 0, 0] * m[:, 1, 1] - m[:, 0, 1] * m[:, 1, 0]
    out = np.empty_like(m)
    out[:, 0, 0], out[:, 1, 1] = m[:, 1, 1] / det, m[:, 0, 0] / det
    out[:, 0, 1], out[:, 1, 0] = -m[:, 0, 1] / det, -m[:, 1, 0] / det
    return out


def controller_response(k: ct.StateSpace, f_hz: FloatArray) -> ComplexArray:
    """``K`` at ``s = j2πf`` (continuous) or ``z = exp(j2πf·dt)`` (discrete), shape (F, p, m).

    The ESRF study runs ``Kd = c2d(K, 1e-4, 'tustin')`` (9.3): Tustin warps the
    notches of K (411.5 Hz → 409.3 Hz at 10 kHz), which matters next to a mode
    1 Hz wide, so the discrete controller is evaluated as such.
    """
    f = np.asarray(f_hz, dtype=float)
    if not k.dt:
        return ss_frequency_response(k, f)
    a, b, c, d = (np.asarray(x, dtype=float) for x in (k.A, k.B, k.C, k.D))
    z = np.exp(2j * np.pi * f * float(k.dt))
    lhs = z[:, None, None] * np.eye(a.shape[0])[None] - a[None]
    x = np.linalg.solve(lhs, np.broadcast_to(b, (f.size, *b.shape)).astype(complex))
    return np.einsum("pn,fnm->fpm", c, x) + d[None]


@dataclass(frozen=True)
class LoopResponse:
    """Frequency responses of the loop on a grid, all shape (F, 2, 2) complex.

    ``g_ru``: ``Rh, Rv ← Uch, Ucv`` [rad/V]; ``g_rn``: ``Rh, Rv ← Unh, Unv``
    [rad/V]; ``k``: controller [V/rad] (zero in open loop); ``s``: output
    sensitivity; ``si``: input sensitivity. ``beam_c``, ``beam_n`` (2, 2):
    beam angle in the 4QD frame per Sercalo / Newport mirror angle.
    """

    f_hz: FloatArray
    closed_loop: bool
    g_ru: ComplexArray
    g_rn: ComplexArray
    k: ComplexArray
    s: ComplexArray
    si: ComplexArray
    beam_c: FloatArray
    beam_n: FloatArray

    def transfers(self, kind: str) -> tuple[ComplexArray, ComplexArray, ComplexArray]:
        """Responses from a source's input to ``R``, ``θc``, ``θn``, each (F, 2, 2).

        ``kind``: ``"sensor"`` (rad at the measurement), ``"sercalo_dac"`` (V at
        Uc), ``"newport_dac"`` (V at Un), ``"newport_angle"`` (rad of mirror angle).
        """
        eye = np.broadcast_to(np.eye(2, dtype=complex), self.s.shape)
        ks = self.k @ self.s
        if kind == "sensor":
            to_r, to_u, to_tn = -(eye - self.s), -ks, np.zeros_like(eye)
        elif kind == "sercalo_dac":
            to_r, to_u, to_tn = self.s @ self.g_ru, self.si, np.zeros_like(eye)
        elif kind == "newport_dac":
            to_r, to_u = self.s @ self.g_rn, -ks @ self.g_rn
            to_tn = np.linalg.inv(self.beam_n) @ self.g_rn
        elif kind == "newport_angle":
            bn = self.beam_n.astype(complex)
            to_r, to_u, to_tn = self.s @ bn, -ks @ bn, eye.copy()
        else:
            raise ValueError(f"unknown source kind {kind!r}; known: {SOURCE_KINDS}")
        to_tc = np.linalg.inv(self.beam_c) @ (self.g_ru @ to_u)
        return np.asarray(to_r), np.asarray(to_tc), np.asarray(to_tn)


def loop_response(plant: PlantModel, *, params: BenchParams, f_hz: FloatArray,
                  controller: ct.StateSpace | None, closed_loop: bool = True) -> LoopResponse:
    """Evaluate plant, controller and sensitivities on ``f_hz`` (delays exact).

    Parameters
    ----------
    plant : PlantModel
        Outputs ``Rh, Rv``, inputs ``Uch, Ucv, Unh, Unv``.
    params : BenchParams
        For the beam matrices (Sercalo factor ±4, Newport 2, 4QD rotation).
    f_hz : ndarray, shape (F,)
        Frequencies > 0 [Hz] (the controller integrates at 0).
    controller : control.StateSpace or None
        ``K: Rh, Rv → Uch, Ucv``, closed as ``U = −K R``, continuous or
        discrete (:func:`controller_response`); ignored in open loop.
    closed_loop : bool
        False: ``K = 0``.
    """
    f = np.asarray(f_hz, dtype=float)
    if np.any(f <= 0):
        raise ValueError("f_hz must be > 0")

    def plant_fr(ff: FloatArray) -> ComplexArray:
        h = plant.frequency_response(ff, outputs=["Rh", "Rv"], inputs=["Uch", "Ucv", "Unh", "Unv"])
        return np.asarray(h.values)

    g = _kept(plant, "Rh, Rv from Uch, Ucv, Unh, Unv", f, lambda: _chunked(plant_fr, f))
    if closed_loop:
        if controller is None:
            raise ValueError("closed_loop=True needs a controller")
        if list(controller.input_labels) != ["Rh", "Rv"] or \
                list(controller.output_labels) != ["Uch", "Ucv"]:
            raise ValueError("controller must map Rh, Rv to Uch, Ucv")
        k = _kept(controller, "K", f, lambda: _chunked(
            lambda ff: controller_response(controller, ff), f))
    else:
        k = np.zeros((f.size, 2, 2), dtype=complex)
    g_ru, g_rn = g[:, :, :2], g[:, :, 2:]
    eye = np.eye(2)[None]
    return LoopResponse(
        f_hz=f, closed_loop=closed_loop, g_ru=g_ru, g_rn=g_rn, k=k,
        s=_inv2(eye + g_ru @ k), si=_inv2(eye + k @ g_ru),
        beam_c=sercalo_beam_matrix(params), beam_n=newport_beam_matrix(params))


@dataclass(frozen=True)
class NoiseInput:
    """One source: kind, one-sided input PSD per channel (F, 2) [V²/Hz or rad²/Hz]."""

    name: str
    kind: str
    psd: FloatArray
    description: str
    seed_section: str


@dataclass(frozen=True)
class QuadraticDistance:
    """Distance error ``Σ cᵢ αᵢ²`` of a Gaussian beam-angle error.

    ``psd_m2_per_hz`` (F,): one-sided PSD of the fluctuation on the budget
    grid, the part above ``fs/2`` folded back (Va is sampled at fs);
    ``mean_m``: bias; ``std_m``: standard deviation (exact, from the covariance).
    """

    f_hz: FloatArray
    psd_m2_per_hz: FloatArray
    mean_m: float
    std_m: float
    coefficients_m_per_rad2: tuple[float, float]


def distance_coefficients(params: BenchParams) -> tuple[float, float]:
    """``cᵢ = (k/2)/bᵢ²`` [m/rad²]: measured distance per squared beam angle, table axes (h, v)."""
    law = small_angle_law(h_m=params.geometry.h_m, l_m=params.geometry.l_m)
    b = params.sercalo.beam_angle_per_mirror_angle.as_array()
    c = 0.5 * law.k_m_per_rad2 / b**2
    return (float(c[0]), float(c[1]))


def quadratic_distance(f_hz: FloatArray, angle_psd: ComplexArray, *,
                       coefficients: tuple[float, float], fs_hz: float) -> QuadraticDistance:
    """Propagate a beam-angle cross-spectral matrix through ``y = Σ cᵢ αᵢ²``.

    Parameters
    ----------
    f_hz : ndarray, shape (N,)
        Uniform grid ``df … N·df = fs/2`` (:func:`budget_grid`).
    angle_psd : ndarray, shape (N, 2, 2)
        One-sided cross-spectral matrix of α (table frame) [rad²/Hz], Hermitian.
    coefficients : (float, float)
        ``cᵢ`` [m/rad²].
    fs_hz : float
        Sampling frequency of the distance record [Hz].

    Returns
    -------
    QuadraticDistance
    """
    f = np.asarray(f_hz, dtype=float)
    n = f.size
    df = float(f[0])
    if not np.isclose(f[-1], fs_hz / 2.0) or not np.allclose(np.diff(f), df):
        raise ValueError("f_hz must be the uniform grid df..fs/2 of budget_grid()")
    p1 = np.asarray(angle_psd, dtype=complex)
    c = np.asarray(coefficients, dtype=float)
    # Two-sided spectra on k = −N..N with P(0) = 0: the rectangle sums then match
    # the covariance r0 below exactly (both leave out the zero-width DC bin).
    p2 = 0.5 * p1
    full = np.concatenate([np.conj(p2[::-1]), np.zeros_like(p2[:1]), p2], axis=0)

    # y's two-sided PSD is 2 Σᵢⱼ cᵢcⱼ Re(Pᵢⱼ ∗ Pᵢⱼ) (Isserlis). The three self-convolutions
    # share one transform length and are summed in the frequency domain: three forward
    # transforms and one inverse, where three fftconvolve calls took nine.
    length = 2 * full.shape[0] - 1  # (4N+1,), lag 0 at 2N
    nfft = next_fast_len(length)
    spectrum = sum(w * np.fft.fft(full[:, i, j], nfft) ** 2
                   for w, (i, j) in ((c[0] ** 2, (0, 0)), (c[1] ** 2, (1, 1)),
                                     (2.0 * c[0] * c[1], (0, 1))))
    sy2 = 2.0 * df * np.fft.ifft(spectrum)[:length].real
    sy1 = 2.0 * sy2[2 * n + 1:]  # one-sided, f = df .. 2N·df = fs
    folded = sy1[:n].copy()
    folded[: n - 1] += sy1[n:2 * n - 1][::-1]  # f and fs − f
    # y's lag-0 bin: the slow envelope of a narrow-band α (difference frequencies
    # within one peak) lands near DC; it is fluctuation, not mean, and goes to df.
    folded[0] += sy2[2 * n]
    r0 = np.real(p1.sum(axis=0)) * df  # covariance at lag 0 (rectangle rule)
    mean = float(c @ np.diag(r0))
    var = float(2.0 * np.sum(np.outer(c, c) * r0**2))
    return QuadraticDistance(f_hz=f, psd_m2_per_hz=np.maximum(folded, 0.0), mean_m=mean,
                             std_m=float(np.sqrt(var)),
                             coefficients_m_per_rad2=(float(c[0]), float(c[1])))


@dataclass(frozen=True)
class PropagatedSource:
    """One source after the loop: beam angle and distance error.

    ``angle_psd`` (F, 2, 2): beam angle in the 4QD frame [rad²/Hz];
    ``angle_rms_rad`` (h, v); ``perpendicular_psd_m2_per_hz`` (F,): piston
    term [m²/Hz]; ``quadratic``: geometric term.
    """

    name: str
    kind: str
    description: str
    seed_section: str
    f_hz: FloatArray
    angle_psd: ComplexArray
    angle_rms_rad: tuple[float, float]
    perpendicular_psd_m2_per_hz: FloatArray
    perpendicular_rms_m: float
    quadratic: QuadraticDistance

    def to_json(self) -> dict[str, object]:
        """Scalars only (the spectra stay in memory for the figures)."""
        return {"name": self.name, "kind": self.kind, "description": self.description,
                "seed_section": self.seed_section, "angle_rms_rad": hv(self.angle_rms_rad),
                "perpendicular_rms_m": self.perpendicular_rms_m,
                "geometric_mean_m": self.quadratic.mean_m,
                "geometric_std_m": self.quadratic.std_m}


def propagate(source: NoiseInput, loop: LoopResponse, *, params: BenchParams) -> PropagatedSource:
    """One source through the loop to the beam angle, the piston and the quadratic distance."""
    f = loop.f_hz
    phi = np.asarray(source.psd, dtype=float)
    if phi.shape != (f.size, 2):
        raise ValueError(f"{source.name}: psd must have shape ({f.size}, 2), got {phi.shape}")
    to_r, to_tc, to_tn = loop.transfers(source.kind)
    angle = np.einsum("fij,fj,fkj->fik", to_r, phi, np.conj(to_r))
    geo = params.geometry
    h_p = geo.sercalo_spot_offset_m * to_tc.sum(axis=1) + geo.newport_spot_offset_m * to_tn.sum(
        axis=1)  # (F, 2): piston per input channel
    perp = np.einsum("fj,fj->f", np.abs(h_p) ** 2, phi)
    df = float(f[0])
    rot = rotation(params.quad_diode.rotation_rad)
    table = np.einsum("ji,fjk,kl->fil", rot, angle, rot)  # α = rotᵀ R
    quad = quadratic_distance(f, table, coefficients=distance_coefficients(params),
                              fs_hz=2.0 * float(f[-1]))
    rms = np.sqrt(np.real(np.einsum("fii->fi", angle)).sum(axis=0) * df)
    return PropagatedSource(
        name=source.name, kind=source.kind, description=source.description,
        seed_section=source.seed_section, f_hz=f, angle_psd=angle,
        angle_rms_rad=(float(rms[0]), float(rms[1])), perpendicular_psd_m2_per_hz=perp,
        perpendicular_rms_m=float(np.sqrt(perp.sum() * df)), quadratic=quad)


def combined_quadratic(sources: Mapping[str, PropagatedSource], *,
                       params: BenchParams) -> QuadraticDistance:
    """Geometric distance error of all sources together (independent: their spectra add).

    Not the sum of the sources' own terms: ``(Σ αₛ)²`` has cross products, whose
    variance ``Var(all) − Σₛ Var(s)`` is ≥ 0.
    """
    if not sources:
        raise ValueError("no sources to combine")
    first = next(iter(sources.values()))
    angle = np.asarray(sum(s.angle_psd for s in sources.values()))
    rot = rotation(params.quad_diode.rotation_rad)
    table = np.einsum("ji,fjk,kl->fil", rot, angle, rot)
    return quadratic_distance(first.f_hz, table, coefficients=distance_coefficients(params),
                              fs_hz=2.0 * float(first.f_hz[-1]))
