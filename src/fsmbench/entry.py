"""Sub-modules that are also the public API's entry points of their names.

``fsmbench.budget`` and ``fsmbench.study`` are packages (modules) of the stage that also
answer a call as :func:`fsmbench.api.budget` and :func:`fsmbench.api.study`. The stage
imports only this module; the call reaches the API when it is made (the one seam upward,
named in ``docs/architecture.md``), through ``sys.modules``: no module imports the API but
the package root.
"""

from __future__ import annotations

import sys
import types
from typing import Any

__all__ = ["callable_module"]


class _EntryModule(types.ModuleType):
    """A sub-module that is also the entry point of its name (see :func:`callable_module`)."""

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        # The package root imports the API before any of its sub-modules runs: found, not
        # imported, so no import edge leads from a stage up to the API.
        api = sys.modules["fsmbench.api"]
        return getattr(api, self.__name__.rsplit(".", 1)[-1])(*args, **kwargs)


def callable_module(name: str) -> None:
    """Make the module ``name`` (``fsmbench.budget``, ``fsmbench.study``) call the entry
    point of the same name.

    Importing a sub-module binds it as its parent's attribute: once anything imported
    ``fsmbench.budget.study``, ``fsmbench.budget`` is the package, not :func:`budget`.
    The package then answers the call itself, so ``fsmbench.budget(...)`` is the API
    whichever was bound last, and ``fsmbench.budget.study`` stays importable.
    """
    sys.modules[name].__class__ = _EntryModule
