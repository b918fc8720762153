"""The fault library: the clean folder untouched, each fault exactly what it says."""

from __future__ import annotations

import hashlib
import stat
from pathlib import Path

import numpy as np
import pytest
from scipy.io import loadmat

from indsim import write_bench
from indsim.faults import CAUSES, FRINGE_M, catalogue, faults


@pytest.fixture(scope="module")
def clean(plain_run, tmp_path_factory) -> Path:
    return write_bench(plain_run, tmp_path_factory.mktemp("clean"))


def _hashes(folder: Path) -> dict[str, str]:
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(folder.iterdir())}


def _vars(path: Path) -> dict[str, np.ndarray]:
    return {k: v.reshape(-1) for k, v in loadmat(path).items() if not k.startswith("__")}


def test_catalogue_ids_unique_and_causes_known():
    ids = [f.id for f in catalogue()]
    assert len(ids) == len(set(ids)) == len(faults())
    assert all(f.cause in CAUSES for f in catalogue())
    assert ids[0] == "none"


def test_every_fault_leaves_the_clean_folder_alone(clean, tmp_path):
    """Each fault writes only its copy; the copy differs from the clean folder where it says."""
    before = _hashes(clean)
    for fault in catalogue():
        case = fault(clean, tmp_path / fault.id, seed=2)
        assert _hashes(clean) == before, fault.id
        if fault.id == "none":
            assert _hashes(tmp_path / "none") == before
            continue
        assert case.files, fault.id
        after = tmp_path / fault.id
        changed = {p.name.removesuffix(".mat") for p in after.iterdir()
                   if not p.is_file() or p.is_symlink() or p.name not in before
                   or hashlib.sha256(p.read_bytes()).hexdigest() != before[p.name]}
        changed |= {n.removesuffix(".mat") for n in before if not (after / n).exists()
                    and not (after / n).is_symlink()}
        assert changed == set(case.files), fault.id


def test_sign_negates_one_signal_of_one_file(clean, tmp_path):
    faults()["sign_Vph_data_uch"](clean, tmp_path / "x")
    a, b = _vars(clean / "data_uch.mat"), _vars(tmp_path / "x" / "data_uch.mat")
    np.testing.assert_array_equal(b["Vph"], -a["Vph"])
    for k in ("t", "Uch", "Vch", "Vpv"):
        np.testing.assert_array_equal(b[k], a[k])


def test_crossed_and_duplicated_channels(clean, tmp_path):
    faults()["qd_outputs_crossed"](clean, tmp_path / "c")
    faults()["Vpv_equals_Vph"](clean, tmp_path / "d")
    for name in ("data_cal_pd_v", "data_rep_h"):
        a = _vars(clean / f"{name}.mat")
        c, d = _vars(tmp_path / "c" / f"{name}.mat"), _vars(tmp_path / "d" / f"{name}.mat")
        np.testing.assert_array_equal(c["Vph"], a["Vpv"])
        np.testing.assert_array_equal(c["Vpv"], a["Vph"])
        np.testing.assert_array_equal(d["Vpv"], a["Vph"])


def test_rate_clip_jump_delay(clean, tmp_path):
    f = faults()
    f["rate_x2_every_file"](clean, tmp_path / "r")
    t0, t1 = _vars(clean / "data_unh.mat")["t"], _vars(tmp_path / "r" / "data_unh.mat")["t"]
    np.testing.assert_allclose(np.diff(t1), 2 * np.diff(t0))
    f["clip_Vch_data_uch"](clean, tmp_path / "k")
    x, y = _vars(clean / "data_uch.mat")["Vch"], _vars(tmp_path / "k" / "data_uch.mat")["Vch"]
    assert np.max(np.abs(y)) == pytest.approx(0.3 * np.max(np.abs(x)))
    f["va_jump_data_huddle_test_1"](clean, tmp_path / "j", seed=5)
    d = (_vars(tmp_path / "j" / "data_huddle_test_1.mat")["Va"]
         - _vars(clean / "data_huddle_test_1.mat")["Va"])
    assert set(np.round(d / FRINGE_M, 9)) == {0.0, 1.0}
    assert 0.4 <= np.mean(d == 0) <= 0.6
    f["delay_20_Vph_Vpv_data_uch"](clean, tmp_path / "l")
    a, b = _vars(clean / "data_uch.mat"), _vars(tmp_path / "l" / "data_uch.mat")
    np.testing.assert_array_equal(b["Vph"][20:], a["Vph"][:-20])
    np.testing.assert_array_equal(b["Uch"], a["Uch"])


def test_seeded(clean, tmp_path):
    f = faults()["mains_50hz"]
    f(clean, tmp_path / "a", seed=3)
    f(clean, tmp_path / "b", seed=3)
    f(clean, tmp_path / "c", seed=4)
    assert _hashes(tmp_path / "a") == _hashes(tmp_path / "b") != _hashes(tmp_path / "c")


def test_unreadable_files(clean, tmp_path):
    f = faults()
    f["unh_unv_fifo"](clean, tmp_path / "fifo")
    assert stat.S_ISFIFO((tmp_path / "fifo" / "data_unh.mat").lstat().st_mode)
    f["unh_unv_dev_zero"](clean, tmp_path / "z")
    assert (tmp_path / "z" / "data_unv.mat").readlink() == Path("/dev/zero")
    f["unh_unv_gzip"](clean, tmp_path / "g")
    assert (tmp_path / "g" / "data_unh.mat").read_bytes()[:2] == b"\x1f\x8b"
    f["unh_unv_deleted"](clean, tmp_path / "d")
    assert not (tmp_path / "d" / "data_unv.mat").exists()
    with pytest.raises(FileExistsError):
        f["none"](clean, tmp_path / "d")
