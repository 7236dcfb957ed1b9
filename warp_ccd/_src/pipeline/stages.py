"""Stage kinds: what the frame relies on of each (a :class:`typing.Protocol` a kind), and the
factories that make a stage from a method name.

:class:`~warp_ccd._src.pipeline.pipeline.CollisionPipeline` holds one stage of each kind and calls them in this
order, on the scene's device, the host reading nothing between them:

1. :class:`BoundsStage` (:class:`~warp_ccd._src.trees.bounds.ObjectBounds`,
   :class:`~warp_ccd._src.trees.bvh.SceneBVH`): ``refit(scene)`` writes the ``(N,)`` object boxes
   ``lower``/``upper``.
2. :class:`BroadPhaseStage` (:class:`~warp_ccd._src.broadphase.sap.BroadPhaseSAP`,
   :class:`~warp_ccd._src.broadphase.sap.BroadPhaseAllPairs`; made by
   :func:`~warp_ccd._src.broadphase.sap.make_broad_phase`): ``launch(lower, upper, pairs)`` writes
   the object pairs whose boxes overlap.
3. :class:`MidPhaseStage` (:class:`~warp_ccd._src.midphase.bvh.MidPhaseBVH`,
   :class:`~warp_ccd._src.midphase.all_pairs.MidPhaseAllPairs`; made with its bounds stage by
   :func:`make_mid_phase`): ``launch(scene, pairs, reset_counters=...)`` writes candidate triangle
   pairs into ``candidates``.
4. :class:`NarrowPhaseStage` (:class:`~warp_ccd._src.narrowphase.discrete.NarrowPhase`; made by
   :func:`make_narrow_phase`): ``launch(scene, candidates, pairs, lower, upper,
   reset_counters=...)`` writes the intersecting triangle pairs into ``hits`` and the per-object
   flags.

Every stage lists in ``counters`` the :class:`~warp_ccd._src.runtime.buffers.GrowableBuffer` s of its own
whose counters its launch writes; the frame zeroes them all before the first stage and reads them
once after the last, growing a buffer that overflowed and running the frame again. The protocols
are ``runtime_checkable``: ``isinstance(stage, MidPhaseStage)`` tells whether a stage has the
members (not their signatures).
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import warp as wp

from ..geometry.triangle import TOLERANCE
from ..midphase.all_pairs import MidPhaseAllPairs
from ..midphase.bvh import MidPhaseBVH
from ..narrowphase.discrete import NarrowPhase
from ..runtime.aliases import DeviceLike
from ..runtime.buffers import GrowableBuffer
from ..runtime.checks import integer_option
from ..scene.scene import Scene
from ..trees.bounds import ObjectBounds
from ..trees.bvh import LEAF_SIZE_MAX, SceneBVH

__all__ = ["MID_METHODS", "BoundsStage", "BroadPhaseStage", "MidPhaseStage", "NarrowPhaseStage", "make_mid_phase",
           "make_narrow_phase"]

MID_METHODS = ("bvh", "all_pairs")
"""Mid-phase methods (:func:`make_mid_phase`): tree-vs-tree traversal, and the all-pairs reference."""


@runtime_checkable
class BoundsStage(Protocol):
    """Object boxes, recomputed every frame from the scene's world vertices.

    Attributes:
        lower, upper: ``(N,)`` ``wp.vec3`` object boxes (world, scene units), written by :meth:`refit`.
        counters: buffers with counters that :meth:`refit` writes (none so far).
    """

    lower: wp.array
    upper: wp.array

    @property
    def counters(self) -> list[GrowableBuffer]: ...

    def refit(self, scene: Scene) -> None:
        """Writes :attr:`lower` and :attr:`upper` from ``scene``'s world vertices (host reads nothing).
        A continuous frame calls ``refit(scene, world_vertex_start)``: swept boxes, over the motion
        from those vertices to the scene's."""


