"""controllers.mat and the second-order-section JSON: discretisation, scaling, document."""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

import control as ct
import numpy as np
import pytest
from scipy import optimize, signal

from fsmbench.bench.esrf import esrf_decentralised_controller, newport_controller, tustin
from fsmbench.control.design import AxisShape
from fsmbench.control.export import (
    SOS_FORMAT,
    SOS_FORMAT_VERSION,
    InputScaling,
    channel_sections,
    discretise,
    discretise_channel,
    siso_zpk,
    sos_document,
    sos_response,
    state_space_struct,
    tustin_sos,
    write_controllers_mat,
    write_sos_json,
)
from fsmbench.control.freq import evaluate_ss
from fsmbench.io.matfile import load_mat

TS = 1e-4  # seed 9.3's sample time [s]


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
    "seed_controller": esrf_decentralised_controller(),
    "newport_controller": newport_controller(gn0_rad_per_v=(5.3e-3, 5.2e-3)),
    "fsmbench_controller": _fsm_like(),
}
SCALING = InputScaling(qd_gain_v_per_rad=(-31.0, 36.3), plant_source="physical (nominal)")
# The seed's notches (9.2): natural frequencies of s^2 + 15.93 s + 6.686e6 (h) and
# s^2 + 17.45 s + 2.491e6 (v).
NOTCH_HZ = (np.sqrt(6.686e6) / (2 * np.pi), np.sqrt(2.491e6) / (2 * np.pi))


def _notch_section(axis: int) -> int:
    secs = channel_sections(CONTROLLERS["seed_controller"], output=axis, input=axis)
    return next(i for i, s in enumerate(secs) if any(abs(z.imag) > 0 for z in s.zeros))


def test_state_space_struct() -> None:
    k = CONTROLLERS["seed_controller"]
    st = state_space_struct(k)
    assert st["Ts"] == 0.0 and st["InputName"] == ["Rh", "Rv"]
    assert st["OutputName"] == ["Uch", "Ucv"]
    assert state_space_struct(tustin(k))["Ts"] == pytest.approx(1e-4)


def test_controllers_mat_round_trip(tmp_path: Path) -> None:
    path = write_controllers_mat(tmp_path / "controllers.mat", CONTROLLERS, scaling=SCALING)
    plain = load_mat(write_controllers_mat(tmp_path / "plain.mat", CONTROLLERS, method="tustin"))
    m = load_mat(path)
    f = np.logspace(-1, np.log10(4.9e3), 200)
    for name, k in CONTROLLERS.items():
        s = m[name]
        np.testing.assert_array_equal(np.atleast_2d(s["K"]["A"]), np.asarray(k.A))  # bits kept
        np.testing.assert_array_equal(np.atleast_2d(s["K"]["C"]), np.asarray(k.C))
        # Plain Tustin on request: the seed's c2d(K, 1e-4, 'tustin'), bit for bit.
        np.testing.assert_array_equal(np.atleast_2d(plain[name]["Kd"]["A"]),
                                      np.asarray(tustin(k).A))
        # Default Kd: the prewarped sections, cascaded.
        kd = ct.ss(*(np.atleast_2d(s["Kd"][x]) for x in "ABCD"), TS)
        z = np.exp(2j * np.pi * f * TS)
        for i in range(2):
            ref = sos_response(tustin_sos(k, output=i, input=i), f)
            # Poles at z = 1 lose eps / (2 pi f T) relative per factor at low f: ~1e-8 at
            # 0.1 Hz for the four integrators; elsewhere rounding.
            np.testing.assert_allclose(evaluate_ss(kd, z)[:, i, i], ref, rtol=1e-6)
        assert float(np.squeeze(s["Kd"]["Ts"])) == pytest.approx(1e-4)
        assert float(np.squeeze(s["K"]["Ts"])) == 0.0
        assert list(s["K"]["InputName"]) == list(k.input_labels)
        assert list(s["Kd"]["OutputName"]) == list(k.output_labels)
    meta = m["fsmbench"]
    assert str(meta["discretisation"]) == "tustin_prewarp"
    assert str(plain["fsmbench"]["discretisation"]) == "tustin"
    assert float(np.squeeze(meta["qd_gain_v_per_rad"]["h"])) == -31.0
    assert not list(tmp_path.glob("*.part"))  # atomic: no temporary left behind


