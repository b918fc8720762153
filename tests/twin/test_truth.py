"""twin_truth.json speaks the identification's definitions (issue 20).

Each definition is checked against the bench's own blocks or a filter built
independently (scipy), not against the formula in ``fsmbench.twin.truth``.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.signal as ss

from fsmbench.bench.blocks import newport_beam_matrix
from fsmbench.bench.params import default_bench, real_bench
from fsmbench.twin.truth import TRUTH_FORMAT, model_values


def _group_delay_s(b: np.ndarray, a: np.ndarray, f_hz: float = 1.0) -> float:
    """``-dφ/dω`` of an analogue filter at ``f_hz`` by a central difference (low frequency)."""
    w = 2 * math.pi * np.array([f_hz * 0.999, f_hz * 1.001])
    _, h = ss.freqs(b, a, worN=w)
    phase = np.unwrap(np.angle(h))
    return float(-(phase[1] - phase[0]) / (w[1] - w[0]))


@pytest.mark.parametrize("which", ["default", "real"])
def test_qd_gain_is_what_a_single_axis_calibration_measures(which: str) -> None:
    p = (default_bench() if which == "default" else real_bench()).true
    values = model_values(p)
    # A calibration sweeps one Newport axis and regresses that axis's 4QD output on the
    # beam angle it commands (the Newport's beam factor): the slope is the 4QD gain times
    # the diagonal of the rotated beam matrix over the unrotated factor.
    beam = newport_beam_matrix(p)
    for i, axis in enumerate("hv"):
        g = p.quad_diode.gain_v_per_rad[axis]
        slope = g * beam[i, i] / p.newport.beam_angle_per_mirror_angle
        assert values["qd_gain_v_per_rad"][axis] == pytest.approx(slope, rel=1e-12)
        assert values["qd_diode_gain_v_per_rad"][axis] == g
    if p.quad_diode.rotation_rad:  # the real bench turns its 4QD: the two differ
        assert values["qd_gain_v_per_rad"]["h"] != values["qd_diode_gain_v_per_rad"]["h"]


@pytest.mark.parametrize("which", ["default", "real"])
def test_effective_delay_adds_the_lags_a_delay_fit_reads(which: str) -> None:
    p = (default_bench() if which == "default" else real_bench()).true
    values = model_values(p)
    gi = p.current_amp_gain_a_per_v()
    # The coil circuit Ic/Uc = 1/(R_total + L s) and the 4QD amplifier (Butterworth or first
    # order at its bandwidth), their group delays at 1 Hz from scipy's own filters.
    coil = np.mean([_group_delay_s(np.array([1.0]),
                                   np.array([p.sercalo.l_coil_h[a], 1.0 / gi[a]]))
                    for a in "hv"])
    qd = p.quad_diode
    sensor = 0.0
    if qd.bandwidth_hz > 0:
        b, a = ss.butter(int(qd.bandwidth_order), 2 * math.pi * qd.bandwidth_hz, analog=True)
        sensor = _group_delay_s(b, a)
    pure = values["delay_s"]
    eff = values["effective_delay_s"]
    # 1e-6 relative: the central difference at 1 Hz of filters whose corners are >= 6 kHz
    assert eff["sercalo"] - pure["sercalo"] == pytest.approx(coil + sensor, rel=1e-6)
    assert eff["newport"] - pure["newport"] == pytest.approx(sensor, rel=1e-6, abs=1e-15)
    assert TRUTH_FORMAT == ("fsmbench.twin_truth", 3)
