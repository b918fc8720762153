"""Reading back what ``fsmbench design`` writes: controllers.mat and controllers_sos.json."""

from __future__ import annotations

import json
from pathlib import Path

import control as ct
import numpy as np
import pytest

from fsmbench.bench.blocks import PlantModel, ss_response
from fsmbench.bench.esrf import esrf_decentralised_controller, newport_controller
from fsmbench.bench.params import Bench
from fsmbench.control.controller import Controller
from fsmbench.control.design import AxisShape, DesignOptions
from fsmbench.control.export import (
    DEFAULT_DISCRETISATION,
    InputScaling,
    discretise,
    write_controllers_mat,
    write_sos_json,
)
from fsmbench.control.load import (
    DEFAULT_CONTROLLER,
    load_controllers,
    select_controller,
)
from fsmbench.control.study import (
    CONTROLLERS_MAT,
    CONTROLLERS_SOS_JSON,
    DesignResult,
    StudyOptions,
    design_study,
)
from fsmbench.io.errors import RecordingError
from fsmbench.io.matwrite import save_mat

TS = 1e-4  # the bench's sample time [s]
F_HZ = np.logspace(0.0, np.log10(4000.0), 300)  # 1 Hz .. 4 kHz
Z = np.exp(2j * np.pi * F_HZ * TS)


def _fsm_like() -> ct.StateSpace:
    """Two channels shaped like fsmbench's controller: four integrators, lead, roll-off."""
    parts = [AxisShape(crossover_hz=fc, integrator_hz=7.0, extra_integrators=3, lead_hz=45.0,
                       lead_ratio=1.5, lowpass_hz=lp, lowpass_damping=0.8,
                       gain=g).realise(input_name=i, output_name=o)
             for fc, lp, g, i, o in ((35.0, 200.0, -4000.0, "Rh", "Uch"),
                                     (33.0, 140.0, 6000.0, "Rv", "Ucv"))]
    k = ct.append(*parts)
    return ct.ss(k.A, k.B, k.C, k.D, inputs=["Rh", "Rv"], outputs=["Uch", "Ucv"])


CONTROLLERS = {
    "seed_controller": esrf_decentralised_controller(),
    "newport_controller": newport_controller(gn0_rad_per_v=(5.3e-3, 5.2e-3)),
    "fsmbench_controller": _fsm_like(),
    "static_gain": ct.ss([], [], [], [[-2.0, 0.0], [0.0, 3.0]], inputs=["Rh", "Rv"],
                         outputs=["Uch", "Ucv"]),
}
DESCRIPTIONS = {"seed_controller": "the ESRF study's controller", "static_gain": "a plain gain"}
SCALING = InputScaling(qd_gain_v_per_rad=(-31.0, 36.3), plant_source="physical (nominal)")


def _write_both(folder: Path, controllers: dict[str, ct.StateSpace], *,
                method: str = DEFAULT_DISCRETISATION, ts_s: float = TS) -> tuple[Path, Path]:
    folder.mkdir(parents=True, exist_ok=True)
    mat = write_controllers_mat(folder / CONTROLLERS_MAT, controllers, ts_s=ts_s, method=method,
                                descriptions=DESCRIPTIONS, scaling=SCALING)
    sos = write_sos_json(folder / CONTROLLERS_SOS_JSON, controllers, scaling=SCALING, ts_s=ts_s,
                         method=method, descriptions=DESCRIPTIONS)
    return mat, sos


def _response(k: Controller) -> np.ndarray:
    """The loaded matrices' response through the bench's own evaluator, shape (F, 2, 2)."""
    return ss_response(ct.ss(k.a, k.b, k.c, k.d, k.ts_s), Z)


def _assert_same_response(h: np.ndarray, ref: np.ndarray) -> None:
    """Diagonal 1e-9 relative; off-diagonal (zero by design) 1e-9 of the diagonal's scale."""
    for i in range(2):
        # Both are the same Tustin sections in two realisations: rounding only (1e-11 seen
        # at 1 Hz for four integrators, where z - 1 amplifies it).
        np.testing.assert_allclose(h[:, i, i], ref[:, i, i], rtol=1e-9, atol=0)
    scale = np.max(np.abs(ref[:, [0, 1], [0, 1]]))
    off = h[:, [0, 1], [1, 0]]
    np.testing.assert_allclose(off, ref[:, [0, 1], [1, 0]], rtol=0, atol=1e-9 * scale)  # as above


