"""``python -m fsmbench.cli``: the ``fsmbench`` command."""

from fsmbench.cli.main import console

console()
