"""Tree builds for every shape of a scene at once, in kernels (CPU or CUDA).

The trees are median splits: a node of ``c > L`` triangles (``L`` the leaf size) is split along
the longest axis of its triangles' centroids, the ``c // 2`` lowest going left. Two facts make a
batched build cheap:

1. **The layout depends on the triangle count alone**, so shapes of one count share one (10^5
   distinct 80-triangle shapes: one layout of 159 nodes). Node counts at depth ``d`` are
   ``m >> d`` or one more, so every level down to ``q``, the first with ``m >> q <= L``, is
   complete (``2**d`` nodes), and on level ``q`` only the nodes of ``L + 1`` triangles split
   (there are ``m - (m >> q << q)`` of them when ``m >> q == L``). Each node's id (breadth first),
   triangle range, children, parent, depth, leaf range and place in the cuts follow from its id
   by a walk from the root of ``O(depth)`` arithmetic steps: one thread per node of every layout,
   one launch (:func:`_layout_kernel`), no sort, no scan; the host computes the sizes with a few
   numpy operations over the layouts (:class:`TreeSizes`).
2. **Only the order of the triangles depends on the geometry.** It comes from three lists of each
   shape's triangles sorted by centroid along x, y, z (one stable radix sort per axis, by shape
   then key), partitioned stably level by level (the classic O(m log m) k-d build): a node's side
   of the split is its triangles' rank in the list of its axis. Nodes of more than ``small``
   triangles are split level by level over all shapes at once (each node's axis, a side kernel, a
   scan, a scatter: four launches a level); every subtree of at most ``small`` triangles is then finished on CUDA
   by one thread block in shared memory (:mod:`~warp_ccd._src.trees.build_block`, subtrees of up to 256:
   no lists needed, so a scene of shapes of at most 256 triangles builds from its keys in three
   launches, no sort), or by one thread (:func:`_finish_kernel`: insertion sort of its three
   lists, then its splits). On the CPU, where Warp runs a kernel on one thread, whole shapes are
   finished by a thread, and a scene of shapes of at most 64 triangles builds in three launches
   and no sort. The radix sorts take one 64-bit key per axis: the shape above the float's bits.

The trees are those of :func:`~warp_ccd._src.trees.reference.build_tree`, the numpy reference kept beside
the kernels: same centroid keys (``(v0 / 4 + v1 / 4) + v2 / 4`` in float32, ties broken by triangle id), same
layout, same triangle order, bit for bit (tests compare them). Rebuilding a shape's order from
moved vertices (:meth:`TreeBuild.order` with other vertices) leaves the layout as it is.

Layout, per shape, nodes in breadth-first order (level ``d`` starts at ``2**d - 1``):

* ``node_child`` ``(left, right)`` or ``(-1, -1)`` for a leaf, ``node_parent`` (-1 at the root);
* ``node_triangle`` ``(start, count)``: the node's triangles are ``tri_order[start:start + count]``
  (every subtree is one contiguous range);
* ``leaf_node`` the leaves in the order of their triangles, ``node_leaf`` ``(first, count)``: a
  node's subtree holds the leaves ``leaf_node[first:first + count]``; ``inner_node`` the inner
  nodes in id order;
* cuts: the nodes at a depth and the leaves above it (subtrees that partition the leaves), two per
  layout (``layout_cut_depth`` and one level deeper), deeper in big trees (:meth:`TreeSizes.cut_depth`).
"""

from functools import cached_property
from typing import Any

import numpy as np
import warp as wp

from ..geometry.precision import precision_overloads
from ..runtime.arrays import packed_upload
from ..runtime.buffers import upper_bound
from .build_block import BLOCK_SUBTREE, finish_blocks, require_lanes, subtree_block_dim, subtree_of
from .reference import ShapeTree

# Forward kernels only; no FMA contraction, so that centroid keys are the same bits everywhere.
wp.set_module_options({"enable_backward": False, "fuse_fp": False})

__all__ = ["CUT_DEPTH_MAX", "CUT_TRIANGLES", "INSERTION_SORT_MAX", "SMALL_SUBTREE", "TreeBuild", "TreeSizes"]

SMALL_SUBTREE = 8
"""Largest subtree (in triangles) that one thread finishes alone (:func:`_finish_kernel`) on CUDA;
bigger nodes are split level by level over all shapes. At least ``2 * leaf_size`` is used. On the
CPU, where Warp runs a kernel on one thread, each shape is finished whole (its lists presorted).
A thread's work on its own block of the lists is uncoalesced: the smallest subtrees built fastest
on a GPU, whole shapes sorted by insertion slowest (docs: architecture, trees)."""

CUT_TRIANGLES = 64
"""A tree's cut (whose boxes under the pose make a big rigid object's box for the broad phase) lies
deep enough that its subtrees hold at most about this many triangles (:meth:`TreeSizes.cut_depth`):
many small boxes, nearly as tight as the vertices."""

