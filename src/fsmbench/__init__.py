"""fsmbench: a fast-steering-mirror beam-stabilisation bench from recordings to report.

Stages (one sub-package each): ``bench`` (parameters and physics), ``twin``
(the digital twin), ``io`` (recordings), ``ident`` (identification),
``budget`` (noise and error budget), ``control`` (analysis and design),
``report`` (figures and HTML). ``fsmbench.cli`` is the command line.
"""

__version__ = "0.1.0"

__all__ = ["__version__"]
