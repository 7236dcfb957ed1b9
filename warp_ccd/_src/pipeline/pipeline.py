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
from ..geometry.triangle import TOLERANCE
from ..narrowphase.clearance import ClearancePhase
from ..narrowphase.contacts import Contacts, ContactStage
from ..narrowphase.depth import PenetrationDepth
from ..narrowphase.self_intersection import SelfIntersection
from ..runtime.aliases import ArrayLike, DeviceLike
from ..runtime.arrays import host_array
from ..runtime.buffers import CounterRead, GrowableBuffer
from ..runtime.frame import CountedFrame, FrameCache, frame_mode
from ..runtime.options import check_option
from ..scene.scene import Scene, quat_to_matrix, transforms_to_poses
from .options import DEFORMING_LEAF_SIZE, RIGID_LEAF_SIZE, PipelineOptions, pipeline_options
from .result import NEAR_ROWS, CollisionResult
from .stages import make_mid_phase, make_narrow_phase

__all__ = ["CollisionPipeline", "CollisionResult", "collide", "contacts"]  # CollisionResult: from .result

STAGES = ("refit", "broad", "mid", "narrow")
"""Stage names of :attr:`CollisionResult.timings` (``refit``: tree refit, or object boxes alone
with the all-pairs mid phase); a pipeline with a clearance times ``clearance`` too."""


