"""warp_ccd: collision detection among many moving triangle meshes, as NVIDIA Warp kernels.

One frame: world vertices -> object bounds -> broad phase (sweep and prune) -> mid phase ->
narrow phase (Möller's exact triangle test) -> object pairs, triangle pairs, per-object flags.

>>> import warp_ccd as wc
>>> res = wc.collide(meshes, transforms)            # one shot
>>> res = wc.collide(meshes, transforms, clearance=0.01)  # and the pairs within 0.01: distances, points
>>> c = wc.contacts(meshes, transforms)             # for a solver: points, normals, depths
>>> far = wc.distance(arm_links, [table])           # least distances however far apart
>>> folds = wc.self_intersections(vertices, triangles)  # one mesh through itself
>>> scene = wc.Scene.random(1000, seed=0)           # polyhedra in motion
>>> pipe = wc.CollisionPipeline(scene)
>>> scene.advance(1 / 60); res = pipe.detect()      # every frame
>>> report = wc.check_usd("anim.usd")               # interpenetrations of a USD animation
>>> hit, toi = wc.ccd_queries("vertex_face", x0, x1)  # continuous: earliest time of impact

The API in levels: this module holds what a user of :func:`collide`, :class:`Scene`,
:class:`CollisionPipeline` and :func:`check_usd` needs; the namespaces below hold the rest:

* :mod:`warp_ccd.geometry`: the exact tests as ``@wp.func``\\ s, to call from your own kernels.
* :mod:`warp_ccd.scene`: shapes (``shape``, ``icosphere``), motion, mesh validation.
* :mod:`warp_ccd.stages`: the stage classes (bounds and trees, broad, mid and narrow phase), their
  protocols and factories.
* :mod:`warp_ccd.usd`: USD import (``scene_from_usd``), animation export, ``check_usd``'s report and overlay.
* :mod:`warp_ccd.preview`: preview pictures.
"""

from . import geometry, preview, scene, stages, usd  # noqa: F401 (the namespaces, as wc.stages, ...)
from ._src.check.check import check_usd
from ._src.check.report import CheckReport
from ._src.geometry.precision import PrecisionWarning
from ._src.geometry.triangle import TOLERANCE
from ._src.pipeline.options import PipelineOptions
from ._src.pipeline.pipeline import CollisionPipeline, collide, contacts
from ._src.pipeline.result import CollisionResult
from ._src.queries.ccd import ccd_queries
from ._src.queries.distance import DistanceQuery, DistanceResult, distance, self_intersections
from ._src.scene.scene import Scene

__version__ = "0.1.0"

__all__ = [
    "TOLERANCE",
    "CheckReport",
    "CollisionPipeline",
    "CollisionResult",
    "DistanceQuery",
    "DistanceResult",
    "PipelineOptions",
    "PrecisionWarning",
    "Scene",
    "ccd_queries",
    "check_usd",
    "collide",
    "contacts",
    "distance",
    "self_intersections",
]
