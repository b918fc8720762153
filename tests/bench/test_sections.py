"""Cascade realisations of zero-pole-gain models."""

from __future__ import annotations

import control as ct
import numpy as np
import pytest

from fsmbench.bench.sections import pair_roots, sections_from_zpk, zpk_cascade


def _zpk_eval(zeros, poles, gain, s):
    return gain * np.prod([s - z for z in zeros], axis=0) / np.prod([s - p for p in poles], axis=0)


@pytest.mark.parametrize(
    ("zeros", "poles", "gain"),
    [
        ([-112.0, -7.9 + 2585j, -7.9 - 2585j], [0.0, 0.0, -352.5, -12566.4], -3216.0),
        ([], [-10.0 + 100j, -10.0 - 100j], 1e4),
        ([-5.0], [-1.0, -20.0, -3.0 + 4j, -3.0 - 4j], 2.0),
        ([-1.0, -2.0], [-3.0, -4.0], 0.5),  # biproper: direct feedthrough
    ],
)
def test_cascade_equals_zpk(zeros, poles, gain) -> None:
    sys = zpk_cascade(zeros, poles, gain, input_name="e", output_name="u")
    s = 2j * np.pi * np.logspace(-1, 4, 60)
    ours = np.array([sys(si) for si in s]).ravel()
    np.testing.assert_allclose(ours, _zpk_eval(zeros, poles, gain, s), rtol=1e-10)
    assert list(sys.input_labels) == ["e"] and list(sys.output_labels) == ["u"]
    assert sys.nstates == len(poles)


def test_entries_are_scaled_to_the_pole_frequencies() -> None:
    """Cascade entries stay O(|p|); the companion form's reach prod(|p|)."""
    poles = [-1e4, -2e4 + 1e4j, -2e4 - 1e4j, -3e4]
    sys = zpk_cascade([], poles, 1.0)
    companion = ct.tf2ss(ct.tf([1.0], np.real(np.poly(poles))))
    assert np.max(np.abs(sys.A)) < 1e2 * max(abs(p) for p in poles)
    assert np.max(np.abs(companion.A)) > 1e12


def test_pairing_errors() -> None:
    assert pair_roots([1 + 2j, 1 - 2j, -3.0]) == [(1 + 2j, 1 - 2j), (-3 + 0j,)]
    with pytest.raises(ValueError, match="conjugate"):
        pair_roots([1 + 2j])
    with pytest.raises(ValueError, match="improper"):
        sections_from_zpk([-1.0, -2.0], [-3.0], 1.0)
