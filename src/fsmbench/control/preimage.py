"""The continuous controller a discrete one is the plain-Tustin image of.

A controller read from a file (``controllers_sos.json``, ``controllers.mat``) is discrete.
What analyses it (margins, predictions, the twin, a re-export) wants a continuous ``K``
whose plain Tustin image is the file's, line for line.

Substituting ``z = (1 + s T/2) / (1 - s T/2)`` into the whole realisation
(:func:`tustin_preimage`) does that exactly in theory, and its frequency response is
right to round-off. Its zeros are not. Tustin puts a section's zeros at infinity on
``z = -1``, and the file's realisation of an integrator section holds entries of ~1e8.
The substitution's zeros then land anywhere between 1e11 and 1e13 rad/s. A zero-pole
split of that model (``export.siso_zpk``, to write it again) kept some of those zeros,
dropped others, and returned a complex gain: a retune exported 20 times the controller
a previous tune had loaded, and it failed that way.

A ``controllers_sos.json`` holds its sections, and their roots are well conditioned
(three coefficients each). :func:`sections_preimage` maps them root by root:

- a discrete zero within :data:`AT_NYQUIST` of ``-1`` is a zero at infinity;
- a section's missing zero (``b0 = 0``) is a zero at ``s = 2/T``;
- each section's gain is matched at one point on the unit circle, away from its roots.

The result is a cascade of scaled sections (:func:`realize.zpk_cascade`).
"""

from __future__ import annotations

from collections.abc import Sequence

import control as ct
import numpy as np

from fsmbench.bench.sections import zpk_cascade

__all__ = ["AT_NYQUIST", "nyquist_pole_distance", "sections_preimage", "tustin_preimage"]

#: A root closer than this to z = -1 counts as on it [1]: its Tustin pre-image would lie
#: beyond 4 / (T 1e-6) rad/s (6e5 times the sample rate), no roll-off of a physical loop,
#: and a double root on -1 is located only to ~sqrt(eps) = 1.5e-8.
AT_NYQUIST = 1e-6

#: Points on the unit circle a section's gain may be matched at [rad of z's angle]: the
#: one farthest from its roots is used, so no factor is near zero.
_MATCH_ANGLES = (0.5, 1.0, 1.7, 2.4)

#: The matched gain's imaginary part, relative, beyond which the roots do not describe
#: the section [1]: round-off of a quadratic's roots gives ~1e-12.
_REAL_GAIN = 1e-6


def nyquist_pole_distance(a: np.ndarray) -> float:
    """The smallest ``|1 + z|`` over the poles ``z`` of ``a`` (inf without states)."""
    if a.shape[0] == 0:
        return float("inf")
    return float(np.min(np.abs(1.0 + np.linalg.eigvals(a))))


def _to_s(z: np.ndarray, ts_s: float) -> np.ndarray:
    return (2.0 / ts_s) * (z - 1.0) / (z + 1.0)


def _section(row: np.ndarray, *, ts_s: float) -> tuple[list[complex], list[complex], float]:
    """One ``[b0, b1, b2, a0, a1, a2]`` section's continuous zeros, poles [rad/s] and
    leading coefficient."""
    b, a = row[:3].astype(float), row[3:].astype(float)
    while b.size > 1 and a.size > 1 and b[-1] == 0.0 and a[-1] == 0.0:
        b, a = b[:-1], a[:-1]  # a common root at z = 0: a first-order section
    if not np.any(b):
        return [], [], 0.0
    # z^-k polynomials as polynomials in z of degree len - 1: a leading zero coefficient is
    # a root at infinity in z, a zero at s = 2/T.
    lead = int(np.argmax(b != 0.0))
    zeros_z = np.roots(b[lead:]).astype(complex)
    poles_z = np.roots(a).astype(complex)
    if np.any(np.abs(1.0 + poles_z) < AT_NYQUIST):
        raise ValueError("a pole at z = -1 (Nyquist) has no continuous-time equivalent")
    finite = np.abs(1.0 + zeros_z) >= AT_NYQUIST
    zeros_s = np.concatenate([_to_s(zeros_z[finite], ts_s),
                              np.full(lead, 2.0 / ts_s, dtype=complex)])
    poles_s = _to_s(poles_z, ts_s)
    roots = np.concatenate([zeros_z, poles_z])
    z0 = max((np.exp(1j * t) for t in _MATCH_ANGLES),
             key=lambda q: float(np.min(np.abs(roots - q), initial=np.inf)))
    h = np.polyval(b, z0) / np.polyval(a, z0)  # the same power of z on both sides
    s0 = complex(_to_s(np.array([z0]), ts_s)[0])
    k = h * np.prod(s0 - poles_s) / np.prod(s0 - zeros_s)
    if abs(k.imag) > _REAL_GAIN * abs(k):
        raise ValueError(f"a section's roots do not describe it (matched gain {k:.3g})")
    return list(zeros_s), list(poles_s), float(k.real)


