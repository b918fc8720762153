"""What the commands read before they compute: the bench file, an identified bench, a
folder of recordings, each checked first with a one-line verdict."""

from __future__ import annotations

import argparse
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from fsmbench.bench.params import Bench, ParamsError, load_bench
from fsmbench.cli.args import typed_option
from fsmbench.cli.runfolder import progress, run_folder

__all__ = ["StageInput", "bench_of", "check_data", "print_document", "sim_bench",
           "stage_folder", "stage_input"]


def bench_of(args: argparse.Namespace) -> Bench:
    """The bench file of ``--params`` (the packaged bench without it), checked first: a
    folder or a file that is not UTF-8 text is one line."""
    path = args.params
    if path is not None and Path(path).is_dir():
        raise ParamsError(f"{path}: is a folder; --params needs a TOML file (e.g. one written "
                          "by fsmbench params --out DIR)")
    try:
        return load_bench(path)
    except UnicodeDecodeError as exc:
        raise ParamsError(f"{path}: is not UTF-8 text ({exc.reason} at byte {exc.start}); "
                          "--params needs a TOML file") from None


def sim_bench(args: argparse.Namespace) -> Bench:
    """The bench a command simulates: identified in ``--bench DIR``, else the bench file."""
    bench = bench_of(args)
    folder = getattr(args, "bench_dir", None)
    if folder is None:
        return bench
    option = typed_option(args, "bench_dir", "--bench")  # or its alias --identification
    if Path(folder).is_file():
        raise ParamsError(f"{folder}: is a file; {option} needs a folder written by fsmbench "
                          "identify or study (a bench TOML goes to --params)")
    from fsmbench.twin.identified import identified_bench

    return identified_bench(folder, bench=bench, option=option)


def check_data(data: Path) -> None:
    """A data folder that is missing or a file: one line, before anything is read."""
    if not data.exists():
        raise FileNotFoundError(2, "data folder does not exist", str(data))
    if not data.is_dir():
        raise NotADirectoryError(20, "is a file; DATA must be a folder of recordings",
                                 str(data))


@dataclass(frozen=True)
class StageInput:
    """What every stage command starts from: folders, bench, progress, recordings."""

    data: Path
    bench: Bench
    say: Callable[[str], None]
    recordings: dict[str, Any]
    skipped: dict[str, str] = field(default_factory=dict)
    unusable: dict[str, str] = field(default_factory=dict)


def stage_input(args: argparse.Namespace, *,
                uses: tuple[str, ...] | None = None) -> StageInput:
    """Read the bench and every experiment present (the folders are checked first).

    ``uses``: the experiments the command reads; a file it does not use, or one that
    is simply absent, is not mentioned (the command's own output says what ran).
    """
    from fsmbench.checks import failed
    from fsmbench.io.folder import load_recordings

    data = Path(args.data)
    say = progress()
    bench = bench_of(args)
    conv = bench.nominal.converter
    # The records' rate is judged by the identification against each other, then the bench
    # file (ident.evidence.rate).
    loaded = load_recordings(data, progress=say, fs_hz=None, adc_range_v=conv.range_v,
                             adc_bits=conv.bits)
    for name, why in loaded.unusable().items():
        # Simply absent: not mentioned; a near miss ("found DATA_UCH.mat: rename it …") is.
        if uses is None or name in uses:
            say(f"skipped {name}: {why}")
    # What the user must know about the files it uses, once each, one line each.
    for check in failed(loaded.checks):
        if uses is None or check.subject.split(".")[0] in uses:
            say(f"check failed: {check.sentence()}")
    for notice in loaded.notices:
        say(f"note: {notice.sentence()}")
    return StageInput(data=data, bench=bench, say=say, recordings=dict(loaded.recordings),
                      skipped=dict(loaded.skipped), unusable=loaded.unusable())


def stage_folder(args: argparse.Namespace, need_bytes: float) -> Any:
    """The ``--out`` transaction of a stage command on ``DATA``, its folders and bench file
    checked first."""
    from fsmbench.io.outdir import check_out_dir

    data = Path(args.data)
    check_out_dir(Path(args.out), data)
    check_data(data)
    bench_of(args)  # a bad --params fails before anything is computed or written
    return run_folder(args, args.out, data=data, need_bytes=need_bytes)


def print_document(run: Any, paths: Sequence[Path], name: str) -> None:
    """A written result file's content on stdout, as written (``--json``)."""
    path = next(Path(run.final_path(p)) for p in paths if Path(p).name == name)
    print(path.read_text(encoding="utf-8"), end="")
