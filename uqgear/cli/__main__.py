"""``python -m uqgear.cli``: the command line (:func:`uqgear.cli.main`)."""

import sys

from . import main

sys.exit(main())
