"""Exit statuses of the ``fsmbench`` command, and the exception SIGTERM raises."""

from __future__ import annotations

__all__ = ["EXIT_BROKEN_PIPE", "EXIT_BUG", "EXIT_SIGINT", "EXIT_SIGTERM", "EXIT_USER_ERROR",
           "Terminated"]

#: An error the user can fix (bad argument, bad data, unwritable folder).
EXIT_USER_ERROR = 2
#: Interrupted by Ctrl-C (SIGINT): 128 + 2, what a shell reports.
EXIT_SIGINT = 130
#: Terminated by SIGTERM: 128 + 15, what a shell reports for a process killed by it.
EXIT_SIGTERM = 143
#: A bug in fsmbench (a traceback, then a request to report it).
EXIT_BUG = 1
#: A shell's status for a command killed by SIGPIPE (128 + 13): its reader closed the pipe.
EXIT_BROKEN_PIPE = 141


class Terminated(BaseException):
    """SIGTERM arrived; raised from the signal handler so every cleanup runs."""
