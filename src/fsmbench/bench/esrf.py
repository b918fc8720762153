"""The ESRF study's controllers (sections 8, 9.2 and 10.2), restored and realised.

The decentralised controller of 9.2 is printed with an unbalanced parenthesis
in ``Kh`` (``/((s^2*(s+352.5)*(1+s/2/pi/2000))``); the intended expression,
the only one that parses with the same factors, is

    Kh = -0.25598 (s + 112)(s^2 + 15.93 s + 6.686e6) / (s^2 (s + 352.5)(1 + s/(2 pi 2000)))
    Kv = 10207 (s + 55.15)(s^2 + 17.45 s + 2.491e6) / (s^2 (s + 491.2)(s + 7695))

(errata E-K1). Both loops then cross over near 27 Hz on the bench's plant,
which supports the restoration (see tests/control/test_esrf.py).
The ESRF study closes the loop with ``-K``: ``[Uch, Ucv] = -K [Rh, Rv]``.
"""

from __future__ import annotations

from dataclasses import dataclass

import control as ct
import numpy as np

from fsmbench.bench.sections import zpk_cascade

__all__ = [
    "ESRF_TS_S",
    "EsrfZpk",
    "esrf_decentralised_controller",
    "esrf_decentralised_zpk",
    "iff_controller",
    "newport_controller",
    "tustin",
]

ESRF_TS_S = 1e-4  # seed 9.3: Kd = c2d(K, 1e-4, 'tustin')


def _quadratic_roots(b1: float, b0: float) -> list[complex]:
    return [complex(r) for r in np.roots([1.0, b1, b0])]


@dataclass(frozen=True)
class EsrfZpk:
    """One axis of the ESRF study's controller of 9.2 as continuous zeros, poles and gain.

    Attributes
    ----------
    zeros_rad_s, poles_rad_s : tuple of complex
        In rad/s (``s`` plane).
    gain : float
        The zpk gain [V/rad·(rad/s)^(poles − zeros)]: ``K(s) = gain Π(s − z)/Π(s − p)``.
    """

    zeros_rad_s: tuple[complex, ...]
    poles_rad_s: tuple[complex, ...]
    gain: float


def esrf_decentralised_zpk() -> dict[str, EsrfZpk]:
    """``Kh`` and ``Kv`` of ESRF study 9.2 by axis (``"h"``, ``"v"``), input R [rad], output V."""
    w_lp = 2.0 * np.pi * 2000.0
    return {"h": EsrfZpk((-112.0, *_quadratic_roots(15.93, 6.686e6)),
                         (0.0, 0.0, -352.5, -w_lp), -0.25598 * w_lp),
            "v": EsrfZpk((-55.15, *_quadratic_roots(17.45, 2.491e6)),
                         (0.0, 0.0, -491.2, -7695.0), 10207.0)}


def esrf_decentralised_controller() -> ct.StateSpace:
    """``K = blkdiag(Kh, Kv)`` (ESRF study 9.2), inputs ``Rh, Rv`` [rad], outputs ``Uch, Ucv``."""
    axes = esrf_decentralised_zpk()
    kh, kv = (zpk_cascade(list(axes[a].zeros_rad_s), list(axes[a].poles_rad_s), axes[a].gain,
                          input_name=f"R{a}", output_name=f"Uc{a}") for a in "hv")
    k = ct.append(kh, kv)
    return ct.ss(k.A, k.B, k.C, k.D, inputs=["Rh", "Rv"], outputs=["Uch", "Ucv"], name="K")


def newport_controller(*, gn0_rad_per_v: tuple[float, float], crossover_hz: float = 10.0,
                       lead_ratio: float = 2.0) -> ct.StateSpace:
    """Newport alignment controller of ESRF study 10.2, inputs ``Rh, Rv``, outputs ``Unh, Unv``.

    ``Kn = 1/Gn0 (w0/s)^2 (1 + s h/w0) / (1 + s/(w0 h)) / h`` per axis, with
    ``Gn0`` the static beam angle per Newport volt (``inv(Gd) Gn`` at DC).
    """
    w0 = 2.0 * np.pi * crossover_hz
    h = lead_ratio
    parts = []
    for g0, (inp, out) in zip(gn0_rad_per_v, (("Rh", "Unh"), ("Rv", "Unv")), strict=True):
        # (w0/s)^2 (1 + s h/w0)/(1 + s/(w0 h))/h = w0^2 * h * (s + w0/h)/(s^2 (s + w0 h)) * h/h
        gain = (w0**2) * (h / w0) * (w0 * h) / h / g0
        parts.append(zpk_cascade([-w0 / h], [0.0, 0.0, -w0 * h], gain,
                                 input_name=inp, output_name=out))
    k = ct.append(*parts)
    return ct.ss(k.A, k.B, k.C, k.D, inputs=["Rh", "Rv"], outputs=["Unh", "Unv"], name="Kn")


def iff_controller() -> ct.StateSpace:
    """Integral force feedback (ESRF study 8.2): ``blkdiag(-10000/s, 0)``, Vch,Vcv to Uch,Ucv."""
    a = np.array([[0.0]])
    b = np.array([[1.0, 0.0]])
    c = np.array([[-10000.0], [0.0]])
    return ct.ss(a, b, c, np.zeros((2, 2)), inputs=["Vch", "Vcv"], outputs=["Uch", "Ucv"],
                 name="Kppf")


def tustin(k: ct.StateSpace, *, ts_s: float = ESRF_TS_S) -> ct.StateSpace:
    """Bilinear (Tustin) discretisation keeping the signal names (ESRF study 9.3)."""
    kd = ct.sample_system(k, ts_s, method="tustin")
    return ct.ss(kd.A, kd.B, kd.C, kd.D, ts_s, inputs=list(k.input_labels),
                 outputs=list(k.output_labels), name=f"{k.name}d" if k.name else None)
