"""``python -m kinlearn``: the same as the ``kinlearn`` command."""

import sys

from .cli.main import main

sys.exit(main())
