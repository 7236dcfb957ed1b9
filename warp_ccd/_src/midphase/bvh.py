"""Mid phase: candidate triangle pairs of candidate object pairs.

Both implementations write ``(obj_a, tri_a, obj_b, tri_b)`` rows into a
:class:`~warp_ccd._src.runtime.buffers.GrowableBuffer` (``candidates``), for the narrow phase.

* :class:`MidPhaseBVH` (default): a simultaneous descent of the two objects' trees, level by level for
  every object pair at once: the tree-pair walk (:mod:`warp_ccd._src.trees.traversal`) with the mid
  phase's tests plugged in. A first kernel writes each pair's
  :class:`~warp_ccd._src.trees.traversal.TreePair` (its trees' starts, the maps between the two box
  spaces and their paddings), then each level is one launch over the *front*, the node pairs whose boxes
  overlap: each opens both nodes (a leaf stays itself) and tests the two to four pairs of children; pairs
  of two leaves whose boxes overlap write their triangle pairs as candidates (a block reserving its rows
  with one atomic add), the other overlapping pairs go to the next level's front. Level 0 is the object
  pairs' roots, tested first (less the whole-object pairs below). Every node pair is one short step, all
  of a level's independent, so no thread walks a big pair alone, and an object pair whose boxes overlap
  but whose trees do not costs a few tests at level 0.

  *Whole-object pairs* skip the trees: in a scene of up to 30,000 objects, a pair of objects of at
  most 64 triangles each (polyhedra) has a block of 64 threads, one per triangle of the larger,
  test its world box against every triangle's of the smaller (:func:`_whole_pair_kernel`, one
  launch for all such pairs; the boxes are the trees' leaf boxes, padded alike). A small scene's
  traversal is latency, a few microseconds a launch a level; a scene of such objects alone
  launches no traversal at all.

  The boxes are tested in ``a``'s box space (:mod:`warp_ccd._src.trees.bvh`: a rigid object's shape space, a
  deforming object's world): ``b``'s box under the pair's relative transform, the box around it
  (three axes, ``a``'s), then ``a``'s box in ``b``'s space (``b``'s three axes): a separating-axis
  test of the two oriented boxes on six of their fifteen axes (``separating_axes=3``: the first
  three alone). The relative transforms come from the poses in float64, once per pair
  (:data:`~warp_ccd._src.trees.traversal.PAIR_KERNELS`), with a padding that bounds every rounding on the
  way, so a test never rejects what the world vertices would put in contact; a deforming object's frame is
  the identity.
* :class:`~warp_ccd._src.midphase.all_pairs.MidPhaseAllPairs`, the reference: every triangle of
  ``a`` against every triangle of ``b`` (its own module).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import warp as wp

from ..geometry.box import boxes_overlap
from ..geometry.precision import precision_overloads
from ..runtime.aliases import DeviceLike
from ..runtime.buffers import GrowableBuffer, block_reserve, used_count
from ..runtime.checks import integer_option
from ..runtime.options import check_option
from ..scene.scene import MeshTopology, Scene
from ..trees.bvh import WORLD_ERROR_ULPS, SceneBVH, TreeView, leaf_box_at, swept_arg_types
from ..trees.traversal import CHILD_LEAF, PAIR_KERNELS, FrontWalk, TreePair, front_kernel, node_pair_overlap

wp.set_module_options({"enable_backward": False})  # forward kernels only

__all__ = ["MidPhase", "MidPhaseBVH"]

WHOLE_TRIANGLES_MAX = 64
"""Default :attr:`MidPhaseBVH.whole_triangles_max`: a pair of objects of at most this many triangles
each (polyhedra) skips the trees: a thread per triangle of the larger tests its box against those
of the smaller, all in one launch (:func:`_whole_pair_kernel`). At most :data:`WHOLE_TRIANGLES_LIMIT`."""

WHOLE_OBJECTS_MAX = 30_000
"""Scenes of at most this many objects use whole-object pairs by default (:data:`WHOLE_TRIANGLES_MAX`),
larger ones walk trees for every pair: measured on a GPU (docs: architecture, mid phase), whole-object
pairs win up to 10^4 polyhedra and trees from 10^5: past a few 10^4 objects the latency of a launch a
level no longer counts, and the trees' tighter boxes do."""

WHOLE_LANES = 64
"""Default :attr:`MidPhaseBVH.whole_lanes`, threads per whole-object pair (:func:`_whole_pair_kernel`;
fewer when a block has fewer): a thread takes a triangle of the larger object, four pairs a block
of 256; 32 lanes (two triangles a thread for a dodecahedron) measured slower at every scale (docs:
architecture, mid phase)."""

