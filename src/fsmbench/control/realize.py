"""Well-conditioned state-space realisations of zero-pole-gain models.

``control.ss(control.zpk(...))`` returns a companion form whose coefficients
span the products of all pole frequencies (1e13 for a fourth-order controller
with poles near 1e4 rad/s); rounding in those coefficients moves lightly
damped notches. Here a model is split into first- and second-order sections,
each realised with states scaled to its natural frequency, and the sections
are cascaded: the A matrix is block lower-triangular with O(w) entries.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import control as ct
import numpy as np

__all__ = ["Section", "pair_roots", "sections_from_zpk", "zpk_cascade"]


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
    den = np.real(np.poly(sec.poles))
    num = sec.gain * num
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
