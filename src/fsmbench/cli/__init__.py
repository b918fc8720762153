"""The ``fsmbench`` command.

    fsmbench params   [--params FILE] [--out DIR] [--json]
    fsmbench simulate OUT [--duration S] [--seed N] [--params FILE] [--format F]
                      [--excitation FILE…] [--bench DIR] [--json]
    fsmbench identify DATA --out OUT [--params FILE] [--frf auto|welch|lpm|periodic]
                      [--weights seed|variance] [--closed-loop] [--json]
    fsmbench budget   DATA --out OUT [--params FILE] [--bench DIR] [--json]
    fsmbench design   DATA --out OUT [--params FILE] [--seed N] [--bench DIR] [--json]
    fsmbench study    [--data DIR] --out OUT [--seed N] [--duration S] [--params FILE]
                      [--figures png,pdf] [--montecarlo DIR] [--json]
    fsmbench serve    [--backend twin|playback DIR] [--params FILE] [--bench DIR] [--seed N]
                      [--speed X] [--nodb --port N] [--out DIR]
    fsmbench montecarlo DATA|--twin --out OUT [--n N] [--seed S] [--scheduler ADDRESS]
                      [--workers N] [--ranges TOML] [--controller FILE[::NAME]] [--bench DIR]
                      [--json]
    fsmbench excite   OUT --input Uch --amplitude-rms V [--kind K] [--band LO HI] ...
                      [--bench DIR] [--json]
    fsmbench tune     (--twin | --device ADDRESS) --out OUT [--running …] [--json]
    fsmbench convert  IN OUT [--fs HZ] [--json]

The package: :mod:`~fsmbench.cli.main` (the parser and the one exception boundary),
:mod:`~fsmbench.cli.options` (the shared options, each defined once),
:mod:`~fsmbench.cli.runfolder` (the one run-folder transaction),
:mod:`~fsmbench.cli.inputs` (bench file, identified bench, data folder, checked first),
:mod:`~fsmbench.cli.args` (argument types), and one module per command in
:mod:`fsmbench.cli.commands` (``register``, ``run``). Every command prints its result on
stdout (a table, the verdict, the files written) and its progress on stderr; ``--json``
prints the result as JSON instead. ``serve`` runs until stopped: its result is the address
line it prints once it serves.

``--bench DIR`` is the one option of every command that simulates: the bench
identified in DIR (``identify`` or ``study`` output) instead of the packaged
twin. On recorded data the design's closed-loop check runs on the bench
identified from them, never on the packaged twin.

Every writing command also takes ``--timestamp`` (wall-clock time in MAT-file
headers and ``run.json``; default none, so the same inputs and seed give
byte-identical files).

Every command writes only under its output folder, never into a data folder,
and writes it as one transaction (:func:`fsmbench.io.outdir.output_transaction`):
after an error, Ctrl-C or SIGTERM the folder holds the complete previous run or
the complete new one, with its manifest ``run.json``.

Exit status: 0 success; 2 an error the user can fix (data, parameters, output
folder, disk), printed as one line ``fsmbench <cmd>: error: <file>: <problem>``;
130 interrupted by Ctrl-C (SIGINT); 143 terminated by SIGTERM (128 + 15, what a
shell reports for a process killed by SIGTERM); 1 a bug in fsmbench (traceback,
then a request to report it).
"""

from __future__ import annotations

from fsmbench.cli.main import build_parser, console, main
from fsmbench.cli.status import (
    EXIT_BROKEN_PIPE,
    EXIT_BUG,
    EXIT_SIGINT,
    EXIT_SIGTERM,
    EXIT_USER_ERROR,
    Terminated,
)

__all__ = ["EXIT_BROKEN_PIPE", "EXIT_BUG", "EXIT_SIGINT", "EXIT_SIGTERM", "EXIT_USER_ERROR",
           "Terminated", "build_parser", "console", "main"]