WHOLE_TRIANGLES_LIMIT = 64
"""Most triangles of an object in a whole-object pair: a thread's hits are the bits of an int64."""


@wp.func
def _leaf_pair_rows(tree: TreeView, node_a: int, node_b: int) -> int:
    """Candidate rows of two leaves (global node ids): the product of their triangle counts."""
    return tree.node_triangle[node_a][1] * tree.node_triangle[node_b][1]


@wp.func
def _write_rows(
    tree: TreeView,
    rows: wp.vec4i,
    node_a: int,
    node_b: int,
    slot: wp.int64,
    candidate: wp.array[wp.vec4i],
    candidate_capacity: int,
) -> wp.int64:
    """Writes the triangle pairs of leaves ``node_a`` (of ``a``) and ``node_b`` (of ``b``, global
    node ids) from ``slot`` on; ``rows`` is the pair's ``(a, b, a's triangle order start, b's)``;
    returns the next slot."""
    ra = tree.node_triangle[node_a]
    rb = tree.node_triangle[node_b]
    for i in range(ra[0], ra[0] + ra[1]):
        tri_a = tree.tri_order[rows[2] + i]
        for j in range(rb[0], rb[0] + rb[1]):
            if slot < wp.int64(candidate_capacity):
                candidate[int(slot)] = wp.vec4i(rows[0], tri_a, rows[1], tree.tri_order[rows[3] + j])
            slot += wp.int64(1)
    return slot


@wp.func
def _is_whole_pair(object_triangle_start: wp.array[wp.int32], a: int, b: int, whole_max: int) -> bool:
    """Whether objects ``a`` and ``b`` have at most ``whole_max`` triangles each (a whole-object
    pair, :func:`_whole_pair_kernel`, not the trees')."""
    ma = object_triangle_start[a + 1] - object_triangle_start[a]
    mb = object_triangle_start[b + 1] - object_triangle_start[b]
    return ma <= whole_max and mb <= whole_max


@wp.struct
class MidParams:
    """What the mid phase's walk reads and writes besides the trees
    (:func:`~warp_ccd._src.trees.traversal.front_kernel`)."""

    tree_pair: wp.array[TreePair]
    pair_rows: wp.array[wp.vec4i]  # (a, b, a's triangle order start, b's): read again when rows are written
    object_triangle_start: wp.array[wp.int32]
    whole_max: int  # object pairs of at most this many triangles each are whole-object pairs (not walked)
    axes: int  # the box test's separating axes (3 or 6)
    candidate: wp.array[wp.vec4i]
    candidate_count: wp.array[wp.int64]
    candidate_capacity: int


@wp.func
def _entry(p: MidParams, tree: TreeView, k: int, na: int, nb: int, roots: int):
    """Pair ``k``'s :class:`TreePair`; a level-0 entry is opened where the pair is no whole-object pair
    and its roots' boxes overlap (a later entry's were tested when it was pushed)."""
    r = p.tree_pair[k]
    opened = True
    if roots != 0:
        opened = (not _is_whole_pair(p.object_triangle_start, r.a, r.b, p.whole_max)
                  and node_pair_overlap(tree, r, na, nb, p.axes))
    return r, r.node_a_start, r.node_b_start, opened


@wp.func
def _near(p: MidParams, tree: TreeView, r: TreePair, xa: int, xb: int) -> bool:
    """A child pair is kept where its boxes overlap."""
    return node_pair_overlap(tree, r, xa, xb, p.axes)


@wp.func
def _rows(p: MidParams, tree: TreeView, r: TreePair, kind: int, xa: int, xb: int) -> int:
    """Candidate rows of a child pair: its leaves' triangle pairs, or none."""
    if kind != CHILD_LEAF:
        return 0
    return _leaf_pair_rows(tree, r.node_a_start + xa, r.node_b_start + xb)


@wp.func
def _reserve(p: MidParams, lane: int, rows: int) -> wp.int64:
    return block_reserve(p.candidate_count, lane, rows)


@wp.func
def _emit(p: MidParams, tree: TreeView, r: TreePair, k: int, kind: int, xa: int, xb: int, slot: wp.int64) -> wp.int64:
    """Writes the rows of a child pair of kind ``CHILD_LEAF`` from ``slot``; returns the next slot."""
    if kind != CHILD_LEAF:
        return slot
    return _write_rows(tree, p.pair_rows[k], r.node_a_start + xa, r.node_b_start + xb, slot, p.candidate,
                       p.candidate_capacity)


_WALK = front_kernel(name="mid_phase_walk", module=__name__, params_type=MidParams, context_type=TreePair,
                     entry=_entry, near=_near, leaf_rows=_rows, reserve=_reserve, emit=_emit)


