"""The scaling benchmark: ms per frame against the number of objects, per stage, with peers in the same run.

``warp-ccd bench`` and ``python -m warp_ccd.bench`` run :func:`main` (options, output and exit status:
:mod:`warp_ccd._src.bench.scaling`)::

    python -m warp_ccd.bench --device cuda:0 --objects 1e2 1e3 1e4 1e5 1e6 --triangles poly 80 \\
        --out scaling_cuda0.json --plot scaling_cuda0.png

The developers' benchmarks (profiles, GPU scripts, comparisons of stages) are not shipped: they live in the
repository's ``bench/`` folder.
"""

from .._src.bench.scaling import main

__all__ = ["main"]
