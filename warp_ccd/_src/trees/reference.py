"""The numpy reference of the tree builds, one shape at a time on the host, and the tree it returns.

:func:`build_tree` makes the median-split tree that :class:`~warp_ccd._src.trees.build.TreeBuild` builds
for every shape at once in kernels (layout and node order described there): same centroid keys
(:func:`centroid_keys`), same layout, same triangle order, bit for bit; tests compare them.
:class:`ShapeTree` holds one shape's tree on the host, from either.
"""

import numpy as np

__all__ = ["ShapeTree", "build_tree", "centroid_keys"]


def centroid_keys(vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Sort keys of the triangles' centroids, as the build kernels compute them: ``(v0 / 4 + v1 / 4)
    + v2 / 4`` in float32 (three quarters of the centroid; no overflow, ``-0`` made ``+0``).

    Returns:
        ``(m, 3)`` float32.
    """
    v = np.asarray(vertices).astype(np.float32)
    t = np.asarray(triangles)
    q = np.float32(0.25)
    return ((v[t[:, 0]] * q + v[t[:, 1]] * q) + v[t[:, 2]] * q) + np.float32(0.0)


class ShapeTree:
    """The tree of one shape (host arrays; layout: :mod:`~warp_ccd._src.trees.build`).

    Attributes:
        node_child: ``(K, 2)`` int32 children (local node ids), ``-1`` for leaves.
        node_parent: ``(K,)`` int32 parent, ``-1`` at the root.
        node_triangle: ``(K, 2)`` int32 ``(start, count)`` into ``tri_order``.
        tri_order: ``(m,)`` int32 triangle ids, each subtree contiguous.
        level_start: ``(D + 1,)`` int32 first node of each level (breadth-first order).
        depth: ``D``, the number of levels.
        leaf_node: ``(L,)`` int32 the leaves, in the order of their triangles in ``tri_order``.
        node_leaf: ``(K, 2)`` int32 ``(first, count)``: the node's subtree holds the leaves
            ``leaf_node[first:first + count]``.
        inner_node: ``(K - L,)`` int32 the inner nodes.
        node_depth: ``(K,)`` int32 level of each node (the root's is 0).
    """

    def __init__(self, node_child, node_parent, node_triangle, tri_order, level_start):
        self.node_child = node_child
        self.node_parent = node_parent
        self.node_triangle = node_triangle
        self.tri_order = tri_order
        self.level_start = level_start
        self.depth = len(level_start) - 1
        is_leaf = node_child[:, 0] < 0
        leaves = np.nonzero(is_leaf)[0]
        leaf_start = node_triangle[leaves, 0]
        order = np.argsort(leaf_start, kind="stable")
        self.leaf_node = leaves[order].astype(np.int32)
        leaf_start = leaf_start[order]
        first = np.searchsorted(leaf_start, node_triangle[:, 0], side="left")
        end = np.searchsorted(leaf_start, node_triangle[:, 0] + node_triangle[:, 1], side="left")
        self.node_leaf = np.stack([first, end - first], axis=1).astype(np.int32)
        self.inner_node = np.nonzero(~is_leaf)[0].astype(np.int32)
        self.node_depth = (np.searchsorted(level_start, np.arange(len(node_child)), side="right") - 1).astype(np.int32)

    def cut(self, depth: int) -> np.ndarray:
        """The nodes at level ``depth`` and the leaves above it: subtrees that partition the
        leaves, at most ``2**depth`` of them (all leaves when the tree is shallower).

        Returns:
            ``(C,)`` int32 local node ids, in breadth-first order.
        """
        is_leaf = self.node_child[:, 0] < 0
        return np.nonzero((self.node_depth == depth) | (is_leaf & (self.node_depth < depth)))[0].astype(np.int32)

    @property
    def num_nodes(self) -> int:
        return len(self.node_child)


def build_tree(vertices: np.ndarray, triangles: np.ndarray, leaf_size: int = 1) -> ShapeTree:
    """Median-split tree of one triangle mesh: the reference of the build kernels (host, numpy,
    vectorised level by level).

    Triangles are presorted by centroid key (:func:`centroid_keys`) along each axis once;
    splitting a level is a stable partition of the three sorted lists.

    Args:
        vertices: ``(n, 3)`` positions.
        triangles: ``(m, 3)`` vertex indices, ``m >= 1``.
        leaf_size: largest number of triangles in a leaf.

    Returns:
        The :class:`ShapeTree`.
    """
    centroid = np.ascontiguousarray(centroid_keys(vertices, triangles).T)  # (3, m): one row per axis
    m = centroid.shape[1]
    # One list per axis, sorted by centroid on that axis; all three grouped by node, same blocks.
    lists = [np.argsort(centroid[a], kind="stable").astype(np.int32) for a in range(3)]

    child, parent, tri_range, level_start = [], [], [], [0]
    # Nodes of the current level: start, count (their block in the lists), parent id.
    cur_start = np.array([0], np.int32)
    cur_count = np.array([m], np.int32)
    cur_parent = np.array([-1], np.int64)
    next_id = 1
    while len(cur_start):
        k = len(cur_start)
        base = next_id - k  # id of the first node of this level
        split = cur_count > leaf_size
        # Children ids, breadth-first: the split nodes' children in order.
        nsplit = int(split.sum())
        first_child = np.full(k, -1, np.int64)
        first_child[split] = next_id + 2 * np.arange(nsplit)
        node_child = np.stack([first_child, np.where(split, first_child + 1, -1)], axis=1)
        child.append(node_child)
        parent.append(cur_parent)
        tri_range.append(np.stack([cur_start, cur_count], axis=1))
        next_id += 2 * nsplit
        level_start.append(next_id - 2 * nsplit)
        if nsplit == 0:
            break
        # Items of the split nodes in "item space": their blocks back to back.
        sp_start = cur_start[split]
        sp_count = cur_count[split]
        sp_left = sp_count // 2
        item_first = np.cumsum(sp_count) - sp_count
        node_of = np.repeat(np.arange(nsplit, dtype=np.int32), sp_count)
        rank = np.arange(int(sp_count.sum()), dtype=np.int32) - item_first[node_of]  # rank within the node block
        start_of = sp_start[node_of]
        pos = start_of + rank  # list position of each item
        left_of = sp_left[node_of]
        # Longest axis of the bounds of each node's centroids: the first and last of its block in
        # each sorted list (O(nodes), where the bounds of the triangles themselves cost O(m)).
        last = sp_start + sp_count - 1
        extent = np.stack([centroid[a][lists[a][last]] - centroid[a][lists[a][sp_start]] for a in range(3)], axis=1)
        node_axis = np.argmax(extent, axis=1)
        axis_of = node_axis[node_of]
        # Side of each triangle: right when its rank along its node's axis reaches the median.
        right_side = rank >= left_of
        segs = [lists[a][pos] for a in range(3)]  # triangles of the items, in each list's order
        side = np.zeros(m, np.bool_)
        for a in range(3):
            mine = axis_of == a
            side[segs[a][mine]] = right_side[mine]
        # Stable partition of each sorted list within each split node: left block, then right.
        for a in range(3):
            seg = segs[a]
            right = side[seg]
            before = np.cumsum(right, dtype=np.int32)
            before -= right
            c1 = before - before[item_first][node_of]  # right items before this one in its node
            lists[a][np.where(right, start_of + left_of + c1, pos - c1)] = seg
        # Next level: children of split nodes.
        pid = (base + np.arange(k))[split]
        cur_start = np.stack([sp_start, sp_start + sp_left], axis=1).reshape(-1)
        cur_count = np.stack([sp_left, sp_count - sp_left], axis=1).reshape(-1)
        cur_parent = np.repeat(pid, 2)
    node_child = np.concatenate(child).astype(np.int32)
    node_parent = np.concatenate(parent).astype(np.int32)
    node_triangle = np.concatenate(tri_range).astype(np.int32)
    tri_order = lists[0].astype(np.int32)
    return ShapeTree(node_child, node_parent, node_triangle, tri_order, np.asarray(level_start, np.int32))
