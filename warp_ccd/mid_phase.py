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
  from the root spends above it (about two tests per level). Work items are laid out by a scan
  of the item counts of the pairs (``wp.utils.array_scan``); a fixed grid of threads takes them
  in rounds, one item per thread per round (the launch size does not depend on the frame, so
  the frame can be a CUDA graph), and each round a block reserves the rows of all its items with
  one atomic add (:func:`~warp_ccd.buffers.block_reserve`).
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

STACK_SIZE = 64
"""Traversal stack entries per thread: a depth-first descent of a subtree of depth ``D`` that
stacks both children of each node it opens holds at most ``D + 1`` pairs; a median-split tree
of fewer than 2**31 triangles has at most 32 levels."""

vec_stack = wp.types.vector(length=STACK_SIZE, dtype=wp.int32)

THREADS_PER_SM = 1024
"""Threads of the traversal per streaming multiprocessor on CUDA (half of what an H100 keeps
resident): enough to hide memory latency, few enough that each has several items at scale."""

assert THREADS_PER_SM % BLOCK_DIM == 0


PAIR_WINDOW = wp.constant(BLOCK_DIM)
"""Pairs a block of the traversal reads at once when it finds the pairs of its items: the block's
width (on CUDA)."""


@wp.func
def _block_upper_bound(values: wp.array[wp.int64], num: int, x: wp.int64, lane: int) -> int:
    """Cooperative (every thread of a block of :data:`PAIR_WINDOW` threads, the same ``x``):
    :func:`~warp_ccd.buffers.upper_bound` over ``values[:num]``, by a search that reads one
    sample per thread a step and counts the samples not above ``x`` (a block sum): each step
    narrows the range :data:`PAIR_WINDOW`-fold, so 10^5 pairs take two dependent reads where a
    binary search takes 17."""
    lo = int(0)
    hi = num
    while hi - lo > PAIR_WINDOW:
        span = wp.int64(hi - lo)
        below = int(0)
        if values[lo + int(wp.int64(lane + 1) * span / wp.int64(PAIR_WINDOW)) - 1] <= x:
            below = 1
        c = wp.tile_extract(wp.tile_sum(wp.tile(below)), 0)
        # The bound lies past sample c - 1 and at or before sample c.
        if c < PAIR_WINDOW:
            hi = lo + int(wp.int64(c + 1) * span / wp.int64(PAIR_WINDOW))
        lo = lo + int(wp.int64(c) * span / wp.int64(PAIR_WINDOW))
    below = int(0)
    if lane < hi - lo:
        if values[lo + lane] <= x:
            below = 1
    return lo + wp.tile_extract(wp.tile_sum(wp.tile(below)), 0)


@wp.func
def _num_leaves(tree: TreeView, shape: int) -> int:
    return tree.shape_leaf_start[shape + 1] - tree.shape_leaf_start[shape]


@wp.func
def _num_cut(tree: TreeView, shape: int) -> int:
    return tree.shape_cut_start[shape + 1] - tree.shape_cut_start[shape]


@wp.func
def _front_side(tree: TreeView, sa: int, sb: int) -> int:
    """Which object of a pair of shapes ``(sa, sb)`` opens to its leaves: 0 (``a``) unless ``b`` has fewer."""
    if _num_leaves(tree, sb) < _num_leaves(tree, sa):
        return 1
    return 0


@wp.func
def _pair_items(tree: TreeView, sa: int, sb: int) -> wp.int64:
    """Work items of a pair of shapes: leaves of the front object times the cut of the other."""
    if _front_side(tree, sa, sb) == 1:
        return wp.int64(_num_leaves(tree, sb)) * wp.int64(_num_cut(tree, sa))
    return wp.int64(_num_leaves(tree, sa)) * wp.int64(_num_cut(tree, sb))


@wp.kernel
def _front_count_kernel(
    tree: TreeView,
    instance_shape: wp.array[wp.int32],
    pair: wp.array[wp.vec2i],
    pair_count: wp.array[wp.int64],
    pair_capacity: int,
    # Outputs
    pair_items: wp.array[wp.int64],
):
    """One thread per pair slot: the pair's work items (:func:`_pair_items`), 0 past the counter."""
    k = wp.tid()
    if k >= used_count(pair_count, pair_capacity):
        pair_items[k] = wp.int64(0)
        return
    p = pair[k]
    pair_items[k] = _pair_items(tree, instance_shape[p[0]], instance_shape[p[1]])


