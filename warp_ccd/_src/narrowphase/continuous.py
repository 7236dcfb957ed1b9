"""Continuous narrow phase: the time of impact of each candidate triangle pair over a linear motion.

A continuous frame (:class:`~warp_ccd._src.pipeline.pipeline.CollisionPipeline` with ``continuous=True``) sees
every world vertex move linearly from ``world_vertex_start`` (``t = 0``) to the scene's
``world_vertex`` (``t = 1``). Its refit, broad and mid phases work on swept boxes (a triangle's box
over both ends, padded by the least distance and the tolerance: :func:`~warp_ccd._src.trees.bvh.swept_triangle_box_at`),
so every triangle pair that comes within ``min_distance`` at some ``t`` is a candidate.
:class:`ContinuousNarrowPhase` then runs :func:`~warp_ccd._src.geometry.ccd.triangle_pair_toi` on each
candidate row ``(obj_a, tri_a, obj_b, tri_b)``, in passes (below): a pair with a toi in ``[0, 1]``
is appended to :attr:`~ContinuousNarrowPhase.hits` (capacity + counter; it grows, nothing is
dropped) with its toi in :attr:`~ContinuousNarrowPhase.toi` (float64, same slot), and both objects
are flagged. The toi is never later than the true one (Tight Inclusion's guarantee); 0 for a
pair that already meets at ``t = 0``.

Cost: one query of up to 15 primitive pairs a candidate, each a bounded search
(``max_iterations`` steps); most queries of a swept frame are ruled out by their swept boxes or
their filters (the coplanarity cubic, the whole box). The work runs in passes, so that no warp
waits on a long search beside finished lanes and no kernel holds the registers of code that few
of its threads run:

1. per candidate (:func:`_first_pass_kernel`): the discrete test at ``t = 0`` on its common path
   (:func:`~warp_ccd._src.geometry.ccd.pair_meets_common`) and the swept-box mask of the 15 queries
   (:func:`~warp_ccd._src.geometry.ccd.pair_near_mask`); a row that meets is a hit (toi 0), a row with
   near queries (or a discrete test left undecided) is listed with its near queries;
2. per near query (:func:`_filter_pass_kernel`): its filters; the few queries they leave are listed;
3. per query left (:func:`_search_pass_kernel`): its search, its toi min-ed into its row's;
4. per listed row (:func:`_last_pass_kernel`): the discrete test at ``t = 1`` when its queries found
   nothing, and the row appended; rows the common path left undecided go to
5. :func:`_undecided_pass_kernel`: the whole discrete test (:func:`~warp_ccd._src.geometry.ccd.pair_meets`).

The results are those of :func:`~warp_ccd._src.geometry.ccd.triangle_pair_toi` on every candidate
(each query is searched on its own, deterministically, its filters its first steps; the common
path's verdicts are the whole test's), which the tests check bit for bit.
The module is compiled without floating-point contraction (``fuse_fp=False``), as
:mod:`warp_ccd._src.geometry.ccd` asks, so that every device gives the same tois.
"""

from typing import Any

import warp as wp

from ..geometry.ccd import (
    CCD_MAX_ITERATIONS,
    CCD_TOLERANCE,
    MEETS_UNDECIDED,
    NO_HIT,
    PAIR_QUERIES,
    pair_meets,
    pair_meets_common,
    pair_near_mask,
    pair_query,
    primitive_toi,
    query_excluded,
)
from ..geometry.precision import precision_overloads
from ..runtime.aliases import DeviceLike
from ..runtime.buffers import GrowableBuffer, block_dim_for, block_reserve, reserve_slot, used_count
from ..runtime.options import check_option
from ..scene.scene import MeshTopology, Scene
from .pairs import PairList, append_hit, pair_count, pair_list, pair_triangles

wp.set_module_options({"enable_backward": False, "fuse_fp": False})

__all__ = ["ContinuousNarrowPhase"]

MAX_REGISTERS = 128
"""Most registers a thread of the first, filter, last and undecided passes on CUDA (as the discrete
narrow phase's kernels): two blocks of 256 a multiprocessor, for a few spilled bytes, measured faster
on a GPU than without the cap (docs: architecture, continuous collision); the search pass keeps its
registers (a cap of 168 or 192 gave nothing)."""

