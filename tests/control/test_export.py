"""controllers.mat and the second-order-section JSON."""

from __future__ import annotations

import json
from pathlib import Path

import control as ct
import numpy as np
import pytest

from fsmbench.control.design import AxisShape
from fsmbench.control.export import (
    SOS_FORMAT,
    siso_zpk,
    sos_document,
    sos_response,
    state_space_struct,
    tustin_sos,
    write_controllers_mat,
    write_sos_json,
)
from fsmbench.control.freq import evaluate_ss
from fsmbench.control.seed import newport_controller, seed_decentralised_controller, tustin
from fsmbench.io.matfile import load_mat


def _fsm_like() -> ct.StateSpace:
    """Two channels shaped like fsmbench's controller: four integrators, lead, roll-off."""
    parts = [AxisShape(crossover_hz=fc, integrator_hz=7.0, extra_integrators=3, lead_hz=45.0,
                       lead_ratio=1.5, lowpass_hz=lp, lowpass_damping=0.8,
                       gain=g).realise(input_name=i, output_name=o)
             for fc, lp, g, i, o in ((35.0, 200.0, -4000.0, "Rh", "Uch"),
                                     (33.0, 140.0, 6000.0, "Rv", "Ucv"))]
    k = ct.append(*parts)
    return ct.ss(k.A, k.B, k.C, k.D, inputs=["Rh", "Rv"], outputs=["Uch", "Ucv"])


CONTROLLERS = {
    "seed_controller": seed_decentralised_controller(),
    "newport_controller": newport_controller(gn0_rad_per_v=(5.3e-3, 5.2e-3)),
    "fsmbench_controller": _fsm_like(),
}


def test_state_space_struct() -> None:
    k = CONTROLLERS["seed_controller"]
    st = state_space_struct(k)
    assert st["Ts"] == 0.0 and st["InputName"] == ["Rh", "Rv"]
    assert st["OutputName"] == ["Uch", "Ucv"]
    assert state_space_struct(tustin(k))["Ts"] == pytest.approx(1e-4)


def test_controllers_mat_round_trip(tmp_path: Path) -> None:
    path = write_controllers_mat(tmp_path / "controllers.mat", CONTROLLERS)
    m = load_mat(path)
    for name, k in CONTROLLERS.items():
        s = m[name]
        np.testing.assert_array_equal(np.atleast_2d(s["K"]["A"]), np.asarray(k.A))  # bits kept
        np.testing.assert_array_equal(np.atleast_2d(s["K"]["C"]), np.asarray(k.C))
        np.testing.assert_array_equal(np.atleast_2d(s["Kd"]["A"]), np.asarray(tustin(k).A))
        assert float(np.squeeze(s["Kd"]["Ts"])) == pytest.approx(1e-4)
        assert float(np.squeeze(s["K"]["Ts"])) == 0.0
        assert list(s["K"]["InputName"]) == list(k.input_labels)
        assert list(s["Kd"]["OutputName"]) == list(k.output_labels)
    assert "fsmbench" in m
    assert not list(tmp_path.glob("*.part"))  # atomic: no temporary left behind


def test_channel_zpk_keeps_only_its_own_dynamics() -> None:
    z, p, k = siso_zpk(CONTROLLERS["seed_controller"], output=0, input=0)
    assert len(z) == 3 and len(p) == 4  # (s+112)(s²+15.93s+6.686e6) / (s²(s+352.5)(1+s/w))
    assert np.sum(p == 0) == 2
    assert k == pytest.approx(-0.25598 * 2 * np.pi * 2000, rel=1e-9)  # leading coefficient
    z, p, _ = siso_zpk(CONTROLLERS["fsmbench_controller"], output=1, input=1)
    assert len(p) == 7 and np.sum(p == 0) == 4 and len(z) == 4


@pytest.mark.parametrize("name", list(CONTROLLERS))
def test_sections_reproduce_the_tustin_controller(name: str) -> None:
    k = CONTROLLERS[name]
    kd = tustin(k)
    f = np.logspace(-1, np.log10(4.9e3), 300)
    for i in range(2):
        sos = tustin_sos(k, output=i, input=i)
        assert sos.shape[1] == 6 and np.all(sos[:, 3] == 1.0)
        ref = evaluate_ss(kd, np.exp(2j * np.pi * f * 1e-4))[:, i, i]
        # Sections with poles at z = 1 lose eps / (2 pi f T)^n relative at low f: up to
        # 1e-7 at 0.1 Hz for the four integrators; elsewhere rounding.
        np.testing.assert_allclose(sos_response(sos, f), ref, rtol=1e-6)


def test_sos_json(tmp_path: Path) -> None:
    path = write_sos_json(tmp_path / "controllers_sos.json", CONTROLLERS)
    doc = json.loads(path.read_text())
    assert doc == json.loads(json.dumps(sos_document(CONTROLLERS)))
    assert doc["format"] == SOS_FORMAT and doc["sample_time_s"] == pytest.approx(1e-4)
    ch = doc["controllers"]["fsmbench_controller"]["channels"][1]
    assert (ch["input"], ch["output"]) == ("Rv", "Ucv")
    assert ch["n_sections"] == len(ch["sos"]) == 4


def test_sos_refuses_a_coupled_controller() -> None:
    k = ct.ss([[-1.0]], [[1.0, 1.0]], [[1.0], [1.0]], np.zeros((2, 2)),
              inputs=["Rh", "Rv"], outputs=["Uch", "Ucv"])
    with pytest.raises(ValueError, match="not diagonal"):
        sos_document({"coupled": k})
