"""The stages of a frame, in data-flow order, each a thin class over the kernels of its module:

1. Bounds (:mod:`~warp_ccd._src.trees.bounds`, :mod:`~warp_ccd._src.trees.bvh`, trees built by
   :mod:`~warp_ccd._src.trees.build`): :class:`ObjectBounds` (object boxes from world vertices)
   or :class:`SceneBVH` (a tree per shape, deforming objects' trees refit; object boxes).
2. Broad phase (:mod:`~warp_ccd._src.broadphase.sap`): object pairs whose boxes overlap,
   :class:`BroadPhaseSAP` (sweep and prune on a grid) or :class:`BroadPhaseAllPairs` (the reference).
3. Mid phase (:mod:`~warp_ccd._src.midphase.bvh`): candidate triangle pairs, :class:`MidPhaseBVH`
   (tree against tree, with :class:`SceneBVH`) or :class:`MidPhaseAllPairs` (the reference, with
   :class:`ObjectBounds`).
4. Narrow phase (:mod:`~warp_ccd._src.narrowphase.discrete`): :class:`NarrowPhase`, the exact triangle test.
5. With a clearance (:mod:`~warp_ccd._src.narrowphase.clearance`): :class:`ClearancePhase`, the object pairs
   within it, their least distances, closest points and directions.

Apart from the frame, :class:`TreeDistance` (:mod:`~warp_ccd._src.queries.tree_distance`) measures the
least distance of chosen object pairs however far apart (branch and bound over their trees).

What the frame relies on of each kind is a protocol (:class:`BoundsStage`, :class:`BroadPhaseStage`,
:class:`MidPhaseStage`, :class:`NarrowPhaseStage`, in :mod:`~warp_ccd._src.pipeline.stages`), and a factory
makes each kind from a method name: :func:`make_broad_phase`, :func:`make_mid_phase` (the mid phase
with its bounds stage), :func:`make_narrow_phase`. Beside them: :func:`broad_phase_pairs`, the
broad phase of boxes given as numpy arrays, and :func:`build_tree`, one shape's tree on the host.
The device buffers (:mod:`~warp_ccd._src.runtime.buffers`) and the frame that runs the stages with one
counter read (:mod:`~warp_ccd._src.runtime.frame`) are shared by all.
"""

from ._src.broadphase.sap import BroadPhaseAllPairs, BroadPhaseSAP, broad_phase_pairs, make_broad_phase
from ._src.midphase.all_pairs import MidPhaseAllPairs
from ._src.midphase.bvh import MidPhaseBVH
from ._src.narrowphase.clearance import ClearancePhase
from ._src.narrowphase.discrete import NarrowPhase
from ._src.pipeline.stages import (
    BoundsStage,
    BroadPhaseStage,
    MidPhaseStage,
    NarrowPhaseStage,
    make_mid_phase,
    make_narrow_phase,
)
from ._src.queries.tree_distance import TreeDistance
from ._src.trees.bounds import ObjectBounds
from ._src.trees.bvh import SceneBVH
from ._src.trees.reference import build_tree

__all__ = [
    "BoundsStage",
    "BroadPhaseAllPairs",
    "BroadPhaseSAP",
    "BroadPhaseStage",
    "ClearancePhase",
    "MidPhaseAllPairs",
    "MidPhaseBVH",
    "MidPhaseStage",
    "NarrowPhase",
    "NarrowPhaseStage",
    "ObjectBounds",
    "SceneBVH",
    "TreeDistance",
    "broad_phase_pairs",
    "build_tree",
    "make_broad_phase",
    "make_mid_phase",
    "make_narrow_phase",
]