@wp.func
def _write_rows(
    tree: TreeView,
    a: int,
    b: int,
    front: int,
    base_front: int,
    base_other: int,
    range_front: wp.vec2i,
    range_other: wp.vec2i,
    slot: wp.int64,
    candidate: wp.array[wp.vec4i],
    candidate_capacity: int,
) -> wp.int64:
    """Writes the triangle pairs of the front leaf and one leaf of the other object, given by their
    ``(start, count)`` in ``tri_order`` after the shapes' ``base_front``/``base_other``, from
    ``slot`` on (rows keep ``a`` first); returns the next slot."""
    for i in range(range_front[0], range_front[0] + range_front[1]):
        tri_f = tree.tri_order[base_front + i]
        for j in range(range_other[0], range_other[0] + range_other[1]):
            if slot < wp.int64(candidate_capacity):
                tri_o = tree.tri_order[base_other + j]
                if front == 0:
                    candidate[int(slot)] = wp.vec4i(a, tri_f, b, tri_o)
                else:
                    candidate[int(slot)] = wp.vec4i(a, tri_o, b, tri_f)
            slot += wp.int64(1)
    return slot


@wp.func
def _leaf_vs_subtree(
    tree: TreeView,
    a: int,
    b: int,
    front: int,
    front_slot: int,
    other_node: int,
    other_slot: int,
    sub: int,
    base_front: int,
    base_other: int,
    range_front: wp.vec2i,
    candidate: wp.array[wp.vec4i],
    candidate_count: wp.array[wp.int64],
    candidate_capacity: int,
):
    """The front leaf (bounds at ``front_slot``, triangles ``range_front``) against the subtree of
    node ``sub`` of the other object's tree (its shape's nodes from ``other_node``, its bounds from
    ``other_slot``), depth first, both children of a node a step (their reads in flight together;
    a node's triangle range is read with its children, so a leaf found needs no further read): the
    ``(start, count)`` triangle ranges of the overlapping leaves, the first
    :data:`~warp_ccd.buffers.ITEM_LIST_SIZE` returned (starts, counts, number), the rows of any
    more emitted at once (one atomic add each)."""
    lo = tree.node_lower[front_slot]
    hi = tree.node_upper[front_slot]
    found_start = vec_items()
    found_count = vec_items()
    num_found = int(0)
    stack = vec_stack()  # the children (two entries) of inner nodes whose boxes overlapped
    top = int(0)
    pending = wp.vec2i(sub, -1)  # the nodes whose boxes this step tests
    while True:
        for side in range(2):
            node = pending[side]
            if node >= 0:
                child = tree.node_child[other_node + node]
                rng = tree.node_triangle[other_node + node]
                if boxes_overlap(lo, hi, tree.node_lower[other_slot + node], tree.node_upper[other_slot + node]):
                    if child[0] >= 0:
                        stack[top] = child[0]
                        stack[top + 1] = child[1]
                        top += 2
                    elif num_found < ITEM_LIST_SIZE:
                        found_start[num_found] = rng[0]
                        found_count[num_found] = rng[1]
                        num_found += 1
                    else:
                        slot = wp.atomic_add(candidate_count, 0, wp.int64(range_front[1] * rng[1]))
                        _write_rows(tree, a, b, front, base_front, base_other, range_front, rng, slot, candidate,
                                    candidate_capacity)
        if top == 0:
            break
        top -= 2
        pending = wp.vec2i(stack[top], stack[top + 1])
    return found_start, found_count, num_found


