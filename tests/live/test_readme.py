"""The README's live-bench tables are the code's: the attribute configuration and the PVs."""

from __future__ import annotations

from pathlib import Path

from fsmbench.live.attributes import ATTRIBUTES, readme_table
from fsmbench.live.epics import ACTIONS, ARGUMENT_COMMANDS, pv_table
from fsmbench.live.states import ALLOWED, REASONS

README = Path(__file__).resolve().parents[2] / "README.md"


def _section() -> str:
    text = README.read_text()
    start = text.index("## Live bench\n")
    return text[start:text.index("\n## ", start + 1)]


def test_the_attribute_and_pv_tables_are_generated_from_the_code() -> None:
    section = _section()
    # A unit, format, limit or event criterion changed in attributes.py without the README
    # (or the other way round) fails here: paste readme_table() / pv_table() again.
    assert readme_table() in section
    assert pv_table() in section
    assert all(f"`{spec.name}`" in section for spec in ATTRIBUTES)


def test_every_command_and_reason_code_is_documented() -> None:
    section = _section()
    for command in ALLOWED:
        assert f"| `{command}` |" in section, command
    for name in (*ACTIONS, *ARGUMENT_COMMANDS):
        assert f"`PREFIX:{name}`" in section, name
    for reason in REASONS:
        if reason != "FSM_Internal":  # a bug's code, not a refusal a user meets
            assert f"`{reason}`" in section, reason
