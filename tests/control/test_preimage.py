"""The continuous pre-image of a discrete controller under plain Tustin.

Checked against the identity that defines it, ``H_d(exp(j w T)) = H_c(j (2/T) tan(w T/2))``,
with the discrete side from scipy's ``sosfreqz`` and the sections from scipy's
``bilinear_zpk`` (neither is fsmbench's), and against the substitution in the realisation.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import signal

from fsmbench.bench.sections import Section, zpk_cascade
from fsmbench.control.export import siso_zpk
from fsmbench.control.preimage import sections_preimage, tustin_preimage

TS_S = 1e-4
F_HZ = np.array([0.05, 1.0, 10.0, 97.0, 251.2, 411.5, 1000.0, 3000.0, 4900.0])


def _continuous(sys: object, s: np.ndarray) -> np.ndarray:
    a, b, c, d = (np.asarray(getattr(sys, x), dtype=float) for x in "ABCD")
    n = a.shape[0]
    return np.array([(c @ np.linalg.solve(x * np.eye(n) - a, b) + d) if n else d for x in s])


def _warped(f_hz: np.ndarray) -> np.ndarray:
    return 1j * (2.0 / TS_S) * np.tan(np.pi * f_hz * TS_S)


def _rows(sections: list[Section]) -> np.ndarray:
    """Plain Tustin of each section by scipy, as ``[b0, b1, b2, a0, a1, a2]`` rows."""
    rows = []
    for sec in sections:
        z, p, k = signal.bilinear_zpk(np.array(sec.zeros, dtype=complex),
                                      np.array(sec.poles, dtype=complex), sec.gain,
                                      fs=1.0 / TS_S)
        b, a = np.real(k * np.poly(z)), np.real(np.poly(p))
        row = np.zeros(6)
        row[:b.size], row[3:3 + a.size] = b, a  # bilinear_zpk: as many zeros as poles
        rows.append(row)
    return np.array(rows)


@st.composite
def cascades(draw: st.DrawFn) -> list[Section]:
    """One to three sections: real or lightly to well damped complex poles from 1 to 2e4
    rad/s (or integrators), with zero to two zeros each, some in the right half plane."""
    out = []
    for _ in range(draw(st.integers(1, 3))):
        w = draw(st.floats(1.0, 2e4))
        kind = draw(st.sampled_from(["pair", "reals", "integrators"]))
        if kind == "pair":
            zeta = draw(st.floats(0.02, 0.9))
            p = -zeta * w + 1j * w * np.sqrt(1 - zeta**2)
            poles: tuple[complex, ...] = (p, np.conj(p))
        elif kind == "reals":
            poles = (-w, -draw(st.floats(1.0, 2e4)))
        else:
            poles = (0.0, -w)
        nz = draw(st.integers(0, 2))
        # Not within 1 % of s = 2/T: Tustin sends a zero there to z = infinity, which
        # scipy's bilinear_zpk cannot write as a section (b0 = 0 is tested on its own).
        zeros = tuple(complex(draw(st.floats(-2e4, 2e4).filter(
            lambda x: abs(x) > 0.5 and abs(x - 2.0 / TS_S) > 0.01 * 2.0 / TS_S)))
            for _ in range(nz))
        out.append(Section(zeros=zeros, poles=poles, gain=draw(st.floats(0.1, 10.0))))
    return out


@settings(max_examples=60, deadline=None)
@given(cascades())
def test_the_pre_image_is_the_continuous_controller_tustin_was_applied_to(
        sections: list[Section]) -> None:
    rows = _rows(sections)
    k = sections_preimage([rows], ts_s=TS_S, inputs=["r"], outputs=["u"], name="k")
    z, p, gain = (list(x) for x in zip(*[(s.zeros, s.poles, s.gain) for s in sections],
                                       strict=True))
    original = zpk_cascade([r for g in z for r in g], [r for g in p for r in g],
                           float(np.prod(gain)))
    s = 2j * np.pi * F_HZ
    ours, theirs = _continuous(k, s)[:, 0, 0], _continuous(original, s)[:, 0, 0]
    # Round-off through scipy's bilinear map (coefficients from roots) and back: a 1 rad/s
    # root sits 1e-4 from z = 1, where its coefficients cancel. 3000 drawn cascades all
    # pass this bound (checked once, outside the suite).
    assert np.allclose(ours, theirs, rtol=1e-6, atol=1e-9 * np.max(np.abs(theirs)))


@settings(max_examples=40, deadline=None)
@given(cascades())
def test_the_pre_image_s_warped_response_is_the_file_s(sections: list[Section]) -> None:
    rows = _rows(sections)
    k = sections_preimage([rows], ts_s=TS_S, inputs=["r"], outputs=["u"], name="k")
    _, h_d = signal.sosfreqz(rows, worN=F_HZ, fs=1.0 / TS_S)
    h_c = _continuous(k, _warped(F_HZ))[:, 0, 0]
    # The defining identity of Tustin; round-off as above (sosfreqz evaluates a section with
    # poles 1e-4 from z = 1 from coefficients that cancel there). 3000 cascades pass.
    assert np.allclose(h_c, h_d, rtol=1e-6, atol=1e-9 * np.max(np.abs(h_d)))


def test_zeros_tustin_put_on_minus_one_are_zeros_at_infinity() -> None:
    # A lowpass of relative degree 2 and two integrators: Tustin gives double zeros on
    # z = -1, located by any root finder only to ~1e-8, i.e. at 1e11-1e13 rad/s under a
    # substitution. The pre-image has no zero there, and its zero-pole split is exact.
    sections = [Section(zeros=(), poles=(-2000 + 2000j, -2000 - 2000j), gain=8e6),
                Section(zeros=(-50.0, -60.0), poles=(0.0, 0.0), gain=1.0)]
    k = sections_preimage([_rows(sections)], ts_s=TS_S, inputs=["r"], outputs=["u"],
                          name="k")
    zeros, poles, gain = siso_zpk(k)
    assert sorted(np.abs(zeros)) == pytest.approx([50.0, 60.0], rel=1e-6)
    assert len(poles) == 4 and gain == pytest.approx(8e6, rel=1e-6)


def test_a_missing_leading_coefficient_is_a_zero_at_two_over_t() -> None:
    # b0 = 0: one sample of delay in the section, a zero at infinity in z, at s = 2/T.
    row = np.array([[0.0, 0.3, 0.1, 1.0, -1.2, 0.5]])
    k = sections_preimage([row], ts_s=TS_S, inputs=["r"], outputs=["u"], name="k")
    zeros, _, _ = siso_zpk(k)
    assert np.min(np.abs(zeros - 2.0 / TS_S)) < 1e-6 * 2.0 / TS_S
    _, h_d = signal.sosfreqz(row, worN=F_HZ, fs=1.0 / TS_S)
    assert np.allclose(_continuous(k, _warped(F_HZ))[:, 0, 0], h_d, rtol=1e-9)


def test_two_axes_are_two_channels_and_agree_with_the_substitution() -> None:
    rows_h = _rows([Section(zeros=(-30.0,), poles=(0.0, -900.0), gain=50.0)])
    rows_v = _rows([Section(zeros=(-20 + 2600j, -20 - 2600j),
                            poles=(-300 + 2600j, -300 - 2600j), gain=1.0)])
    k = sections_preimage([rows_h, rows_v], ts_s=TS_S, inputs=["Rh", "Rv"],
                          outputs=["Uch", "Ucv"], name="k")
    # The same cascades realised by scipy in state space, then substituted as a whole.
    blocks = [signal.zpk2ss(*signal.sos2zpk(r)) for r in (rows_h, rows_v)]
    a = np.block([[blocks[0][0], np.zeros((2, 2))], [np.zeros((2, 2)), blocks[1][0]]])
    b = np.block([[blocks[0][1], np.zeros((2, 1))], [np.zeros((2, 1)), blocks[1][1]]])
    c = np.block([[blocks[0][2], np.zeros((1, 2))], [np.zeros((1, 2)), blocks[1][2]]])
    d = np.diag([blocks[0][3][0, 0], blocks[1][3][0, 0]])
    whole = tustin_preimage(a, b, c, d, ts_s=TS_S, inputs=["Rh", "Rv"],
                            outputs=["Uch", "Ucv"], name="k")
    s = 2j * np.pi * F_HZ
    ours, theirs = _continuous(k, s), _continuous(whole, s)
    assert list(k.input_labels) == ["Rh", "Rv"] and list(k.output_labels) == ["Uch", "Ucv"]
    assert np.all(ours[:, 0, 1] == 0) and np.all(ours[:, 1, 0] == 0)
    # Two well-conditioned routes to one transfer function: round-off.
    assert np.allclose(ours, theirs, rtol=1e-8, atol=1e-12)


@pytest.mark.parametrize("route", ["sections", "realisation"])
def test_a_pole_on_minus_one_has_no_pre_image(route: str) -> None:
    row = np.array([[1.0, 0.0, 0.0, 1.0, 1.0, 0.0]])  # 1 / (1 + z^-1): a pole at z = -1
    with pytest.raises(ValueError, match=r"z = -1 \(Nyquist\)"):
        if route == "sections":
            sections_preimage([row], ts_s=TS_S, inputs=["r"], outputs=["u"], name="k")
        else:
            tustin_preimage(np.array([[-1.0]]), np.array([[1.0]]), np.array([[-1.0]]),
                            np.array([[1.0]]), ts_s=TS_S, inputs=["r"], outputs=["u"],
                            name="k")
