"""Closed-loop verification of the ESRF study's controllers on the bench's plants."""

from __future__ import annotations

import control as ct
import numpy as np
import pytest

from fsmbench.bench.blocks import PlantModel
from fsmbench.bench.esrf import esrf_decentralised_controller, newport_controller, tustin
from fsmbench.bench.params import Bench
from fsmbench.control.analysis import ControlObjective, control_objective
from fsmbench.control.design import perturbed_plants
from fsmbench.control.freq import evaluate_ss
from fsmbench.control.loops import (
    LoopAnalysis,
    analyse_loop,
    closed_loop_poles,
    delayed_subsystem,
    discrete_axis_margins,
    newport_to_beam,
)


@pytest.fixture(scope="module")
def objective(bench: Bench) -> ControlObjective:
    return control_objective(bench.nominal)


@pytest.fixture(scope="module")
def seed_on_true(true_plant: PlantModel, objective: ControlObjective) -> LoopAnalysis:
    return analyse_loop(true_plant, esrf_decentralised_controller(), objective=objective,
                        name="seed")


def test_feedback_identities(seed_on_true: LoopAnalysis) -> None:
    la = seed_on_true
    eye = np.broadcast_to(np.eye(2), la.sensitivity.shape)
    # S + T = I and S (I + L) = I: one 2x2 inversion per frequency, rounding only.
    assert la.identity_error < 1e-12
    np.testing.assert_allclose(la.sensitivity @ (eye + la.loop), eye, atol=1e-12)
    np.testing.assert_allclose(la.sensitivity + la.complementary, eye, atol=1e-12)


def test_modulus_margin_is_inverse_peak_sensitivity(seed_on_true: LoopAnalysis) -> None:
    la = seed_on_true
    for i, axis in enumerate("hv"):
        peak = np.max(np.abs(1 / (1 + la.loop[:, i, i])))
        mm = la.axes[axis].margins.modulus_margin
        # The refined minimum sits between grid points: at most 1e-3 deeper (100/decade).
        assert mm <= 1 / peak + 1e-12
        assert mm == pytest.approx(1 / peak, rel=1e-3)


def test_seed_loops_on_the_true_plant(seed_on_true: LoopAnalysis) -> None:
    la = seed_on_true
    assert la.stable and la.nyquist.stable
    for axis in "hv":
        ax = la.axes[axis]
        assert ax.stable
        assert 20.0 < ax.margins.crossover_hz < 35.0  # as tests/control/test_seed.py finds
        assert ax.margins.gain_margin_db > 6.0
        # |S(1 Hz)| = 1/|1 + L|: the seed's loops do not reach 6.1's 2e-4.
        assert ax.sensitivity_at_f0 == pytest.approx(1 / abs(1 + ax.loop_gain_at_f0), rel=0.01)
        assert not ax.meets_objective
    assert not la.meets_objective
    js = la.to_json()
    assert set(js["h"]) >= {"stable", "gain_margin_db", "phase_margin_deg", "modulus_margin",
                            "crossover_hz", "sensitivity_at_1hz"}


def test_closed_loop_poles_match_python_control(true_plant: PlantModel) -> None:
    k = esrf_decentralised_controller()
    g = delayed_subsystem(true_plant, outputs=["Rh", "Rv"], inputs=["Uch", "Ucv"])
    ref = ct.feedback(g, k, sign=-1).poles()
    ours = closed_loop_poles(true_plant, k)
    # Same matrix up to state order; eigenvalues of a 40-state system agree to ~1e-9.
    np.testing.assert_allclose(np.sort_complex(ours), np.sort_complex(ref), rtol=1e-7, atol=1e-6)


class _PadePlant:
    """A plant whose rational path (delays as Padé) is ``g``: what closed_loop_poles reads."""

    def __init__(self, g: ct.StateSpace) -> None:
        self.g = g

    def with_pade(self, *, order: int) -> ct.StateSpace:
        return self.g


