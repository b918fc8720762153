"""Shared fixtures of the live-bench tests: fsmbench's controller, and 20 times it."""

from __future__ import annotations

from pathlib import Path

import control as ct
import numpy as np
import pytest

from fsmbench.bench.blocks import physical_plant
from fsmbench.bench.params import Bench
from fsmbench.control.analysis import control_objective
from fsmbench.control.design import design_controller
from fsmbench.control.export import InputScaling, write_sos_json


@pytest.fixture(scope="session")
def fsmbench_controller(bench: Bench) -> ct.StateSpace:
    """fsmbench's own controller designed on the true physical plant (inputs Rh, Rv)."""
    d = design_controller(physical_plant(bench.true, source="physical"),
                          objective=control_objective(bench.nominal))
    return d.controller


@pytest.fixture(scope="session")
def controller_x20(bench: Bench, fsmbench_controller: ct.StateSpace,
                   tmp_path_factory: pytest.TempPathFactory) -> Path:
    """``controllers_sos.json`` holding fsmbench's controller with 20 times its gain."""
    k = fsmbench_controller
    k20 = ct.ss(k.A, k.B, 20.0 * np.asarray(k.C), 20.0 * np.asarray(k.D),
                inputs=["Rh", "Rv"], outputs=["Uch", "Ucv"])
    gd = bench.true.quad_diode.gain_v_per_rad
    scaling = InputScaling(qd_gain_v_per_rad=(float(gd.h), float(gd.v)),
                           plant_source="physical (true)")
    path = tmp_path_factory.mktemp("controller-x20") / "controllers_sos.json"
    return write_sos_json(path, {"fsmbench_controller": k20}, scaling=scaling)
