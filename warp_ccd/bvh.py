"""Bounding-volume trees: built once per shape (median split), refit per instance every frame.

Build (kernels, all shapes at once: :mod:`warp_ccd.bvh_build`): the root holds all triangles;
each node with more than ``leaf_size`` triangles is split at the median of its triangles'
centroids along the longest axis of its bounds, so the tree is balanced with
``ceil(log2(m / leaf_size)) + 1`` levels. The layout follows from the triangle counts alone (one
thread per node); the triangle order from three centroid-sorted lists per shape, partitioned
level by level over all shapes, small subtrees finished one thread each.

Stored flat, topology shared by every instance of a shape (:class:`~warp_ccd.bvh_build.ShapeTree`
is one shape's tree on the host):

* nodes in breadth-first order (a node's children are on the next level; level ``d`` of a
  shape starts at node ``2**d - 1``), so refit can run level by level from the deepest up;
* ``node_child`` ``(left, right)`` or ``(-1, -1)`` for a leaf;
* ``node_triangle`` ``(start, count)``: the node's triangles are ``tri_order[start:start + count]``
  (every subtree is one contiguous range).

Refit (device, every frame): per instance, node bounds ``node_lower`` / ``node_upper`` at
``instance_node_start[i] + node``. Leaf boxes come from the world vertices of their triangles,
padded by the narrow phase's tolerance times their longest edge; inner boxes are the union of
their children. Instances of small trees (up to 255 nodes: polyhedra, 80-triangle spheres) are
refit in two launches: one thread per leaf of every such instance, then one thread per inner node
(the union of the leaf boxes of its subtree, which the leaf order makes a contiguous run of
:attr:`TreeView.leaf_node`): no thread walks a whole tree, so a few hundred objects still fill
the GPU in a few microseconds. Bigger trees one launch
per level, deepest first, one thread per (instance, node), so a few big meshes still spread over
the whole device.
The root's box is the object's AABB: no separate bounds pass. Deforming meshes need nothing else:
the caller writes world vertices, refit does the rest; :meth:`SceneBVH.rebuild` re-sorts their
triangles into the same layout when the refit boxes have loosened.
"""


from typing import Any

import numpy as np
import warp as wp

from .aabb import BOX_EMPTY, box_lower32, box_upper32
from .buffers import upper_bound
from .bvh_build import ShapeTree, TreeBuild, packed_upload
from .precision import precision_overloads
from .scene import MeshTopology, mesh_triangle

wp.set_module_options({"enable_backward": False})  # forward kernels only

LEAF_SIZE_MAX = 256
"""Most triangles per leaf: a traversal thread emits up to 16 leaf pairs of ``leaf_size**2``
rows at once and its block of 256 counts them in int32 (:func:`~warp_ccd.buffers.block_reserve`)."""

__all__ = ["SceneBVH", "TreeView"]


@wp.struct
class TreeView:
    """What the refit and traversal kernels need: layouts shared by the shapes of one triangle count,
    triangle order per shape, bounds per instance.

    Shape ``s`` has layout ``l = shape_layout[s]`` (a tree's layout depends on its triangle count
    alone, :mod:`warp_ccd.bvh_build`): its nodes are ``layout_node_start[l] + local id``, its
    leaves (local ids) ``leaf_node[layout_leaf_start[l]:layout_leaf_start[l + 1]]`` and its two
    cuts (subtrees that partition the leaves, :meth:`~warp_ccd.bvh_build.ShapeTree.cut`), at the
    scene's ``cut_depth`` and one level deeper: ``cut_node[layout_cut_start[2 l + deep]:
    layout_cut_start[2 l + deep + 1]]``; its triangle order starts at ``shape_tri_order_start[s]``;
    the bounds of instance ``i`` are ``node_lower/upper[instance_node_start[i] + local id]``.
    """

    shape_layout: wp.array[wp.int32]
    layout_node_start: wp.array[wp.int32]
    shape_tri_order_start: wp.array[wp.int32]
    layout_leaf_start: wp.array[wp.int32]
    node_child: wp.array[wp.vec2i]
    node_triangle: wp.array[wp.vec2i]
    node_leaf: wp.array[wp.vec2i]
    leaf_node: wp.array[wp.int32]
    layout_cut_start: wp.array[wp.int32]
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
    shape_node = tree.layout_node_start[tree.shape_layout[s]] + node
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
    shape_layout: wp.array[wp.int32],
    layout_start: wp.array[wp.int32],
):
    """Flat work item ``t`` over the small instances, ``small_end`` the inclusive scan of their
    per-layout item counts (``layout_start`` offsets per layout): ``(instance, shape, index of the
    item in the layouts' concatenated list)``."""
    k = upper_bound(small_end, 0, small_end.shape[0], t)
    inst = small_instance[k]
    s = instance_shape[inst]
    layout = shape_layout[s]
    first = layout_start[layout]
    return inst, s, first + t - (small_end[k] - (layout_start[layout + 1] - first))


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
    inst, s, item = _small_item(wp.tid(), small_leaf_end, small_instance, mesh.instance_shape, tree.shape_layout,
                                tree.layout_leaf_start)
    node = tree.leaf_node[item]
    _refit_node(mesh, world_vertex, tree, s, inst, node, margin_rel, instance_lower, instance_upper)