def test_closed_loop_poles_with_feedthrough_on_both_sides(true_plant: PlantModel) -> None:
    # A retune runs a controller read back from its SOS file (biproper) on a plant whose
    # Padé paths pass some of each command straight through: a well-posed loop (I + Dk Dg
    # invertible) that was refused as "algebraic". python-control closes it independently.
    g0 = delayed_subsystem(true_plant, outputs=["Rh", "Rv"], inputs=["Uch", "Ucv"])
    d_g = np.array([[2e-3, 1e-4], [-1e-4, 3e-3]])
    g = ct.ss(g0.A, g0.B, g0.C, d_g, inputs=["Uch", "Ucv"], outputs=["Rh", "Rv"])
    k0 = esrf_decentralised_controller()
    k = ct.ss(k0.A, k0.B, k0.C, np.asarray(k0.D) + 50.0 * np.eye(2),
              inputs=list(k0.input_labels), outputs=list(k0.output_labels))
    ours = closed_loop_poles(_PadePlant(g), k)  # type: ignore[arg-type]
    ref = ct.feedback(g, k, sign=-1).poles()
    np.testing.assert_allclose(np.sort_complex(ours), np.sort_complex(ref), rtol=1e-7, atol=1e-6)
    # Feedthrough that cancels (Dk Dg = -I) is refused: the loop is not well posed.
    k_bad = ct.ss(k0.A, k0.B, k0.C, -np.linalg.inv(d_g),
                  inputs=list(k0.input_labels), outputs=list(k0.output_labels))
    with pytest.raises(ValueError, match="not well posed"):
        closed_loop_poles(_PadePlant(g), k_bad)  # type: ignore[arg-type]


@pytest.mark.parametrize(("label", "unstable"), [("f×1 ξ×1", 0), ("f×1.05 ξ×1", 2),
                                                 ("f×1.05 ξ×0.5", 2), ("f×0.95 ξ×0.5", 0)],
                         ids=["unperturbed", "f+5%", "f+5%_xi/2", "f-5%_xi/2"])
def test_nyquist_count_agrees_with_closed_loop_poles(nominal_plant: PlantModel,
                                                     objective: ControlObjective,
                                                     label: str, unstable: int) -> None:
    """The study's notch leaves the nominal plant's mode 5 % up unstable; both methods agree."""
    plant = dict(perturbed_plants(nominal_plant))[label]
    la = analyse_loop(plant, esrf_decentralised_controller(), objective=objective)
    assert int(np.sum(la.poles.real > 0)) == la.nyquist.closed_loop_unstable == unstable


def test_tustin_is_the_warped_continuous_controller() -> None:
    """Kd(e^{jwT}) = K(j (2/T) tan(wT/2)) exactly; the notch moves down accordingly."""
    k = esrf_decentralised_controller()
    ts = 1e-4
    kd = tustin(k, ts_s=ts)
    f = np.logspace(-1, 3, 200)
    disc = evaluate_ss(kd, np.exp(2j * np.pi * f * ts))
    warped = evaluate_ss(k, 2j / ts * np.tan(np.pi * f * ts))
    # Two evaluations of the same rational function: rounding, amplified near the notch.
    np.testing.assert_allclose(disc, warped, rtol=1e-8, atol=1e-12 * np.max(np.abs(warped)))


def test_discrete_comparison_reports_the_notch_shift(true_plant: PlantModel,
                                                     objective: ControlObjective,
                                                     seed_on_true: LoopAnalysis) -> None:
    d = seed_on_true.discrete
    assert d is not None
    shifts = dict(d.notch_shifts_hz)
    f_h = np.sqrt(6.686e6 - (15.93 / 2) ** 2) / (2 * np.pi)  # damped frequency of the h notch
    f_d = shifts[min(shifts, key=lambda x: abs(x - f_h))]
    assert f_d == pytest.approx(np.arctan(np.pi * f_h * 1e-4) / (np.pi * 1e-4), rel=1e-12)
    assert f_h - f_d == pytest.approx(2.3, abs=0.1)  # 0.56 % lower: the seed's Kd misses 411.5 Hz
    for axis in "hv":  # below the crossover Tustin changes nothing that matters
        c, dm = seed_on_true.axes[axis].margins, d.margins[axis]
        # At ~30 Hz the warp is 3e-5: the phase margin moves by < 0.01°.
        assert dm.phase_margin_deg == pytest.approx(c.phase_margin_deg, abs=0.01)
        assert dm.crossover_hz == pytest.approx(c.crossover_hz, rel=1e-3)


