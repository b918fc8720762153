"""MATLAB exports: frf.mat and plant.mat."""

from __future__ import annotations

from pathlib import Path

import control as ct
import numpy as np
import scipy.io

from fsmbench.bench.blocks import PlantModel
from fsmbench.ident.export import frf_variables, ss_struct, write_frf_mat, write_plant_mat
from fsmbench.ident.frf.response import spectral_matrix
from fsmbench.signal.welch import hanning


def test_plant_mat_rebuilds_the_same_systems(nominal_plant: PlantModel, tmp_path: Path) -> None:
    path = write_plant_mat(tmp_path / "plant.mat", nominal_plant)
    data = scipy.io.loadmat(path, simplify_cells=True)
    s = data["sys"]
    rebuilt = ct.ss(s["A"], s["B"], s["C"], s["D"])
    f = np.array([1.0, 100.0, 400.0])
    ours = nominal_plant.sys(2j * np.pi * f)
    theirs = rebuilt(2j * np.pi * f)
    np.testing.assert_allclose(theirs, ours, rtol=1e-12)  # the same matrices, stored as doubles
    assert list(s["OutputName"]) == list(nominal_plant.sys.output_labels)
    np.testing.assert_allclose(s["InputDelay"], [1.5e-4, 1.5e-4, 5e-4, 5e-4])
    assert data["Gd"]["InputName"].tolist() == ["Rh", "Rv"]


def test_frf_mat_uses_the_seeds_names(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    u = rng.standard_normal(30000)
    y = np.column_stack([np.convolve(u, [0.5, 0.25], "same"), u])
    frf = spectral_matrix(u, y, input_names=["Uch"], output_names=["Vph", "Vpv"],
                          window=hanning(1000), fs_hz=1e4)
    data = scipy.io.loadmat(write_frf_mat(tmp_path / "frf.mat", {"s": frf}))
    assert sorted(k for k in data if not k.startswith("__")) == [
        "coh_Uch_Vph", "coh_Uch_Vpv", "f", "tf_Uch_Vph", "tf_Uch_Vpv"]
    np.testing.assert_array_equal(data["tf_Uch_Vpv"][:, 0], frf.frf.values[:, 1, 0])


def test_static_block_struct() -> None:
    g = ct.ss([], [], [], np.diag([2.0, 3.0]), inputs=["a", "b"], outputs=["c", "d"])
    s = ss_struct(g)
    assert s["A"].shape == (0, 0) and s["B"].shape == (0, 2) and s["StateName"] == []
    np.testing.assert_array_equal(s["D"], np.diag([2.0, 3.0]))


def test_responses_on_two_grids_each_keep_their_own(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    u = rng.standard_normal(20_000)
    y = np.column_stack([u, 0.5 * u]) + 0.01 * rng.standard_normal((20_000, 2))
    a = spectral_matrix(u, y, input_names=["Uch"], output_names=["Vph", "Vpv"],
                        window=hanning(1000), fs_hz=1e4)
    b = spectral_matrix(u, y, input_names=["Unh"], output_names=["Vph", "Vpv"],
                        window=hanning(2000), fs_hz=1e4)
    v = frf_variables({"sercalo": a, "newport": b})
    assert v["frf_grid_Uch"] == "f" and v["frf_grid_Unh"] == "f_newport"
    np.testing.assert_array_equal(v["f_newport"].ravel(), b.frequency_hz)
    assert v["tf_Unh_Vph"].shape == v["f_newport"].shape
    write_frf_mat(tmp_path / "frf.mat", {"sercalo": a, "newport": b})
    m = scipy.io.loadmat(tmp_path / "frf.mat")
    assert m["f_newport"].shape == (b.frequency_hz.size, 1)
