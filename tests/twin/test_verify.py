"""A controller on the twin against the linear prediction from model and noise budget."""

from __future__ import annotations

import dataclasses

import control as ct
import pytest

from fsmbench.bench.blocks import PlantModel, replace_params
from fsmbench.bench.esrf import esrf_decentralised_controller
from fsmbench.bench.params import Bench, PerAxis
from fsmbench.twin.verify import predict_tracking, verify_on_twin


def test_seed_controller_on_the_twin_matches_the_prediction(bench: Bench,
                                                            true_plant: PlantModel) -> None:
    check = verify_on_twin(esrf_decentralised_controller(), bench=bench, plant=true_plant,
                           name="seed", duration_s=8.0)
    for axis in "hv":
        # Issue target: the twin agrees with the linear prediction within 20 %.
        assert 0.8 < check.ratio[axis] < 1.2, check.to_json()


def test_prediction_terms_scale_as_their_sources(bench: Bench, true_plant: PlantModel) -> None:
    k = esrf_decentralised_controller()
    _, parts = predict_tracking(true_plant, k, bench=bench, n_freq=4000)
    q = bench.true.quad_diode.noise_rms_v
    louder = dataclasses.replace(bench, true=replace_params(
        bench.true, quad_diode={"noise_rms_v": PerAxis(h=3 * q.h, v=3 * q.v)}))
    _, parts3 = predict_tracking(true_plant, k, bench=louder, n_freq=4000)
    # Each white source enters linearly: 3x the 4QD noise, 3x its term, nothing else moves.
    for axis in "hv":
        assert parts3[axis]["qd_noise"] == pytest.approx(3 * parts[axis]["qd_noise"], rel=1e-12)
        assert parts3[axis]["newport_sine"] == parts[axis]["newport_sine"]


def test_a_destabilising_controller_is_refused(bench: Bench, true_plant: PlantModel) -> None:
    k = esrf_decentralised_controller()
    bad = ct.ss(k.A, k.B, -k.C, -k.D, inputs=k.input_labels, outputs=k.output_labels)
    with pytest.raises(ValueError, match="does not stabilise"):
        verify_on_twin(bad, bench=bench, plant=true_plant, name="bad", duration_s=5.0)
