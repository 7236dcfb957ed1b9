"""warp_ccd: collision detection among many moving triangle meshes, as NVIDIA Warp kernels.

One frame: world vertices -> object bounds -> broad phase (sweep and prune) -> mid phase ->
narrow phase (Möller's exact triangle test) -> object pairs, triangle pairs, per-object flags.

>>> import warp_ccd as wc
>>> res = wc.collide(meshes, transforms)            # one shot
>>> scene = wc.Scene.random(1000, seed=0)           # polyhedra in motion
>>> pipe = wc.CollisionPipeline(scene)
>>> scene.advance(1 / 60); res = pipe.detect()      # every frame
"""

from .geometry import TOLERANCE, tri_tri_edge_face, tri_tri_moller
from .pipeline import CollisionPipeline, CollisionResult, collide
from .preview import render_frame, save_preview
from .scene.motion import EllipseMotion
from .scene.scene import Scene
from .scene.shapes import SHAPES, icosphere, shape, validate_mesh
from .stages.broad_phase import BroadPhaseAllPairs as BroadPhaseNxN
from .stages.broad_phase import BroadPhaseSAP, broad_phase_pairs
from .stages.bvh import SceneBVH
from .stages.bvh_reference import build_tree
from .stages.mid_phase import MidPhaseAllPairs, MidPhaseBVH
from .stages.narrow_phase import NarrowPhase
from .usd.export import UsdAnimationWriter

__version__ = "0.1.0"

__all__ = [
    "SHAPES",
    "TOLERANCE",
    "UsdAnimationWriter",
    "BroadPhaseNxN",
    "BroadPhaseSAP",
    "CollisionPipeline",
    "CollisionResult",
    "EllipseMotion",
    "MidPhaseAllPairs",
    "MidPhaseBVH",
    "NarrowPhase",
    "Scene",
    "SceneBVH",
    "broad_phase_pairs",
    "build_tree",
    "collide",
    "icosphere",
    "render_frame",
    "save_preview",
    "shape",
    "tri_tri_edge_face",
    "tri_tri_moller",
    "validate_mesh",
]