START_UNDECIDED = wp.constant(1 << PAIR_QUERIES)
"""Bit of a deferred row's mask (above its queries' bits): the discrete test at ``t = 0`` left it to
the whole test (:func:`~warp_ccd._src.geometry.ccd.pair_meets_common`)."""

QUERY_BITS = wp.constant((1 << PAIR_QUERIES) - 1)
"""The bits of a deferred row's mask that name its near queries."""


@wp.func
def _row_vertices(mesh: MeshTopology, world_vertex_start: wp.array[Any], world_vertex: wp.array[Any], c: wp.vec4i):
    """The two triangles of row ``c`` at the start and at the end of the motion."""
    a0, a1, a2, b0, b1, b2 = pair_triangles(mesh, world_vertex_start, c)
    a0e, a1e, a2e, b0e, b1e, b2e = pair_triangles(mesh, world_vertex, c)
    return a0, a1, a2, b0, b1, b2, a0e, a1e, a2e, b0e, b1e, b2e


@wp.func
def _append_timed_hit(c: wp.vec4i, toi: wp.float64, hits: PairList, hit_toi: wp.array[wp.float64],
                      object_colliding: wp.array[wp.int32]):
    """Appends row ``c`` with its toi (same slot) and flags its objects, when the toi is in ``[0, 1]``."""
    if toi <= wp.float64(1.0):
        slot = append_hit(hits, object_colliding, c)
        if slot >= 0:
            hit_toi[slot] = toi


@wp.func
def _bit_count(mask: int) -> int:
    n = int(0)
    for q in range(PAIR_QUERIES):
        n += (mask >> q) & 1
    return n


@wp.kernel(cuda_max_registers=MAX_REGISTERS)
def _first_pass_kernel(
    mesh: MeshTopology,
    world_vertex_start: wp.array[Any],
    world_vertex: wp.array[Any],
    candidates: PairList,
    min_distance: wp.float64,
    deferred_capacity: int,
    query_capacity: int,
    # Outputs
    hits: PairList,
    hit_toi: wp.array[wp.float64],
    object_colliding: wp.array[wp.int32],
    deferred: wp.array[wp.vec2i],
    deferred_toi: wp.array[wp.float64],
    deferred_count: wp.array[wp.int64],
    query: wp.array[wp.vec2i],
    query_count: wp.array[wp.int64],
):
    """One thread per candidate slot (blocks of threads that reserve their outputs together, as
    :func:`~warp_ccd._src.runtime.buffers.block_reserve` asks): row ``(obj_a, tri_a, obj_b, tri_b)`` over
    the motion from ``world_vertex_start`` to ``world_vertex``. A row that meets at ``t = 0`` is
    appended with toi 0; a row none of whose queries' swept boxes come near
    (:func:`~warp_ccd._src.geometry.ccd.pair_near_mask`) has no hit; any other row goes to ``deferred``
    as ``(slot, mask of its near queries)``, ``deferred_toi`` no hit, and each near query to
    ``query`` as ``(deferred row, query)``."""
    block, lane = wp.tid()
    k = block * wp.block_dim() + lane
    c = wp.vec4i()
    mask = int(0)
    toi = NO_HIT
    if k < pair_count(candidates):
        c = candidates.row[k]
        a0, a1, a2, b0, b1, b2, a0e, a1e, a2e, b0e, b1e, b2e = _row_vertices(mesh, world_vertex_start, world_vertex,
                                                                              c)
        meets = pair_meets_common(a0, a1, a2, b0, b1, b2)
        if meets == 1:
            toi = wp.float64(0.0)
        else:  # no near query: no contact, and no discrete hit at t = 1 either (pair_search)
            mask = pair_near_mask(a0, a1, a2, b0, b1, b2, a0e, a1e, a2e, b0e, b1e, b2e, min_distance)
            if meets == MEETS_UNDECIDED:
                mask = mask | START_UNDECIDED  # the last passes decide it
    # Every thread of the block reserves (with 0 items past the candidates): one atomic a block.
    is_hit = int(0)
    if toi <= wp.float64(1.0):
        is_hit = 1
    slot = block_reserve(hits.count, lane, is_hit)
    if is_hit != 0:
        if slot < wp.int64(hits.capacity):
            hits.row[int(slot)] = c
            hit_toi[int(slot)] = toi
        object_colliding[c[0]] = 1
        object_colliding[c[2]] = 1
    is_deferred = int(0)
    if mask != 0:
        is_deferred = 1
    row = block_reserve(deferred_count, lane, is_deferred)
    stored = is_deferred != 0 and row < wp.int64(deferred_capacity)
    queries = int(0)
    if stored:
        queries = _bit_count(mask)  # only a stored row's queries: every listed query names a stored row
    first = block_reserve(query_count, lane, queries)
    if stored:
        i = int(row)
        deferred[i] = wp.vec2i(k, mask)
        deferred_toi[i] = NO_HIT
        n = int(0)
        for q in range(PAIR_QUERIES):
            if (mask >> q) & 1 != 0:
                j = first + wp.int64(n)
                if j < wp.int64(query_capacity):
                    query[int(j)] = wp.vec2i(i, q)
                n += 1


