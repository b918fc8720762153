"""float32 check of exported controllers: closed forms for one section, the seed's channels."""

from __future__ import annotations

import numpy as np

from fsmbench.bench.esrf import esrf_decentralised_controller
from fsmbench.control.export import discretise_channel
from fsmbench.control.export_check import (
    FLOAT32_REL_TOL,
    float32_sos_check,
    float32_state_space_check,
)

TS = 1e-4


def test_first_order_section_error_matches_its_closed_form() -> None:
    # 1 / (1 - p z^-1) at DC is 1 / (1 - p): rounding p to float32 changes it by
    # (1 - p) / (1 - p32) - 1, computed here without the module's frequency response.
    p = 1.0 - 1.234567e-4
    p32 = float(np.float32(p))
    expected = abs((1.0 - p) / (1.0 - p32) - 1.0)
    chk = float32_sos_check([[1.0, 0.0, 0.0, 1.0, -p, 0.0]], ts_s=TS, f_hz=np.array([1e-6]))
    # 1e-6 Hz is 6e-10 rad per sample from DC: the response differs from its DC value by
    # far less than the float32 step (1e-3 relative of the expected error is ample).
    assert abs(chk.max_relative_error - expected) < 1e-3 * expected
    assert expected > 0  # the chosen p is not a float32 number
    assert chk.stable_poles_kept and chk.integrators_exact


def test_float32_exact_coefficients_have_no_error() -> None:
    sos = np.array([[0.5, -0.25, 0.125, 1.0, -2.0, 1.0], [1.0, 0.5, 0.0, 1.0, -0.5, 0.0]])
    chk = float32_sos_check(sos, ts_s=TS)
    assert chk.max_relative_error == 0.0
    assert chk.max_phase_error_deg < 1e-12  # arg(h / h): the division's own rounding
    assert chk.integrators_exact and chk.passes
    assert chk.to_json()["passes"] is True


def test_a_pole_rounded_onto_the_unit_circle_is_reported() -> None:
    # 1 - 2^-30 rounds to 1.0 in float32: a stable pole becomes an integrator.
    p = 1.0 - 2.0 ** -30
    chk = float32_sos_check([[1.0, 0.0, 0.0, 1.0, -p, 0.0]], ts_s=TS)
    assert float(np.float32(p)) == 1.0
    assert not chk.passes
    assert not chk.integrators_exact  # one more pole on z = 1 than in float64


def test_seed_controller_sections_pass_and_the_sentence_says_so() -> None:
    k = esrf_decentralised_controller()
    for i in range(2):
        sos = np.array([s.sos for s in discretise_channel(k, ts_s=TS, output=i, input=i)])
        chk = float32_sos_check(sos, ts_s=TS)
        assert chk.passes, chk.sentence()
        assert chk.max_relative_error < FLOAT32_REL_TOL
        assert "passes" in chk.sentence()
        assert chk.t_peak_bound == 1.0 / chk.max_relative_error


def test_state_space_check_agrees_with_the_sections_on_a_well_scaled_model() -> None:
    # One section, realised as its controllable form: both routes round the same five
    # numbers (a1, a2 and the numerator) so their errors are of one order.
    b0, b1, b2, a1, a2 = 0.3, -0.2, 0.05, -1.2, 0.45
    a = np.array([[-a1, -a2], [1.0, 0.0]])
    b = np.array([[1.0], [0.0]])
    c = np.array([[b1 - a1 * b0, b2 - a2 * b0]])
    d = np.array([[b0]])
    f = np.logspace(-1, 3.6, 200)
    ss = float32_state_space_check(a, b, c, d, ts_s=TS, f_hz=f)
    so = float32_sos_check([[b0, b1, b2, 1.0, a1, a2]], ts_s=TS, f_hz=f)
    # float32 eps is 6e-8: a section with poles 0.6 ± 0.3j amplifies it by < 100.
    assert ss.max_relative_error < 1e-5 and so.max_relative_error < 1e-5
    assert ss.passes and so.passes


def test_sos_document_carries_the_float32_check_antiwindup_and_note() -> None:
    import json

    from scipy import signal

    from fsmbench.control.export import DAC_RAILS_V, InputScaling, sos_document

    doc = sos_document({"seed_controller": esrf_decentralised_controller()},
                       scaling=InputScaling(qd_gain_v_per_rad=(-31.0, 36.3),
                                            plant_source="physical (nominal)"), ts_s=TS)
    json.dumps(doc, allow_nan=False)  # the file's own rule: no NaN or inf
    assert doc["dac_rails_v"] == {"min": DAC_RAILS_V[0], "max": DAC_RAILS_V[1]}
    f = np.logspace(0, 3.6, 40)
    for axis in ("h", "v"):
        ch = doc["controllers"]["seed_controller"][axis]
        own = float32_sos_check(ch["sos"], ts_s=TS).to_json()
        assert ch["float32"]["max_relative_error"] == own["max_relative_error"]
        aw = ch["antiwindup"]
        assert aw["scheme"] == "back-calculation" and len(aw["integrator_registers"]) == 2
        assert {r["register"] for r in aw["integrator_registers"]} == {"s1", "s2"}
        # Reordering the sections leaves the filter as it was (sections commute).
        _, h0 = signal.sosfreqz(np.array(ch["sos"]), worN=f, fs=1 / TS)
        _, h1 = signal.sosfreqz(np.array(aw["sos_integrators_last"]), worN=f, fs=1 / TS)
        np.testing.assert_allclose(h1, h0, rtol=1e-12)  # same products, another order
    note = " ".join(doc["implementation_note"])
    for words in ("direct form II transposed", "-10 V .. 10 V", "back-calculation",
                  "float32, seed_controller h", "Tracking time"):
        assert words in note