@wp.func
def _whole_row(topology: MeshTopology, world_vertex: wp.array[Any], world_vertex_start: wp.array[Any], swept: int,
               pad_abs: wp.float64, margin_rel: Any, big: int, i: int, small: int, m_small: int):
    """``(hits, count)``: bit ``j`` of the int64 ``hits`` is set when the world boxes of triangle
    ``i`` of ``big`` and ``j`` of ``small`` overlap (:func:`~warp_ccd._src.trees.bvh.triangle_box_at`, the
    trees' leaf boxes; with ``swept``, their boxes over the motion from ``world_vertex_start``)."""
    big_start = topology.shape_triangle_start[topology.object_shape[big]]
    lo, hi = leaf_box_at(topology, world_vertex, world_vertex_start, swept, pad_abs, margin_rel, big_start,
                     topology.object_vertex_start[big], i)
    tri_start = topology.shape_triangle_start[topology.object_shape[small]]
    vertex_start = topology.object_vertex_start[small]
    hits = wp.int64(0)
    count = int(0)
    for j in range(m_small):
        lo_j, hi_j = leaf_box_at(topology, world_vertex, world_vertex_start, swept, pad_abs, margin_rel, tri_start,
                             vertex_start, j)
        if boxes_overlap(lo, hi, lo_j, hi_j):
            hits = hits | (wp.int64(1) << wp.int64(j))
            count += 1
    return hits, count


@wp.func
def _write_whole_row(hits: wp.int64, m_small: int, a: int, b: int, big_is_a: bool, i: int, slot: wp.int64,
                     candidate: wp.array[wp.vec4i], candidate_capacity: int) -> wp.int64:
    """Writes the rows of a row's ``hits`` (:func:`_whole_row`) from ``slot``; returns the next slot."""
    for j in range(m_small):
        if (hits >> wp.int64(j)) & wp.int64(1) != wp.int64(0):
            if slot < wp.int64(candidate_capacity):
                if big_is_a:
                    candidate[int(slot)] = wp.vec4i(a, i, b, j)
                else:
                    candidate[int(slot)] = wp.vec4i(a, j, b, i)
            slot += wp.int64(1)
    return slot


@wp.kernel
def _whole_pair_kernel(
    topology: MeshTopology,
    world_vertex: wp.array[Any],
    world_vertex_start: wp.array[Any],
    swept: int,
    pad_abs: wp.float64,
    margin_rel: Any,
    pair: wp.array[wp.vec2i],
    pair_count: wp.array[wp.int64],
    pair_capacity: int,
    whole_max: int,
    lanes: int,
    num_blocks: int,
    candidate_capacity: int,
    # Outputs
    candidate: wp.array[wp.vec4i],
    candidate_count: wp.array[wp.int64],
):
    """Whole-object pairs: ``lanes`` threads per pair (a block holds ``block_dim / lanes`` pairs a
    round; ``num_blocks`` blocks stride over the stored pairs). For a pair of objects of at most
    ``whole_max`` triangles each, thread ``l`` takes triangles ``l, l + lanes, ...`` of the larger
    object and tests each one's world box against every triangle's of the smaller
    (:func:`_whole_row`); the block reserves the rows (:func:`~warp_ccd._src.runtime.buffers.block_reserve`) and
    each thread writes its hits (a thread with more than one triangle tests the later ones again).
    Other pairs are left to the trees."""
    block, lane = wp.tid()
    per_block = wp.block_dim() // lanes
    n = used_count(pair_count, pair_capacity)
    sub = lane % lanes
    for base in range(block * per_block, n, num_blocks * per_block):
        k = base + lane // lanes
        a = int(0)
        b = int(0)
        big = int(0)
        small = int(0)
        m_big = int(0)
        m_small = int(0)
        if k < n:
            p = pair[k]
            a = p[0]
            b = p[1]
            if _is_whole_pair(topology.object_triangle_start, a, b, whole_max):
                ma = topology.object_triangle_start[a + 1] - topology.object_triangle_start[a]
                mb = topology.object_triangle_start[b + 1] - topology.object_triangle_start[b]
                big = wp.where(ma >= mb, a, b)
                small = wp.where(ma >= mb, b, a)
                m_big = wp.max(ma, mb)
                m_small = wp.min(ma, mb)
        count = int(0)
        first = wp.int64(0)
        for i in range(sub, m_big, lanes):
            hits, found = _whole_row(topology, world_vertex, world_vertex_start, swept, pad_abs, margin_rel, big, i,
                                     small, m_small)
            if i == sub:
                first = hits
            count += found
        slot = block_reserve(candidate_count, lane, count)
        if count > 0:
            for i in range(sub, m_big, lanes):
                hits = first
                if i != sub:
                    hits, _found = _whole_row(topology, world_vertex, world_vertex_start, swept, pad_abs, margin_rel,
                                              big, i, small, m_small)
                slot = _write_whole_row(hits, m_small, a, b, big == a, i, slot, candidate, candidate_capacity)