@wp.kernel
def _refit_small_inner_kernel(
    tree: TreeView,
    instance_shape: wp.array[wp.int32],
    small_instance: wp.array[wp.int32],
    small_inner_end: wp.array[wp.int32],
    layout_inner_start: wp.array[wp.int32],
    inner_node: wp.array[wp.int32],
    # Outputs
    instance_lower: wp.array[wp.vec3],
    instance_upper: wp.array[wp.vec3],
):
    """One thread per inner node of each instance of a small shape, after the leaves: the union
    of the boxes of the leaves of its subtree (the same bits as the union of its children's)."""
    inst, s, item = _small_item(wp.tid(), small_inner_end, small_instance, instance_shape, tree.shape_layout,
                                layout_inner_start)
    node = inner_node[item]
    layout = tree.shape_layout[s]
    leaves = tree.node_leaf[tree.layout_node_start[layout] + node]
    leaf_base = tree.layout_leaf_start[layout]
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


_REFIT_LEVEL, _REFIT_SMALL_LEAF = (
    precision_overloads(k, lambda s, v, q, t: {"world_vertex": wp.array[v], "margin_rel": s})
    for k in (_refit_level_kernel, _refit_small_leaf_kernel))


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
        cut_depth: level of each tree's cut (:meth:`~warp_ccd.bvh_build.ShapeTree.cut`, at most ``2**cut_depth``
            subtrees), where the traversal starts its descents; the trees also keep the cut one
            level deeper, for frames with little work (:class:`~warp_ccd.mid_phase.MidPhaseBVH`).
        small_subtree: largest subtree one thread of the build finishes alone (default: see
            :class:`~warp_ccd.bvh_build.TreeBuild`).

    Attributes:
        lower, upper: ``(N,)`` object AABBs (the roots), written by :meth:`refit`.
        tree: the :class:`TreeView` struct for kernels.
        build: the :class:`~warp_ccd.bvh_build.TreeBuild` that made the trees (device arrays).
    """

    def __init__(self, scene, *, leaf_size: int = 1, margin_rel: float = 0.0, instance_refit_max_nodes: int = 255,
                 cut_depth: int = 3, small_subtree: int | None = None):
        if not 1 <= leaf_size <= LEAF_SIZE_MAX:
            raise ValueError(f"leaf_size must lie in [1, {LEAF_SIZE_MAX}], got {leaf_size}")
        if isinstance(cut_depth, bool) or not isinstance(cut_depth, (int, np.integer)) or not 0 <= cut_depth <= 16:
            raise ValueError(f"cut_depth must be an integer in [0, 16], got {cut_depth!r}")
        self.device = scene.device
        self.margin_rel = float(margin_rel)
        self.leaf_size = int(leaf_size)
        self.cut_depth = int(cut_depth)
        d = self.device
        build = TreeBuild(scene.shape_triangle, scene.shape_triangle_start_np, leaf_size=leaf_size,
                          cut_depth=cut_depth, small=small_subtree, device=d)
        self.build = build
        build.layout()
        build.order(scene.shape_vertex, scene.shape_vertex_start)
        sizes = build.sizes
        num_shapes = scene.num_shapes
        n = scene.num_objects
        nodes = sizes.num_nodes
        inst_nodes = nodes[scene.instance_shape_np] if n else np.zeros(0, np.int64)
        inode = np.concatenate([[0], np.cumsum(inst_nodes)])
        if inode[-1] >= 2**31:
            raise ValueError(f"scene too large for the BVH: {inode[-1]} tree nodes (limit 2**31 - 1)")
        self.num_node_slots = int(inode[-1])
        self.max_depth = int(sizes.num_levels.max()) if num_shapes else 0
        # Where each shape's first instance's world vertices start, which a rebuild reads (-1: no
        # instance, the shape's own vertices).
        first = np.full(num_shapes, n, np.int64)
        np.minimum.at(first, scene.instance_shape_np, np.arange(n))
        world_start = np.full(num_shapes, -1, np.int64)
        has = first < n
        world_start[has] = scene.instance_vertex_start_np[first[has]]
        self._shape_world_start = wp.array(world_start.astype(np.int32), dtype=wp.int32, device=d)

        # Instances of small trees: a thread per leaf, then per inner node. The others grouped by
        # shape, and per level the work blocks of each shape.
        small = nodes <= instance_refit_max_nodes
        is_small = small[scene.instance_shape_np] if n else np.zeros(0, bool)
        small_instance = np.nonzero(is_small)[0].astype(np.int32)
        self.small_instance = wp.array(small_instance, dtype=wp.int32, device=d)
        leaves = sizes.num_leaves
        inner = sizes.num_inner
        small_shape = scene.instance_shape_np[small_instance]
        small_leaf_end = np.cumsum(leaves[small_shape])
        small_inner_end = np.cumsum(inner[small_shape])
        self.num_small_leaves = int(small_leaf_end[-1]) if len(small_leaf_end) else 0
        self.num_small_inner = int(small_inner_end[-1]) if len(small_inner_end) else 0
        if max(self.num_small_leaves, self.num_small_inner) >= 2**31:
            raise ValueError("scene too large for the BVH refit (2**31 tree nodes of small shapes)")
        self.small_leaf_end = wp.array(small_leaf_end.astype(np.int32), dtype=wp.int32, device=d)
        self.small_inner_end = wp.array(small_inner_end.astype(np.int32), dtype=wp.int32, device=d)
        self.inner_node = build.inner_node
        order = np.argsort(scene.instance_shape_np, kind="stable").astype(np.int32)
        per_shape = np.bincount(scene.instance_shape_np, minlength=num_shapes) if n else np.zeros(num_shapes, np.int64)
        per_shape = np.where(small, 0, per_shape)  # small shapes own no level work
        order = order[~is_small[order]] if n else order
        self.shape_instance = wp.array(order, dtype=wp.int32, device=d)
        self.shape_instance_start = wp.array(np.concatenate([[0], np.cumsum(per_shape)]).astype(np.int32), device=d)
        level_items, level_arrays = [], []
        for level in range(self.max_depth if per_shape.any() else 0):
            level_first, count = sizes.level(level)
            block = np.concatenate([[0], np.cumsum(count * per_shape)])
            if block[-1] >= 2**31:
                raise ValueError("scene too large for the BVH refit (2**31 work items on one level)")
            level_items.append(int(block[-1]))
            level_arrays += [block, level_first, np.maximum(count, 1)]
        views = packed_upload(level_arrays, d) if level_arrays else []  # one copy for all levels
        # (items, block_start, level_first, level_count) per level
        self.levels = [(items, *views[3 * k: 3 * k + 3]) for k, items in enumerate(level_items)]

        tv = TreeView()
        tv.shape_layout = build.shape_layout_device
        tv.layout_node_start = build.layout_node_start_device
        tv.shape_tri_order_start = scene.shape_triangle_start
        tv.node_child = build.node_child
        tv.node_triangle = build.node_triangle
        tv.node_leaf = build.node_leaf
        tv.leaf_node = build.leaf_node
        tv.layout_leaf_start = build.layout_leaf_start_device
        tv.layout_cut_start = build.layout_cut_start_device
        tv.cut_node = build.cut_node
        tv.tri_order = build.tri_order
        tv.instance_node_start = wp.array(inode.astype(np.int32), dtype=wp.int32, device=d)
        tv.node_lower = wp.zeros(self.num_node_slots, dtype=wp.vec3, device=d)
        tv.node_upper = wp.zeros(self.num_node_slots, dtype=wp.vec3, device=d)
        self.tree = tv
        self.lower = wp.zeros(n, dtype=wp.vec3, device=d)
        self.upper = wp.zeros(n, dtype=wp.vec3, device=d)

    def shape_tree(self, s: int) -> ShapeTree:
        """Shape ``s``'s tree as host arrays (reads the device; for tests and inspection)."""
        return self.build.shape_tree(s)

    def rebuild(self, scene) -> None:
        """Rebuilds every shape's triangle order from the world vertices of its first instance (for
        deforming meshes whose refit trees have loosened); the layout, and so every array and
        captured graph, stays. Enqueues kernels only; the next :meth:`refit` sets the boxes."""
        self.build.order(scene.shape_vertex, scene.shape_vertex_start, scene.world_vertex, self._shape_world_start)

    @property
    def counters(self) -> list:
        """Buffers with counters that :meth:`refit` writes: none (its arrays have fixed sizes)."""
        return []

    def refit(self, scene) -> None:
        """Refits all node bounds (and the object boxes) from ``scene.world_vertex``: small trees
        in one launch, the others deepest level first."""
        margin = scene.scalar_type(self.margin_rel)
        if self.num_small_leaves:
            wp.launch(_REFIT_SMALL_LEAF[scene.precision], dim=self.num_small_leaves,
                      inputs=[scene.topology, scene.world_vertex, self.tree, self.small_instance, self.small_leaf_end,
                              margin],
                      outputs=[self.lower, self.upper], device=self.device)
        if self.num_small_inner:
            wp.launch(_refit_small_inner_kernel, dim=self.num_small_inner,
                      inputs=[self.tree, scene.instance_shape, self.small_instance, self.small_inner_end,
                              self.build.layout_inner_start_device, self.inner_node],
                      outputs=[self.lower, self.upper], device=self.device)
        for items, block, first, count in reversed(self.levels):
            if items == 0:
                continue
            wp.launch(
                _REFIT_LEVEL[scene.precision],
                dim=items,
                inputs=[scene.topology, scene.world_vertex, self.tree, block, first, count, self.shape_instance,
                        self.shape_instance_start, margin],
                outputs=[self.lower, self.upper],
                device=self.device,
            )
