"""Integral force feedback (ESRF study 8): why it cannot damp this bench, and that it can damp a
plant whose coil voltage carries the mirror's back-EMF."""

from __future__ import annotations

import dataclasses

import control as ct
import numpy as np
import pytest

from fsmbench.bench.blocks import PlantModel
from fsmbench.bench.params import Bench
from fsmbench.control.iff import iff_analysis


def _iff(gain: float) -> ct.StateSpace:
    """``blkdiag(-gain/s, 0)``, Vch, Vcv -> Uch, Ucv (added to the command, as the ESRF study's)."""
    return ct.ss([[0.0]], [[1.0, 0.0]], [[-gain], [0.0]], np.zeros((2, 2)),
                 inputs=["Vch", "Vcv"], outputs=["Uch", "Ucv"])


def _with_back_emf(plant: PlantModel, bench: Bench) -> PlantModel:
    """The true plant, delay-free, with a motional voltage ``kappa dtheta_h/dt`` in ``Vt_h``.

    ``kappa = 2 xi Rc / (g0 w0)`` makes the motional voltage at resonance equal to
    ``Rc I``; the sensor path then has zeros at the mode's frequency with twice its
    damping, which IFF drives the poles towards.
    """
    sp, va = bench.true.sercalo, bench.true.voltage_amplifier
    w0 = 2 * np.pi * sp.resonance_hz.h
    kappa = 2 * sp.damping_ratio.h * sp.r_coil_ohm.h / (sp.dc_gain_rad_per_a.h * w0)
    labels = list(plant.sys.state_labels)
    a = np.array(plant.sys.A, dtype=float)
    # d(Vch)/dt = wc (Ga0 Vt - Vch); the mode's second state is dtheta/dt / w0.
    a[labels.index("Ga_Vch"), labels.index("Gc_dtheta_ch")] += (
        2 * np.pi * va.cutoff_hz * va.gain * kappa * w0)
    sys = ct.ss(a, plant.sys.B, plant.sys.C, plant.sys.D, inputs=list(plant.sys.input_labels),
                outputs=list(plant.sys.output_labels), states=labels)
    return dataclasses.replace(plant, sys=sys, source="true + back-EMF, no delay",
                               input_delay_s={k: 0.0 for k in plant.input_delay_s})


def test_iff_cannot_damp_the_bench(true_plant: PlantModel) -> None:
    """Vc = Ga Zc Gi Uc with a static Zc: the modes never reach the sensor (ESRF study 8.3)."""
    r = iff_analysis(true_plant)
    for axis in "hv":
        m = r.modes[axis]
        assert m.sensor_peak_ratio < 1e-9  # unobservable from Vc: rounding only
        # The closed-loop pole is the open-loop one: eigenvalue rounding only.
        assert m.damping_ratio_closed == pytest.approx(m.damping_ratio_open, rel=1e-6)
    assert r.modes["h"].frequency_hz_open == pytest.approx(411.5, rel=1e-9)
    assert r.modes["h"].damping_ratio_open == pytest.approx(1.2e-3, rel=1e-9)
    # -10000/s is far beyond what the sensor loop tolerates (Ga's 1 kHz pole, Gi's
    # inductance and the 0.15 ms delay): unstable, by both methods.
    assert not r.loop_stable and not r.nyquist.stable and not r.loop_stable_without_delay
    assert r.gain_limit["h"] < 100.0
    js = r.to_json()
    assert {"damping_ratio_open", "damping_ratio_closed"} <= set(js["h"])


@pytest.mark.parametrize("gain", [50.0, 300.0])
def test_iff_increases_damping_with_back_emf(true_plant: PlantModel, bench: Bench,
                                             gain: float) -> None:
    plant = _with_back_emf(true_plant, bench)
    r = iff_analysis(plant, controller=_iff(gain))
    h = r.modes["h"]
    assert r.loop_stable and r.nyquist.stable
    assert h.sensor_peak_ratio > 0.5  # the sensor now sees the mode
    # Root locus from the mode's poles to the sensor's zeros (damping 2 xi): at these
    # gains the poles are most of the way there (1.95x and 2.03x measured).
    assert h.damping_ratio_closed > 1.8 * h.damping_ratio_open
    assert h.frequency_hz_closed == pytest.approx(h.frequency_hz_open, rel=1e-3)
    v = r.modes["v"]  # no IFF on the v axis: untouched
    assert v.damping_ratio_closed == pytest.approx(v.damping_ratio_open, rel=1e-6)