class CollisionPipeline:
    """Persistent collision detection for one :class:`Scene`, every frame on its device.

    Args:
        scene: the scene; its world vertices are read at each :meth:`detect`.
        options: a :class:`~warp_ccd._src.pipeline.options.PipelineOptions` (every option, checked when it was
            made); None: the defaults.
        **kwargs: options by name (fields of :class:`~warp_ccd._src.pipeline.options.PipelineOptions`, over
            ``options``): ``CollisionPipeline(scene, clearance=0.01)``.

    Attributes:
        options: the :class:`~warp_ccd._src.pipeline.options.PipelineOptions` the pipeline runs with (its
            ``leaf_size`` chosen for the scene where it was None).
        boxes: the refit stage, object boxes (``lower``, ``upper``) recomputed each frame: the
            scene's :class:`~warp_ccd._src.trees.bvh.SceneBVH` (deforming objects' trees refit) with the ``bvh``
            mid phase, else an :class:`~warp_ccd._src.trees.bounds.ObjectBounds` (a
            :class:`~warp_ccd._src.pipeline.stages.BoundsStage` either way).
        broad, mid, narrow: the other stages (:class:`~warp_ccd._src.pipeline.stages.BroadPhaseStage`,
            :class:`~warp_ccd._src.pipeline.stages.MidPhaseStage`,
            :class:`~warp_ccd._src.pipeline.stages.NarrowPhaseStage`); ``pairs``: the object pairs the broad
            phase writes.
        near_phase: with a clearance, the :class:`~warp_ccd._src.narrowphase.clearance.ClearancePhase`, else None.
        self_phase: with ``self_intersections``, the
            :class:`~warp_ccd._src.narrowphase.self_intersection.SelfIntersection`, else None.
        clearance, continuous, timings, rebuild_every: the options of those names.
        counter_read: the :class:`~warp_ccd._src.runtime.buffers.CounterRead` of every buffer with a counter the
            frame writes (``pairs`` and each stage's ``counters``).
        graph: whether frames are replayed as CUDA graphs.
        rebuilds: tree rebuilds so far (``rebuild_every``).
    """

    def __init__(self, scene: Scene, options: PipelineOptions | None = None, **kwargs: Any) -> None:
        if not isinstance(scene, Scene):
            raise TypeError(f"scene: expected a warp_ccd.Scene, got {type(scene).__name__}")
        o = pipeline_options(options, kwargs, "CollisionPipeline")
        mode = frame_mode(scene.device, False if o.graph is None and o.timings else o.graph)
        if o.leaf_size is None:
            deforming_leaves = scene.deforming and not o.continuous and not o.self_intersections
            o = o.replace(leaf_size=DEFORMING_LEAF_SIZE if deforming_leaves else RIGID_LEAF_SIZE)
        self.options = o
        self.scene = scene
        self.device = d = scene.device
        n = scene.num_objects
        self.clearance = o.clearance
        self.continuous = o.continuous
        self.timings = o.timings
        self.rebuild_every = o.rebuild_every
        self.graph = mode == "graph"
        self.broad = make_broad_phase(o.broad_phase, device=d, entry_capacity=o.entry_capacity)
        self.narrow = make_narrow_phase(n, o, device=d)
        # Leaf boxes padded by the discrete tolerance (a continuous frame: at least the one of the test at t = 0
        # of triangle_pair_toi) and by what the narrow phase may report beyond it (pad_abs: a continuous test's
        # least distance and tolerance).
        margin_rel = max(o.tolerance, TOLERANCE) if self.continuous else self.narrow.tolerance
        pad_abs = self.narrow.pad_abs
        self.boxes, self.mid = make_mid_phase(scene, o, margin_rel=margin_rel, world_trees=self.continuous,
                                              pad_abs=pad_abs, device=d)
        self.near_phase = (ClearancePhase(n, self.clearance, tolerance=self.narrow.tolerance,
                                          capacity=o.near_capacity or max(64, n), device=d)
                           if self.clearance > 0.0 else None)
        self.contact_phase = None
        if o.contacts:
            self.depth = PenetrationDepth(scene, trees=self.boxes if o.mid_phase == "bvh" else None,
                                          triangle_tolerance=self.narrow.tolerance)
            self.contact_phase = ContactStage(scene, self.depth.trees, self.depth.surface, self.depth.object_solid,
                                              max_per_pair=o.max_per_pair, tolerance=self.narrow.tolerance)
        self.self_phase = None
        if o.self_intersections:  # the bvh mid phase's trees (PipelineOptions asks for them)
            self.self_phase = SelfIntersection(scene, self.boxes, tolerance=self.narrow.tolerance, device=d,
                                               hit_capacity=o.self_capacity)
        # The motion's start, two arrays: a frame reads one and writes the other (module docs).
        self._starts = [wp.clone(scene.world_vertex), wp.empty_like(scene.world_vertex)] if self.continuous else None
        self._parity = 0
        # One pair slot an object to start with (the scaling scenes hold 0.01-0.13 pairs an object; a
        # crowded frame grows it once): the mid phase keeps a TreePair of 136 bytes a slot beside it.
        self.pairs = GrowableBuffer(wp.vec2i, o.pair_capacity or max(64, n), d, "broad-phase pairs")
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
        self.boxes.refit(scene, start)
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
        self.broad.launch(self.boxes.lower, self.boxes.upper, self.pairs, scene.collision_filter)
        t = mark("broad", t)
        self.mid.launch(scene, self.pairs, reset_counters=False, world_vertex_start=start)
        t = mark("mid", t)
        self.narrow.launch(scene, self.mid.candidates, self.pairs, self.boxes.lower, self.boxes.upper,
                           world_vertex_start=start, reset_counters=False)
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
        result.object_world = self._object_world
        if self.contact_phase is not None:
            result.contacts = self._contacts(result)
        result.host_ms = (time.perf_counter() - start) * 1e3 - wait_ms
        result.runs = runs
        return result

    def _contacts(self, result: CollisionResult) -> Contacts:
        """The frame's contacts (:mod:`~warp_ccd._src.narrowphase.contacts`): the intersecting pairs' depths and
        witnesses (:class:`~warp_ccd._src.narrowphase.depth.PenetrationDepth`), then the contact stage; with
        ``containment``, each pair of one object wholly inside another gets its deepest contact (the inner surface's
        deepest point); with a margin, the pairs apart within it too."""
        rows = result.triangle_pairs.astype(np.int64)
        pairs = result.intersecting_pairs.astype(np.int64).reshape(-1, 2)
        contained = result.containment_pairs
        contained = np.zeros((0, 2), np.int64) if contained is None else contained.astype(np.int64).reshape(-1, 2)
        found = self.depth(pairs, rows=rows, contained=contained)
        # Rows of pairs, points (on a, on b), triangles, depths, apart: intersecting, contained, near; one sort.
        parts = [(pairs, found.pair_points, found.pair_triangles, found.pair_depth, np.zeros(len(pairs), bool))]
        if len(contained):  # (inner, outer): its inner surface's deepest point, as a pair (a, b), a < b
            flip = contained[:, 0] > contained[:, 1]
            parts.append((np.sort(contained, axis=1),
                          np.where(flip[:, None, None], found.contained_points[:, ::-1], found.contained_points),
                          np.where(flip[:, None], found.contained_triangles[:, ::-1], found.contained_triangles),
                          found.contained_depth, np.zeros(len(contained), bool)))
        n = np.int64(max(self.scene.num_objects, 1))
        if self.options.margin > 0.0 and result.object_distance is not None:
            near = result.object_pairs.astype(np.int64).reshape(-1, 2)
            keep = (~result.object_intersecting.astype(bool)) & (result.object_distance <= self.options.margin)
            touched = np.concatenate([p[0] for p in parts])
            keep &= ~np.isin(near[:, 0] * n + near[:, 1], touched[:, 0] * n + touched[:, 1])
            parts.append((near[keep], result.closest_points[keep].reshape(-1, 2, 3),
                          result.closest_triangles[keep].reshape(-1, 2), -result.object_distance[keep],
                          np.ones(int(keep.sum()), bool)))
        pairs, points, triangles, depth, apart = (np.concatenate(column) for column in zip(*parts))
        if len(parts) > 1:
            order = np.argsort(pairs[:, 0] * n + pairs[:, 1], kind="stable")
            pairs, points, triangles, depth, apart = (pairs[order], points[order], triangles[order], depth[order],
                                                      apart[order])
        return self.contact_phase(pairs, rows, depth, points, triangles, near={"apart": apart})

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
        result = CollisionResult(n, wp.zeros(0, dtype=wp.vec4i, device=d), wp.zeros(n, dtype=wp.int32, device=d),
                                 {s: 0.0 for s in stages} if self.timings else None,
                                 device_contained=empty, device_segments=no_segments, device_toi=no_toi,
                                 clearance=self.clearance, near=near, self_rows=no_self)
        if self.contact_phase is not None:
            result.contacts = self.contact_phase(np.zeros((0, 2)), np.zeros((0, 4)), np.zeros(0), np.zeros((0, 2, 3)),
                                                 np.zeros((0, 2)))
        return result


