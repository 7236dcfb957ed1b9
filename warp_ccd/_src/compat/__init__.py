"""Bridges to other libraries: drop-ins for their collision APIs, built on the library's scenes, pipelines and
queries (``trimesh.collision.CollisionManager``: :mod:`~warp_ccd._src.compat.trimesh`), and warp_ccd's results
written where their simulations read them (mesh-mesh contacts for newton's rigid-body solvers:
:mod:`~warp_ccd._src.compat.newton`). Each imports its library inside its own module: importing warp_ccd never
imports them."""
