"""Output folders: where a command may write."""

from __future__ import annotations

from pathlib import Path

__all__ = ["check_out_dir"]


def check_out_dir(out_dir: Path, data_dir: Path | None) -> None:
    """Refuse to write into the data folder (inputs are never touched)."""
    if data_dir is None:
        return
    out, data = out_dir.resolve(), data_dir.resolve()
    if out == data or data in out.parents:
        raise ValueError(f"--out {out_dir} is inside the data folder {data_dir}; "
                         "fsmbench never writes into the data folder, choose another --out")