def sections_preimage(sections: Sequence[np.ndarray], *, ts_s: float,
                      inputs: Sequence[str], outputs: Sequence[str],
                      name: str) -> ct.StateSpace:
    """The continuous diagonal ``K`` whose plain Tustin image is a cascade per axis.

    Parameters
    ----------
    sections : sequence of ndarray, shape (n_sections, 6)
        Per axis, its cascade ``[b0, b1, b2, a0, a1, a2]`` in powers of ``z^-1``, section
        0 first, from input ``i`` to output ``i``.
    ts_s : float
        Sample time [s].
    inputs, outputs : sequence of str
        Signal names, one per axis.
    name : str
        The result's name.

    Returns
    -------
    control.StateSpace
        Continuous, block-diagonal: one cascade of scaled sections per axis.

    Raises
    ------
    ValueError
        A pole on ``z = -1``, or a section whose matched gain is not real.
    """
    parts = []
    for rows, i_name, o_name in zip(sections, inputs, outputs, strict=True):
        zeros: list[complex] = []
        poles: list[complex] = []
        gain = 1.0
        for row in np.atleast_2d(np.asarray(rows, dtype=float)):
            z, p, k = _section(row, ts_s=ts_s)
            zeros, poles, gain = zeros + z, poles + p, gain * k
        if gain == 0.0 or not poles:
            part = ct.ss([], [], [], [[gain]], inputs=[i_name], outputs=[o_name])
        else:
            part = zpk_cascade(zeros, poles, gain, input_name=i_name, output_name=o_name)
        parts.append(part)
    sys = ct.append(*parts) if len(parts) > 1 else parts[0]
    return ct.ss(sys.A, sys.B, sys.C, sys.D, inputs=list(inputs), outputs=list(outputs),
                 name=name)


def tustin_preimage(a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray, *,
                    ts_s: float, inputs: Sequence[str], outputs: Sequence[str],
                    name: str) -> ct.StateSpace:
    """The continuous ``K`` whose plain Tustin image at ``ts_s`` is ``(a, b, c, d)``.

    By substitution in the realisation: its response is exact to round-off, its zeros
    need not be (module notes; a file with sections: :func:`sections_preimage`).

    Parameters
    ----------
    a : ndarray, shape (n, n)
        Discrete state matrix (no pole within :data:`AT_NYQUIST` of ``z = -1``: such a
        pole has no pre-image; see :func:`nyquist_pole_distance`).
    b : ndarray, shape (n, m)
    c : ndarray, shape (p, n)
    d : ndarray, shape (p, m)
        In the file's units (V/rad for a ``Rh, Rv -> Uch, Ucv`` controller).
    ts_s : float
        Sample time [s].
    inputs, outputs : sequence of str
        Signal names, ``m`` and ``p`` of them.
    name : str
        The result's name.

    Raises
    ------
    ValueError
        A pole on ``z = -1``.
    """
    a, b, c, d = (np.asarray(x, dtype=float) for x in (a, b, c, d))
    if nyquist_pole_distance(a) < AT_NYQUIST:
        raise ValueError("a pole at z = -1 (Nyquist) has no continuous-time equivalent")
    n = a.shape[0]
    # z = (1 + s T/2)/(1 - s T/2) in C (zI - A)^-1 B + D, with M = I + A:
    # Ac = (2/T) M^-1 (A - I), Bc = M^-1 B, Cc = (4/T) C M^-1, Dc = D - C M^-1 B.
    minv = np.linalg.inv(np.eye(n) + a) if n else np.zeros((0, 0))
    return ct.ss((2.0 / ts_s) * minv @ (a - np.eye(n)), minv @ b, (4.0 / ts_s) * c @ minv,
                 d - c @ minv @ b, inputs=list(inputs), outputs=list(outputs), name=name)
