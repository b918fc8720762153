"""Monte Carlo of the closed loop on the twin: reproducible, equal on Dask and in one process."""

from __future__ import annotations

import json
import math
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pytest

pytest.importorskip("distributed")

from fsmbench.bench.blocks import physical_plant
from fsmbench.bench.params import Bench, default_bench
from fsmbench.cli import main
from fsmbench.control.analysis import control_objective
from fsmbench.control.controller import Controller
from fsmbench.control.export import InputScaling, write_controllers_mat
from fsmbench.control.loops import LoopOptions, analyse_loop
from fsmbench.scale.montecarlo import (
    METRICS,
    PARAMETERS,
    RANGE_OF_PARAMETER,
    DrawResult,
    MonteCarloSetup,
    Ranges,
    draw_parameters,
    run_draw,
    run_montecarlo,
)
from fsmbench.scale.montecarlo_run import (
    dask_client,
    designed_controller,
    loaded_controller,
    read_ranges,
)
from fsmbench.sim.controller import feedback_controller
from fsmbench.twin.verify import verify_on_twin

N = 6  # draws of the equality checks
DURATION_S = 5.0  # the shortest record the repeatability experiments accept is 4.5 s
SETTLE_S = 2.0


@pytest.fixture(scope="module")
def bench() -> Bench:
    return default_bench()


@pytest.fixture(scope="module")
def controller(bench: Bench) -> Controller:
    return designed_controller(bench)


@pytest.fixture(scope="module")
def setup(bench: Bench, controller: Controller) -> MonteCarloSetup:
    return MonteCarloSetup(bench=bench, controller=controller, duration_s=DURATION_S,
                           settle_s=SETTLE_S)


@pytest.fixture(scope="module")
def client() -> Iterator[Any]:
    with dask_client(scheduler=None, workers=2) as c:
        yield c


@pytest.fixture(scope="module")
def reference(setup: MonteCarloSetup) -> Any:
    return run_montecarlo(setup, n=N, seed=11)


def _rows(draws: Sequence[DrawResult]) -> dict[str, np.ndarray]:
    out = {k: np.array([d.metrics[k] for d in draws]) for k in METRICS}
    out.update({k: np.array([d.factors[k] for d in draws]) for k in PARAMETERS})
    out["noise_seed"] = np.array([d.noise_seed for d in draws])
    out["index"] = np.array([d.index for d in draws])
    return out


def _assert_identical(a: Sequence[DrawResult], b: Sequence[DrawResult]) -> None:
    ra, rb = _rows(a), _rows(b)
    for key in ra:
        assert np.array_equal(ra[key], rb[key], equal_nan=True), key


def test_cluster_equals_single_process(setup: MonteCarloSetup, client: Any,
                                       reference: Any) -> None:
    assert [d.index for d in reference.draws] == list(range(N))
    assert all(d.stable for d in reference.draws)
    on_cluster = run_montecarlo(setup, n=N, seed=11, client=client)
    _assert_identical(reference.draws, on_cluster.draws)
    one_per_task = run_montecarlo(setup, n=N, seed=11, client=client, batch_size=1)
    _assert_identical(reference.draws, one_per_task.draws)


def test_draws_depend_on_the_seed_only(setup: MonteCarloSetup, reference: Any) -> None:
    ranges = Ranges()
    a = draw_parameters(seed=11, n=N, ranges=ranges)
    assert a == draw_parameters(seed=11, n=N, ranges=ranges)
    # Draw i comes from spawn(n)[i]: a shorter run is a prefix of a longer one.
    assert a[:3] == draw_parameters(seed=11, n=3, ranges=ranges)
    other = draw_parameters(seed=12, n=N, ranges=ranges)
    assert all(x.factors != y.factors and x.noise_seed != y.noise_seed
               for x, y in zip(a, other, strict=True))
    for d in a:
        for key, value in d.factors.items():
            lo, hi = getattr(ranges, RANGE_OF_PARAMETER[key])
            assert lo <= value <= hi, key
    # The rows of the reference run are those draws, and the metrics differ between draws.
    assert [r.factors for r in reference.draws] == [dict(d.factors) for d in a]
    assert np.unique(_rows(reference.draws)["tracking_error_rms_rad.h"]).size == N


def test_defaults_are_the_design_robust_set_and_identification_targets() -> None:
    from fsmbench.control.design import DesignOptions
    from fsmbench.twin.compare import TARGETS

    r, opts = Ranges(), DesignOptions()
    assert r.resonance_scale == (min(opts.frequency_scales), max(opts.frequency_scales))
    assert r.damping_scale == (min(opts.damping_scales), max(opts.damping_scales))
    assert r.newport_gain_scale == pytest.approx((1 - TARGETS["newport_gain_v_per_v.h"][1],
                                                  1 + TARGETS["newport_gain_v_per_v.h"][1]))
    # Delay targets are in samples; the ranges in seconds at the packaged bench's 10 kHz.
    assert TARGETS["delay_s.sercalo"] == TARGETS["delay_s.newport"] == ("samples", 1.0)
    assert r.dac_delay_s == r.newport_delay_s == (-1e-4, 1e-4)