@wp.func
def _query_points(mesh: MeshTopology, world_vertex_start: wp.array[Any], world_vertex: wp.array[Any],
                  candidate: wp.array[wp.vec4i], deferred: wp.array[wp.vec2i], entry: wp.vec2i):
    """Query ``entry[1]`` of deferred row ``entry[0]``: ``(kind, x0, x1)`` (:func:`pair_query`)."""
    c = candidate[deferred[entry[0]][0]]
    a0, a1, a2, b0, b1, b2, a0e, a1e, a2e, b0e, b1e, b2e = _row_vertices(mesh, world_vertex_start, world_vertex, c)
    return pair_query(entry[1], wp.vec3d(a0), wp.vec3d(a1), wp.vec3d(a2), wp.vec3d(b0), wp.vec3d(b1), wp.vec3d(b2),
                      wp.vec3d(a0e), wp.vec3d(a1e), wp.vec3d(a2e), wp.vec3d(b0e), wp.vec3d(b1e), wp.vec3d(b2e))


@wp.kernel(cuda_max_registers=MAX_REGISTERS)
def _filter_pass_kernel(
    mesh: MeshTopology,
    world_vertex_start: wp.array[Any],
    world_vertex: wp.array[Any],
    candidate: wp.array[wp.vec4i],
    deferred: wp.array[wp.vec2i],
    query: wp.array[wp.vec2i],
    query_count: wp.array[wp.int64],
    query_capacity: int,
    min_distance: wp.float64,
    search_capacity: int,
    # Outputs
    search: wp.array[wp.vec2i],
    search_count: wp.array[wp.int64],
):
    """One thread per listed query (blocks, as :func:`_first_pass_kernel`): its filters
    (:func:`~warp_ccd._src.geometry.ccd.query_excluded`, the first steps of its search); a query they
    leave goes to ``search`` (a few percent: packed, their searches run side by side)."""
    block, lane = wp.tid()
    j = block * wp.block_dim() + lane
    entry = wp.vec2i()
    keep = int(0)
    if j < used_count(query_count, query_capacity):
        entry = query[j]
        kind, x0, x1 = _query_points(mesh, world_vertex_start, world_vertex, candidate, deferred, entry)
        if not query_excluded(kind, x0, x1, min_distance):
            keep = 1
    slot = block_reserve(search_count, lane, keep)
    if keep != 0 and slot < wp.int64(search_capacity):
        search[int(slot)] = entry


@wp.kernel
def _search_pass_kernel(
    mesh: MeshTopology,
    world_vertex_start: wp.array[Any],
    world_vertex: wp.array[Any],
    candidate: wp.array[wp.vec4i],
    deferred: wp.array[wp.vec2i],
    search: wp.array[wp.vec2i],
    search_count: wp.array[wp.int64],
    search_capacity: int,
    min_distance: wp.float64,
    tolerance: wp.float64,
    max_iterations: int,
    # Outputs
    deferred_toi: wp.array[wp.float64],
):
    """One thread per query left by its filters: its search (within ``max_iterations`` steps), its
    toi min-ed into its row's ``deferred_toi``."""
    j = wp.tid()
    if j >= used_count(search_count, search_capacity):
        return
    entry = search[j]
    kind, x0, x1 = _query_points(mesh, world_vertex_start, world_vertex, candidate, deferred, entry)
    toi = primitive_toi(kind, x0, x1, min_distance, tolerance, max_iterations, NO_HIT)
    if toi <= wp.float64(1.0):
        wp.atomic_min(deferred_toi, entry[0], toi)


