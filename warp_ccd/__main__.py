"""``python -m warp_ccd``: the ``warp-ccd`` command (see :mod:`warp_ccd._src.cli.commands`)."""

import sys

from ._src.cli.commands import main

sys.exit(main())
