"""``main``: the ``fsmbench`` parser and the one exception boundary of every command.

Exit status: 0 success; 2 an error the user can fix, printed as one line
``fsmbench <cmd>: error: <file>: <problem>``; 130 Ctrl-C; 143 SIGTERM; 141 the reader of
stdout went away; 1 a bug in fsmbench (traceback, then a request to report it).
"""

from __future__ import annotations

import argparse
import contextlib
import os
import signal
import sys
import threading
import traceback
from collections.abc import Iterator, Sequence
from pathlib import Path
from types import FrameType

# Ctrl-C while the command line loads (its imports take about a second): one line, the
# shell's 130, not a traceback; nothing has run, so no device, file or folder was touched.
try:
    from fsmbench.bench.params import ParamsError
    from fsmbench.cli.args import Parser
    from fsmbench.cli.commands import COMMANDS
    from fsmbench.cli.runfolder import Current, mapped
    from fsmbench.cli.status import (
        EXIT_BROKEN_PIPE,
        EXIT_BUG,
        EXIT_SIGINT,
        EXIT_SIGTERM,
        EXIT_USER_ERROR,
        Terminated,
    )
    from fsmbench.version import __version__
except KeyboardInterrupt:
    print("fsmbench: interrupted (Ctrl-C) while starting, before it contacted any device or "
          "wrote any file: nothing was changed", file=sys.stderr)
    raise SystemExit(130) from None

__all__ = ["build_parser", "console", "main"]


def build_parser() -> argparse.ArgumentParser:
    """The ``fsmbench`` parser: each command of :data:`fsmbench.cli.commands.COMMANDS`
    registers its sub-command (``register``), which runs its ``run``."""
    parser = Parser(
        prog="fsmbench",
        description="Fast-steering-mirror bench: digital twin, identification, budget, control.")
    parser.add_argument("--version", action="version", version=f"fsmbench {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=Parser)
    for command in COMMANDS:
        command.register(sub)
    return parser


# ------------------------------------------------------------------ the exception boundary


def _describe(exc: BaseException) -> str:
    """``<file>: <problem>`` for an error the user can fix."""
    if isinstance(exc, OSError) and not isinstance(exc, _own_errors()):
        problem = exc.strerror or (exc.args[0] if exc.args else type(exc).__name__)
        if exc.filename is not None and exc.filename2 is not None:
            return f"{exc.filename} -> {exc.filename2}: {problem}"
        if exc.filename is not None:
            return f"{exc.filename}: {problem}"
        return str(problem)
    return str(exc)


def _own_errors() -> tuple[type[BaseException], ...]:
    from fsmbench.io.errors import RecordingError
    from fsmbench.io.outdir import OutputError

    return (ParamsError, RecordingError, OutputError)


def _raised_by_fsmbench(exc: BaseException) -> bool:
    """True when the innermost frame of the traceback is fsmbench's own code.

    A ``ValueError`` fsmbench raises on purpose (a duration too short, an
    unknown experiment) is a verdict for the user; one raised deep inside
    numpy or scipy is a bug to report.
    """
    tb = exc.__traceback__
    if tb is None:
        return True
    while tb.tb_next is not None:
        tb = tb.tb_next
    package = str(Path(__file__).resolve().parent.parent)  # fsmbench/, not fsmbench/cli/
    return str(Path(tb.tb_frame.f_code.co_filename).resolve()).startswith(package)


def _user_error(exc: BaseException) -> bool:
    if isinstance(exc, (*_own_errors(), OSError)):
        return True
    return isinstance(exc, ValueError) and _raised_by_fsmbench(exc)


@contextlib.contextmanager
def _sigterm_raises() -> Iterator[None]:
    """SIGTERM raises :class:`Terminated`, so staging folders and temporary files go."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def handler(_signum: int, _frame: FrameType | None) -> None:
        raise Terminated

    saved = signal.signal(signal.SIGTERM, handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, saved)


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``fsmbench`` console script; returns the exit status."""
    argv = list(sys.argv[1:] if argv is None else argv)
    try:
        args = build_parser().parse_args(argv)
    except SystemExit as exc:  # --help, --version, or a bad argument (one line printed)
        return exc.code if isinstance(exc.code, int) else EXIT_USER_ERROR
    args.argv = argv
    Current.run = None
    out = getattr(args, "out", None) or getattr(args, "out_pos", None) or "the output folder"
    prefix = f"fsmbench {args.command}: error:"
    untouched = f"{out} was left as it was (no partial output)"
    try:
        with _sigterm_raises():
            return int(args.func(args))
    except KeyboardInterrupt:
        print(f"{prefix} {out}: interrupted (Ctrl-C); {untouched}", file=sys.stderr)
        return EXIT_SIGINT
    except Terminated:
        print(f"{prefix} {out}: terminated (SIGTERM); {untouched}", file=sys.stderr)
        return EXIT_SIGTERM
    except BrokenPipeError:
        # The reader went away (``fsmbench params --json | head``): no error to tell it.
        # Later writes to stdout (the interpreter's flush at exit) go nowhere.
        with contextlib.suppress(OSError, ValueError):
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, sys.stdout.fileno())
        return EXIT_BROKEN_PIPE
    except Exception as exc:
        if not _user_error(exc):
            traceback.print_exc()
            print(f"fsmbench {args.command}: internal error ({type(exc).__name__}), a bug in "
                  f"fsmbench {__version__}; please report it with the command line and the "
                  "traceback above", file=sys.stderr)
            return EXIT_BUG
        text = mapped(_describe(exc))
        print(f"{prefix} {' '.join(text.split())}", file=sys.stderr)
        return EXIT_USER_ERROR


def console() -> None:
    """The ``fsmbench`` console script (and ``python -m fsmbench.cli``): :func:`main`, then
    the interpreter's exit with SIGINT ignored.

    Once the command has returned, its result is written and said; what remains is the
    interpreter's teardown (a device proxy's, a server's threads). A Ctrl-C there killed
    the process by the signal (status -2, no sentence) after a tune had finished and
    reported (a soak's run): there is nothing left for it to stop. Not in :func:`main`,
    which a caller's process (a test, a script) keeps its own Ctrl-C around.
    """
    status = main()
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    sys.exit(status)


if __name__ == "__main__":  # pragma: no cover
    console()
