"""An identified bench: the user's recordings, simulated by the one engine.

A bench of our own (``tests/data/benches/stiff_bench.toml``: other resonances,
damping, gains and 4QD noise) is simulated, identified with the packaged bench
file, and the identification folder becomes a bench every command simulates
(``--bench DIR``). Checked against independent references: the identified
plant's own frequency response (the engine's discrete plant must be its exact
sampled version), the identification's own values (a bench identified from the
simulation of an identified bench is that bench again), the closed-form
feedthrough of a held input, and the true bench (what the recordings came from).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from fsmbench.bench.params import Bench, default_bench, load_bench
from fsmbench.bench.perturbed import perturbed_identified
from fsmbench.cli import main
from fsmbench.ident.pipeline import identify, write_identification
from fsmbench.io.errors import RecordingError
from fsmbench.sim.discretize import zoh_with_delays
from fsmbench.sim.plant import ADC_CHANNELS, DAC_CHANNELS, bench_discrete
from fsmbench.twin import simulate_bench
from fsmbench.twin.compare import TARGETS
from fsmbench.twin.identified import identified_bench

STIFF = Path(__file__).resolve().parents[1] / "data" / "benches" / "stiff_bench.toml"
IDENT = ("data_cal_pd_h", "data_cal_pd_v", "data_uch", "data_ucv", "data_unh", "data_unv")
HUDDLE = ("data_huddle_test_1", "data_huddle_test_2", "data_huddle_test_4")


@pytest.fixture(scope="module")
def stiff() -> Bench:
    return load_bench(STIFF)


@pytest.fixture(scope="module")
def folder(stiff: Bench, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The stiff bench identified with the packaged bench file (recorded data: no truth)."""
    run = simulate_bench(stiff, seed=4, experiments=IDENT)
    huddle = simulate_bench(stiff, seed=4, duration_s=21.0, experiments=HUDDLE)
    out = tmp_path_factory.mktemp("stiff-identified")
    ident = identify({**run.recordings, **huddle.recordings}, bench=default_bench(),
                     source="stiff bench")
    assert ident.noise_model is not None and not ident.warnings
    write_identification(ident, out)
    return out


@pytest.fixture(scope="module")
def identified(folder: Path) -> Bench:
    return identified_bench(folder, bench=default_bench())


def test_the_engine_plant_is_the_identified_plant_sampled(identified: Bench) -> None:
    """Below 1 kHz the engine's discrete plant is the identified model held and sampled."""
    model = identified.model
    assert model is not None
    plant = bench_discrete(identified)
    f = np.array([1.0, 10.0, 100.0, 250.0, 415.0, 1000.0])
    h = plant.frequency_response(f)
    ts = identified.true.converter.ts_s
    for out, inp in (("Vph", "Uch"), ("Vpv", "Ucv"), ("Vph", "Unh"), ("Vpv", "Unv")):
        cont = model.plant.frequency_response(f, outputs=[out], inputs=[inp]).values[:, 0, 0]
        disc = h[:, ADC_CHANNELS.index(out), DAC_CHANNELS.index(inp)]
        # The identification's delay holds the hold's half sample; the hold's amplitude
        # droop is sinc(f T). What is left is the sampling of the model's own dynamics,
        # O((2π f T)²) relative: 0.4 % at 1 kHz, 1e-6 at 1 Hz.
        rel = np.abs(disc / (cont * np.sinc(f * ts)) - 1.0)
        assert np.all(rel <= 1e-5 + 0.5 * (2 * np.pi * f * ts) ** 2), (out, inp, rel)