# --------------------------------------------------------------------------- responses
@pytest.mark.parametrize("method", ["tustin_prewarp", "tustin"])
def test_loaded_controllers_reproduce_the_discretised_design(tmp_path: Path,
                                                             method: str) -> None:
    mat, sos = _write_both(tmp_path, CONTROLLERS, method=method)
    from_mat = load_controllers(mat, ts_s=TS)
    from_json = load_controllers(sos, ts_s=TS)
    assert list(from_mat) == list(from_json) == list(CONTROLLERS)  # the file's order
    for name, k in CONTROLLERS.items():
        ref = ss_response(discretise(k, ts_s=TS, method=method), Z)
        m, j = from_mat[name], from_json[name]
        _assert_same_response(_response(m), ref)
        _assert_same_response(_response(j), ref)
        _assert_same_response(_response(j), _response(m))  # JSON- and MAT-loaded agree
        # Both are minimal cascades of the same sections: as many states.
        assert m.n_states == j.n_states
        for loaded in (m, j):
            assert loaded.name == name and loaded.ts_s == TS
            assert loaded.input_names == tuple(k.input_labels)
            assert loaded.output_names == tuple(k.output_labels)
            assert loaded.description == DESCRIPTIONS.get(name, "")
            assert loaded.gd_v_per_rad == (-31.0, 36.3)
            assert loaded.discretisation == method
            assert not loaded.a.flags.writeable and not loaded.d.flags.writeable
            # Its own evaluator: the same formula as the bench's, batched the same way.
            np.testing.assert_allclose(loaded.response(F_HZ), _response(loaded),
                                       rtol=1e-12, atol=0)
        assert m.source_path == mat and j.source_path == sos
    assert from_json["static_gain"].n_states == 0
    np.testing.assert_array_equal(from_json["static_gain"].d, [[-2.0, 0.0], [0.0, 3.0]])


def test_json_realisation_is_well_conditioned_near_z_1(tmp_path: Path) -> None:
    """Four integrators at 10 kHz: the sections' companion form would lose ~1e-5 at 1 Hz.

    At 0.1 Hz (|z - 1| = 6.3e-5) the cascade still matches the design's own: each
    pole at z = 1 costs eps / |z - 1| = 3.5e-12 relative, four of them 1.4e-11
    (8e-12 seen); 1e-10 leaves room for the sections' other roundings. (sosfreqz on
    the same coefficients, a polynomial evaluation, is off by 4e-8 there.)
    """
    _, sos = _write_both(tmp_path, {"fsmbench_controller": _fsm_like()})
    k = load_controllers(sos)["fsmbench_controller"]
    z = np.exp(2j * np.pi * np.array([0.1, 0.3]) * TS)
    ref = ss_response(discretise(_fsm_like(), ts_s=TS), z)
    h = ss_response(ct.ss(k.a, k.b, k.c, k.d, TS), z)
    for i in range(2):
        np.testing.assert_allclose(h[:, i, i], ref[:, i, i], rtol=1e-10)  # reason: docstring


# --------------------------------------------------------------------------- a real design
@pytest.fixture(scope="module")
def design(true_plant: PlantModel, bench: Bench) -> DesignResult:
    """A small design (short search, nominal robust set only), about a second."""
    opts = StudyOptions(design=DesignOptions(max_iterations=20, extra_integrators=(3,),
                                             frequency_scales=(1.0,), damping_scales=(1.0,),
                                             per_decade=20),
                        with_seed_robustness=False)
    return design_study(true_plant, bench=bench, options=opts)


def test_design_output_folder_loads_fsmbench_controller_by_default(design: DesignResult,
                                                                   tmp_path: Path) -> None:
    design.write(tmp_path)
    ts = design.options.loop.ts_s
    from_folder = load_controllers(tmp_path, ts_s=ts)  # a folder means its controllers.mat
    from_json = load_controllers(tmp_path / CONTROLLERS_SOS_JSON, ts_s=ts)
    assert next(iter(from_folder.values())).source_path == tmp_path / CONTROLLERS_MAT
    # The files list the seed's controller first; the default is fsmbench's own.
    assert next(iter(from_folder)) == next(iter(from_json)) == "seed_controller"
    for loaded in (from_folder, from_json):
        chosen = select_controller(loaded)
        assert chosen.name == DEFAULT_CONTROLLER == "fsmbench_controller"
        assert chosen.gd_v_per_rad == design.qd_gain_v_per_rad
        ref = ss_response(discretise(design.controllers[DEFAULT_CONTROLLER], ts_s=ts), Z)
        _assert_same_response(_response(chosen), ref)
    assert "iff_controller" in from_folder and "iff_controller" not in from_json
    assert from_folder["iff_controller"].input_names == ("Vch", "Vcv")