@wp.kernel
def _front_traverse_kernel(
    tree: TreeView,
    instance_shape: wp.array[wp.int32],
    pair: wp.array[wp.vec2i],
    pair_count: wp.array[wp.int64],
    pair_capacity: int,
    pair_item_end: wp.array[wp.int64],
    num_blocks: int,
    candidate_capacity: int,
    # Outputs
    candidate: wp.array[wp.vec4i],
    candidate_count: wp.array[wp.int64],
):
    """``num_blocks`` blocks of threads take the work items (inclusive scan ``pair_item_end`` of the
    pairs' item counts) in rounds, one item per thread per round; item ``w`` of pair ``k`` is leaf
    ``w / C`` (in leaf order) of the pair's front object against cut subtree ``w % C`` of the
    other's ``C``. Each round, a block reserves all its threads' rows with one atomic add."""
    block, lane = wp.tid()
    width = wp.block_dim()
    num_threads = wp.int64(num_blocks * width)
    t = wp.int64(block * width + lane)
    num_pairs = used_count(pair_count, pair_capacity)
    if num_pairs == 0:
        return  # the whole grid returns: no block is left waiting in block_reserve
    total = pair_item_end[num_pairs - 1]
    if wp.int64(block * width) >= total:
        return  # the whole block: its items, t + r * num_threads, are all past the last
    rounds = (total + num_threads - wp.int64(1)) / num_threads  # the same in every thread
    k = int(0)
    item = t
    for _round in range(int(rounds)):
        found_start = vec_items()
        found_count = vec_items()
        num_found = int(0)
        a = int(0)
        b = int(0)
        front = int(0)
        base_front = int(0)
        base_other = int(0)
        range_front = wp.vec2i()
        if width == PAIR_WINDOW:
            # The pairs of the block's items this round: the first by a block-wide search, the
            # others among the next PAIR_WINDOW (each pair has an item at least), read into
            # shared memory at once and searched there by each thread.
            first = _block_upper_bound(pair_item_end, num_pairs, item - wp.int64(lane), int(lane))
            window = wp.tile_load(pair_item_end, shape=(PAIR_WINDOW,), offset=(first,), storage="shared")
            if item < total:
                lo = int(0)
                hi = wp.min(PAIR_WINDOW, num_pairs - first)
                while lo < hi:
                    mid = (lo + hi) // 2
                    if window[mid] > item:
                        hi = mid
                    else:
                        lo = mid + 1
                k = first + lo
                if lo == PAIR_WINDOW:  # not in the window: only if some pair had no items
                    k = upper_bound(pair_item_end, k, num_pairs, item)
        elif item < total:
            k = upper_bound(pair_item_end, k, num_pairs, item)  # items only move forward: so does k
        if item < total:
            p = pair[k]
            a = p[0]
            b = p[1]
            sa = instance_shape[a]
            sb = instance_shape[b]
            front = _front_side(tree, sa, sb)
            s_front = sa
            s_other = sb
            front_obj = a
            other_obj = b
            if front == 1:
                s_front = sb
                s_other = sa
                front_obj = b
                other_obj = a
            num_cut = wp.int64(_num_cut(tree, s_other))
            w = item - (pair_item_end[k] - wp.int64(_num_leaves(tree, s_front)) * num_cut)
            leaf = tree.leaf_node[tree.shape_leaf_start[s_front] + int(w / num_cut)]
            sub = tree.cut_node[tree.shape_cut_start[s_other] + int(w % num_cut)]
            range_front = tree.node_triangle[tree.shape_node_start[s_front] + leaf]
            base_front = tree.shape_tri_order_start[s_front]
            base_other = tree.shape_tri_order_start[s_other]
            found_start, found_count, num_found = _leaf_vs_subtree(
                tree, a, b, front, tree.instance_node_start[front_obj] + leaf, tree.shape_node_start[s_other],
                tree.instance_node_start[other_obj], sub, base_front, base_other, range_front, candidate,
                candidate_count, candidate_capacity)
        rows = int(0)
        for m in range(num_found):
            rows += found_count[m]
        slot = block_reserve(candidate_count, int(lane), range_front[1] * rows)
        for m in range(num_found):
            slot = _write_rows(tree, a, b, front, base_front, base_other, range_front,
                               wp.vec2i(found_start[m], found_count[m]), slot, candidate, candidate_capacity)
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
        if 2 * (bvh.max_depth + 1) > STACK_SIZE:
            raise ValueError(f"trees of depth {bvh.max_depth} need a traversal stack above {STACK_SIZE}")
        self.candidates = GrowableBuffer(wp.vec4i, capacity, self.device, "candidate triangle pairs")
        self.block_dim = block_dim_for(self.device)
        self.num_blocks = self.device.sm_count * THREADS_PER_SM // BLOCK_DIM if self.device.is_cuda else 1
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
        tree = self.bvh.tree
        wp.launch(_front_count_kernel, dim=pairs.capacity,
                  inputs=[tree, scene.instance_shape, pairs.data, pairs.count, pairs.capacity],
                  outputs=[self._items], device=d)
        wp.utils.array_scan(self._items, self._item_end, inclusive=True)
        wp.launch_tiled(_front_traverse_kernel, dim=[self.num_blocks],
                        inputs=[tree, scene.instance_shape, pairs.data, pairs.count, pairs.capacity, self._item_end,
                                self.num_blocks, self.candidates.capacity],
                        outputs=[self.candidates.data, self.candidates.count], block_dim=self.block_dim, device=d)


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
