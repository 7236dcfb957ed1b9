"""``python -m warp_ccd.bench``: the scaling benchmark (see :mod:`warp_ccd.bench.scaling`)."""

import sys

from .scaling import main

sys.exit(main(prog="python -m warp_ccd.bench"))
