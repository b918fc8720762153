"""``fsmbench study`` on recorded data: stages, skipped experiments, untouched inputs."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np
import pytest
import scipy.io

from fsmbench.forked import fork_available
from fsmbench.study import StudyResult, run_study
from fsmbench.twin import TwinRun, write_twin


def _digest(folder: Path) -> dict[str, str]:
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(folder.iterdir())}


@pytest.fixture
def data_dir(short_twin: TwinRun, tmp_path: Path) -> Path:
    folder = tmp_path / "data"
    folder.mkdir()
    sub = TwinRun(recordings={k: v for k, v in short_twin.recordings.items()
                              if k in ("data_uch", "data_ucv", "data_huddle_test_1")},
                  truth=short_twin.truth, seed=short_twin.seed,
                  experiments=short_twin.experiments)
    write_twin(sub, folder)
    (folder / "twin_truth.json").unlink()  # recorded data have no truth beside them
    return folder


def test_study_on_a_partial_folder_says_what_it_skipped(data_dir: Path, tmp_path: Path) -> None:
    before = _digest(data_dir)
    # A broken file: NaN in a signal. It must be skipped with the reason.
    bad = {"t": np.arange(30000) / 1e4, "Unh": np.zeros(30000), "Vph": np.zeros(30000),
           "Vpv": np.zeros(30000)}
    bad["Vph"][123] = np.nan
    scipy.io.savemat(data_dir / "data_unh.mat", bad)
    before = _digest(data_dir)
    result = run_study(out_dir=tmp_path / "out", data_dir=data_dir)
    assert _digest(data_dir) == before  # inputs are never modified
    assert set(result.experiments) == {"data_uch", "data_ucv", "data_huddle_test_1"}
    assert "data_unh.mat" in result.skipped_experiments["data_unh"]
    assert "Vph" in result.skipped_experiments["data_unh"]
    assert "NaN" in result.skipped_experiments["data_unh"]
    assert "no data_rep_h.mat" in result.skipped_experiments["data_rep_h"]
    report = Path(result.report).read_text()
    verdict = report[report.index('id="verdict"'):report.index("</section>")]
    assert "data_unh.mat" in verdict and "NaN" in verdict  # named in the first screen
    # Identification ran on what is there (2.2, 2.3) and says what it skipped.
    stage = next(s for s in result.stages if s.name == "identify")
    # data_unh was there (with a NaN): never called missing
    assert stage.ran and "newport: missing data_unv; data_unh was not used (" in stage.reason
    assert (tmp_path / "out" / "identification.json").is_file()
    assert "2. Identification of the system dynamics" in report
    assert "true value (twin)" not in report  # recorded data: no twin wording
    study = json.loads((tmp_path / "out" / "study.json").read_text())
    assert study["experiments"] == list(result.experiments)


def test_study_refuses_to_write_into_the_data_folder(data_dir: Path) -> None:
    with pytest.raises(ValueError, match="inside the data folder"):
        run_study(out_dir=data_dir / "report", data_dir=data_dir)
    with pytest.raises(ValueError, match="inside the data folder"):
        run_study(out_dir=data_dir, data_dir=data_dir)


def test_missing_data_folder_is_named(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match="nowhere"):
        run_study(out_dir=tmp_path / "out", data_dir=tmp_path / "nowhere")


def test_study_on_the_twin_writes_its_data_and_report(twin_study: StudyResult) -> None:
    out = Path(twin_study.out_dir)
    assert len(twin_study.experiments) == 13 and not twin_study.skipped_experiments
    assert (out / "twin-data" / "twin_truth.json").is_file()
    report = Path(twin_study.report).read_text()
    assert "true value (twin)" in report  # the twin's truth is beside its data
    # plotly.js once, the zoom pyramid's script once, the drawing script once.
    assert report.count("<script>") == 3
    ident = json.loads((out / "identification.json").read_text())
    assert set(ident["sercalo"]) == {"h", "v"}


def _same(a: object, b: object) -> bool:
    """MAT-file values equal, structs and cells included (NaN equal to NaN)."""
    x, y = np.asarray(a), np.asarray(b)
    if x.shape != y.shape or x.dtype != y.dtype:
        return False
    if x.dtype.names:
        return all(_same(x[name], y[name]) for name in x.dtype.names)
    if x.dtype == object:
        return all(_same(u, v) for u, v in zip(x.ravel(), y.ravel(), strict=True))
    return bool(np.array_equal(x, y, equal_nan=x.dtype.kind in "fc"))


def test_the_design_beside_the_budget_gives_the_serial_study(twin_study: StudyResult,
                                                             tmp_path: Path) -> None:
    """The design forked beside the budget and the validation writes, file for file, what
    the stages one after the other write (all but the timings): no result depends on
    which process computed it."""
    out = Path(twin_study.out_dir)
    timings = json.loads((out / "timings.json").read_text())["seconds"]
    assert ("design_wait" in timings) == ("validation_wait" in timings) == fork_available()
    serial = run_study(out_dir=tmp_path / "serial", duration_s=5.0, parallel=False)
    assert "design_wait" not in json.loads(
        (Path(serial.out_dir) / "timings.json").read_text())["seconds"]
    written = sorted(p.relative_to(out) for p in out.rglob("*") if p.is_file()
                     and p.name != "timings.json")
    assert written == sorted(p.relative_to(serial.out_dir)
                             for p in Path(serial.out_dir).rglob("*")
                             if p.is_file() and p.name != "timings.json")
    differ = [str(p) for p in written if p.suffix == ".json"
              and (out / p).read_bytes() != (Path(serial.out_dir) / p).read_bytes()]
    for p in (p for p in written if p.suffix == ".mat"):  # the header holds the clock
        forked, alone = (scipy.io.loadmat(root / p) for root in (out, Path(serial.out_dir)))
        if any(k not in alone or not _same(forked[k], alone[k])
               for k in forked if not k.startswith("__")):
            differ.append(str(p))
    assert differ == []
