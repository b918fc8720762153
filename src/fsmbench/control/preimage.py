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

A ``controllers_sos.json`` holds its sections. :func:`sections_preimage` substitutes
Tustin's map into each section's own coefficients (three and three), exact algebra with
no root to find: Tustin's double zero on ``z = -1`` becomes a constant numerator, a
missing ``b0`` a zero at ``s = 2/T``. Each section is realised with scaled states
(:func:`fsmbench.bench.sections.polynomial_ss`) and the sections are cascaded. Roots were
tried first: a double root near ``z = 1`` (an integrator's neighbour) is located from
three coefficients only to ``sqrt(eps)``, 1e-4 of a 1 rad/s zero.
"""

from __future__ import annotations

from collections.abc import Sequence

import control as ct
import numpy as np

from fsmbench.bench.sections import polynomial_ss

__all__ = ["AT_NYQUIST", "nyquist_pole_distance", "sections_preimage", "tustin_preimage"]

#: A root closer than this to z = -1 counts as on it [1]: its Tustin pre-image would lie
#: beyond 4 / (T 1e-6) rad/s (6e5 times the sample rate), no roll-off of a physical loop,
#: and a double root on -1 is located only to ~sqrt(eps) = 1.5e-8.
AT_NYQUIST = 1e-6


def nyquist_pole_distance(a: np.ndarray) -> float:
    """The smallest ``|1 + z|`` over the poles ``z`` of ``a`` (inf without states)."""
    if a.shape[0] == 0:
        return float("inf")
    return float(np.min(np.abs(1.0 + np.linalg.eigvals(a))))


def _in_s(coefficients: np.ndarray, ts_s: float) -> np.ndarray:
    """A section's numerator or denominator in ``z^-1`` (``c0 + c1 z^-1 [+ c2 z^-2]``) under
    ``z = (1 + w) / (1 - w)``, times ``(1 - w)^n``, with ``w = s T / 2``: its coefficients
    in ``s``, highest power first. Exact algebra: a double zero of Tustin on ``z = -1``
    (``c = g [1, 2, 1]``) gives a constant, not two roots located to ``sqrt(eps)``."""
    half = ts_s / 2.0
    if coefficients.size == 2:
        c0, c1 = coefficients
        in_w = np.array([c0 - c1, c0 + c1])
    else:
        c0, c1, c2 = coefficients
        in_w = np.array([c0 - c1 + c2, 2.0 * (c0 - c2), c0 + c1 + c2])
    return in_w * half ** np.arange(in_w.size - 1, -1, -1)


def _section(row: np.ndarray, *, ts_s: float) -> ct.StateSpace:
    """One ``[b0, b1, b2, a0, a1, a2]`` section's continuous pre-image (at most 2 states)."""
    b, a = row[:3].astype(float), row[3:].astype(float)
    while b.size > 1 and b[-1] == 0.0 and a[-1] == 0.0:
        b, a = b[:-1], a[:-1]  # a common root at z = 0: a first-order section
    if not np.any(a[1:]) and not np.any(b[1:]):
        return ct.ss([], [], [], [[b[0] / a[0]]])
    poles_z = np.roots(a)
    if poles_z.size and float(np.min(np.abs(1.0 + poles_z))) < AT_NYQUIST:
        raise ValueError("a pole at z = -1 (Nyquist) has no continuous-time equivalent")
    num, den = _in_s(b, ts_s), _in_s(a, ts_s)
    # Leading coefficients zero in s (a pole on z = -1 excluded above: den's is not) are
    # dropped so that the realisation sees the section's true degree.
    den = np.trim_zeros(den, "f")
    num = np.trim_zeros(num, "f")
    return polynomial_ss(num if num.size else np.zeros(1), den)


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
        A pole on ``z = -1``.
    """
    parts = []
    for rows, i_name, o_name in zip(sections, inputs, outputs, strict=True):
        chain = ct.ss([], [], [], [[1.0]])
        for row in np.atleast_2d(np.asarray(rows, dtype=float)):
            chain = ct.series(chain, _section(row, ts_s=ts_s))
        parts.append(ct.ss(chain.A, chain.B, chain.C, chain.D, inputs=[i_name],
                           outputs=[o_name]))
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
