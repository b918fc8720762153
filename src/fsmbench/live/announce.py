"""What ``fsmbench serve`` says on stdout once it serves: a sentence, or with ``--json`` one
JSON document, for the Tango server and the EPICS IOC alike."""

from __future__ import annotations

import json
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from fsmbench.live.serve import ServeOptions

__all__ = ["SERVE_FORMAT", "announce"]

#: The document ``fsmbench serve --json`` prints once it serves.
SERVE_FORMAT = ("fsmbench.serve", 1)


def announce(options: ServeOptions, sentence: str, *, address: str,
             **more: Any) -> None:
    """Say on stdout, once it serves, where: ``sentence``, or with ``announce_json`` one
    JSON line (format ``fsmbench.serve``): ``protocol``, ``address`` (what ``tune
    --device`` and the clients take), ``backend``, ``speed``, the folders, and ``more``."""
    if not options.announce_json:
        print(sentence, flush=True)
        return
    controllers = options.controllers_folder or options.output_folder
    doc = {"format": SERVE_FORMAT[0], "format_version": SERVE_FORMAT[1],
           "protocol": options.protocol, "address": address, "backend": options.backend,
           "speed": float(options.speed), "output_folder": str(options.output_folder.resolve()),
           "controllers_folder": str(controllers.resolve()), **more}
    print(json.dumps(doc), flush=True)
