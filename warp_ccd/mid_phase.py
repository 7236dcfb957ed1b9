"""Mid phase: candidate triangle pairs of candidate object pairs.

Both implementations write ``(obj_a, tri_a, obj_b, tri_b)`` rows into a
:class:`~warp_ccd.buffers.GrowableBuffer` (``candidates``), for the narrow phase.

* :class:`MidPhaseBVH` (default): traversal of the two objects' trees (:mod:`warp_ccd.bvh`)
  from a front of node pairs: every leaf of the object with fewer leaves against every subtree
  of the other's cut (its nodes at level ``cut_depth``, and the leaves above; at most 8 subtrees
  by default). One work item per such (leaf, subtree) pair; each descends its subtree, depth
  first with a short stack, gathers the leaves whose boxes overlap its own and reserves their
  triangle pairs with one atomic add. That is the set a simultaneous descent of both trees
  finds (an inner box is the union of its children's, so two leaf boxes overlap only where all
  their ancestors' do), with the first tree opened to its leaves and the second to its cut at
  once: no thread walks a big pair alone, the longest descent is a subtree's (not a whole
  tree's: at 1,000 polyhedra the slowest of the root-first items visited 71 nodes), and a frame
  of a hundred object pairs still fills the GPU. Testing the cut's boxes costs what a descent
  from the root spends above it (about two tests per level). Work items are laid out by a scan
  of the item counts of the pairs (``wp.utils.array_scan``); a fixed number of threads splits
  them in contiguous runs, so that the launch size does not depend on the frame and the frame
  can be a CUDA graph.
* :class:`MidPhaseAllPairs`, the reference: every triangle of ``a`` against every triangle of
  ``b``. Count per pair, inclusive scan (``wp.utils.array_scan``), then one thread per candidate
  finds its pair by binary search over the scan. O(sum of m_a m_b) work; for small meshes only.
"""

from __future__ import annotations

import warp as wp

from .aabb import boxes_overlap
from .buffers import GrowableBuffer, upper_bound, used_count
from .bvh import SceneBVH, TreeView

wp.set_module_options({"enable_backward": False})  # forward kernels only

__all__ = ["MidPhaseAllPairs", "MidPhaseBVH"]

STACK_SIZE = 32
"""Traversal stack entries per thread: a depth-first descent of a tree of depth ``D`` needs
``D + 1``; a median-split tree of fewer than 2**31 triangles has at most 32 levels."""

vec_stack = wp.types.vector(length=STACK_SIZE, dtype=wp.int32)

FOUND_SIZE = wp.constant(16)
"""Overlapping leaves a work item gathers before it reserves their candidate rows with one
atomic add (a cut subtree of a small tree has fewer leaves: usually one atomic per item)."""

vec_found = wp.types.vector(length=FOUND_SIZE, dtype=wp.int32)

THREADS_PER_SM = 1024
"""Threads of the traversal per streaming multiprocessor on CUDA (half of what an H100 keeps
resident): enough to hide memory latency, few enough that each has a run of items."""


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
def _emit_found(
    tree: TreeView,
    a: int,
    b: int,
    sa: int,
    sb: int,
    front: int,
    front_node: int,
    found: vec_found,
    num_found: int,
    candidate: wp.array[wp.vec4i],
    candidate_count: wp.array[wp.int64],
    candidate_capacity: int,
):
    """The triangle pairs of the front leaf ``front_node`` with each of the ``num_found`` leaves
    of the other object (shape-global node ids): one atomic reserves them all, rows keep ``a``
    first."""
    rf = tree.node_triangle[front_node]
    total = int(0)
    for m in range(num_found):
        total += rf[1] * tree.node_triangle[found[m]][1]
    slot = wp.atomic_add(candidate_count, 0, wp.int64(total))
    s_front = sa
    s_other = sb
    if front == 1:
        s_front = sb
        s_other = sa
    base_f = tree.shape_tri_order_start[s_front]
    base_o = tree.shape_tri_order_start[s_other]
    for m in range(num_found):
        ro = tree.node_triangle[found[m]]
        for i in range(rf[0], rf[0] + rf[1]):
            tri_f = tree.tri_order[base_f + i]
            for j in range(ro[0], ro[0] + ro[1]):
                if slot < wp.int64(candidate_capacity):
                    tri_o = tree.tri_order[base_o + j]
                    if front == 0:
                        candidate[int(slot)] = wp.vec4i(a, tri_f, b, tri_o)
                    else:
                        candidate[int(slot)] = wp.vec4i(a, tri_o, b, tri_f)
                slot += wp.int64(1)