def collide(meshes: Sequence, transforms: ArrayLike | None = None, device: DeviceLike = None,
            precision: str = "float32", *, transforms_end: ArrayLike | None = None,
            vertices_end: Sequence | None = None, min_distance: float = 0.0, world: ArrayLike | None = None,
            group: ArrayLike | None = None, mask: ArrayLike | None = None, exclude_pairs: ArrayLike | None = None,
            options: PipelineOptions | None = None, **kwargs: Any) -> CollisionResult:
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
        options: the pipeline's :class:`~warp_ccd._src.pipeline.options.PipelineOptions` (checked before anything
            is built); None: the defaults.
        **kwargs: options by name, over ``options`` (``tolerance``, ``segments``, ``containment``,
            ``clearance``, ``ccd_tolerance``, capacities, ...). ``clearance=d`` reports every pair of objects
            whose surfaces come within ``d`` too, with ``object_distance``, ``closest_points``,
            ``object_normal``, ``closest_triangles``.

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
    o = pipeline_options(options, kwargs, "collide")
    min_distance = check_option("min_distance", min_distance)
    filters = {"world": world, "group": group, "mask": mask, "exclude_pairs": exclude_pairs}
    if transforms_end is not None or vertices_end is not None or min_distance > 0.0:
        # continuous; the keyword's least distance where given, else the options' own
        o = o.replace(continuous=True, min_distance=min_distance if min_distance > 0.0 else o.min_distance)
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
    leaf = o.leaf_size or RIGID_LEAF_SIZE
    one_shot = {"pair_capacity": max(64, min(n * (n - 1) // 2, 32 * n)), "entry_capacity": max(1024, 4 * n),
                "candidate_capacity": max(1024, 16 * n, 2 * leaf * tris), "hit_capacity": max(256, 4 * n, tris // 4),
                "front_capacity": max(1024, 4 * n, tris)}
    pipeline = CollisionPipeline(scene, o.replace(**{k: v for k, v in one_shot.items() if getattr(o, k) is None}))
    if vertices_end is not None:
        scene.set_world_vertices(np.concatenate(end) if end else np.zeros((0, 3)))
    elif transforms_end is not None:
        scene.set_transforms(transforms_end)
    return pipeline.detect()


def contacts(meshes: Sequence, transforms: ArrayLike | None = None, device: DeviceLike = None,
             precision: str = "float32", *, max_per_pair: int = 8, margin: float = 0.0, world: ArrayLike | None = None,
             group: ArrayLike | None = None, mask: ArrayLike | None = None, exclude_pairs: ArrayLike | None = None,
             options: PipelineOptions | None = None, **kwargs: Any) -> Contacts:
    """One-shot contacts among meshes, for a solver (:mod:`~warp_ccd._src.narrowphase.contacts`).

    Args:
        meshes: sequence of ``(vertices (n, 3) float, triangles (m, 3) int)``, one per object.
        transforms: ``(N, 4, 4)`` rigid transforms or ``(N, 7)`` poses, or None (vertices in world space).
        device: Warp device (default: Warp's default device).
        precision: ``"float32"`` (default) or ``"float64"``.
        world: ``(N,)`` world id of each object (as :func:`collide`).
        group: ``(N,)`` collision group of each object (as :func:`collide`).
        mask: ``(N,)`` collision mask of each object (as :func:`collide`).
        exclude_pairs: ``(E, 2)`` object pairs that never collide.
        options: the pipeline's :class:`~warp_ccd._src.pipeline.options.PipelineOptions`; None: the defaults.
        **kwargs: options by name, over ``options`` (``tolerance``, capacities, ...).
        max_per_pair: the most contacts an object pair keeps (in ``[1, 32]``).
        margin: pairs apart by at most this distance (scene units) get a speculative contact too: their closest
            points, ``depth = -distance``.

    Returns:
        The :class:`~warp_ccd._src.narrowphase.contacts.Contacts`: ``pairs`` ``(C, 2)`` (``a < b``), ``point_a``,
        ``point_b`` ``(C, 3)`` on each surface, ``normal`` ``(C, 3)`` unit from ``b`` to ``a``, ``depth`` ``(C,)``
        (``point_a = point_b - depth * normal``), ``triangles`` ``(C, 2)``.
    """
    res = collide(meshes, transforms, device, precision, world=world, group=group, mask=mask,
                  exclude_pairs=exclude_pairs, options=options, contacts=True, max_per_pair=max_per_pair,
                  margin=margin, **kwargs)
    return res.contacts


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