@wp.kernel(cuda_max_registers=MAX_REGISTERS)
def _last_pass_kernel(
    mesh: MeshTopology,
    world_vertex: wp.array[Any],
    candidate: wp.array[wp.vec4i],
    deferred: wp.array[wp.vec2i],
    deferred_toi: wp.array[wp.float64],
    deferred_count: wp.array[wp.int64],
    deferred_capacity: int,
    undecided_capacity: int,
    # Outputs
    hits: PairList,
    hit_toi: wp.array[wp.float64],
    object_colliding: wp.array[wp.int32],
    undecided: wp.array[wp.int32],
    undecided_count: wp.array[wp.int64],
):
    """One thread per deferred row: its toi (the discrete test at ``t = 1`` when its queries found
    none, on its common path), appended as the first pass does; a row whose discrete test at
    ``t = 0`` or ``t = 1`` only the whole test decides goes to ``undecided``
    (:func:`_undecided_pass_kernel`)."""
    i = wp.tid()
    if i >= used_count(deferred_count, deferred_capacity):
        return
    d = deferred[i]
    c = candidate[d[0]]
    toi = deferred_toi[i]
    later = (d[1] & START_UNDECIDED) != 0
    if not later and toi > wp.float64(1.0):
        a0e, a1e, a2e, b0e, b1e, b2e = pair_triangles(mesh, world_vertex, c)
        meets = pair_meets_common(a0e, a1e, a2e, b0e, b1e, b2e)
        if meets == 1:
            toi = wp.float64(1.0)
        later = meets == MEETS_UNDECIDED
    if later:
        slot = reserve_slot(undecided_count, undecided_capacity)
        if slot >= 0:
            undecided[slot] = i
        return
    _append_timed_hit(c, toi, hits, hit_toi, object_colliding)


@wp.kernel(cuda_max_registers=MAX_REGISTERS)
def _undecided_pass_kernel(
    mesh: MeshTopology,
    world_vertex_start: wp.array[Any],
    world_vertex: wp.array[Any],
    candidate: wp.array[wp.vec4i],
    deferred: wp.array[wp.vec2i],
    deferred_toi: wp.array[wp.float64],
    undecided: wp.array[wp.int32],
    undecided_count: wp.array[wp.int64],
    undecided_capacity: int,
    # Outputs
    hits: PairList,
    hit_toi: wp.array[wp.float64],
    object_colliding: wp.array[wp.int32],
):
    """One thread per row left undecided (a few): the whole discrete test
    (:func:`~warp_ccd._src.geometry.ccd.pair_meets`) at ``t = 0`` if the first pass left it, then at
    ``t = 1`` if its queries found no toi, and the row appended as the first pass does."""
    j = wp.tid()
    if j >= used_count(undecided_count, undecided_capacity):
        return
    i = undecided[j]
    d = deferred[i]
    c = candidate[d[0]]
    toi = deferred_toi[i]
    if (d[1] & START_UNDECIDED) != 0:
        a0, a1, a2, b0, b1, b2 = pair_triangles(mesh, world_vertex_start, c)
        if pair_meets(a0, a1, a2, b0, b1, b2):
            toi = wp.float64(0.0)
    if toi > wp.float64(1.0) and (d[1] & QUERY_BITS) != 0:
        a0e, a1e, a2e, b0e, b1e, b2e = pair_triangles(mesh, world_vertex, c)
        if pair_meets(a0e, a1e, a2e, b0e, b1e, b2e):
            toi = wp.float64(1.0)
    _append_timed_hit(c, toi, hits, hit_toi, object_colliding)


