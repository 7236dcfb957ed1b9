"""Mid phase: candidate triangle pairs of candidate object pairs.

Both implementations write ``(obj_a, tri_a, obj_b, tri_b)`` rows into a
:class:`~warp_ccd.buffers.GrowableBuffer` (``candidates``), for the narrow phase.

* :class:`MidPhaseBVH` (default): traversal of the two objects' trees (:mod:`warp_ccd.bvh`)
  from a front of node pairs: every leaf of the object with fewer leaves against every subtree
  of the other's cut (its nodes at level ``cut_depth``, and the leaves above; at most 8 subtrees
  by default). One work item per such (leaf, subtree) pair; each descends its subtree, depth
  first with a short stack, and gathers the leaves whose boxes overlap its own: their triangle
  pairs are the candidates. That is the set a simultaneous descent of both trees
  finds (an inner box is the union of its children's, so two leaf boxes overlap only where all
  their ancestors' do), with the first tree opened to its leaves and the second to its cut at
  once: no thread walks a big pair alone, the longest descent is a subtree's (not a whole
  tree's: at 1,000 polyhedra the slowest of the root-first items visited 71 nodes), and a frame
  of a hundred object pairs still fills the GPU. Testing the cut's boxes costs what a descent
  from the root spends above it (about two tests per level). A first kernel writes each pair's
  :class:`FrontPair` (its sides' starts in the tree arrays) and item count; work items are laid
  out by a scan of those counts (``wp.utils.array_scan``); a fixed grid of threads takes them
  in rounds, one item per thread per round (the launch size does not depend on the frame, so
  the frame can be a CUDA graph), and each round a block reserves the rows of all its items with
  one atomic add (:func:`~warp_ccd.buffers.block_reserve`). A light frame, one whose items would
  fit the grid once even if twice as many (judged by the last frame's, which the traversal
  records on the device), starts one level below the cut: twice the items, shorter descents.
* :class:`MidPhaseAllPairs`, the reference: every triangle of ``a`` against every triangle of
  ``b``. Count per pair, inclusive scan (``wp.utils.array_scan``), then one thread per candidate
  finds its pair by binary search over the scan. O(sum of m_a m_b) work; for small meshes only.
"""

from __future__ import annotations

import warp as wp

from .aabb import boxes_overlap
from .buffers import (
    BLOCK_DIM,
    ITEM_LIST_SIZE,
    GrowableBuffer,
    block_dim_for,
    block_reserve,
    upper_bound,
    used_count,
    vec_items,
)
from .bvh import SceneBVH, TreeView

wp.set_module_options({"enable_backward": False})  # forward kernels only

__all__ = ["MidPhaseAllPairs", "MidPhaseBVH"]

STACK_SIZE = 32
"""Traversal stack entries per thread: a depth-first descent of a tree of depth ``D`` needs
``D + 1``; a median-split tree of fewer than 2**31 triangles has at most 32 levels."""

vec_stack = wp.types.vector(length=STACK_SIZE, dtype=wp.int32)

THREADS_PER_SM = 512
"""Threads of the traversal per streaming multiprocessor on CUDA: the kernel takes 96 registers a
thread, so an H100 SM keeps two blocks of 256 resident; 512 is one wave (1,024 was two, the second
mostly blocks that find no item: 0.035 against 0.038 ms at 10^4 objects, the same at 10^3 and 10^5)."""

assert THREADS_PER_SM % BLOCK_DIM == 0


@wp.struct
class FrontPair:
    """What the traversal needs of one object pair, laid out once per pair by
    :func:`_front_count_kernel` so that a work item reads it in one step (not through the pair, its
    shapes, then their starts: four dependent reads). The front object is the one opened to its
    leaves; ``a < b`` are the pair's objects as the rows name them."""

    a: int
    b: int
    front: int  # 0: a is the front object, 1: b
    num_leaves: int  # of the front object's tree
    num_cut: int  # subtrees of the other's cut
    leaf_start: int  # the front shape's leaves in TreeView.leaf_node
    cut_start: int  # the other shape's cut in TreeView.cut_node
    front_node_start: int  # global node id of the front shape's local node 0 (in its layout)
    other_node_start: int
    front_slot_start: int  # the front instance's node boxes in TreeView.node_lower/upper
    other_slot_start: int
    front_tri_start: int  # the front shape's triangle order in TreeView.tri_order
    other_tri_start: int


