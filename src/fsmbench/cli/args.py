"""Argument types and the parser class of the ``fsmbench`` command line.

Every number a user types is checked here, and a bad one gives one line,
status 2.
"""

from __future__ import annotations

import argparse
import math
from typing import Any, NoReturn

from fsmbench.cli.status import EXIT_USER_ERROR

__all__ = ["EXIT_USER_ERROR", "SEED_MAX", "Parser", "default_noted", "drift_rate", "factor",
           "figure_formats", "nanometres", "port", "positive", "seconds", "seed",
           "typed_option"]


#: Largest ``--seed``: numpy's SeedSequence takes non-negative integers only, and the live
#: device keeps the seed in a Tango 64-bit signed integer property.
SEED_MAX = 2**63 - 1


class _DescribedSubParsers(argparse._SubParsersAction):
    """Sub-commands whose ``--help`` page opens with their one-line ``help``."""

    def add_parser(self, name: str, **kwargs: Any) -> argparse.ArgumentParser:
        text = kwargs.get("help")
        if text and "description" not in kwargs:
            kwargs["description"] = text[0].upper() + text[1:] + "."
        return super().add_parser(name, **kwargs)


#: Namespace attribute: destination to the option the user typed for it (``--bench`` or its
#: alias ``--identification``), or a positional's name (``OUT``) when one was given.
_TYPED = "typed_options"
#: The actions that store what the user typed (help, version and sub-commands are not values).
_VALUE_ACTIONS = (None, "store", "store_const", "store_true", "store_false", "append",
                  "append_const", "extend", "count")


def _recording(cls: type[argparse.Action]) -> type[argparse.Action]:
    """``cls`` that also notes, in the namespace, the option string it was called by."""

    class Recording(cls):  # type: ignore[valid-type,misc]
        def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace,
                     values: Any, option_string: str | None = None) -> None:
            # argparse passes the option's full string, also for an abbreviation or --opt=v.
            name = option_string or (self.metavar if values is not self.default else None)
            if isinstance(name, str):
                typed = getattr(namespace, _TYPED, None)
                if typed is None:
                    typed = {}
                    setattr(namespace, _TYPED, typed)
                typed[self.dest] = name
            super().__call__(parser, namespace, values, option_string)

    Recording.__name__ = f"Recording{cls.__name__}"
    return Recording


def typed_option(args: argparse.Namespace, dest: str, default: str) -> str:
    """The option the user typed for ``dest`` (of two aliases, the one typed; a positional's
    name), or ``default`` when none was typed.

    Parameters
    ----------
    args : argparse.Namespace
        Parsed by :class:`Parser`.
    dest : str
        The destination (``"bench_dir"``).
    default : str
        The name to use when the user typed none (``"--bench"``).
    """
    return str(getattr(args, _TYPED, {}).get(dest, default))


def default_noted(args: argparse.Namespace, dest: str, text: str) -> str:
    """``text`` (``"--band 1 2000"``) as is when the user typed the option, else followed by
    ``" (the default)"``: a message never presents a default as what the user typed."""
    return text if dest in getattr(args, _TYPED, {}) else f"{text} (the default)"


class Parser(argparse.ArgumentParser):
    """argparse with errors as one line ``fsmbench <cmd>: error: ...`` and status 2.

    Every option and positional notes what the user typed for it (:func:`typed_option`),
    so that messages name the alias that was typed.
    """

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.register("action", "parsers", _DescribedSubParsers)
        for name in _VALUE_ACTIONS:
            cls = self._registry_get("action", name, None)
            if cls is not None:
                self.register("action", name, _recording(cls))

    def error(self, message: str) -> NoReturn:
        self.exit(EXIT_USER_ERROR, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def positive(text: str, unit: str) -> float:
    """A finite, positive number (``inf``, ``nan``, ``0``, ``-1`` rejected)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number of {unit}") from None
    if not math.isfinite(value) or value <= 0:
        raise argparse.ArgumentTypeError(f"{text!r} is not a finite positive number of {unit}")
    return value


def drift_rate(text: str) -> float:
    """A resonance drift rate [%/h], within what the twin's drift allows
    (:data:`fsmbench.live.states.MAX_DRIFT_PCT_PER_H`): ``serve --drift-rate`` and
    ``tune --drift-rate`` take the same."""
    from fsmbench.live.states import MAX_DRIFT_PCT_PER_H

    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a drift rate in %/h") from None
    if not (math.isfinite(value) and abs(value) <= MAX_DRIFT_PCT_PER_H):
        raise argparse.ArgumentTypeError(f"{text!r}: give a drift rate within "
                                         f"±{MAX_DRIFT_PCT_PER_H:g} %/h")
    return value


def seconds(text: str) -> float:
    """A duration [s]."""
    return positive(text, "seconds")


def factor(text: str) -> float:
    """A factor (> 0)."""
    return positive(text, "times real time")


def nanometres(text: str) -> float:
    """A distance given in nm, returned in m."""
    return positive(text, "nm") * 1e-9


def seed(text: str) -> int:
    """A random seed: a whole number from 0 to :data:`SEED_MAX`."""
    try:
        value = int(text.strip(), 10)
    except ValueError:
        value = -1
    if not 0 <= value <= SEED_MAX:
        raise argparse.ArgumentTypeError(f"{text!r} is not a seed: seeds are whole numbers "
                                         "from 0 to 2**63 - 1")
    return value


def port(text: str) -> int:
    """A TCP port: 0 (any free port) to 65535 (ports are 16-bit numbers)."""
    try:
        value = int(text.strip(), 10)
    except ValueError:
        value = -1
    if not 0 <= value <= 65535:
        raise argparse.ArgumentTypeError(f"{text!r} is not a TCP port from 0 to 65535 "
                                         "(0: any free port)")
    return value


def figure_formats(text: str) -> tuple[str, ...]:
    """``png,pdf`` → ("png", "pdf"); ``none`` or empty → ()."""
    items = [x.strip().lower() for x in text.split(",") if x.strip()]
    if items == ["none"]:
        return ()
    bad = [x for x in items if x not in ("png", "pdf")]
    if bad:
        raise argparse.ArgumentTypeError(f"unknown figure format(s) {', '.join(bad)}; "
                                         "use png, pdf or png,pdf")
    return tuple(dict.fromkeys(items))