# --------------------------------------------------------------------------- selection
def test_select_controller(tmp_path: Path) -> None:
    mat, _ = _write_both(tmp_path, {"newport_controller": CONTROLLERS["newport_controller"],
                                    "static_gain": CONTROLLERS["static_gain"],
                                    "seed_controller": CONTROLLERS["seed_controller"]})
    loaded = load_controllers(mat)
    # No fsmbench controller: the first, in the file's order, from Rh, Rv to Uch, Ucv.
    assert select_controller(loaded).name == "static_gain"
    assert select_controller(loaded, "seed_controller").name == "seed_controller"
    newport = select_controller(loaded, "newport_controller", outputs=("Unh", "Unv"))
    assert newport.output_names == ("Unh", "Unv")
    with pytest.raises(RecordingError) as err:
        select_controller(loaded, "kd_controller")
    assert str(err.value) == (f"{mat}: has no controller 'kd_controller'; it holds: "
                              "newport_controller, static_gain, seed_controller")
    with pytest.raises(RecordingError) as err:
        select_controller(loaded, "newport_controller")
    assert str(err.value) == (f"{mat}: controller 'newport_controller' maps Rh, Rv to Unh, Unv; "
                              "this loop needs Rh, Rv to Uch, Ucv")
    with pytest.raises(RecordingError, match=r"has no controller from Rh, Rv to Uch, Ucv; it "
                       r"holds: newport_controller \(Rh, Rv to Unh, Unv\)$"):
        select_controller({"newport_controller": loaded["newport_controller"]})


# --------------------------------------------------------------------------- errors
def _one_line(err: pytest.ExceptionInfo[RecordingError], path: Path) -> str:
    text = str(err.value)
    assert "\n" not in text and text.startswith(f"{path}: ")
    return text


def test_errors_name_the_file_and_the_problem(tmp_path: Path) -> None:
    mat, sos = _write_both(tmp_path / "design", CONTROLLERS)
    missing = tmp_path / "nowhere" / "controllers_sos.json"
    with pytest.raises(RecordingError) as err:
        load_controllers(missing)
    assert "does not exist" in _one_line(err, missing)
    with pytest.raises(RecordingError) as err:
        load_controllers(tmp_path)  # a folder without the design's files
    assert f"without {CONTROLLERS_MAT} or {CONTROLLERS_SOS_JSON}" in _one_line(err, tmp_path)

    for path in (mat, sos):  # a sample time that does not match
        with pytest.raises(RecordingError) as err:
            load_controllers(path, ts_s=2e-4)
        assert ("sampled every 0.0001 s (10000 Hz), but they would run every 0.0002 s "
                "(5000 Hz)") in _one_line(err, path)

    doc = json.loads(sos.read_text())
    # Another document's 'format' is not quoted (the live device answers clients with these
    # words); fsmbench's own format's version is a number, and named.
    for key, value, found in (("format_version", 1, "format 'fsmbench.controllers_sos' "
                                                   "version 1"),
                              ("format_version", "2b", "another 'format_version'"),
                              ("format", "fsmbench.plant", "another 'format'")):
        bad = tmp_path / f"bad_{key}.json"
        bad.write_text(json.dumps({**doc, key: value}))
        with pytest.raises(RecordingError) as err:
            load_controllers(bad)
        assert _one_line(err, bad).endswith("is not a controllers file: expected format "
                                            f"'fsmbench.controllers_sos' version 2, found {found}")
    listing = tmp_path / "list.json"
    listing.write_text("[1, 2]")
    with pytest.raises(RecordingError) as err:
        load_controllers(listing)
    assert _one_line(err, listing).endswith("found a JSON list")

    other = save_mat(tmp_path / "data_uch.mat", {"t": np.arange(3.0), "Vph": np.zeros(3)})
    with pytest.raises(RecordingError) as err:
        load_controllers(other)
    assert _one_line(err, other).endswith("is not a controllers file written by fsmbench "
                                          "design: it has no 'fsmbench' struct listing the "
                                          "controllers (it holds 2 other variables)")
    text = tmp_path / "notes.txt"
    text.write_text("gain = 3\n")
    with pytest.raises(RecordingError) as err:
        load_controllers(text)
    line = _one_line(err, text)
    assert "is not a controllers file fsmbench reads" in line
    assert "gain" not in line.removeprefix(f"{text}: ")  # the reader's excerpt is not kept
    for content, words in ((b'{"format": "Qz7:x:0:0', "is not valid JSON (line 1, column 12)"),
                           (b'{"a": "\xff\xfe Qz7"}', "is not UTF-8 text (byte 7)"),
                           (b"[" * 100_000, "nests too deeply")):
        doc_path = tmp_path / "broken.json"
        doc_path.write_bytes(content)
        with pytest.raises(RecordingError) as err:
            load_controllers(doc_path)
        line = _one_line(err, doc_path).removeprefix(f"{doc_path}: ")
        assert words in line and "Qz7" not in line and "\\x" not in line, line

    broken = json.loads(sos.read_text())
    broken["controllers"]["seed_controller"]["h"]["sos"][0][3] = 0.0
    bad_sos = tmp_path / "zero_a0.json"
    bad_sos.write_text(json.dumps(broken))
    with pytest.raises(RecordingError) as err:
        load_controllers(bad_sos)
    assert "controller 'seed_controller', axis h: a section holds NaN, infinite values or " \
           "a0 = 0" in _one_line(err, bad_sos)
    with pytest.raises(ValueError, match="must be positive"):
        load_controllers(sos, ts_s=0.0)
