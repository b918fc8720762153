"""``FsmBench INSTANCE``: the Tango device server as Starter (Astor) launches it.

Tango's Starter runs a server by its class name with the instance as the first argument,
so this is a console script of its own (``FsmBench``), beside ``fsmbench serve``.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Sequence

from fsmbench.live.serve import SERVER, refuse_second_start, tango_database

__all__ = ["main"]


def main(argv: Sequence[str] | None = None) -> int:
    """``FsmBench INSTANCE [Tango options]``: the server as Starter (Astor) launches it.

    Everything comes from the database; an instance with no device, a second
    start or an unreachable database is one line on stderr and status 2.
    """
    args = list(sys.argv[1:] if argv is None else argv)
    if not args or args[0].startswith("-"):
        print(f"usage: {SERVER} INSTANCE [Tango server options]  (register the device with "
              "`fsmbench serve INSTANCE --device NAME` or Jive)", file=sys.stderr)
        return 2
    instance = args[0]
    try:
        try:
            import tango  # noqa: F401  (a missing extra is one line)
        except ImportError:
            raise ValueError("needs PyTango: pip install 'fsmbench[tango]'") from None
        db = tango_database()
        devices = list(db.get_device_class_list(f"{SERVER}/{instance}"))
        if SERVER not in devices[1::2]:
            raise ValueError(f"{SERVER}/{instance} has no {SERVER} device in the database at "
                             f"{os.environ.get('TANGO_HOST')}: register one with `fsmbench "
                             f"serve {instance} --device NAME` (or Jive)")
        refuse_second_start(db, instance, None)
    except ValueError as exc:
        print(f"{SERVER} {instance}: error: {' '.join(str(exc).split())}", file=sys.stderr)
        return 2
    from fsmbench.live.device import FsmBench

    FsmBench.run_server(args=args)
    return 0
