"""The Sercalo's modes re-estimated on the time records (seed 2.3, without its bias).

The rational fit of 2.3 is made on the seed's Welch estimate (1 s Hann
window), which widens modes whose half-power bandwidth (~0.5–1 Hz) is below
the window's resolution: its damping ratios come out 1.5–3× too high. Here
each axis's mode is re-estimated from its own experiment (``data_uch`` for
the horizontal mode, ``data_ucv`` for the vertical one) with
:func:`fsmbench.ident.fit.modal.estimate_modes` — a frequency-domain output-error
fit on the full-record DFT with the exact leakage term — starting from the
vector-fitting result. The fitted ``Gc`` keeps its residues; only the
reported modal parameters (and the ones used downstream) change.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
import xarray as xr

from fsmbench.ident.calibration import trim_recording
from fsmbench.ident.fit.modal import ModalEstimate, ModeEstimate, estimate_modes

if TYPE_CHECKING:
    from fsmbench.ident.sercalo import SercaloIdentification

__all__ = ["ModeRefinement", "refine_modes"]

_AXES = (("h", "data_uch", "Uch", "Vph"), ("v", "data_ucv", "Ucv", "Vpv"))


@dataclass(frozen=True, eq=False)
class ModeRefinement:
    """Refined mode of each axis.

    Attributes
    ----------
    estimates : dict axis -> ModalEstimate
        The full estimate (band, residuals, convergence) per axis.
    initial : dict axis -> (resonance_hz, damping_ratio)
        The vector-fitting values it started from.
    """

    estimates: dict[str, ModalEstimate]
    initial: dict[str, tuple[float, float]]

    def by_axis(self) -> dict[str, ModeEstimate]:
        """The (single) mode of each axis."""
        return {axis: est.modes[0] for axis, est in self.estimates.items()}

    def poles_by_input(self) -> dict[str, complex]:
        """Upper-half-plane continuous pole of each axis's mode, keyed by its input [rad/s]."""
        out = {}
        for axis, _exp, signal, _out in _AXES:
            m = self.estimates[axis].modes[0]
            w0 = 2 * np.pi * m.resonance_hz
            xi = m.damping_ratio
            out[signal] = complex(-xi * w0, w0 * np.sqrt(1 - xi**2))
        return out

    def to_json(self) -> dict[str, Any]:
        """Plain values."""
        return {axis: {"initial": {"resonance_hz": self.initial[axis][0],
                                   "damping_ratio": self.initial[axis][1]},
                       **est.summary()} for axis, est in self.estimates.items()}


def refine_modes(recordings: Mapping[str, xr.Dataset], *, sercalo: SercaloIdentification,
                 trims_s: Mapping[str, float]) -> ModeRefinement:
    """Re-estimate each axis's mode from its record, starting from the rational fit."""
    fit_modes = sercalo.fit.modes()
    if not fit_modes:
        raise ValueError("the Sercalo fit has no complex mode to refine")
    estimates: dict[str, ModalEstimate] = {}
    initial: dict[str, tuple[float, float]] = {}
    for axis, experiment, signal, output in _AXES:
        target = sercalo.resonances_hz[signal]
        start = fit_modes[int(np.argmin([abs(m.resonance_hz - target) for m in fit_modes]))]
        ds = trim_recording(recordings[experiment], t0_s=trims_s.get(experiment, 0.0))
        guess = (float(start.resonance_hz), float(max(start.damping_ratio, 1e-5)))
        initial[axis] = guess
        estimates[axis] = estimate_modes(
            np.asarray(ds[signal].values, dtype=float),
            np.asarray(ds[output].values, dtype=float), fs_hz=float(ds.attrs["fs_hz"]),
            input_names=[signal], output_names=[output], initial=[guess])
    return ModeRefinement(estimates=estimates, initial=initial)
