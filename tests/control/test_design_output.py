"""A real design output folder: DesignResult.write and fsmbench_load.m run in Octave."""

from __future__ import annotations

import json
import math
import shutil
import subprocess
from importlib import resources
from pathlib import Path

import numpy as np
import pytest
import scipy.io
from scipy.interpolate import pade

from fsmbench.bench.blocks import PlantModel
from fsmbench.bench.params import Bench
from fsmbench.control.design import DesignOptions
from fsmbench.control.export import SOS_FORMAT, sos_response
from fsmbench.control.freq import evaluate_ss
from fsmbench.control.study import (
    CONTROLLERS_MAT,
    CONTROLLERS_SOS_JSON,
    MATLAB_LOADER,
    DesignResult,
    StudyOptions,
    design_study,
)
from fsmbench.ident.export import write_plant_mat
from fsmbench.io.matfile import load_mat

OCTAVE = shutil.which("octave")
F_HZ = np.array([1.0, 10.0, 100.0, 300.0])  # below the Padé approximation's range limit
PADE_ORDER = 6  # fsmbench_load's default


@pytest.fixture(scope="module")
def design(true_plant: PlantModel, bench: Bench) -> DesignResult:
    """A small design (short search, nominal robust set only): seconds, same outputs."""
    opts = StudyOptions(design=DesignOptions(max_iterations=20, extra_integrators=(3,),
                                             frequency_scales=(1.0,), damping_scales=(1.0,),
                                             per_decade=20),
                        with_seed_robustness=False)
    return design_study(true_plant, bench=bench, options=opts)


