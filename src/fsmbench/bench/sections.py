"""Well-conditioned state-space realisations of zero-pole-gain models.

``control.ss(control.zpk(...))`` returns a companion form whose coefficients
span the products of all pole frequencies (1e13 for a fourth-order controller
with poles near 1e4 rad/s); rounding in those coefficients moves lightly
damped notches. Here a model is split into first- and second-order sections,
each realised with states scaled to its natural frequency, and the sections
are cascaded: the A matrix is block lower-triangular with O(w) entries.

The same sections are what a real-time target runs: :func:`tustin_section`
discretises one section by Tustin, by default prewarped at the section's own
notch (or resonance) frequency so that the discrete response there equals the
continuous one exactly (plain Tustin moves the ESRF study's 411.5 Hz notch to
409.3 Hz, errata E26); :func:`tustin_cascade` does the same on the sections'
scaled state-space realisations.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import control as ct
import numpy as np
from scipy import signal

__all__ = [
    "DiscreteSection",
    "Section",
    "pair_roots",
    "polynomial_ss",
    "section_prewarp_rad_s",
    "section_response",
    "sections_from_zpk",
    "structural_states",
    "tustin_cascade",
    "tustin_rate_hz",
    "tustin_section",
    "warped_frequency_rad_s",
    "zpk_cascade",
]


@dataclass(frozen=True)
class Section:
    """``gain * prod(s - z) / prod(s - p)`` with at most two zeros and two poles.

    Roots come in conjugate pairs or are real; ``len(zeros) <= len(poles)``.
    """

    zeros: tuple[complex, ...]
    poles: tuple[complex, ...]
    gain: float


def pair_roots(roots: Sequence[complex], *, tol: float = 1e-9) -> list[tuple[complex, ...]]:
    """Group roots into conjugate pairs ``(r, conj r)`` and single real roots.

    Complex roots without a conjugate partner (within ``tol`` relative) raise ``ValueError``.
    """
    remaining = [complex(r) for r in roots]
    groups: list[tuple[complex, ...]] = []
    reals = [r for r in remaining if abs(r.imag) <= tol * max(1.0, abs(r))]
    cplx = [r for r in remaining if abs(r.imag) > tol * max(1.0, abs(r))]
    upper = sorted((r for r in cplx if r.imag > 0), key=lambda r: abs(r))
    lower = [r for r in cplx if r.imag < 0]
    for r in upper:
        match = min(lower, key=lambda q: abs(q - r.conjugate()), default=None)
        if match is None or abs(match - r.conjugate()) > 1e-6 * max(1.0, abs(r)):
            raise ValueError(f"complex root {r} has no conjugate partner")
        lower.remove(match)
        groups.append((r, r.conjugate()))
    if lower:
        raise ValueError(f"complex roots {lower} have no conjugate partner")
    groups.extend((complex(r.real, 0.0),) for r in sorted(reals, key=lambda r: abs(r)))
    return groups


def sections_from_zpk(zeros: Sequence[complex], poles: Sequence[complex],
                      gain: float) -> list[Section]:
    """Split ``gain * prod(s - z) / prod(s - p)`` into proper sections.

    Poles are grouped in pairs (conjugates, or two real poles) from the
    slowest up; zeros are attached to the section whose poles are nearest,
    so each section stays close to unit gain and well scaled.
    """
    if len(zeros) > len(poles):
        raise ValueError(f"improper model: {len(zeros)} zeros > {len(poles)} poles")
    pole_groups = pair_roots(poles)
    # Merge single real poles into pairs so every section but maybe one is second order.
    singles = [g for g in pole_groups if len(g) == 1]
    pairs = [g for g in pole_groups if len(g) == 2]
    while len(singles) >= 2:
        pairs.append((singles.pop(0)[0], singles.pop(0)[0]))
    pole_sets = sorted(pairs, key=lambda g: max(abs(r) for r in g)) + singles
    zero_groups = pair_roots(zeros)
    sections_z: list[list[complex]] = [[] for _ in pole_sets]
    for zg in sorted(zero_groups, key=lambda g: -len(g)):
        # Attach to the nearest section with room for these zeros.
        candidates = [i for i, ps in enumerate(pole_sets)
                      if len(sections_z[i]) + len(zg) <= len(ps)]
        if not candidates:
            raise ValueError("cannot distribute zeros into proper sections")
        scale = abs(zg[0])
        best = min(candidates, key=lambda i: abs(np.log((max(abs(p) for p in pole_sets[i])
                                                         + 1e-300) / (scale + 1e-300))))
        sections_z[best].extend(zg)
    return [Section(zeros=tuple(z), poles=tuple(p), gain=gain if i == 0 else 1.0)
            for i, (z, p) in enumerate(zip(sections_z, pole_sets, strict=True))]


def _section_ss(sec: Section) -> ct.StateSpace:
    """Realise one section with states scaled to its pole magnitude."""
    num = np.real(np.poly(sec.zeros)) if sec.zeros else np.array([1.0])
    return polynomial_ss(sec.gain * num, np.real(np.poly(sec.poles)))


def polynomial_ss(num: np.ndarray, den: np.ndarray) -> ct.StateSpace:
    """Realise ``num(s) / den(s)`` (proper, ``den`` of degree 0 to 2) with states scaled to
    its pole magnitude.

    Parameters
    ----------
    num, den : ndarray
        Coefficients, highest power first (``numpy.polyval``'s order); ``len(num) <=
        len(den) <= 3`` and ``den[0] != 0``.
    """
    num = np.asarray(num, dtype=float) / den[0]
    den = np.asarray(den, dtype=float) / den[0]
    n = len(den) - 1
    if n == 0:
        return ct.ss([], [], [], [[num[-1] / den[0]]])
    # Direct feedthrough and strictly proper remainder.
    num_full = np.concatenate([np.zeros(len(den) - len(num)), num])
    d = num_full[0] / den[0]
    rem = num_full - d * den  # leading coefficient now zero
    w = max(np.sqrt(abs(den[-1])) if n == 2 else abs(den[-1]), 1.0)
    if n == 1:
        # x' = -a0 x + w u, y = (r0 / w) x + d u
        a0 = den[1]
        return ct.ss([[-a0]], [[w]], [[rem[1] / w]], [[d]])
    a1, a0 = den[1], den[2]
    b1, b0 = rem[1], rem[2]
    # Observable-like form scaled by w: states x1 = y_sp, x2 = (y_sp' + a1 y_sp - b1 u) / w.
    a = np.array([[-a1, w], [-a0 / w, 0.0]])
    b = np.array([[b1], [b0 / w]])
    c = np.array([[1.0, 0.0]])
    return ct.ss(a, b, c, [[d]])


def zpk_cascade(zeros: Sequence[complex], poles: Sequence[complex], gain: float, *,
                input_name: str = "u", output_name: str = "y") -> ct.StateSpace:
    """Cascade realisation of ``gain * prod(s - z) / prod(s - p)`` (continuous, SISO).

    Parameters
    ----------
    zeros, poles : sequences of complex
        Roots [rad/s]; complex ones in conjugate pairs.
    gain : float
        Leading coefficient ``k`` of ``k prod(s - z) / prod(s - p)``.
    input_name, output_name : str
        Signal names of the result.
    """
    sections = sections_from_zpk(zeros, poles, gain)
    sys = ct.ss([], [], [], [[1.0]])
    for sec in sections:
        sys = ct.series(sys, _section_ss(sec))
    return ct.ss(sys.A, sys.B, sys.C, sys.D, inputs=[input_name], outputs=[output_name])


def structural_states(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> list[int]:
    """States reachable from ``b`` and observable from ``c`` on the sparsity graph of ``a``.

    Parameters
    ----------
    a : ndarray, shape (n, n)
    b : ndarray, shape (n,)
        One input's column.
    c : ndarray, shape (n,)
        One output's row.

    Returns
    -------
    list of int
        The indices, ascending: exact for block-diagonal controllers (each channel's own
        states), with no numerical cancellation.
    """
    nz = a != 0

    def closure(start: np.ndarray, adj: np.ndarray) -> np.ndarray:
        seen = start.copy()
        frontier = start.copy()
        while frontier.any():
            new = adj[:, frontier].any(axis=1) & ~seen
            seen |= new
            frontier = new
        return seen

    reach = closure(b != 0, nz)        # x_i driven by x_j when a[i, j] != 0
    observe = closure(c != 0, nz.T)    # x_j seen through x_i when a[i, j] != 0
    return [int(i) for i in np.nonzero(reach & observe)[0]]


# ----------------------------------------------------------------------------- discrete sections


@dataclass(frozen=True)
class DiscreteSection:
    """One section discretised by Tustin, optionally prewarped.

    Attributes
    ----------
    sos : tuple of 6 floats
        ``(b0, b1, b2, 1, a1, a2)`` in powers of ``z^-1`` (scipy's layout).
    prewarp_rad_s : float or None
        Frequency at which the discrete response equals the continuous one
        exactly [rad/s]; None for plain Tustin.
    continuous : Section
        The section it came from.
    """

    sos: tuple[float, ...]
    prewarp_rad_s: float | None
    continuous: Section


def section_prewarp_rad_s(sec: Section, *, ts_s: float,
                          damping_max: float = 0.2) -> float | None:
    """Frequency a section is prewarped at [rad/s], or None for plain Tustin.

    The natural frequency ``|z|`` of a lightly damped complex zero pair (a
    notch) if the section has one, else ``|p|`` of a lightly damped complex
    pole pair (a resonance), else None: a well-damped or real root has no
    sharp feature to pin, and prewarping would only rescale the section's
    frequency axis by ``(pi f0 ts)^2 / 3`` away from ``f0``. Lightly damped:
    damping ratio below ``damping_max`` (0.2, as the notch report of
    :mod:`fsmbench.control.loops`). Frequencies at or above Nyquist
    (``pi / ts_s``) cannot be prewarped: None.
    """
    for roots in (sec.zeros, sec.poles):
        light = [r for r in roots if r.imag > 0.0 and -r.real < damping_max * abs(r)]
        if light:
            w0 = float(abs(light[0]))
            return w0 if w0 * ts_s / 2.0 < np.pi / 2.0 else None
    return None


def tustin_rate_hz(*, ts_s: float, prewarp_rad_s: float | None) -> float:
    """The ``fs`` of ``s = 2 fs (z - 1)/(z + 1)``: ``1/ts_s``, or ``w0 / (2 tan(w0 ts_s / 2))``."""
    if prewarp_rad_s is None:
        return 1.0 / ts_s
    return prewarp_rad_s / (2.0 * np.tan(prewarp_rad_s * ts_s / 2.0))


def warped_frequency_rad_s(omega_rad_s: np.ndarray, *, ts_s: float,
                           prewarp_rad_s: float | None) -> np.ndarray:
    """Continuous frequency [rad/s] whose response the discrete section gives at ``omega``.

    ``H_d(exp(j w ts)) = H_c(j w')`` with ``w' = 2 fs tan(w ts / 2)`` and ``fs``
    from :func:`tustin_rate_hz`; ``w' = w`` at the prewarp frequency.
    Shape as ``omega_rad_s``.
    """
    fs = tustin_rate_hz(ts_s=ts_s, prewarp_rad_s=prewarp_rad_s)
    return 2.0 * fs * np.tan(np.asarray(omega_rad_s, dtype=float) * ts_s / 2.0)


def tustin_section(sec: Section, *, ts_s: float, prewarp: bool = True) -> DiscreteSection:
    """Discretise one section by Tustin, prewarped per :func:`section_prewarp_rad_s`.

    Parameters
    ----------
    sec : Section
        Continuous section, roots [rad/s].
    ts_s : float
        Sample time [s].
    prewarp : bool
        False for plain Tustin.
    """
    w0 = section_prewarp_rad_s(sec, ts_s=ts_s) if prewarp else None
    fs = tustin_rate_hz(ts_s=ts_s, prewarp_rad_s=w0)
    zd, pd, kd = signal.bilinear_zpk(np.asarray(sec.zeros, dtype=complex),
                                     np.asarray(sec.poles, dtype=complex), sec.gain, fs=fs)
    b = np.real(kd * np.poly(zd)) if len(zd) else np.array([kd], dtype=float)
    a = np.real(np.poly(pd)) if len(pd) else np.array([1.0])
    row = np.zeros(6)
    row[:len(b)] = b
    row[3:3 + len(a)] = a
    return DiscreteSection(sos=tuple(float(x) for x in row), prewarp_rad_s=w0, continuous=sec)


def section_response(sec: Section, s: np.ndarray) -> np.ndarray:
    """``gain prod(s - z) / prod(s - p)`` at complex ``s``, shape as ``s``."""
    s = np.asarray(s, dtype=complex)
    num = np.prod([s - z for z in sec.zeros], axis=0) if sec.zeros else np.ones_like(s)
    den = np.prod([s - p for p in sec.poles], axis=0) if sec.poles else np.ones_like(s)
    return sec.gain * num / den


def tustin_cascade(sections: Sequence[Section], *, ts_s: float, prewarp: bool = True,
                   input_name: str = "u", output_name: str = "y") -> ct.StateSpace:
    """Discrete state-space cascade of sections, each discretised like :func:`tustin_section`.

    Each section's scaled continuous realisation (as in :func:`zpk_cascade`)
    goes through the bilinear map at its own rate (:func:`tustin_rate_hz`),
    so the states stay as well scaled as the continuous cascade's; the
    response equals the cascade of :func:`tustin_section` rows.

    Parameters
    ----------
    sections : sequence of Section
        Continuous sections [rad/s].
    ts_s : float
        Sample time [s].
    prewarp : bool
        False for plain Tustin.
    input_name, output_name : str
        Signal names of the result.
    """
    sys = ct.ss([], [], [], [[1.0]], ts_s)
    for sec in sections:
        if not sec.poles:  # static (proper sections without poles have no zeros)
            part = ct.ss([], [], [], [[sec.gain]], ts_s)
        else:
            cont = _section_ss(sec)
            w0 = section_prewarp_rad_s(sec, ts_s=ts_s) if prewarp else None
            dt_eff = 1.0 / tustin_rate_hz(ts_s=ts_s, prewarp_rad_s=w0)
            a, b, c, d, _ = signal.cont2discrete(
                (np.asarray(cont.A, dtype=float), np.asarray(cont.B, dtype=float),
                 np.asarray(cont.C, dtype=float), np.asarray(cont.D, dtype=float)),
                dt_eff, method="bilinear")
            part = ct.ss(a, b, c, d, ts_s)
        sys = ct.series(sys, part)
    return ct.ss(sys.A, sys.B, sys.C, sys.D, ts_s, inputs=[input_name], outputs=[output_name])
