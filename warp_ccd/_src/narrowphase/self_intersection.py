"""Self-intersection: triangles of one mesh that meet other than through the vertices they share.

A mesh passes through itself where two of its triangles meet beyond what they share
(:func:`~warp_ccd._src.geometry.adjacent.tri_tri_self`: a vertex, an edge; coincident vertices are one,
:func:`weld_vertices`). Each mesh's tree is walked against itself, level by level as the mid phase walks
two trees, for every mesh at once: the tree-pair walk (:mod:`warp_ccd._src.trees.traversal`) with
``self_pairs`` and this stage's tests plugged in:

* a front entry ``(item, na, nb)`` is a pair of nodes of one tree, ``na <= nb`` in effect: level 0 holds
  each item's ``(root, root)``. A node against itself opens into its children against themselves and
  against each other (``(c0, c0)``, ``(c1, c1)`` always, ``(c0, c1)`` when their boxes overlap); two
  different nodes open as in the mid phase (a leaf stays itself, the two to four child pairs whose boxes
  overlap go on). So each unordered pair of nodes is reached once, and each triangle pair once.
* A leaf against itself gives the pairs ``i < j`` of its triangles, two leaves the product of theirs:
  candidate rows ``(item, tri, tri)`` (local triangle ids), tested by :func:`_self_narrow_kernel`, which
  writes the rows ``(item, tri_a, tri_b)``, ``tri_a < tri_b``, of the pairs that meet and flags the item.

The boxes are the trees' own (leaves padded by the triangle test's tolerance), in one space per tree,
so a test is a plain box overlap. :class:`SelfTraversal` runs this over a list of items of one
:class:`~warp_ccd._src.trees.bvh.TreeView`: the shapes of rigid objects in shape space (a rigid object cannot
change its self-intersections: its shape's are computed once) or the deforming objects in the world
after each refit. :class:`SelfIntersection` is the frame's stage: the rigid objects' rows from their
shapes' (computed at construction), then the deforming objects' traversal.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import warp as wp

from ..geometry.adjacent import tri_tri_self
from ..geometry.box import boxes_overlap
from ..geometry.precision import precision_overloads
from ..geometry.triangle import TOLERANCE, crossing_depth
from ..runtime.aliases import DeviceLike
from ..runtime.buffers import (
    CounterRead,
    GrowableBuffer,
    block_reserve,
    reserve_slot,
    used_count,
)
from ..runtime.frame import FrameCache
from ..runtime.options import check_option
from ..scene.scene import MeshTopology, Scene, mesh_triangle
from ..trees.bvh import SceneBVH, TreeView
from ..trees.traversal import CHILD_LEAF, CHILD_SELF_LEAF, FrontWalk, front_kernel

# Forward kernels only; no FMA contraction, so that CPU and CUDA round every step alike.
wp.set_module_options({"enable_backward": False, "fuse_fp": False})

__all__ = ["SelfIntersection", "SelfTraversal", "weld_vertices"]


def weld_vertices(vertices: np.ndarray, vertex_start: np.ndarray) -> np.ndarray:
    """Each vertex's id for adjacency: the least local index of the vertices of its shape at exactly
    its position (so that a mesh stored with split vertices, as STL and many exports are, shares its
    edges as a welded one does).

    Args:
        vertices: ``(V, 3)`` the shapes' local vertices, concatenated.
        vertex_start: ``(S + 1,)`` each shape's first vertex.

    Returns:
        ``(V,)`` int32 local vertex ids.
    """
    v = np.asarray(vertices, np.float64).reshape(-1, 3)
    starts = np.asarray(vertex_start, np.int64)
    shape = np.repeat(np.arange(len(starts) - 1), np.diff(starts))
    local = np.arange(len(v), dtype=np.int64) - starts[shape] if len(v) else np.zeros(0, np.int64)
    v = v + 0.0  # -0.0 as 0.0
    order = np.lexsort((local, v[:, 2], v[:, 1], v[:, 0], shape))
    sv = v[order]
    ss = shape[order]
    new = np.ones(len(v), bool)
    if len(v) > 1:
        new[1:] = (ss[1:] != ss[:-1]) | (sv[1:] != sv[:-1]).any(axis=1)
    first = np.maximum.accumulate(np.where(new, np.arange(len(v)), 0))  # each sorted row's group start
    weld = np.empty(len(v), np.int32)
    weld[order] = local[order][first]
    return weld


@wp.struct
class SelfParams:
    """What the self traversal's walk reads and writes besides the tree
    (:func:`~warp_ccd._src.trees.traversal.front_kernel`)."""

    object_shape: wp.array[wp.int32]
    item: wp.array[wp.int32]  # the objects (or shapes) walked
    candidate: wp.array[wp.vec3i]
    candidate_count: wp.array[wp.int64]
    candidate_capacity: int


@wp.struct
class SelfItem:
    """An item's tree: its object, its shape's node 0 and triangle order, its boxes' first slot."""

    obj: int
    node_start: int
    tri_start: int
    slot: int


