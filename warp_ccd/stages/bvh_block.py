"""Subtrees of the median-split build finished by one thread block each, in shared memory (CUDA).

:class:`~warp_ccd.stages.bvh_build.TreeBuild` splits nodes of more than ``small`` triangles level
by level over all shapes at once (three launches a level); what is left is a subtree of at most
``small`` triangles per node. Here one thread block finishes each such subtree, one thread per
triangle (:func:`_block_finish_kernel`): the block loads its triangles' centroid keys and ids into
shared memory, then splits level by level inside the block:

* the three lists of the subtree's triangles sorted along x, y, z are made once: each thread
  counts the members before it along each axis (by key, ties by triangle id: the order of the
  reference's stable sorts; ``c`` shared-memory reads a thread, broadcasts, for a subtree of ``c``);
* a level is the global levels' partition in shared memory: each thread takes the node of list
  position ``i`` (a walk from the subtree's root), the node's longest axis from its first and last
  entries in each list (the first axis on ties), and a side for the member at ``i`` of each list
  (right when its position in the axis list reaches the median, ``count // 2``); one block scan of
  the sides (``wp.tile_scan_exclusive``) gives each its place in the stable partition;
* at the end the x list holds every leaf's triangles in the reference's order: ``tri_order``.

So a subtree needs no lists in global memory: a scene whose shapes are all of at most ``small``
triangles builds from its centroid keys in one launch (no radix sort, no level kernels), and a
bigger shape needs ``log2(m / small)`` levels fewer than with subtrees finished by one thread.
Work per thread is ``c`` shared reads plus a scan and a few barriers a level, not the uncoalesced
per-thread passes over global memory of :func:`~warp_ccd.stages.bvh_build._finish_kernel`.

The trees are those of the numpy reference, bit for bit (the same keys, the same comparisons, the
same float32 extents). On the CPU Warp runs a block as one lane unless
``wp.config.enable_cpu_blocks`` is on; the build there finishes whole shapes by one thread instead
(:data:`~warp_ccd.stages.bvh_build.SMALL_SUBTREE`), and the tests run this kernel on the CPU with
CPU blocks on.
"""

import warp as wp

from .buffers import upper_bound

wp.set_module_options({"enable_backward": False, "fuse_fp": False})

__all__ = ["BLOCK_SUBTREE", "block_dim_for", "finish_blocks"]

BLOCK_SUBTREE = 256
"""Most triangles of a subtree one block finishes: the shared tables' size (64 bytes a triangle:
three keys, an id, two halves of three lists, three positions, three sides; 16 KB a block)."""

_TILE = wp.constant(BLOCK_SUBTREE)
_TILE3 = wp.constant(3 * BLOCK_SUBTREE)
_TILE6 = wp.constant(6 * BLOCK_SUBTREE)