def test_newport_loop_of_10_2(true_plant: PlantModel, objective: ControlObjective) -> None:
    gn0 = np.real(evaluate_ss(true_plant.subsystem(outputs=["Rh", "Rv"], inputs=["Unh", "Unv"]),
                              np.zeros(1))[0])
    kn = newport_controller(gn0_rad_per_v=(gn0[0, 0], gn0[1, 1]))
    la = analyse_loop(true_plant, kn, objective=objective, name="newport")
    assert la.stable and la.nyquist.stable and la.meets_margins
    for axis in "hv":
        # Crossover at 10 Hz by construction (1/Gn0 and a lead centred on w0); the
        # plant's 0.5 ms delay and 2nd order only perturb it by < 1 %.
        assert la.axes[axis].margins.crossover_hz == pytest.approx(10.0, rel=0.01)
        assert la.axes[axis].margins.phase_margin_deg > 30.0


def test_newport_to_beam(true_plant: PlantModel) -> None:
    f = np.array([0.5, 1.0, 50.0])
    k = esrf_decentralised_controller()
    open_ = newport_to_beam(true_plant, None, f)
    ref = true_plant.frequency_response(f, outputs=["Rh", "Rv"], inputs=["Unh", "Unv"]).values
    np.testing.assert_allclose(open_, ref, rtol=1e-12)  # same evaluation
    closed = newport_to_beam(true_plant, k, f)
    s = 2j * np.pi * f
    g = true_plant.frequency_response(f, outputs=["Rh", "Rv"], inputs=["Uch", "Ucv"]).values
    lmat = g @ evaluate_ss(k, s)
    np.testing.assert_allclose((np.eye(2)[None] + lmat) @ closed, open_, rtol=1e-9,
                               atol=1e-15)  # (I + L) S Gn = Gn
    assert np.all(np.abs(closed[:2, 0, 0]) < 0.01 * np.abs(open_[:2, 0, 0]))  # rejected at 1 Hz


def test_discrete_axis_margins_are_the_study_s_and_scale_with_the_loop(
        true_plant: PlantModel, seed_on_true: LoopAnalysis) -> None:
    """The margins the live device checks a controller with are the design study's discrete
    ones; a 4QD gain twice the one divided by doubles the loop: 6.02 dB less gain margin."""
    assert seed_on_true.discrete is not None
    kd = seed_on_true.discrete.kd
    abcd = {x: np.asarray(getattr(kd, x.upper()), dtype=float) for x in "abcd"}
    one = discrete_axis_margins(true_plant, **abcd, ts_s=float(kd.dt))
    two = discrete_axis_margins(true_plant, **abcd, ts_s=float(kd.dt), loop_scale=(2.0, 2.0))
    for axis in ("h", "v"):
        ref = seed_on_true.discrete.margins[axis]
        # The same loop on grids refined alike: root-finding tolerance (1e-12 relative).
        assert one[axis].gain_margin_db == pytest.approx(ref.gain_margin_db, rel=1e-6)
        assert one[axis].modulus_margin == pytest.approx(ref.modulus_margin, rel=1e-6)
        # A pure gain moves the phase crossing nowhere: exactly 20 log10(2) dB.
        assert one[axis].gain_margin_db - two[axis].gain_margin_db == pytest.approx(
            20 * np.log10(2.0), abs=1e-6)
