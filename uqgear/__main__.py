"""``python -m uqgear``: the command line (see :mod:`uqgear.cli`)."""

import sys

from .cli import main

sys.exit(main())
