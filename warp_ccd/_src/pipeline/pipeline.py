"""The frame: refit (object bounds) -> broad phase -> mid phase -> narrow phase -> result.

:class:`CollisionPipeline` owns one object of each stage and calls their methods in order on the
scene's device; each stage launches its own work and exposes the buffers with counters it writes
(``counters``). All those counters live in one block (:class:`~warp_ccd._src.runtime.buffers.CounterRead`):
the frame starts by zeroing it (one memset) and ends by copying it to pinned host memory (one
small kernel) and waiting once; between stages the host reads nothing. On CUDA the whole
frame, optionally with the scene's motion, is a captured graph replayed each frame
(:class:`~warp_ccd._src.runtime.frame.CountedFrame`). A counter that passed its buffer's capacity makes that
buffer grow and the frame run again (then the graph is captured anew), so no pair is ever dropped.

A continuous pipeline (``continuous=True``) reports what happens over the linear motion of every
world vertex since the previous :meth:`~CollisionPipeline.detect` (or the pipeline's construction):
it keeps the motion's start, :attr:`~CollisionPipeline.world_vertex_start`, in one of two device
arrays; its frame refits every tree from swept boxes (:class:`~warp_ccd._src.trees.bvh.SceneBVH` with
``world_trees``), runs the broad and mid phases on them, then the continuous narrow phase
(:mod:`warp_ccd._src.narrowphase.continuous`), and copies the world vertices into the *other* array, the next
frame's start (a copy inside the frame, so inside its graph). A run of the frame that made a buffer
grow runs again on the same start (it only wrote the other array); the two arrays swap roles once
a frame fits, so each of the two frames (and graphs) reads one and writes the other.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from typing import Any

import numpy as np
import warp as wp

from ..broadphase.sap import make_broad_phase
from ..geometry.ccd import CCD_MAX_ITERATIONS, CCD_TOLERANCE
from ..geometry.triangle import TOLERANCE
from ..narrowphase.clearance import CLEARANCE_MAX, ClearancePhase
from ..narrowphase.continuous import ContinuousNarrowPhase, continuous_options
from ..narrowphase.self_intersection import SelfIntersection
from ..runtime.aliases import ArrayLike, DeviceLike
from ..runtime.arrays import host_array
from ..runtime.buffers import CounterRead, GrowableBuffer
from ..runtime.checks import integer_option, number_option
from ..runtime.frame import CountedFrame, FrameCache, frame_mode
from ..scene.scene import Scene, quat_to_matrix, transforms_to_poses
from ..trees.bvh import SceneBVH
from .result import NEAR_ROWS, CollisionResult
from .stages import make_mid_phase, make_narrow_phase

__all__ = ["CollisionPipeline", "CollisionResult", "collide"]  # CollisionResult: from .result

RIGID_LEAF_SIZE = 1
"""Default triangles per leaf in a scene of rigid objects: on the H100 the frame took 4.3 / 1.65 /
1.03 / 0.44 ms at 10^6 polyhedra / 10^5 80-triangle / 10^4 1,280-triangle / 10^3 mixed objects
with leaves of 1, against 5.5 / 2.3 / 1.39 / 0.48 with leaves of 2 and 7.7 / 3.4 / 1.93 / 0.57
with 4 (``warp_ccd/bench/box_tests.py``, ``bench/results/box_tests_sweep_cuda0.json``): the level by
level descent tests node pairs at memory speed, and a leaf pair's boxes are its triangles' boxes,
so that fewer pairs reach the exact test (half as many as with leaves of 2)."""

DEFORMING_LEAF_SIZE = 4
"""Default triangles per leaf in a scene with deforming objects, whose trees are refit every frame:
a quarter of the nodes to refit (and of the bytes it moves), for more triangle pairs per leaf pair
(``warp_ccd/bench/deforming.py``). Not in a continuous frame: its leaf pairs' triangle pairs each
cost a continuous test, dearer than a refit (leaves of one triangle: 18,088 candidates of 3,000
polyhedra over a step against 66,796 with leaves of 4)."""

STAGES = ("refit", "broad", "mid", "narrow")
"""Stage names of :attr:`CollisionResult.timings` (``refit``: tree refit, or object boxes alone
with the all-pairs mid phase); a pipeline with a clearance times ``clearance`` too."""

class CollisionPipeline:
    """Persistent collision detection for one :class:`Scene`, every frame on its device.

    Args:
        scene: the scene; its world vertices are read at each :meth:`detect`.
        broad_phase: ``"sap"`` (default) or ``"all_pairs"`` (reference; ``"nxn"`` is an alias).
        mid_phase: ``"bvh"`` (default: tree-vs-tree traversal) or ``"all_pairs"`` (reference:
            every triangle pair of each object pair).
        narrow_phase: ``"moller"`` (default) or ``"edge_face"``.
        tolerance: relative tolerance of touching contacts (see :mod:`warp_ccd._src.geometry.triangle`).
        timings: when True, synchronise after each stage and report ms per stage (frames are then
            launched eagerly).
        graph: replay each frame as a captured CUDA graph (default: on CUDA, unless ``timings``);
            False launches every kernel from Python (the CPU always does). Both give the same results.
        leaf_size: triangles per tree leaf (``bvh`` mid phase; default :data:`RIGID_LEAF_SIZE`, or
            :data:`DEFORMING_LEAF_SIZE` in a discrete pipeline of a scene with deforming objects that
            does not seek self-intersections: a leaf's pairs are candidates of the adjacency-aware test,
            the self frame's costliest kernel, and on the H100 a frame of 100 folded 10k-triangle sheets
            took 6.9 ms with leaves of 1 against 18.7 with leaves of 4, the pairwise part alike,
            ``bench/results/self_intersection_leaves_cuda0.json``).
        cut_depth: least level of the tree cut whose boxes make a big rigid object's box for the
            broad phase (``bvh`` mid phase; ``object_bounds``, :class:`~warp_ccd._src.trees.bvh.SceneBVH`).
        separating_axes: the traversal's box test (``bvh`` mid phase): 6 (default), the box around
            one object's box in the other's space, both ways round; 3, one way (see
            :mod:`warp_ccd._src.midphase.bvh`).
        object_bounds: a rigid object's box for the broad phase (``bvh`` mid phase): ``"auto"``
            (default), ``"vertices"``, ``"tree"``, or the most vertices of an object whose box comes
            from its vertices (see :class:`~warp_ccd._src.trees.bvh.SceneBVH`).
        segments: also compute the intersection segment of each triangle pair
            (:attr:`CollisionResult.segments`).
        containment: also report objects wholly inside another (winding number of one vertex,
            for object pairs where one object's box holds the other's vertex), in
            :attr:`CollisionResult.containment_pairs`.
        pair_capacity: initial capacity of the broad phase's object pairs (it grows).
        entry_capacity: initial capacity of the ``sap`` broad phase's grid entries (it grows;
            default: see :class:`~warp_ccd._src.broadphase.sap.BroadPhaseSAP`).
        candidate_capacity: initial capacity of the mid phase's candidate triangle pairs (it grows).
        hit_capacity: initial capacity of the narrow phase's intersecting triangle pairs (it grows).
        near_capacity: initial capacity of the object pairs within the clearance (it grows).
        front_capacity: initial capacity of the traversal's front of node pairs (``bvh`` mid phase;
            it grows; default four per object).
        rebuild_every: with the ``bvh`` mid phase, rebuild the trees' triangle order from the world
            vertices before every ``k``-th :meth:`detect` (:meth:`SceneBVH.rebuild
            <warp_ccd._src.trees.bvh.SceneBVH.rebuild>`: for deforming meshes whose refit trees have loosened;
            the results are the same, the traversal faster); 0 (default) never.
        continuous: report what collides over the linear motion of every world vertex since the
            previous :meth:`detect` (at the first, since construction): triangle pairs that meet at
            some time ``t`` in ``[0, 1]`` of it, with their times of impact
            (:attr:`CollisionResult.triangle_toi`; see :mod:`warp_ccd._src.narrowphase.continuous`). Every
            tree is then refit each frame from swept boxes (``leaf_size`` defaults to
            :data:`RIGID_LEAF_SIZE`). Not with ``segments``, ``containment`` or another
            ``narrow_phase`` than the default.
        min_distance: with ``continuous``, pairs that come within this distance (scene units,
            infinity norm, >= 0) collide too.
        ccd_tolerance: with ``continuous``, the test's distance tolerance (> 0, scene units: a false
            positive comes within about it of a contact; default
            :data:`~warp_ccd._src.geometry.ccd.CCD_TOLERANCE`).
        ccd_max_iterations: with ``continuous``, the most boxes one primitive query examines
            (default :data:`~warp_ccd._src.geometry.ccd.CCD_MAX_ITERATIONS`; past it the answer is a
            conservative collision).
        clearance: also report every object pair whose surfaces come within this distance (scene
            units, in ``[0, 1e37]``), with its least distance, closest points, direction and closest triangle
            pair (:attr:`CollisionResult.object_pairs` are then those pairs; see
            :mod:`warp_ccd._src.narrowphase.clearance`); 0 (default) adds nothing. Not with ``continuous``
            (whose ``min_distance`` is the clearance over a motion).
        self_intersections: also report the triangles of each object that meet each other beyond the
            vertices they share (:attr:`CollisionResult.self_pairs`, :attr:`CollisionResult.self_colliding`;
            see :mod:`warp_ccd._src.narrowphase.self_intersection`): a rigid object's from its shape, computed once
            at construction, a deforming object's every frame. With the ``bvh`` mid phase, not with
            ``continuous``.
        self_capacity: initial capacity of the self-intersecting triangle pairs (it grows).

    Attributes:
        boxes: the refit stage, object boxes (``lower``, ``upper``) recomputed each frame: the
            scene's :class:`~warp_ccd._src.trees.bvh.SceneBVH` (deforming objects' trees refit) with the ``bvh`` mid
            phase,
            else an :class:`~warp_ccd._src.trees.bounds.ObjectBounds`.
        broad, mid, narrow: the other stages; ``pairs``: the object pairs the broad phase writes.
        near_phase: with a clearance, the :class:`~warp_ccd._src.narrowphase.clearance.ClearancePhase`, else None.
        self_phase: with ``self_intersections``, the
            :class:`~warp_ccd._src.narrowphase.self_intersection.SelfIntersection`, else None.
        clearance: as above.
        counter_read: the :class:`~warp_ccd._src.runtime.buffers.CounterRead` of every buffer with a counter the
            frame writes (``pairs`` and each stage's ``counters``).
        graph: whether frames are replayed as CUDA graphs.
        rebuilds: tree rebuilds so far (``rebuild_every``).
        continuous: as above.
    """

    def __init__(
        self,
        scene: Scene,
        *,
        broad_phase: str = "sap",
        mid_phase: str = "bvh",
        narrow_phase: str = "moller",
        tolerance: float = TOLERANCE,
        timings: bool = False,
        graph: bool | None = None,
        leaf_size: int | None = None,
        cut_depth: int = 3,
        separating_axes: int = 6,
        object_bounds: str | int = "auto",
        segments: bool = False,
        containment: bool = False,
        pair_capacity: int | None = None,
        entry_capacity: int | None = None,
        candidate_capacity: int | None = None,
        hit_capacity: int | None = None,
        front_capacity: int | None = None,
        rebuild_every: int = 0,
        continuous: bool = False,
        min_distance: float = 0.0,
        ccd_tolerance: float = CCD_TOLERANCE,
        ccd_max_iterations: int = CCD_MAX_ITERATIONS,
        clearance: float = 0.0,
        near_capacity: int | None = None,
        self_intersections: bool = False,
        self_capacity: int | None = None,
    ) -> None:
        if not isinstance(scene, Scene):
            raise TypeError(f"scene: expected a warp_ccd.Scene, got {type(scene).__name__}")
        ccd = _continuous_check(continuous, min_distance, ccd_tolerance, ccd_max_iterations, narrow_phase,
                                segments, containment)
        self.clearance = number_option("clearance", clearance, low=0.0, high=CLEARANCE_MAX)
        if self.clearance > 0.0 and ccd is not None:
            raise ValueError("clearance: a continuous pipeline's least distance is its min_distance "
                             f"(continuous=True), got clearance={clearance!r}")
        mode = frame_mode(scene.device, False if graph is None and timings else graph)
        if graph and timings:
            raise ValueError("graph: a frame timed stage by stage (timings=True) cannot be one graph")
        self.rebuild_every = integer_option("rebuild_every", rebuild_every, low=0)
        if self.rebuild_every and mid_phase == "all_pairs":
            raise ValueError(f"rebuild_every must be 0 with the all_pairs mid phase (no trees), got {rebuild_every!r}")
        pair_capacity = integer_option("pair_capacity", pair_capacity, low=1, allow_none=True)
        if leaf_size is None:
            deforming_leaves = scene.deforming and not continuous and not self_intersections
            leaf_size = DEFORMING_LEAF_SIZE if deforming_leaves else RIGID_LEAF_SIZE
        self.scene = scene
        self.device = d = scene.device
        n = scene.num_objects
        self.timings = bool(timings)
        self.graph = mode == "graph"
        self.broad = make_broad_phase(broad_phase, device=d, entry_capacity=entry_capacity)
        self.continuous = ccd is not None
        if self.continuous:
            hit_capacity = integer_option("hit_capacity", hit_capacity, low=1, allow_none=True)
            self.narrow = ContinuousNarrowPhase(n, min_distance=ccd[0], tolerance=ccd[1], max_iterations=ccd[2],
                                                capacity=hit_capacity or max(256, 4 * n), device=d)
            # Leaf boxes padded by the discrete tolerance (at least the one of the test at t = 0 of
            # triangle_pair_toi), the least distance and the continuous tolerance.
            margin_rel = max(number_option("tolerance", tolerance, low=0.0, high=0.1, high_open=True), TOLERANCE)
            pad_abs = self.narrow.pad_abs
        else:
            self.narrow = make_narrow_phase(narrow_phase, n, tolerance=tolerance, hit_capacity=hit_capacity,
                                            segments=segments, containment=containment, device=d)
            margin_rel, pad_abs = self.narrow.tolerance, 0.0
        self.boxes, self.mid = make_mid_phase(
            mid_phase, scene, leaf_size=leaf_size, margin_rel=margin_rel, cut_depth=cut_depth,
            separating_axes=separating_axes, object_bounds=object_bounds, candidate_capacity=candidate_capacity,
            front_capacity=front_capacity, world_trees=self.continuous, pad_abs=pad_abs, clearance=self.clearance,
            device=d)
        near_capacity = integer_option("near_capacity", near_capacity, low=1, allow_none=True)
        self.near_phase = (ClearancePhase(n, self.clearance, tolerance=self.narrow.tolerance,
                                          capacity=near_capacity or max(64, n), device=d)
                           if self.clearance > 0.0 else None)
        if not isinstance(self_intersections, (bool, np.bool_)):
            raise ValueError(f"self_intersections must be True or False, got {self_intersections!r}")
        self.self_phase = None
        if self_intersections:
            if self.continuous:
                raise ValueError("self_intersections: a continuous pipeline does not report self-intersections "
                                 "(continuous=True)")
            if not isinstance(self.boxes, SceneBVH):
                raise ValueError(f"self_intersections: needs the trees of the bvh mid phase, "
                                 f"got mid_phase={mid_phase!r}")
            self.self_phase = SelfIntersection(
                scene, self.boxes, tolerance=self.narrow.tolerance, device=d,
                hit_capacity=integer_option("self_capacity", self_capacity, low=1, allow_none=True))
        # The motion's start, two arrays: a frame reads one and writes the other (module docs).
        self._starts = [wp.clone(scene.world_vertex), wp.empty_like(scene.world_vertex)] if self.continuous else None
        self._parity = 0
        # One pair slot an object to start with (the scaling scenes hold 0.01-0.13 pairs an object; a
        # crowded frame grows it once): the mid phase keeps a TreePair of 136 bytes a slot beside it.
        self.pairs = GrowableBuffer(wp.vec2i, pair_capacity or max(64, n), d, "broad-phase pairs")
        stages = (self.boxes, self.broad, self.mid, self.narrow) + ((self.near_phase,) if self.near_phase else ())
        buffers = [self.pairs, *(b for stage in stages for b in stage.counters)]
        # Data-flow order of the counters: the broad phase's own (grid entries) 0, its pairs 1, the
        # mid phase's 2 (its front's count tells little of its candidates'), the narrow phase's 3, the
        # clearance's 4 (a shortfall upstream scales the estimates downstream).
        flow = [1, *(k if k > 1 else 0 for k, stage in enumerate(stages) for _ in stage.counters)]
        if self.self_phase is not None:  # work of its own: it neither grows with the others nor they with it
            buffers += self.self_phase.counters
            flow += [None] * len(self.self_phase.counters)
        self.counter_read = CounterRead(buffers, d, stages=flow, watch=scene.input_check.fault)
        f = scene.collision_filter
        self._object_world = None if f is None or not f.use_world else f.object_world
        self._frames = FrameCache(self.counter_read, mode)  # by advance step (None: detection alone)
        self.rebuilds = 0
        self._detects = 0
        self._times = None

    @property
    def world_vertex_start(self) -> wp.array | None:
        """``(V,)`` world vertices where the next :meth:`detect`'s motion starts (the scene's vector
        type, on its device): the scene's at construction, then at the previous :meth:`detect`.
        None unless ``continuous``. Writing into it (``wp.copy``) moves the next motion's start."""
        return None if self._starts is None else self._starts[self._parity]

    def _launch_stages(self, parity: int = 0) -> None:
        """Enqueues the four stages (the frame's counters were reset before); with ``timings``,
        times each stage. A continuous frame works on swept boxes over the motion from start
        ``parity`` to the world vertices, then copies the world vertices into the other start (the
        next frame's)."""
        scene = self.scene
        start = self._starts[parity] if self.continuous else None
        sweep = {} if start is None else {"world_vertex_start": start}
        times = {} if self.timings else None

        def mark(stage: str, start: float) -> float:
            if times is None:
                return start
            wp.synchronize_device(self.device)
            now = time.perf_counter()
            times[stage] = (now - start) * 1e3
            return now

        if times is not None:
            wp.synchronize_device(self.device)
        t = time.perf_counter()
        self.boxes.refit(scene, **sweep)
        t = mark("refit", t)
        if scene.num_objects < 2:  # one object: its self-intersections alone (detect() asks only then)
            self.self_phase.launch(scene)
            mark("self", t)
            if times is not None:
                times.update({stage: 0.0 for stage in STAGES[1:]})
                if self.near_phase is not None:
                    times["clearance"] = 0.0
                times["total"] = sum(times.values())
            self._times = times
            return
        if scene.collision_filter is None:
            self.broad.launch(self.boxes.lower, self.boxes.upper, self.pairs)
        else:
            self.broad.launch(self.boxes.lower, self.boxes.upper, self.pairs, scene.collision_filter)
        t = mark("broad", t)
        self.mid.launch(scene, self.pairs, reset_counters=False, **sweep)
        t = mark("mid", t)
        if start is None:
            self.narrow.launch(scene, self.mid.candidates, self.pairs, self.boxes.lower, self.boxes.upper,
                               reset_counters=False)
        else:
            self.narrow.launch(scene, start, self.mid.candidates, reset_counters=False)
        t = mark("narrow", t)
        if self.near_phase is not None:
            self.near_phase.launch(scene, self.pairs, self.mid.candidates, self.narrow.hits, self.boxes.lower,
                             self.boxes.upper, reset_counters=False)
            t = mark("clearance", t)
        if self.self_phase is not None:
            self.self_phase.launch(scene)
            mark("self", t)
        if start is not None:
            wp.copy(self._starts[1 - parity], scene.world_vertex)
        if times is not None:
            times["total"] = sum(times.values())
        self._times = times

    def _frame(self, step: float | None) -> CountedFrame:
        """The frame that advances the scene by ``step`` first (None: detection alone); a continuous
        pipeline's reads the current start (one frame per start array)."""
        parity = self._parity
        key = (step, parity) if self.continuous else step
        frame = self._frames.frames.get(key)
        if frame is not None:
            return frame
        if step is None:
            return self._frames.get(key, lambda: self._launch_stages(parity))

        def launch():
            self.scene.enqueue_advance(step)
            self._launch_stages(parity)

        return self._frames.get(key, launch)

    def detect(self, advance: float | None = None) -> CollisionResult:
        """Runs one frame on the scene's world vertices.

        Args:
            advance: when given, first moves the scene by this many seconds as
                :meth:`Scene.advance <warp_ccd._src.scene.scene.Scene.advance>` does, in the same frame (on
                CUDA the same graph: one launch for motion and detection).

        Returns:
            A :class:`CollisionResult` holding views of this pipeline's device buffers, valid until
            the next ``detect()`` (:meth:`CollisionResult.copy` keeps them).
        """
        # Every step here is host time of every frame, a few microseconds in all: no array
        # allocated, no view made before it is asked for.
        start = time.perf_counter()
        scene = self.scene
        step = None if advance is None else scene.advance_host(advance)
        if scene.num_objects < 2 and (self.self_phase is None or scene.num_objects == 0):
            scene.input_check.check()  # no frame to read the inputs' fault with: read it now
            return self._no_pairs(step)
        if self.rebuild_every:
            self._detects += 1
            if self._detects % self.rebuild_every == 0:
                if step is not None:  # the frame would move the scene first: move it, then rebuild and detect
                    scene.enqueue_advance(step)
                    step = None
                self.boxes.rebuild(scene)
                self.rebuilds += 1
        frame = self._frame(step)
        grew = frame.run_once()
        if self.counter_read.watched:  # the device-side inputs (set_poses, ...) were bad
            scene.input_check.raise_for(self.counter_read.watched)
        wait_ms = frame.wait_ms
        runs = 1
        while grew:  # a buffer grew: detect again on the same world vertices (and the same start)
            frame = self._frame(None)
            grew = frame.run_once()
            wait_ms += frame.wait_ms
            runs += 1
        if scene.num_objects < 2:  # one object: its self-intersections alone
            phase = self.self_phase
            result = self._no_pairs(None, self_rows=(phase.hits.data[: phase.hits.last_count], phase.object_flag))
            if self._times is not None:
                result.timings = self._times
            result.host_ms = (time.perf_counter() - start) * 1e3 - wait_ms
            result.runs = runs
            return result
        narrow = self.narrow
        hits = narrow.hits
        rows = {"device_triangle_pairs": (hits.data, hits.last_count)}
        if self.continuous:
            rows["device_toi"] = (narrow.toi, hits.last_count)
            self._parity ^= 1  # the frame wrote the other start: the next motion starts here
        if narrow.contained is not None:
            rows["device_contained"] = (narrow.contained.data, narrow.contained.last_count)
        if narrow.segments:
            rows["device_segments"] = (narrow.segment, hits.last_count)
        near = self.near_phase
        if near is not None:
            count = near.near.last_count
            for name, array in zip(NEAR_ROWS, (near.near.data, near.distance, near.point, near.normal,
                                               near.triangle, near.intersecting)):
                rows[name] = (array, count)
        if self.self_phase is not None:
            rows["device_self_pairs"] = (self.self_phase.hits.data, self.self_phase.hits.last_count)
            rows["device_self_colliding"] = (self.self_phase.object_flag, scene.num_objects)
        result = CollisionResult._of_buffers(scene.num_objects, rows, narrow.object_colliding, self._times,
                                             self.mid.candidates.last_count, self.pairs.last_count, self.clearance,
                                             None if near is None else near.object_near)
        result.host_ms = (time.perf_counter() - start) * 1e3 - wait_ms
        result.runs = runs
        result.object_world = self._object_world
        return result

    def _no_pairs(self, step: float | None, self_rows: tuple | None = None) -> CollisionResult:
        """The result of a scene of fewer than two objects (moved by ``step`` first, when given); with
        ``self_rows``, the frame's ``(device_self_pairs, device_self_colliding)`` (one object's)."""
        n, d = self.scene.num_objects, self.device
        if step is not None:
            self.scene.enqueue_advance(step)
        empty = wp.zeros(0, dtype=wp.vec2i, device=d) if self.narrow.contained is not None else None
        no_segments = wp.zeros((0, 2), dtype=self.scene.vec3_type, device=d) if self.narrow.segments else None
        no_toi = None
        if self.continuous:
            wp.copy(self.world_vertex_start, self.scene.world_vertex)
            no_toi = wp.zeros(0, dtype=wp.float64, device=d)
        near = None
        if self.near_phase is not None:
            s, v = self.scene.scalar_type, self.scene.vec3_type
            near = dict(zip(NEAR_ROWS, (wp.zeros(0, dtype=wp.vec2i, device=d), wp.zeros(0, dtype=s, device=d),
                                        wp.zeros((0, 2), dtype=v, device=d), wp.zeros(0, dtype=v, device=d),
                                        wp.zeros(0, dtype=wp.vec2i, device=d), wp.zeros(0, dtype=wp.int32, device=d))))
            near["device_near"] = wp.zeros(n, dtype=wp.int32, device=d)
        stages = (*STAGES, "clearance", "total") if self.near_phase is not None else (*STAGES, "total")
        if self.self_phase is not None:
            stages = (*stages[:-1], "self", "total")
        no_self = self_rows
        if self_rows is None and self.self_phase is not None:
            no_self = (wp.zeros(0, dtype=wp.vec3i, device=d), wp.zeros(n, dtype=wp.int32, device=d))
        return CollisionResult(n, wp.zeros(0, dtype=wp.vec4i, device=d), wp.zeros(n, dtype=wp.int32, device=d),
                               {s: 0.0 for s in stages} if self.timings else None,
                               device_contained=empty, device_segments=no_segments, device_toi=no_toi,
                               clearance=self.clearance, near=near, self_rows=no_self)


