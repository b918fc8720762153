"""The plant of an identified bench, in the form the simulation engine steps.

A packaged bench is simulated from physics (:func:`fsmbench.sim.plant.twin_continuous`
of its ``[true]`` parameters). An identified bench is simulated from what an
identification found: the blocks ``Gi, Zc, Ga, Gc, Gn, Gd`` of ``plant.mat``
with their input delays. :func:`engine_model` wires them into the engine's
signals (inputs ``Uch, Ucv, Unh, Unv``; outputs the six ADC channels and the
six internal angles):

- ``Ich, Icv = Gi Uc``; ``Vch, Vcv = Ga Zc Ic``;
- ``Vph, Vpv = Gc Ic + Gn Un`` (the 4QD's response, including whatever
  cross-coupling and modes the identification resolved);
- ``Rh, Rv = Gd⁻¹ (Vph, Vpv)``;
- the mirror angles from the beam angles through the bench file's optics
  (assumed: no recording measures a mirror angle):
  ``theta_c = (Gd Sc)⁻¹ Gc Ic``, ``theta_n = (Gd Sn)⁻¹ Gn Un``;
- ``Vnh, Vnv = theta_n / gn0`` (the Newport's metrology gain, bench file).

The identified delays are *effective*: they hold the converter's half-sample
hold (an identification sees a zero-order hold as half a sample of delay)
and the 4QD amplifier's lag. The engine applies its own hold, so each input's
delay before the hold is the identified one less half a sample.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import control as ct
import numpy as np

from fsmbench.bench.blocks import PlantModel, newport_beam_matrix, sercalo_beam_matrix
from fsmbench.bench.params import BenchParams

__all__ = ["DAC_INPUTS", "ENGINE_OUTPUTS", "IdentifiedModel", "engine_model"]

DAC_INPUTS = ("Uch", "Ucv", "Unh", "Unv")
ENGINE_OUTPUTS = ("Vch", "Vcv", "Vph", "Vpv", "Vnh", "Vnv",
                  "theta_ch", "theta_cv", "theta_nh", "theta_nv", "Rh", "Rv")


@dataclass(frozen=True, eq=False)
class IdentifiedModel:
    """An identified bench's plant as the engine runs it, and where it comes from.

    Attributes
    ----------
    a, b, c, d : arrays (n, n), (n, 4), (12, n), (12, 4)
        Continuous plant, inputs :data:`DAC_INPUTS` [V], outputs
        :data:`ENGINE_OUTPUTS` (volts for the ADC channels, radians for the angles).
    input_delay_samples : tuple of 4 floats
        Delay of each input before the converter's hold [samples].
    plant : PlantModel
        The identified plant (``plant.mat``) it was built from.
    folder : str
        The identification folder.
    values : mapping
        The identification's contracted values (``identification.json``'s
        ``qd_gain_v_per_rad``, ``sercalo`` …), what a simulation of this bench
        is the truth of.
    provenance : mapping of str to str
        Each simulated quantity → where it comes from, in words ("measured:
        data_uch, data_ucv" or "assumed: bench file").
    noise_fit : mapping
        The noise model fitted to the recordings (JSON), empty when none was.
    label : str
        The bench in words; default "the bench identified in FOLDER".
    """

    a: np.ndarray
    b: np.ndarray
    c: np.ndarray
    d: np.ndarray
    input_delay_samples: tuple[float, ...]
    plant: PlantModel
    folder: str
    values: Mapping[str, Any] = field(default_factory=dict)
    provenance: Mapping[str, str] = field(default_factory=dict)
    noise_fit: Mapping[str, Any] = field(default_factory=dict)
    label: str = ""


def _block(plant: PlantModel, name: str) -> ct.StateSpace:
    return plant.blocks[name]


def engine_model(plant: PlantModel, *, params: BenchParams
                 ) -> tuple[ct.StateSpace, tuple[float, ...]]:
    """The identified plant wired into the engine's signals (see the module notes).

    Parameters
    ----------
    plant : PlantModel
        Identified blocks ``Gi, Zc, Ga, Gc, Gn, Gd`` and input delays [s].
    params : BenchParams
        The bench file's values for what no recording measures: the optics
        (beam matrices), the Newport's metrology gain and the converter rate.

    Returns
    -------
    sys : control.StateSpace
        Inputs :data:`DAC_INPUTS`, outputs :data:`ENGINE_OUTPUTS`.
    delays : tuple of 4 floats
        Each input's delay before the hold [samples], ≥ 0.

    Raises
    ------
    ValueError
        A block is missing, or ``Gd`` is singular.
    """
    missing = [n for n in ("Gi", "Zc", "Ga", "Gc", "Gn", "Gd") if n not in plant.blocks]
    if missing:
        raise ValueError(f"the identified plant lacks the block(s) {', '.join(missing)}")
    gd = np.asarray(_block(plant, "Gd").D, dtype=float)
    if abs(np.linalg.det(gd)) == 0.0:
        raise ValueError("the identified 4QD gain Gd is singular")
    gd_inv = np.linalg.inv(gd)
    sc_inv = np.linalg.inv(gd @ sercalo_beam_matrix(params))
    sn_inv = np.linalg.inv(gd @ newport_beam_matrix(params))
    gn0 = params.newport.metrology_gain_rad_per_v

    def static(m: np.ndarray, inputs: list[str], outputs: list[str], name: str) -> ct.StateSpace:
        return ct.ss([], [], [], m, inputs=inputs, outputs=outputs, name=name)

    gc = _block(plant, "Gc")
    gn = _block(plant, "Gn")
    # Two copies of Gc and Gn: one feeds the 4QD sum, the other the mirror angles, so
    # each angle is only its own mirror's share.
    parts = [
        _block(plant, "Gi"), _block(plant, "Zc"), _block(plant, "Ga"), gc, gn,
        ct.summing_junction(inputs=["Vpch", "Vpnh"], output="Vph", name="Sh"),
        ct.summing_junction(inputs=["Vpcv", "Vpnv"], output="Vpv", name="Sv"),
        static(gd_inv, ["Vph", "Vpv"], ["Rh", "Rv"], "Gd_inv"),
        static(sc_inv, ["Vpch", "Vpcv"], ["theta_ch", "theta_cv"], "Sc_inv"),
        static(sn_inv, ["Vpnh", "Vpnv"], ["theta_nh", "theta_nv"], "Sn_inv"),
        static(np.eye(2) / gn0, ["theta_nh", "theta_nv"], ["Vnh", "Vnv"], "metrology"),
    ]
    sys = ct.interconnect(parts, inplist=list(DAC_INPUTS), outlist=list(ENGINE_OUTPUTS),
                          inputs=list(DAC_INPUTS), outputs=list(ENGINE_OUTPUTS),
                          name="identified")
    ts = params.converter.ts_s
    delays = []
    for name in DAC_INPUTS:
        # The identification's delay holds the hold's half sample; the engine adds its own.
        tau = float(plant.input_delay_s.get(name, 0.0)) / ts - 0.5
        delays.append(max(0.0, tau))
    return (ct.ss(sys.A, sys.B, sys.C, sys.D, inputs=list(DAC_INPUTS),
                  outputs=list(ENGINE_OUTPUTS), name="identified"), tuple(delays))
