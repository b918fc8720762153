"""The loop compiled for one plant equals the generic loop bit for bit."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from fsmbench.bench.esrf import esrf_decentralised_controller
from fsmbench.bench.params import Bench
from fsmbench.sim import codegen
from fsmbench.sim.controller import feedback_controller
from fsmbench.sim.engine import Quantiser, run_loop
from fsmbench.sim.plant import ADC_CHANNELS, twin_discrete


def test_unrolled_loop_is_bit_identical_to_the_generic_one(bench: Bench) -> None:
    plant = twin_discrete(bench.true)
    rng = np.random.default_rng(3)
    n = 20000
    u = np.zeros((n, 4))
    u[:, 0] = 0.02 * rng.standard_normal(n)
    u[:, 3] = 0.1 * rng.standard_normal(n)
    noise = 1e-3 * rng.standard_normal((n, len(ADC_CHANNELS)))
    conv = Quantiser(range_v=20.0, bits=16)
    k = feedback_controller(esrf_decentralised_controller(),
                            gd_v_per_rad=bench.nominal.quad_diode.gain_v_per_rad, ts_s=1e-4)
    runs = [run_loop(plant, u_ext=u, adc_noise=noise, adc=conv, dac=conv, controller=k,
                     n_adc=len(ADC_CHANNELS), specialise=spec) for spec in (False, True)]
    for field in ("adc", "dac", "internal"):
        np.testing.assert_array_equal(getattr(runs[0], field), getattr(runs[1], field))


def test_source_has_the_coefficients_as_literals(bench: Bench) -> None:
    plant = twin_discrete(bench.true)
    src = codegen.kernel_source(plant)
    assert "c_val[q]" not in src and "ab_val[q]" not in src  # no indirect products left
    assert f"{float(plant.a[0, 0])!r} * zu[0]" in src
    compile(src, "kernel", "exec")  # valid Python


def test_kernel_is_built_once_and_cached_on_disk(bench: Bench, tmp_path: Path,
                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    codegen._load.cache_clear()
    plant = twin_discrete(bench.true)
    first = codegen.specialised_kernel(plant)
    assert codegen.specialised_kernel(plant) is first
    files = list((tmp_path / "fsmbench" / "kernels").glob("fsmbench_kernel_*.py"))
    assert len(files) == 1 and files[0].read_text() == codegen.kernel_source(plant)


def test_unwritable_cache_falls_back_to_a_temporary_folder(bench: Bench, tmp_path: Path,
                                                           monkeypatch: pytest.MonkeyPatch) -> None:
    blocker = tmp_path / "not-a-folder"
    blocker.write_text("x")
    monkeypatch.setenv("XDG_CACHE_HOME", str(blocker))
    codegen._load.cache_clear()
    kernel = codegen.specialised_kernel(twin_discrete(bench.true))
    assert callable(kernel)
    codegen._load.cache_clear()
