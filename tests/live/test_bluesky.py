"""Bluesky drives the live bench: fsmbench's ophyd-async devices and plans, over Tango and EPICS.

Each protocol's server is a real ``fsmbench serve`` process (``--nodb`` Tango device, or
the IOC on a private Channel Access port) at ``--speed 100``; this process runs a
RunEngine. The devices read the attribute table's units through each control system,
commands answer with the device's reply or raise its refusal, and the study's plans record
the open-loop and closed-loop identification experiments whose identification is judged
against the twin's truth with the open-loop identification's own targets
(:data:`fsmbench.twin.compare.TARGETS`).
"""

from __future__ import annotations

import json
import os
import sys
import uuid
from collections.abc import Iterator
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest

pytest.importorskip("bluesky")
pytest.importorskip("ophyd_async")

from fsmbench.bench.params import default_bench
from fsmbench.live.attributes import ATTRIBUTES, ca_units, precision
from fsmbench.twin.compare import TARGETS, comparison_rows
from fsmbench.twin.truth import model_values

BENCH = default_bench()
SERVE = [sys.executable, "-m", "fsmbench.cli", "serve"]
SPEED = "100"  # the highest SpeedFactor: the records take seconds of wall clock
#: Channel Access array size (the spectra: 8193 doubles) for the client in this process.
MAX_ARRAY_BYTES = "4000000"


@pytest.fixture(scope="module")
def run_engine() -> Any:
    from bluesky import RunEngine

    return RunEngine({}, call_returns_result=True)


@pytest.fixture(scope="module")
def excitations() -> dict[str, np.ndarray]:
    """One design of the closed-loop excitations, played on both protocols."""
    from fsmbench.live.plans import design_excitations

    return design_excitations(model=BENCH)


@pytest.fixture(scope="module", params=["tango", "epics"])
def live(request: pytest.FixtureRequest, parts: SimpleNamespace,
         tmp_path_factory: pytest.TempPathFactory, run_engine: Any) -> Iterator[Any]:
    """A served bench, its ophyd-async device connected in the RunEngine's loop."""
    from ophyd_async.plan_stubs import ensure_connected

    from fsmbench.live.ophyd import bench_device

    protocol = request.param
    if protocol == "tango":
        pytest.importorskip("tango")
    else:
        pytest.importorskip("softioc")
        pytest.importorskip("aioca")
    folder = tmp_path_factory.mktemp(f"bluesky-{protocol}")
    out = folder / "out"
    saved = dict(os.environ)
    if protocol == "tango":
        port = parts.free_port()
        args = [*SERVE, "--nodb", "--port", str(port), "--speed", SPEED, "--out", str(out)]
        address = f"tango://127.0.0.1:{port}/fsmbench/bench/1#dbase=no"
        ready = "Ready to accept request"  # Tango's own line: the device is exported
    else:
        prefix = f"FSMB{uuid.uuid4().hex[:6].upper()}"
        # A private CA port, set before this process's first Channel Access context (aioca
        # makes it on first use and reads the environment then).
        os.environ.update({"EPICS_CA_SERVER_PORT": str(parts.free_port()),
                           "EPICS_CA_ADDR_LIST": "127.0.0.1", "EPICS_CA_AUTO_ADDR_LIST": "NO",
                           "EPICS_CA_MAX_ARRAY_BYTES": MAX_ARRAY_BYTES,
                           "EPICS_PVAS_SERVER_PORT": str(parts.free_port()),
                           "EPICS_PVAS_BROADCAST_PORT": str(parts.free_port())})
        args = [*SERVE, "--protocol", "epics", "--prefix", prefix, "--speed", SPEED, "--out",
                str(out)]
        address = f"ca://{prefix}"
        ready = "fsmbench serve: IOC"
        pyepics_ca = sys.modules.get("epics.ca")
        if pyepics_ca is not None:
            # ophyd-async attaches to pyepics' context when pyepics is imported (test_epics
            # imports it): made here, on the main thread with these ports, as test_epics
            # makes its own (made on the RunEngine's thread, pyepics could not attach it).
            pyepics_ca.initialize_libca()
    server = parts.start(args, env=dict(os.environ), folder=folder, name=protocol,
                         ready=ready)
    try:
        device = bench_device(address)
        run_engine(ensure_connected(device, timeout=parts.WAIT_S))
        def loop_closed() -> bool:
            import bluesky.plan_stubs as bps

            def read() -> Any:
                return (yield from bps.rd(device.loop_closed))

            return bool(run_engine(read()).plan_result)

        yield SimpleNamespace(protocol=protocol, device=device, folder=folder, out=out,
                              device_loop_closed=loop_closed)
    finally:
        if protocol == "epics":
            _clear_channels()
        server.stop()
        os.environ.clear()
        os.environ.update(saved)


