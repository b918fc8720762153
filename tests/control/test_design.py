"""fsmbench's controller: the perturbed set, the design and its verification."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fsmbench.bench.blocks import PlantModel, physical_plant, replace_params
from fsmbench.bench.params import Bench, PerAxis
from fsmbench.control.analysis import ControlObjective, control_objective
from fsmbench.control.design import (
    AxisShape,
    FsmDesign,
    design_controller,
    perturb_modes,
    perturbed_plants,
    phase_travel,
    robustness,
)
from fsmbench.control.freq import evaluate_ss
from fsmbench.control.loops import analyse_loop
from fsmbench.ident.pipeline import identify
from fsmbench.twin import TwinRun


@pytest.fixture(scope="module")
def objective(bench: Bench) -> ControlObjective:
    return control_objective(bench.nominal)


@pytest.fixture(scope="module")
def design_nominal(nominal_plant: PlantModel, objective: ControlObjective) -> FsmDesign:
    return design_controller(nominal_plant, objective=objective)


@pytest.fixture(scope="module")
def design_true(true_plant: PlantModel, objective: ControlObjective) -> FsmDesign:
    return design_controller(true_plant, objective=objective)


def _beam(plant: PlantModel, f: np.ndarray) -> np.ndarray:
    return plant.frequency_response(f, outputs=["Rh", "Rv"], inputs=["Uch", "Ucv"]).values


@pytest.mark.parametrize(("fs", "ds"), [(1.05, 1.0), (0.95, 0.5), (1.0, 2.0)])
def test_modal_perturbation_matches_the_physical_parameters(bench: Bench, true_plant: PlantModel,
                                                            fs: float, ds: float) -> None:
    sp = bench.true.sercalo
    params = replace_params(bench.true, sercalo={
        "resonance_hz": PerAxis(h=sp.resonance_hz.h * fs, v=sp.resonance_hz.v * fs),
        "damping_ratio": PerAxis(h=sp.damping_ratio.h * ds, v=sp.damping_ratio.v * ds)})
    ref = physical_plant(params)
    ours = dict(perturbed_plants(true_plant, frequency_scales=(fs,),
                                 damping_scales=(ds,)))[f"f×{fs:g} ξ×{ds:g}"]
    f = np.concatenate([np.logspace(-1, 3, 200), np.linspace(230, 440, 4000)])
    a, b = _beam(ref, f), _beam(ours, f)
    # Frequency scaling is exact (same stiffness/mass ratio); a damping change keeps
    # r/λ instead of g0 w0²: the residues differ by O(ξ) = 1e-3 of the peak.
    tol = 1e-10 if ds == 1.0 else 3e-3
    assert np.max(np.abs(a - b)) <= tol * np.max(np.abs(a))


def test_identity_perturbation(true_plant: PlantModel) -> None:
    gc = true_plant.blocks["Gc"]
    same = perturb_modes(gc)
    s = 2j * np.pi * np.array([1.0, 411.0, 411.5, 2000.0])
    # A similarity transform to modal form: rounding only.
    np.testing.assert_allclose(evaluate_ss(same, s), evaluate_ss(gc, s), rtol=1e-9, atol=1e-12)


def test_shape_realisation_matches_its_formula() -> None:
    shape = AxisShape(crossover_hz=35.0, integrator_hz=7.0, extra_integrators=3, lead_hz=45.0,
                      lead_ratio=1.6, lowpass_hz=200.0, lowpass_damping=0.8, gain=-4000.0)
    k = shape.realise(input_name="Rh", output_name="Uch")
    s = 2j * np.pi * np.logspace(-1, 3.5, 50)
    # Cascade realisation vs the product of factors: rounding only.
    np.testing.assert_allclose(evaluate_ss(k, s)[:, 0, 0], shape.response(s), rtol=1e-9)
    assert k.nstates == 7


@pytest.mark.parametrize("which", ["nominal", "true"])
def test_design_meets_the_requirements_on_its_plant(which: str, request,
                                                    objective: ControlObjective) -> None:
    plant: PlantModel = request.getfixturevalue(f"{which}_plant")
    design: FsmDesign = request.getfixturevalue(f"design_{which}")
    assert all(score > 0 for score in design.scores.values())  # every slack positive
    la = analyse_loop(plant, design.controller, objective=objective)
    assert la.stable and la.nyquist.stable
    assert la.meets_objective and la.meets_margins
    for axis in "hv":
        ax = la.axes[axis]
        assert ax.margins.gain_margin_db >= 6.0
        assert ax.margins.phase_margin_deg >= 30.0
        assert ax.sensitivity_at_f0 < objective.sensitivity_bound
        assert ax.margins.gain_reduction_margin_db >= 6.0  # conditionally stable: room down too


@pytest.mark.parametrize("which", ["nominal", "true"])
def test_design_is_robust_over_the_perturbed_set(which: str, request,
                                                 objective: ControlObjective) -> None:
    plant: PlantModel = request.getfixturevalue(f"{which}_plant")
    design: FsmDesign = request.getfixturevalue(f"design_{which}")
    rob = robustness(plant, design.controller, objective=objective)
    assert len(rob.labels) == 9
    assert rob.all_stable
    assert rob.worst_gain_margin_db >= 6.0 and rob.worst_phase_margin_deg >= 30.0
    assert rob.worst_modulus_margin >= 0.4
    js = rob.to_json()
    assert js["worst_gain_margin_db"] == pytest.approx(rob.worst_gain_margin_db)


def test_design_on_the_truth_is_stable_on_the_nominal_model(nominal_plant: PlantModel,
                                                            design_true: FsmDesign,
                                                            objective: ControlObjective) -> None:
    """The true plant's gain is 0.65x the nominal one: the loop survives +3.7 dB."""
    la = analyse_loop(nominal_plant, design_true.controller, objective=objective)
    assert la.stable and la.nyquist.stable and la.meets_objective


