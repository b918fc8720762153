"""One module per ``fsmbench`` command, each with ``register(sub)`` (its sub-parser, its
options from :mod:`fsmbench.cli.options`) and ``run(args) -> int`` (its result on stdout,
progress on stderr, ``--json``). :data:`COMMANDS` is the order of ``fsmbench --help``."""

from __future__ import annotations

from types import ModuleType

from fsmbench.cli.commands import (
    budget,
    convert,
    design,
    excite,
    identify,
    montecarlo,
    params,
    serve,
    simulate,
    study,
    tune,
)

__all__ = ["COMMANDS"]

#: The commands, in the order ``fsmbench --help`` lists them.
COMMANDS: tuple[ModuleType, ...] = (params, simulate, identify, budget, design, study, serve,
                                    montecarlo, excite, tune, convert)