_SWEPT = lambda s, v, q, t: {"world_vertex_start": wp.array[v], "world_vertex": wp.array[v]}  # noqa: E731
_FIRST = precision_overloads(_first_pass_kernel, _SWEPT)
_FILTER = precision_overloads(_filter_pass_kernel, _SWEPT)
_SEARCH = precision_overloads(_search_pass_kernel, _SWEPT)
_LAST = precision_overloads(_last_pass_kernel, lambda s, v, q, t: {"world_vertex": wp.array[v]})
_UNDECIDED = precision_overloads(_undecided_pass_kernel, _SWEPT)


class ContinuousNarrowPhase:
    """Times of impact of candidate triangle pairs over a linear motion; owns what it writes.

    Args:
        num_objects: ``N`` (size of :attr:`object_colliding`).
        min_distance: pairs that come within this distance (scene units, infinity norm) collide.
        tolerance: the test's distance tolerance (scene units; a false positive comes within about
            it of a contact).
        max_iterations: most boxes one primitive query examines (past it the answer is conservative).
        capacity: initial capacity of the hit buffer (it grows).
        device: Warp device.

    Attributes:
        hits: :class:`~warp_ccd._src.runtime.buffers.GrowableBuffer` of ``wp.vec4i`` rows
            ``(obj_a, tri_a, obj_b, tri_b)``, ``obj_a < obj_b``, of the pairs that collide in ``[0, 1]``.
        toi: ``(hits.capacity,)`` float64, the toi of each row of :attr:`hits` (same slot), in ``[0, 1]``.
        object_colliding: ``(N,)`` int32, 1 for an object with a hit.
        deferred: :class:`~warp_ccd._src.runtime.buffers.GrowableBuffer` of ``wp.vec2i`` ``(candidate slot,
            mask of its near queries)``, the rows whose queries the later passes run; ``deferred_toi``
            their toi so far.
        queries: ``wp.vec2i`` ``(deferred row, query)``, each near query; ``searches``: the same, the
            queries their filters leave (:class:`~warp_ccd._src.runtime.buffers.GrowableBuffer` both).
        min_distance, tolerance, max_iterations: as above.
        segments, segment, contained: False, None, None (a continuous frame has neither segments
            nor containment; :class:`~warp_ccd._src.pipeline.stages.NarrowPhaseStage`'s members).
    """

    def __init__(self, num_objects: int, *, min_distance: float = 0.0, tolerance: float = CCD_TOLERANCE,
                 max_iterations: int = CCD_MAX_ITERATIONS, capacity: int = 1024, device: DeviceLike = None) -> None:
        self.min_distance = check_option("min_distance", min_distance)
        self.tolerance = check_option("ccd_tolerance", tolerance)
        self.max_iterations = check_option("ccd_max_iterations", max_iterations)
        self.device = wp.get_device(device)
        self.hits = GrowableBuffer(wp.vec4i, capacity, self.device, "triangle pairs")
        self.deferred = GrowableBuffer(wp.vec2i, max(64, capacity // 4), self.device, "deferred candidates")
        self.queries = GrowableBuffer(wp.vec2i, 4 * self.deferred.capacity, self.device, "primitive queries")
        self.searches = GrowableBuffer(wp.vec2i, self.queries.capacity, self.device,
                                       "primitive searches")
        self.undecided = GrowableBuffer(wp.int32, self.deferred.capacity, self.device, "undecided rows")
        self.deferred_toi = wp.zeros(self.deferred.capacity, dtype=wp.float64, device=self.device)
        self.toi = wp.zeros(self.hits.capacity, dtype=wp.float64, device=self.device)
        self.object_colliding = wp.zeros(num_objects, dtype=wp.int32, device=self.device)
        self.segments = False
        self.segment = None
        self.contained = None

    @property
    def pad_abs(self) -> float:
        """Padding in scene units of the swept boxes upstream: the least distance plus the tolerance
        (a pair the test may report is never culled by a box)."""
        return self.min_distance + self.tolerance

    @property
    def counters(self) -> list[GrowableBuffer]:
        """The buffers with counters that :meth:`launch` writes (the hits, the deferred candidates,
        their queries, the queries searched and the rows the discrete test's common path left)."""
        return [self.hits, self.deferred, self.queries, self.searches, self.undecided]

    def launch(self, scene: Scene, candidates: GrowableBuffer, object_pairs: GrowableBuffer | None = None,
               object_lower: wp.array | None = None, object_upper: wp.array | None = None, *,
               world_vertex_start: wp.array | None = None, reset_counters: bool = True) -> None:
        """Tests the ``candidates`` over the motion from ``world_vertex_start`` to ``scene.world_vertex``:
        resets and writes :attr:`hits`, :attr:`toi` and :attr:`object_colliding` (host reads nothing).

        Args:
            scene: the :class:`~warp_ccd._src.scene.scene.Scene` (its world vertices at ``t = 1``).
            candidates: ``wp.vec4i`` candidate triangle pairs (the mid phase's, from swept boxes).
            object_pairs: the broad phase's object pairs (unused: the narrow phases take the same arguments).
            object_lower: the lower corners of its object boxes (unused).
            object_upper: the upper corners of its object boxes (unused).
            world_vertex_start: ``(V,)`` world vertices at ``t = 0`` (the scene's vector type; required).
            reset_counters: zero the hits' counter first; False when the caller has.

        A buffer of :attr:`counters` that overflows leaves this launch's hits incomplete (rows may
        be appended with a later toi than their full answer): the caller reads the counters and
        runs again after they grow, as :class:`~warp_ccd._src.pipeline.pipeline.CollisionPipeline` does.
        """
        if world_vertex_start is None:
            raise ValueError("world_vertex_start: a continuous narrow phase tests a motion: give its start")
        d = self.device
        hits = self.hits
        if reset_counters:
            hits.reset()
        if self.toi.shape[0] != hits.capacity:  # follows the hits' capacity (after a growth, eagerly)
            self.toi = wp.zeros(hits.capacity, dtype=wp.float64, device=d)
        self.object_colliding.zero_()
        deferred, queries, searches, undecided = self.deferred, self.queries, self.searches, self.undecided
        if reset_counters:
            for buffer in (deferred, queries, searches, undecided):
                buffer.reset()
        if self.deferred_toi.shape[0] != deferred.capacity:
            self.deferred_toi = wp.zeros(deferred.capacity, dtype=wp.float64, device=d)
        d64, tol64 = wp.float64(self.min_distance), wp.float64(self.tolerance)
        block = block_dim_for(d)
        swept = [scene.topology, world_vertex_start, scene.world_vertex, candidates.data]
        hit_list = pair_list(hits)
        wp.launch_tiled(_FIRST[scene.precision], dim=[(candidates.capacity + block - 1) // block],
                        inputs=[*swept[:3], pair_list(candidates), d64, deferred.capacity, queries.capacity],
                        outputs=[hit_list, self.toi, self.object_colliding, deferred.data, self.deferred_toi,
                                 deferred.count, queries.data, queries.count],
                        block_dim=block, device=d)
        wp.launch_tiled(_FILTER[scene.precision], dim=[(queries.capacity + block - 1) // block],
                        inputs=[*swept, deferred.data, queries.data, queries.count, queries.capacity, d64,
                                searches.capacity],
                        outputs=[searches.data, searches.count], block_dim=block, device=d)
        wp.launch(_SEARCH[scene.precision], dim=searches.capacity,
                  inputs=[*swept, deferred.data, searches.data, searches.count, searches.capacity, d64, tol64,
                          self.max_iterations],
                  outputs=[self.deferred_toi], device=d)
        wp.launch(_LAST[scene.precision], dim=deferred.capacity,
                  inputs=[scene.topology, scene.world_vertex, candidates.data, deferred.data, self.deferred_toi,
                          deferred.count, deferred.capacity, undecided.capacity],
                  outputs=[hit_list, self.toi, self.object_colliding, undecided.data, undecided.count], device=d)
        wp.launch(_UNDECIDED[scene.precision], dim=undecided.capacity,
                  inputs=[*swept, deferred.data, self.deferred_toi, undecided.data, undecided.count,
                          undecided.capacity],
                  outputs=[hit_list, self.toi, self.object_colliding], device=d)