@wp.func
def _num_leaves(tree: TreeView, layout: int) -> int:
    return tree.layout_leaf_start[layout + 1] - tree.layout_leaf_start[layout]


@wp.func
def _cut_start(tree: TreeView, layout: int, deep: int) -> int:
    """Where the layout's cut (``deep`` 0) or its cut one level deeper (1) starts in ``cut_node``."""
    return tree.layout_cut_start[2 * layout + deep]


@wp.func
def _num_cut(tree: TreeView, layout: int, deep: int) -> int:
    return _cut_start(tree, layout, deep + 1) - _cut_start(tree, layout, deep)


@wp.func
def _deep_cut(load: wp.array[wp.int64], num_threads: int) -> int:
    """1 when this frame's traversal starts one level below the cut: when the last frame's items,
    at most doubled by that level (``2**(d + 1)`` subtrees against ``2**d``), fit in one round of
    the grid; else 0. ``load``: the last frame's items and whether it went deep (a frame run again
    after a buffer grew judges by its first, cut-short run: at worst one heavy frame goes deep)."""
    room = wp.int64(num_threads)
    if load[1] == wp.int64(0):
        room = room / wp.int64(2)
    if load[0] <= room:
        return 1
    return 0


@wp.func
def _front_pair(tree: TreeView, instance_shape: wp.array[wp.int32], a: int, b: int, deep: int) -> FrontPair:
    """The :class:`FrontPair` of objects ``a < b``: ``a`` opens to its leaves unless ``b`` has fewer;
    the other starts from its cut, or one level deeper (``deep``)."""
    sa = instance_shape[a]
    sb = instance_shape[b]
    r = FrontPair()
    r.a = a
    r.b = b
    r.front = 0
    s_front = sa
    s_other = sb
    front_obj = a
    other_obj = b
    if _num_leaves(tree, tree.shape_layout[sb]) < _num_leaves(tree, tree.shape_layout[sa]):
        r.front = 1
        s_front = sb
        s_other = sa
        front_obj = b
        other_obj = a
    l_front = tree.shape_layout[s_front]
    l_other = tree.shape_layout[s_other]
    r.num_leaves = _num_leaves(tree, l_front)
    r.num_cut = _num_cut(tree, l_other, deep)
    r.leaf_start = tree.layout_leaf_start[l_front]
    r.cut_start = _cut_start(tree, l_other, deep)
    r.front_node_start = tree.layout_node_start[l_front]
    r.other_node_start = tree.layout_node_start[l_other]
    r.front_slot_start = tree.instance_node_start[front_obj]
    r.other_slot_start = tree.instance_node_start[other_obj]
    r.front_tri_start = tree.shape_tri_order_start[s_front]
    r.other_tri_start = tree.shape_tri_order_start[s_other]
    return r


@wp.kernel
def _front_count_kernel(
    tree: TreeView,
    instance_shape: wp.array[wp.int32],
    pair: wp.array[wp.vec2i],
    pair_count: wp.array[wp.int64],
    pair_capacity: int,
    load: wp.array[wp.int64],
    num_threads: int,
    # Outputs
    front_pair: wp.array[FrontPair],
    pair_items: wp.array[wp.int64],
    cut_level: wp.array[wp.int32],
):
    """One thread per pair slot: the pair's :class:`FrontPair` and work items (leaves of the front
    object times the cut of the other), 0 items past the counter; every pair starts from the cut,
    or one level below it when the last frame's ``load`` was light (:func:`_deep_cut`, the choice
    also written to ``cut_level``)."""
    k = wp.tid()
    deep = _deep_cut(load, num_threads)
    if k == 0:
        cut_level[0] = deep
    if k >= used_count(pair_count, pair_capacity):
        pair_items[k] = wp.int64(0)
        return
    p = pair[k]
    r = _front_pair(tree, instance_shape, p[0], p[1], deep)
    front_pair[k] = r
    pair_items[k] = wp.int64(r.num_leaves) * wp.int64(r.num_cut)


@wp.func
def _leaf_pair_rows(tree: TreeView, front_node: int, other_node: int) -> int:
    """Candidate rows of two leaves (shape-global node ids): the product of their triangle counts."""
    return tree.node_triangle[front_node][1] * tree.node_triangle[other_node][1]


