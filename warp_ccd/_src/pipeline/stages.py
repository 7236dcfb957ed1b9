"""Stage kinds: what the frame calls of each (a :class:`typing.Protocol` a kind), and the factories that
make the stages of a pipeline's options.

:class:`~warp_ccd._src.pipeline.pipeline.CollisionPipeline` holds one stage of each kind and calls them in this
order, on the scene's device, the host reading nothing between them, with the same arguments whatever the
class (no branch on a concrete stage):

1. :class:`BoundsStage` (:class:`~warp_ccd._src.trees.bounds.ObjectBounds`,
   :class:`~warp_ccd._src.trees.bvh.SceneBVH`): ``refit(scene, world_vertex_start)`` writes the ``(N,)``
   object boxes ``lower``/``upper`` (swept over a motion when a start is given).
2. :class:`BroadPhaseStage` (:class:`~warp_ccd._src.broadphase.sap.BroadPhaseSAP`,
   :class:`~warp_ccd._src.broadphase.sap.BroadPhaseAllPairs`; made by
   :func:`~warp_ccd._src.broadphase.sap.make_broad_phase`): ``launch(lower, upper, pairs, pair_filter)`` writes
   the object pairs whose boxes overlap (and that the filter lets collide).
3. :class:`MidPhaseStage` (:class:`~warp_ccd._src.midphase.bvh.MidPhaseBVH`,
   :class:`~warp_ccd._src.midphase.all_pairs.MidPhaseAllPairs`; made with its bounds stage by
   :func:`make_mid_phase`): ``launch(scene, pairs, ...)`` writes candidate triangle pairs into ``candidates``.
4. :class:`NarrowPhaseStage` (:class:`~warp_ccd._src.narrowphase.discrete.NarrowPhase`,
   :class:`~warp_ccd._src.narrowphase.continuous.ContinuousNarrowPhase`; made by :func:`make_narrow_phase`):
   ``launch(scene, candidates, pairs, lower, upper, ...)`` writes the intersecting (or, over a motion,
   colliding) triangle pairs into ``hits`` and the per-object flags.
5. :class:`ClearanceStage` (:class:`~warp_ccd._src.narrowphase.clearance.ClearancePhase`), with a clearance:
   the object pairs within it, from the broad, mid and narrow phases' outputs.
6. :class:`SelfStage` (:class:`~warp_ccd._src.narrowphase.self_intersection.SelfIntersection`), with
   self-intersections: each object's own triangles that meet.

Every stage lists in ``counters`` the :class:`~warp_ccd._src.runtime.buffers.GrowableBuffer` s of its own
whose counters its launch writes; the frame zeroes them all before the first stage and reads them
once after the last, growing a buffer that overflowed and running the frame again. The protocols
are ``runtime_checkable``: ``isinstance(stage, MidPhaseStage)`` tells whether a stage has the
members; ``tests/test_pipeline.py`` checks the signatures too.
"""

from __future__ import annotations

from typing import Any, Protocol, runtime_checkable

import warp as wp

from ..midphase.all_pairs import MidPhaseAllPairs
from ..midphase.bvh import MidPhaseBVH
from ..narrowphase.continuous import ContinuousNarrowPhase
from ..narrowphase.discrete import NarrowPhase
from ..runtime.aliases import DeviceLike
from ..runtime.buffers import GrowableBuffer
from ..scene.filter import CollisionFilter
from ..scene.scene import Scene
from ..trees.bounds import ObjectBounds
from ..trees.bvh import SceneBVH
from .options import RIGID_LEAF_SIZE, PipelineOptions, pipeline_options

__all__ = ["BoundsStage", "BroadPhaseStage", "ClearanceStage", "MidPhaseStage", "NarrowPhaseStage", "SelfStage",
           "make_mid_phase", "make_narrow_phase"]


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

    def refit(self, scene: Scene, world_vertex_start: wp.array | None = None) -> None:
        """Writes :attr:`lower` and :attr:`upper` from ``scene``'s world vertices (host reads nothing); with
        ``world_vertex_start``, the boxes swept over the linear motion from those vertices to the scene's."""