@wp.func
def _entry(p: SelfParams, tree: TreeView, k: int, na: int, nb: int, roots: int):
    """Item ``k``'s tree; every entry is opened (its pair of nodes was kept when it was pushed)."""
    c = SelfItem()
    c.obj = p.item[k]
    shape = p.object_shape[c.obj]
    c.node_start = tree.layout_node_start[tree.shape_layout[shape]]
    c.tri_start = tree.shape_tri_order_start[shape]
    c.slot = tree.object_node_start[c.obj]
    return c, c.node_start, c.node_start, True


@wp.func
def _near(p: SelfParams, tree: TreeView, c: SelfItem, xa: int, xb: int) -> bool:
    """Two nodes of one tree are kept where their boxes (one space) overlap."""
    return boxes_overlap(tree.node_lower[c.slot + xa], tree.node_upper[c.slot + xa], tree.node_lower[c.slot + xb],
                         tree.node_upper[c.slot + xb])


@wp.func
def _rows(p: SelfParams, tree: TreeView, c: SelfItem, kind: int, xa: int, xb: int) -> int:
    """Candidate rows of a child pair: a leaf's pairs ``i < j``, two leaves' product, or none."""
    if kind == CHILD_SELF_LEAF:
        m = tree.node_triangle[c.node_start + xa][1]
        return m * (m - 1) // 2
    if kind == CHILD_LEAF:
        return tree.node_triangle[c.node_start + xa][1] * tree.node_triangle[c.node_start + xb][1]
    return 0


@wp.func
def _reserve(p: SelfParams, lane: int, rows: int) -> wp.int64:
    return block_reserve(p.candidate_count, lane, rows)


@wp.func
def _emit(p: SelfParams, tree: TreeView, c: SelfItem, k: int, kind: int, xa: int, xb: int,
          slot: wp.int64) -> wp.int64:
    """Writes the candidate rows ``(item, tri, tri)`` of a child pair from ``slot``; returns the next slot."""
    if kind != CHILD_SELF_LEAF and kind != CHILD_LEAF:
        return slot
    ra = tree.node_triangle[c.node_start + xa]
    rb = tree.node_triangle[c.node_start + xb]
    for i in range(ra[0], ra[0] + ra[1]):
        tri_a = tree.tri_order[c.tri_start + i]
        j0 = rb[0]
        if kind == CHILD_SELF_LEAF:
            j0 = i + 1
        for j in range(j0, rb[0] + rb[1]):
            if slot < wp.int64(p.candidate_capacity):
                p.candidate[int(slot)] = wp.vec3i(c.obj, tri_a, tree.tri_order[c.tri_start + j])
            slot += wp.int64(1)
    return slot


_WALK = front_kernel(name="self_walk", module=__name__, params_type=SelfParams, context_type=SelfItem,
                     entry=_entry, near=_near, leaf_rows=_rows, reserve=_reserve, emit=_emit, self_pairs=True)


@wp.func
def _welded(topology: MeshTopology, shape_vertex_start: wp.array[wp.int32], weld: wp.array[wp.int32], shape: int,
            tri: int) -> wp.vec3i:
    """The welded vertex ids of local triangle ``tri`` of ``shape`` (:func:`weld_vertices`)."""
    idx = topology.shape_triangle[topology.shape_triangle_start[shape] + tri]
    base = shape_vertex_start[shape]
    return wp.vec3i(weld[base + idx[0]], weld[base + idx[1]], weld[base + idx[2]])


@wp.func
def _boxes_apart(a0: Any, a1: Any, a2: Any, b0: Any, b1: Any, b2: Any, tol_rel: wp.float64) -> bool:
    """Whether the triangles' boxes lie apart by more than 2.5 ``tol_rel`` times the larger box's
    largest extent on some axis: then they are farther apart than the test ever accepts (``eps``,
    ``tol_rel`` times the longest edge, at most sqrt(3) times that extent; coplanar pairs touch up to
    sqrt(2) ``eps``, at most 2.45 ``tol_rel`` times the extent) and cannot meet. A candidate of a leaf of
    several triangles is mostly such a pair."""
    lo_a = wp.min(wp.min(a0, a1), a2)
    hi_a = wp.max(wp.max(a0, a1), a2)
    lo_b = wp.min(wp.min(b0, b1), b2)
    hi_b = wp.max(wp.max(b0, b1), b2)
    ea = hi_a - lo_a
    eb = hi_b - lo_b
    extent = wp.max(wp.max(wp.max(ea[0], ea[1]), ea[2]), wp.max(wp.max(eb[0], eb[1]), eb[2]))
    pad = type(extent)(tol_rel * wp.float64(2.5)) * extent
    for i in range(3):
        if lo_a[i] > hi_b[i] + pad or lo_b[i] > hi_a[i] + pad:
            return True
    return False


