"""Mid phase: candidate triangle pairs of candidate object pairs.

Both implementations write ``(obj_a, tri_a, obj_b, tri_b)`` rows into a
:class:`~warp_ccd.buffers.GrowableBuffer` (``candidates``), for the narrow phase.

* :class:`MidPhaseBVH` (default): tree-vs-tree traversal of the two objects' trees
  (:mod:`warp_ccd.bvh`), one thread per object pair with a bounded stack. When two nodes' boxes
  overlap, the one with the smaller volume is kept and the bigger one is opened (the smaller one
  when the bigger is a leaf); two overlapping leaves give their triangle pairs. Work is about
  proportional to the number of overlapping node pairs.
* :class:`MidPhaseAllPairs`, the reference: every triangle of ``a`` against every triangle of
  ``b``. Count per pair, inclusive scan (``wp.utils.array_scan``), then one thread per candidate
  finds its pair by binary search over the scan. O(sum of m_a m_b) work; for small meshes only.
"""

from __future__ import annotations

import warp as wp

from .broad_phase import boxes_overlap
from .buffers import GrowableBuffer, reserve_slot, used_count
from .bvh import SceneBVH, TreeView

wp.set_module_options({"enable_backward": False})  # forward kernels only

__all__ = ["MidPhaseAllPairs", "MidPhaseBVH", "all_pairs_count_kernel", "all_pairs_write_kernel", "traverse_kernel"]

STACK_SIZE = 64
"""Traversal stack entries per thread: enough for two trees of depth 31 (2**31 triangles each)."""

vec_stack = wp.types.vector(length=STACK_SIZE, dtype=wp.int32)


@wp.func
def _volume(lo: wp.vec3, hi: wp.vec3) -> float:
    d = hi - lo
    return d[0] * d[1] * d[2]


@wp.kernel
def traverse_kernel(
    tree: TreeView,
    instance_shape: wp.array[wp.int32],
    pair: wp.array[wp.vec2i],
    pair_count: wp.array[wp.int64],
    pair_capacity: int,
    candidate_capacity: int,
    # Outputs
    candidate: wp.array[wp.vec4i],
    candidate_count: wp.array[wp.int64],
):
    """One thread per object pair: simultaneous descent of both trees."""
    k = wp.tid()
    if k >= used_count(pair_count, pair_capacity):
        return
    p = pair[k]
    a = p[0]
    b = p[1]
    sa = instance_shape[a]
    sb = instance_shape[b]
    shape_a = tree.shape_node_start[sa]
    shape_b = tree.shape_node_start[sb]
    slot_a = tree.instance_node_start[a]
    slot_b = tree.instance_node_start[b]
    tri_a = tree.shape_tri_order_start[sa]
    tri_b = tree.shape_tri_order_start[sb]
    stack_a = vec_stack()
    stack_b = vec_stack()
    stack_a[0] = 0
    stack_b[0] = 0
    top = int(1)
    while top > 0:
        top -= 1
        na = stack_a[top]
        nb = stack_b[top]
        lo_a = tree.node_lower[slot_a + na]
        hi_a = tree.node_upper[slot_a + na]
        lo_b = tree.node_lower[slot_b + nb]
        hi_b = tree.node_upper[slot_b + nb]
        if not boxes_overlap(lo_a, hi_a, lo_b, hi_b):
            continue
        ca = tree.node_child[shape_a + na]
        cb = tree.node_child[shape_b + nb]
        if ca[0] < 0 and cb[0] < 0:
            ra = tree.node_triangle[shape_a + na]
            rb = tree.node_triangle[shape_b + nb]
            for i in range(ra[0], ra[0] + ra[1]):
                for j in range(rb[0], rb[0] + rb[1]):
                    slot = reserve_slot(candidate_count, candidate_capacity)
                    if slot >= 0:
                        candidate[slot] = wp.vec4i(a, tree.tri_order[tri_a + i], b, tree.tri_order[tri_b + j])
            continue
        open_a = cb[0] < 0 or (ca[0] >= 0 and _volume(lo_a, hi_a) >= _volume(lo_b, hi_b))
        if open_a:
            stack_a[top] = ca[0]
            stack_b[top] = nb
            stack_a[top + 1] = ca[1]
            stack_b[top + 1] = nb
        else:
            stack_a[top] = na
            stack_b[top] = cb[0]
            stack_a[top + 1] = na
            stack_b[top + 1] = cb[1]
        top += 2


class MidPhaseBVH:
    """Tree-vs-tree traversal over the broad phase's object pairs.

    Args:
        bvh: the scene's :class:`~warp_ccd.bvh.SceneBVH` (refit before each launch).
        capacity: initial capacity of the candidate buffer (it grows).
        device: Warp device.
    """

    def __init__(self, bvh: SceneBVH, *, capacity: int = 4096, device=None):
        self.device = wp.get_device(device)
        self.bvh = bvh
        if 2 * bvh.max_depth + 2 > STACK_SIZE:
            raise ValueError(f"trees of depth {bvh.max_depth} need a traversal stack above {STACK_SIZE}")
        self.candidates = GrowableBuffer(wp.vec4i, capacity, self.device, "candidate triangle pairs")

    def launch(self, scene, pairs: GrowableBuffer) -> None:
        """Writes candidates of the object ``pairs`` of ``scene`` into :attr:`candidates`."""
        wp.launch(
            traverse_kernel,
            dim=pairs.capacity,
            inputs=[self.bvh.tree, scene.instance_shape, pairs.data, pairs.count, pairs.capacity,
                    self.candidates.capacity],
            outputs=[self.candidates.data, self.candidates.count],
            device=self.device,
        )


@wp.kernel
def all_pairs_count_kernel(
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
def all_pairs_write_kernel(
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
    lo = int(0)
    hi = num_slots - 1
    while lo < hi:
        mid = (lo + hi) / 2
        if pair_work_end[mid] > wp.int64(c):
            hi = mid
        else:
            lo = mid + 1
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

    def launch(self, scene, pairs: GrowableBuffer) -> None:
        """Writes candidates of the object ``pairs`` of ``scene`` into :attr:`candidates`."""
        d = self.device
        if self._work is None or self._work.shape[0] != pairs.capacity:
            self._work = wp.zeros(pairs.capacity, dtype=wp.int64, device=d)
            self._work_end = wp.zeros(pairs.capacity, dtype=wp.int64, device=d)
        wp.launch(all_pairs_count_kernel, dim=pairs.capacity,
                  inputs=[pairs.data, pairs.count, pairs.capacity, scene.instance_triangle_start],
                  outputs=[self._work], device=d)
        wp.utils.array_scan(self._work, self._work_end, inclusive=True)
        wp.launch(all_pairs_write_kernel, dim=self.candidates.capacity,
                  inputs=[pairs.data, self._work, self._work_end, scene.instance_triangle_start,
                          self.candidates.capacity],
                  outputs=[self.candidates.data, self.candidates.count], device=d)