@runtime_checkable
class BroadPhaseStage(Protocol):
    """Object pairs whose boxes overlap.

    Attributes:
        counters: buffers of its own with counters that :meth:`launch` writes, besides ``pairs``.
    """

    @property
    def counters(self) -> list[GrowableBuffer]: ...

    def launch(self, lower: wp.array, upper: wp.array, pairs: GrowableBuffer,
               pair_filter: CollisionFilter | None = None) -> None:
        """Writes the pairs ``(a, b)``, ``a < b``, of the ``(N,)`` closed boxes that overlap (and that
        ``pair_filter`` lets collide) into ``pairs`` (``wp.vec2i``; the caller resets its counter)."""


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

    def launch(self, scene: Scene, pairs: GrowableBuffer, *, reset_counters: bool = True,
               world_vertex_start: wp.array | None = None) -> None:
        """Writes the candidates of the object ``pairs`` of ``scene`` (``reset_counters=False``: the caller
        has zeroed :attr:`counters`; ``world_vertex_start``: a continuous frame's motion start)."""


@runtime_checkable
class NarrowPhaseStage(Protocol):
    """Exact tests of the candidates: the frame's result.

    Attributes:
        hits: ``wp.vec4i`` rows ``(obj_a, tri_a, obj_b, tri_b)`` of intersecting (colliding) triangle pairs.
        object_colliding: ``(N,)`` int32, 1 for an object with a hit.
        tolerance: its test's tolerance (relative to the triangles for the discrete tests, scene units for
            the continuous one).
        segments: whether :attr:`segment` holds each hit's intersection segment.
        segment: ``(hits.capacity, 2)`` end points, or None without ``segments``.
        contained: ``wp.vec2i`` rows ``(inner, outer)`` of objects wholly inside another, or None.
        toi: ``(hits.capacity,)`` float64 time of impact of each hit over a motion, or None (discrete).
        pad_abs: padding in scene units of the boxes upstream besides the tolerance's (a continuous test's least
            distance and tolerance; 0 for the discrete tests).
        counters: buffers with counters that :meth:`launch` writes (``hits`` among them).
    """

    hits: GrowableBuffer
    object_colliding: wp.array
    tolerance: float
    segments: bool
    segment: wp.array | None
    contained: GrowableBuffer | None
    toi: wp.array | None

    @property
    def pad_abs(self) -> float: ...

    @property
    def counters(self) -> list[GrowableBuffer]: ...

    def launch(self, scene: Scene, candidates: GrowableBuffer, object_pairs: GrowableBuffer | None = None,
               object_lower: wp.array | None = None, object_upper: wp.array | None = None, *,
               world_vertex_start: wp.array | None = None, reset_counters: bool = True) -> None:
        """Tests the ``candidates`` of ``scene``, writing :attr:`hits` and :attr:`object_colliding` (and what
        else it reports); ``object_pairs`` and the object boxes are the broad phase's input and output
        (containment reads them); ``world_vertex_start``, a continuous frame's motion start."""


@runtime_checkable
class ClearanceStage(Protocol):
    """The object pairs within a clearance, with their least distances and closest points.

    Attributes:
        near: ``wp.vec2i`` rows ``(a, b)`` of the object pairs within the clearance.
        counters: buffers with counters that :meth:`launch` writes (``near`` among them).
    """

    near: GrowableBuffer

    @property
    def counters(self) -> list[GrowableBuffer]: ...

    def launch(self, scene: Scene, pairs: GrowableBuffer, candidates: GrowableBuffer, hits: GrowableBuffer,
               object_lower: wp.array, object_upper: wp.array, *, reset_counters: bool = True) -> None:
        """Writes the pairs within the clearance from the frame's object pairs, candidates and hits."""


@runtime_checkable
class SelfStage(Protocol):
    """Each object's own triangles that meet beyond the vertices they share.

    Attributes:
        hits: ``wp.vec3i`` rows ``(object, tri_a, tri_b)``.
        object_flag: ``(N,)`` int32, 1 for an object through itself.
        counters: buffers with counters that :meth:`launch` writes (``hits`` among them).
    """

    hits: GrowableBuffer
    object_flag: wp.array

    @property
    def counters(self) -> list[GrowableBuffer]: ...

    def launch(self, scene: Scene) -> None:
        """Writes the frame's self-intersecting rows (the trees refit for this frame)."""