def test_tustin_controller_below_1khz(true_plant: PlantModel, design_true: FsmDesign,
                                      objective: ControlObjective) -> None:
    k = design_true.controller
    la = analyse_loop(true_plant, k, objective=objective)
    d = la.discrete
    assert d is not None
    f = np.logspace(-1, 3, 300)
    ts = d.ts_s
    kc = evaluate_ss(k, 2j * np.pi * f)
    kz = evaluate_ss(d.kd, np.exp(2j * np.pi * f * ts))
    warp = np.log(np.tan(np.pi * f * ts) / (np.pi * f * ts))
    for i in range(2):
        # Kd(e^{jwT}) = K(jw (1 + warp)): relative change = complex log-slope x warp to
        # first order; 1.2 covers the second-order term (slope x warp <= 0.15 here).
        h = 1e-4
        slope = (np.log(evaluate_ss(k, 2j * np.pi * f * np.exp(h))[:, i, i])
                 - np.log(evaluate_ss(k, 2j * np.pi * f * np.exp(-h))[:, i, i])) / (2 * h)
        rel = np.abs(kz[:, i, i] / kc[:, i, i] - 1)
        assert np.all(rel <= 1.2 * np.abs(slope) * warp + 1e-9)
        c, dm = la.axes["hv"[i]].margins, d.margins["hv"[i]]
        # Crossovers (35 Hz) and phase crossovers (130-180 Hz) see a warp < 0.1 %.
        assert dm.gain_margin_db == pytest.approx(c.gain_margin_db, abs=0.1)
        assert dm.phase_margin_deg == pytest.approx(c.phase_margin_deg, abs=0.1)
    assert d.max_relative_error < 0.15  # < 4.5 x the 3.4 % warp at 1 kHz


@pytest.fixture(scope="module")
def identified_plant(ident_twin: TwinRun, bench: Bench) -> PlantModel:
    plant = identify(ident_twin.recordings, bench=bench, source="twin").plant
    assert plant is not None
    return plant


def test_perturbation_of_an_identified_plant(identified_plant: PlantModel) -> None:
    """Vector fitting shares each pole between the inputs: repeated eigenvalues, still moved."""
    base = identified_plant.blocks["Gc"].poles()
    up = dict(perturbed_plants(identified_plant, frequency_scales=(1.05,),
                               damping_scales=(2.0,)))["f×1.05 ξ×2"].blocks["Gc"].poles()
    light = np.sort(np.abs(base[base.imag > 0]))
    moved = np.sort(np.abs(up[up.imag > 0]))
    np.testing.assert_allclose(moved, 1.05 * light, rtol=1e-9)  # eigenvalue rounding only
    zeta = np.sort(-up.real / np.abs(up))
    np.testing.assert_allclose(zeta, np.sort(-2 * base.real / np.abs(base)), rtol=1e-6)


def test_design_on_the_identified_plant_holds_on_the_truth(identified_plant: PlantModel,
                                                           true_plant: PlantModel,
                                                           objective: ControlObjective) -> None:
    """The intended flow: identify on the twin, design on the model, run on the truth."""
    design = design_controller(identified_plant, objective=objective)
    la = analyse_loop(true_plant, design.controller, objective=objective)
    assert la.stable and la.nyquist.stable
    assert la.meets_objective and la.meets_margins


@settings(max_examples=60, deadline=None)
@given(st.integers(min_value=1, max_value=12), st.integers(min_value=2, max_value=2000),
       st.integers(min_value=0, max_value=2**32 - 1))
def test_the_phase_travel_is_unwrap_s_without_the_unwrapped_rows(rows: int, points: int,
                                                                 seed: int) -> None:
    """The design counts half-turns of 1 + L from the phase's travel: numpy's unwrap is the
    reference, on smooth loops (few wraps) and on noise (a wrap at most points)."""
    rng = np.random.default_rng(seed)
    w = np.logspace(-2, 4, points)
    smooth = np.angle(1.0 - rng.uniform(0.1, 1e3, (rows, 1))
                      / (1j * w / rng.uniform(1.0, 500.0, (rows, 1)) + 1.0) ** 3)
    noise = np.angle(rng.standard_normal((rows, points))
                     + 1j * rng.standard_normal((rows, points)))
    for angle in (smooth, noise):
        ref = np.unwrap(angle, axis=1)
        travel = phase_travel(angle)
        # The same steps summed in another order: round-off of ~points × eps × π.
        np.testing.assert_allclose(travel, ref[:, -1] - ref[:, 0], rtol=0, atol=1e-11)
        np.testing.assert_array_equal(np.rint(travel / np.pi),
                                      np.rint((ref[:, -1] - ref[:, 0]) / np.pi))
