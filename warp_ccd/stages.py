"""The stages of a frame, for your own pipelines: each a thin class that owns its buffers and launches its
kernels, in data-flow order:

1. Bounds: :class:`ObjectBounds` (object boxes from world vertices) or :class:`SceneBVH` (a tree per shape,
   deforming objects' trees refit; object boxes).
2. Broad phase: object pairs whose boxes overlap, :class:`BroadPhaseSAP` (sweep and prune on a grid) or
   :class:`BroadPhaseAllPairs` (the reference).
3. Mid phase: candidate triangle pairs, :class:`MidPhaseBVH` (tree against tree, with :class:`SceneBVH`) or
   :class:`MidPhaseAllPairs` (the reference, with :class:`ObjectBounds`).
4. Narrow phase: :class:`NarrowPhase` (the exact triangle test) or :class:`ContinuousNarrowPhase` (times of
   impact over a linear motion).
5. With a clearance: :class:`ClearancePhase`, the object pairs within it, their least distances, closest
   points and directions; with self-intersections, :class:`SelfIntersection`; with contacts,
   :class:`PenetrationDepth` (each pair's depth and its witness) and :class:`ContactStage` (the
   :class:`Contacts`: points, normals, depths, a few per pair).

Apart from the frame, :class:`TreeDistance` measures the least distance of chosen object pairs however far
apart (branch and bound over their trees).

What the frame calls of each kind is a protocol (:class:`BoundsStage`, :class:`BroadPhaseStage`,
:class:`MidPhaseStage`, :class:`NarrowPhaseStage`, :class:`ClearanceStage`, :class:`SelfStage`); the
factories make the stages of a :class:`~warp_ccd.PipelineOptions` (:func:`make_mid_phase`, the mid phase with
its bounds stage; :func:`make_narrow_phase`) or of a method name (:func:`make_broad_phase`). Every stage writes
into :class:`GrowableBuffer` s (a device array with a capacity and a counter); :func:`find_pairs` runs a broad
phase until its buffers hold every pair. Beside them: :func:`broad_phase_pairs`, the broad phase of boxes given as
numpy arrays, and :func:`build_tree`, one shape's tree on the host.
"""

from ._src.broadphase.sap import BroadPhaseAllPairs, BroadPhaseSAP, broad_phase_pairs, find_pairs, make_broad_phase
from ._src.midphase.all_pairs import MidPhaseAllPairs
from ._src.midphase.bvh import MidPhaseBVH
from ._src.narrowphase.clearance import ClearancePhase
from ._src.narrowphase.contacts import Contacts, ContactStage
from ._src.narrowphase.continuous import ContinuousNarrowPhase
from ._src.narrowphase.depth import DepthResult, PenetrationDepth
from ._src.narrowphase.discrete import NarrowPhase
from ._src.narrowphase.self_intersection import SelfIntersection
from ._src.pipeline.stages import (
    BoundsStage,
    BroadPhaseStage,
    ClearanceStage,
    MidPhaseStage,
    NarrowPhaseStage,
    SelfStage,
    make_mid_phase,
    make_narrow_phase,
)
from ._src.queries.tree_distance import TreeDistance
from ._src.runtime.buffers import GrowableBuffer
from ._src.trees.bounds import ObjectBounds
from ._src.trees.bvh import SceneBVH
from ._src.trees.reference import build_tree

__all__ = [
    "BoundsStage",
    "BroadPhaseAllPairs",
    "BroadPhaseSAP",
    "BroadPhaseStage",
    "ClearancePhase",
    "ClearanceStage",
    "ContactStage",
    "Contacts",
    "ContinuousNarrowPhase",
    "DepthResult",
    "GrowableBuffer",
    "MidPhaseAllPairs",
    "MidPhaseBVH",
    "MidPhaseStage",
    "NarrowPhase",
    "NarrowPhaseStage",
    "ObjectBounds",
    "PenetrationDepth",
    "SceneBVH",
    "SelfIntersection",
    "SelfStage",
    "TreeDistance",
    "broad_phase_pairs",
    "build_tree",
    "find_pairs",
    "make_broad_phase",
    "make_mid_phase",
    "make_narrow_phase",
]