def test_a_held_feedthrough_is_the_command_of_its_delay() -> None:
    """y = D u(t − τ) with a hold: at sample k the command of sample k − ceil(τ/T), exactly."""
    d = np.array([[2.5]])
    for delay, lag in ((1.0, 1), (1.3, 2), (2.0, 2), (2.7, 3)):
        plant = zoh_with_delays(np.zeros((1, 1)), np.zeros((1, 1)), np.zeros((1, 1)),
                                d=d, ts_s=1e-4, input_delay_samples=[delay],
                                input_names=["u"], output_names=["y"])
        u = np.arange(1.0, 11.0)
        z = np.zeros(plant.a.shape[0])
        y = []
        for uk in u:
            y.append(float((plant.c @ z)[0]))
            z = plant.a @ z + plant.b[:, 0] * uk
        assert y == [0.0] * lag + list(2.5 * u[:len(u) - lag]), (delay, y)
    with pytest.raises(ValueError, match="direct feedthrough and no delay"):
        zoh_with_delays(np.zeros((1, 1)), np.zeros((1, 1)), np.zeros((1, 1)), d=d, ts_s=1e-4,
                        input_delay_samples=[0.0], input_names=["u"], output_names=["y"])


def test_the_identified_bench_says_where_each_part_comes_from(identified: Bench,
                                                              folder: Path) -> None:
    model = identified.model
    assert model is not None and identified.is_identified
    assert identified.label == f"the bench identified in {folder}"
    prov = model.provenance
    assert prov["Sercalo"].startswith("measured") and prov["Newport"].startswith("measured")
    assert prov["4QD gain and compression"].startswith("measured")
    assert prov["noise: quad_diode.noise_rms_v"].startswith("measured")
    assert prov["Newport angle noise, optics, environment, converters"].startswith("assumed")
    # The engine reads the fitted noise, not the bench file's.
    fit = model.noise_fit
    assert identified.true.quad_diode.noise_rms_v.h == fit["noise_rms_v"]["h"]["value"]
    nominal = default_bench().nominal.quad_diode.noise_rms_v
    assert identified.true.quad_diode.noise_rms_v.h != nominal.h


def test_simulating_the_identified_bench_gives_back_its_identification(
        identified: Bench, stiff: Bench) -> None:
    """Round trip: the records of an identified bench identify as that bench (its targets)."""
    run = simulate_bench(identified, seed=9, experiments=IDENT)
    assert run.truth["bench"]["kind"] == "identified"
    again = identify(run.recordings, bench=default_bench(), source="identified bench")
    js = again.to_json()
    truth = run.truth
    for axis in "hv":
        for key in ("resonance_hz", "damping_ratio", "dc_gain_v_per_a"):
            kind, tol = TARGETS[f"sercalo.{axis}.{key}"]
            got, want = js["sercalo"][axis][key], truth["sercalo"][axis][key]
            assert kind == "rel" and abs(got / want - 1) <= tol, (axis, key, got, want)
        kind, tol = TARGETS[f"qd_gain_v_per_rad.{axis}"]
        assert abs(js["qd_gain_v_per_rad"][axis] / truth["qd_gain_v_per_rad"][axis] - 1) <= tol
    # And the identified bench is the stiff bench, not the packaged one (resonance 0.5 %).
    for axis in "hv":
        assert js["sercalo"][axis]["resonance_hz"] == pytest.approx(
            stiff.true.sercalo.resonance_hz[axis], rel=0.005)


def test_a_folder_without_a_sercalo_is_refused_in_one_line(tmp_path: Path) -> None:
    run = simulate_bench(default_bench(), seed=1, experiments=["data_cal_pd_h", "data_cal_pd_v"])
    write_identification(identify(run.recordings, bench=default_bench(), source="t"), tmp_path)
    with pytest.raises(RecordingError, match="has no identified Sercalo"):
        identified_bench(tmp_path, bench=default_bench())


