"""The options several commands share, each defined here once.

A command adds them with the words of its own help where the meaning differs
(``--seed`` seeds the twin's noise in ``study``, the draws in ``montecarlo``);
the option's name, destination, type and metavar are the same everywhere, so a
message, ``run.json`` and the live device's properties name them one way.
"""

from __future__ import annotations

import argparse
import functools
from pathlib import Path
from typing import Any

from fsmbench.cli.args import positive, seed

__all__ = ["BENCH_HELP", "add_bench", "add_closed_loop", "add_identify_options", "add_json",
           "add_max_error", "add_out", "add_params", "add_seed", "add_timestamp",
           "identify_options", "out_folder"]

BENCH_HELP = ("simulate the bench identified in DIR (the output of fsmbench identify or "
              "study: identification.json, plant.mat) instead of the packaged twin; converters "
              "and everything no recording measured come from --params")


def add_params(p: argparse.ArgumentParser) -> None:
    """``--params FILE``: the bench file (``None``: the packaged bench)."""
    p.add_argument("--params", metavar="FILE", default=None,
                   help="bench parameters (TOML); default: the packaged Sercalo bench")


def add_timestamp(p: argparse.ArgumentParser, *, where: str = "MAT-file headers and run.json"
                  ) -> None:
    """``--timestamp``: the wall-clock time in the files named by ``where``."""
    p.add_argument("--timestamp", action="store_true",
                   help=f"write the wall-clock time into {where} (default: none, so that "
                        "outputs are byte-identical)")


def add_out(p: argparse.ArgumentParser, *, required: bool = True, positional: bool = False,
            help: str = "output folder") -> None:
    """``--out DIR``; with ``positional`` also ``OUT`` (``simulate OUT``, ``excite OUT``).

    Read it with :func:`out_folder`; ``required`` is checked there when ``positional``.
    """
    if positional:
        p.add_argument("out_pos", metavar="OUT", nargs="?", default=None, help=help)
        p.add_argument("--out", metavar="DIR", default=None, help=f"{help} (same as OUT)")
        p.set_defaults(out_required=required)
    else:
        p.add_argument("--out", metavar="DIR", default=None, required=required, help=help)


def out_folder(args: argparse.Namespace) -> str | None:
    """The output folder the user gave (``OUT`` or ``--out``); an error when a command that
    needs one got none."""
    out = getattr(args, "out_pos", None) or getattr(args, "out", None)
    if out is None and getattr(args, "out_required", False):
        raise ValueError(f"{args.command} needs an output folder: fsmbench {args.command} OUT")
    return None if out is None else str(out)


def add_seed(p: argparse.ArgumentParser, *, help: str, default: int | None = 0) -> None:
    """``--seed N``: a random seed (``help`` says what it seeds and the default)."""
    p.add_argument("--seed", metavar="N", type=seed, default=default, help=help)


def add_bench(p: argparse.ArgumentParser, *, help: str = BENCH_HELP,
              alias: bool = False) -> None:
    """``--bench DIR``: a bench identified by ``identify`` or ``study``; with ``alias`` also
    its older name ``--identification``."""
    names = ["--bench", *(["--identification"] if alias else [])]
    p.add_argument(*names, metavar="DIR", default=None, dest="bench_dir",
                   help=help + (" (--identification: the same, older name)" if alias else ""))


def add_max_error(p: argparse.ArgumentParser, *, default: float | None, help: str) -> None:
    """``--max-error-urad U``: the rms beam error a closed-loop measurement may add [µrad]."""
    p.add_argument("--max-error-urad", metavar="U", dest="max_error_urad",
                   type=functools.partial(positive, unit="µrad"), default=default, help=help)


def add_closed_loop(p: argparse.ArgumentParser, *, help: str, max_error_default: float | None,
                    max_error_help: str) -> None:
    """``--closed-loop CONTROLLER [--at output|reference] [--max-error-urad U]``: an
    excitation played with the loop closed (``simulate``, ``excite``)."""
    p.add_argument("--closed-loop", metavar="CONTROLLER", dest="closed_loop", default=None,
                   help=help)
    p.add_argument("--at", choices=("output", "reference"), default="output",
                   help="with --closed-loop: the excitation is added to the controller's "
                        "output (default) or to the loop's reference (4QD volts); at the "
                        "reference the controller's notch removes it at the Sercalo's "
                        "resonances, which then come out poorly")
    add_max_error(p, default=max_error_default, help=max_error_help)


def add_json(p: argparse.ArgumentParser, *, help: str) -> None:
    """``--json``: the result as JSON on stdout instead of the table."""
    p.add_argument("--json", action="store_true", help=help)


def add_identify_options(p: argparse.ArgumentParser) -> None:
    """``--frf`` and ``--weights`` of the identification (``identify`` and ``study``)."""
    p.add_argument("--frf", choices=("auto", "welch", "lpm", "periodic"), default="auto",
                   help="frequency-response estimator: auto (averaging over periods when every "
                        "excitation repeats, else Welch as the ESRF study), welch, lpm (local "
                        "polynomial method), periodic (default auto)")
    p.add_argument("--weights", choices=("seed", "variance"), default="seed",
                   help="vector-fit weights: the ESRF study's coherence recipe, or the inverse "
                        "standard deviation of each line, which also gives the Sercalo's "
                        "parameters standard deviations (default seed)")


def identify_options(args: argparse.Namespace, *, data: str | Path | None = None) -> Any:
    """The :class:`~fsmbench.ident.pipeline.IdentifyOptions` of ``--frf`` and ``--weights``.

    ``data``: the recording folder; the transient periods of every excitation
    described there (``fsmbench excite``'s JSON beside the records) are dropped by
    the periodic averaging, at least (more when the records show a transient).
    """
    from fsmbench.ident.load import excitation_transients
    from fsmbench.ident.pipeline import IdentifyOptions

    return IdentifyOptions(frf=args.frf, weights=args.weights,
                           transient_periods={} if data is None else excitation_transients(data))
