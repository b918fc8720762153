"""The layers as code: pyproject.toml's import-linter contracts hold (issue 32; the style's
"layers are written as an import-linter contract, never only in the docs")."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
LINT = Path(sys.executable).with_name("lint-imports")


def _lint(*config: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([str(LINT), *config], cwd=ROOT, capture_output=True, text=True,
                          timeout=600, check=False)


def test_the_import_contracts_hold() -> None:
    done = _lint()
    assert done.returncode == 0, done.stdout[-4000:] + done.stderr[-2000:]
    assert "0 broken" in done.stdout and "6 kept" in done.stdout, done.stdout[-2000:]



def test_a_broken_contract_fails(tmp_path: Path) -> None:
    # The tool reads this tree and can fail: ident does import numpy.
    config = tmp_path / "broken.toml"
    config.write_text('[tool.importlinter]\nroot_package = "fsmbench"\n'
                      "include_external_packages = true\n\n"
                      "[[tool.importlinter.contracts]]\n"
                      'name = "no numpy in ident (false on purpose)"\ntype = "forbidden"\n'
                      'source_modules = ["fsmbench.ident"]\nforbidden_modules = ["numpy"]\n',
                      encoding="utf-8")
    done = _lint(str(config))
    assert done.returncode != 0 and "BROKEN" in done.stdout, done.stdout[-2000:]
