"""What every narrow phase reads and writes: lists of triangle pairs, and the steps its kernels share.

A list of triangle pairs is a device array of rows ``(obj_a, tri_a, obj_b, tri_b)`` with its capacity and
counter (:class:`~warp_ccd._src.runtime.buffers.GrowableBuffer`), passed to a kernel as one
:class:`PairList`: the mid phase's candidates, a phase's hits, and the lists a phase keeps between its
passes (the discrete test's touching and rare rows). Every narrow kernel starts the same way (a row of
its list, the row's two triangles in the world: :func:`pair_triangles`) and ends the same way (a hit
appended, its two objects flagged: :func:`append_hit`).
"""

from typing import Any

import warp as wp

from ..runtime.buffers import GrowableBuffer, reserve_slot, used_count
from ..scene.scene import MeshTopology, mesh_triangle

__all__ = ["PairList", "append_hit", "append_pair", "pair_count", "pair_list", "pair_triangles"]


@wp.struct
class PairList:
    """A device list of triangle pairs: ``row[:capacity]``, of which ``count[0]`` were written (the counter
    counts past the capacity: the buffer then grows and the frame runs again)."""

    row: wp.array[wp.vec4i]
    count: wp.array[wp.int64]
    capacity: int


def pair_list(buffer: GrowableBuffer) -> PairList:
    """The :class:`PairList` of a ``wp.vec4i`` buffer's current arrays (made again after it grows)."""
    out = PairList()
    out.row = buffer.data
    out.count = buffer.count
    out.capacity = buffer.capacity
    return out


@wp.func
def pair_count(pairs: PairList) -> int:
    """Rows actually stored: the counter, at most the capacity."""
    return used_count(pairs.count, pairs.capacity)


@wp.func
def pair_triangles(mesh: MeshTopology, world_vertex: wp.array[Any], c: wp.vec4i):
    """World vertices of the two triangles of row ``c = (obj_a, tri_a, obj_b, tri_b)``."""
    a0, a1, a2 = mesh_triangle(mesh, world_vertex, c[0], c[1])
    b0, b1, b2 = mesh_triangle(mesh, world_vertex, c[2], c[3])
    return a0, a1, a2, b0, b1, b2


@wp.func
def append_pair(pairs: PairList, c: wp.vec4i) -> int:
    """Appends row ``c``; returns its slot, or -1 when the list is full (the counter goes on)."""
    slot = reserve_slot(pairs.count, pairs.capacity)
    if slot >= 0:
        pairs.row[slot] = c
    return slot


@wp.func
def append_hit(hits: PairList, object_colliding: wp.array[wp.int32], c: wp.vec4i) -> int:
    """Appends the triangle pair ``c`` to the hits and flags its two objects; returns its slot (-1: full)."""
    slot = append_pair(hits, c)
    object_colliding[c[0]] = 1
    object_colliding[c[2]] = 1
    return slot
