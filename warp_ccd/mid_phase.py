"""Mid phase: candidate triangle pairs of candidate object pairs.

Both implementations write ``(obj_a, tri_a, obj_b, tri_b)`` rows into a
:class:`~warp_ccd.buffers.GrowableBuffer` (``candidates``), for the narrow phase.

* :class:`MidPhaseBVH` (default): traversal of the two objects' trees (:mod:`warp_ccd.bvh`)
  from a front of node pairs: every leaf of the object with fewer leaves against the root of the
  other's tree. One work item per such (leaf, root) pair; each descends the other tree, depth
  first with a short stack, and the leaf pairs whose boxes overlap give their triangle pairs.
  That is the set a simultaneous descent of both trees finds (an inner box is the union of its
  children's, so two leaf boxes overlap only where all their ancestors' do), with the first tree
  opened to its leaves at once: no thread walks a big pair alone, a pair whose boxes barely
  overlap costs one box test per leaf of its smaller object, and a frame of a few hundred object
  pairs still fills the GPU. Work items are laid out by a scan of the leaf counts of the pairs
  (``wp.utils.array_scan``); a fixed number of threads splits them in contiguous runs, so that
  the launch size does not depend on the frame and the frame can be a CUDA graph.
* :class:`MidPhaseAllPairs`, the reference: every triangle of ``a`` against every triangle of
  ``b``. Count per pair, inclusive scan (``wp.utils.array_scan``), then one thread per candidate
  finds its pair by binary search over the scan. O(sum of m_a m_b) work; for small meshes only.
"""

from __future__ import annotations

import warp as wp

from .aabb import boxes_overlap
from .buffers import GrowableBuffer, reserve_slot, upper_bound, used_count
from .bvh import SceneBVH, TreeView

wp.set_module_options({"enable_backward": False})  # forward kernels only

__all__ = ["MidPhaseAllPairs", "MidPhaseBVH"]

STACK_SIZE = 32
"""Traversal stack entries per thread: a depth-first descent of a tree of depth ``D`` needs
``D + 1``; a median-split tree of fewer than 2**31 triangles has at most 32 levels."""

vec_stack = wp.types.vector(length=STACK_SIZE, dtype=wp.int32)

THREADS_PER_SM = 1024
"""Threads of the traversal per streaming multiprocessor on CUDA (half of what an H100 keeps
resident): enough to hide memory latency, few enough that each has a run of items."""


@wp.func
def _emit_leaves(
    tree: TreeView,
    a: int,
    b: int,
    sa: int,
    sb: int,
    leaf_a: int,
    leaf_b: int,
    candidate: wp.array[wp.vec4i],
    candidate_count: wp.array[wp.int64],
    candidate_capacity: int,
):
    """All triangle pairs of two overlapping leaves (shape-global node ids) become candidates."""
    ra = tree.node_triangle[leaf_a]
    rb = tree.node_triangle[leaf_b]
    base_a = tree.shape_tri_order_start[sa]
    base_b = tree.shape_tri_order_start[sb]
    for i in range(ra[0], ra[0] + ra[1]):
        for j in range(rb[0], rb[0] + rb[1]):
            slot = reserve_slot(candidate_count, candidate_capacity)
            if slot >= 0:
                candidate[slot] = wp.vec4i(a, tree.tri_order[base_a + i], b, tree.tri_order[base_b + j])


@wp.func
def _num_leaves(tree: TreeView, shape: int) -> int:
    return tree.shape_leaf_start[shape + 1] - tree.shape_leaf_start[shape]


@wp.func
def _front_side(tree: TreeView, sa: int, sb: int) -> int:
    """Which object of a pair of shapes ``(sa, sb)`` opens to its leaves: 0 (``a``) unless ``b`` has fewer."""
    if _num_leaves(tree, sb) < _num_leaves(tree, sa):
        return 1
    return 0


@wp.kernel
def _front_count_kernel(
    tree: TreeView,
    instance_shape: wp.array[wp.int32],
    pair: wp.array[wp.vec2i],
    pair_count: wp.array[wp.int64],
    pair_capacity: int,
    # Outputs
    pair_front: wp.array[wp.int64],
):
    """One thread per pair slot: the pair's work items (leaves of its smaller object), 0 past the counter."""
    k = wp.tid()
    if k >= used_count(pair_count, pair_capacity):
        pair_front[k] = wp.int64(0)
        return
    p = pair[k]
    sa = instance_shape[p[0]]
    sb = instance_shape[p[1]]
    pair_front[k] = wp.int64(wp.min(_num_leaves(tree, sa), _num_leaves(tree, sb)))