def test_nominal_draw_is_verify_on_twin(bench: Bench, controller: Controller) -> None:
    nominal = MonteCarloSetup(bench=bench, controller=controller, ranges=Ranges.nominal(),
                              duration_s=DURATION_S, settle_s=SETTLE_S)
    draw = draw_parameters(seed=3, n=1, ranges=nominal.ranges)[0]
    row = run_draw(draw, nominal)
    gd = bench.nominal.quad_diode.gain_v_per_rad  # what controller.feedback divides by
    check = verify_on_twin(controller.continuous, bench=bench, plant=physical_plant(bench.true),
                           name="fsmbench controller", seed=draw.noise_seed,
                           duration_s=DURATION_S, settle_s=SETTLE_S, gd_v_per_rad=(gd.h, gd.v))
    # Same noise streams, same controller arithmetic: the same numbers, bit for bit.
    for axis in "hv":
        assert row.metrics[f"tracking_error_rms_rad.{axis}"] == check.measured_rms_rad[axis]
        # The study's criterion (report summary): measured / predicted within 0.9-1.1.
        assert 0.9 <= check.ratio[axis] <= 1.1
    # The twin's controller is the one verify_on_twin builds.
    ref = feedback_controller(controller.continuous,
                              gd_v_per_rad=bench.nominal.quad_diode.gain_v_per_rad,
                              ts_s=bench.true.converter.ts_s)
    mine = controller.feedback
    for m in "abcd":
        assert np.array_equal(getattr(mine, m), getattr(ref, m))
    # Margins against the design study's discrete-loop margins (analyse_loop), on its own
    # grid: both refine crossings on the exact response, so only root-finding tolerance
    # (~1e-9 relative) separates them; 1e-6 leaves room for it.
    loop = analyse_loop(physical_plant(bench.true), controller.continuous,
                        objective=control_objective(bench.nominal),
                        options=LoopOptions(ts_s=bench.true.converter.ts_s))
    assert loop.discrete is not None
    for axis in "hv":
        ref_m = loop.discrete.margins[axis]
        assert row.metrics[f"gain_margin_db.{axis}"] == pytest.approx(ref_m.gain_margin_db,
                                                                      rel=1e-6)
        assert row.metrics[f"phase_margin_deg.{axis}"] == pytest.approx(
            ref_m.phase_margin_deg, rel=1e-6)
        assert row.metrics[f"modulus_margin.{axis}"] == pytest.approx(ref_m.modulus_margin,
                                                                      rel=1e-6)
    # The slowest time constant is the spectral radius's: -T / ln(rho).
    assert row.metrics["slowest_time_constant_s"] == pytest.approx(
        -1e-4 / math.log(row.metrics["spectral_radius"]), rel=1e-12)
    assert 20 * row.metrics["slowest_time_constant_s"] < SETTLE_S


def test_loaded_controller_runs_like_the_design(tmp_path: Path, bench: Bench,
                                                controller: Controller) -> None:
    gd = bench.nominal.quad_diode.gain_v_per_rad
    path = write_controllers_mat(tmp_path / "controllers.mat",
                                 {"fsmbench_controller": controller.continuous}, ts_s=1e-4,
                                 method="tustin",
                                 scaling=InputScaling(qd_gain_v_per_rad=(gd.h, gd.v),
                                                      plant_source="physical (nominal)"))
    loaded = loaded_controller(path, name=None, bench=bench)
    assert loaded.name == "fsmbench_controller"
    ranges = Ranges.nominal()
    draw = draw_parameters(seed=4, n=1, ranges=ranges)[0]
    a = run_draw(draw, MonteCarloSetup(bench=bench, controller=controller, ranges=ranges,
                                       duration_s=DURATION_S, settle_s=SETTLE_S))
    b = run_draw(draw, MonteCarloSetup(bench=bench, controller=loaded, ranges=ranges,
                                       duration_s=DURATION_S, settle_s=SETTLE_S))
    for key in METRICS:
        # Same Tustin controller, possibly another state basis: rounding differences in the
        # closed loop, amplified by the lightly damped loop over 5e4 steps, stay far below 1e-6.
        assert b.metrics[key] == pytest.approx(a.metrics[key], rel=1e-6), key


def test_destabilising_range_marks_draws_unstable(bench: Bench,
                                                  controller: Controller) -> None:
    # Current-amplifier gain ×20 (26 dB) exceeds the ~14 dB gain margin.
    ranges = Ranges(current_amp_gain_scale=(20.0, 20.0))
    setup = MonteCarloSetup(bench=bench, controller=controller, ranges=ranges,
                            duration_s=DURATION_S, settle_s=SETTLE_S)
    result = run_montecarlo(setup, n=2, seed=0)
    assert all(not d.stable and d.metrics["spectral_radius"] >= 1.0 for d in result.draws)
    assert all(math.isnan(d.metrics["tracking_error_rms_rad.h"]) for d in result.draws)
    doc = result.to_json()
    assert doc["fraction_unstable"] == 1.0
    assert doc["quantiles"]["tracking_error_rms_rad"]["h"]["n"] == 0
    json.dumps(doc, allow_nan=False)