def _continuous_check(continuous, min_distance, ccd_tolerance, ccd_max_iterations, narrow_phase: str,
                      segments: bool, containment: bool) -> tuple | None:
    """The continuous options checked: ``(min_distance, tolerance, max_iterations)``, or None for a
    discrete pipeline (whose continuous options must keep their defaults).

    Raises:
        ValueError: naming the option: a bad value, a continuous option without ``continuous=True``,
            or an option a continuous pipeline does not have (``segments``, ``containment``, another
            ``narrow_phase``).
    """
    if not isinstance(continuous, (bool, np.bool_)):
        raise ValueError(f"continuous must be True or False, got {continuous!r}")
    options = continuous_options(min_distance, ccd_tolerance, ccd_max_iterations)
    if not continuous:
        for name, value, default in zip(("min_distance", "ccd_tolerance", "ccd_max_iterations"), options,
                                        (0.0, CCD_TOLERANCE, CCD_MAX_ITERATIONS)):
            if value != default:
                raise ValueError(f"{name} is an option of continuous detection (continuous=True), got {value!r}")
        return None
    if segments:
        raise ValueError("segments: a continuous pipeline has no intersection segments (continuous=True)")
    if containment:
        raise ValueError("containment: a continuous pipeline does not report containment (continuous=True)")
    if narrow_phase != "moller":
        raise ValueError(f"narrow_phase: a continuous pipeline's narrow phase is its own (continuous=True), "
                         f"got {narrow_phase!r}")
    return options


