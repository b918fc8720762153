"""StartExcitation of kind ``samples``: a designed command file played sample for sample.

``fsmbench tune --device`` plays its beam-bounded multisines this way (issue 24). The
bench is stepped by hand (no loop thread): the recorded DAC command is the file's
samples exactly, then repeats from ``loop_from``; bad files are refused in one sentence.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from fsmbench.bench.params import default_bench
from fsmbench.io.recording import read_recording
from fsmbench.live.core import LiveBench
from fsmbench.live.states import Refused

BENCH = default_bench()
FS = BENCH.nominal.converter.fs_hz


@pytest.fixture()
def live(tmp_path: Path) -> Iterator[LiveBench]:
    bench = LiveBench(BENCH, seed=7, output_folder=tmp_path / "out")
    bench.advance(1000)
    yield bench
    bench.stop()


def test_the_samples_are_played_exactly_then_repeated(live: LiveBench, tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    x = 0.1 * rng.standard_normal(3000)
    np.save(tmp_path / "x.npy", x)
    path = Path(live.record(json.dumps({"signals": ["Uch"], "duration_s": 0.5,
                                        "name": "played"})))
    live.advance(100)
    live.start_excitation(json.dumps({"input": "Uch", "kind": "samples",
                                      "path": str(tmp_path / "x.npy"), "loop_from": 1000}))
    doc = json.loads(live.excitation_text)
    assert doc["kind"] == "samples" and doc["n_samples"] == 3000 and doc["loop_from"] == 1000
    while live.state == "MOVING":
        live.advance(500)
        if live.bench_time_s > 5.0:
            break
    live.wait_idle(30.0)
    u = read_recording(path, require=())["Uch"].values
    first = round(doc["start_time_s"] * FS) - round(0.1 * FS)  # the record began 100 samples
    # Loop open, nothing else on Uch: the DAC gives the file's commands (to its 16-bit step).
    lsb = BENCH.nominal.converter.lsb_v
    np.testing.assert_allclose(u[first:first + 3000], x, atol=lsb)
    # After the end, samples[1000:] again.
    np.testing.assert_allclose(u[first + 3000:first + 4000], x[1000:2000], atol=lsb)


@pytest.mark.parametrize(("content", "extra", "words"), [
    (None, {}, "not a readable .npy"),
    (np.zeros((2, 3)), {}, "of shape (2, 3)"),
    (np.array([0.0, np.nan]), {}, "not finite"),
    (np.array([0.0, 50.0]), {}, "beyond the DAC"),
    (np.zeros(10), {"loop_from": 10}, "loop_from must be a sample index"),
    (np.zeros(10), {"amplitude_v": 1.0}, "not for a samples excitation"),
])
def test_bad_sample_files_are_refused(live: LiveBench, tmp_path: Path, content: object,
                                      extra: dict[str, object], words: str) -> None:
    f = tmp_path / "bad.npy"
    if content is None:
        f.write_text("not numpy")
    else:
        np.save(f, content)
    with pytest.raises(Refused) as exc:
        live.start_excitation(json.dumps({"input": "Ucv", "kind": "samples", "path": str(f),
                                          **extra}))
    assert exc.value.reason == "FSM_BadArgument"
    assert words in exc.value.sentence and "\n" not in exc.value.sentence
    assert live.excitation_text == "{}"