@wp.func
def _leaf_vs_tree(
    tree: TreeView,
    a: int,
    b: int,
    sa: int,
    sb: int,
    front: int,
    leaf: int,
    candidate: wp.array[wp.vec4i],
    candidate_count: wp.array[wp.int64],
    candidate_capacity: int,
):
    """Leaf ``leaf`` (shape-local) of the pair's front object (``a`` when ``front`` is 0, else
    ``b``) against the other object's tree, depth first from its root; overlapping leaf pairs
    give their triangle pairs (rows keep ``a`` first)."""
    s_front = sa
    s_other = sb
    front_obj = a
    other_obj = b
    if front == 1:
        s_front = sb
        s_other = sa
        front_obj = b
        other_obj = a
    front_node = tree.shape_node_start[s_front] + leaf
    front_slot = tree.instance_node_start[front_obj] + leaf
    lo = tree.node_lower[front_slot]
    hi = tree.node_upper[front_slot]
    other_node = tree.shape_node_start[s_other]
    other_slot = tree.instance_node_start[other_obj]
    stack = vec_stack()
    stack[0] = 0
    top = int(1)
    while top > 0:
        top -= 1
        node = stack[top]
        if boxes_overlap(lo, hi, tree.node_lower[other_slot + node], tree.node_upper[other_slot + node]):
            child = tree.node_child[other_node + node]
            if child[0] < 0:
                if front == 0:
                    _emit_leaves(tree, a, b, sa, sb, front_node, other_node + node, candidate, candidate_count,
                                 candidate_capacity)
                else:
                    _emit_leaves(tree, a, b, sa, sb, other_node + node, front_node, candidate, candidate_count,
                                 candidate_capacity)
            else:
                stack[top] = child[1]
                stack[top + 1] = child[0]
                top += 2


@wp.kernel
def _front_traverse_kernel(
    tree: TreeView,
    instance_shape: wp.array[wp.int32],
    pair: wp.array[wp.vec2i],
    pair_count: wp.array[wp.int64],
    pair_capacity: int,
    pair_front_end: wp.array[wp.int64],
    num_threads: int,
    candidate_capacity: int,
    # Outputs
    candidate: wp.array[wp.vec4i],
    candidate_count: wp.array[wp.int64],
):
    """``num_threads`` threads split the work items (inclusive scan ``pair_front_end`` of the
    pairs' leaf counts) in contiguous runs; item ``w`` of pair ``k`` is leaf ``w`` (in leaf order)
    of the pair's front object against the other's tree."""
    t = wp.tid()
    num_pairs = used_count(pair_count, pair_capacity)
    if num_pairs == 0:
        return
    total = pair_front_end[num_pairs - 1]
    run = (total + wp.int64(num_threads - 1)) / wp.int64(num_threads)
    item = wp.int64(t) * run
    end = wp.min(item + run, total)
    if item >= end:
        return
    k = upper_bound(pair_front_end, 0, num_pairs, item)  # the pair whose block holds the first item
    while item < end:
        p = pair[k]
        a = p[0]
        b = p[1]
        sa = instance_shape[a]
        sb = instance_shape[b]
        front = _front_side(tree, sa, sb)
        s_front = sa
        if front == 1:
            s_front = sb
        block_end = pair_front_end[k]
        block_start = block_end - wp.int64(_num_leaves(tree, s_front))
        leaf_base = tree.shape_leaf_start[s_front]
        stop = wp.min(block_end, end)
        while item < stop:
            leaf = tree.leaf_node[leaf_base + int(item - block_start)]
            _leaf_vs_tree(tree, a, b, sa, sb, front, leaf, candidate, candidate_count, candidate_capacity)
            item += wp.int64(1)
        k += 1


class MidPhaseBVH:
    """Tree traversal over the broad phase's object pairs, from the front of leaves (see module docs).

    Args:
        bvh: the scene's :class:`~warp_ccd.bvh.SceneBVH` (refit before each launch).
        capacity: initial capacity of the candidate buffer (it grows).
        device: Warp device.

    Attributes:
        candidates: the :class:`~warp_ccd.buffers.GrowableBuffer` of candidate rows.
        num_threads: threads of the traversal kernel (on the CPU one, which loops over all items).
    """

    def __init__(self, bvh: SceneBVH, *, capacity: int = 4096, device=None):
        self.device = wp.get_device(device)
        self.bvh = bvh
        if bvh.max_depth + 1 > STACK_SIZE:
            raise ValueError(f"trees of depth {bvh.max_depth} need a traversal stack above {STACK_SIZE}")
        self.candidates = GrowableBuffer(wp.vec4i, capacity, self.device, "candidate triangle pairs")
        self.num_threads = self.device.sm_count * THREADS_PER_SM if self.device.is_cuda else 1
        self._front = None

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
        if self._front is None or self._front.shape[0] != pairs.capacity:  # scratch follows the pair capacity
            self._front = wp.zeros(pairs.capacity, dtype=wp.int64, device=d)
            self._front_end = wp.zeros(pairs.capacity, dtype=wp.int64, device=d)
        tree = self.bvh.tree
        wp.launch(_front_count_kernel, dim=pairs.capacity,
                  inputs=[tree, scene.instance_shape, pairs.data, pairs.count, pairs.capacity],
                  outputs=[self._front], device=d)
        wp.utils.array_scan(self._front, self._front_end, inclusive=True)
        wp.launch(_front_traverse_kernel, dim=self.num_threads,
                  inputs=[tree, scene.instance_shape, pairs.data, pairs.count, pairs.capacity, self._front_end,
                          self.num_threads, self.candidates.capacity],
                  outputs=[self.candidates.data, self.candidates.count], device=d)


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