@wp.kernel
def _block_finish_kernel(
    num_triangles: int,
    leaf_size: int,
    shape_triangle_start: wp.array[wp.int32],
    shape_global_levels: wp.array[wp.int32],
    shape_subtree_end: wp.array[wp.int32],
    tri_key: wp.array[wp.vec3],
    tri_list: wp.array[wp.int32],
    # Outputs
    tri_order: wp.array[wp.int32],
):
    """One block per subtree left by the level-by-level splits (a whole shape when it has none),
    one thread per triangle of it: the subtree's splits down to the leaves, and its triangle order
    (shape-local ids). ``tri_list``: the lists after the global levels (read when there were some)."""
    blk, i = wp.tid()
    s = upper_bound(shape_subtree_end, 0, shape_subtree_end.shape[0], blk)
    d0 = shape_global_levels[s]
    j = blk - (shape_subtree_end[s] - (1 << d0))
    first = shape_triangle_start[s]
    start = int(0)
    count = shape_triangle_start[s + 1] - first
    for r in range(d0):
        left = count // 2
        if ((j >> (d0 - 1 - r)) & 1) == 1:
            start += left
            count -= left
        else:
            count = left
    block = first + start
    active = i < count
    tri = block + i
    key = wp.vec3(0.0)
    if active:
        if d0 > 0:  # the subtree's triangles: its block of the x list, in the half the levels ended in
            tri = tri_list[(d0 % 2) * 3 * num_triangles + block + i]
        key = tri_key[tri]
    # Member i's keys and id; three lists of members (by key along x, y, z, ties by id) in two halves
    # (read one, write the other), each member's position in each list, the split sides and their scan.
    kx = wp.tile_zeros(shape=_TILE, dtype=wp.float32, storage="shared")
    ky = wp.tile_zeros(shape=_TILE, dtype=wp.float32, storage="shared")
    kz = wp.tile_zeros(shape=_TILE, dtype=wp.float32, storage="shared")
    kid = wp.tile_zeros(shape=_TILE, dtype=wp.int32, storage="shared")
    lists = wp.tile_zeros(shape=_TILE6, dtype=wp.int32, storage="shared")
    pos = wp.tile_zeros(shape=_TILE3, dtype=wp.int32, storage="shared")
    side = wp.tile_zeros(shape=_TILE3, dtype=wp.int32, storage="shared")
    wp.tile_scatter_masked(kx, i, key[0], active)
    wp.tile_scatter_masked(ky, i, key[1], active)
    wp.tile_scatter_masked(kz, i, key[2], active)
    wp.tile_scatter_masked(kid, i, tri, active)
    rank = wp.vec3i(0, 0, 0)  # the lists, sorted once: each member's rank along each axis
    if active:
        for k in range(count):
            earlier = kid[k] < tri
            x = kx[k]
            y = ky[k]
            z = kz[k]
            if x < key[0] or (x == key[0] and earlier):
                rank[0] += 1
            if y < key[1] or (y == key[1] and earlier):
                rank[1] += 1
            if z < key[2] or (z == key[2] and earlier):
                rank[2] += 1
    for a in range(3):
        wp.tile_scatter_masked(lists, a * _TILE + rank[a], i, active)
        wp.tile_scatter_masked(pos, a * _TILE + i, rank[a], active)
    levels = int(0)  # the same in every thread: splits until the biggest node is a leaf
    biggest = int(count)
    while biggest > leaf_size:
        biggest -= biggest // 2
        levels += 1
    for level in range(levels):
        cur = (level % 2) * _TILE3
        nxt = _TILE3 - cur
        # The node of list position i at this level (a leaf above it stays), and where it splits.
        ns = int(0)
        nc = int(count)
        for _r in range(level):
            if nc > leaf_size:
                half = nc // 2
                if i < ns + half:
                    nc = half
                else:
                    ns += half
                    nc -= half
        splits = active and nc > leaf_size
        axis = int(0)
        if splits:
            best = wp.float32(0.0)
            for b in range(3):
                lo = lists[cur + b * _TILE + ns]
                hi = lists[cur + b * _TILE + ns + nc - 1]
                extent = wp.float32(0.0)
                if b == 0:
                    extent = kx[hi] - kx[lo]
                elif b == 1:
                    extent = ky[hi] - ky[lo]
                else:
                    extent = kz[hi] - kz[lo]
                if b == 0 or extent > best:  # the longest axis, the first on ties
                    axis = b
                    best = extent
        member = wp.vec3i(0, 0, 0)
        for a in range(3):  # 1 where the member at position i of list a goes right
            right = int(0)
            if active:
                member[a] = lists[cur + a * _TILE + i]
                if splits and pos[axis * _TILE + member[a]] >= ns + nc // 2:
                    right = 1
            wp.tile_scatter_masked(side, a * _TILE + i, right, active)
        rights = wp.tile_scan_exclusive(side)
        for a in range(3):  # stable partition of each node's block of each list: left, then right
            new = int(i)
            if splits:
                right_before = rights[a * _TILE + i] - rights[a * _TILE + ns]
                if side[a * _TILE + i] == 1:
                    new = ns + nc // 2 + right_before
                else:
                    new = i - right_before
            wp.tile_scatter_masked(lists, nxt + a * _TILE + new, member[a], active)
            wp.tile_scatter_masked(pos, a * _TILE + member[a], new, active)
    if active:  # the x list, in its last half: every leaf's triangles in the reference's order
        tri_order[block + i] = kid[lists[(levels % 2) * _TILE3 + i]] - first


def block_dim_for(largest: int) -> int:
    """Threads of a block for subtrees of at most ``largest`` triangles: a power of two from 32
    (a warp) to :data:`BLOCK_SUBTREE`."""
    if largest > BLOCK_SUBTREE:
        raise ValueError(f"a block finishes subtrees of at most {BLOCK_SUBTREE} triangles, not {largest}")
    dim = 32
    while dim < largest:
        dim *= 2
    return dim


def finish_blocks(num_subtrees: int, block_dim: int, num_triangles: int, leaf_size: int, shape_triangle_start,
                  shape_global_levels, shape_subtree_end, tri_key, tri_list, tri_order, device) -> None:
    """Launches :func:`_block_finish_kernel`: ``num_subtrees`` blocks of ``block_dim`` threads.

    Args:
        num_subtrees: subtrees of all shapes (``shape_subtree_end[-1]``).
        block_dim: threads a block, at least the largest subtree (:func:`block_dim_for`).
        num_triangles: triangles of all shapes.
        leaf_size: most triangles per leaf.
        shape_triangle_start: ``(S + 1,)`` int32 offsets of the shapes' triangles.
        shape_global_levels: ``(S,)`` int32 levels each shape was split level by level.
        shape_subtree_end: ``(S,)`` int32 inclusive scan of ``2**shape_global_levels``.
        tri_key: ``(T,)`` ``wp.vec3`` centroid keys.
        tri_list: the build's lists (read only after global levels; any int32 array otherwise).
        tri_order: ``(T,)`` int32 output.
        device: Warp device.
    """
    if num_subtrees == 0:
        return
    wp.launch_tiled(_block_finish_kernel, dim=[num_subtrees],
                    inputs=[num_triangles, leaf_size, shape_triangle_start, shape_global_levels, shape_subtree_end,
                            tri_key, tri_list],
                    outputs=[tri_order], block_dim=block_dim, device=device)
