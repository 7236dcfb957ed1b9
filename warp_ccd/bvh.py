"""Bounding-volume trees: built once per shape (median split), refit per instance every frame.

Build (host, numpy, once per shape, vectorised level by level): the root holds all triangles;
each node with more than ``leaf_size`` triangles is split at the median of its triangles'
centroids along the longest axis of its bounds, so the tree is balanced with
``ceil(log2(m / leaf_size)) + 1`` levels. Triangles are presorted by centroid along each axis
once; splitting a level is then a stable partition of the three sorted lists (O(m) per level,
O(m log m) in all; 1.5 s for a 1.3M-triangle shape on one CPU core).

Stored flat, topology shared by every instance of a shape:

* nodes in breadth-first order (a node's children are on the next level),
  :attr:`ShapeTree.level_start` gives each level's first node, so refit can run level by level from the deepest up;
* ``node_child`` ``(left, right)`` or ``(-1, -1)`` for a leaf, ``node_parent`` (-1 at the root);
* ``node_triangle`` ``(start, count)``: the node's triangles are ``tri_order[start:start + count]``
  (every subtree is one contiguous range).

Refit (device, every frame): per instance, node bounds ``node_lower`` / ``node_upper`` at
``instance_node_start[i] + node``. Leaf boxes come from the world vertices of their triangles,
padded by the narrow phase's tolerance times their longest edge; inner boxes are the union of
their children. Instances of small trees (up to 255 nodes: polyhedra, 80-triangle spheres) are
refit in two launches: one thread per leaf of every such instance, then one thread per inner node
(the union of the leaf boxes of its subtree, which the leaf order makes a contiguous run of
:attr:`ShapeTree.leaf_node`): no thread walks a whole tree, so a few hundred objects still fill
the GPU in a few microseconds. Bigger trees one launch
per level, deepest first, one thread per (instance, node), so a few big meshes still spread over
the whole device.
The root's box is the object's AABB: no separate bounds pass. Deforming meshes need nothing else:
the caller writes world vertices, refit does the rest.
"""


from typing import Any

import numpy as np
import warp as wp

from .aabb import BOX_EMPTY, box_lower32, box_upper32
from .buffers import upper_bound
from .precision import PRECISIONS, precision_types
from .scene import MeshTopology, mesh_triangle

wp.set_module_options({"enable_backward": False})  # forward kernels only

LEAF_SIZE_MAX = 256
"""Most triangles per leaf: a traversal thread emits up to 16 leaf pairs of ``leaf_size**2``
rows at once and its block of 256 counts them in int32 (:func:`~warp_ccd.buffers.block_reserve`)."""

__all__ = ["SceneBVH", "ShapeTree", "TreeView", "build_tree"]