@wp.kernel
def _self_narrow_kernel(
    topology: MeshTopology,
    vertex: wp.array[Any],
    shape_vertex_start: wp.array[wp.int32],
    weld: wp.array[wp.int32],
    tol_rel: wp.float64,
    candidate: wp.array[wp.vec3i],
    candidate_count: wp.array[wp.int64],
    candidate_capacity: int,
    hit_capacity: int,
    # Outputs
    hit: wp.array[wp.vec3i],
    hit_count: wp.array[wp.int64],
    flag: wp.array[wp.int32],
):
    """One thread per candidate ``(item, tri, tri)``: :func:`~warp_ccd._src.geometry.adjacent.tri_tri_self`
    on the item's vertices (``vertex``, placed by ``topology``); a pair that meets is written as
    ``(item, tri_a, tri_b)``, ``tri_a < tri_b``, and flags its item."""
    k = wp.tid()
    if k >= used_count(candidate_count, candidate_capacity):
        return
    c = candidate[k]
    obj = c[0]
    shape = topology.object_shape[obj]
    a0, a1, a2 = mesh_triangle(topology, vertex, obj, c[1])
    b0, b1, b2 = mesh_triangle(topology, vertex, obj, c[2])
    if _boxes_apart(a0, a1, a2, b0, b1, b2, tol_rel):
        return
    ia = _welded(topology, shape_vertex_start, weld, shape, c[1])
    ib = _welded(topology, shape_vertex_start, weld, shape, c[2])
    if tri_tri_self(a0, a1, a2, b0, b1, b2, ia, ib, tol_rel):
        slot = reserve_slot(hit_count, hit_capacity)
        if slot >= 0:
            hit[slot] = wp.vec3i(obj, wp.min(c[1], c[2]), wp.max(c[1], c[2]))
        flag[obj] = 1


_NARROW = precision_overloads(_self_narrow_kernel, lambda s, v, q, t: {"vertex": wp.array[v]})


@wp.kernel
def _self_depth_kernel(
    topology: MeshTopology,
    vertex: wp.array[Any],
    tol_rel: wp.float64,
    row: wp.array[wp.vec3i],
    # Outputs
    depth: wp.array[wp.float64],
):
    """One thread per row ``(object, tri_a, tri_b)``: how deep the two triangles cross
    (:func:`~warp_ccd._src.geometry.triangle.crossing_depth`, scene units; 0 for a fold or a touch)."""
    k = wp.tid()
    r = row[k]
    a0, a1, a2 = mesh_triangle(topology, vertex, r[0], r[1])
    b0, b1, b2 = mesh_triangle(topology, vertex, r[0], r[2])
    depth[k] = wp.float64(crossing_depth(a0, a1, a2, b0, b1, b2, type(a0[0])(tol_rel)))


_DEPTH = precision_overloads(_self_depth_kernel, lambda s, v, q, t: {"vertex": wp.array[v]})


@wp.kernel
def _rigid_rows_kernel(
    rigid_object: wp.array[wp.int32],
    object_shape: wp.array[wp.int32],
    shape_row_start: wp.array[wp.int32],
    shape_row: wp.array[wp.vec2i],
    hit_capacity: int,
    # Outputs
    hit: wp.array[wp.vec3i],
    hit_count: wp.array[wp.int64],
    flag: wp.array[wp.int32],
):
    """One thread per rigid object whose shape intersects itself: the shape's rows as the object's."""
    i = rigid_object[wp.tid()]
    s = object_shape[i]
    first = shape_row_start[s]
    m = shape_row_start[s + 1] - first
    slot = wp.atomic_add(hit_count, 0, wp.int64(m))
    for j in range(m):
        if slot + wp.int64(j) < wp.int64(hit_capacity):
            r = shape_row[first + j]
            hit[int(slot) + j] = wp.vec3i(i, r[0], r[1])
    flag[i] = 1


