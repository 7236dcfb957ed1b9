"""The reference mid phase: every triangle pair of each object pair (:class:`MidPhaseAllPairs`).

Count per pair, inclusive scan (``wp.utils.array_scan``), then one thread per candidate finds its
pair by binary search over the scan. O(sum of m_a m_b) work; for small meshes only, and as the
oracle of the tree traversal (:class:`~warp_ccd._src.midphase.bvh.MidPhaseBVH`), behind the same
interface (:class:`~warp_ccd._src.midphase.bvh.MidPhase`).
"""

from __future__ import annotations

import warp as wp

from ..runtime.aliases import DeviceLike
from ..runtime.buffers import GrowableBuffer, upper_bound, used_count
from ..scene.scene import Scene
from .bvh import MidPhase

wp.set_module_options({"enable_backward": False})  # forward kernels only

__all__ = ["MidPhaseAllPairs"]


@wp.kernel
def _all_pairs_count_kernel(
    pair: wp.array[wp.vec2i],
    pair_count: wp.array[wp.int64],
    pair_capacity: int,
    object_triangle_start: wp.array[wp.int32],
    # Outputs
    pair_work: wp.array[wp.int64],
):
    """One thread per pair slot: ``m_a * m_b`` triangle pairs, 0 past the counter."""
    k = wp.tid()
    if k >= used_count(pair_count, pair_capacity):
        pair_work[k] = wp.int64(0)
        return
    p = pair[k]
    ma = object_triangle_start[p[0] + 1] - object_triangle_start[p[0]]
    mb = object_triangle_start[p[1] + 1] - object_triangle_start[p[1]]
    pair_work[k] = wp.int64(ma) * wp.int64(mb)


@wp.kernel
def _all_pairs_write_kernel(
    pair: wp.array[wp.vec2i],
    pair_work: wp.array[wp.int64],
    pair_work_end: wp.array[wp.int64],
    object_triangle_start: wp.array[wp.int32],
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
    mb = wp.int64(object_triangle_start[p[1] + 1] - object_triangle_start[p[1]])
    candidate[c] = wp.vec4i(p[0], int(local / mb), p[1], int(local % mb))


class MidPhaseAllPairs(MidPhase):
    """Reference mid phase: all triangle pairs of each broad-phase pair.

    Args:
        capacity: initial capacity of the candidate buffer (it grows).
        device: Warp device.
    """

    def __init__(self, *, capacity: int = 4096, device: DeviceLike = None) -> None:
        super().__init__(capacity=capacity, device=device)
        self._work = None

    @property
    def counters(self) -> list[GrowableBuffer]:
        """The buffers with counters that :meth:`launch` writes (the candidates, their counter set
        by the write kernel), whose counters the caller reads after it."""
        return [self.candidates]

    def launch(self, scene: Scene, pairs: GrowableBuffer, *, reset_counters: bool = True,
               world_vertex_start: wp.array | None = None) -> None:
        """Writes candidates of the object ``pairs`` of ``scene`` into :attr:`candidates` (its
        counter is set by the write kernel, so ``reset_counters`` changes nothing, nor ``world_vertex_start``)."""
        d = self.device
        if self._work is None or self._work.shape[0] != pairs.capacity:
            self._work = wp.zeros(pairs.capacity, dtype=wp.int64, device=d)
            self._work_end = wp.zeros(pairs.capacity, dtype=wp.int64, device=d)
        wp.launch(_all_pairs_count_kernel, dim=pairs.capacity,
                  inputs=[pairs.data, pairs.count, pairs.capacity, scene.object_triangle_start],
                  outputs=[self._work], device=d)
        wp.utils.array_scan(self._work, self._work_end, inclusive=True)
        wp.launch(_all_pairs_write_kernel, dim=self.candidates.capacity,
                  inputs=[pairs.data, self._work, self._work_end, scene.object_triangle_start,
                          self.candidates.capacity],
                  outputs=[self.candidates.data, self.candidates.count], device=d)