class ShapeTree:
    """The tree of one shape (host arrays).

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
    """Median-split tree of one triangle mesh.

    Args:
        vertices: ``(n, 3)`` positions.
        triangles: ``(m, 3)`` vertex indices, ``m >= 1``.
        leaf_size: largest number of triangles in a leaf.

    Returns:
        The :class:`ShapeTree`.
    """
    v = np.asarray(vertices, np.float64)
    tri = v[np.asarray(triangles)]
    m = tri.shape[0]
    centroid = np.ascontiguousarray(tri.mean(axis=1).T)  # (3, m): one contiguous row per axis
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


@wp.struct
class TreeView:
    """What the refit and traversal kernels need: topology per shape, bounds per instance.

    Per shape ``s``, its nodes are ``shape_node_start[s] + local id``, its leaves (shape-local
    ids) ``leaf_node[shape_leaf_start[s]:shape_leaf_start[s + 1]]`` and its two cuts (subtrees
    that partition the leaves, :meth:`ShapeTree.cut`), at the scene's ``cut_depth`` and one level
    deeper: ``cut_node[shape_cut_start[2 s + deep]:shape_cut_start[2 s + deep + 1]]``; the bounds
    of instance ``i`` are ``node_lower/upper[instance_node_start[i] + local id]``.
    """

    shape_node_start: wp.array[wp.int32]
    shape_tri_order_start: wp.array[wp.int32]
    shape_leaf_start: wp.array[wp.int32]
    node_child: wp.array[wp.vec2i]
    node_triangle: wp.array[wp.vec2i]
    node_leaf: wp.array[wp.vec2i]
    leaf_node: wp.array[wp.int32]
    shape_cut_start: wp.array[wp.int32]
    cut_node: wp.array[wp.int32]
    tri_order: wp.array[wp.int32]
    instance_node_start: wp.array[wp.int32]
    node_lower: wp.array[wp.vec3]
    node_upper: wp.array[wp.vec3]


@wp.func
def _refit_node(
    mesh: MeshTopology,
    world_vertex: wp.array[Any],
    tree: TreeView,
    s: int,
    inst: int,
    node: int,
    margin_rel: Any,
    instance_lower: wp.array[wp.vec3],
    instance_upper: wp.array[wp.vec3],
):
    """Box of ``node`` (local id in shape ``s``) of instance ``inst``: from its triangles (leaf,
    padded by the tolerance) or its children's boxes; the root's box is the object's box."""
    shape_node = tree.shape_node_start[s] + node
    slot = tree.instance_node_start[inst] + node
    child = tree.node_child[shape_node]
    lo = wp.vec3(0.0)
    hi = wp.vec3(0.0)
    if child[0] < 0:
        rng = tree.node_triangle[shape_node]
        base = tree.shape_tri_order_start[s]
        lo = wp.vec3(BOX_EMPTY)
        hi = wp.vec3(-BOX_EMPTY)
        for k in range(rng[0], rng[0] + rng[1]):
            a, b, c = mesh_triangle(mesh, world_vertex, inst, tree.tri_order[base + k])
            edge = wp.max(wp.max(wp.length(b - a), wp.length(c - b)), wp.length(a - c))
            pad = type(a)(margin_rel * edge, margin_rel * edge, margin_rel * edge)
            lo = wp.min(lo, box_lower32(wp.min(wp.min(a, b), c) - pad))
            hi = wp.max(hi, box_upper32(wp.max(wp.max(a, b), c) + pad))
    else:
        base_slot = tree.instance_node_start[inst]
        lo = wp.min(tree.node_lower[base_slot + child[0]], tree.node_lower[base_slot + child[1]])
        hi = wp.max(tree.node_upper[base_slot + child[0]], tree.node_upper[base_slot + child[1]])
    tree.node_lower[slot] = lo
    tree.node_upper[slot] = hi
    if node == 0:
        instance_lower[inst] = lo
        instance_upper[inst] = hi


@wp.kernel
def _refit_level_kernel(
    mesh: MeshTopology,
    world_vertex: wp.array[Any],
    tree: TreeView,
    block_start: wp.array[wp.int32],
    level_first: wp.array[wp.int32],
    level_count: wp.array[wp.int32],
    shape_instance: wp.array[wp.int32],
    shape_instance_start: wp.array[wp.int32],
    margin_rel: Any,
    # Outputs
    instance_lower: wp.array[wp.vec3],
    instance_upper: wp.array[wp.vec3],
):
    """One thread per (instance, node of this level): leaf box from triangles, else children union.

    Work items are laid out shape by shape: shape ``s`` owns ``block_start[s] .. block_start[s+1]``
    (its instances times its nodes on this level).
    """
    t = wp.tid()
    s = upper_bound(block_start, 0, block_start.shape[0], t) - 1  # last s with block_start[s] <= t
    local = t - block_start[s]
    cnt = level_count[s]
    inst = shape_instance[shape_instance_start[s] + local / cnt]
    node = level_first[s] + local % cnt
    _refit_node(mesh, world_vertex, tree, s, inst, node, margin_rel, instance_lower, instance_upper)


@wp.func
def _small_item(
    t: int,
    small_end: wp.array[wp.int32],
    small_instance: wp.array[wp.int32],
    instance_shape: wp.array[wp.int32],
    shape_start: wp.array[wp.int32],
):
    """Flat work item ``t`` over the small instances, ``small_end`` the inclusive scan of their
    per-shape item counts (``shape_start`` offsets per shape): ``(instance, shape, index of the
    item in the shapes' concatenated list)``."""
    k = upper_bound(small_end, 0, small_end.shape[0], t)
    inst = small_instance[k]
    s = instance_shape[inst]
    first = shape_start[s]
    return inst, s, first + t - (small_end[k] - (shape_start[s + 1] - first))


