"""The file formats the docs quote are the ones the code writes (issue 33: docs/results.md's
own example asserted budget version 2 while the files were version 4, so it raised)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
_QUOTED = re.compile(r'\("(fsmbench\.[a-z_]+)",\s*(\d+)\)')


def _written() -> dict[str, int]:
    """Every ``("fsmbench.<name>", N)`` constant in the package's source."""
    found: dict[str, set[int]] = {}
    for path in (ROOT / "src" / "fsmbench").rglob("*.py"):
        for name, version in _QUOTED.findall(path.read_text(encoding="utf-8")):
            found.setdefault(name, set()).add(int(version))
    assert all(len(v) == 1 for v in found.values()), found  # one version per format
    return {k: v.pop() for k, v in found.items()}


@pytest.mark.parametrize("doc", ["README.md", "docs/results.md", "docs/architecture.md",
                                 "docs/decisions.md"])
def test_quoted_formats_are_the_written_ones(doc: str) -> None:
    written = _written()
    assert written["fsmbench.budget"] >= 4  # the scan finds the constants
    for name, version in _QUOTED.findall((ROOT / doc).read_text(encoding="utf-8")):
        assert name in written, f"{doc} quotes {name}, which nothing writes"
        assert int(version) == written[name], f"{doc}: {name} {version}, written {written[name]}"