def test_json_is_stamped_and_documented(reference: Any) -> None:
    doc = reference.to_json()
    assert (doc["format"], doc["format_version"]) == ("fsmbench.montecarlo", 3)
    assert list(doc)[:2] == ["format", "format_version"]
    json.dumps(doc, allow_nan=False)
    for key in ("fsmbench_version", "seed", "n", "controller", "ranges", "duration_s",
                "settle_s", "quantiles", "fraction_unstable", "unsettled_draws", "worst_draws",
                "draws", "metric_descriptions", "parameter_descriptions"):
        assert key in doc, key
    assert len(doc["draws"]) == N and len(doc["worst_draws"]) == 5
    for key in METRICS:
        q = _at(doc["quantiles"], key)
        x = reference.metric(key)
        assert q["n"] == N
        assert q["min"] <= q["p5"] <= q["p50"] <= q["p95"] <= q["max"] == np.max(x)
        assert q["p50"] == pytest.approx(float(np.median(x)), rel=1e-12)
    worst = doc["worst_draws"][0]["metrics"]["tracking_error_rms_rad"]
    tracking = doc["quantiles"]["tracking_error_rms_rad"]
    assert max(worst.values()) == max(tracking["h"]["max"], tracking["v"]["max"])
    # Keys are ids (docs/results.md): no dots; (h, v) pairs are objects.
    text = json.dumps(doc)
    assert '.h"' not in text and '.v"' not in text
    assert set(doc["draws"][0]["factors"]["resonance_scale"]) == {"h", "v"}
    assert _at(doc["metric_descriptions"], "tracking_error_rms_rad.h") == (
        "tracking error h (4QD, sine and noise) [µrad rms]")


def _at(tree: dict[str, Any], dotted: str) -> Any:
    for part in dotted.split("."):
        tree = tree[part]
    return tree


def test_cli_writes_json_and_prints_table(tmp_path: Path, client: Any,
                                          capsys: pytest.CaptureFixture[str]) -> None:
    ranges = tmp_path / "ranges.toml"
    ranges.write_text("resonance_scale = [0.9, 1.1]\ndac_delay_s = [0, 0]\n")
    docs = []
    for where, how in (("one", ["--workers", "1"]),
                       ("scheduler", ["--scheduler", client.scheduler.address])):
        out = tmp_path / where
        argv = ["montecarlo", "--twin", "--out", str(out), "--n", "3", "--duration",
                str(DURATION_S), "--seed", "2", "--ranges", str(ranges), *how]
        assert main(argv) == 0
        doc = json.loads((out / "montecarlo.json").read_text())
        assert doc["format"] == "fsmbench.montecarlo" and doc["n"] == 3
        assert doc["ranges"]["resonance_scale"] == [0.9, 1.1]
        assert all(r["factors"]["dac_delay_offset_s"] == 0.0 for r in doc["draws"])
        assert (out / "run.json").is_file()
        printed = capsys.readouterr().out
        assert "3 draws, random seed 2" in printed and "tracking error h" in printed
        assert "worst draws" in printed
        docs.append(doc)
    # The running scheduler gives the file the process gives.
    assert docs[0] == docs[1]


def test_cli_refuses_unclear_input(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    for argv, message in (
            (["--out", str(tmp_path / "o")], "give one of a DATA folder, --bench DIR or --twin"),
            ([str(tmp_path), "--twin", "--out", str(tmp_path / "o")],
             "give one of a DATA folder, --bench DIR or --twin"),
            (["--twin", "--out", str(tmp_path / "o"), "--settle", "6"], "leaves nothing"),
            (["--twin", "--out", str(tmp_path / "o"), "--duration", "3"],
             "--duration 3 s is too short for data_rep_h, data_rep_v")):
        assert main(["montecarlo", *argv]) == 2
        assert message in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_bad_ranges_file_is_one_line(tmp_path: Path) -> None:
    bad = tmp_path / "r.toml"
    bad.write_text("resonance = [0.9, 1.1]\n")
    with pytest.raises(ValueError, match=r"r\.toml: unknown range\(s\) resonance;"):
        read_ranges(bad)
    bad.write_text("damping_scale = [2.0, 0.5]\n")
    with pytest.raises(ValueError, match=r"r\.toml: range damping_scale must be .* low <= high"):
        read_ranges(bad)
    bad.write_text("qd_gain_scale = 1.0\n")
    with pytest.raises(ValueError, match=r"r\.toml: 'qd_gain_scale' must be a pair"):
        read_ranges(bad)