class SelfTraversal:
    """A tree against itself for each of a list of items, and the adjacency-aware triangle test over
    the candidates (module docs).

    Args:
        num_levels: levels of the deepest tree walked (the traversal launches one fewer, at least 1).
        tolerance: relative tolerance of the triangle test (:func:`~warp_ccd._src.geometry.adjacent.tri_tri_self`).
        capacity, front_capacity, hit_capacity: initial capacities (they grow).
        device: Warp device.

    Attributes:
        front: node pairs between levels (two halves; its counter: the largest level's count).
        candidates: ``(item, tri, tri)`` rows (``wp.vec3i``).
        hits: the rows that meet, ``(item, tri_a, tri_b)``, ``tri_a < tri_b`` (``wp.vec3i``), unsorted.
    """

    def __init__(self, num_levels: int, *, tolerance: float = TOLERANCE, capacity: int = 4096,
                 front_capacity: int = 1024, hit_capacity: int = 256, device=None):
        self.device = d = wp.get_device(device)
        self.tolerance = check_option("tolerance", tolerance)
        self.walk = FrontWalk(num_levels, front_capacity, "self-traversal front", d)
        self.num_levels = self.walk.num_levels
        self.front = self.walk.front
        self.candidates = GrowableBuffer(wp.vec3i, capacity, d, "self candidate triangle pairs")
        self.hits = GrowableBuffer(wp.vec3i, hit_capacity, d, "self-intersecting triangle pairs")
        self._item_count = wp.zeros(1, dtype=wp.int64, device=d)

    @property
    def counters(self) -> list[GrowableBuffer]:
        """The front (its largest level), the candidates, the hits."""
        return [self.front, self.candidates, self.hits]

    def launch(self, tree: TreeView, topology: MeshTopology, vertex: wp.array, items: wp.array,
               shape_vertex_start: wp.array, weld: wp.array, flag: wp.array, precision: str) -> None:
        """Enqueues the traversal of ``items`` (object ids of ``topology`` and ``tree``) and the test of
        its candidates on ``vertex`` (placed by ``topology``); hits flag ``flag[item]``. The counters
        are the caller's to reset."""
        num_items = items.shape[0]
        if num_items == 0:
            return
        d = self.device
        self._item_count.fill_(num_items)
        cand = self.candidates
        params = SelfParams()
        params.object_shape = topology.object_shape
        params.item = items
        params.candidate = cand.data
        params.candidate_count = cand.count
        params.candidate_capacity = cand.capacity
        self.walk.launch(_WALK, tree, params, self._item_count, num_items)
        wp.launch(_NARROW[precision], dim=cand.capacity,
                  inputs=[topology, vertex, shape_vertex_start, weld, wp.float64(self.tolerance), cand.data,
                          cand.count, cand.capacity, self.hits.capacity],
                  outputs=[self.hits.data, self.hits.count, flag], device=d)