@wp.func
def _leaf_vs_subtree(
    tree: TreeView,
    a: int,
    b: int,
    sa: int,
    sb: int,
    front: int,
    leaf: int,
    sub: int,
    candidate: wp.array[wp.vec4i],
    candidate_count: wp.array[wp.int64],
    candidate_capacity: int,
):
    """Leaf ``leaf`` (shape-local) of the pair's front object (``a`` when ``front`` is 0, else
    ``b``) against the subtree of node ``sub`` of the other object's tree, depth first; the
    overlapping leaves are gathered and their triangle pairs emitted :data:`FOUND_SIZE` at a time."""
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
    found = vec_found()
    num_found = int(0)
    stack = vec_stack()
    stack[0] = sub
    top = int(1)
    while top > 0:
        top -= 1
        node = stack[top]
        if boxes_overlap(lo, hi, tree.node_lower[other_slot + node], tree.node_upper[other_slot + node]):
            child = tree.node_child[other_node + node]
            if child[0] < 0:
                if num_found == FOUND_SIZE:
                    _emit_found(tree, a, b, sa, sb, front, front_node, found, num_found, candidate, candidate_count,
                                candidate_capacity)
                    num_found = 0
                found[num_found] = other_node + node
                num_found += 1
            else:
                stack[top] = child[1]
                stack[top + 1] = child[0]
                top += 2
    if num_found > 0:
        _emit_found(tree, a, b, sa, sb, front, front_node, found, num_found, candidate, candidate_count,
                    candidate_capacity)


@wp.kernel
def _front_traverse_kernel(
    tree: TreeView,
    instance_shape: wp.array[wp.int32],
    pair: wp.array[wp.vec2i],
    pair_count: wp.array[wp.int64],
    pair_capacity: int,
    pair_item_end: wp.array[wp.int64],
    num_threads: int,
    candidate_capacity: int,
    # Outputs
    candidate: wp.array[wp.vec4i],
    candidate_count: wp.array[wp.int64],
):
    """``num_threads`` threads split the work items (inclusive scan ``pair_item_end`` of the
    pairs' item counts) in contiguous runs; item ``w`` of pair ``k`` is leaf ``w / C`` (in leaf
    order) of the pair's front object against cut subtree ``w % C`` of the other's ``C``."""
    t = wp.tid()
    num_pairs = used_count(pair_count, pair_capacity)
    if num_pairs == 0:
        return
    total = pair_item_end[num_pairs - 1]
    run = (total + wp.int64(num_threads - 1)) / wp.int64(num_threads)
    item = wp.int64(t) * run
    end = wp.min(item + run, total)
    if item >= end:
        return
    k = upper_bound(pair_item_end, 0, num_pairs, item)  # the pair whose block holds the first item
    while item < end:
        p = pair[k]
        a = p[0]
        b = p[1]
        sa = instance_shape[a]
        sb = instance_shape[b]
        front = _front_side(tree, sa, sb)
        s_front = sa
        s_other = sb
        if front == 1:
            s_front = sb
            s_other = sa
        num_cut = wp.int64(_num_cut(tree, s_other))
        block_end = pair_item_end[k]
        block_start = block_end - wp.int64(_num_leaves(tree, s_front)) * num_cut
        leaf_base = tree.shape_leaf_start[s_front]
        cut_base = tree.shape_cut_start[s_other]
        stop = wp.min(block_end, end)
        while item < stop:
            w = item - block_start
            leaf = tree.leaf_node[leaf_base + int(w / num_cut)]
            sub = tree.cut_node[cut_base + int(w % num_cut)]
            _leaf_vs_subtree(tree, a, b, sa, sb, front, leaf, sub, candidate, candidate_count, candidate_capacity)
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
        wp.launch(_front_traverse_kernel, dim=self.num_threads,
                  inputs=[tree, scene.instance_shape, pairs.data, pairs.count, pairs.capacity, self._item_end,
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
