"""Does an exported controller survive a float32 target? Coefficients rounded, response compared.

A real-time target often runs its filters in single precision. Rounding the
exported coefficients to float32 moves the sections' roots; the closer a root
sits to ``z = 1`` (slow poles at a fast rate), the more it moves (a root pair's
shift goes as ``sqrt(eps)``, ~2.4e-4, against its distance from 1). This module
rounds each section (or a state-space model) to float32, evaluates both
responses over the band, and states:

* the largest relative response error ``max |K32 - K64| / |K64|`` and the
  largest phase error [deg] from 0.1 Hz to 0.9 of Nyquist (:func:`check_band_hz`);
* whether every pole stays where it belongs: poles strictly inside the unit
  circle stay inside, and the integrators (sections ``1 - 2 z^-1 + z^-2`` or
  ``1 - z^-1``) stay exactly on ``z = 1`` (their coefficients are exact in
  float32);
* the loop bound it implies: a relative error ``eps(f)`` is a multiplicative
  perturbation of the loop gain, so any loop stable with the float64
  controller stays stable with the float32 one wherever
  ``|T(f)| < 1 / eps(f)`` (small-gain theorem); :attr:`Float32Check.t_peak_bound`
  is ``1 / max eps``.

Only the coefficients are rounded: the target's arithmetic roundoff (a noise
at each section's state) is not simulated here.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy import signal

__all__ = [
    "FLOAT32_REL_TOL",
    "Float32Check",
    "check_band_hz",
    "float32_sos_check",
    "float32_state_space_check",
]

#: A float32 form "passes" when its response is within this of float64's over the band
#: (1 %, 0.09 dB: the identification's own target; an error below it changes no margin the
#: design relied on).
FLOAT32_REL_TOL = 1e-2
_F_MIN_HZ = 0.1  # below the integrators' corner of every controller here (≥ 1 Hz)
_F_TOP = 0.9  # of Nyquist: see check_band_hz


@dataclass(frozen=True)
class Float32Check:
    """A controller channel's float64 response against its float32-rounded coefficients.

    Attributes
    ----------
    form : str
        ``"sos"`` (direct-form sections) or ``"state_space"``.
    f_hz : numpy.ndarray
        Frequencies compared [Hz] (by default :func:`check_band_hz`).
    max_relative_error : float
        ``max |K32 - K64| / |K64|`` over ``f_hz`` [1].
    worst_f_hz : float
        Where it occurs [Hz].
    max_phase_error_deg : float
        Largest ``|arg(K32 / K64)|`` [deg].
    max_pole_radius : float
        Largest ``|p|`` of the float32 model's poles other than its exact
        integrators [1] (below 1: stable apart from the integrators).
    stable_poles_kept : bool
        Every float64 pole with ``|p| < 1`` stays strictly inside with float32.
    integrators_exact : bool
        Every float64 pole on ``z = 1`` is still exactly there with float32.
    """

    form: str
    f_hz: np.ndarray = field(repr=False)
    max_relative_error: float
    worst_f_hz: float
    max_phase_error_deg: float
    max_pole_radius: float
    stable_poles_kept: bool
    integrators_exact: bool

    @property
    def passes(self) -> bool:
        """Poles kept and the response within :data:`FLOAT32_REL_TOL`."""
        return (self.stable_poles_kept and self.integrators_exact
                and self.max_relative_error <= FLOAT32_REL_TOL)

    @property
    def t_peak_bound(self) -> float:
        """``1 / max_relative_error``: a loop whose ``|T|`` stays below it stays stable [1]."""
        return float(1.0 / self.max_relative_error) if self.max_relative_error > 0 else np.inf

    def sentence(self) -> str:
        """One line for the export's note."""
        verdict = "passes" if self.passes else "does not pass"
        bound = (f"|T| < {self.t_peak_bound:.3g}" if np.isfinite(self.t_peak_bound)
                 else "any |T|")
        return (f"float32 {self.form.replace('_', '-')}: response within "
                f"{self.max_relative_error:.2g} relative (worst at {self.worst_f_hz:.3g} Hz) and "
                f"{self.max_phase_error_deg:.2g} deg of float64 from {self.f_hz[0]:g} Hz to "
                f"{self.f_hz[-1]:.4g} Hz; poles inside the unit circle stay inside: "
                f"{'yes' if self.stable_poles_kept else 'NO'}; integrators exactly on z = 1: "
                f"{'yes' if self.integrators_exact else 'NO'}; a loop stays stable with "
                f"{bound}; {verdict} the {FLOAT32_REL_TOL:g} tolerance")

    def to_json(self) -> dict[str, Any]:
        """Plain numbers for the export's JSON."""
        return {"form": self.form, "f_min_hz": float(self.f_hz[0]),
                "f_max_hz": float(self.f_hz[-1]), "n_frequencies": int(self.f_hz.size),
                "max_relative_error": float(self.max_relative_error),
                "worst_f_hz": float(self.worst_f_hz),
                "max_phase_error_deg": float(self.max_phase_error_deg),
                "max_pole_radius": float(self.max_pole_radius),
                "stable_poles_kept": bool(self.stable_poles_kept),
                "integrators_exact": bool(self.integrators_exact),
                # No error at all: no bound (JSON has no inf).
                "t_peak_bound": (float(self.t_peak_bound) if np.isfinite(self.t_peak_bound)
                                 else None),
                "tolerance": FLOAT32_REL_TOL, "passes": bool(self.passes),
                "scope": "coefficients rounded to float32; arithmetic roundoff not simulated"}


