"""The README's Python API block runs as written (a fresh interpreter, the twin)."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

README = Path(__file__).resolve().parents[1] / "README.md"


def test_the_readme_api_block_runs(tmp_path: Path) -> None:
    text = README.read_text(encoding="utf-8")
    section = text[text.index("## Python API"):]
    block = re.search(r"```python\n(.*?)```", section, flags=re.S)
    assert block is not None, "the Python API section has no python block"
    script = tmp_path / "readme_api.py"
    script.write_text(block.group(1), encoding="utf-8")
    done = subprocess.run([sys.executable, str(script)], cwd=tmp_path, capture_output=True,
                          text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    total_m, margins = done.stdout.strip().splitlines()[-2:]
    # The twin's budget is nanometres (the ESRF study's 2 nm scale), and the margins are
    # finite numbers a reader can quote (gain and reduction margins in dB, degrees, s).
    assert 1e-10 < float(total_m) < 1e-7
    gm, grm, pm, dm = (float(x) for x in margins.split())
    assert gm > 6.0 and grm > 6.0 and pm > 30.0 and dm > 0.0