def _clear_channels() -> None:
    """Clear the channels on the RunEngine's thread (their context's), while the IOC is up,
    then finish pyepics' context when there is one (test_epics then makes its own, with
    its ports). Left to aioca's exit handler, the channels were cleared from the main
    thread after test_epics had finished its context, and the process hung at exit."""
    from aioca import purge_channel_caches
    from bluesky.run_engine import call_in_bluesky_event_loop

    async def purge() -> None:
        purge_channel_caches()

    call_in_bluesky_event_loop(purge())
    pyepics_ca = sys.modules.get("epics.ca")
    if pyepics_ca is not None:
        pyepics_ca.finalize_libca()


def _call(run_engine: Any, plan: Any) -> Any:
    return run_engine(plan).plan_result


def test_devices_read_units_and_commands_answer(live: Any, run_engine: Any) -> None:
    import bluesky.plan_stubs as bps
    import bluesky.plans as bp

    from fsmbench.live.ophyd import BenchState, CommandRefusedError
    from fsmbench.live.plans import execute

    bench = live.device
    docs: list[tuple[str, dict[str, Any]]] = []
    token = run_engine.subscribe(lambda name, doc: docs.append((name, doc)))
    try:
        run_engine(bp.count([bench], num=2))
    finally:
        run_engine.unsubscribe(token)
    events = [d for n, d in docs if n == "event"]
    (descriptor,) = [d for n, d in docs if n == "descriptor"]
    assert len(events) == 2
    # The same signal names on both protocols, the units and precisions of the attribute
    # table as each control system carries them (Tango's unit; EPICS' 7-character EGU).
    specs = {spec.name: spec for spec in ATTRIBUTES}
    from fsmbench.live.ophyd import READ_SIGNALS

    assert set(descriptor["data_keys"]) == {f"fsm_bench-{k}" for k in READ_SIGNALS}
    for key, attr in READ_SIGNALS.items():
        spec, data_key = specs[attr], descriptor["data_keys"][f"fsm_bench-{key}"]
        unit = spec.unit if live.protocol == "tango" else ca_units(spec.egu)
        assert (data_key["units"], data_key["precision"]) == (unit, precision(spec.fmt)), key
    config = descriptor["configuration"]["fsm_bench"]["data"]
    assert config["fsm_bench-speed_factor"] == float(SPEED)
    assert config["fsm_bench-loop_closed"] is False
    assert np.all(np.isfinite([events[-1]["data"][f"fsm_bench-{k}"] for k in READ_SIGNALS]))

    def commands() -> Any:
        yield from bps.trigger(bench.close_loop, wait=True)
        state = yield from bps.rd(bench.state)
        with pytest.raises(CommandRefusedError) as again:
            yield from execute(bench.close_loop)
        with pytest.raises(CommandRefusedError) as outside:
            yield from execute(bench.load_controller, "/etc/passwd")
        path = yield from execute(bench.record, json.dumps(
            {"signals": ["Vph", "Vpv"], "duration_s": 0.5, "name": "bluesky_record"}))
        from fsmbench.live.plans import wait_until_done

        after = yield from wait_until_done(bench, "the record")
        reply = yield from execute(bench.open_loop)
        return state, again.value, outside.value, path, after, reply

    state, again, outside, path, after, reply = _call(run_engine, commands())
    assert state == BenchState.RUNNING
    # The device's reason codes and sentences, the same on both protocols.
    assert again.reason == "FSM_NotAllowed" and "already closed" in again.sentence
    assert outside.reason == "FSM_BadArgument" and "outside the controllers folder" in \
        outside.sentence and "root:" not in outside.sentence
    assert Path(path) == live.out.resolve() / "bluesky_record.mat" and Path(path).is_file()
    assert after == BenchState.RUNNING
    assert reply == "loop opened, holding the last command"

    # A plan the device refuses mid-way fails with the refusal and leaves the bench as it
    # found it: 20 V commands are beyond the DAC's +/-10 V, refused once the plan has
    # closed the loop; the plan opens it again.
    from fsmbench.live.plans import closed_loop_experiments

    too_large = {ch: np.full(400, 20.0) for ch in ("Uch", "Ucv")}
    stops: list[dict[str, Any]] = []
    token = run_engine.subscribe(lambda name, doc: stops.append(doc) if name == "stop" else None)
    try:
        with pytest.raises(CommandRefusedError) as refused:
            run_engine(closed_loop_experiments(bench, live.folder / "refused",
                                               excitations=too_large))
    finally:
        run_engine.unsubscribe(token)
    assert refused.value.reason == "FSM_BadArgument" and "DAC" in refused.value.sentence
    assert [d["exit_status"] for d in stops] == ["fail"]
    assert not live.device_loop_closed()
    assert not list((live.folder / "refused").glob("data_cl_*"))


