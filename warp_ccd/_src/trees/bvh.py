"""Bounding-volume trees: built once per shape (median split); rigid objects use their shape's tree
as it is, deforming objects refit their own every frame.

Build (kernels, all shapes at once: :mod:`warp_ccd._src.trees.build`): the root holds all triangles;
each node with more than ``leaf_size`` triangles is split at the median of its triangles'
centroids along the longest axis of its bounds, so the tree is balanced with
``ceil(log2(m / leaf_size)) + 1`` levels. The layout follows from the triangle counts alone (one
thread per node); the triangle order from three centroid-sorted lists per shape, partitioned
level by level over all shapes, small subtrees finished one thread each.

Stored flat, topology shared by every object of a shape (:class:`~warp_ccd._src.trees.reference.ShapeTree`
is one shape's tree on the host):

* nodes in breadth-first order (a node's children are on the next level; level ``d`` of a
  shape starts at node ``2**d - 1``), so refit can run level by level from the deepest up;
* ``node_child`` ``(left, right)`` or ``(-1, -1)`` for a leaf;
* ``node_triangle`` ``(start, count)``: the node's triangles are ``tri_order[start:start + count]``
  (every subtree is one contiguous range).

Node boxes (float32, ``node_lower`` / ``node_upper``) live in one array of *slots*, in the frame
of the object's *box space*:

* **rigid objects** share their shape's boxes, in shape space (the shape's own vertices, before
  scale and pose), computed once when the trees are built and never refit. The traversal
  (:mod:`warp_ccd._src.midphase.bvh`) tests one object's boxes against the other's under the pair's
  relative transform, as FCL does; the broad phase's object box is the union of the shape's cut
  boxes (:meth:`~warp_ccd._src.trees.reference.ShapeTree.cut`) under the pose, or the box of its world
  vertices (one thread an object either way; by default the vertices of objects of up to 64,
  whose cuts are fewer, bigger boxes, and the cut of bigger ones, whose cuts are many small ones).
* **deforming objects** (``scene.object_deforming_np``) have boxes of their own, in world space,
  refit every frame from their world vertices: objects of small trees (up to 255 nodes:
  polyhedra, 80-triangle spheres) in two launches, one thread per leaf of every such object,
  then one thread per inner node (the union of the leaf boxes of its subtree, a contiguous run of
  :attr:`TreeView.leaf_node`); bigger trees one launch per level, deepest first, one thread per
  (object, node). The root's box is the object's box.

* **world trees** (``SceneBVH(world_trees=True)``, a continuous frame's): every object is treated
  as a deforming one, its tree refit in the world each frame from its triangles' *swept* boxes (the
  box of a triangle at both ends of a linear motion, :func:`swept_triangle_box_at`, padded by
  ``pad_abs`` too), so the traversal's frames are identities and the roots hold the whole motion.

Leaf boxes are padded by the narrow phase's tolerance times their triangle's longest edge (in
their own space: the padding scales with the object), so that the trees never reject a pair the
narrow phase accepts. A rigid object's world vertices are computed from its pose in floating
point, so every box under a pose is also padded by a bound on that rounding
(:data:`WORLD_ERROR_ULPS`). :meth:`SceneBVH.rebuild` re-sorts the triangles of the deforming
meshes' shapes from their world vertices when the refit boxes have loosened.
"""


from typing import Any

import numpy as np
import warp as wp

from ..geometry.box import BOX_EMPTY, box_lower32, box_upper32, vertex_bounds
from ..geometry.precision import precision_overloads
from ..runtime.arrays import packed_upload
from ..runtime.buffers import upper_bound
from ..runtime.options import check_option
from ..scene.scene import MeshTopology, Scene
from .bounds import pad_boxes
from .build import CUT_TRIANGLES, TreeBuild
from .reference import ShapeTree

wp.set_module_options({"enable_backward": False})  # forward kernels only

OBJECT_BOUNDS = {"auto": 64, "tree": -1, "vertices": 2**31 - 1}
"""How a rigid object's box for the broad phase is found (:class:`SceneBVH`), and the most world
vertices of an object whose box comes from them (not from its tree): ``"auto"`` up to 64. Measured on a
GPU (the docs' performance page), the vertices win only for the smallest shapes, whose cuts are a few big
boxes; from about 162 vertices on the tree wins: one thread reading hundreds of vertices costs more than
the looser boxes cost the traversal."""

WORLD_ERROR_ULPS = 128.0
"""Bound on the rounding of a world vertex computed from its pose (``pose * (scale * p)``: a
quaternion rotation and a translation) and of a box put under a pose, in units in the last place
of ``|t| + scale * r`` (``t`` the translation, ``r`` the shape's radius): each output is a sum of
about ten rounded terms of at most that size; 128 leaves a wide margin."""

__all__ = ["OBJECT_BOUNDS", "WORLD_ERROR_ULPS", "SceneBVH", "TreeView", "leaf_box_at",
           "swept_triangle_box_at"]


