"""warp_ccd's implementation, by concept. Nothing here is public: the public modules (``warp_ccd``,
``warp_ccd.geometry``, ``warp_ccd.scene``, ``warp_ccd.stages``, ``warp_ccd.usd``, ``warp_ccd.preview``,
``warp_ccd.bench``, ``warp_ccd.trimesh``, ``warp_ccd.newton``) re-export what users call, and a name may move
between these folders without notice.

Folders, each importing only those above it in this list (``tests/test_layout.py`` keeps the rule):

* ``runtime``: arrays in from anywhere, buffers with a capacity and a counter, the counted frame (one
  CUDA graph, one read), option checks.
* ``geometry``: the exact tests as ``@wp.func``\\ s (triangles, distance, time of impact), precision.
* ``scene``: shapes, objects, poses, motion, filters: the flat device arrays every stage reads.
* ``trees``: object boxes, tree builds and refits, and the one tree-pair traversal every stage walks.
* ``broadphase``, ``midphase``, ``narrowphase``: the stages of a frame.
* ``queries``: the standalone queries (distance however far, continuous primitive queries).
* ``pipeline``: the frame, its options (checked once), results, ``collide()``.
* ``usd``: reading USD stages into scenes, writing animations.
* ``check``: the check application (``check_usd``, its report, overlay, many files, Ray).
* ``preview``, ``output``, ``cli``, ``bench``: pictures, atomic file writing, the ``warp-ccd`` command,
  the scaling benchmark.
* ``compat``: bridges to other libraries: drop-ins for their collision APIs (trimesh's ``CollisionManager``),
  warp_ccd's results where their simulations read them (newton's rigid contacts); each imports its library
  in its own module.
"""