def _judged(result: Any) -> dict[str, Any]:
    """Each identified value against the twin's truth, with the open-loop targets."""
    rows = comparison_rows(result.to_json(), reference=model_values(BENCH.true), bench=BENCH)
    return {r.key: r for r in rows}


@pytest.mark.slow  # two protocols' records and four identifications: ~2 min each
def test_plans_record_what_identifies_the_bench(live: Any, run_engine: Any,
                                                excitations: dict[str, np.ndarray]) -> None:
    from fsmbench.live.plans import (
        IDENTIFICATION_EXPERIMENTS,
        closed_loop_experiments,
        identification_experiments,
        identify_records,
    )

    docs: list[str] = []
    token = run_engine.subscribe(lambda name, doc: docs.append(name))
    try:
        opened = _call(run_engine, identification_experiments(live.device,
                                                              live.folder / "open"))
        closed = _call(run_engine, closed_loop_experiments(live.device, live.folder / "closed",
                                                           excitations=excitations))
    finally:
        run_engine.unsubscribe(token)
    # One run per plan, an event after each experiment.
    assert docs.count("start") == docs.count("stop") == 2
    assert docs.count("event") == len(IDENTIFICATION_EXPERIMENTS) + 2
    assert sorted(opened.files) == sorted(IDENTIFICATION_EXPERIMENTS)
    assert all(p.parent == live.folder / "open" and p.is_file() for p in opened.files.values())
    assert sorted(closed.files) == ["data_cl_uch", "data_cl_ucv"]
    assert "ESRF study" in closed.controller

    # The open-loop identification from the plan's files: every target (resonance 0.5 %,
    # damping 25 %, gains 1-3 %, delays one sample) against the twin's truth.
    rows = _judged(identify_records(opened, model=BENCH))
    assert set(rows) == set(TARGETS)
    missed = [str(r) for r in rows.values() if not r.within_target]
    assert not missed, "\n".join(missed)
    # The closed-loop identification gives the Sercalo, its current amplifiers and delay:
    # each within the same targets, but the dampings. One stage at the default bound leaves
    # the resonance bands too little excitation: the v damping came out 2.8 to 10 times the
    # true one in 3 of 17 runs on the twin, the h damping +63 % in 1 of 9 runs of this test
    # (closed_loop_identification's two stages bring them within: the test below); each is
    # checked to be a damping (positive, below 1), the rest to hold.
    result = identify_records(closed, model=BENCH)
    assert not live.device_loop_closed(), "the plan opens the loop it closed"
    rows = _judged(result)
    assert {f"sercalo.{a}.{q}" for a in "hv" for q in ("resonance_hz", "damping_ratio",
                                                          "dc_gain_v_per_a")} <= set(rows)
    for axis in "hv":
        assert 0.0 < rows.pop(f"sercalo.{axis}.damping_ratio").identified < 1.0
    missed = [str(r) for r in rows.values() if not r.within_target]
    assert not missed, "\n".join(missed)


@pytest.mark.slow  # two stages of two records and three identifications: ~1 min each
def test_the_two_stage_plan_identifies_every_target_in_closed_loop(live: Any,
                                                                   run_engine: Any) -> None:
    from fsmbench.live.plans import closed_loop_identification

    bound = 30e-6
    docs: list[str] = []
    token = run_engine.subscribe(lambda name, doc: docs.append(name))
    try:
        run = _call(run_engine, closed_loop_identification(live.device,
                                                           live.folder / "two_stage"))
    finally:
        run_engine.unsubscribe(token)
    assert not live.device_loop_closed(), "the plan opens the loop it closed"
    # One run, an event after each stage; each stage's two records kept in its folder.
    assert docs.count("start") == docs.count("stop") == 1
    assert docs.count("event") == len(run.stage_folders) >= 2
    for folder in run.stage_folders:
        assert sorted(p.name for p in folder.glob("data_cl_*.mat")) == ["data_cl_uch.mat",
                                                                         "data_cl_ucv.mat"]
    assert "ESRF study" in run.controller
    names = sorted(p.name for p in run.files)
    assert names == ["frf.mat", "identification.json", "measurement.json", "plant.mat"]
    for name in ("identification.json", "measurement.json"):
        assert list(json.loads((run.folder / name).read_text()))[:2] == ["format",
                                                                        "format_version"]
    # Every target of the open-loop identification, the dampings included, against the
    # twin's truth; the beam error the measurement added under the bound on both axes.
    rows = _judged(run.measurement.identification)
    assert {f"sercalo.{a}.{q}" for a in "hv" for q in ("resonance_hz", "damping_ratio",
                                                          "dc_gain_v_per_a")} <= set(rows)
    missed = [str(r) for r in rows.values() if not r.within_target]
    assert not missed, "\n".join(missed)
    assert max(run.measurement.tracking_added_rad().values()) <= bound