@wp.func
def _leaf_rows(tree: TreeView, front_node: int, found: vec_items, num_found: int) -> int:
    """Candidate rows of the front leaf ``front_node`` with the ``num_found`` leaves ``found``."""
    rows = int(0)
    for m in range(num_found):
        rows += tree.node_triangle[found[m]][1]
    return rows * tree.node_triangle[front_node][1]


@wp.func
def _write_rows(
    tree: TreeView,
    r: FrontPair,
    front_node: int,
    other_node: int,
    slot: wp.int64,
    candidate: wp.array[wp.vec4i],
    candidate_capacity: int,
) -> wp.int64:
    """Writes the triangle pairs of the front leaf and one leaf of the other object (shape-global
    node ids) from ``slot`` on (rows keep ``a`` first); returns the next slot."""
    rf = tree.node_triangle[front_node]
    ro = tree.node_triangle[other_node]
    for i in range(rf[0], rf[0] + rf[1]):
        tri_f = tree.tri_order[r.front_tri_start + i]
        for j in range(ro[0], ro[0] + ro[1]):
            if slot < wp.int64(candidate_capacity):
                tri_o = tree.tri_order[r.other_tri_start + j]
                if r.front == 0:
                    candidate[int(slot)] = wp.vec4i(r.a, tri_f, r.b, tri_o)
                else:
                    candidate[int(slot)] = wp.vec4i(r.a, tri_o, r.b, tri_f)
            slot += wp.int64(1)
    return slot


@wp.func
def _leaf_vs_subtree(
    tree: TreeView,
    r: FrontPair,
    leaf: int,
    sub: int,
    candidate: wp.array[wp.vec4i],
    candidate_count: wp.array[wp.int64],
    candidate_capacity: int,
):
    """Leaf ``leaf`` (shape-local) of the pair's front object against the subtree of node ``sub``
    of the other object's tree, depth first: the overlapping leaves (shape-global ids), the first
    :data:`~warp_ccd.buffers.ITEM_LIST_SIZE` returned with their number, the rows of any more
    emitted at once (one atomic add each). A node's children are read with its box, before its
    test: one dependent read a node, not two."""
    front_node = r.front_node_start + leaf
    lo = tree.node_lower[r.front_slot_start + leaf]
    hi = tree.node_upper[r.front_slot_start + leaf]
    found = vec_items()
    num_found = int(0)
    stack = vec_stack()
    stack[0] = sub
    top = int(1)
    while top > 0:
        top -= 1
        node = stack[top]
        slot = r.other_slot_start + node
        child = tree.node_child[r.other_node_start + node]
        if boxes_overlap(lo, hi, tree.node_lower[slot], tree.node_upper[slot]):
            if child[0] < 0:
                if num_found < ITEM_LIST_SIZE:
                    found[num_found] = r.other_node_start + node
                    num_found += 1
                else:
                    other_node = r.other_node_start + node
                    first = wp.atomic_add(candidate_count, 0, wp.int64(_leaf_pair_rows(tree, front_node, other_node)))
                    _write_rows(tree, r, front_node, other_node, first, candidate, candidate_capacity)
            else:
                stack[top] = child[1]
                stack[top + 1] = child[0]
                top += 2
    return found, num_found