def check_band_hz(ts_s: float, *, n: int = 1500) -> np.ndarray:
    """Log-spaced frequencies from 0.1 Hz to 0.9 of Nyquist [Hz].

    Not closer to Nyquist: Tustin puts the controllers' roll-off zeros at
    ``z = -1``, where ``|K| -> 0`` and any rounding is a large relative error
    of a response the loop no longer feels (fsmbench's ``Kd`` in float32:
    8e-4 up to 0.9 of Nyquist, 9 at 0.999).
    """
    return np.logspace(np.log10(_F_MIN_HZ), np.log10(_F_TOP * 0.5 / ts_s), n)


def _compare(h64: np.ndarray, h32: np.ndarray) -> tuple[float, int, float]:
    mag = np.abs(h64)
    ok = mag > 0
    rel = np.where(ok, np.abs(h32 - h64) / np.where(ok, mag, 1.0), 0.0)
    i = int(np.argmax(rel))
    with np.errstate(invalid="ignore", divide="ignore"):
        phase = np.where(ok, np.abs(np.angle(h32 / np.where(ok, h64, 1.0), deg=True)), 0.0)
    return float(rel[i]), i, float(np.max(phase))


def _pole_verdict(p64: np.ndarray, p32: np.ndarray, *,
                  on_one: np.ndarray, on_one32: np.ndarray) -> tuple[float, bool, bool]:
    inside64 = np.abs(p64[~on_one]) < 1.0
    rest32 = p32[~on_one32]
    radius = float(np.max(np.abs(rest32))) if rest32.size else 0.0
    kept = bool(np.all(inside64)) and radius < 1.0 if rest32.size else True
    return radius, kept, int(np.count_nonzero(on_one32)) == int(np.count_nonzero(on_one))


def _sos_poles(sos: np.ndarray) -> np.ndarray:
    roots = [np.roots(row[3:]) for row in sos]
    return np.concatenate(roots) if roots else np.zeros(0, dtype=complex)


