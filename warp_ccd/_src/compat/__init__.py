"""Drop-ins for other libraries' collision APIs, built on the library's scenes, pipelines and queries:
``trimesh.collision.CollisionManager`` (:mod:`~warp_ccd._src.compat.trimesh`)."""