@wp.kernel
def _front_traverse_kernel(
    tree: TreeView,
    front_pair: wp.array[FrontPair],
    pair_count: wp.array[wp.int64],
    pair_capacity: int,
    pair_item_end: wp.array[wp.int64],
    num_blocks: int,
    candidate_capacity: int,
    cut_level: wp.array[wp.int32],
    # Outputs
    candidate: wp.array[wp.vec4i],
    candidate_count: wp.array[wp.int64],
    load: wp.array[wp.int64],
):
    """``num_blocks`` blocks of threads take the work items (inclusive scan ``pair_item_end`` of the
    pairs' item counts) in rounds, one item per thread per round; item ``w`` of pair ``k`` is leaf
    ``w / C`` (in leaf order) of the pair's front object against cut subtree ``w % C`` of the
    other's ``C``. Each round, a block reserves all its threads' rows with one atomic add. The
    first thread records the frame's ``load`` (items, deep cut or not) for the next frame's choice."""
    block, lane = wp.tid()
    width = wp.block_dim()
    num_threads = wp.int64(num_blocks * width)
    t = wp.int64(block * width + lane)
    num_pairs = used_count(pair_count, pair_capacity)
    total = wp.int64(0)
    if num_pairs > 0:
        total = pair_item_end[num_pairs - 1]
    if t == wp.int64(0):
        load[0] = total
        load[1] = wp.int64(cut_level[0])
    if num_pairs == 0:
        return  # the whole grid returns: no block is left waiting in block_reserve
    if wp.int64(block * width) >= total:
        return  # the whole block: its items, t + r * num_threads, are all past the last
    rounds = (total + num_threads - wp.int64(1)) / num_threads  # the same in every thread
    k = int(0)
    item = t
    for _round in range(int(rounds)):
        found = vec_items()
        num_found = int(0)
        r = FrontPair()
        front_node = int(0)
        if item < total:
            k = upper_bound(pair_item_end, k, num_pairs, item)  # items only move forward: so does k
            r = front_pair[k]
            w = item - (pair_item_end[k] - wp.int64(r.num_leaves) * wp.int64(r.num_cut))
            leaf_index = int(0)
            cut_index = int(0)
            if w < wp.int64(2147483647):  # 32-bit division where it fits (nearly always)
                leaf_index = int(w) / r.num_cut
                cut_index = int(w) - leaf_index * r.num_cut
            else:
                leaf_index = int(w / wp.int64(r.num_cut))
                cut_index = int(w - wp.int64(leaf_index) * wp.int64(r.num_cut))
            leaf = tree.leaf_node[r.leaf_start + leaf_index]
            front_node = r.front_node_start + leaf
            found, num_found = _leaf_vs_subtree(tree, r, leaf, tree.cut_node[r.cut_start + cut_index], candidate,
                                                candidate_count, candidate_capacity)
        slot = block_reserve(candidate_count, int(lane), _leaf_rows(tree, front_node, found, num_found))
        for m in range(num_found):
            slot = _write_rows(tree, r, front_node, found[m], slot, candidate, candidate_capacity)
        item += num_threads


class MidPhaseBVH:
    """Tree traversal over the broad phase's object pairs, from the front of leaves (see module docs).

    Args:
        bvh: the scene's :class:`~warp_ccd.bvh.SceneBVH` (refit before each launch).
        capacity: initial capacity of the candidate buffer (it grows).
        device: Warp device.

    Attributes:
        candidates: the :class:`~warp_ccd.buffers.GrowableBuffer` of candidate rows.
        num_blocks, block_dim: the traversal kernel's grid (on the CPU one block, of one thread
            that takes every item in turn unless ``wp.config.enable_cpu_blocks`` is set).
    """

    def __init__(self, bvh: SceneBVH, *, capacity: int = 4096, device=None):
        self.device = wp.get_device(device)
        self.bvh = bvh
        if bvh.max_depth + 1 > STACK_SIZE:
            raise ValueError(f"trees of depth {bvh.max_depth} need a traversal stack above {STACK_SIZE}")
        self.candidates = GrowableBuffer(wp.vec4i, capacity, self.device, "candidate triangle pairs")
        self.block_dim = block_dim_for(self.device)
        self.num_blocks = self.device.sm_count * THREADS_PER_SM // BLOCK_DIM if self.device.is_cuda else 1
        # The last frame's items and cut level (:func:`_deep_cut`); it starts as a heavy frame.
        self._load = wp.array([2**62, 0], dtype=wp.int64, device=self.device)
        self._cut_level = wp.zeros(1, dtype=wp.int32, device=self.device)
        self._items = None

    @property
    def counters(self) -> list[GrowableBuffer]:
        """The buffers with counters that :meth:`launch` resets and writes, whose counters the caller
        reads after it: the candidates."""
        return [self.candidates]

    def launch(self, scene, pairs: GrowableBuffer, *, reset_counters: bool = True) -> None:
        """Writes candidates of the object ``pairs`` of ``scene`` into :attr:`candidates`.

        Args:
            scene: the scene whose trees :attr:`bvh` holds (refit for this frame).
            pairs: the broad phase's object pairs.
            reset_counters: zero the candidates' counter first; False when the caller has.
        """
        d = self.device
        if reset_counters:
            self.candidates.reset()
        if self._items is None or self._items.shape[0] != pairs.capacity:  # scratch follows the pair capacity
            self._items = wp.zeros(pairs.capacity, dtype=wp.int64, device=d)
            self._item_end = wp.zeros(pairs.capacity, dtype=wp.int64, device=d)
            self._front_pair = wp.zeros(pairs.capacity, dtype=FrontPair, device=d)
        tree = self.bvh.tree
        wp.launch(_front_count_kernel, dim=pairs.capacity,
                  inputs=[tree, scene.instance_shape, pairs.data, pairs.count, pairs.capacity, self._load,
                          self.num_blocks * self.block_dim],
                  outputs=[self._front_pair, self._items, self._cut_level], device=d)
        wp.utils.array_scan(self._items, self._item_end, inclusive=True)
        wp.launch_tiled(_front_traverse_kernel, dim=[self.num_blocks],
                        inputs=[tree, self._front_pair, pairs.count, pairs.capacity, self._item_end,
                                self.num_blocks, self.candidates.capacity, self._cut_level],
                        outputs=[self.candidates.data, self.candidates.count, self._load],
                        block_dim=self.block_dim, device=d)


