"""The identified model's Bode with an uncertainty band from its parameters' stds
(MATLAB's ``bode(sys, 'sd', 3)``).

Every identified parameter the bench model is built from comes with its total standard
deviation (:mod:`fsmbench.ident.totals`, as bench-file keys by
:func:`fsmbench.ident.evidence.departures.measured_keys`). The plant is rebuilt from the
bench file that matches the records (:func:`fsmbench.bench.blocks.physical_plant` of
``Identification.matching``) with each parameter moved by ±1 std in turn, and the
response's sensitivity to it taken as the central difference

    δH_k(f) = (H(p + σ_k e_k) − H(p − σ_k e_k)) / 2,

a first-order propagation, as MATLAB's ``bode(sys, 'sd')`` does from the covariance,
with the parameters taken independent (no covariance is carried between them): the std
of the magnitude is ``sqrt(Σ_k (δ|H|_k)²)`` and of the phase ``sqrt(Σ_k (δ∠H_k)²)``. The
relative std of the magnitude so found is laid on the identified model's own response
(the vector fit's for the Sercalo): the band is ``|H| (1 ± n σ_|H|/|H|)`` and
``∠H ± n σ_∠``. At DC, where ``|H(0)|`` is a product of gains, the band's half-width is
the static gain's std.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from fsmbench.bench.blocks import PlantModel, physical_plant
from fsmbench.bench.params import BenchParams
from fsmbench.ident.evidence.departures import MeasuredKey, set_key

__all__ = ["BAND_PATHS", "ModelBand", "PathBand", "model_band"]

#: The paths drawn: (input, output), the direct ones of each actuator.
BAND_PATHS: tuple[tuple[str, str], ...] = (("Uch", "Vph"), ("Ucv", "Vpv"), ("Unh", "Vph"),
                                           ("Unv", "Vpv"))


@dataclass(frozen=True, eq=False)
class PathBand:
    """One path's response with its std.

    Attributes
    ----------
    input, output : str
    magnitude_v_per_v, magnitude_std_v_per_v : numpy.ndarray
        |H| of the identified model and its one-sigma std, per frequency [V/V].
    phase_deg, phase_std_deg : numpy.ndarray
        Unwrapped phase of the identified model and its one-sigma std [deg].
    """

    input: str
    output: str
    magnitude_v_per_v: np.ndarray
    magnitude_std_v_per_v: np.ndarray
    phase_deg: np.ndarray
    phase_std_deg: np.ndarray


@dataclass(frozen=True, eq=False)
class ModelBand:
    """The identified model's response on its main paths with their stds.

    Attributes
    ----------
    f_hz : numpy.ndarray
        Frequencies [Hz].
    paths : tuple of PathBand
    keys : tuple of str
        The parameters (bench-file keys) with a non-zero std that were propagated.
    stds : tuple of float
        Their stds, in each key's unit.
    n_sigma : float
        How many stds the report's band spans on each side (MATLAB's ``'sd', 3``).
    """

    f_hz: np.ndarray
    paths: tuple[PathBand, ...]
    keys: tuple[str, ...]
    stds: tuple[float, ...]
    n_sigma: float = 3.0

    def path(self, input: str, output: str) -> PathBand:
        """The band of ``input → output``."""
        for p in self.paths:
            if p.input == input and p.output == output:
                return p
        raise KeyError(f"no band for {input} → {output}")

    def to_json(self) -> dict[str, Any]:
        """The propagated parameters and, per path, the band's largest relative width."""
        return {"keys": list(self.keys), "stds": [float(s) for s in self.stds],
                "n_sigma": float(self.n_sigma),
                "max_relative_magnitude_std": {
                    f"{p.input}_to_{p.output}": float(np.nanmax(
                        p.magnitude_std_v_per_v / np.maximum(p.magnitude_v_per_v, 1e-300)))
                    for p in self.paths}}


def _responses(plant: PlantModel, f_hz: np.ndarray,
               paths: Sequence[tuple[str, str]]) -> np.ndarray:
    """(n_paths, nf) complex responses with the delays."""
    ins = sorted({i for i, _ in paths})
    outs = sorted({o for _, o in paths})
    h = plant.frequency_response(f_hz, outputs=outs, inputs=ins).values
    return np.array([h[:, outs.index(o), ins.index(i)] for i, o in paths])


def model_band(plant: PlantModel, *, params: BenchParams, measured: Sequence[MeasuredKey],
               f_hz: np.ndarray, paths: Sequence[tuple[str, str]] = BAND_PATHS,
               n_sigma: float = 3.0) -> ModelBand:
    """The identified model's response on ``paths`` with its first-order std.

    Parameters
    ----------
    plant : PlantModel
        The identified model: the band's centre.
    params : BenchParams
        The bench parameters that match the records (``Identification.matching.nominal``):
        the parametric model the sensitivities are taken on.
    measured : sequence of MeasuredKey
        The identified parameters with their total stds (keys of ``params``).
    f_hz : array
        Frequencies [Hz].
    paths : sequence of (input, output)
    n_sigma : float
        Stds each side of the band the report draws.
    """
    f = np.asarray(f_hz, dtype=float).ravel()
    centre = _responses(plant, f, paths)
    base = _responses(physical_plant(params), f, paths)
    var_rel = np.zeros(centre.shape)
    var_phase = np.zeros(centre.shape)
    keys, stds = [], []
    for m in measured:
        if not (np.isfinite(m.std) and m.std > 0 and np.isfinite(m.value)):
            continue
        up = _responses(physical_plant(set_key(params, m.key, m.value + m.std)), f, paths)
        down = _responses(physical_plant(set_key(params, m.key, m.value - m.std)), f, paths)
        with np.errstate(divide="ignore", invalid="ignore"):
            var_rel += ((np.abs(up) - np.abs(down)) / (2 * np.abs(base))) ** 2
            # The phase's change, each side taken against the centre (no unwrapping across).
            d_phase = 0.5 * (np.angle(up / base) - np.angle(down / base))
        var_phase += np.degrees(d_phase) ** 2
        keys.append(m.key)
        stds.append(float(m.std))
    mag = np.abs(centre)
    phase = np.degrees(np.unwrap(np.angle(centre), axis=1))
    bands = tuple(PathBand(input=i, output=o, magnitude_v_per_v=mag[k],
                           magnitude_std_v_per_v=mag[k] * np.sqrt(var_rel[k]),
                           phase_deg=phase[k], phase_std_deg=np.sqrt(var_phase[k]))
                  for k, (i, o) in enumerate(paths))
    return ModelBand(f_hz=f, paths=bands, keys=tuple(keys), stds=tuple(stds),
                     n_sigma=float(n_sigma))