class SelfIntersection:
    """The frame's self-intersection stage (module docs): rigid objects' rows from their shapes' (computed
    once, at construction), deforming objects' traversal every frame after the refit.

    Args:
        scene: the :class:`~warp_ccd._src.scene.scene.Scene`.
        bvh: its :class:`~warp_ccd._src.trees.bvh.SceneBVH` (leaf boxes padded by ``tolerance``, or more).
        tolerance: relative tolerance of the triangle test.
        hit_capacity: initial capacity of :attr:`hits` (it grows).
        device: Warp device (the scene's).

    Attributes:
        shape_rows: ``(R, 3)`` int32 rows ``(shape, tri_a, tri_b)`` of the shapes of rigid objects that
            intersect themselves, sorted (host).
        hits: the frame's rows ``(object, tri_a, tri_b)`` (the deforming traversal's buffer; unsorted).
        object_flag: ``(N,)`` int32 device flags: the object intersects itself.
    """

    def __init__(self, scene: Scene, bvh: SceneBVH, *, tolerance: float = TOLERANCE, hit_capacity: int | None = None,
                 device: DeviceLike = None) -> None:
        self.device = d = wp.get_device(device or scene.device)
        n = scene.num_objects
        self.tolerance = check_option("tolerance", tolerance)
        self.weld = wp.array(weld_vertices(scene.shape_vertex.numpy(), scene.shape_vertex_start_np), dtype=wp.int32,
                             device=d)
        self.shape_vertex_start = scene.shape_vertex_start
        self.bvh = bvh
        deforming = bvh.object_deforming.numpy().astype(bool)
        shape = scene.object_shape_np
        self.object_flag = wp.zeros(n, dtype=wp.int32, device=d)
        # Rigid objects: their shapes' self-intersections, once (shape space, the shapes' own vertices).
        rigid_shapes = np.unique(shape[~deforming]).astype(np.int32)
        self.shape_rows = self._shape_rows(scene, rigid_shapes)
        counts = np.bincount(self.shape_rows[:, 0], minlength=scene.num_shapes)
        self._shape_row_start = wp.array(np.concatenate([[0], np.cumsum(counts)]).astype(np.int32), dtype=wp.int32,
                                         device=d)
        self._shape_row = wp.array(np.ascontiguousarray(self.shape_rows[:, 1:]).reshape(-1, 2), dtype=wp.vec2i,
                                   device=d)
        self._rigid_object = wp.array(np.nonzero(~deforming & (counts[shape] > 0))[0].astype(np.int32),
                                      dtype=wp.int32, device=d)
        rigid_rows = int(counts[shape[~deforming]].sum()) if n else 0
        self._deforming_object = wp.array(np.nonzero(deforming)[0].astype(np.int32), dtype=wp.int32, device=d)
        tris = np.diff(scene.shape_triangle_start_np)[shape[deforming]].sum() if n else 0
        self.traversal = SelfTraversal(bvh.num_levels, tolerance=self.tolerance, device=d,
                                       capacity=max(4096, int(8 * tris)), front_capacity=max(1024, int(2 * tris)),
                                       hit_capacity=hit_capacity or max(256, 2 * rigid_rows))

    def _shape_rows(self, scene, shapes: np.ndarray) -> np.ndarray:
        """``(R, 3)`` sorted rows ``(shape, tri_a, tri_b)`` of ``shapes`` (run now, to the end)."""
        if len(shapes) == 0:
            return np.zeros((0, 3), np.int32)
        d = self.device
        bvh = self.bvh
        tris = int(np.diff(scene.shape_triangle_start_np)[shapes].sum())
        walk = SelfTraversal(bvh.num_levels, tolerance=self.tolerance, device=d, capacity=max(4096, 8 * tris),
                             front_capacity=max(1024, 2 * tris))
        items = wp.array(shapes, dtype=wp.int32, device=d)
        flag = wp.zeros(scene.num_shapes, dtype=wp.int32, device=d)
        frames = FrameCache(CounterRead(walk.counters, d, stages=[0, 1, 2]), "eager")

        def launch():
            walk.launch(bvh._shape_tree, bvh._shape_topology, scene.shape_vertex, items, scene.shape_vertex_start,
                        self.weld, flag, scene.precision)

        while frames.get(None, launch).run_once():
            pass
        rows = walk.hits.numpy(walk.hits.last_count).reshape(-1, 3).astype(np.int32)
        return rows[np.lexsort((rows[:, 2], rows[:, 1], rows[:, 0]))]

    @property
    def hits(self) -> GrowableBuffer:
        return self.traversal.hits

    @property
    def counters(self) -> list[GrowableBuffer]:
        """The deforming traversal's front, candidates and hits (rigid objects' rows are hits too)."""
        return self.traversal.counters

    def depth(self, scene: Scene, rows: np.ndarray) -> np.ndarray:
        """``(M,)`` float64 crossing depths (scene units) of rows ``(object, tri_a, tri_b)`` on the scene's
        world vertices now (:func:`~warp_ccd._src.geometry.triangle.crossing_depth`; 0 for a fold flat onto
        itself). Waits for the device."""
        rows = np.ascontiguousarray(np.asarray(rows, np.int32).reshape(-1, 3))
        if len(rows) == 0:
            return np.zeros(0)
        out = wp.empty(len(rows), dtype=wp.float64, device=self.device)
        wp.launch(_DEPTH[scene.precision], dim=len(rows),
                  inputs=[scene.topology, scene.world_vertex, wp.float64(self.tolerance),
                          wp.array(rows, dtype=wp.vec3i, device=self.device)],
                  outputs=[out], device=self.device)
        return out.numpy()

    def launch(self, scene: Scene) -> None:
        """Enqueues the frame's rows: the rigid objects' (their shapes'), then the deforming objects'
        traversal on ``scene.world_vertex`` (their trees refit for this frame). The counters are the
        caller's to reset."""
        d = self.device
        self.object_flag.zero_()
        hits = self.hits
        if self._rigid_object.shape[0]:
            wp.launch(_rigid_rows_kernel, dim=self._rigid_object.shape[0],
                      inputs=[self._rigid_object, scene.object_shape, self._shape_row_start, self._shape_row,
                              hits.capacity],
                      outputs=[hits.data, hits.count, self.object_flag], device=d)
        self.traversal.launch(self.bvh.tree, scene.topology, scene.world_vertex, self._deforming_object,
                              scene.shape_vertex_start, self.weld, self.object_flag, scene.precision)
