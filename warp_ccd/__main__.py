"""``python -m warp_ccd``: the ``warp-ccd`` command (see :mod:`warp_ccd.cli.commands`)."""

import sys

from .cli import main

sys.exit(main())
