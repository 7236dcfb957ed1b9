"""``python -m warp_ccd.bench``: the scaling benchmark (see :mod:`warp_ccd.bench`)."""

import sys

from .._src.bench.scaling import main

sys.exit(main(prog="python -m warp_ccd.bench"))
