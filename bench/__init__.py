"""The developers' lab: benchmarks, profiles and GPU scripts of warp_ccd, kept beside the package and not
shipped with it.

What users run, the scaling benchmark against peers (``warp-ccd bench``, ``python -m warp_ccd.bench``), is in
the package (``warp_ccd/_src/bench/``); its peers, comparisons, timing and report serve the lab too. Each
module here is one benchmark, run from the repository root as ``python -m bench.NAME`` (its docstring gives
the command line); ``bench/run_cuda.sh`` runs them all on a CUDA machine (``DEVICE=cpu SMOKE=1`` at tiny
sizes, to check the scripts), results in ``bench/results/``.

* frames: ``pipeline`` (the whole frame against Warp's built-in pipeline, through the scaling benchmark),
  ``frame_stages`` (a small frame as a graph, stage by stage), ``profile_frame`` (activity by activity),
  ``box_tests`` (the traversal's options), ``deforming`` (trees refit every frame), ``worlds`` (many
  independent worlds).
* stages and trees: ``broad_phase`` (boxes alone, against ``wp.Bvh`` and newton), ``build`` (tree builds,
  one-shot ``collide()`` against python-fcl), ``narrow_phase`` (what one verdict on every device costs),
  ``kernel_resources`` (registers and spills).
* queries: ``ccd_queries`` and ``continuous`` (continuous collision), ``clearance`` and ``distance``,
  ``self_intersection``.
* the host: ``host_breakdown``, ``host_after_wait``.
* USD: ``usd_check``, ``usd_export``, ``distributed`` (the check on Ray).
* before and after a change: ``frame_ab`` (the frame of two source trees, alternating rounds in one run),
  ``kernel_times_ab`` (their kernels' GPU times a frame).

Shared: ``command`` (the command-line set-up and the result document) and ``timing`` (row numbers, timed
frames). ``narrow_phase`` takes its near-degenerate pairs from the tests (``tests/awkward_pairs.py``).
"""