def float32_sos_check(sos: Sequence[Sequence[float]] | np.ndarray, *, ts_s: float,
                      f_hz: np.ndarray | None = None) -> Float32Check:
    """Round a cascade of sections ``[b0, b1, b2, a0, a1, a2]`` to float32 and compare.

    Parameters
    ----------
    sos : array-like, shape (n_sections, 6)
        In ``z^-1``, float64.
    ts_s : float
        Sample time [s].
    f_hz : numpy.ndarray, optional
        Frequencies [Hz] (default :func:`check_band_hz`).

    Returns
    -------
    Float32Check
    """
    s64 = np.asarray(sos, dtype=float)
    s32 = s64.astype(np.float32).astype(float)
    f = check_band_hz(ts_s) if f_hz is None else np.asarray(f_hz, dtype=float)
    _, h64 = signal.sosfreqz(s64, worN=f, fs=1.0 / ts_s)
    _, h32 = signal.sosfreqz(s32, worN=f, fs=1.0 / ts_s)
    rel, i, phase = _compare(h64, h32)
    # An integrator section's denominator is exact in float32; its roots are 1 exactly.
    on_one64 = np.concatenate([_integrator_mask(row) for row in s64]) if s64.size else \
        np.zeros(0, dtype=bool)
    on_one32 = np.concatenate([_integrator_mask(row) for row in s32]) if s32.size else \
        np.zeros(0, dtype=bool)
    radius, kept, exact = _pole_verdict(_sos_poles(s64), _sos_poles(s32), on_one=on_one64,
                                        on_one32=on_one32)
    return Float32Check(form="sos", f_hz=f, max_relative_error=rel, worst_f_hz=float(f[i]),
                        max_phase_error_deg=phase, max_pole_radius=radius,
                        stable_poles_kept=kept, integrators_exact=exact)


def _integrator_mask(row: np.ndarray) -> np.ndarray:
    """Which of a section's ``len(roots(a))`` poles are exactly ``z = 1``."""
    a = row[3:] / row[3]
    n = len(np.roots(row[3:]))
    if n == 2 and a[1] == -2.0 and a[2] == 1.0:
        return np.array([True, True])
    mask = np.zeros(n, dtype=bool)
    if n == 2 and a[1] + a[2] == -1.0:  # (1 - z^-1)(1 - p z^-1): one root exactly 1
        mask[int(np.argmin(np.abs(np.roots(row[3:]) - 1.0)))] = True
    elif n == 1 and a[1] == -1.0:
        mask[0] = True
    return mask


def float32_state_space_check(a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray, *,
                              ts_s: float, f_hz: np.ndarray | None = None) -> Float32Check:
    """Round a SISO discrete ``(a, b, c, d)`` to float32 and compare its response.

    Integrators: eigenvalues within 1e-9 of ``z = 1`` in float64; with float32
    they count as exact when still within that distance.

    Parameters
    ----------
    a, b, c, d : numpy.ndarray
        ``x[k+1] = a x + b e``, ``v = c x + d e`` (one input, one output).
    ts_s : float
        Sample time [s].
    f_hz : numpy.ndarray, optional
        Frequencies [Hz] (default :func:`check_band_hz`).
    """
    f = check_band_hz(ts_s) if f_hz is None else np.asarray(f_hz, dtype=float)
    z = np.exp(2j * np.pi * f * ts_s)
    m64 = [np.atleast_2d(np.asarray(x, dtype=float)) for x in (a, b, c, d)]
    m32 = [x.astype(np.float32).astype(float) for x in m64]

    def resp(m: list[np.ndarray]) -> np.ndarray:
        aa, bb, cc, dd = m
        n = aa.shape[0]
        if n == 0:
            return np.full(z.shape, dd[0, 0], dtype=complex)
        x = np.linalg.solve(z[:, None, None] * np.eye(n)[None] - aa[None],
                            np.broadcast_to(bb[:, :1], (z.size, n, 1)).astype(complex))
        return np.asarray((cc[:1] @ x)[:, 0, 0] + dd[0, 0])

    rel, i, phase = _compare(resp(m64), resp(m32))
    p64 = np.linalg.eigvals(m64[0]) if m64[0].size else np.zeros(0, dtype=complex)
    p32 = np.linalg.eigvals(m32[0]) if m32[0].size else np.zeros(0, dtype=complex)
    # A Jordan block at 1 has eigenvalues 1 ± O(sqrt(eps)) numerically: 1e-6 separates them
    # from the controllers' slowest real poles (≥ 1 rad/s: 1e-4 from 1 at 10 kHz).
    radius, kept, exact = _pole_verdict(p64, p32, on_one=np.abs(p64 - 1.0) < 1e-6,
                                        on_one32=np.abs(p32 - 1.0) < 1e-6)
    return Float32Check(form="state_space", f_hz=f, max_relative_error=rel,
                        worst_f_hz=float(f[i]), max_phase_error_deg=phase,
                        max_pole_radius=radius, stable_poles_kept=kept, integrators_exact=exact)
