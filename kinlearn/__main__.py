"""``python -m kinlearn``: the same as the ``kinlearn`` command."""

import sys

from .cli import main

sys.exit(main())
