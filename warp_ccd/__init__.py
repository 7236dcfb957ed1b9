"""warp_ccd: collision detection among many moving triangle meshes, as NVIDIA Warp kernels.

One frame: world vertices -> object bounds -> broad phase (sweep and prune) -> mid phase ->
narrow phase (Möller's exact triangle test) -> object pairs, triangle pairs, per-object flags.

>>> import warp_ccd as wc
>>> res = wc.collide(meshes, transforms)            # one shot
>>> res = wc.collide(meshes, transforms, clearance=0.01)  # and the pairs within 0.01: distances, points
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

import importlib
from typing import Any

from . import geometry, preview, scene, stages, usd  # noqa: F401 (the namespaces, as wc.stages, ...)
from ._deprecated import install_moved_modules, module_aliases, warn_renamed
from .geometry import TOLERANCE
from .geometry.ccd_queries import ccd_queries
from .geometry.precision import PrecisionWarning
from .pipeline import CollisionPipeline, CollisionResult, collide
from .query import DistanceQuery, distance, self_intersections
from .scene import Scene
from .stages import broad_phase_pairs
from .usd import CheckReport, check_usd

__version__ = "0.1.0"

__all__ = [
    "TOLERANCE",
    "CheckReport",
    "CollisionPipeline",
    "CollisionResult",
    "DistanceQuery",
    "PrecisionWarning",
    "Scene",
    "broad_phase_pairs",
    "ccd_queries",
    "check_usd",
    "collide",
    "distance",
    "self_intersections",
]

# Names of the top level until 0.1, kept one release: each use warns and reaches its new home.
_moved_name = module_aliases(__name__, {
    **{name: f"warp_ccd.scene:{name}" for name in ("SHAPES", "EllipseMotion", "icosphere", "shape",
                                                      "validate_mesh")},
    **{name: f"warp_ccd.stages:{name}" for name in ("BroadPhaseSAP", "MidPhaseAllPairs", "MidPhaseBVH",
                                                       "NarrowPhase", "SceneBVH", "build_tree")},
    "BroadPhaseNxN": "warp_ccd.stages:BroadPhaseAllPairs",
    **{name: f"warp_ccd.geometry:{name}" for name in ("tri_tri_edge_face", "tri_tri_moller")},
    **{name: f"warp_ccd.preview:{name}" for name in ("render_frame", "save_preview")},
    "UsdAnimationWriter": "warp_ccd.usd:UsdAnimationWriter",
})

# Modules of 0.1 that moved into a room: their old paths import (with a warning) for one release, and
# their names are found in their new homes (the main one first).
_MOVED_MODULES = {
    "aabb": ("geometry.box", "stages.bounds"),
    "precision": ("geometry.precision",),
    "shapes": ("scene.shapes",),
    "motion": ("scene.motion",),
    "buffers": ("stages.buffers",),
    "frame": ("stages.frame",),
    "bvh": ("stages.bvh",),
    "bvh_build": ("stages.bvh_build", "stages.bvh_reference"),
    "broad_phase": ("stages.broad_phase",),
    "mid_phase": ("stages.mid_phase",),
    "narrow_phase": ("stages.narrow_phase", "geometry.triangle", "geometry.primitives", "stages.crossing"),
    "crossing": ("stages.crossing", "stages.surface"),
    "usd_import": ("usd.importer", "usd.stage", "usd.meshes", "usd.poses", "usd.workers"),
    "check": ("usd.check",),
    "cli_common": ("cli.common",),
}
install_moved_modules({f"warp_ccd.{old}": tuple(f"warp_ccd.{h}" for h in homes)
                       for old, homes in _MOVED_MODULES.items()})


def __getattr__(name: str) -> Any:
    if name in _MOVED_MODULES:  # wc.narrow_phase, as the package's attribute it was
        return importlib.import_module(f"warp_ccd.{name}")
    return _moved_name(name)


def _scene_from_usd(cls: type[Scene], *args: Any, **kwargs: Any) -> Scene:
    """Deprecated: :func:`warp_ccd.usd.scene_from_usd` (the scene room does not read USD)."""
    warn_renamed("Scene.from_usd", "warp_ccd.usd.scene_from_usd", stacklevel=3)
    return usd.scene_from_usd(*args, **kwargs)


Scene.from_usd = classmethod(_scene_from_usd)
