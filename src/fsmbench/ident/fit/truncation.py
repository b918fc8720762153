"""Modes above the Sercalo's fitted band: the static gain's truncation bias, tested and removed.

The vector fit models the lines up to ``f_max_hz`` with the modes inside the
band and a constant ``D`` for what lies above. A mode above the band (the
real-bench twin's second modes at 1420 and 1850 Hz, 1 % of the gain) is not a
constant over the band: its response rises as ``1/(1 − (f/f₂)²)``, which
``D`` cannot follow, and the fit bends its in-band residues to follow it. On
the exact, noise-free FRF of the real-bench twin the static gain came out
+1.0e-3 (h) and +2.3e-3 (v) high with the 1 kHz band, 2 to 8 of its stds;
over half the band, +1e-4 and +3e-4.

The bias grows with the band, as ``f_max²`` or faster (the out-of-band
mode's curvature over the band). The fit over half the band is consistent
whether or not a mode lies above it, but noisier; the full band's is
efficient when none does. Their difference ``Δ`` then has the variance
``σ²_half − σ²_full`` (Hausman: an efficient estimator against a consistent
one); beyond :data:`HAUSMAN_Z` of it a mode above the band is said to bend
the full band's fit (``significant``). The half band's static gain is
reported (on the default twin, which has no such mode, its std is 1.2–1.3× the
full band's), with its own parts and a ``truncation`` part: the bias left
at half the band, at most ``|Δ|/3`` (a bias growing at least as ``f_max²``
keeps at most a quarter of itself at half the band, ``Δ (1/4)/(1 − 1/4)``),
a bound. The reported static gain then differs from the plant model's
``Gc(0)`` (the full band's fit) by ``Δ``.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from fsmbench.ident.sercalo import SercaloIdentification, fit_sercalo, refit_with_poles

__all__ = ["HAUSMAN_Z", "TruncationCheck", "truncation_checks"]

#: The difference is significant beyond this many of its standard deviations (a false alarm
#: in 0.27 % of axes; what the report says, the value reported is the half band's anyway).
HAUSMAN_Z = 3.0
#: Half the band must still lie this far above the axis's mode (its peak and roll-off in).
_ABOVE_MODE = 1.15


@dataclass(frozen=True)
class TruncationCheck:
    """The static gain of one axis over the full and half the band.

    Attributes
    ----------
    axis : {"h", "v"}
    full_v_per_a, half_v_per_a : float
        Static gain of the fits up to ``f_max_hz`` and ``f_max_hz / 2`` [V/A].
    delta_std_v_per_a : float
        Standard deviation of their difference, ``sqrt(σ²_half − σ²_full)`` [V/A].
    half_band_hz : float
        Top of the half band [Hz].
    significant : bool
        ``|Δ|`` beyond :data:`HAUSMAN_Z` of its std: a mode above the band.
    half_parts : mapping str -> float
        The half-band fit's parts of the static gain's std [V/A].
    """

    axis: str
    full_v_per_a: float
    half_v_per_a: float
    delta_std_v_per_a: float
    half_band_hz: float
    significant: bool
    half_parts: Mapping[str, float]

    @property
    def bias_bound_v_per_a(self) -> float:
        """Half-width of the bias left at half the band, ``|Δ|/3`` [V/A]."""
        return abs(self.full_v_per_a - self.half_v_per_a) / 3.0

    def to_json(self) -> dict[str, Any]:
        """Plain values."""
        return {"full_v_per_a": self.full_v_per_a, "half_v_per_a": self.half_v_per_a,
                "delta_std_v_per_a": self.delta_std_v_per_a,
                "half_band_hz": self.half_band_hz, "significant": self.significant}


def truncation_checks(sid: SercaloIdentification, *,
                      poles: Mapping[str, complex] | None = None) -> dict[str, TruncationCheck]:
    """Fit again over half the band and test the static gains (see the module).

    Parameters
    ----------
    sid : SercaloIdentification
        The identification as reported (with its parameter stds).
    poles : mapping input -> complex, optional
        The refined modes the reported fit holds (the half-band fit holds them too).

    Returns
    -------
    dict axis -> TruncationCheck
        Empty when the half band would cut a mode, or a fit has no stds.
    """
    full = sid.parameter_std
    half_hz = 0.5 * float(sid.options.f_max_hz)
    top_mode = max(sid.resonances_hz.values(), default=math.inf)
    if full is None or half_hz < _ABOVE_MODE * top_mode:
        return {}
    try:
        again = fit_sercalo(sid.frf, gi_a_per_v=sid.gi_a_per_v, options=dataclasses.replace(
            sid.options, f_max_hz=half_hz, delay_s=sid.delay_s))
        if poles is not None:
            again = refit_with_poles(again, poles=poles)
    except ValueError:
        return {}
    half = again.parameter_std
    if half is None:
        return {}
    out = {}
    for axis in "hv":
        if axis not in full.value or axis not in half.value:
            continue
        d_full = full.value[axis]["dc_gain_v_per_a"]
        d_half = half.value[axis]["dc_gain_v_per_a"]
        s_full = full.std[axis]["dc_gain_v_per_a"]
        s_half = half.std[axis]["dc_gain_v_per_a"]
        # Hausman's variance; when noise made the half band's std come out the lower, the
        # half band's own (a conservative stand-in).
        var = s_half**2 - s_full**2
        sd = math.sqrt(var) if var > 0 else s_half
        out[axis] = TruncationCheck(
            axis=axis, full_v_per_a=float(d_full), half_v_per_a=float(d_half),
            delta_std_v_per_a=float(sd), half_band_hz=half_hz,
            significant=bool(abs(d_full - d_half) > HAUSMAN_Z * sd),
            half_parts={k: float(v) for k, v in half.parts[axis]["dc_gain_v_per_a"].items()
                        if math.isfinite(v)})
    return out
