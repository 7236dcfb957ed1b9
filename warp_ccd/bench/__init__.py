"""Benchmarks of warp_ccd against its peers, in the same process: not part of the library.

The core package never imports this subpackage. ``warp-ccd bench`` and ``python -m warp_ccd.bench``
run :func:`~warp_ccd.bench.scaling.main`, the scaling benchmark:

* :mod:`warp_ccd.bench.scaling`: its command (options, the run, exit status): ms per frame against the
  number of objects, per stage, with peers, checks and memory; JSON and a plot.
* :mod:`warp_ccd.bench.methods`: the methods it runs on a scene frame by frame, and one case.
* :mod:`warp_ccd.bench.memory`: what this package's pipeline holds, and its peak.
* :mod:`warp_ccd.bench.report`: its tables, JSON and plot; the environment and JSON writer every
  benchmark records its results with.

What the benchmarks share:

* :mod:`warp_ccd.bench.command`: the command-line set-up of every other benchmark (``--device``,
  ``--frames``, ``--warmup``, ``--seed``, ``--out``; parsing, the device, the result document).
* :mod:`warp_ccd.bench.peers`: the peers (Warp's built-in tools, python-fcl, newton), each at its
  best.
* :mod:`warp_ccd.bench.compare`: comparing what two methods found (box pairs exactly, triangle
  pairs by classification).
* :mod:`warp_ccd.bench.timing`: frames timed as a careful Warp user runs them, and their summaries.
* :mod:`warp_ccd.bench.meshes`: the scenes' shapes (``--triangles`` specs, meshes of real assets' sizes).
* :mod:`warp_ccd.bench.awkward_pairs`: 10^5 near-degenerate triangle pairs and their verdicts.

Each other module is one benchmark, run as ``python -m warp_ccd.bench.NAME`` (its docstring gives the
command line; ``bench/run_cuda.sh`` runs them all on a CUDA machine).
"""

from .scaling import main

__all__ = ["main"]
