"""Mid phase: candidate triangle pairs of candidate object pairs.

:class:`MidPhaseAllPairs` is the reference: every triangle of ``a`` against every triangle of
``b`` for each broad-phase pair ``(a, b)``. Count per pair, exclusive scan
(``wp.utils.array_scan``), then one thread per candidate finds its pair by binary search over the
scan and writes ``(obj_a, tri_a, obj_b, tri_b)``. O(sum of m_a m_b) work; for small meshes only.
"""

from __future__ import annotations

import warp as wp

from .buffers import COUNT_LIMIT, GrowableBuffer

__all__ = ["MidPhaseAllPairs", "all_pairs_count_kernel", "all_pairs_write_kernel"]


@wp.kernel
def all_pairs_count_kernel(
    pair: wp.array[wp.vec2i],
    pair_count: wp.array[wp.int32],
    pair_capacity: int,
    instance_triangle_start: wp.array[wp.int32],
    # Outputs
    pair_work: wp.array[wp.int64],
):
    """One thread per pair slot: ``m_a * m_b`` triangle pairs, 0 past the counter."""
    k = wp.tid()
    if k >= wp.min(pair_count[0], pair_capacity):
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
    count_limit: wp.int64,
    # Outputs
    candidate: wp.array[wp.vec4i],
    candidate_count: wp.array[wp.int32],
):
    """One thread per candidate slot: binary search of its pair in the inclusive scan."""
    c = wp.tid()
    num_slots = pair_work_end.shape[0]
    total = pair_work_end[num_slots - 1]
    if c == 0:
        candidate_count[0] = int(wp.min(total, count_limit))
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
                          self.candidates.capacity, wp.int64(COUNT_LIMIT)],
                  outputs=[self.candidates.data, self.candidates.count], device=d)
