"""Back-calculation anti-windup for a controller's integrators at the DAC limits.

A controller with integrators (fsmbench's has four per axis, the ESRF study's
two) keeps integrating while the DAC sits on its rail: the integrators wind up
far beyond what the loop can use, and after the cause goes the command stays
on the rail until they unwind. Back-calculation (Åström & Rundqwist 1989, the
observer form of Åström & Wittenmark, *Computer-Controlled Systems*, 9.4)
feeds the part of the command the DAC could not apply back into the
integrators' states::

    v      = C x + D e                      (the controller's demand, V)
    v_sat  = clip(v, DAC rails)
    x[k+1] = A x + B e + L (v_sat - v)

Unsaturated, ``v_sat - v = 0`` and the controller is the linear one exactly.
Saturated, the integrators' part of the controller runs with the poles of
``A_I - L C_I`` instead of ``z = 1``: they follow the applied command within
the tracking time ``Tt`` instead of winding.

Form: each channel's sections (:func:`fsmbench.control.export.discretise_channel`)
are reordered so that the integrator sections (``1 - 2 z^-1 + z^-2`` or
``1 - z^-1``) come last — sections commute, the response is unchanged — and
realised in direct form II transposed (scipy's ``sosfilt``): a section
``[b0, b1, b2, 1, a1, a2]`` with input ``w`` and states ``s1, s2`` computes
``y = b0 w + s1``, ``s1 <- s2 + b1 w - a1 y``, ``s2 <- b2 w - a2 y``. ``L``
acts only on the integrator sections' states, so a target adds ``L_i (v_sat -
v)`` to those registers after its usual update. ``L`` places the
integrators' poles, when saturated, at ``exp(-i Ts / Tt)``, ``i = 1 .. n_I``
(time constants ``Tt, Tt/2, ...``: distinct, so placing them is well posed).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy import signal

__all__ = [
    "DEFAULT_TRACKING_TIME_S",
    "AntiWindupChannel",
    "antiwindup_channel",
    "df2t_cascade",
    "is_integrator_section",
]

#: Tracking time constant [s]: near fsmbench's integrator corner (7 Hz, 23 ms), so the
#: saturated integrators unwind at the pace their own action has. Measured on the twin's
#: saturating step (:func:`fsmbench.control.antiwindup_loop.saturating_step`): 2–5 ms made the
#: four-integrator loop overshoot again after the rail, 20–40 ms recovered as fast as the
#: unsaturated loop settles.
DEFAULT_TRACKING_TIME_S = 20e-3


def is_integrator_section(row: np.ndarray) -> bool:
    """A section whose denominator is ``(1 - z^-1)^2`` or ``1 - z^-1`` exactly."""
    a0, a1, a2 = (float(x) for x in np.asarray(row, dtype=float)[3:])
    return (a1 / a0 == -2.0 and a2 / a0 == 1.0) or (a1 / a0 == -1.0 and a2 == 0.0)


def df2t_cascade(sos: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """State space of a cascade of sections in direct form II transposed, section 0 first.

    Each section of order ``n`` (2, or 1 when ``a2 = b2 = 0``, 0 when static)
    contributes its ``n`` DF2T registers, in section order.

    Returns
    -------
    a, b, c, d : numpy.ndarray
        ``(nk, nk)``, ``(nk, 1)``, ``(1, nk)``, ``(1, 1)``.
    """
    a, b, c, d = np.zeros((0, 0)), np.zeros((0, 1)), np.zeros((1, 0)), np.eye(1)
    for row in np.asarray(sos, dtype=float):
        b0, b1, b2, _a0, a1, a2 = row / row[3]
        order = 2 if (a2 != 0.0 or b2 != 0.0) else (1 if (a1 != 0.0 or b1 != 0.0) else 0)
        a_s = np.array([[-a1, 1.0], [-a2, 0.0]])[:order, :order]
        b_s = np.array([[b1 - a1 * b0], [b2 - a2 * b0]])[:order]
        c_s = np.array([[1.0, 0.0]])[:, :order]
        d_s = np.array([[b0]])
        # Series: the section's input is the cascade's output so far.
        a = np.block([[a, np.zeros((a.shape[0], order))], [b_s @ c, a_s]])
        b = np.vstack([b, b_s @ d])
        c = np.hstack([d_s @ c, c_s])
        d = d_s @ d
    return a, b, c, d


@dataclass(frozen=True, eq=False)
class AntiWindupChannel:
    """One SISO channel ``v = K e`` with its sections reordered and its back-calculation gain.

    Attributes
    ----------
    sos : numpy.ndarray, shape (n_sections, 6)
        The channel's sections, integrator sections last (same response).
    a, b, c, d : numpy.ndarray
        Their DF2T realisation (:func:`df2t_cascade`), ``e`` [rad] to ``v`` [V].
    gain : numpy.ndarray, shape (nk,)
        ``L`` [1/V per V of unapplied command, in the states' units]; zero
        outside the integrator sections' registers.
    integrator_states : tuple of int
        The registers ``L`` acts on.
    tracking_time_s : float
        ``Tt`` [s].
    ts_s : float
        Sample time [s].
    saturated_poles : numpy.ndarray
        Poles of the integrator sections while saturated, ``eig(A_I - L C_I)``.
    """

    sos: np.ndarray = field(repr=False)
    a: np.ndarray = field(repr=False)
    b: np.ndarray = field(repr=False)
    c: np.ndarray = field(repr=False)
    d: np.ndarray = field(repr=False)
    gain: np.ndarray = field(repr=False)
    integrator_states: tuple[int, ...]
    tracking_time_s: float
    ts_s: float
    saturated_poles: np.ndarray = field(repr=False)

    @property
    def n_integrators(self) -> int:
        """Poles on ``z = 1``."""
        return len(self.integrator_states)

    def to_json(self) -> dict[str, Any]:
        """The reordered sections, ``L`` per integrator register and the tracking time.

        Registers are numbered as :func:`df2t_cascade` orders them; each names
        its section (index in ``sos_integrators_last``) and ``s1`` or ``s2``.
        """
        owner: list[tuple[int, str]] = []
        for i, row in enumerate(self.sos):
            order = 2 if (row[5] != 0.0 or row[2] != 0.0) else (
                1 if (row[4] != 0.0 or row[1] != 0.0) else 0)
            owner.extend((i, f"s{j + 1}") for j in range(order))
        regs = [{"state_index": int(k), "section": owner[k][0], "register": owner[k][1],
                 "gain": float(self.gain[k])} for k in self.integrator_states]
        poles = [{"z": float(abs(p)), "time_constant_s": float(-self.ts_s / np.log(abs(p)))}
                 for p in self.saturated_poles]
        return {"scheme": "back-calculation", "tracking_time_s": self.tracking_time_s,
                "sos_integrators_last": [[float(x) for x in r] for r in self.sos],
                "integrator_registers": regs, "saturated_poles": poles}


def antiwindup_channel(sos: np.ndarray, *, ts_s: float,
                       tracking_time_s: float = DEFAULT_TRACKING_TIME_S) -> AntiWindupChannel:
    """Reorder a channel's sections (integrators last) and compute its back-calculation gain.

    Parameters
    ----------
    sos : array-like, shape (n_sections, 6)
        The channel's sections ``[b0, b1, b2, a0, a1, a2]`` in ``z^-1``.
    ts_s : float
        Sample time [s].
    tracking_time_s : float
        ``Tt`` [s], the slowest saturated pole's time constant; at least the integrators'
        count of samples (``n * ts_s``), which the result then records.

    Raises
    ------
    ValueError
        ``tracking_time_s`` not positive, or the integrator registers are not
        observable from the output (an integrator cancelled by a zero at ``z = 1``).
    """
    if not tracking_time_s > 0:
        raise ValueError(f"tracking_time_s must be > 0, got {tracking_time_s}")
    rows = np.asarray(sos, dtype=float)
    integ = [r for r in rows if is_integrator_section(r)]
    ordered = np.array([r for r in rows if not is_integrator_section(r)] + integ)
    a, b, c, d = df2t_cascade(ordered)
    n_int = 0
    for r in integ:
        n_int += 2 if r[5] != 0.0 or r[2] != 0.0 else 1
    nk = a.shape[0]
    states = tuple(range(nk - n_int, nk))
    gain = np.zeros(nk)
    poles = np.zeros(0, dtype=complex)
    if n_int:
        a_i = a[nk - n_int:, nk - n_int:]
        c_i = c[:, nk - n_int:]
        # A tracking time of a few samples at least: at a slow rate (a bench file at 10 Hz)
        # 20 ms put the poles at 1e-9 and no placement reached them; the fastest stays e^-1.
        tracking_time_s = max(float(tracking_time_s), n_int * ts_s)
        want = np.exp(-ts_s * np.arange(1, n_int + 1) / tracking_time_s)
        # Observer-style placement on the dual pair (A_I^T, C_I^T); its conditioning is poor
        # (states scaled 1 : 1e-9 by the cascade's gain), so the result is checked below.
        placed = signal.place_poles(a_i.T, c_i.T, want)
        gain[nk - n_int:] = placed.gain_matrix[0]
        poles = np.linalg.eigvals(a_i - np.outer(gain[nk - n_int:], c_i[0]))
        if np.max(np.abs(np.sort(np.abs(poles)) - np.sort(want))) > 1e-3 * (1 - want.min()):
            raise ValueError("the integrators' saturated poles could not be placed "
                             f"(wanted {want}, got {np.sort(np.abs(poles))})")
    return AntiWindupChannel(sos=ordered, a=a, b=b, c=c, d=d, gain=gain,
                             integrator_states=states, tracking_time_s=float(tracking_time_s),
                             ts_s=float(ts_s), saturated_poles=poles)