_WHOLE = precision_overloads(_whole_pair_kernel, swept_arg_types)


class MidPhase:
    """What both mid phases share: the candidate buffer (``capacity``, it grows) of ``wp.vec4i`` rows
    ``(obj_a, tri_a, obj_b, tri_b)``, and the options of whole-object pairs, checked when set (read
    at each launch by :class:`MidPhaseBVH`, unused by :class:`MidPhaseAllPairs`, whose pairs are all
    whole: one setting serves either).

    Attributes:
        whole_triangles_max: pairs of objects of at most this many triangles each skip the trees (at
            most :data:`WHOLE_TRIANGLES_LIMIT`; 0, the default here: none): their triangles' world
            boxes are tested pair by pair in one launch (:func:`_whole_pair_kernel`); a scene of
            such objects alone launches no tree traversal.
        whole_lanes: threads per whole-object pair (default :data:`WHOLE_LANES`; a power of two up to 256).
    """

    def __init__(self, *, capacity: int = 4096, device: DeviceLike = None) -> None:
        self.device = wp.get_device(device)
        self.candidates = GrowableBuffer(wp.vec4i, capacity, self.device, "candidate triangle pairs")
        self.whole_triangles_max = 0
        self.whole_lanes = WHOLE_LANES

    @property
    def whole_triangles_max(self) -> int:
        """Pairs of objects of at most this many triangles each skip the trees (see the class docs)."""
        return self._whole_triangles_max

    @whole_triangles_max.setter
    def whole_triangles_max(self, value: int) -> None:
        self._whole_triangles_max = integer_option("whole_triangles_max", value, low=0, high=WHOLE_TRIANGLES_LIMIT)

    @property
    def whole_lanes(self) -> int:
        """Threads per whole-object pair (see the class docs)."""
        return self._whole_lanes

    @whole_lanes.setter
    def whole_lanes(self, value: int) -> None:
        self._whole_lanes = integer_option("whole_lanes", value, choices=(1, 2, 4, 8, 16, 32, 64, 128, 256))


