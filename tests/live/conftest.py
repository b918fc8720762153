"""Shared fixtures of the live-bench tests: fsmbench's controller, and 20 times it.

The real parts (PyTango's own database server, fsmbench server and IOC processes) are
started through the ``parts`` fixture of ``tests/conftest.py`` (``tune --device`` starts
them too).
"""

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


def _sos_file(bench: Bench, k: ct.StateSpace, gain: float, folder: Path) -> Path:
    scaled = ct.ss(k.A, k.B, gain * np.asarray(k.C), gain * np.asarray(k.D),
                   inputs=["Rh", "Rv"], outputs=["Uch", "Ucv"])
    gd = bench.true.quad_diode.gain_v_per_rad
    scaling = InputScaling(qd_gain_v_per_rad=(float(gd.h), float(gd.v)),
                           plant_source="physical (true)")
    return write_sos_json(folder / "controllers_sos.json", {"fsmbench_controller": scaled},
                          scaling=scaling)


@pytest.fixture(scope="session")
def controller_x20(bench: Bench, fsmbench_controller: ct.StateSpace,
                   tmp_path_factory: pytest.TempPathFactory) -> Path:
    """``controllers_sos.json`` holding fsmbench's controller with 20 times its gain."""
    return _sos_file(bench, fsmbench_controller, 20.0,
                     tmp_path_factory.mktemp("controller-x20"))


@pytest.fixture(scope="session")
def controller_x1(bench: Bench, fsmbench_controller: ct.StateSpace,
                  tmp_path_factory: pytest.TempPathFactory) -> Path:
    """``controllers_sos.json`` holding fsmbench's controller as designed."""
    return _sos_file(bench, fsmbench_controller, 1.0, tmp_path_factory.mktemp("controller-x1"))
