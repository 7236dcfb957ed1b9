"""Benchmarks of warp_ccd against its peers, in the same process: not part of the library.

The core package never imports this subpackage. ``warp-ccd bench`` and ``python -m warp_ccd.bench``
run :func:`~warp_ccd.bench.scaling.main`.

* :mod:`warp_ccd.bench.scaling`: ms per frame against the number of objects, per stage, with
  peers, checks and memory; JSON and a plot.
* :mod:`warp_ccd.bench.peers`: the peers (Warp's built-in tools, python-fcl, newton), each at its
  best.
* :mod:`warp_ccd.bench.compare`: comparing what two methods found (box pairs exactly, triangle
  pairs by classification).
"""

from .scaling import main

__all__ = ["main"]