def test_channel_zpk_keeps_only_its_own_dynamics() -> None:
    z, p, k = siso_zpk(CONTROLLERS["seed_controller"], output=0, input=0)
    assert len(z) == 3 and len(p) == 4  # (s+112)(s²+15.93s+6.686e6) / (s²(s+352.5)(1+s/w))
    assert np.sum(p == 0) == 2
    assert k == pytest.approx(-0.25598 * 2 * np.pi * 2000, rel=1e-9)  # leading coefficient
    z, p, _ = siso_zpk(CONTROLLERS["fsmbench_controller"], output=1, input=1)
    assert len(p) == 7 and np.sum(p == 0) == 4 and len(z) == 4


@pytest.mark.parametrize("name", list(CONTROLLERS))
def test_plain_sections_reproduce_the_tustin_controller(name: str) -> None:
    k = CONTROLLERS[name]
    kd = tustin(k)
    f = np.logspace(-1, np.log10(4.9e3), 300)
    for i in range(2):
        sos = tustin_sos(k, output=i, input=i, method="tustin")
        assert sos.shape[1] == 6 and np.all(sos[:, 3] == 1.0)
        ref = evaluate_ss(kd, np.exp(2j * np.pi * f * 1e-4))[:, i, i]
        # Sections with poles at z = 1 lose eps / (2 pi f T)^n relative at low f: up to
        # 1e-7 at 0.1 Hz for the four integrators; elsewhere rounding.
        np.testing.assert_allclose(sos_response(sos, f), ref, rtol=1e-6)