def make_mid_phase(scene: Scene, options: PipelineOptions | None = None, *, margin_rel: float = 0.0,
                   world_trees: bool = False, pad_abs: float = 0.0, device: DeviceLike = None,
                   **kwargs: Any) -> tuple[BoundsStage, MidPhaseStage]:
    """The mid phase of the options' ``mid_phase``, with the bounds stage it reads.

    Args:
        scene: the :class:`~warp_ccd._src.scene.scene.Scene`.
        options: the :class:`~warp_ccd._src.pipeline.options.PipelineOptions` (``mid_phase``, ``leaf_size``,
            ``cut_depth``, ``separating_axes``, ``object_bounds``, ``candidate_capacity``, ``front_capacity``,
            ``clearance``); None: the defaults.
        margin_rel: box padding relative to the boxes' size (the narrow phase's tolerance).
        world_trees: every tree in the world, refit each frame (``bvh``; a continuous frame's swept boxes).
        pad_abs: swept boxes' padding in scene units (a continuous test's least distance and tolerance).
        device: Warp device (the scene's).
        **kwargs: options by name, over ``options``.

    Returns:
        ``(bounds stage, mid phase)``: with ``"bvh"``, the scene's :class:`~warp_ccd._src.trees.bvh.SceneBVH`
        (object boxes, trees refit; leaves of ``leaf_size``, or of
        :data:`~warp_ccd._src.pipeline.options.RIGID_LEAF_SIZE` when None) and
        :class:`~warp_ccd._src.midphase.bvh.MidPhaseBVH`; with ``"all_pairs"`` (the reference),
        :class:`~warp_ccd._src.trees.bounds.ObjectBounds` and
        :class:`~warp_ccd._src.midphase.all_pairs.MidPhaseAllPairs`. The clearance pads the object boxes by
        half of it, the traversal's tests by all of it.
    """
    o = pipeline_options(options, kwargs, "make_mid_phase")
    n = scene.num_objects
    if o.mid_phase == "bvh":
        bvh = SceneBVH(scene, leaf_size=o.leaf_size or RIGID_LEAF_SIZE, margin_rel=margin_rel, cut_depth=o.cut_depth,
                       object_bounds=o.object_bounds, world_trees=world_trees, pad_abs=pad_abs,
                       box_pad=0.5 * o.clearance)
        return bvh, MidPhaseBVH(bvh, capacity=o.candidate_capacity or max(1024, 16 * n),
                                front_capacity=o.front_capacity, separating_axes=o.separating_axes,
                                clearance=o.clearance, device=device)
    return (ObjectBounds(n, device=device, margin_rel=margin_rel, pad_abs=pad_abs, box_pad=0.5 * o.clearance),
            MidPhaseAllPairs(capacity=o.candidate_capacity or max(1024, 64 * n), device=device))


def make_narrow_phase(num_objects: int, options: PipelineOptions | None = None, *, device: DeviceLike = None,
                      **kwargs: Any) -> NarrowPhaseStage:
    """The narrow phase of the options: a :class:`~warp_ccd._src.narrowphase.continuous.ContinuousNarrowPhase`
    with ``continuous`` (``min_distance``, ``ccd_tolerance``, ``ccd_max_iterations``), else a
    :class:`~warp_ccd._src.narrowphase.discrete.NarrowPhase` of ``narrow_phase`` (``tolerance``,
    ``segments``, ``containment``); ``hit_capacity`` default four an object, at least 256.

    Args:
        num_objects: ``N``.
        options: the :class:`~warp_ccd._src.pipeline.options.PipelineOptions`; None: the defaults.
        device: Warp device.
        **kwargs: options by name, over ``options``.
    """
    o = pipeline_options(options, kwargs, "make_narrow_phase")
    capacity = o.hit_capacity or max(256, 4 * num_objects)
    if o.continuous:
        return ContinuousNarrowPhase(num_objects, min_distance=o.min_distance, tolerance=o.ccd_tolerance,
                                     max_iterations=o.ccd_max_iterations, capacity=capacity, device=device)
    return NarrowPhase(num_objects, method=o.narrow_phase, tolerance=o.tolerance, capacity=capacity,
                       segments=o.segments, containment=o.containment, device=device)
