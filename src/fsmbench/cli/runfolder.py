"""The one run-folder transaction of every writing command, and its progress lines.

Every command writes only under its output folder and writes it as one transaction
(:func:`fsmbench.io.outdir.output_transaction`): after an error, Ctrl-C or SIGTERM the
folder holds the complete previous run or the complete new one, with its manifest
``run.json``. Messages name the final paths, never the hidden staging folder.
"""

from __future__ import annotations

import argparse
import contextlib
import sys
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any

from fsmbench.cli.args import typed_option

__all__ = ["FILES_FORMAT", "Current", "check_inputs_first", "command_inputs", "mapped",
           "out_option", "print_files", "progress", "run_folder"]

InputPaths = list[tuple[str, Any]]

#: The ``--json`` of a command whose result is the files it wrote (``simulate``, ``convert``).
FILES_FORMAT = ("fsmbench.files", 1)


class Current:
    """The run folder being written, to map staging paths in messages."""

    run: Any = None


def mapped(text: str) -> str:
    """``text`` with the staging folder's paths written as the final ones."""
    run = Current.run
    return text if run is None else run.final_text(text)


def progress() -> Callable[[str], None]:
    """The progress reporter of a command (stderr, elapsed time, final paths)."""
    from fsmbench.progress import Reporter

    return Reporter(rewrite=mapped)


def _out_arguments(argv: Sequence[str], out: str | None) -> list[str]:
    """The command line with the output folder written ``.`` (run.json's own folder)."""
    if out is None:
        return list(argv)
    result = []
    for arg in argv:
        if arg == out:
            result.append(".")
        elif arg.startswith("--out=") and arg[len("--out="):] == out:
            result.append("--out=.")
        else:
            result.append(arg)
    return result


def command_inputs(args: argparse.Namespace, data: str | Path | None) -> InputPaths:
    """Every input path of the command line, with the option that named it.

    A command with inputs of its own (``--controller``, ``--ranges``, ``--running``) sets
    ``args.more_inputs`` (a list of the same pairs).
    """
    data_option = "--data" if args.command == "study" else "DATA"
    pairs: InputPaths = [(data_option, data), ("--params", getattr(args, "params", None)),
                         (typed_option(args, "bench_dir", "--bench"),
                          getattr(args, "bench_dir", None))]
    pairs += [("--excitation", path) for path in getattr(args, "excitation", None) or ()]
    pairs += list(getattr(args, "more_inputs", None) or ())
    return pairs


def out_option(args: argparse.Namespace) -> str:
    """How the user gave the output folder: ``--out DIR``, or ``OUT``."""
    return typed_option(args, "out_pos", "") or typed_option(args, "out", "--out")


def check_inputs_first(args: argparse.Namespace, out: str | None,
                       data: str | Path | None) -> None:
    """The inputs against the output folder, before any of them is read (:func:`run_folder`
    checks them again as the transaction starts)."""
    from fsmbench.io.outdir import check_inputs

    if out is not None:
        check_inputs(out, command_inputs(args, data), out_option=out_option(args))


@contextlib.contextmanager
def run_folder(args: argparse.Namespace, out: str, *, data: str | Path | None,
               need_bytes: float) -> Iterator[Any]:
    """The output folder ``out`` as one transaction (its staging folder is ``run.staging``)
    with the wall-clock headers of ``--timestamp``."""
    from fsmbench.io.matwrite import wall_clock_headers
    from fsmbench.io.outdir import output_transaction

    def warn(msg: str) -> None:
        print(f"fsmbench {args.command}: warning: {msg}", file=sys.stderr)

    timestamp = bool(getattr(args, "timestamp", False))
    with output_transaction(out, command=args.command,
                            arguments=_out_arguments(getattr(args, "argv", []), out),
                            data_dir=data, need_bytes=int(need_bytes), timestamp=timestamp,
                            warn=warn, inputs=command_inputs(args, data),
                            out_option=out_option(args)) as run, \
            wall_clock_headers(timestamp):
        Current.run = run  # kept after an error too: main maps paths in its message
        yield run


def print_files(paths: Sequence[Path | str], *, as_json: bool, command: str) -> None:
    """The files a command wrote, its result, on stdout: one path a line, or with ``--json``
    a ``fsmbench.files`` document (``{"command": ..., "files": [...]}``)."""
    if as_json:
        from fsmbench.jsonutil import format_text, stamped

        name, version = FILES_FORMAT
        print(format_text(stamped({"command": command, "files": [str(p) for p in paths]},
                                  format=name, version=version)), end="")
    else:
        for path in paths:
            print(path)