@runtime_checkable
class BroadPhaseStage(Protocol):
    """Object pairs whose boxes overlap.

    Attributes:
        counters: buffers of its own with counters that :meth:`launch` writes, besides ``pairs``.
    """

    @property
    def counters(self) -> list[GrowableBuffer]: ...

    def launch(self, lower: wp.array, upper: wp.array, pairs: GrowableBuffer) -> None:
        """Writes the pairs ``(a, b)``, ``a < b``, of the ``(N,)`` closed boxes that overlap into
        ``pairs`` (``wp.vec2i``; the caller resets its counter)."""


@runtime_checkable
class MidPhaseStage(Protocol):
    """Candidate triangle pairs of the broad phase's object pairs.

    Attributes:
        candidates: ``wp.vec4i`` rows ``(obj_a, tri_a, obj_b, tri_b)`` for the narrow phase.
        counters: buffers with counters that :meth:`launch` writes (``candidates`` among them).
    """

    candidates: GrowableBuffer

    @property
    def counters(self) -> list[GrowableBuffer]: ...

    def launch(self, scene: Scene, pairs: GrowableBuffer, *, reset_counters: bool = True) -> None:
        """Writes the candidates of the object ``pairs`` of ``scene`` (``reset_counters=False``:
        the caller has zeroed :attr:`counters`; a continuous frame passes ``world_vertex_start`` too)."""


@runtime_checkable
class NarrowPhaseStage(Protocol):
    """Exact tests of the candidates: the frame's result.

    Attributes:
        hits: ``wp.vec4i`` rows ``(obj_a, tri_a, obj_b, tri_b)`` of intersecting triangle pairs.
        object_colliding: ``(N,)`` int32, 1 for an object with a hit.
        segments: whether :attr:`segment` holds each hit's intersection segment.
        segment: ``(hits.capacity, 2)`` end points, or None without ``segments``.
        contained: ``wp.vec2i`` rows ``(inner, outer)`` of objects wholly inside another, or None
            when not asked for.
        counters: buffers with counters that :meth:`launch` writes (``hits`` among them).
    """

    hits: GrowableBuffer
    object_colliding: wp.array
    segments: bool
    segment: wp.array | None
    contained: GrowableBuffer | None

    @property
    def counters(self) -> list[GrowableBuffer]: ...

    def launch(self, scene: Scene, candidates: GrowableBuffer, object_pairs: GrowableBuffer | None = None,
               object_lower: wp.array | None = None, object_upper: wp.array | None = None, *,
               reset_counters: bool = True) -> None:
        """Tests the ``candidates`` of ``scene``, writing :attr:`hits` and :attr:`object_colliding`
        (and the segments and containment pairs when asked for); ``object_pairs`` and the object
        boxes are the broad phase's input and output, needed with containment."""


