"""The scripts in examples/ run as a user runs them (a subprocess, a fresh folder)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"

#: Each script, the figure it writes and lines its output must hold.
CASES = {
    "step_by_step.py": ("step_by_step.png", ("read 13 records", "identified plant: identified",
                                             "distance error budget:", "fsmbench           Rh")),
    "loop_margins.py": ("loop_margins.png", ("Padé order 6: 11", "delay exact: 6",
                                             "control.stability_margins on the FRD")),
}


def test_every_example_is_run() -> None:
    assert {p.name for p in EXAMPLES.glob("*.py")} == set(CASES)


@pytest.mark.parametrize("script", sorted(CASES))
def test_example_runs(script: str, tmp_path: Path) -> None:
    figure, expected = CASES[script]
    env = {**os.environ, "MPLBACKEND": "Agg", "FSMBENCH_EXAMPLE_OUT": str(tmp_path / "env")}
    done = subprocess.run([sys.executable, str(EXAMPLES / script), str(tmp_path)],
                          capture_output=True, text=True, timeout=600, env=env, check=False)
    assert done.returncode == 0, done.stderr[-3000:]
    for line in expected:
        assert line in done.stdout, (line, done.stdout)
    png = tmp_path / figure
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 10_000
    assert not (tmp_path / "env").exists()  # the argument wins over the variable