def collide(meshes: Sequence, transforms: ArrayLike | None = None, device: DeviceLike = None,
            precision: str = "float32", *, transforms_end: ArrayLike | None = None,
            vertices_end: Sequence | None = None, min_distance: float = 0.0, world: ArrayLike | None = None,
            group: ArrayLike | None = None, mask: ArrayLike | None = None, exclude_pairs: ArrayLike | None = None,
            **options: Any) -> CollisionResult:
    """One-shot collision detection among meshes (like trimesh's ``CollisionManager``), at one
    moment or over a motion.

    Args:
        meshes: sequence of ``(vertices (n, 3) float, triangles (m, 3) int)``, one per object.
        transforms: ``(N, 4, 4)`` rigid transforms or ``(N, 7)`` poses (position, then quaternion
            ``x, y, z, w``), or None when vertices are in world space. Arrays anywhere: numpy, Warp,
            torch, JAX, CuPy.
        device: Warp device (default: Warp's default device).
        precision: ``"float32"`` (default) or ``"float64"``: vertices, poses and the exact test in
            double precision (for scenes far from the origin).
        transforms_end: ``(N, 4, 4)`` rigid transforms at the end of a motion (continuous detection:
            every vertex moves linearly from where ``transforms`` put it, ``t = 0``, to where
            ``transforms_end`` puts it, ``t = 1``).
        vertices_end: the meshes' vertices at the end of a motion, one ``(n_i, 3)`` array per mesh
            in the mesh's own frame (placed by ``transforms_end``, or else ``transforms``, when given):
            continuous detection of deforming meshes.
        min_distance: continuous detection: pairs that come within this distance (scene units,
            infinity norm) collide too; with neither end given, a query of the meshes as they are.
        world: ``(N,)`` world id of each object: objects of different worlds never pair; ``-1`` pairs
            with every world (:class:`~warp_ccd._src.scene.scene.Scene`). The result's :attr:`pair_world
            <warp_ccd._src.pipeline.result.CollisionResult.pair_world>` gives each pair's world.
        group: ``(N,)`` 32-bit collision group of each object: a pair collides when
            ``group[a] & mask[b]`` and ``group[b] & mask[a]`` are non-zero.
        mask: ``(N,)`` 32-bit collision mask of each object (the groups it collides with; see ``group``).
        exclude_pairs: ``(E, 2)`` object indices of pairs that never collide.
        **options: passed to :class:`CollisionPipeline` (``broad_phase``, ``mid_phase``,
            ``narrow_phase``, ``tolerance``, ``timings``, ``graph``, ``leaf_size``, ``segments``,
            ``containment``, ``clearance``, ``ccd_tolerance``, ``ccd_max_iterations``, capacities).
            ``clearance=d`` reports every pair of objects whose surfaces come within ``d`` too, with
            ``object_distance``, ``closest_points``, ``object_normal``, ``closest_triangles``.

    Returns:
        :class:`CollisionResult` with ``object_pairs``, ``triangle_pairs`` and ``colliding``; a
        continuous one (either end given, or ``min_distance`` > 0) with the pairs that collide at
        some time of the motion, and ``triangle_toi``, ``object_toi``, ``toi``.

    Raises:
        ValueError / TypeError: naming the bad mesh, transform or end and the problem; a ValueError
            too where the coordinates are too far from the origin for ``precision`` at the
            triangles' size (float32: beyond about ``8.4e3`` times the typical triangle, use
            ``precision="float64"``; see :meth:`Scene.from_meshes <warp_ccd._src.scene.scene.Scene.from_meshes>`).
    """
    min_distance = number_option("min_distance", min_distance, low=0.0)
    filters = {"world": world, "group": group, "mask": mask, "exclude_pairs": exclude_pairs}
    continuous = transforms_end is not None or vertices_end is not None or min_distance > 0.0
    if continuous:
        options["continuous"] = True
        options["min_distance"] = min_distance
    end_poses = None if transforms_end is None else _checked_poses(transforms_end, len(meshes), "transforms_end")
    if vertices_end is not None:  # deforming: world vertices at both ends, computed here
        ends = _vertices_end(meshes, vertices_end)
        start_poses = None if transforms is None else _checked_poses(transforms, len(meshes), "transforms")
        start = _placed([np.asarray(host_array(v, f"mesh {i}"), np.float64) for i, (v, _) in enumerate(meshes)],
                        start_poses)
        end = _placed(ends, start_poses if end_poses is None else end_poses)
        scene = Scene.from_meshes([(v, t) for v, (_, t) in zip(start, meshes)], deforming=True, device=device,
                                  precision=precision, **filters)
    else:
        scene = Scene.from_meshes(meshes, transforms, device=device, precision=precision, **filters)
    # One frame, run once: capacities few scenes exceed, where a persistent pipeline starts lean and
    # grows (a second run costs the whole frame again). Per object: every object pair of a small
    # scene or 32 pairs an object (8 bytes each), 4 grid entries a box for the sweep (16 bytes each
    # with the sort's scratch; boxes cover 2.25 cells on average, more with varied sizes: 2 a box
    # overflowed for a third of the seeds of 1,000 polyhedra). Per triangle: two candidates a
    # triangle per triangle of a leaf (32 bytes; 60 noisy spheres of 208k triangles need 0.6 to
    # 1.25 a triangle, so one a triangle overflowed for a fifth of the seeds), a node pair of the
    # front (24 bytes) and a quarter of a hit and of a touching candidate (8 bytes): about 64 bytes a
    # triangle, for this call only.
    n, tris = scene.num_objects, scene.num_triangles
    leaf = options.get("leaf_size") or RIGID_LEAF_SIZE
    options.setdefault("pair_capacity", max(64, min(n * (n - 1) // 2, 32 * n)))
    options.setdefault("entry_capacity", max(1024, 4 * n))
    options.setdefault("candidate_capacity", max(1024, 16 * n, 2 * leaf * tris))
    options.setdefault("hit_capacity", max(256, 4 * n, tris // 4))
    options.setdefault("front_capacity", max(1024, 4 * n, tris))
    pipeline = CollisionPipeline(scene, **options)
    if vertices_end is not None:
        scene.set_world_vertices(np.concatenate(end) if end else np.zeros((0, 3)))
    elif transforms_end is not None:
        scene.set_transforms(transforms_end)
    return pipeline.detect()


def _vertices_end(meshes: Sequence, vertices_end) -> list[np.ndarray]:
    """``vertices_end`` as float64 arrays, one per mesh, checked against the meshes."""
    if isinstance(vertices_end, (str, bytes)) or not isinstance(vertices_end, Sequence):
        raise ValueError(f"vertices_end: expected a sequence of (n, 3) arrays, one per mesh, "
                         f"got {type(vertices_end).__name__}")
    if len(vertices_end) != len(meshes):
        raise ValueError(f"vertices_end: expected {len(meshes)} arrays (one per mesh), got {len(vertices_end)}")
    out = []
    for i, (v, (v0, _)) in enumerate(zip(vertices_end, meshes)):
        try:
            a = np.asarray(host_array(v, f"vertices_end: mesh {i}"), dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"vertices_end: mesh {i}: not an array of numbers ({exc})") from None
        shape = np.shape(v0)
        if a.shape != shape:
            raise ValueError(f"vertices_end: mesh {i}: expected shape {shape} (its vertices), got {a.shape}")
        if not np.isfinite(a).all():
            raise ValueError(f"vertices_end: mesh {i}: vertex {int(np.argmin(np.isfinite(a).all(axis=1)))} "
                             f"is not finite")
        out.append(a)
    return out


def _checked_poses(transforms: ArrayLike, n: int, name: str) -> np.ndarray:
    """Rigid transforms validated and converted (:func:`~warp_ccd._src.scene.scene.transforms_to_poses`), the
    message naming ``name``: ``(n, 7)`` float64 poses."""
    try:
        return transforms_to_poses(transforms, n)
    except ValueError as exc:
        raise ValueError(f"{name}: {exc}" if name != "transforms" else str(exc)) from None


def _placed(vertices: list[np.ndarray], poses: np.ndarray | None) -> list[np.ndarray]:
    """Each mesh's ``vertices`` under its ``(N, 7)`` pose (:func:`_checked_poses`), in float64; as they
    are without poses."""
    if poses is None:
        return vertices
    rot = quat_to_matrix(poses[:, 3:])
    return [v @ rot[i].T + poses[i, :3] for i, v in enumerate(vertices)]