def make_mid_phase(method: str, scene: Scene, *, leaf_size: int = 1, margin_rel: float = 0.0, cut_depth: int = 3,
                   separating_axes: int = 6, object_bounds: str | int = "auto", candidate_capacity: int | None = None,
                   front_capacity: int | None = None, world_trees: bool = False, pad_abs: float = 0.0,
                   clearance: float = 0.0, device: DeviceLike = None) -> tuple[BoundsStage, MidPhaseStage]:
    """The mid phase of a method name, with the bounds stage it reads.

    Args:
        method: ``"bvh"``: the scene's :class:`~warp_ccd._src.trees.bvh.SceneBVH` (object boxes, trees
            refit) and :class:`~warp_ccd._src.midphase.bvh.MidPhaseBVH`; ``"all_pairs"`` (the
            reference): :class:`~warp_ccd._src.trees.bounds.ObjectBounds` and
            :class:`~warp_ccd._src.midphase.all_pairs.MidPhaseAllPairs`.
        scene: the :class:`~warp_ccd._src.scene.scene.Scene`.
        leaf_size: triangles per tree leaf, in ``[1, LEAF_SIZE_MAX]`` (checked with either method).
        margin_rel: box padding relative to the boxes' size (the narrow phase's tolerance).
        cut_depth: least level of each tree's cut (``bvh``; see :class:`~warp_ccd._src.trees.bvh.SceneBVH`).
        separating_axes: axes of the traversal's box test (``bvh``; see
            :class:`~warp_ccd._src.midphase.bvh.MidPhaseBVH`).
        object_bounds: how a rigid object's box is made (``bvh``; see :class:`~warp_ccd._src.trees.bvh.SceneBVH`).
        candidate_capacity: initial capacity of the candidates (>= 1; default 16 an object with
            ``bvh``, 64 with ``all_pairs``, at least 1,024).
        front_capacity: initial capacity of the traversal's front (>= 1; ``bvh``; default four per object).
        world_trees: every tree in the world, refit each frame (``bvh``; a continuous frame's swept boxes).
        pad_abs: swept boxes' padding in scene units (a continuous test's least distance and tolerance).
        clearance: candidates within this distance (scene units): object boxes padded by half of it,
            the traversal's tests by all of it (:class:`~warp_ccd._src.midphase.bvh.MidPhaseBVH`).
        device: Warp device (the scene's).

    Returns:
        ``(bounds stage, mid phase)``.

    Raises:
        ValueError: an unknown method (the message lists the known ones), or a bad option (naming it).
    """
    if not isinstance(method, str) or method not in MID_METHODS:
        raise ValueError(f"mid_phase must be 'bvh' or 'all_pairs', got {method!r}")
    leaf_size = integer_option("leaf_size", leaf_size, low=1, high=LEAF_SIZE_MAX)
    candidate_capacity = integer_option("candidate_capacity", candidate_capacity, low=1, allow_none=True)
    front_capacity = integer_option("front_capacity", front_capacity, low=1, allow_none=True)
    n = scene.num_objects
    if method == "bvh":
        bvh = SceneBVH(scene, leaf_size=leaf_size, margin_rel=margin_rel, cut_depth=cut_depth,
                       object_bounds=object_bounds, world_trees=world_trees, pad_abs=pad_abs, box_pad=0.5 * clearance)
        return bvh, MidPhaseBVH(bvh, capacity=candidate_capacity or max(1024, 16 * n), front_capacity=front_capacity,
                                separating_axes=separating_axes, clearance=clearance, device=device)
    return (ObjectBounds(n, device=device, margin_rel=margin_rel, pad_abs=pad_abs, box_pad=0.5 * clearance),
            MidPhaseAllPairs(capacity=candidate_capacity or max(1024, 64 * n), device=device))


def make_narrow_phase(method: str, num_objects: int, *, tolerance: float = TOLERANCE,
                      hit_capacity: int | None = None, segments: bool = False, containment: bool = False,
                      device: DeviceLike = None) -> NarrowPhaseStage:
    """The narrow phase of a method name: a :class:`~warp_ccd._src.narrowphase.discrete.NarrowPhase`.

    Args:
        method: ``"moller"`` or ``"edge_face"``
            (:data:`~warp_ccd._src.narrowphase.discrete.NARROW_METHODS`).
        num_objects: ``N``.
        tolerance: relative tolerance of touching contacts, in ``[0, 0.1)``.
        hit_capacity: initial capacity of the hits (>= 1; default four an object, at least 256).
        segments: as for :class:`~warp_ccd._src.narrowphase.discrete.NarrowPhase`.
        containment: as for :class:`~warp_ccd._src.narrowphase.discrete.NarrowPhase`.
        device: as for :class:`~warp_ccd._src.narrowphase.discrete.NarrowPhase`.

    Raises:
        ValueError: an unknown method (the message lists the known ones), or a bad option (naming it;
            the method and the tolerance are checked by the class).
    """
    hit_capacity = integer_option("hit_capacity", hit_capacity, low=1, allow_none=True)
    return NarrowPhase(num_objects, method=method, tolerance=tolerance,
                       capacity=hit_capacity or max(256, 4 * num_objects), segments=segments,
                       containment=containment, device=device)
