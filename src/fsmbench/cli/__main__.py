"""``python -m fsmbench.cli``: the ``fsmbench`` command."""

import sys

from fsmbench.cli.main import main

sys.exit(main())
