"""Mid phase: candidate triangle pairs of candidate object pairs.

Both implementations write ``(obj_a, tri_a, obj_b, tri_b)`` rows into a
:class:`~warp_ccd.buffers.GrowableBuffer` (``candidates``), for the narrow phase.

* :class:`MidPhaseBVH` (default): tree-vs-tree traversal of the two objects' trees
  (:mod:`warp_ccd.bvh`) with a bounded stack, one thread per object pair, or on CUDA one thread
  per work item after a breadth-first split of each pair into about 8 node pairs. When two nodes' boxes
  overlap, the one with the smaller volume is kept and the bigger one is opened (the smaller one
  when the bigger is a leaf); two overlapping leaves give their triangle pairs. Work is about
  proportional to the number of overlapping node pairs.
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

STACK_SIZE = 64
"""Traversal stack entries per thread: enough for two trees of depth 31 (2**31 triangles each)."""

vec_stack = wp.types.vector(length=STACK_SIZE, dtype=wp.int32)

VISIT_APART = wp.constant(0)
"""A node pair whose boxes are apart: nothing below it."""
VISIT_LEAVES = wp.constant(1)
"""Two overlapping leaves: their triangle pairs are candidates."""
VISIT_OPEN = wp.constant(2)
"""Overlapping boxes, one of them inner: its two child pairs are visited next."""


@wp.func
def _volume(lo: wp.vec3, hi: wp.vec3) -> float:
    d = hi - lo
    return d[0] * d[1] * d[2]


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
def _step(
    tree: TreeView,
    shape_a: int,
    shape_b: int,
    slot_a: int,
    slot_b: int,
    na: int,
    nb: int,
):
    """Visits node pair ``(na, nb)``: returns ``(kind, n1a, n1b, n2a, n2b)`` with kind
    :data:`VISIT_APART`, :data:`VISIT_LEAVES` (emit) or :data:`VISIT_OPEN` (push the two child pairs
    ``(n1a, n1b)``, ``(n2a, n2b)``). The bigger box (by volume) is opened, the smaller one when the
    bigger is a leaf."""
    lo_a = tree.node_lower[slot_a + na]
    hi_a = tree.node_upper[slot_a + na]
    lo_b = tree.node_lower[slot_b + nb]
    hi_b = tree.node_upper[slot_b + nb]
    if not boxes_overlap(lo_a, hi_a, lo_b, hi_b):
        return VISIT_APART, na, nb, na, nb
    ca = tree.node_child[shape_a + na]
    cb = tree.node_child[shape_b + nb]
    if ca[0] < 0 and cb[0] < 0:
        return VISIT_LEAVES, na, nb, na, nb
    if cb[0] < 0 or (ca[0] >= 0 and _volume(lo_a, hi_a) >= _volume(lo_b, hi_b)):
        return VISIT_OPEN, ca[0], nb, ca[1], nb
    return VISIT_OPEN, na, cb[0], na, cb[1]


@wp.func
def _pair_layout(tree: TreeView, instance_shape: wp.array[wp.int32], a: int, b: int):
    """Shapes of objects ``a``, ``b``, their first nodes in the topology, and their first node
    slots in the per-instance bounds."""
    sa = instance_shape[a]
    sb = instance_shape[b]
    return (sa, sb, tree.shape_node_start[sa], tree.shape_node_start[sb],
            tree.instance_node_start[a], tree.instance_node_start[b])


@wp.func
def _descend(
    tree: TreeView,
    instance_shape: wp.array[wp.int32],
    item: wp.vec4i,
    candidate: wp.array[wp.vec4i],
    candidate_count: wp.array[wp.int64],
    candidate_capacity: int,
):
    """Depth-first simultaneous descent from node pair ``(item[2], item[3])`` of objects
    ``(item[0], item[1])``, with a bounded stack; leaf pairs become candidates."""
    a = item[0]
    b = item[1]
    sa, sb, shape_a, shape_b, slot_a, slot_b = _pair_layout(tree, instance_shape, a, b)
    stack_a = vec_stack()
    stack_b = vec_stack()
    stack_a[0] = item[2]
    stack_b[0] = item[3]
    top = int(1)
    while top > 0:
        top -= 1
        kind, n1a, n1b, n2a, n2b = _step(tree, shape_a, shape_b, slot_a, slot_b, stack_a[top], stack_b[top])
        if kind == VISIT_LEAVES:
            _emit_leaves(tree, a, b, sa, sb, shape_a + n1a, shape_b + n1b, candidate, candidate_count,
                         candidate_capacity)
        elif kind == VISIT_OPEN:
            stack_a[top] = n1a
            stack_b[top] = n1b
            stack_a[top + 1] = n2a
            stack_b[top + 1] = n2b
            top += 2


@wp.kernel
def _traverse_kernel(
    tree: TreeView,
    instance_shape: wp.array[wp.int32],
    pair: wp.array[wp.vec2i],
    pair_count: wp.array[wp.int64],
    pair_capacity: int,
    split: int,
    candidate_capacity: int,
    work_capacity: int,
    # Outputs
    candidate: wp.array[wp.vec4i],
    candidate_count: wp.array[wp.int64],
    work: wp.array[wp.vec4i],
    work_count: wp.array[wp.int64],
):
    """One thread per object pair. With ``split <= 1`` the whole traversal. Otherwise a
    breadth-first expansion from the roots until ``split`` overlapping node pairs wait (or none),
    which are written as work items ``(a, b, node_a, node_b)`` for :func:`_traverse_work_kernel`:
    big trees then spread over many threads, in pieces of about equal depth."""
    k = wp.tid()
    if k >= used_count(pair_count, pair_capacity):
        return
    p = pair[k]
    a = p[0]
    b = p[1]
    if split <= 1:
        _descend(tree, instance_shape, wp.vec4i(a, b, 0, 0), candidate, candidate_count, candidate_capacity)
        return
    sa, sb, shape_a, shape_b, slot_a, slot_b = _pair_layout(tree, instance_shape, a, b)
    queue_a = vec_stack()
    queue_b = vec_stack()
    head = int(0)
    tail = int(1)  # queue_a/b[0] = root pair (0, 0)
    while head < tail and tail - head < split and tail + 2 <= STACK_SIZE:
        kind, n1a, n1b, n2a, n2b = _step(tree, shape_a, shape_b, slot_a, slot_b, queue_a[head], queue_b[head])
        head += 1
        if kind == VISIT_LEAVES:
            _emit_leaves(tree, a, b, sa, sb, shape_a + n1a, shape_b + n1b, candidate, candidate_count,
                         candidate_capacity)
        elif kind == VISIT_OPEN:
            queue_a[tail] = n1a
            queue_b[tail] = n1b
            queue_a[tail + 1] = n2a
            queue_b[tail + 1] = n2b
            tail += 2
    for q in range(head, tail):
        slot = reserve_slot(work_count, work_capacity)
        if slot >= 0:
            work[slot] = wp.vec4i(a, b, queue_a[q], queue_b[q])


@wp.kernel
def _traverse_work_kernel(
    tree: TreeView,
    instance_shape: wp.array[wp.int32],
    work: wp.array[wp.vec4i],
    work_count: wp.array[wp.int64],
    work_capacity: int,
    candidate_capacity: int,
    # Outputs
    candidate: wp.array[wp.vec4i],
    candidate_count: wp.array[wp.int64],
):
    """One thread per work item ``(a, b, node_a, node_b)``: depth-first descent from there."""
    k = wp.tid()
    if k >= used_count(work_count, work_capacity):
        return
    _descend(tree, instance_shape, work[k], candidate, candidate_count, candidate_capacity)


class MidPhaseBVH:
    """Tree-vs-tree traversal over the broad phase's object pairs.

    Args:
        bvh: the scene's :class:`~warp_ccd.bvh.SceneBVH` (refit before each launch).
        capacity: initial capacity of the candidate buffer (it grows).
        split: work items per object pair: 0 or 1 traverses each pair in one thread; ``k > 1``
            first expands each pair breadth-first into about ``k`` node pairs, each traversed by
            its own thread (balances big meshes against small ones). Default: 8 on CUDA, 0 on CPU,
            where there is one thread anyway.
        device: Warp device.
    """

    def __init__(self, bvh: SceneBVH, *, capacity: int = 4096, split: int | None = None, device=None):
        self.device = wp.get_device(device)
        self.bvh = bvh
        if 2 * bvh.max_depth + 2 > STACK_SIZE:
            raise ValueError(f"trees of depth {bvh.max_depth} need a traversal stack above {STACK_SIZE}")
        self.split = (8 if self.device.is_cuda else 0) if split is None else int(split)
        if not 0 <= self.split <= STACK_SIZE // 2:
            raise ValueError(f"traversal split must lie in [0, {STACK_SIZE // 2}], got {split}")
        self.candidates = GrowableBuffer(wp.vec4i, capacity, self.device, "candidate triangle pairs")
        self.work = GrowableBuffer(wp.vec4i, max(1024, capacity // 4), self.device, "traversal work items")

    @property
    def counters(self) -> list[GrowableBuffer]:
        """The buffers with counters that :meth:`launch` resets and writes, whose counters the caller
        reads after it: the candidates, and the traversal's work items when it splits."""
        return [self.candidates, self.work] if self.split > 1 else [self.candidates]

    def launch(self, scene, pairs: GrowableBuffer) -> None:
        """Writes candidates of the object ``pairs`` of ``scene`` into :attr:`candidates` (reset first)."""
        for buffer in self.counters:
            buffer.reset()
        wp.launch(
            _traverse_kernel,
            dim=pairs.capacity,
            inputs=[self.bvh.tree, scene.instance_shape, pairs.data, pairs.count, pairs.capacity, self.split,
                    self.candidates.capacity, self.work.capacity],
            outputs=[self.candidates.data, self.candidates.count, self.work.data, self.work.count],
            device=self.device,
        )
        if self.split > 1:
            wp.launch(
                _traverse_work_kernel,
                dim=self.work.capacity,
                inputs=[self.bvh.tree, scene.instance_shape, self.work.data, self.work.count, self.work.capacity,
                        self.candidates.capacity],
                outputs=[self.candidates.data, self.candidates.count],
                device=self.device,
            )


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

    def launch(self, scene, pairs: GrowableBuffer) -> None:
        """Writes candidates of the object ``pairs`` of ``scene`` into :attr:`candidates`."""
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