@wp.struct
class TreeView:
    """What the refit and traversal kernels need: layouts shared by the shapes of one triangle count,
    triangle order per shape, box slots per object.

    Shape ``s`` has layout ``l = shape_layout[s]`` (a tree's layout depends on its triangle count
    alone, :mod:`warp_ccd._src.trees.build`): its nodes are ``layout_node_start[l] + local id``, its
    leaves (local ids) ``leaf_node[layout_leaf_start[l]:layout_leaf_start[l + 1]]`` and its two
    cuts (subtrees that partition the leaves, :meth:`~warp_ccd._src.trees.reference.ShapeTree.cut`), at the
    layout's cut depth and one level deeper: ``cut_node[layout_cut_start[2 l + deep]:
    layout_cut_start[2 l + deep + 1]]``; its triangle order starts at ``shape_tri_order_start[s]``;
    the boxes of object ``i`` (its box space: its shape's for a rigid object, the world for a
    deforming one) are ``node_lower/upper[object_node_start[i] + local id]``.
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
    object_node_start: wp.array[wp.int32]
    node_lower: wp.array[wp.vec3]
    node_upper: wp.array[wp.vec3]


@wp.func
def triangle_box_at(mesh: MeshTopology, world_vertex: wp.array[Any], margin_rel: Any, tri_start: int,
                    vertex_start: int, tri: int):
    """``(lower, upper)`` float32 box in the world of triangle ``tri`` of an object whose shape's
    triangles start at ``tri_start`` (in ``mesh.shape_triangle``) and whose world vertices at
    ``vertex_start``, padded by ``margin_rel`` times its longest edge (the narrow phase's tolerance)
    and rounded outward: a leaf's box, or a triangle's in a whole-object pair (:mod:`warp_ccd._src.midphase.bvh`)."""
    idx = mesh.shape_triangle[tri_start + tri]
    a = world_vertex[vertex_start + idx[0]]
    b = world_vertex[vertex_start + idx[1]]
    c = world_vertex[vertex_start + idx[2]]
    edge = wp.sqrt(wp.max(wp.max(wp.length_sq(b - a), wp.length_sq(c - b)), wp.length_sq(a - c)))
    pad = type(a)(margin_rel * edge, margin_rel * edge, margin_rel * edge)
    return box_lower32(wp.min(wp.min(a, b), c) - pad), box_upper32(wp.max(wp.max(a, b), c) + pad)


@wp.func
def swept_triangle_box_at(mesh: MeshTopology, world_vertex: wp.array[Any], world_vertex_start: wp.array[Any],
                          margin_rel: Any, pad_abs: wp.float64, tri_start: int, vertex_start: int, tri: int):
    """``(lower, upper)`` float32 box in the world of triangle ``tri`` (as :func:`triangle_box_at`)
    over a linear motion: the box of its three vertices in ``world_vertex_start`` (the motion's
    start) and in ``world_vertex`` (its end), which holds the triangle at every time between,
    padded by ``margin_rel`` times its longest edge at either end plus ``pad_abs`` (scene units:
    a continuous test's least distance and tolerance), in float64, and rounded outward."""
    idx = mesh.shape_triangle[tri_start + tri]
    a = world_vertex[vertex_start + idx[0]]
    b = world_vertex[vertex_start + idx[1]]
    c = world_vertex[vertex_start + idx[2]]
    a0 = world_vertex_start[vertex_start + idx[0]]
    b0 = world_vertex_start[vertex_start + idx[1]]
    c0 = world_vertex_start[vertex_start + idx[2]]
    edge_sq = wp.max(wp.max(wp.length_sq(b - a), wp.length_sq(c - b)), wp.length_sq(a - c))
    edge_sq = wp.max(edge_sq, wp.max(wp.max(wp.length_sq(b0 - a0), wp.length_sq(c0 - b0)), wp.length_sq(a0 - c0)))
    edge = wp.sqrt(edge_sq)
    pad = type(a)(margin_rel * edge, margin_rel * edge, margin_rel * edge)
    lo = wp.vec3d(wp.min(wp.min(wp.min(a, b), c), wp.min(wp.min(a0, b0), c0)) - pad) - wp.vec3d(pad_abs)
    hi = wp.vec3d(wp.max(wp.max(wp.max(a, b), c), wp.max(wp.max(a0, b0), c0)) + pad) + wp.vec3d(pad_abs)
    return box_lower32(lo), box_upper32(hi)


@wp.func
def leaf_box_at(mesh: MeshTopology, world_vertex: wp.array[Any], world_vertex_start: wp.array[Any], swept: int,
                pad_abs: wp.float64, margin_rel: Any, tri_start: int, vertex_start: int, tri: int):
    """A triangle's box as a leaf's: :func:`triangle_box_at`, padded by ``pad_abs`` (scene units)
    when it is positive, or with ``swept`` (a continuous frame's) :func:`swept_triangle_box_at`
    (``world_vertex_start`` is then read, else not)."""
    if swept != 0:
        return swept_triangle_box_at(mesh, world_vertex, world_vertex_start, margin_rel, pad_abs, tri_start,
                                     vertex_start, tri)
    lo, hi = triangle_box_at(mesh, world_vertex, margin_rel, tri_start, vertex_start, tri)
    if pad_abs > wp.float64(0.0):
        return box_lower32(wp.vec3d(lo) - wp.vec3d(pad_abs)), box_upper32(wp.vec3d(hi) + wp.vec3d(pad_abs))
    return lo, hi


@wp.func
def triangle_box(mesh: MeshTopology, world_vertex: wp.array[Any], inst: int, tri: int, margin_rel: Any):
    """:func:`triangle_box_at` of local triangle ``tri`` of object ``inst``."""
    return triangle_box_at(mesh, world_vertex, margin_rel, mesh.shape_triangle_start[mesh.object_shape[inst]],
                           mesh.object_vertex_start[inst], tri)


@wp.func
def _refit_node(
    mesh: MeshTopology,
    world_vertex: wp.array[Any],
    world_vertex_start: wp.array[Any],
    swept: int,
    pad_abs: wp.float64,
    tree: TreeView,
    s: int,
    inst: int,
    node: int,
    margin_rel: Any,
    object_lower: wp.array[wp.vec3],
    object_upper: wp.array[wp.vec3],
):
    """Box of ``node`` (local id in shape ``s``) of object ``inst``: from its triangles (leaf,
    padded by the tolerance; with ``swept`` their boxes over the motion from ``world_vertex_start``,
    :func:`swept_triangle_box_at`) or its children's boxes; the root's box is the object's box."""
    shape_node = tree.layout_node_start[tree.shape_layout[s]] + node
    slot = tree.object_node_start[inst] + node
    child = tree.node_child[shape_node]
    lo = wp.vec3(0.0)
    hi = wp.vec3(0.0)
    if child[0] < 0:
        rng = tree.node_triangle[shape_node]
        base = tree.shape_tri_order_start[s]
        lo = wp.vec3(BOX_EMPTY)
        hi = wp.vec3(-BOX_EMPTY)
        tri_start = mesh.shape_triangle_start[mesh.object_shape[inst]]
        vertex_start = mesh.object_vertex_start[inst]
        for k in range(rng[0], rng[0] + rng[1]):
            tri_lo, tri_hi = leaf_box_at(mesh, world_vertex, world_vertex_start, swept, pad_abs, margin_rel,
                                         tri_start, vertex_start, tree.tri_order[base + k])
            lo = wp.min(lo, tri_lo)
            hi = wp.max(hi, tri_hi)
    else:
        base_slot = tree.object_node_start[inst]
        lo = wp.min(tree.node_lower[base_slot + child[0]], tree.node_lower[base_slot + child[1]])
        hi = wp.max(tree.node_upper[base_slot + child[0]], tree.node_upper[base_slot + child[1]])
    tree.node_lower[slot] = lo
    tree.node_upper[slot] = hi
    if node == 0:
        object_lower[inst] = lo
        object_upper[inst] = hi


@wp.func
def _layout_item(
    t: int,
    block_start: wp.array[wp.int32],
    block_count: wp.array[wp.int32],
    layout_object: wp.array[wp.int32],
    layout_object_start: wp.array[wp.int32],
):
    """Flat work item ``t`` of a launch whose items are laid out layout by layout: block ``b`` (one
    per tree layout with objects in the launch) owns items ``block_start[b] .. block_start[b + 1]``,
    ``block_count[b]`` per object, its objects ``layout_object[layout_object_start[b]:
    layout_object_start[b + 1]]``. Returns ``(block, object, index of the item within its
    object)``: one search over the few layouts, not over the objects or shapes."""
    b = upper_bound(block_start, 0, block_start.shape[0], t) - 1  # last b with block_start[b] <= t
    local = t - block_start[b]
    cnt = block_count[b]
    return b, layout_object[layout_object_start[b] + local / cnt], local % cnt


@wp.kernel
def _refit_level_kernel(
    mesh: MeshTopology,
    world_vertex: wp.array[Any],
    world_vertex_start: wp.array[Any],
    swept: int,
    pad_abs: wp.float64,
    tree: TreeView,
    block_start: wp.array[wp.int32],
    level_count: wp.array[wp.int32],
    level_first: int,
    layout_object: wp.array[wp.int32],
    layout_object_start: wp.array[wp.int32],
    margin_rel: Any,
    # Outputs
    object_lower: wp.array[wp.vec3],
    object_upper: wp.array[wp.vec3],
):
    """One thread per (object, node of this level): leaf box from triangles, else children union.
    Items laid out by layout (:func:`_layout_item`), ``level_count`` nodes of the level per object;
    the level's nodes are ``level_first ..`` in every tree (:meth:`~warp_ccd._src.trees.build.TreeSizes.level`)."""
    _b, inst, k = _layout_item(wp.tid(), block_start, level_count, layout_object, layout_object_start)
    _refit_node(mesh, world_vertex, world_vertex_start, swept, pad_abs, tree, mesh.object_shape[inst], inst,
                level_first + k, margin_rel, object_lower, object_upper)


@wp.kernel
def _refit_small_leaf_kernel(
    mesh: MeshTopology,
    world_vertex: wp.array[Any],
    world_vertex_start: wp.array[Any],
    swept: int,
    pad_abs: wp.float64,
    tree: TreeView,
    block_start: wp.array[wp.int32],
    block_count: wp.array[wp.int32],
    block_layout: wp.array[wp.int32],
    layout_object: wp.array[wp.int32],
    layout_object_start: wp.array[wp.int32],
    margin_rel: Any,
    # Outputs
    object_lower: wp.array[wp.vec3],
    object_upper: wp.array[wp.vec3],
):
    """One thread per leaf of each object of a small tree: the leaf's box from its triangles. Items
    laid out by layout (:func:`_layout_item`), ``block_count`` leaves per object."""
    b, inst, k = _layout_item(wp.tid(), block_start, block_count, layout_object, layout_object_start)
    node = tree.leaf_node[tree.layout_leaf_start[block_layout[b]] + k]
    _refit_node(mesh, world_vertex, world_vertex_start, swept, pad_abs, tree, mesh.object_shape[inst], inst, node,
                margin_rel, object_lower, object_upper)


@wp.kernel
def _refit_small_inner_kernel(
    tree: TreeView,
    block_start: wp.array[wp.int32],
    block_count: wp.array[wp.int32],
    block_layout: wp.array[wp.int32],
    layout_object: wp.array[wp.int32],
    layout_object_start: wp.array[wp.int32],
    layout_inner_start: wp.array[wp.int32],
    inner_node: wp.array[wp.int32],
    # Outputs
    object_lower: wp.array[wp.vec3],
    object_upper: wp.array[wp.vec3],
):
    """One thread per inner node of each object of a small tree, after the leaves: the union of the
    boxes of the leaves of its subtree (the same bits as the union of its children's). Items laid
    out by layout (:func:`_layout_item`), ``block_count`` inner nodes per object."""
    b, inst, k = _layout_item(wp.tid(), block_start, block_count, layout_object, layout_object_start)
    layout = block_layout[b]
    node = inner_node[layout_inner_start[layout] + k]
    leaves = tree.node_leaf[tree.layout_node_start[layout] + node]
    leaf_base = tree.layout_leaf_start[layout]
    slot = tree.object_node_start[inst]
    lo = wp.vec3(BOX_EMPTY)
    hi = wp.vec3(-BOX_EMPTY)
    for j in range(leaves[0], leaves[0] + leaves[1]):
        leaf = slot + tree.leaf_node[leaf_base + j]
        lo = wp.min(lo, tree.node_lower[leaf])
        hi = wp.max(hi, tree.node_upper[leaf])
    tree.node_lower[slot + node] = lo
    tree.node_upper[slot + node] = hi
    if node == 0:
        object_lower[inst] = lo
        object_upper[inst] = hi


def leaf_box_args(vertices: wp.array, start: wp.array | None, pad_abs: float) -> list:
    """``[world_vertex, world_vertex_start, swept, pad_abs]`` of a kernel of leaf boxes
    (:func:`leaf_box_at`): swept when ``start`` is given, else not (and the start is ``vertices``
    themselves, never read)."""
    swept = start is not None
    return [vertices, start if swept else vertices, int(swept), wp.float64(pad_abs)]


def swept_arg_types(s, v, q, t) -> dict:
    """Argument types of a kernel of one precision (:func:`~warp_ccd._src.geometry.precision.precision_overloads`)
    that takes ``world_vertex``, ``world_vertex_start`` and ``margin_rel`` (the leaf boxes' inputs)."""
    return {"world_vertex": wp.array[v], "world_vertex_start": wp.array[v], "margin_rel": s}


_REFIT_LEVEL, _REFIT_SMALL_LEAF = (precision_overloads(k, swept_arg_types)
                                   for k in (_refit_level_kernel, _refit_small_leaf_kernel))


@wp.func
def abs_matrix(m: Any):
    """Entry-wise absolute value of a 3x3 matrix (the extent of a box under a linear map is
    ``abs_matrix(m) * half``)."""
    return type(m)(wp.abs(m[0, 0]), wp.abs(m[0, 1]), wp.abs(m[0, 2]),
                   wp.abs(m[1, 0]), wp.abs(m[1, 1]), wp.abs(m[1, 2]),
                   wp.abs(m[2, 0]), wp.abs(m[2, 1]), wp.abs(m[2, 2]))


@wp.func
def box_radius(lo: wp.vec3, hi: wp.vec3) -> float:
    """Distance from the origin of a box's farthest corner, or more (a bound on its points' norms)."""
    return wp.length(wp.max(wp.abs(lo), wp.abs(hi)))


@wp.kernel
def _rigid_bounds_kernel(
    tree: TreeView,
    rigid_object: wp.array[wp.int32],
    object_shape: wp.array[wp.int32],
    object_pose: wp.array[Any],
    object_scale: wp.array[wp.float32],
    world_vertex: wp.array[Any],
    object_vertex_start: wp.array[wp.int32],
    vertices_max: int,
    margin_rel: Any,
    world_eps: Any,
    # Outputs
    object_lower: wp.array[wp.vec3],
    object_upper: wp.array[wp.vec3],
):
    """One thread per rigid object: the box of its world vertices (padded by ``margin_rel`` times
    its diagonal) when it has at most ``vertices_max``; else the union of its shape's cut boxes
    under its scale and pose (each box's centre moved, its half extent through the rotation's
    absolute values), padded by the rounding bound ``world_eps * (|t| + scale * r)``
    (:data:`WORLD_ERROR_ULPS`). Float32 corners, rounded outward."""
    i = rigid_object[wp.tid()]
    v0 = object_vertex_start[i]
    v1 = object_vertex_start[i + 1]
    if v1 - v0 <= vertices_max:
        lo, hi = vertex_bounds(world_vertex, v0, v1)
        pad = margin_rel * wp.length(hi - lo)
        m = type(lo)(pad, pad, pad)
        object_lower[i] = box_lower32(lo - m)
        object_upper[i] = box_upper32(hi + m)
        return
    pose = object_pose[i]
    t = wp.transform_get_translation(pose)
    rot = wp.quat_to_matrix(wp.transform_get_rotation(pose))
    rot_abs = abs_matrix(rot)
    half = type(world_eps)(0.5)
    s = type(world_eps)(object_scale[i])
    layout = tree.shape_layout[object_shape[i]]
    base = tree.object_node_start[i]
    lo = type(t)(type(world_eps)(BOX_EMPTY))
    hi = -lo
    for k in range(tree.layout_cut_start[2 * layout], tree.layout_cut_start[2 * layout + 1]):
        slot = base + tree.cut_node[k]
        nlo = type(t)(tree.node_lower[slot])
        nhi = type(t)(tree.node_upper[slot])
        c = rot * ((nlo + nhi) * (half * s)) + t
        h = rot_abs * ((nhi - nlo) * (half * s))
        lo = wp.min(lo, c - h)
        hi = wp.max(hi, c + h)
    r = type(world_eps)(box_radius(tree.node_lower[base], tree.node_upper[base]))
    at = wp.abs(t)
    pad = world_eps * (wp.max(wp.max(at[0], at[1]), at[2]) + s * r)
    p = type(t)(pad, pad, pad)
    object_lower[i] = box_lower32(lo - p)
    object_upper[i] = box_upper32(hi + p)


_RIGID_BOUNDS = precision_overloads(_rigid_bounds_kernel, lambda s, v, q, t: {
    "object_pose": wp.array[t], "world_vertex": wp.array[v], "margin_rel": s, "world_eps": s})


class _RefitPlan:
    """The refit of the trees of some objects (the deforming ones each frame; the shapes once, as
    objects of their own), as launches prepared on the host.

    Args:
        objects: ``(K,)`` ids of the objects to refit.
        object_shape: ``(N,)`` shape of every object of the topology the launches take.
        build: the :class:`~warp_ccd._src.trees.build.TreeBuild` (layouts, their sizes and inner-node lists).
        small_max_nodes: trees of at most this many nodes are refit leaves-then-inner-nodes, the
            others level by level.
        device: Warp device.
    """

    def __init__(self, objects: np.ndarray, object_shape: np.ndarray, build: TreeBuild, small_max_nodes: int,
                 device):
        self.device = device
        self.build = build
        objects = np.asarray(objects, np.int64)
        layout = build.shape_layout[object_shape[objects]]
        lsizes = build.layout_sizes  # a tree's shape depends on its layout (triangle count) alone
        small = (lsizes.num_nodes <= small_max_nodes)[layout]

        def group(members: np.ndarray, member_layout: np.ndarray) -> tuple:
            """``(layouts with members, members sorted by layout, start of each layout's members)``."""
            used, per = np.unique(member_layout, return_counts=True)
            order = members[np.argsort(member_layout, kind="stable")]
            return used, order, np.concatenate([[0], np.cumsum(per)])

        def blocks(per_member: np.ndarray, members: np.ndarray) -> tuple:
            """``(items, block_start, block_count)``: ``per_member[b]`` items for each of
            ``members[b]`` objects."""
            block = np.concatenate([[0], np.cumsum(per_member.astype(np.int64) * members)])
            if block[-1] >= 2**31:
                raise ValueError("scene too large for the BVH refit (2**31 work items in one launch)")
            return int(block[-1]), block, np.maximum(per_member, 1)

        # Small trees: their leaves, then their inner nodes, one launch each for every such object.
        used, order, start = group(objects[small], layout[small])
        self.num_small_leaves, leaf_block, leaf_count = blocks(lsizes.num_leaves[used], np.diff(start))
        self.num_small_inner, inner_block, inner_count = blocks(lsizes.num_inner[used], np.diff(start))
        arrays = [leaf_block, leaf_count, inner_block, inner_count, used, order, start]
        # The others level by level, deepest first (the nodes of level d are the same ids in every tree).
        used_big, order_big, start_big = group(objects[~small], layout[~small])
        arrays += [order_big, start_big]
        depth = int(lsizes.num_levels[used_big].max()) if len(used_big) else 0
        self.level_items, self.level_first = [], []
        for level in range(depth):
            first, count = lsizes.level(level)
            items, block, per = blocks(count[used_big], np.diff(start_big))
            self.level_items.append(items)
            self.level_first.append(int(first[0]))
            arrays += [block, per]
        views = packed_upload(arrays, device)  # one copy for all
        (self.small_leaf_block, self.small_leaf_count, self.small_inner_block, self.small_inner_count,
         self.small_layout, self.small_object, self.small_object_start, self.big_object,
         self.big_object_start) = views[:9]
        self.levels = [tuple(views[9 + 2 * k: 11 + 2 * k]) for k in range(depth)]  # (block_start, level_count)

    def launch(self, topology: MeshTopology, vertices: wp.array, tree: TreeView, margin, precision: str,
               lower: wp.array, upper: wp.array, start: wp.array | None = None, pad_abs: float = 0.0) -> None:
        """Refits the boxes of the plan's objects from ``vertices`` (``topology``'s), small trees
        first, then the others deepest level first; roots also into ``lower`` / ``upper``. With
        ``start``, swept boxes over the motion from ``start`` to ``vertices``, padded by ``pad_abs``
        too (:func:`swept_triangle_box_at`)."""
        d = self.device
        small = [self.small_layout, self.small_object, self.small_object_start]
        sweep = leaf_box_args(vertices, start, pad_abs)
        if self.num_small_leaves:
            wp.launch(_REFIT_SMALL_LEAF[precision], dim=self.num_small_leaves,
                      inputs=[topology, *sweep, tree, self.small_leaf_block, self.small_leaf_count, *small,
                              margin],
                      outputs=[lower, upper], device=d)
        if self.num_small_inner:
            wp.launch(_refit_small_inner_kernel, dim=self.num_small_inner,
                      inputs=[tree, self.small_inner_block, self.small_inner_count, *small,
                              self.build.layout_inner_start_device, self.build.inner_node],
                      outputs=[lower, upper], device=d)
        for k in reversed(range(len(self.levels))):
            if self.level_items[k]:
                block, count = self.levels[k]
                wp.launch(_REFIT_LEVEL[precision], dim=self.level_items[k],
                          inputs=[topology, *sweep, tree, block, count, self.level_first[k], self.big_object,
                                  self.big_object_start, margin],
                          outputs=[lower, upper], device=d)


class SceneBVH:
    """Trees of all shapes of a scene: shape-space boxes for rigid objects, per-object boxes refit
    every frame for deforming ones, and every object's box for the broad phase.

    Args:
        scene: the :class:`~warp_ccd._src.scene.scene.Scene`.
        leaf_size: largest number of triangles per leaf.
        margin_rel: leaf padding relative to the triangle's longest edge (the narrow phase's
            tolerance, so that tree culling never rejects a pair the narrow phase accepts).
        object_refit_max_nodes: deforming objects of shapes with at most this many nodes are refit
            in two launches, leaves then inner nodes (an inner node reads all its leaves); bigger
            trees level by level, one thread per node.
        cut_depth: least level of each tree's cut (:meth:`~warp_ccd._src.trees.reference.ShapeTree.cut`),
            whose boxes under the pose make a big rigid object's box (``object_bounds``); big
            trees cut deeper, so that a cut's subtrees hold about ``cut_triangles`` triangles at
            most (:meth:`~warp_ccd._src.trees.build.TreeSizes.cut_depth`).
        cut_triangles: see ``cut_depth`` (:data:`~warp_ccd._src.trees.build.CUT_TRIANGLES`).
        object_bounds: a rigid object's box for the broad phase, one thread an object:
            ``"vertices"`` the box of its world vertices (tight; a thread reads them all);
            ``"tree"`` the union of its shape's cut boxes under its pose (a few boxes; loose where
            the cut's boxes are big, in small trees); ``"auto"`` (default) the vertices of objects
            of up to :data:`OBJECT_BOUNDS` ``["auto"]`` vertices, the tree of bigger ones; an integer
            ``n``, the vertices of objects of up to ``n`` vertices (0: ``"tree"``).
        small_subtree: largest subtree the build finishes in one thread block (CUDA, where it and
            ``2 * leaf_size`` are at most 256) or one thread (default: see
            :class:`~warp_ccd._src.trees.build.TreeBuild`).
        world_trees: every object's tree in the world, refit every frame as a deforming object's
            (a continuous frame's swept boxes: :meth:`refit` with ``world_vertex_start``); the
            traversal's frames are then identities.
        pad_abs: leaf padding in scene units besides ``margin_rel``, with ``world_vertex_start``
            (a continuous test's least distance plus its tolerance).
        box_pad: padding in scene units of every object box (:attr:`lower`, :attr:`upper`): half a
            clearance (:func:`~warp_ccd._src.trees.bounds.pad_boxes`); the trees' boxes are not padded
            (the traversal pads its tests: :class:`~warp_ccd._src.midphase.bvh.MidPhaseBVH`).

    Attributes:
        lower, upper: ``(N,)`` object AABBs (float32, world), written by :meth:`refit`.
        tree: the :class:`TreeView` struct for kernels.
        build: the :class:`~warp_ccd._src.trees.build.TreeBuild` that made the trees (device arrays).
        object_deforming: ``(N,)`` int32 device flags, 1 for a deforming object.
        num_node_slots: node boxes stored: the shapes of rigid objects once, each deforming object.
        num_levels: levels of the deepest tree (the root alone: 1).
        max_triangles, min_triangles: triangles of the largest and of the smallest object's mesh.
        bounds_vertices_max: most vertices of a rigid object whose box comes from its vertices
            (from ``object_bounds``).
        world_trees, pad_abs, box_pad: as above.
    """

    def __init__(self, scene: Scene, *, leaf_size: int = 1, margin_rel: float = 0.0, object_refit_max_nodes: int = 255,
                 cut_depth: int = 3, cut_triangles: int = CUT_TRIANGLES, object_bounds: str | int = "auto",
                 small_subtree: int | None = None, world_trees: bool = False, pad_abs: float = 0.0,
                 box_pad: float = 0.0) -> None:
        leaf_size = check_option("leaf_size", leaf_size) or 1
        cut_depth = check_option("cut_depth", cut_depth)
        object_bounds = check_option("object_bounds", object_bounds)
        vertices_max = OBJECT_BOUNDS.get(object_bounds, object_bounds)
        self.device = scene.device
        self.margin_rel = float(margin_rel)
        self.world_trees = bool(world_trees)
        self.pad_abs = float(pad_abs)
        self.box_pad = float(box_pad)
        self.leaf_size = int(leaf_size)
        self.cut_depth = int(cut_depth)
        self.object_bounds = object_bounds
        self.bounds_vertices_max = vertices_max
        d = self.device
        build = TreeBuild(scene.shape_triangle, scene.shape_triangle_start_np, leaf_size=leaf_size,
                          cut_depth=cut_depth, cut_triangles=cut_triangles, small=small_subtree, device=d)
        self.build = build
        build.layout()
        build.order(scene.shape_vertex, scene.shape_vertex_start)
        num_shapes = scene.num_shapes
        n = scene.num_objects
        inst_shape = scene.object_shape_np
        deforming = scene.object_deforming_np | self.world_trees  # world trees: every object's refit
        nodes = build.layout_sizes.num_nodes[build.shape_layout]  # a tree's size is its layout's
        # Slots: the shapes of rigid objects first (shape space), then each deforming object's.
        has_rigid = np.zeros(num_shapes, bool)
        has_rigid[inst_shape[~deforming]] = True
        shape_slot = np.concatenate([[0], np.cumsum(np.where(has_rigid, nodes, 0))])
        own = np.where(deforming, nodes[inst_shape] if n else 0, 0)
        own_slot = shape_slot[-1] + np.concatenate([[0], np.cumsum(own)])
        if own_slot[-1] >= 2**31:
            raise ValueError(f"scene too large for the BVH: {own_slot[-1]} tree node boxes (limit 2**31 - 1)")
        self.num_node_slots = int(own_slot[-1])
        inode = np.where(deforming, own_slot[:-1], shape_slot[inst_shape] if n else 0)
        self.num_levels = int(build.layout_sizes.num_levels.max()) if num_shapes else 1  # every layout is used
        shape_tris = np.diff(scene.shape_triangle_start_np)
        self.max_triangles = int(shape_tris[inst_shape].max()) if n else 0
        self.min_triangles = int(shape_tris[inst_shape].min()) if n else 0
        # Where each shape's first deforming object's world vertices start, which a rebuild reads
        # (-1: none, the shape's own vertices).
        first = np.full(num_shapes, n, np.int64)
        np.minimum.at(first, inst_shape[deforming], np.nonzero(deforming)[0])
        world_start = np.full(num_shapes, -1, np.int64)
        has = first < n
        world_start[has] = scene.object_vertex_start_np[first[has]]
        # The small index arrays in one copy: views of one upload.
        (self._shape_world_start, self.rigid_object, self.object_deforming, tree_node_start, shape_node_start,
         shape_ids) = packed_upload([world_start, np.nonzero(~deforming)[0], deforming,
                                     np.append(inode, self.num_node_slots), shape_slot, np.arange(num_shapes)], d)
        self.refit_plan = _RefitPlan(np.nonzero(deforming)[0], inst_shape, build, object_refit_max_nodes, d)
        self._shape_plan = _RefitPlan(np.nonzero(has_rigid)[0], np.arange(num_shapes), build,
                                      object_refit_max_nodes, d)

        def view(node_start):
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
            tv.object_node_start = node_start
            tv.node_lower = self._node_lower
            tv.node_upper = self._node_upper
            return tv

        self._node_lower = wp.zeros(self.num_node_slots, dtype=wp.vec3, device=d)
        self._node_upper = wp.zeros(self.num_node_slots, dtype=wp.vec3, device=d)
        self.tree = view(tree_node_start)
        self._shape_tree = view(shape_node_start)  # the shapes as objects of their own (their boxes' slots)
        self._shape_topology = MeshTopology()
        for name in ("shape_triangle", "shape_triangle_start"):
            setattr(self._shape_topology, name, getattr(scene, name))
        self._shape_topology.object_shape = shape_ids
        self._shape_topology.object_vertex_start = scene.shape_vertex_start
        self._shape_topology.object_triangle_start = scene.shape_triangle_start
        self._shape_lower = wp.zeros(num_shapes, dtype=wp.vec3, device=d)
        self._shape_upper = wp.zeros(num_shapes, dtype=wp.vec3, device=d)
        self.lower = wp.zeros(n, dtype=wp.vec3, device=d)
        self.upper = wp.zeros(n, dtype=wp.vec3, device=d)
        self._refit_shapes(scene)

    def _refit_shapes(self, scene: Scene) -> None:
        """The shape-space boxes of the shapes of rigid objects, from the shapes' own vertices."""
        self._shape_plan.launch(self._shape_topology, scene.shape_vertex, self._shape_tree,
                                scene.scalar_type(self.margin_rel), scene.precision, self._shape_lower,
                                self._shape_upper)

    def shape_tree(self, s: int) -> ShapeTree:
        """Shape ``s``'s tree as host arrays (reads the device; for tests and inspection)."""
        return self.build.shape_tree(s)

    def rebuild(self, scene: Scene) -> None:
        """Rebuilds the triangle order of every shape of a deforming object from that object's world
        vertices (for deforming meshes whose refit trees have loosened; a shape shared with rigid
        objects gets its shape-space boxes again); the layout, and so every array and captured
        graph, stays. Enqueues kernels only; the next :meth:`refit` sets the deforming boxes."""
        self.build.order(scene.shape_vertex, scene.shape_vertex_start, scene.world_vertex, self._shape_world_start)
        self._refit_shapes(scene)

    @property
    def counters(self) -> list:
        """Buffers with counters that :meth:`refit` writes: none (its arrays have fixed sizes)."""
        return []

    def sweep_args(self, scene: Scene, world_vertex_start: wp.array | None, pad_extra: float = 0.0) -> list:
        """:func:`leaf_box_args` of the scene's world vertices and this tree's :attr:`pad_abs` plus
        ``pad_extra`` (scene units: half a clearance, for the triangle boxes of whole-object pairs)."""
        return leaf_box_args(scene.world_vertex, world_vertex_start, self.pad_abs + pad_extra)

    def refit(self, scene: Scene, world_vertex_start: wp.array | None = None, object_boxes: bool = True) -> None:
        """The frame's boxes: the deforming objects' trees refit from ``scene.world_vertex`` (their
        roots are their object boxes), then the rigid objects' boxes (see ``object_bounds``).

        Args:
            scene: the scene.
            world_vertex_start: ``(V,)`` world vertices at the start of a linear motion that ends at
                ``scene.world_vertex`` (the scene's vector type): leaf boxes are then the triangles'
                swept boxes, padded by :attr:`pad_abs` too (``world_trees`` only).
            object_boxes: also the rigid objects' boxes (a caller without a broad phase, such as a
                distance query walking the trees alone, leaves them out).
        """
        if world_vertex_start is not None and self.rigid_object.shape[0]:
            raise ValueError("world_vertex_start: swept boxes need every tree in the world (world_trees=True)")
        margin = scene.scalar_type(self.margin_rel)
        self.refit_plan.launch(scene.topology, scene.world_vertex, self.tree, margin, scene.precision, self.lower,
                               self.upper, world_vertex_start, self.pad_abs)
        if self.rigid_object.shape[0] and object_boxes:
            eps = float(np.finfo(np.float64 if scene.precision == "float64" else np.float32).eps)
            wp.launch(_RIGID_BOUNDS[scene.precision], dim=self.rigid_object.shape[0],
                      inputs=[self.tree, self.rigid_object, scene.object_shape, scene.object_pose,
                              scene.object_scale, scene.world_vertex, scene.object_vertex_start,
                              self.bounds_vertices_max, margin, scene.scalar_type(WORLD_ERROR_ULPS * eps)],
                      outputs=[self.lower, self.upper], device=self.device)
        pad_boxes(self.lower, self.upper, self.box_pad)
