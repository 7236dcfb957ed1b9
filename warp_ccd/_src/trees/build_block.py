"""Subtrees of the median-split build finished by one thread block each, in shared memory (CUDA).

:class:`~warp_ccd._src.trees.build.TreeBuild` splits nodes of more than ``small`` triangles level
by level over all shapes at once (three launches a level); what is left is a subtree of at most
``small`` triangles per node. Here one thread block finishes each such subtree, one thread per
triangle (:func:`_block_finish_kernel`): the block loads its triangles' centroid keys and ids into
shared memory, then splits level by level inside the block, a barrier a level:

* each thread loops over the members of its node (a few hundred shared-memory reads at the top,
  half as many a level down: about ``2 c`` for a subtree of ``c``), taking the bounds of their
  keys and its own rank along each axis (by key, ties by triangle id: the order of the reference's
  stable sorts);
* the node's longest axis (the first on ties) picks the rank; the thread goes left when its rank
  is below the median (``count // 2``), and writes itself into its new place, its node's first
  position plus its rank (the other half of a double-buffered slot table);
* at the leaves, its rank along x among the leaf's triangles gives its place in ``tri_order``
  (the reference's leaves keep the x list's order).

Where the build sorted its lists (a scene with a shape of more than ``small`` triangles), each
subtree's block of each list is sorted already: the first level reads its ranks (positions) and
bounds (first and last keys) off the lists instead of counting, half of a subtree's work.

So a subtree needs no sorted lists at all: a scene whose shapes are all of at most ``small``
triangles builds from its centroid keys in one launch (no radix sort, no level kernels), and a
bigger shape needs ``log2(m / small)`` levels fewer than with subtrees finished by one thread.
Work per thread is ``O(c)`` reads that the whole node shares (broadcasts, no bank conflicts), not
the uncoalesced per-thread passes over global memory of
:func:`~warp_ccd._src.trees.build._finish_kernel`. Tried and measured slower on a GPU (docs:
architecture, trees): the three lists sorted once by counting, then each level a stable partition
by a block scan of the sides (``wp.tile_scan_exclusive``); each node's first member finding the
node's axis alone for the others to count along it only (a second barrier a level).

The trees are those of the numpy reference, bit for bit (the same keys, the same comparisons, the
same float32 extents). On the CPU Warp runs a block as one lane unless
``wp.config.enable_cpu_blocks`` is on; the build there finishes whole shapes by one thread instead
(:data:`~warp_ccd._src.trees.build.SMALL_SUBTREE`), and the tests run this kernel on the CPU with
CPU blocks on.
"""

import warp as wp

from ..runtime.buffers import blocks_have_lanes, upper_bound

wp.set_module_options({"enable_backward": False, "fuse_fp": False})

__all__ = ["BLOCK_SUBTREE", "finish_blocks", "require_lanes", "subtree_block_dim", "subtree_of"]

BLOCK_SUBTREE = 256
"""Most triangles of a subtree one block finishes: the shared tables' size (24 bytes a triangle:
three keys, an id, two slots; 6 KB a block, so that 32 small blocks fit on a multiprocessor)."""

_TILE = wp.constant(BLOCK_SUBTREE)
_TILE2 = wp.constant(2 * BLOCK_SUBTREE)


@wp.func
def subtree_of(shape_triangle_start: wp.array[wp.int32], shape_global_levels: wp.array[wp.int32],
               shape_subtree_end: wp.array[wp.int32], t: int):
    """Subtree ``t`` of all shapes (the nodes left after each shape's ``shape_global_levels[s]``
    levels, ``shape_subtree_end`` their inclusive scan): ``(s, levels, first, start, count)``, its
    shape, the shape's levels and first triangle, and its triangle range within the shape."""
    s = upper_bound(shape_subtree_end, 0, shape_subtree_end.shape[0], t)
    d0 = shape_global_levels[s]
    j = t - (shape_subtree_end[s] - (1 << d0))
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
    return s, d0, first, start, count


