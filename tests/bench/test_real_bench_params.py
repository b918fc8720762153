"""Real-bench feature parameters: defaults off, the packaged real bench, overrides, verdicts."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from fsmbench.bench.blocks import replace_params, sercalo_angles
from fsmbench.bench.params import (
    ParamsError,
    PerAxis,
    default_bench,
    load_bench,
    real_bench,
    save_bench,
)
from fsmbench.sim.plant import twin_continuous

FEATURES = {
    "converter": ("dac_extra_delay_s",),
    "sercalo": ("mode_shape_angle_rad", "second_mode_hz", "second_mode_relative_gain"),
    "quad_diode": ("bandwidth_hz", "flicker_asd_v_per_rthz", "mains_amplitude_v",
                   "offset_drift_v_per_s", "offset_random_walk_v_per_rts", "nonlinearity_pct"),
}


def _is_off(value: object) -> bool:
    if isinstance(value, PerAxis):
        return value.h == 0.0 and value.v == 0.0
    if isinstance(value, tuple):
        return len(value) == 0
    return value == 0.0


def test_every_feature_is_off_in_the_default_bench_and_on_in_the_real_one() -> None:
    default, real = default_bench(), real_bench()
    for group, names in FEATURES.items():
        for name in names:
            assert _is_off(getattr(getattr(default.true, group), name)), (group, name)
            assert _is_off(getattr(getattr(default.nominal, group), name)), (group, name)
            assert not _is_off(getattr(getattr(real.true, group), name)), (group, name)
    # Identification starts from the same nominal model on both benches.
    assert real.nominal == default.nominal
    # Coupling goes through the mode shapes, not the constant fraction.
    assert real.true.sercalo.coupling_h_to_v == 0.0 == real.true.sercalo.coupling_v_to_h


def test_the_default_twin_plant_is_unchanged_by_the_new_parameters() -> None:
    # Same states, same matrices as a bench that never heard of the features: with every
    # feature at its default the Sercalo block keeps the seed's four states.
    p = default_bench().true
    assert sercalo_angles(p).nstates == 4
    assert twin_continuous(p).nstates == 12  # 2 coil currents, 2 Ga, 4 Sercalo, 4 Newport


def test_real_bench_round_trips_through_toml(tmp_path: Path) -> None:
    bench = real_bench()
    path = save_bench(bench, tmp_path / "b.toml")
    assert load_bench(path) == bench


def test_packaged_name_and_base_files(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    assert load_bench("real_bench.toml") == real_bench()
    f = tmp_path / "mine.toml"
    f.write_text('base = "real"\n[nominal.converter]\nfs_hz = 5000.0\n'
                 "[true.quad_diode]\nnonlinearity_pct = 1.0\n")
    b = load_bench(f)
    assert b.true.converter.fs_hz == 5000.0 == b.nominal.converter.fs_hz
    assert b.true.quad_diode.nonlinearity_pct == 1.0
    # Everything else is the real bench's.
    assert b.true.sercalo == real_bench().true.sercalo


@pytest.mark.parametrize(("text", "words"), [
    ('base = "nope"\n', "'base' must be one of"),
    ('base = "real"\n[true.quad_diode]\nbandwidth_order = 3\n', "bandwidth_order' must be 1 or 2"),
    ('base = "real"\n[true.quad_diode]\nmains_amplitude_v = 0.1\n', "must be an array"),
    ('base = "real"\n[nominal.converter]\nfs_hz = 3000.0\n', "is not below the Nyquist"),
    ('base = "real"\n[true.sercalo]\nsecond_mode_damping_ratio = { h = 0.0 }\n',
     "second_mode_damping_ratio.h' must be > 0"),
    ('base = "default"\n[true.quad_diode]\nnonlinearity_pct = 40.0\n', "in [0, 30) %"),
])
def test_bad_feature_values_get_a_one_line_verdict_naming_the_file(tmp_path: Path, text: str,
                                                                  words: str) -> None:
    f = tmp_path / "bad.toml"
    f.write_text(text)
    with pytest.raises(ParamsError) as err:
        load_bench(f)
    message = str(err.value)
    assert str(f) in message and words in message and "\n" not in message


def test_mode_shape_angle_of_zero_is_the_decoupled_seed_model() -> None:
    p = default_bench().true
    q = replace_params(p, sercalo={"mode_shape_angle_rad": PerAxis(h=0.0, v=0.0)})
    a, b = sercalo_angles(p), sercalo_angles(q)
    for m in ("A", "B", "C"):
        np.testing.assert_array_equal(getattr(a, m), getattr(b, m))
    # And a turned shape changes the coupling, not the direct DC gain's first order.
    r = replace_params(p, sercalo={"coupling_h_to_v": 0.0, "coupling_v_to_h": 0.0,
                                   "mode_shape_angle_rad": PerAxis(h=0.02, v=0.0)})
    dc = np.asarray(sercalo_angles(r).dcgain())
    # theta_cv / theta_ch for Ich = tan(0.02); the v mode (unturned, uncoupled) is not driven.
    assert dc[1, 0] / dc[0, 0] == pytest.approx(np.tan(0.02), rel=1e-12)  # rounding only