@pytest.fixture(scope="module")
def out_dir(design: DesignResult, true_plant: PlantModel,
            tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("design")
    design.write(out)
    write_plant_mat(out / "plant.mat", true_plant)  # as ``fsmbench study`` puts it alongside
    return out


def test_write_ships_the_loader_and_the_scaling(design: DesignResult, true_plant: PlantModel,
                                                out_dir: Path, tmp_path: Path) -> None:
    shipped = resources.files("fsmbench").joinpath("matlab", MATLAB_LOADER).read_text("utf-8")
    assert (out_dir / MATLAB_LOADER).read_text("utf-8") == shipped
    assert "[G, K] = fsmbench_load(OUTDIR)" in shipped  # usage in the help text
    doc = json.loads((out_dir / CONTROLLERS_SOS_JSON).read_text())
    assert doc["format"] == SOS_FORMAT and doc["discretisation"]["method"] == "tustin_prewarp"
    gd = np.diag(np.asarray(true_plant.blocks["Gd"].D, dtype=float))
    assert doc["input_scaling"]["qd_gain_v_per_rad"] == {"h": gd[0], "v": gd[1]}
    assert doc["input_scaling"]["plant_source"] == true_plant.source
    assert doc["controllers"]["seed_controller"]["h"]["input_scale_rad_per_v"] == 1 / gd[0]
    # Plain Tustin on request, in both files.
    paths = design.write(tmp_path, method="tustin")
    assert [p.name for p in paths] == [CONTROLLERS_MAT, CONTROLLERS_SOS_JSON, MATLAB_LOADER]
    plain = json.loads((tmp_path / CONTROLLERS_SOS_JSON).read_text())
    assert plain["discretisation"]["method"] == "tustin"
    assert str(load_mat(tmp_path / CONTROLLERS_MAT)["fsmbench"]["discretisation"]) == "tustin"


def _pade_error(x: np.ndarray, n: int) -> np.ndarray:
    """|P_n(jx) - exp(-jx)| of the (n, n) Padé approximant, from scipy's own Padé."""
    taylor = [(-1.0) ** k / math.factorial(k) for k in range(2 * n + 1)]
    p, q = pade(taylor, n)
    return np.abs(p(1j * x) / q(1j * x) - np.exp(-1j * x))


_SCRIPT = """
[G, K, Kd, info] = fsmbench_load('{out}');
w = 2 * pi * [{f}];
Hg = freqresp(G.sys, w);
names = {{}};
ctrl = {{'seed_controller', 'fsmbench_controller', 'newport_controller'}};
for i = 1:numel(ctrl)
  eval(sprintf('K_%d = freqresp(K.(ctrl{{i}}), w);', i));
  eval(sprintf('Kd_%d = freqresp(Kd.(ctrl{{i}}), w);', i));
  eval(sprintf('Kin_%d = strjoin(K.(ctrl{{i}}).InputName(:).'', '','');', i));
  eval(sprintf('Kout_%d = strjoin(Kd.(ctrl{{i}}).OutputName(:).'', '','');', i));
end
Gin = strjoin(G.sys.InputName(:).', ',');
Gout = strjoin(G.sys.OutputName(:).', ',');
Ts = Kd.seed_controller.Ts;
pade_order = info.pade_order;
delay = info.InputDelay;
save('-v7', '{res}', 'Hg', 'K_1', 'K_2', 'K_3', 'Kd_1', 'Kd_2', 'Kd_3', 'Kin_1', 'Kin_2', ...
     'Kin_3', 'Kout_1', 'Kout_2', 'Kout_3', 'Gin', 'Gout', 'Ts', 'pade_order', 'delay');
"""


@pytest.mark.skipif(OCTAVE is None, reason="GNU Octave is not installed (Debian: apt-get install "
                    "-y --no-install-recommends octave octave-control)")
def test_octave_loads_the_design_output(design: DesignResult, true_plant: PlantModel,
                                        out_dir: Path, tmp_path: Path) -> None:
    res = tmp_path / "octave_result.mat"
    script = _SCRIPT.format(out=out_dir, f=" ".join(repr(float(x)) for x in F_HZ), res=res)
    run = subprocess.run([str(OCTAVE), "--no-gui", "--no-window-system", "--quiet",
                          "--eval", script], capture_output=True, text=True, timeout=300,
                         cwd=out_dir, check=False)
    assert run.returncode == 0 and res.exists(), run.stdout + run.stderr
    assert "Pade approximations of order 6" in run.stdout  # Octave: the note is printed
    r = scipy.io.loadmat(res, squeeze_me=True)

    # Names and delays.
    sys = true_plant.sys
    assert str(r["Gin"]).split(",") == list(sys.input_labels)
    assert str(r["Gout"]).split(",") == list(sys.output_labels)
    np.testing.assert_array_equal(np.ravel(r["delay"]),
                                  [true_plant.input_delay_s[n] for n in sys.input_labels])
    assert int(r["pade_order"]) == PADE_ORDER and float(r["Ts"]) == design.options.loop.ts_s

    # The plant with its delays against Python's exact-delay response.
    ref = true_plant.frequency_response(F_HZ).values  # (f, out, in), exact exp(-s tau)
    oct_g = np.moveaxis(np.asarray(r["Hg"]), 2, 0)     # Octave: (out, in, f)
    x = 2 * np.pi * F_HZ[:, None] * np.array([true_plant.input_delay_s[n]
                                              for n in sys.input_labels])[None, :]
    pade_err = _pade_error(x, PADE_ORDER)  # (f, in); < 1e-13 up to 300 Hz
    assert np.max(pade_err) < 1e-12
    scale = np.max(np.abs(ref), axis=2, keepdims=True)  # per output and frequency
    # Two realisations (12 states; 36 with the Padé blocks) solved by two LU codes:
    # ~1e-13 relative; the Padé error adds per input.
    assert np.all(np.abs(oct_g - ref) <= 1e-10 * scale + pade_err[:, None, :] * np.abs(ref))

    # Controllers: continuous against Python, discrete against the JSON's sections.
    doc = json.loads((out_dir / CONTROLLERS_SOS_JSON).read_text())
    z_check = 2j * np.pi * F_HZ
    for i, name in enumerate(("seed_controller", "fsmbench_controller",
                              "newport_controller"), start=1):
        k = design.controllers[name]
        assert str(r[f"Kin_{i}"]).split(",") == list(k.input_labels)
        assert str(r[f"Kout_{i}"]).split(",") == list(k.output_labels)
        kc = np.moveaxis(np.asarray(r[f"K_{i}"]), 2, 0)
        # Cascade realisations with integrators at s = 0: ~eps / (w/w_max) at 1 Hz.
        np.testing.assert_allclose(kc, evaluate_ss(k, z_check), rtol=1e-9, atol=0)
        kd = np.moveaxis(np.asarray(r[f"Kd_{i}"]), 2, 0)
        for j, axis in enumerate("hv"):
            sos = doc["controllers"][name][axis]["sos"]
            # Poles at z = 1: relative eps / (2 pi f T)^2 per double integrator in each
            # evaluation, 5.6e-10 at 1 Hz; fsmbench's has two (measured 1.9e-9).
            np.testing.assert_allclose(kd[:, j, j], sos_response(sos, F_HZ), rtol=1e-8)
            assert np.all(kd[:, j, 1 - j] == 0)  # decentralised


@pytest.mark.skipif(OCTAVE is None, reason="GNU Octave is not installed (Debian: apt-get install "
                    "-y --no-install-recommends octave octave-control)")
def test_octave_says_what_is_missing(out_dir: Path, tmp_path: Path) -> None:
    """A design folder without plant.mat (``fsmbench design`` alone): G empty, said so;
    PadeOrder 0 leaves the delays out and says so."""
    shutil.copy(out_dir / CONTROLLERS_MAT, tmp_path / CONTROLLERS_MAT)
    script = (f"[G, K] = fsmbench_load('{tmp_path}'); assert(isempty(G)); "
              "assert(isfield(K, 'fsmbench_controller')); "
              f"[G2, K2, Kd2, info] = fsmbench_load('{tmp_path}', 'PlantDir', '{out_dir}', "
              "'PadeOrder', 0); assert(size(G2.sys.a, 1) == 12); disp(numel(info.notes))")
    run = subprocess.run([str(OCTAVE), "--no-gui", "--no-window-system", "--quiet",
                          "--eval", script], capture_output=True, text=True, timeout=300,
                         cwd=out_dir, check=False)  # where fsmbench_load.m was written
    assert run.returncode == 0, run.stdout + run.stderr
    assert f"no plant.mat in {tmp_path}: G is empty" in run.stdout
    assert "PadeOrder is 0: G.sys has NO input delays" in run.stdout