class MidPhaseBVH(MidPhase):
    """Tree-vs-tree traversal over the broad phase's object pairs, level by level over the front of
    overlapping node pairs (see module docs).

    Args:
        bvh: the scene's :class:`~warp_ccd._src.trees.bvh.SceneBVH` (refit before each launch).
        capacity: initial capacity of the candidate buffer (it grows).
        front_capacity: initial capacity of each level's front of node pairs (it grows; default
            four per object).
        separating_axes: 6 (default) tests ``b``'s boxes as the boxes around them in ``a``'s space
            and ``a``'s in ``b``'s; 3 the first alone (more candidates, less arithmetic a test).
        whole_triangles_max: default :data:`WHOLE_TRIANGLES_MAX` up to :data:`WHOLE_OBJECTS_MAX` objects, else 0.
        clearance: candidates are the triangle pairs whose boxes come within this distance (scene units,
            >= 0): every test padded by it (a tree's boxes in its object's space by ``clearance /
            scale``, a whole-object pair's triangle boxes by half of it each), so that no pair of
            triangles within it is culled (:mod:`warp_ccd._src.narrowphase.clearance`). 0 (default): pairs whose
            boxes overlap.
        device: Warp device.

    Attributes:
        candidates, whole_triangles_max, whole_lanes: as in :class:`MidPhase`.
        walk: the :class:`~warp_ccd._src.trees.traversal.FrontWalk` of the trees (its ``front``, ``num_levels``,
            ``num_blocks`` and ``block_dim`` are this stage's too).
        front: the walk's front of node pairs ``(pair, node a, node b)`` (its counter: the largest level's count).
        separating_axes, clearance: as above (read at each launch: a captured frame keeps the value it
            was captured with).
    """

    def __init__(self, bvh: SceneBVH, *, capacity: int = 4096, front_capacity: int | None = None,
                 separating_axes: int = 6, whole_triangles_max: int | None = None, clearance: float = 0.0,
                 device: DeviceLike = None) -> None:
        super().__init__(capacity=capacity, device=device)
        self.bvh = bvh
        self.clearance = check_option("clearance", clearance)
        self.separating_axes = check_option("separating_axes", separating_axes)
        self.walk = FrontWalk(bvh.num_levels, front_capacity or max(256, 4 * bvh.lower.shape[0]), "tree-pair front",
                              self.device)
        if whole_triangles_max is None:
            whole_triangles_max = WHOLE_TRIANGLES_MAX if bvh.lower.shape[0] <= WHOLE_OBJECTS_MAX else 0
        self.whole_triangles_max = whole_triangles_max
        self._pairs_capacity = -1

    @property
    def front(self) -> GrowableBuffer:
        """The walk's front of node pairs ``(pair, node a, node b)`` (its counter: the largest level's count)."""
        return self.walk.front

    @property
    def num_levels(self) -> int:
        """Launches of the walk a frame: the deepest tree's levels less one (at least 1)."""
        return self.walk.num_levels

    @property
    def num_blocks(self) -> int:
        """The largest grid of a launch, in blocks, the walk's and the whole-object pairs' (set it before a frame
        is captured: a captured frame keeps the grid it was captured with)."""
        return self.walk.num_blocks

    @num_blocks.setter
    def num_blocks(self, value: int) -> None:
        self.walk.num_blocks = integer_option("num_blocks", value, low=1)

    @property
    def block_dim(self) -> int:
        """Threads per block of the walk's and the whole-object pairs' launches."""
        return self.walk.block_dim

    @property
    def counters(self) -> list[GrowableBuffer]:
        """The buffers with counters that :meth:`launch` resets and writes, whose counters the caller
        reads after it: the front (its largest level), then the candidates."""
        return [self.front, self.candidates]

    def launch(self, scene: Scene, pairs: GrowableBuffer, *, reset_counters: bool = True,
               world_vertex_start: wp.array | None = None) -> None:
        """Writes candidates of the object ``pairs`` of ``scene`` into :attr:`candidates`.

        Args:
            scene: the scene whose trees :attr:`bvh` holds (refit for this frame).
            pairs: the broad phase's object pairs.
            reset_counters: zero the counters of :attr:`counters` first; False when the caller has.
            world_vertex_start: the start of a linear motion to ``scene.world_vertex`` (a continuous
                frame: the trees were refit with it, and whole-object pairs test swept boxes too).
        """
        d = self.device
        if reset_counters:
            for buffer in self.counters:
                buffer.reset()
        if self._pairs_capacity != pairs.capacity:  # scratch follows the pair capacity
            self._pairs_capacity = pairs.capacity
            self._tree_pair = wp.zeros(pairs.capacity, dtype=TreePair, device=d)
            self._pair_rows = wp.zeros(pairs.capacity, dtype=wp.vec4i, device=d)
        tree = self.bvh.tree
        eps = float(np.finfo(np.float64 if scene.precision == "float64" else np.float32).eps)
        cand = self.candidates
        whole = self.whole_triangles_max
        if whole >= self.bvh.min_triangles:  # some object pairs may be whole-object pairs
            lanes = min(self.whole_lanes, self.block_dim)
            per_block = self.block_dim // lanes
            blocks = min(self.num_blocks, (pairs.capacity + per_block - 1) // per_block)
            wp.launch_tiled(_WHOLE[scene.precision], dim=[blocks],
                            inputs=[scene.topology, *self.bvh.sweep_args(scene, world_vertex_start,
                                                                         0.5 * self.clearance),
                                    scene.scalar_type(self.bvh.margin_rel),
                                    pairs.data, pairs.count, pairs.capacity, whole, lanes, blocks, cand.capacity],
                            outputs=[cand.data, cand.count], block_dim=self.block_dim, device=d)
        if self.bvh.max_triangles <= whole:
            return  # every pair is a whole-object pair
        wp.launch(PAIR_KERNELS[scene.precision], dim=pairs.capacity,
                  inputs=[tree, scene.object_shape, scene.object_pose, scene.object_scale,
                          self.bvh.object_deforming, WORLD_ERROR_ULPS * eps, wp.float64(self.clearance),
                          pairs.data, pairs.count, pairs.capacity],
                  outputs=[self._tree_pair, self._pair_rows, self.walk.level_count], device=d)
        params = MidParams()
        params.tree_pair = self._tree_pair
        params.pair_rows = self._pair_rows
        params.object_triangle_start = scene.object_triangle_start
        params.whole_max = whole
        params.axes = self.separating_axes
        params.candidate = cand.data
        params.candidate_count = cand.count
        params.candidate_capacity = cand.capacity
        # The pair kernel zeroed the levels' counts below the roots (no memset node in the frame).
        self.walk.launch(_WALK, tree, params, pairs.count, pairs.capacity, zero_levels=False)