@pytest.mark.parametrize("axis", [0, 1])
def test_prewarped_notch_section_is_exact_at_its_notch(axis: int) -> None:
    """The defining property of prewarping, and two independent implementations of it."""
    k = CONTROLLERS["seed_controller"]
    j = _notch_section(axis)
    sec = discretise_channel(k, output=axis, input=axis)[j]
    cont = sec.continuous
    w0 = 2 * np.pi * NOTCH_HZ[axis]
    assert sec.prewarp_rad_s == pytest.approx(w0, rel=1e-12)  # zeros recovered to ~1e-13
    num = np.real(cont.gain * np.poly(cont.zeros))
    den = np.real(np.poly(cont.poles))
    hc = np.polyval(num, 1j * w0) / np.polyval(den, 1j * w0)
    hd = sos_response([sec.sos], np.array([NOTCH_HZ[axis]]))[0]
    # At the notch bottom the numerator cancels to 2 zeta w0^2 (1/(2 zeta) ~ 160 times
    # below its terms): rounding stays ~1e-13, far inside 1e-9.
    assert abs(hd / hc - 1) < 1e-9
    # python-control's prewarped Tustin on the same section: same coefficients.
    ref = ct.sample_system(ct.tf(num, den), TS, method="tustin", prewarp_frequency=w0)
    b_ref, a_ref = np.ravel(ref.num[0][0]), np.ravel(ref.den[0][0])
    np.testing.assert_allclose(np.array(sec.sos[:3]), b_ref / a_ref[0], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(np.array(sec.sos[3:]), a_ref / a_ref[0], rtol=1e-9, atol=1e-12)
    # scipy's bilinear on the polynomials with the prewarped rate w0 / (2 tan(w0 T / 2)).
    b_s, a_s = signal.bilinear(num, den, fs=w0 / (2 * np.tan(w0 * TS / 2)))
    np.testing.assert_allclose(np.array(sec.sos[:3]), b_s / a_s[0], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(np.array(sec.sos[3:]), a_s / a_s[0], rtol=1e-9, atol=1e-12)


def _notch_minimum_hz(h: Any, f0: float) -> float:
    res = optimize.minimize_scalar(lambda f: abs(h(f)), bounds=(f0 - 5.0, f0 + 5.0),
                                   method="bounded", options={"xatol": 1e-7})
    return float(res.x)


@pytest.mark.parametrize(("axis", "plain_hz"), [(0, 409.3), (1, 250.7)])
def test_notch_stays_in_place(axis: int, plain_hz: float) -> None:
    """E26: plain Tustin moves the notches (411.5 -> 409.3 Hz, 251.2 -> 250.7 Hz); prewarped not."""
    k = CONTROLLERS["seed_controller"]
    f0 = NOTCH_HZ[axis]
    cont = _notch_minimum_hz(lambda f: evaluate_ss(k, np.array([2j * np.pi * f]))[0, axis, axis],
                             f0)
    found = {m: _notch_minimum_hz(lambda f, m=m: sos_response(
        tustin_sos(k, output=axis, input=axis, method=m), np.array([f]))[0], f0)
        for m in ("tustin", "tustin_prewarp")}
    # The warp's slope at the notch is w0 T / sin(w0 T) ~ 1.006-1.011, so the whole
    # controller's minimum (4 mHz off w0) moves by < 1e-4 Hz; the notch is 1.3 Hz wide.
    assert found["tustin_prewarp"] == pytest.approx(cont, abs=1e-3)
    assert found["tustin"] == pytest.approx(plain_hz, abs=0.05)  # E26's values, 0.1 Hz printed


def _warp_bound(k: ct.StateSpace, axis: int, entry: dict[str, Any], f: np.ndarray) -> np.ndarray:
    """Bound of |Hd/Hc - 1| from the frequency warp of each section (triangle inequality).

    A section evaluated at w' instead of w changes each root factor (jw - r) by
    j(w' - w): relative |w' - w| / |jw - r|; zeros multiply by (1 + e), poles by 1/(1 + e).
    """
    secs = channel_sections(k, output=axis, input=axis)
    w = 2 * np.pi * f
    log_bound = np.zeros_like(w)
    for sec, f0 in zip(secs, entry["prewarp_frequency_hz"], strict=True):
        fs = 1 / TS if f0 is None else 2 * np.pi * f0 / (2 * np.tan(np.pi * f0 * TS))
        dw = np.abs(2 * fs * np.tan(w * TS / 2) - w)
        for z in sec.zeros:
            log_bound += np.log1p(dw / np.abs(1j * w - z))
        for p in sec.poles:
            e = dw / np.abs(1j * w - p)
            log_bound -= np.log1p(-np.minimum(e, 1 - 1e-15))
    return np.expm1(log_bound)


@pytest.mark.parametrize("name", list(CONTROLLERS))
def test_cascade_follows_the_continuous_controller(name: str) -> None:
    k = CONTROLLERS[name]
    doc = sos_document({name: k}, scaling=SCALING)
    f = np.logspace(-1, np.log10(4.5e3), 400)
    for axis, key in enumerate("hv"):
        entry = doc["controllers"][name][key]
        hd = sos_response(entry["sos"], f)
        hc = evaluate_ss(k, 2j * np.pi * f)[:, axis, axis]
        err = np.abs(hd / hc - 1)
        # sosfreqz evaluates 1 - 2 z^-1 + z^-2 near z = 1 from O(1) terms: absolute eps,
        # relative eps / (w T)^2 per double integrator (5.6e-8 at 0.1 Hz), two of them.
        rounding = 1e-12 + 4 * np.finfo(float).eps / (2 * np.pi * f * TS) ** 2
        # Everywhere below 0.45 fs, notches included: within the warp bound.
        assert np.all(err <= _warp_bound(k, axis, entry, f) + rounding)
        if name == "seed_controller":
            # Away from the notch (< 100 Hz) the prewarped notch section's other roots are
            # off by its prewarp scaling (pi f0 T)^2 / 3 = 5.6e-3 (h) / 2.1e-3 (v) in
            # frequency: measured 5.0e-3 / 1.7e-3, plain Tustin 1e-3.
            assert np.max(err[f <= 100.0]) < (np.pi * NOTCH_HZ[axis] * TS) ** 2 / 3


def _keys(obj: Any) -> list[str]:
    if isinstance(obj, dict):
        return [*obj, *(k for v in obj.values() for k in _keys(v))]
    if isinstance(obj, list):
        return [k for v in obj for k in _keys(v)]
    return []


def test_sos_document(tmp_path: Path) -> None:
    path = write_sos_json(tmp_path / "controllers_sos.json", CONTROLLERS, scaling=SCALING)
    doc = json.loads(path.read_text())
    assert doc == json.loads(json.dumps(sos_document(CONTROLLERS, scaling=SCALING)))
    assert (doc["format"], doc["format_version"]) == (SOS_FORMAT, SOS_FORMAT_VERSION)
    assert doc["sample_time_s"] == pytest.approx(1e-4)
    assert doc["discretisation"]["method"] == "tustin_prewarp"
    assert all(re.fullmatch(r"[a-z][a-z0-9_]*", k) for k in _keys(doc))  # no spaces, dashes
    sc = doc["input_scaling"]
    assert sc["qd_gain_v_per_rad"] == {"h": -31.0, "v": 36.3}
    assert sc["qd_gain_from"] == "nominal"
    fsm = doc["controllers"]["fsmbench_controller"]
    assert set(fsm) == {"description", "h", "v"}
    v = fsm["v"]
    assert v["measured_signal"] == {"name": "Vpv", "unit": "V",
                                    "description": "4QD output, vertical"}
    assert (v["input_signal"]["name"], v["input_signal"]["unit"]) == ("Rv", "rad")
    assert (v["output_signal"]["name"], v["output_signal"]["unit"]) == ("Ucv", "V")
    assert v["input_scale_rad_per_v"] == pytest.approx(1 / 36.3, rel=1e-15)
    assert v["n_sections"] == len(v["sos"]) == 4
    assert v["prewarp_frequency_hz"] == [None] * 4  # roll-off damping 0.8: nothing to pin
    seed_h = doc["controllers"]["seed_controller"]["h"]
    assert [x for x in seed_h["prewarp_frequency_hz"] if x] == [pytest.approx(NOTCH_HZ[0])]
    assert doc["controllers"]["newport_controller"]["h"]["output_signal"]["name"] == "Unh"
    plain = sos_document(CONTROLLERS, scaling=SCALING, method="tustin")
    assert plain["discretisation"]["method"] == "tustin"
    assert all(x is None for c in plain["controllers"].values() for a in "hv"
               for x in c[a]["prewarp_frequency_hz"])
    ident = InputScaling(qd_gain_v_per_rad=(-31.4, 35.9), plant_source="identified (Gd: cal)")
    assert ident.to_json()["qd_gain_from"] == "identified"


@pytest.mark.parametrize("method", ["tustin_prewarp", "tustin"])
def test_sosfreqz_reproduces_the_stated_response(method: str) -> None:
    """The document's response (from the continuous sections at their warped frequencies)
    is what scipy's sosfreqz of its coefficients gives."""
    doc = sos_document(CONTROLLERS, scaling=SCALING, method=method)
    for name, ctrl in doc["controllers"].items():
        for axis, key in enumerate("hv"):
            resp = ctrl[key]["response_v_per_rad"]
            f = np.array(resp["f_hz"])
            stated = np.array(resp["discrete"]["real"]) + 1j * np.array(resp["discrete"]["imag"])
            # Coefficient rounding, amplified ~160x at a notch bottom and by
            # 1/(2 pi f T) per integrator at 1 Hz: ~1e-12 at most.
            np.testing.assert_allclose(sos_response(ctrl[key]["sos"], f), stated, rtol=1e-9)
            cont = np.array(resp["continuous"]["real"]) + 1j * np.array(
                resp["continuous"]["imag"])
            np.testing.assert_allclose(
                cont, evaluate_ss(CONTROLLERS[name], 2j * np.pi * f)[:, axis, axis], rtol=1e-12)
    # The seed's notch frequencies are among the stated ones when prewarping.
    if method == "tustin_prewarp":
        f_h = doc["controllers"]["seed_controller"]["h"]["response_v_per_rad"]["f_hz"]
        assert any(abs(x - NOTCH_HZ[0]) < 1e-9 for x in f_h)


def test_discretise_keeps_names_and_refuses_unknown_methods() -> None:
    kd = discretise(CONTROLLERS["seed_controller"])
    assert kd.dt == TS and list(kd.input_labels) == ["Rh", "Rv"]
    assert list(kd.output_labels) == ["Uch", "Ucv"]
    with pytest.raises(ValueError, match="unknown discretisation 'zoh'"):
        discretise(CONTROLLERS["seed_controller"], method="zoh")


def test_sos_refuses_a_coupled_controller() -> None:
    k = ct.ss([[-1.0]], [[1.0, 1.0]], [[1.0], [1.0]], np.zeros((2, 2)),
              inputs=["Rh", "Rv"], outputs=["Uch", "Ucv"])
    with pytest.raises(ValueError, match="not diagonal"):
        sos_document({"coupled": k}, scaling=SCALING)