@wp.kernel
def _block_finish_kernel(
    num_triangles: int,
    leaf_size: int,
    shape_triangle_start: wp.array[wp.int32],
    shape_global_levels: wp.array[wp.int32],
    shape_subtree_end: wp.array[wp.int32],
    tri_key: wp.array[wp.vec3],
    tri_list: wp.array[wp.int32],
    tri_pos: wp.array[wp.int32],
    sorted_lists: int,
    # Outputs
    tri_order: wp.array[wp.int32],
):
    """One block per subtree left by the level-by-level splits (a whole shape when it has none),
    one thread per triangle of it: the subtree's splits down to the leaves, and its triangle order
    (shape-local ids). ``tri_list``: the lists after the global levels (read when there were some)."""
    blk, i = wp.tid()
    s, d0, first, start, count = subtree_of(shape_triangle_start, shape_global_levels, shape_subtree_end, blk)
    block = first + start
    active = i < count
    tri = block + i
    key = wp.vec3(0.0)
    if active:
        if d0 > 0:  # the subtree's triangles: its block of the x list, in the half the levels ended in
            tri = tri_list[(d0 % 2) * 3 * num_triangles + block + i]
        key = tri_key[tri]
    kx = wp.tile_zeros(shape=_TILE, dtype=wp.float32, storage="shared")
    ky = wp.tile_zeros(shape=_TILE, dtype=wp.float32, storage="shared")
    kz = wp.tile_zeros(shape=_TILE, dtype=wp.float32, storage="shared")
    kid = wp.tile_zeros(shape=_TILE, dtype=wp.int32, storage="shared")
    slot = wp.tile_zeros(shape=_TILE2, dtype=wp.int32, storage="shared")  # two halves: read one, write the other
    wp.tile_scatter_masked(kx, i, key[0], active)
    wp.tile_scatter_masked(ky, i, key[1], active)
    wp.tile_scatter_masked(kz, i, key[2], active)
    wp.tile_scatter_masked(kid, i, tri, active)
    wp.tile_scatter_masked(slot, i, i, active)
    levels = int(0)  # the same in every thread: splits until the biggest node is a leaf
    biggest = int(count)
    while biggest > leaf_size:
        biggest -= biggest // 2
        levels += 1
    ns = int(0)  # this thread's node: first position and count, within the subtree
    nc = int(count)
    p = int(i)
    for level in range(levels):
        cur = (level % 2) * _TILE
        if active and nc > leaf_size:
            lo = key
            hi = key
            rx = int(0)
            ry = int(0)
            rz = int(0)
            if level == 0 and sorted_lists == 1:
                # The subtree's block of each list is sorted already: its ranks and bounds read off them.
                n = num_triangles
                lists = (d0 % 2) * 3 * n
                last = block + count - 1
                rx = tri_pos[tri] - block
                ry = tri_pos[n + tri] - block
                rz = tri_pos[2 * n + tri] - block
                lo = wp.vec3(tri_key[tri_list[lists + block]][0], tri_key[tri_list[lists + n + block]][1],
                             tri_key[tri_list[lists + 2 * n + block]][2])
                hi = wp.vec3(tri_key[tri_list[lists + last]][0], tri_key[tri_list[lists + n + last]][1],
                             tri_key[tri_list[lists + 2 * n + last]][2])
            else:
                for k in range(ns, ns + nc):
                    o = slot[cur + k]
                    x = kx[o]
                    y = ky[o]
                    z = kz[o]
                    lo = wp.vec3(wp.min(lo[0], x), wp.min(lo[1], y), wp.min(lo[2], z))
                    hi = wp.vec3(wp.max(hi[0], x), wp.max(hi[1], y), wp.max(hi[2], z))
                    before = kid[o] < tri
                    if x < key[0] or (x == key[0] and before):
                        rx += 1
                    if y < key[1] or (y == key[1] and before):
                        ry += 1
                    if z < key[2] or (z == key[2] and before):
                        rz += 1
            extent = hi - lo  # the longest axis, the first on ties
            rank = rx
            best = extent[0]
            if extent[1] > best:
                rank = ry
                best = extent[1]
            if extent[2] > best:
                rank = rz
            half = nc // 2
            p = ns + rank
            if rank < half:
                nc = half
            else:
                ns += half
                nc -= half
        wp.tile_scatter_masked(slot, _TILE - cur + p, i, active)
    if active:
        cur = (levels % 2) * _TILE
        rank = int(0)
        for k in range(ns, ns + nc):
            o = slot[cur + k]
            x = kx[o]
            if x < key[0] or (x == key[0] and kid[o] < tri):
                rank += 1
        tri_order[block + ns + rank] = tri - first


def require_lanes(device, why: str) -> None:
    """ValueError unless a block on ``device`` has its lanes (:func:`~warp_ccd._src.runtime.buffers.blocks_have_lanes`):
    this kernel's threads share their block's work, which one lane would leave undone (``why``: the
    message's note)."""
    if not blocks_have_lanes(device):
        raise ValueError(f"finish='block' on the CPU needs wp.config.enable_cpu_blocks ({why})")


def subtree_block_dim(largest: int) -> int:
    """Threads of a block for subtrees of at most ``largest`` triangles: a power of two from 32
    (a warp) to :data:`BLOCK_SUBTREE`."""
    if largest > BLOCK_SUBTREE:
        raise ValueError(f"a block finishes subtrees of at most {BLOCK_SUBTREE} triangles, not {largest}")
    dim = 32
    while dim < largest:
        dim *= 2
    return dim


def finish_blocks(num_subtrees: int, block_dim: int, num_triangles: int, leaf_size: int, shape_triangle_start,
                  shape_global_levels, shape_subtree_end, tri_key, tri_list, tri_pos, sorted_lists: bool, tri_order,
                  device) -> None:
    """Launches :func:`_block_finish_kernel`: ``num_subtrees`` blocks of ``block_dim`` threads.

    Args:
        num_subtrees: subtrees of all shapes (``shape_subtree_end[-1]``).
        block_dim: threads a block, at least the largest subtree (:func:`subtree_block_dim`).
        num_triangles: triangles of all shapes.
        leaf_size: most triangles per leaf.
        shape_triangle_start: ``(S + 1,)`` int32 offsets of the shapes' triangles.
        shape_global_levels: ``(S,)`` int32 levels each shape was split level by level.
        shape_subtree_end: ``(S,)`` int32 inclusive scan of ``2**shape_global_levels``.
        tri_key: ``(T,)`` ``wp.vec3`` centroid keys.
        tri_list: the build's lists (read only where they were sorted; any int32 array otherwise).
        tri_pos: each triangle's position in each list (read only where they were sorted).
        sorted_lists: the lists were radix-sorted (and split ``shape_global_levels`` times): a
            subtree's block of each list is sorted, and its first level reads ranks and bounds
            there instead of counting.
        tri_order: ``(T,)`` int32 output.
        device: Warp device.
    """
    if num_subtrees == 0:
        return
    wp.launch_tiled(_block_finish_kernel, dim=[num_subtrees],
                    inputs=[num_triangles, leaf_size, shape_triangle_start, shape_global_levels, shape_subtree_end,
                            tri_key, tri_list, tri_pos, int(sorted_lists)],
                    outputs=[tri_order], block_dim=block_dim, device=device)
