"""The scaling benchmark against peers, what users run (``warp-ccd bench``, ``python -m warp_ccd.bench``):
ms per frame against the number of objects, per stage, with Warp's built-in pipeline, python-fcl, the
all-pairs broad phase and newton's sweep and prune in the same run, their answers checked against this
package's.

* :mod:`~warp_ccd._src.bench.scaling`: its command (options, the run, exit status); :func:`main`.
* :mod:`~warp_ccd._src.bench.methods`: the methods it runs on a scene frame by frame, and one case.
* :mod:`~warp_ccd._src.bench.peers`: the peers (Warp's built-in tools, python-fcl, newton), each at its best.
* :mod:`~warp_ccd._src.bench.compare`: comparing what two methods found (box pairs exactly, triangle pairs by
  classification).
* :mod:`~warp_ccd._src.bench.timing`: frames timed as a careful Warp user runs them, and their summaries.
* :mod:`~warp_ccd._src.bench.memory`: what this package's pipeline holds, and its peak.
* :mod:`~warp_ccd._src.bench.meshes`: the scenes' shapes (``--triangles`` specs, meshes of real assets' sizes).
* :mod:`~warp_ccd._src.bench.report`: its tables, JSON and plot, and where a result was measured.

The developers' lab (profiles, GPU scripts, comparisons of stages) is not part of the package: it lives in
the repository's top-level ``bench/`` and imports from here.
"""