def test_a_perturbation_moves_the_identified_modes_and_keeps_their_gain(
        identified: Bench) -> None:
    from fsmbench.twin.draws import PARAMETERS

    factors = dict.fromkeys(PARAMETERS, 1.0) | {"dac_delay_offset_s": 0.0,
                                                 "newport_delay_offset_s": 0.0,
                                                 "resonance_scale.h": 1.03,
                                                 "damping_scale.v": 2.0}
    moved = perturbed_identified(identified, factors)
    assert moved.model is not None and identified.model is not None
    f0 = identified.model.values["sercalo"]["h"]["resonance_hz"]
    poles = np.linalg.eigvals(np.asarray(moved.model.plant.blocks["Gc"].A))
    near = poles[np.argmin(np.abs(np.abs(poles) - 2 * np.pi * f0 * 1.03))]
    assert abs(near) / (2 * np.pi) == pytest.approx(f0 * 1.03, rel=1e-9)
    # The mode's static gain is kept (the mass-spring's DC gain does not move with it).
    dc_before = identified.model.plant.dc_gain(output="Vph", input="Uch")
    dc_after = moved.model.plant.dc_gain(output="Vph", input="Uch")
    assert dc_after == pytest.approx(dc_before, rel=1e-6)
    assert moved.model.values["sercalo"]["v"]["damping_ratio"] == pytest.approx(
        2.0 * identified.model.values["sercalo"]["v"]["damping_ratio"])


# ----------------------------------------------------------------------------- --bench DIR


def test_simulate_bench_dir_writes_the_identified_benchs_records(folder: Path,
                                                                 tmp_path: Path) -> None:
    out = tmp_path / "sim"
    assert main(["simulate", str(out), "--bench", str(folder), "--duration", "5",
                 "--experiments", "data_uch", "data_rep_h"]) == 0
    truth = json.loads((out / "twin_truth.json").read_text())
    assert truth["bench"]["kind"] == "identified"
    ident = json.loads((folder / "identification.json").read_text())
    assert truth["sercalo"] == ident["sercalo"]


def test_design_runs_its_closed_loop_check_on_the_identified_bench(
        folder: Path, tmp_path: Path, stiff: Bench) -> None:
    data = tmp_path / "data"
    assert main(["simulate", str(data), "--params", str(STIFF), "--duration", "5",
                 "--experiments", "data_uch"]) == 0
    out = tmp_path / "design"
    assert main(["design", str(data), "--out", str(out), "--bench", str(folder)]) == 0
    design = json.loads((out / "design.json").read_text())
    assert design["closed_loop_twin"]["bench_kind"] == "identified"
    assert design["closed_loop_twin"]["bench"] == f"the bench identified in {folder}"


def test_excite_checks_its_limits_on_the_identified_bench(folder: Path, tmp_path: Path) -> None:
    out = tmp_path / "exc"
    assert main(["excite", str(out), "--input", "Uch", "--amplitude-rms", "0.005",
                 "--band", "1", "1000", "--resolution", "1", "--periods", "2",
                 "--bench", str(folder)]) == 0
    meta = json.loads((out / "excitation.json").read_text())
    assert f"bench identified in {folder}" in json.dumps(meta)


def test_bench_dir_must_be_a_folder(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    toml = tmp_path / "b.toml"
    toml.write_text("base = \"default\"\n")
    assert main(["simulate", str(tmp_path / "o"), "--bench", str(toml)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--bench needs a folder" in err[0]


def test_montecarlo_draws_around_the_identified_bench(folder: Path, tmp_path: Path) -> None:
    out = tmp_path / "mc"
    assert main(["montecarlo", "--bench", str(folder), "--out", str(out), "--n", "2",
                 "--workers", "1"]) == 0
    doc = json.loads((out / "montecarlo.json").read_text())
    assert doc["bench_kind"] == "identified"
    assert doc["bench"] == f"the bench identified in {folder}"
    ident = json.loads((folder / "identification.json").read_text())
    for row in doc["draws"]:
        # Each draw's resonance is the identified one times its factor.
        for axis in "hv":
            assert row["parameters"]["sercalo"]["resonance_hz"][axis] == pytest.approx(
                ident["sercalo"][axis]["resonance_hz"] * row["factors"]["resonance_scale"][axis])


def test_the_live_twin_runs_the_identified_bench(identified: Bench) -> None:
    from fsmbench.live.backend import TwinBackend

    backend = TwinBackend(identified, seed=0)
    block = backend.step(200)
    assert np.all(np.isfinite(block.signals["Vph"]))
    # The live stream steps the identified plant, not the packaged physics.
    assert np.array_equal(backend.stream.plant.a, bench_discrete(identified).a)