@wp.kernel
def _all_pairs_count_kernel(
    pair: wp.array[wp.vec2i],
    pair_count: wp.array[wp.int64],
    pair_capacity: int,
    instance_triangle_start: wp.array[wp.int32],
    # Outputs
    pair_work: wp.array[wp.int64],
):
    """One thread per pair slot: ``m_a * m_b`` triangle pairs, 0 past the counter."""
    k = wp.tid()
    if k >= used_count(pair_count, pair_capacity):
        pair_work[k] = wp.int64(0)
        return
    p = pair[k]
    ma = instance_triangle_start[p[0] + 1] - instance_triangle_start[p[0]]
    mb = instance_triangle_start[p[1] + 1] - instance_triangle_start[p[1]]
    pair_work[k] = wp.int64(ma) * wp.int64(mb)


@wp.kernel
def _all_pairs_write_kernel(
    pair: wp.array[wp.vec2i],
    pair_work: wp.array[wp.int64],
    pair_work_end: wp.array[wp.int64],
    instance_triangle_start: wp.array[wp.int32],
    candidate_capacity: int,
    # Outputs
    candidate: wp.array[wp.vec4i],
    candidate_count: wp.array[wp.int64],
):
    """One thread per candidate slot: binary search of its pair in the inclusive scan."""
    c = wp.tid()
    num_slots = pair_work_end.shape[0]
    total = pair_work_end[num_slots - 1]
    if c == 0:
        candidate_count[0] = total
    if wp.int64(c) >= total:
        return
    lo = upper_bound(pair_work_end, 0, num_slots, wp.int64(c))  # the pair whose block holds c
    p = pair[lo]
    local = wp.int64(c) - (pair_work_end[lo] - pair_work[lo])
    mb = wp.int64(instance_triangle_start[p[1] + 1] - instance_triangle_start[p[1]])
    candidate[c] = wp.vec4i(p[0], int(local / mb), p[1], int(local % mb))


class MidPhaseAllPairs:
    """Reference mid phase: all triangle pairs of each broad-phase pair.

    Args:
        capacity: initial capacity of the candidate buffer (it grows).
        device: Warp device.
    """

    def __init__(self, *, capacity: int = 4096, device=None):
        self.device = wp.get_device(device)
        self.candidates = GrowableBuffer(wp.vec4i, capacity, self.device, "candidate triangle pairs")
        self._work = None

    @property
    def counters(self) -> list[GrowableBuffer]:
        """The buffers with counters that :meth:`launch` writes (the candidates, their counter set
        by the write kernel), whose counters the caller reads after it."""
        return [self.candidates]

    def launch(self, scene, pairs: GrowableBuffer, *, reset_counters: bool = True) -> None:
        """Writes candidates of the object ``pairs`` of ``scene`` into :attr:`candidates` (its
        counter is set by the write kernel, so ``reset_counters`` changes nothing)."""
        d = self.device
        if self._work is None or self._work.shape[0] != pairs.capacity:
            self._work = wp.zeros(pairs.capacity, dtype=wp.int64, device=d)
            self._work_end = wp.zeros(pairs.capacity, dtype=wp.int64, device=d)
        wp.launch(_all_pairs_count_kernel, dim=pairs.capacity,
                  inputs=[pairs.data, pairs.count, pairs.capacity, scene.instance_triangle_start],
                  outputs=[self._work], device=d)
        wp.utils.array_scan(self._work, self._work_end, inclusive=True)
        wp.launch(_all_pairs_write_kernel, dim=self.candidates.capacity,
                  inputs=[pairs.data, self._work, self._work_end, scene.instance_triangle_start,
                          self.candidates.capacity],
                  outputs=[self.candidates.data, self.candidates.count], device=d)