CUT_DEPTH_MAX = 8
"""Deepest cut chosen by size (at most 256 subtrees a tree)."""

INSERTION_SORT_MAX = 64
"""Shapes of at most this many triangles sort their lists by insertion in :func:`_finish_kernel`;
a scene with a bigger shape sorts all lists first (radix sorts), so that the insertion sort finds
them sorted."""


# ---------------------------------------------------------------------------------------------- sizes
def _bit_length(x: np.ndarray) -> np.ndarray:
    """Bits of each non-negative integer below 2**53 (0 for 0)."""
    return np.frexp(np.asarray(x, np.float64))[1].astype(np.int64)


class TreeSizes:
    """Per-shape sizes of median-split trees, from triangle counts alone (numpy, vectorised).

    Args:
        m: ``(S,)`` triangles per shape (each at least 1).
        leaf_size: most triangles per leaf ``L``.

    Attributes:
        q: ``(S,)`` the last complete level: the first with ``m >> q <= L``.
        split: ``(S,)`` nodes of level ``q`` that split (``L + 1`` triangles each).
        num_nodes, num_leaves, num_inner: ``(S,)`` int64; ``num_levels`` follows from ``q`` and ``split``.
    """

    def __init__(self, m, leaf_size: int):
        m = np.asarray(m, np.int64)
        self.m = m
        self.leaf_size = int(leaf_size)
        self.q = _bit_length(m // (self.leaf_size + 1))
        f = m >> self.q
        self.split = np.where(f == self.leaf_size, m - (f << self.q), 0)
        self.num_nodes = (np.int64(1) << (self.q + 1)) - 1 + 2 * self.split
        self.num_leaves = (np.int64(1) << self.q) + self.split
        self.num_inner = self.num_nodes - self.num_leaves

    @property
    def num_levels(self) -> np.ndarray:
        """``(S,)`` levels of each tree: down to ``q``, and one more where level ``q`` splits."""
        return self.q + 1 + (self.split > 0)

    def take(self, index: np.ndarray) -> "TreeSizes":
        """The sizes of the trees ``index`` (gathered, not recomputed)."""
        out = object.__new__(TreeSizes)
        out.leaf_size = self.leaf_size
        for name in ("m", "q", "split", "num_nodes", "num_leaves", "num_inner"):
            setattr(out, name, getattr(self, name)[index])
        return out

    def level(self, d: int) -> tuple[np.ndarray, np.ndarray]:
        """``(first node, node count)`` of level ``d`` of every shape (count 0 past its last)."""
        first = np.full(self.m.shape, (1 << d) - 1, np.int64)
        count = np.where(d <= self.q, np.int64(1) << min(d, 62), np.where(d == self.q + 1, 2 * self.split, 0))
        return first, count

    def cut_size(self, depth) -> np.ndarray:
        """Nodes in the cut at ``depth`` (one level, or ``(S,)`` levels) of every shape: ``2**depth``,
        or all leaves below."""
        depth = np.asarray(depth, np.int64)
        return np.where(depth <= self.q, np.int64(1) << np.minimum(depth, 62), self.num_leaves)

    def cut_depth(self, depth: int, cut_triangles: int) -> np.ndarray:
        """``(S,)`` level of each tree's cut: at least ``depth``, deeper in a big tree until its cut's
        subtrees hold at most about ``cut_triangles`` triangles, but no deeper than
        :data:`CUT_DEPTH_MAX` (when ``depth`` is not deeper still)."""
        need = _bit_length((self.m - 1) // max(int(cut_triangles), 1))  # ceil(log2(m / cut_triangles))
        return np.maximum(np.int64(depth), np.minimum(need, CUT_DEPTH_MAX))


def _distinct(m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(index, values)``: the distinct values of ``m`` ascending, and each entry's index among
    them (``np.unique(..., return_inverse=True)``, by counting when the values are small)."""
    if len(m) == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    top = int(m.max())
    if top > 4 * len(m) + 4096:
        values, index = np.unique(m, return_inverse=True)
        return index.reshape(-1), values
    present = np.zeros(top + 1, np.bool_)
    present[m] = True
    return (np.cumsum(present) - 1)[m], np.flatnonzero(present)


# ---------------------------------------------------------------------------------------------- layout
@wp.func
def _bits(x: int) -> int:
    """Bits of a non-negative ``x`` (0 for 0)."""
    n = int(0)
    y = x
    while y > 0:
        y = y >> 1
        n += 1
    return n


@wp.func
def _last_full_level(m: int, leaf_size: int) -> int:
    """``q``: the first level whose node counts (``m >> q`` or one more) are at most ``leaf_size + 1``."""
    return _bits(m // (leaf_size + 1))


@wp.kernel
def _layout_kernel(
    layout_triangles: wp.array[wp.int32],
    layout_node_start: wp.array[wp.int32],
    layout_leaf_start: wp.array[wp.int32],
    layout_inner_start: wp.array[wp.int32],
    layout_cut_start: wp.array[wp.int32],
    layout_cut_depth: wp.array[wp.int32],
    leaf_size: int,
    # Outputs
    node_child: wp.array[wp.vec2i],
    node_parent: wp.array[wp.int32],
    node_triangle: wp.array[wp.vec2i],
    node_leaf: wp.array[wp.vec2i],
    leaf_node: wp.array[wp.int32],
    inner_node: wp.array[wp.int32],
    cut_node: wp.array[wp.int32],
):
    """One thread per node of every layout (one per triangle count ``layout_triangles[l]``): its
    range, children, parent, leaf range; leaves and inner nodes write themselves into their lists,
    and cut members into the layout's two cuts (at ``layout_cut_depth[l]`` and one level deeper)."""
    t = wp.tid()
    s = upper_bound(layout_node_start, 0, layout_node_start.shape[0], t) - 1
    k = t - layout_node_start[s]
    m = layout_triangles[s]
    q = _last_full_level(m, leaf_size)
    f = m >> q
    high_splits = f == leaf_size  # level q's nodes of f + 1 triangles split
    split = int(0)
    if high_splits:
        split = m - (f << q)
    full = (1 << (q + 1)) - 1  # nodes on levels 0..q
    start = int(0)
    count = int(m)
    before = int(0)  # leaves whose triangles come before this node's
    depth = int(0)
    j = int(0)  # index within the level
    i = int(0)  # index within level q + 1
    parent = int(-1)
    child = wp.vec2i(-1, -1)
    leaves = int(1)
    if k < full:
        depth = _bits(k + 1) - 1
        j = k + 1 - (1 << depth)
        for r in range(depth):
            left = count // 2
            if ((j >> (depth - 1 - r)) & 1) == 1:
                rel = q - r - 1  # the left sibling's subtree spans levels r + 1 .. q
                before += 1 << rel
                if high_splits:
                    before += left - (f << rel)
                start += left
                count -= left
            else:
                count = left
        rel = q - depth
        leaves = 1 << rel
        if high_splits:
            leaves += count - (f << rel)
        if depth > 0:
            parent = (1 << (depth - 1)) - 1 + j // 2
        if depth < q:
            c0 = (1 << (depth + 1)) - 1 + 2 * j
            child = wp.vec2i(c0, c0 + 1)
        elif count > leaf_size:  # level q, a node of f + 1 triangles: after the ones left of it
            c0 = full + 2 * (before - j)
            child = wp.vec2i(c0, c0 + 1)
    else:
        i = k - full
        h = int(i // 2)  # the parent is the h-th splitting node of level q: find it from the root
        for r in range(q):
            left = count // 2
            rel = q - r - 1
            left_high = left - (f << rel)
            if h < left_high:
                count = left
                j = 2 * j
            else:
                h -= left_high
                start += left
                count -= left
                j = 2 * j + 1
        depth = q + 1
        parent = (1 << q) - 1 + j
        left = count // 2
        if i % 2 == 0:
            count = left
        else:
            start += left
            count -= left
        before = j + i // 2 + i % 2
    node_child[t] = child
    node_parent[t] = parent
    node_triangle[t] = wp.vec2i(start, count)
    node_leaf[t] = wp.vec2i(before, leaves)
    if child[0] < 0:
        leaf_node[layout_leaf_start[s] + before] = k
    elif depth < q:
        inner_node[layout_inner_start[s] + k] = k
    else:
        inner_node[layout_inner_start[s] + (1 << q) - 1 + before - j] = k
    for deep in range(2):
        cd = layout_cut_depth[s] + deep
        base = layout_cut_start[2 * s + deep]
        if cd <= q:
            if depth == cd:
                cut_node[base + j] = k
        elif depth == q and child[0] < 0:  # the leaves of level q, then level q + 1
            cut_node[base + j - (before - j)] = k
        elif depth == q + 1:
            cut_node[base + (1 << q) - split + i] = k


# ---------------------------------------------------------------------------------------------- order
@wp.kernel
def _key_kernel(
    shape_vertex: wp.array[Any],
    shape_vertex_start: wp.array[wp.int32],
    world_vertex: wp.array[Any],
    shape_world_start: wp.array[wp.int32],
    shape_triangle: wp.array[wp.vec3i],
    shape_triangle_start: wp.array[wp.int32],
    num_triangles: int,
    lists: int,
    use_world: int,
    # Outputs
    tri_shape: wp.array[wp.int32],
    tri_key: wp.array[wp.vec3],
    tri_list: wp.array[wp.int32],
):
    """One thread per shape triangle: its centroid key (with ``use_world`` 1, from ``world_vertex``
    at ``shape_world_start[s]`` when that is not -1; else from the shape's own vertices) and, when
    ``lists`` is 1, its shape and its place in the three lists, in triangle order."""
    g = wp.tid()
    s = upper_bound(shape_triangle_start, 0, shape_triangle_start.shape[0], g) - 1
    idx = shape_triangle[g]
    w = int(-1)
    if use_world == 1:
        w = shape_world_start[s]
    a = wp.vec3(0.0)
    b = wp.vec3(0.0)
    c = wp.vec3(0.0)
    if w >= 0:
        a = wp.vec3(world_vertex[w + idx[0]])
        b = wp.vec3(world_vertex[w + idx[1]])
        c = wp.vec3(world_vertex[w + idx[2]])
    else:
        base = shape_vertex_start[s]
        a = wp.vec3(shape_vertex[base + idx[0]])
        b = wp.vec3(shape_vertex[base + idx[1]])
        c = wp.vec3(shape_vertex[base + idx[2]])
    quarter = wp.float32(0.25)
    tri_key[g] = ((a * quarter + b * quarter) + c * quarter) + wp.vec3(0.0)
    if lists == 1:
        tri_shape[g] = s
        for axis in range(3):
            tri_list[axis * num_triangles + g] = g


_KEY = precision_overloads(_key_kernel, lambda s, v, q, t: {"shape_vertex": wp.array[v], "world_vertex": wp.array[v]})


_SIGN_BIT = wp.constant(wp.uint32(0x80000000))
"""A float32's sign bit, typed as a constant: ``wp.uint32(0x80000000)`` in a kernel is generated as an
int32 literal first (clang's ``-Wconstant-conversion``: 2147483648 becomes -2147483648, then the same
bits as uint32)."""


@wp.kernel
def _axis_key_kernel(key_bits: wp.array[wp.uint32], tri_shape: wp.array[wp.int32], axis: int,
                     # Outputs
                     sort_key: wp.array[wp.uint64], sort_value: wp.array[wp.int32]):
    """One thread per triangle: the key of the radix sort of the ``axis`` list, its shape in the
    high 32 bits and its centroid key's float bits made to sort as the floats do in the low 32
    (``key_bits``: the keys' bits; no -0, no NaN), the triangle as its value."""
    g = wp.tid()
    bits = key_bits[3 * g + axis]
    if (bits & _SIGN_BIT) != wp.uint32(0):
        bits = ~bits
    else:
        bits = bits | _SIGN_BIT
    sort_key[g] = (wp.uint64(tri_shape[g]) << wp.uint64(32)) | wp.uint64(bits)
    sort_value[g] = g


@wp.kernel
def _store_list_kernel(sort_value: wp.array[wp.int32], axis: int, num_triangles: int,
                       # Outputs
                       tri_list: wp.array[wp.int32], tri_pos: wp.array[wp.int32]):
    """One thread per list position: the sorted triangle there, and its position."""
    i = wp.tid()
    g = sort_value[i]
    tri_list[axis * num_triangles + i] = g
    tri_pos[axis * num_triangles + g] = i


@wp.func
def _node_at(m: int, depth: int, p: int):
    """``(start, count)`` of the node at level ``depth`` (levels above it complete) holding position ``p``."""
    start = int(0)
    count = int(m)
    for _r in range(depth):
        left = count // 2
        if p < start + left:
            count = left
        else:
            start += left
            count -= left
    return start, count


@wp.func
def _split_axis(tri_key: wp.array[wp.vec3], tri_list: wp.array[wp.int32], list_base: int, num_triangles: int,
                first: int, count: int) -> int:
    """Longest axis of the centroid keys of the list block ``first .. first + count``: the first and
    last of the block in each axis's sorted list (the first axis on ties)."""
    best = int(0)
    best_extent = wp.float32(0.0)
    for a in range(3):
        row = list_base + a * num_triangles + first
        extent = tri_key[tri_list[row + count - 1]][a] - tri_key[tri_list[row]][a]
        if a == 0 or extent > best_extent:
            best = a
            best_extent = extent
    return best


@wp.kernel
def _node_axis_kernel(
    level: int,
    num_triangles: int,
    tri_shape: wp.array[wp.int32],
    shape_triangle_start: wp.array[wp.int32],
    shape_global_levels: wp.array[wp.int32],
    tri_key: wp.array[wp.vec3],
    tri_list: wp.array[wp.int32],
    # Outputs
    node_axis: wp.array[wp.int32],
):
    """One thread per list position: where a node split on ``level`` begins, its split axis
    (:func:`_split_axis`), written at its first position; once a node, not once a list entry."""
    g = wp.tid()
    s = tri_shape[g]
    if level >= shape_global_levels[s]:
        return
    first = shape_triangle_start[s]
    start, count = _node_at(shape_triangle_start[s + 1] - first, level, g - first)
    if g - first == start:
        node_axis[g] = _split_axis(tri_key, tri_list, (level % 2) * 3 * num_triangles, num_triangles, g, count)


@wp.kernel
def _split_side_kernel(
    level: int,
    num_triangles: int,
    tri_shape: wp.array[wp.int32],
    shape_triangle_start: wp.array[wp.int32],
    shape_global_levels: wp.array[wp.int32],
    node_axis: wp.array[wp.int32],
    tri_list: wp.array[wp.int32],
    tri_pos: wp.array[wp.int32],
    # Outputs
    side: wp.array[wp.int32],
):
    """One thread per (axis list, position): 1 when the triangle there goes right at the split of
    its node on ``level`` (its rank along the node's axis, ``node_axis`` at the node's first
    position, reaches the median), else 0."""
    t = wp.tid()
    a = t // num_triangles
    g = t - a * num_triangles
    s = tri_shape[g]
    if level >= shape_global_levels[s]:
        side[t] = 0
        return
    first = shape_triangle_start[s]
    start, count = _node_at(shape_triangle_start[s + 1] - first, level, g - first)
    axis = node_axis[first + start]
    tri = tri_list[(level % 2) * 3 * num_triangles + t]
    if tri_pos[axis * num_triangles + tri] - first >= start + count // 2:
        side[t] = 1
    else:
        side[t] = 0


@wp.kernel
def _split_scatter_kernel(
    level: int,
    num_triangles: int,
    tri_shape: wp.array[wp.int32],
    shape_triangle_start: wp.array[wp.int32],
    shape_global_levels: wp.array[wp.int32],
    side: wp.array[wp.int32],
    side_before: wp.array[wp.int32],
    # Outputs
    tri_list: wp.array[wp.int32],
    tri_pos: wp.array[wp.int32],
):
    """One thread per (axis list, position): the stable partition of each node's block, left items
    then right ones, into the other half of ``tri_list`` (``side_before``: exclusive scan of ``side``)."""
    t = wp.tid()
    a = t // num_triangles
    g = t - a * num_triangles
    s = tri_shape[g]
    if level >= shape_global_levels[s]:
        return
    first = shape_triangle_start[s]
    p = g - first
    start, count = _node_at(shape_triangle_start[s + 1] - first, level, p)
    right_before = side_before[t] - side_before[a * num_triangles + first + start]  # in this node
    new_p = p - right_before
    if side[t] == 1:
        new_p = start + count // 2 + right_before
    src = (level % 2) * 3 * num_triangles
    dst = (1 - level % 2) * 3 * num_triangles
    tri = tri_list[src + t]
    tri_list[dst + a * num_triangles + first + new_p] = tri
    tri_pos[a * num_triangles + tri] = first + new_p


@wp.kernel
def _finish_kernel(
    num_triangles: int,
    leaf_size: int,
    shape_triangle_start: wp.array[wp.int32],
    shape_global_levels: wp.array[wp.int32],
    shape_subtree_end: wp.array[wp.int32],
    tri_key: wp.array[wp.vec3],
    # Outputs
    tri_list: wp.array[wp.int32],
    tri_pos: wp.array[wp.int32],
    tri_order: wp.array[wp.int32],
):
    """One thread per subtree left by the level-by-level splits (a whole shape when it is small):
    sorts its block of each list (insertion sort: stable, linear when the block is sorted already),
    splits its nodes down to the leaves, and writes its triangle order (shape-local ids)."""
    t = wp.tid()
    shape, d0, first, start, count = subtree_of(shape_triangle_start, shape_global_levels, shape_subtree_end, t)
    m = shape_triangle_start[shape + 1] - first
    n = num_triangles
    lists = (d0 % 2) * 3 * n
    scratch = (1 - d0 % 2) * 3 * n
    block = first + start
    for a in range(3):
        row = lists + a * n + block
        for k in range(1, count):
            x = tri_list[row + k]
            key = tri_key[x][a]
            h = int(k)
            while h > 0:
                y = tri_list[row + h - 1]
                if tri_key[y][a] <= key:
                    break
                tri_list[row + h] = y
                h -= 1
            tri_list[row + h] = x
        for k in range(count):
            tri_pos[a * n + tri_list[row + k]] = block + k
    q = _last_full_level(m, leaf_size)
    for depth in range(d0, q + 1):
        rel = depth - d0
        for jj in range(1 << rel):
            ns = int(start)
            nc = int(count)
            for r in range(rel):
                left = nc // 2
                if ((jj >> (rel - 1 - r)) & 1) == 1:
                    ns += left
                    nc -= left
                else:
                    nc = left
            if nc <= leaf_size:
                continue
            axis = _split_axis(tri_key, tri_list, lists, n, first + ns, nc)
            cut = first + ns + nc // 2
            for b in range(3):
                if b == axis:
                    continue  # its block is split already: the first half is the left side
                row = lists + b * n + first + ns
                tmp = scratch + b * n + first + ns
                lo = int(0)
                hi = int(nc // 2)
                for k in range(nc):
                    x = tri_list[row + k]
                    if tri_pos[axis * n + x] < cut:
                        tri_list[tmp + lo] = x
                        lo += 1
                    else:
                        tri_list[tmp + hi] = x
                        hi += 1
                for k in range(nc):
                    x = tri_list[tmp + k]
                    tri_list[row + k] = x
                    tri_pos[b * n + x] = first + ns + k
    for k in range(count):
        tri_order[block + k] = tri_list[lists + block + k] - first


class TreeBuild:
    """Median-split trees of every shape of a scene, built by kernels on its device.

    A layout (:meth:`layout`) is computed once per distinct triangle count and shared by the
    shapes of that count (``shape_layout``); the triangle order (:meth:`order`) per shape, from the
    shapes' own vertices at first, and again from any vertices (a deforming mesh's world vertices)
    on request, in the same arrays.

    Args:
        shape_triangle: ``(T,)`` ``wp.vec3i`` shape-local vertex indices of all shapes' triangles.
        shape_triangle_start: ``(S + 1,)`` int numpy offsets of each shape's triangles (each shape
            has at least one).
        leaf_size: most triangles per leaf.
        cut_depth: least level of the first of the two cuts each layout keeps (see
            :class:`ShapeTree`); big trees cut deeper (:meth:`TreeSizes.cut_depth`).
        cut_triangles: most triangles, about, of a cut's subtree in a big tree (:data:`CUT_TRIANGLES`).
        small: largest subtree finished by one block (``finish="block"``, default and at most
            :data:`~warp_ccd._src.trees.build_block.BLOCK_SUBTREE`) or one thread (default
            :data:`SMALL_SUBTREE` on CUDA, whole shapes on the CPU); at least ``2 * leaf_size``.
        presort: radix-sort the lists before the splits (default: when some shape is split level by
            level, and with ``finish="thread"`` when some shape has more than
            :data:`INSERTION_SORT_MAX` triangles; blocks read no lists of their own, so ``True``
            with blocks and no level split only costs the sorts). Limits of the blocks: one shape
            above ``small`` makes the whole scene's lists sorted and split level by level, and one
            launch has one block size, that of its largest subtree (a 200-triangle shape among
            20-triangle ones: every block of 256 threads).
        finish: ``"block"`` (default on CUDA where ``small`` and ``2 * leaf_size`` are at most
            :data:`~warp_ccd._src.trees.build_block.BLOCK_SUBTREE`): each subtree of at most ``small`` triangles
            finished
            by a thread block in shared memory (:mod:`~warp_ccd._src.trees.build_block`; on the CPU only
            with ``wp.config.enable_cpu_blocks``); ``"thread"`` (default on the CPU): by one thread.
        device: Warp device.

    Attributes:
        sizes: the :class:`TreeSizes` of the shapes (made on first use); ``layout_sizes`` those of
            the layouts.
        shape_layout: ``(S,)`` numpy layout of each shape.
        layout_node_start, layout_leaf_start, layout_inner_start, layout_cut_start: numpy offsets
            (``L + 1`` entries; ``2 L + 1`` for the cuts, two per layout), and ``*_device`` copies.
        node_child, node_parent, node_triangle, node_leaf, leaf_node, inner_node, cut_node: device
            arrays of the layouts (local ids); ``tri_order``: ``(T,)`` of the shapes.
    """

    def __init__(self, shape_triangle, shape_triangle_start, *, leaf_size: int = 1, cut_depth: int = 3,
                 cut_triangles: int = CUT_TRIANGLES, small: int | None = None, presort: bool | None = None,
                 finish: str | None = None, device=None):
        self.device = wp.get_device(device)
        d = self.device
        tstart = np.asarray(shape_triangle_start, np.int64)
        m = np.diff(tstart)
        if (m < 1).any():
            raise ValueError(f"shape {int(np.argmax(m < 1))}: a tree needs at least one triangle")
        self.num_triangles = int(tstart[-1])
        if 6 * self.num_triangles >= 2**31:  # six lists of them (two halves of three axes), int32 indices
            raise ValueError(f"scene too large for the tree build: {self.num_triangles} shape triangles "
                             f"(limit {(2**31 - 1) // 6})")
        self.leaf_size = int(leaf_size)
        self.cut_depth = int(cut_depth)
        if finish is None:  # blocks on CUDA, where their subtrees fit (leaves of up to 128, small up to 256)
            fits = max(int(small or 0), 2 * self.leaf_size) <= BLOCK_SUBTREE
            finish = "block" if d.is_cuda and fits else "thread"
        if finish not in ("block", "thread"):
            raise ValueError(f"finish must be 'block' or 'thread', got {finish!r}")
        if finish == "block":
            require_lanes(d, "else a block is one lane")
        self.finish = finish
        if small is None:
            small = BLOCK_SUBTREE if finish == "block" else SMALL_SUBTREE if d.is_cuda else 2**31 - 1
        self.small = max(int(small), 2 * self.leaf_size)
        if finish == "block" and self.small > BLOCK_SUBTREE:
            raise ValueError(f"small: a block finishes subtrees of at most {BLOCK_SUBTREE} triangles, "
                             f"got {self.small} (leaf_size {self.leaf_size})")
        self.shape_layout, layout_m = _distinct(m)
        self.layout_sizes = sizes = TreeSizes(layout_m, self.leaf_size)

        def offsets(counts):
            return np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)

        self.layout_node_start = offsets(sizes.num_nodes)
        if self.layout_node_start[-1] >= 2**31:
            raise ValueError(f"scene too large for the tree build: {self.layout_node_start[-1]} tree nodes")
        self.layout_leaf_start = offsets(sizes.num_leaves)
        self.layout_inner_start = offsets(sizes.num_inner)
        self.layout_cut_depth = sizes.cut_depth(self.cut_depth, cut_triangles)
        cuts = np.stack([sizes.cut_size(self.layout_cut_depth), sizes.cut_size(self.layout_cut_depth + 1)],
                        axis=1).reshape(-1)
        self.layout_cut_start = offsets(cuts)
        # Levels split over all shapes at once: until the nodes hold at most `small` triangles.
        layout_levels = _bit_length((layout_m + self.small - 1) // self.small - 1)
        self.global_levels = layout_levels[self.shape_layout]
        self.num_global_levels = int(layout_levels.max()) if len(m) else 0
        # Threads a block: the largest subtree left (ceil(m / 2**levels) triangles).
        largest = int((-(-layout_m // (np.int64(1) << layout_levels))).max()) if len(m) else 1
        self.block_dim = subtree_block_dim(largest) if finish == "block" else 0
        subtree_end = np.cumsum(np.int64(1) << self.global_levels)
        self.num_subtrees = int(subtree_end[-1]) if len(m) else 0

        self.shape_triangle = shape_triangle
        self.shape_triangle_start = tstart
        # Every small per-shape and per-layout array in one upload (one copy, not ten).
        (self._tstart, self._global_levels, self._subtree_end, self._layout_m, self.shape_layout_device,
         self.layout_node_start_device, self.layout_leaf_start_device, self.layout_inner_start_device,
         self.layout_cut_start_device, self._layout_cut_depth) = packed_upload(
            [tstart, self.global_levels, subtree_end, layout_m, self.shape_layout, self.layout_node_start,
             self.layout_leaf_start, self.layout_inner_start, self.layout_cut_start, self.layout_cut_depth], d)
        k = int(self.layout_node_start[-1])
        n = self.num_triangles
        self.node_child = wp.empty(k, dtype=wp.vec2i, device=d)
        self.node_parent = wp.empty(k, dtype=wp.int32, device=d)
        self.node_triangle = wp.empty(k, dtype=wp.vec2i, device=d)
        self.node_leaf = wp.empty(k, dtype=wp.vec2i, device=d)
        self.leaf_node = wp.empty(int(self.layout_leaf_start[-1]), dtype=wp.int32, device=d)
        self.inner_node = wp.empty(int(self.layout_inner_start[-1]), dtype=wp.int32, device=d)
        self.cut_node = wp.empty(int(self.layout_cut_start[-1]), dtype=wp.int32, device=d)
        self.tri_order = wp.empty(n, dtype=wp.int32, device=d)
        # Scratch of the order: keys; with lists (levels split over all shapes, or subtrees finished
        # by a thread), each triangle's shape, two halves of three lists, positions, and one block
        # shared by the sorts' keys and values and, after the sorts, the split sides and their scan.
        if presort is None:
            presort = finish == "thread" and len(m) > 0 and int(m.max()) > INSERTION_SORT_MAX
        self.presort = bool(presort) or bool(self.num_global_levels)
        self._lists = self.presort or finish == "thread"
        ln = n if self._lists else 0
        self._tri_key = wp.empty(n, dtype=wp.vec3, device=d)
        self._tri_shape = wp.empty(ln, dtype=wp.int32, device=d)
        self._tri_list = wp.empty(6 * ln, dtype=wp.int32, device=d)
        self._tri_pos = wp.empty(3 * ln, dtype=wp.int32, device=d)
        self._side = self._side_before = self._sort_key = self._sort_value = self._node_axis = None
        if self.presort and n:
            self._scratch = wp.empty(6 * n, dtype=wp.int32, device=d)
            self._side, self._side_before = self._scratch[: 3 * n], self._scratch[3 * n:]
            self._sort_key = wp.array(ptr=self._scratch.ptr, dtype=wp.uint64, shape=(2 * n,), device=d)
            self._sort_value = self._scratch[4 * n:]
            self._node_axis = self._side_before[:n]  # a level's axes: read by the side kernel, then scanned over
            self._key_bits = wp.array(ptr=self._tri_key.ptr, dtype=wp.uint32, shape=(3 * n,), device=d)
        self._sort_bits = 32 + int(_bit_length(np.array([max(len(m) - 1, 0)]))[0])

    @cached_property
    def sizes(self) -> TreeSizes:
        """The :class:`TreeSizes` of every shape (gathered from its layout's on first use)."""
        return self.layout_sizes.take(self.shape_layout)

    def layout(self) -> None:
        """Launches the layouts (one thread per node of each distinct triangle count)."""
        k = int(self.layout_node_start[-1])
        if k == 0:
            return
        wp.launch(_layout_kernel, dim=k,
                  inputs=[self._layout_m, self.layout_node_start_device, self.layout_leaf_start_device,
                          self.layout_inner_start_device, self.layout_cut_start_device, self._layout_cut_depth,
                          self.leaf_size],
                  outputs=[self.node_child, self.node_parent, self.node_triangle, self.node_leaf, self.leaf_node,
                           self.inner_node, self.cut_node],
                  device=self.device)

    def order(self, shape_vertex, shape_vertex_start, world_vertex=None, shape_world_start=None) -> None:
        """Launches the build of every shape's triangle order (:attr:`tri_order`).

        Args:
            shape_vertex: the shapes' vertices (``wp.vec3`` or ``wp.vec3d``), ``shape_vertex_start``
                (``(S + 1,)`` int32 device array) their offsets.
            world_vertex: optional vertices of the same type to build from instead: shape ``s``
                reads its vertices at ``shape_world_start[s]`` (``(S,)`` int32 device array) there,
                or its own where that is -1.
        """
        n = self.num_triangles
        if n == 0:
            return
        d = self.device
        if self.finish == "block":
            require_lanes(d, "turned off since the build was made")
        use_world = int(world_vertex is not None)
        if world_vertex is None:
            world_vertex, shape_world_start = shape_vertex, self._tstart  # not read
        precision = "float64" if shape_vertex.dtype == wp.vec3d else "float32"
        wp.launch(_KEY[precision], dim=n,
                  inputs=[shape_vertex, shape_vertex_start, world_vertex, shape_world_start, self.shape_triangle,
                          self._tstart, n, int(self._lists), use_world],
                  outputs=[self._tri_shape, self._tri_key, self._tri_list], device=d)
        if self.presort:
            for axis in range(3):  # each list sorted by shape, then key (stable: then by triangle)
                wp.launch(_axis_key_kernel, dim=n, inputs=[self._key_bits, self._tri_shape, axis],
                          outputs=[self._sort_key, self._sort_value], device=d)
                wp.utils.radix_sort_pairs(self._sort_key, self._sort_value, n, end_bit=self._sort_bits)
                wp.launch(_store_list_kernel, dim=n, inputs=[self._sort_value, axis, n],
                          outputs=[self._tri_list, self._tri_pos], device=d)
        if self.num_global_levels:
            for level in range(self.num_global_levels):
                common = [level, n, self._tri_shape, self._tstart, self._global_levels]
                wp.launch(_node_axis_kernel, dim=n, inputs=[*common, self._tri_key, self._tri_list],
                          outputs=[self._node_axis], device=d)
                wp.launch(_split_side_kernel, dim=3 * n,
                          inputs=[*common, self._node_axis, self._tri_list, self._tri_pos],
                          outputs=[self._side], device=d)
                wp.utils.array_scan(self._side, self._side_before, inclusive=False)
                wp.launch(_split_scatter_kernel, dim=3 * n, inputs=[*common, self._side, self._side_before],
                          outputs=[self._tri_list, self._tri_pos], device=d)
        if self.finish == "block":
            finish_blocks(self.num_subtrees, self.block_dim, n, self.leaf_size, self._tstart, self._global_levels,
                          self._subtree_end, self._tri_key, self._tri_list, self._tri_pos, self.presort, self.tri_order,
                          d)
        else:
            wp.launch(_finish_kernel, dim=self.num_subtrees,
                      inputs=[n, self.leaf_size, self._tstart, self._global_levels, self._subtree_end, self._tri_key],
                      outputs=[self._tri_list, self._tri_pos, self.tri_order], device=d)

    def shape_tree(self, s: int) -> ShapeTree:
        """Shape ``s``'s tree as host arrays (reads the device; for tests and inspection)."""
        layout = int(self.shape_layout[s])
        a, b = int(self.layout_node_start[layout]), int(self.layout_node_start[layout + 1])
        t0, t1 = int(self.shape_triangle_start[s]), int(self.shape_triangle_start[s + 1])
        levels = int(self.layout_sizes.num_levels[layout])
        level_start = np.array([(1 << d) - 1 for d in range(levels)] + [b - a], np.int32)
        return ShapeTree(self.node_child.numpy()[a:b].astype(np.int32), self.node_parent.numpy()[a:b],
                         self.node_triangle.numpy()[a:b].astype(np.int32), self.tri_order.numpy()[t0:t1],
                         level_start)