@wp.kernel
def _refit_small_leaf_kernel(
    mesh: MeshTopology,
    world_vertex: wp.array[Any],
    tree: TreeView,
    small_instance: wp.array[wp.int32],
    small_leaf_end: wp.array[wp.int32],
    margin_rel: Any,
    # Outputs
    instance_lower: wp.array[wp.vec3],
    instance_upper: wp.array[wp.vec3],
):
    """One thread per leaf of each instance of a small shape: the leaf's box from its triangles.
    ``small_leaf_end`` is the inclusive scan of the leaf counts of ``small_instance``."""
    inst, s, item = _small_item(wp.tid(), small_leaf_end, small_instance, mesh.instance_shape, tree.shape_leaf_start)
    node = tree.leaf_node[item]
    _refit_node(mesh, world_vertex, tree, s, inst, node, margin_rel, instance_lower, instance_upper)


@wp.kernel
def _refit_small_inner_kernel(
    tree: TreeView,
    instance_shape: wp.array[wp.int32],
    small_instance: wp.array[wp.int32],
    small_inner_end: wp.array[wp.int32],
    shape_inner_start: wp.array[wp.int32],
    inner_node: wp.array[wp.int32],
    # Outputs
    instance_lower: wp.array[wp.vec3],
    instance_upper: wp.array[wp.vec3],
):
    """One thread per inner node of each instance of a small shape, after the leaves: the union
    of the boxes of the leaves of its subtree (the same bits as the union of its children's)."""
    inst, s, item = _small_item(wp.tid(), small_inner_end, small_instance, instance_shape, shape_inner_start)
    node = inner_node[item]
    leaves = tree.node_leaf[tree.shape_node_start[s] + node]
    leaf_base = tree.shape_leaf_start[s]
    slot = tree.instance_node_start[inst]
    lo = wp.vec3(BOX_EMPTY)
    hi = wp.vec3(-BOX_EMPTY)
    for j in range(leaves[0], leaves[0] + leaves[1]):
        leaf = slot + tree.leaf_node[leaf_base + j]
        lo = wp.min(lo, tree.node_lower[leaf])
        hi = wp.max(hi, tree.node_upper[leaf])
    tree.node_lower[slot + node] = lo
    tree.node_upper[slot + node] = hi
    if node == 0:
        instance_lower[inst] = lo
        instance_upper[inst] = hi


for _precision in PRECISIONS:
    _scalar, _vec3, _, _ = precision_types(_precision)
    for _kernel in (_refit_level_kernel, _refit_small_leaf_kernel):
        wp.overload(_kernel, {"world_vertex": wp.array[_vec3], "margin_rel": _scalar})


class SceneBVH:
    """Trees of all shapes of a scene, and per-instance node bounds refit every frame.

    Args:
        scene: the :class:`~warp_ccd.scene.Scene`.
        leaf_size: largest number of triangles per leaf.
        margin_rel: leaf padding relative to the triangle's longest edge (the narrow phase's
            tolerance, so that tree culling never rejects a pair the narrow phase accepts).
        instance_refit_max_nodes: instances of shapes with at most this many nodes are refit in
            two launches, leaves then inner nodes (an inner node reads all its leaves); bigger trees
            are refit level by level, one thread per node.
        cut_depth: level of each tree's cut (:meth:`ShapeTree.cut`, at most ``2**cut_depth``
            subtrees), where the traversal starts its descents; the trees also keep the cut one
            level deeper, for frames with little work (:class:`~warp_ccd.mid_phase.MidPhaseBVH`).

    Attributes:
        lower, upper: ``(N,)`` object AABBs (the roots), written by :meth:`refit`.
        tree: the :class:`TreeView` struct for kernels.
        trees: per-shape :class:`ShapeTree` (host).
    """

    def __init__(self, scene, *, leaf_size: int = 1, margin_rel: float = 0.0, instance_refit_max_nodes: int = 255,
                 cut_depth: int = 3):
        if not 1 <= leaf_size <= LEAF_SIZE_MAX:
            raise ValueError(f"leaf_size must lie in [1, {LEAF_SIZE_MAX}], got {leaf_size}")
        if isinstance(cut_depth, bool) or not isinstance(cut_depth, (int, np.integer)) or not 0 <= cut_depth <= 16:
            raise ValueError(f"cut_depth must be an integer in [0, 16], got {cut_depth!r}")
        self.device = scene.device
        self.margin_rel = float(margin_rel)
        self.leaf_size = int(leaf_size)
        d = self.device
        self.trees = [build_tree(v, t, leaf_size) for v, t in scene.shape_meshes]
        num_shapes = len(self.trees)
        n = scene.num_objects
        nodes = np.array([tr.num_nodes for tr in self.trees], np.int64)
        self.shape_node_start_np = np.concatenate([[0], np.cumsum(nodes)]).astype(np.int32)
        inst_nodes = nodes[scene.instance_shape_np] if n else np.zeros(0, np.int64)
        inode = np.concatenate([[0], np.cumsum(inst_nodes)])
        if inode[-1] >= 2**31:
            raise ValueError(f"scene too large for the BVH: {inode[-1]} tree nodes (limit 2**31 - 1)")
        self.num_node_slots = int(inode[-1])
        self.max_depth = max((tr.depth for tr in self.trees), default=0)

        # Instances of small trees: a thread per leaf, then per inner node. The others grouped by
        # shape, and per level the work blocks of each shape.
        small = nodes <= instance_refit_max_nodes
        is_small = small[scene.instance_shape_np] if n else np.zeros(0, bool)
        small_instance = np.nonzero(is_small)[0].astype(np.int32)
        self.small_instance = wp.array(small_instance, dtype=wp.int32, device=d)
        leaves = np.array([len(tr.leaf_node) for tr in self.trees], np.int64)
        inner = nodes - leaves
        small_shape = scene.instance_shape_np[small_instance]
        small_leaf_end = np.cumsum(leaves[small_shape])
        small_inner_end = np.cumsum(inner[small_shape])
        self.num_small_leaves = int(small_leaf_end[-1]) if len(small_leaf_end) else 0
        self.num_small_inner = int(small_inner_end[-1]) if len(small_inner_end) else 0
        if max(self.num_small_leaves, self.num_small_inner) >= 2**31:
            raise ValueError("scene too large for the BVH refit (2**31 tree nodes of small shapes)")
        self.small_leaf_end = wp.array(small_leaf_end.astype(np.int32), dtype=wp.int32, device=d)
        self.small_inner_end = wp.array(small_inner_end.astype(np.int32), dtype=wp.int32, device=d)
        self.shape_inner_start = wp.array(np.concatenate([[0], np.cumsum(inner)]).astype(np.int32), device=d)
        self.inner_node = wp.array(np.concatenate([tr.inner_node for tr in self.trees]) if self.trees
                                   else np.zeros(0, np.int32), dtype=wp.int32, device=d)
        order = np.argsort(scene.instance_shape_np, kind="stable").astype(np.int32)
        per_shape = np.bincount(scene.instance_shape_np, minlength=num_shapes) if n else np.zeros(num_shapes, np.int64)
        per_shape = np.where(small, 0, per_shape)  # small shapes own no level work
        order = order[~is_small[order]] if n else order
        self.shape_instance = wp.array(order, dtype=wp.int32, device=d)
        self.shape_instance_start = wp.array(np.concatenate([[0], np.cumsum(per_shape)]).astype(np.int32), device=d)
        self.levels = []  # (items, block_start, level_first, level_count) per level
        for level in range(self.max_depth):
            first = np.array([tr.level_start[level] if level < tr.depth else 0 for tr in self.trees], np.int64)
            count = np.array(
                [tr.level_start[level + 1] - tr.level_start[level] if level < tr.depth else 0 for tr in self.trees],
                np.int64,
            )
            items = count * per_shape
            block = np.concatenate([[0], np.cumsum(items)])
            if block[-1] >= 2**31:
                raise ValueError("scene too large for the BVH refit (2**31 work items on one level)")
            self.levels.append((
                int(block[-1]),
                wp.array(block.astype(np.int32), device=d),
                wp.array(first.astype(np.int32), device=d),
                wp.array(np.maximum(count, 1).astype(np.int32), device=d),
            ))

        tv = TreeView()
        tv.shape_node_start = wp.array(self.shape_node_start_np, dtype=wp.int32, device=d)
        tri_len = np.array([len(tr.tri_order) for tr in self.trees], np.int64)
        tv.shape_tri_order_start = wp.array(np.concatenate([[0], np.cumsum(tri_len)]).astype(np.int32), device=d)

        def cat(xs, shape):
            return np.concatenate(xs) if xs else np.zeros(shape, np.int32)

        tv.node_child = wp.array(cat([tr.node_child for tr in self.trees], (0, 2)), dtype=wp.vec2i, device=d)
        tv.node_triangle = wp.array(cat([tr.node_triangle for tr in self.trees], (0, 2)), dtype=wp.vec2i, device=d)
        tv.node_leaf = wp.array(cat([tr.node_leaf for tr in self.trees], (0, 2)), dtype=wp.vec2i, device=d)
        tv.leaf_node = wp.array(cat([tr.leaf_node for tr in self.trees], (0,)), dtype=wp.int32, device=d)
        tv.shape_leaf_start = wp.array(np.concatenate([[0], np.cumsum(leaves)]).astype(np.int32), device=d)
        cuts = [tr.cut(int(cut_depth) + deep) for tr in self.trees for deep in (0, 1)]  # shape-major
        tv.shape_cut_start = wp.array(np.concatenate([[0], np.cumsum([len(c) for c in cuts])]).astype(np.int32),
                                      dtype=wp.int32, device=d)
        tv.cut_node = wp.array(cat(cuts, (0,)), dtype=wp.int32, device=d)
        self.cut_depth = int(cut_depth)
        tv.tri_order = wp.array(cat([tr.tri_order for tr in self.trees], (0,)), dtype=wp.int32, device=d)
        tv.instance_node_start = wp.array(inode.astype(np.int32), dtype=wp.int32, device=d)
        tv.node_lower = wp.zeros(self.num_node_slots, dtype=wp.vec3, device=d)
        tv.node_upper = wp.zeros(self.num_node_slots, dtype=wp.vec3, device=d)
        self.tree = tv
        self.lower = wp.zeros(n, dtype=wp.vec3, device=d)
        self.upper = wp.zeros(n, dtype=wp.vec3, device=d)

    @property
    def counters(self) -> list:
        """Buffers with counters that :meth:`refit` writes: none (its arrays have fixed sizes)."""
        return []

    def refit(self, scene) -> None:
        """Refits all node bounds (and the object boxes) from ``scene.world_vertex``: small trees
        in one launch, the others deepest level first."""
        margin = scene.scalar_type(self.margin_rel)
        if self.num_small_leaves:
            wp.launch(_refit_small_leaf_kernel, dim=self.num_small_leaves,
                      inputs=[scene.topology, scene.world_vertex, self.tree, self.small_instance, self.small_leaf_end,
                              margin],
                      outputs=[self.lower, self.upper], device=self.device)
        if self.num_small_inner:
            wp.launch(_refit_small_inner_kernel, dim=self.num_small_inner,
                      inputs=[self.tree, scene.instance_shape, self.small_instance, self.small_inner_end,
                              self.shape_inner_start, self.inner_node],
                      outputs=[self.lower, self.upper], device=self.device)
        for items, block, first, count in reversed(self.levels):
            if items == 0:
                continue
            wp.launch(
                _refit_level_kernel,
                dim=items,
                inputs=[scene.topology, scene.world_vertex, self.tree, block, first, count, self.shape_instance,
                        self.shape_instance_start, margin],
                outputs=[self.lower, self.upper],
                device=self.device,
            )
