"""Mid phase: candidate triangle pairs of candidate object pairs.

Both implementations write ``(obj_a, tri_a, obj_b, tri_b)`` rows into a
:class:`~warp_ccd._src.runtime.buffers.GrowableBuffer` (``candidates``), for the narrow phase.

* :class:`MidPhaseBVH` (default): a simultaneous descent of the two objects' trees
  (:mod:`warp_ccd._src.trees.bvh`), level by level for every object pair at once: a first kernel writes each
  pair's :class:`TreePair` (its trees' starts, the maps between the two box spaces and their
  paddings), then each level is one launch over the *front*, the node pairs whose boxes overlap:
  each opens both nodes (a leaf stays itself) and tests the two to four pairs of children; pairs
  of two leaves whose boxes overlap write their triangle pairs as candidates, the other
  overlapping pairs go to the next level's front. Level 0 is the object pairs' roots. The deepest
  tree's levels bound the launches, so a frame is a fixed sequence of kernels (a CUDA graph);
  each launch is a fixed grid whose threads stride over the level's node pairs (its count on the
  device), and each round a block reserves its front slots and its rows with one atomic add each
  (:func:`~warp_ccd._src.runtime.buffers.block_reserve`). Every node pair is one short step, all of a level's
  independent, so no thread walks a big pair alone, and an object pair whose boxes overlap but
  whose trees do not costs a few tests at level 0. The front is a buffer with a capacity and a
  counter (its largest level's count), grown as any other.

  *Whole-object pairs* skip the trees: in a scene of up to 30,000 objects, a pair of objects of at
  most 64 triangles each (polyhedra) has a block of 64 threads, one per triangle of the larger,
  test its world box against every triangle's of the smaller (:func:`_whole_pair_kernel`, one
  launch for all such pairs; the boxes are the trees' leaf boxes, padded alike). A small scene's
  traversal is latency, a few microseconds a launch a level; a scene of such objects alone
  launches no traversal at all.

  The boxes are tested in ``a``'s box space (:mod:`warp_ccd._src.trees.bvh`: a rigid object's shape space, a
  deforming object's world): ``b``'s box under the pair's relative transform, the box around it
  (three axes, ``a``'s), then ``a``'s box in ``b``'s space (``b``'s three axes): a separating-axis
  test of the two oriented boxes on six of their fifteen axes (``separating_axes=3``: the first
  three alone). The relative transforms come from the poses in float64, once per pair
  (:func:`_tree_pair`), with a padding that bounds every rounding on the way, so a test never
  rejects what the world vertices would put in contact; a deforming object's frame is the identity.
* :class:`~warp_ccd._src.midphase.all_pairs.MidPhaseAllPairs`, the reference: every triangle of
  ``a`` against every triangle of ``b`` (its own module).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import warp as wp

from ..geometry.box import boxes_overlap
from ..geometry.precision import precision_overloads
from ..geometry.primitives import _max_abs
from ..runtime.aliases import DeviceLike
from ..runtime.buffers import BLOCK_DIM, GrowableBuffer, block_dim_for, block_reserve, used_count
from ..runtime.checks import integer_option, number_option
from ..scene.scene import MeshTopology, Scene
from ..trees.bvh import WORLD_ERROR_ULPS, SceneBVH, TreeView, abs_matrix, box_radius, leaf_box_at, swept_arg_types

wp.set_module_options({"enable_backward": False})  # forward kernels only

__all__ = ["MidPhase", "MidPhaseBVH", "TreePair"]

EXPAND_THREADS_PER_SM = 1024
"""Most threads of an expansion launch per streaming multiprocessor on CUDA: the grid is fixed (so
that the frame can be a CUDA graph), no bigger than one thread per slot of the level's input (a
small scene launches few blocks), and its threads stride over the level's node pairs. On the H100
1,024 and 2,048 gave the same frames within noise (``bench/results/box_tests_sweep_cuda0.json``)."""

PAIR_MAX_REGISTERS = 128
"""Most registers a thread of the pair set-up kernel on CUDA (148 as compiled freely, 256 threads a
multiprocessor; capped with the exact test's kernels in ``bench/results/box_tests_registers_cuda0.json``)."""

TEST_ERROR_ULPS = 32.0
"""Bound on the rounding of one box test in float32 (centres, half extents, the transform applied),
in units in the last place of the boxes' and the translation's sizes."""

SEPARATING_AXES = (3, 6)
"""Axes of the box test (:class:`MidPhaseBVH`): 3, ``a``'s; 6, both objects'."""

WHOLE_TRIANGLES_MAX = 64
"""Default :attr:`MidPhaseBVH.whole_triangles_max`: a pair of objects of at most this many triangles
each (polyhedra) skips the trees: a thread per triangle of the larger tests its box against those
of the smaller, all in one launch (:func:`_whole_pair_kernel`). At most :data:`WHOLE_TRIANGLES_LIMIT`."""

WHOLE_OBJECTS_MAX = 30_000
"""Scenes of at most this many objects use whole-object pairs by default (:data:`WHOLE_TRIANGLES_MAX`),
larger ones walk trees for every pair. On the H100 (frames as graphs, motion included,
``bench/results/frame_stages*_cuda0.json``) whole-object pairs took 0.081 / 0.147 ms at 10^3 /
10^4 polyhedra against 0.128 / 0.194 with trees, but 0.434 / 3.22 ms at 10^5 / 10^6 against
0.417 / 2.77: past a few 10^4 objects the latency of a launch a level no longer counts, and the
trees' tighter boxes do."""

WHOLE_LANES = 64
"""Default :attr:`MidPhaseBVH.whole_lanes`, threads per whole-object pair (:func:`_whole_pair_kernel`;
fewer when a block has fewer): a thread takes a triangle of the larger object, four pairs a block
of 256. On the H100 32 lanes (two triangles a thread for a dodecahedron) took 0.032 ms against
0.016 at 1,000 polyhedra, 2.41 against 2.26 ms at 10^6 (``bench/results/frame_stages*_cuda0.json``)."""

WHOLE_TRIANGLES_LIMIT = 64
"""Most triangles of an object in a whole-object pair: a thread's hits are the bits of an int64."""


@wp.struct
class TreePair:
    """What the traversal needs of one object pair, written once per pair by
    :func:`_pair_kernel` so that a work item reads it in one step: the trees' starts, and
    the maps between the two objects' box spaces with their paddings."""

    a: int
    b: int
    node_a_start: int  # global node id of local node 0 (in the shape's layout)
    node_b_start: int
    slot_a_start: int  # the object's node boxes in TreeView.node_lower/upper
    slot_b_start: int
    tri_a_start: int  # the shape's triangle order in TreeView.tri_order
    tri_b_start: int
    b_to_a: wp.mat33  # x_a = b_to_a * x_b + b_to_a_shift (box spaces)
    b_to_a_shift: wp.vec3
    a_to_b: wp.mat33
    a_to_b_shift: wp.vec3
    pad_a: float  # added to every half extent of a test in a's space (rounding bound)
    pad_b: float


@wp.func
def _frame(pose: Any, scale: wp.float32, deforming: int):
    """``(rotation, translation, scale)`` of an object's box space in the world, in float64: the
    linear map that ``wp.transform_point`` applies with the pose's quaternion (whatever its norm),
    or the identity for a deforming object (its boxes are in the world)."""
    q = wp.transform_get_rotation(pose)
    p = wp.transform_get_translation(pose)
    rot = wp.quat_to_matrix(wp.quatd(wp.float64(q[0]), wp.float64(q[1]), wp.float64(q[2]), wp.float64(q[3])))
    t = wp.vec3d(wp.float64(p[0]), wp.float64(p[1]), wp.float64(p[2]))
    s = wp.float64(scale)
    if deforming != 0:
        rot = wp.identity(n=3, dtype=wp.float64)
        t = wp.vec3d(0.0)
        s = wp.float64(1.0)
    return rot, t, s


@wp.func
def _norm_inf(m: wp.mat33d) -> wp.float64:
    """Largest row sum of absolute values (the max-norm's operator norm)."""
    r = abs_matrix(m) * wp.vec3d(1.0)
    return wp.max(wp.max(r[0], r[1]), r[2])


@wp.func
def _map_between(rot_a: wp.mat33d, t_a: wp.vec3d, s_a: wp.float64, rot_b: wp.mat33d, t_b: wp.vec3d,
                 s_b: wp.float64, r_a: wp.float64, r_b: wp.float64, err: wp.float64, clearance: wp.float64):
    """The map from ``b``'s box space to ``a``'s (float32 matrix and shift) and the padding of a
    test in ``a``'s space: the float32 test's rounding on boxes of radii ``r_a``, ``r_b``, the
    world vertices' rounding ``err`` (both objects', world units) brought into ``a``'s space, and
    the ``clearance`` (world units; in ``a``'s space, ``clearance / s_a``: two points that close are
    no farther apart along any axis)."""
    inv_a = wp.inverse(rot_a)
    m = inv_a * rot_b * (s_b / s_a)
    shift = inv_a * (t_b - t_a) / s_a
    ulp = wp.float64(TEST_ERROR_ULPS) * wp.float64(1.1920929e-07)
    pad = ulp * (_max_abs(shift) + r_a + _norm_inf(m) * r_b) + err * _norm_inf(inv_a) / s_a + clearance / s_a
    return wp.mat33(m), wp.vec3(shift), wp.float32(pad) * wp.float32(1.001)


@wp.func
def _tree_pair(tree: TreeView, object_shape: wp.array[wp.int32], object_pose: wp.array[Any],
               object_scale: wp.array[wp.float32], object_deforming: wp.array[wp.int32], world_eps: float,
               clearance: wp.float64, a: int, b: int) -> TreePair:
    """The :class:`TreePair` of objects ``a < b``, its tests padded by ``clearance`` (world units)
    besides the rounding."""
    la = tree.shape_layout[object_shape[a]]
    lb = tree.shape_layout[object_shape[b]]
    r = TreePair()
    r.a = a
    r.b = b
    r.node_a_start = tree.layout_node_start[la]
    r.node_b_start = tree.layout_node_start[lb]
    r.slot_a_start = tree.object_node_start[a]
    r.slot_b_start = tree.object_node_start[b]
    r.tri_a_start = tree.shape_tri_order_start[object_shape[a]]
    r.tri_b_start = tree.shape_tri_order_start[object_shape[b]]
    def_a = object_deforming[a]
    def_b = object_deforming[b]
    rot_a, t_a, s_a = _frame(object_pose[a], object_scale[a], def_a)
    rot_b, t_b, s_b = _frame(object_pose[b], object_scale[b], def_b)
    r_a = wp.float64(box_radius(tree.node_lower[r.slot_a_start], tree.node_upper[r.slot_a_start]))
    r_b = wp.float64(box_radius(tree.node_lower[r.slot_b_start], tree.node_upper[r.slot_b_start]))
    # The world vertices' rounding (a rigid object's, from its pose; a deforming one's are given).
    err = wp.float64(0.0)
    eps = wp.float64(world_eps)
    if def_a == 0:
        err += eps * (_max_abs(t_a) + s_a * _norm_inf(rot_a) * r_a)
    if def_b == 0:
        err += eps * (_max_abs(t_b) + s_b * _norm_inf(rot_b) * r_b)
    m, shift, pad = _map_between(rot_a, t_a, s_a, rot_b, t_b, s_b, r_a, r_b, err, clearance)
    r.b_to_a = m
    r.b_to_a_shift = shift
    r.pad_a = pad
    m, shift, pad = _map_between(rot_b, t_b, s_b, rot_a, t_a, s_a, r_b, r_a, err, clearance)
    r.a_to_b = m
    r.a_to_b_shift = shift
    r.pad_b = pad
    return r


@wp.kernel(cuda_max_registers=PAIR_MAX_REGISTERS)
def _pair_kernel(
    tree: TreeView,
    object_shape: wp.array[wp.int32],
    object_pose: wp.array[Any],
    object_scale: wp.array[wp.float32],
    object_deforming: wp.array[wp.int32],
    world_eps: float,
    clearance: wp.float64,
    pair: wp.array[wp.vec2i],
    pair_count: wp.array[wp.int64],
    pair_capacity: int,
    # Outputs
    tree_pair: wp.array[TreePair],
    pair_rows: wp.array[wp.vec4i],
    level_count: wp.array[wp.int64],
):
    """One thread per stored pair: the pair's :class:`TreePair` and what its rows name (``(a, b,
    a's triangle order start, b's)``, read again when rows are written); thread 0 also zeroes the
    front's counts of the levels below the roots (``level_count[1:]``)."""
    k = wp.tid()
    if k == 0:
        for i in range(1, level_count.shape[0]):
            level_count[i] = wp.int64(0)
    if k >= used_count(pair_count, pair_capacity):
        return
    p = pair[k]
    r = _tree_pair(tree, object_shape, object_pose, object_scale, object_deforming, world_eps, clearance, p[0], p[1])
    tree_pair[k] = r
    pair_rows[k] = wp.vec4i(r.a, r.b, r.tri_a_start, r.tri_b_start)


_PAIR = precision_overloads(_pair_kernel, lambda s, v, q, t: {"object_pose": wp.array[t]})


@wp.func
def _boxes_overlap_mapped(lo_a: wp.vec3, hi_a: wp.vec3, lo_b: wp.vec3, hi_b: wp.vec3, r: TreePair, axes: int) -> bool:
    """Whether box ``a`` (``a``'s space) and box ``b`` (``b``'s space) may overlap: no separating
    axis among ``a``'s three (and ``b``'s three when ``axes`` is 6), each test padded."""
    ca = (lo_a + hi_a) * 0.5
    ha = (hi_a - lo_a) * 0.5
    cb = (lo_b + hi_b) * 0.5
    hb = (hi_b - lo_b) * 0.5
    d = r.b_to_a * cb + r.b_to_a_shift - ca
    e = ha + abs_matrix(r.b_to_a) * hb  # a box's half extent goes through the entries' absolute values
    if wp.abs(d[0]) > e[0] + r.pad_a or wp.abs(d[1]) > e[1] + r.pad_a or wp.abs(d[2]) > e[2] + r.pad_a:
        return False
    if axes == 6:
        d = r.a_to_b * ca + r.a_to_b_shift - cb
        e = hb + abs_matrix(r.a_to_b) * ha
        if wp.abs(d[0]) > e[0] + r.pad_b or wp.abs(d[1]) > e[1] + r.pad_b or wp.abs(d[2]) > e[2] + r.pad_b:
            return False
    return True


@wp.func
def _leaf_pair_rows(tree: TreeView, node_a: int, node_b: int) -> int:
    """Candidate rows of two leaves (global node ids): the product of their triangle counts."""
    return tree.node_triangle[node_a][1] * tree.node_triangle[node_b][1]


@wp.func
def _write_rows(
    tree: TreeView,
    rows: wp.vec4i,
    node_a: int,
    node_b: int,
    slot: wp.int64,
    candidate: wp.array[wp.vec4i],
    candidate_capacity: int,
) -> wp.int64:
    """Writes the triangle pairs of leaves ``node_a`` (of ``a``) and ``node_b`` (of ``b``, global
    node ids) from ``slot`` on; ``rows`` is the pair's ``(a, b, a's triangle order start, b's)``;
    returns the next slot."""
    ra = tree.node_triangle[node_a]
    rb = tree.node_triangle[node_b]
    for i in range(ra[0], ra[0] + ra[1]):
        tri_a = tree.tri_order[rows[2] + i]
        for j in range(rb[0], rb[0] + rb[1]):
            if slot < wp.int64(candidate_capacity):
                candidate[int(slot)] = wp.vec4i(rows[0], tri_a, rows[1], tree.tri_order[rows[3] + j])
            slot += wp.int64(1)
    return slot


@wp.func
def _is_leaf(tree: TreeView, node: int) -> bool:
    """Whether ``node`` (global id) is a leaf."""
    return tree.node_child[node][0] < 0


@wp.func
def _overlap(tree: TreeView, r: TreePair, na: int, nb: int, axes: int) -> bool:
    """Whether node ``na`` of ``a``'s tree and ``nb`` of ``b``'s (local ids) may overlap."""
    slot_a = r.slot_a_start + na
    slot_b = r.slot_b_start + nb
    return _boxes_overlap_mapped(tree.node_lower[slot_a], tree.node_upper[slot_a], tree.node_lower[slot_b],
                                 tree.node_upper[slot_b], r, axes)


CHILD_NONE = wp.constant(0)
"""Kind of a child pair (:func:`_child_kind`): its boxes do not overlap."""
CHILD_PUSH = wp.constant(1)
"""Kind of a child pair: its boxes overlap and one node is not a leaf (to the next level's front)."""
CHILD_LEAF = wp.constant(2)
"""Kind of a child pair: two leaves whose boxes overlap (their triangle pairs are candidates)."""


@wp.func
def _child_kind(tree: TreeView, r: TreePair, xa: int, xb: int, axes: int) -> int:
    """:data:`CHILD_NONE`, :data:`CHILD_PUSH` or :data:`CHILD_LEAF` for nodes ``xa``, ``xb`` (local ids)."""
    if not _overlap(tree, r, xa, xb, axes):
        return CHILD_NONE
    if _is_leaf(tree, r.node_a_start + xa) and _is_leaf(tree, r.node_b_start + xb):
        return CHILD_LEAF
    return CHILD_PUSH


@wp.func
def _is_push(kind: int) -> int:
    return wp.where(kind == CHILD_PUSH, 1, 0)


@wp.func
def _leaf_rows(tree: TreeView, r: TreePair, kind: int, xa: int, xb: int) -> int:
    """Candidate rows of a child pair: its leaves' triangle pairs, or none."""
    if kind != CHILD_LEAF:
        return 0
    return _leaf_pair_rows(tree, r.node_a_start + xa, r.node_b_start + xb)


@wp.func
def _push(front_out: wp.array[wp.vec3i], front_capacity: int, slot: wp.int64, kind: int, k: int, xa: int,
          xb: int) -> wp.int64:
    """Writes a child pair of kind :data:`CHILD_PUSH` of pair ``k`` into the front at ``slot``
    (below the capacity); returns the next slot."""
    if kind != CHILD_PUSH:
        return slot
    if slot < wp.int64(front_capacity):
        front_out[int(slot)] = wp.vec3i(k, xa, xb)
    return slot + wp.int64(1)


@wp.func
def _emit(tree: TreeView, row: wp.vec4i, r: TreePair, kind: int, xa: int, xb: int, slot: wp.int64,
          candidate: wp.array[wp.vec4i], candidate_capacity: int) -> wp.int64:
    """Writes the rows of a child pair of kind :data:`CHILD_LEAF` from ``slot``; returns the next slot."""
    if kind != CHILD_LEAF:
        return slot
    return _write_rows(tree, row, r.node_a_start + xa, r.node_b_start + xb, slot, candidate, candidate_capacity)


@wp.kernel
def _expand_kernel(
    tree: TreeView,
    tree_pair: wp.array[TreePair],
    pair_rows: wp.array[wp.vec4i],
    front_in: wp.array[wp.vec3i],
    front_in_count: wp.array[wp.int64],
    front_in_capacity: int,
    roots: int,
    object_triangle_start: wp.array[wp.int32],
    whole_max: int,
    num_blocks: int,
    front_capacity: int,
    candidate_capacity: int,
    axes: int,
    # Outputs
    front_out: wp.array[wp.vec3i],
    front_out_count: wp.array[wp.int64],
    front_peak: wp.array[wp.int64],
    candidate: wp.array[wp.vec4i],
    candidate_count: wp.array[wp.int64],
):
    """One level of the simultaneous descent: each node pair ``(k, na, nb)`` of ``front_in`` (pair
    ``k``'s nodes, local ids, boxes known to overlap) opens both nodes (a leaf stays itself) and
    tests the two to four pairs of children; overlapping pairs of two leaves become candidate rows,
    the others go to ``front_out``. With ``roots`` the entries are the pairs themselves (entry
    ``k`` is ``(k, 0, 0)``, its roots not tested yet: tested first), less the whole-object pairs
    (objects of at most ``whole_max`` triangles, :func:`_whole_pair_kernel`).

    ``num_blocks`` blocks stride over the entries; each round a block reserves its threads' front
    slots and rows with one atomic add each (:func:`~warp_ccd._src.runtime.buffers.block_reserve`). The front's
    counter (``front_peak``) keeps the largest level's count, against the front's capacity."""
    block, lane = wp.tid()
    width = wp.block_dim()
    n = int(wp.min(front_in_count[0], wp.int64(front_in_capacity)))
    base = block * width
    while base < n:
        e = base + lane
        k = int(0)
        r = TreePair()
        # The (up to) four child pairs (xa0 | xa1) x (xb0 | xb1) and their kinds (_child_kind), in
        # registers: no arrays indexed at run time (they would live in local memory).
        xa0 = int(0)
        xa1 = int(0)
        xb0 = int(0)
        xb1 = int(0)
        k00 = int(0)
        k01 = int(0)
        k10 = int(0)
        k11 = int(0)
        if e < n:
            na = int(0)
            nb = int(0)
            if roots != 0:
                k = e
            else:
                f = front_in[e]
                k = f[0]
                na = f[1]
                nb = f[2]
            r = tree_pair[k]
            ca = tree.node_child[r.node_a_start + na]
            cb = tree.node_child[r.node_b_start + nb]
            xa0 = na
            xa1 = na
            xb0 = nb
            xb1 = nb
            if roots == 0 or (not _is_whole_pair(object_triangle_start, r.a, r.b, whole_max)
                              and _overlap(tree, r, na, nb, axes)):
                if ca[0] < 0 and cb[0] < 0:
                    k00 = CHILD_LEAF  # two roots that are leaves
                else:
                    if ca[0] >= 0:
                        xa0 = ca[0]
                        xa1 = ca[1]
                    if cb[0] >= 0:
                        xb0 = cb[0]
                        xb1 = cb[1]
                    k00 = _child_kind(tree, r, xa0, xb0, axes)
                    if cb[0] >= 0:
                        k01 = _child_kind(tree, r, xa0, xb1, axes)
                    if ca[0] >= 0:
                        k10 = _child_kind(tree, r, xa1, xb0, axes)
                        if cb[0] >= 0:
                            k11 = _child_kind(tree, r, xa1, xb1, axes)
        num_push = _is_push(k00) + _is_push(k01) + _is_push(k10) + _is_push(k11)
        rows = (_leaf_rows(tree, r, k00, xa0, xb0) + _leaf_rows(tree, r, k01, xa0, xb1)
                + _leaf_rows(tree, r, k10, xa1, xb0) + _leaf_rows(tree, r, k11, xa1, xb1))
        slot = block_reserve(front_out_count, lane, num_push)
        if lane == width - 1:
            wp.atomic_max(front_peak, 0, slot + wp.int64(num_push))
        slot = _push(front_out, front_capacity, slot, k00, k, xa0, xb0)
        slot = _push(front_out, front_capacity, slot, k01, k, xa0, xb1)
        slot = _push(front_out, front_capacity, slot, k10, k, xa1, xb0)
        slot = _push(front_out, front_capacity, slot, k11, k, xa1, xb1)
        slot = block_reserve(candidate_count, lane, rows)
        if rows > 0:
            row = pair_rows[k]
            slot = _emit(tree, row, r, k00, xa0, xb0, slot, candidate, candidate_capacity)
            slot = _emit(tree, row, r, k01, xa0, xb1, slot, candidate, candidate_capacity)
            slot = _emit(tree, row, r, k10, xa1, xb0, slot, candidate, candidate_capacity)
            slot = _emit(tree, row, r, k11, xa1, xb1, slot, candidate, candidate_capacity)
        base += num_blocks * width


@wp.func
def _is_whole_pair(object_triangle_start: wp.array[wp.int32], a: int, b: int, whole_max: int) -> bool:
    """Whether objects ``a`` and ``b`` have at most ``whole_max`` triangles each (a whole-object
    pair, :func:`_whole_pair_kernel`, not the trees')."""
    ma = object_triangle_start[a + 1] - object_triangle_start[a]
    mb = object_triangle_start[b + 1] - object_triangle_start[b]
    return ma <= whole_max and mb <= whole_max


@wp.func
def _whole_row(topology: MeshTopology, world_vertex: wp.array[Any], world_vertex_start: wp.array[Any], swept: int,
               pad_abs: wp.float64, margin_rel: Any, big: int, i: int, small: int, m_small: int):
    """``(hits, count)``: bit ``j`` of the int64 ``hits`` is set when the world boxes of triangle
    ``i`` of ``big`` and ``j`` of ``small`` overlap (:func:`~warp_ccd._src.trees.bvh.triangle_box_at`, the
    trees' leaf boxes; with ``swept``, their boxes over the motion from ``world_vertex_start``)."""
    big_start = topology.shape_triangle_start[topology.object_shape[big]]
    lo, hi = leaf_box_at(topology, world_vertex, world_vertex_start, swept, pad_abs, margin_rel, big_start,
                     topology.object_vertex_start[big], i)
    tri_start = topology.shape_triangle_start[topology.object_shape[small]]
    vertex_start = topology.object_vertex_start[small]
    hits = wp.int64(0)
    count = int(0)
    for j in range(m_small):
        lo_j, hi_j = leaf_box_at(topology, world_vertex, world_vertex_start, swept, pad_abs, margin_rel, tri_start,
                             vertex_start, j)
        if boxes_overlap(lo, hi, lo_j, hi_j):
            hits = hits | (wp.int64(1) << wp.int64(j))
            count += 1
    return hits, count


@wp.func
def _write_whole_row(hits: wp.int64, m_small: int, a: int, b: int, big_is_a: bool, i: int, slot: wp.int64,
                     candidate: wp.array[wp.vec4i], candidate_capacity: int) -> wp.int64:
    """Writes the rows of a row's ``hits`` (:func:`_whole_row`) from ``slot``; returns the next slot."""
    for j in range(m_small):
        if (hits >> wp.int64(j)) & wp.int64(1) != wp.int64(0):
            if slot < wp.int64(candidate_capacity):
                if big_is_a:
                    candidate[int(slot)] = wp.vec4i(a, i, b, j)
                else:
                    candidate[int(slot)] = wp.vec4i(a, j, b, i)
            slot += wp.int64(1)
    return slot


@wp.kernel
def _whole_pair_kernel(
    topology: MeshTopology,
    world_vertex: wp.array[Any],
    world_vertex_start: wp.array[Any],
    swept: int,
    pad_abs: wp.float64,
    margin_rel: Any,
    pair: wp.array[wp.vec2i],
    pair_count: wp.array[wp.int64],
    pair_capacity: int,
    whole_max: int,
    lanes: int,
    num_blocks: int,
    candidate_capacity: int,
    # Outputs
    candidate: wp.array[wp.vec4i],
    candidate_count: wp.array[wp.int64],
):
    """Whole-object pairs: ``lanes`` threads per pair (a block holds ``block_dim / lanes`` pairs a
    round; ``num_blocks`` blocks stride over the stored pairs). For a pair of objects of at most
    ``whole_max`` triangles each, thread ``l`` takes triangles ``l, l + lanes, ...`` of the larger
    object and tests each one's world box against every triangle's of the smaller
    (:func:`_whole_row`); the block reserves the rows (:func:`~warp_ccd._src.runtime.buffers.block_reserve`) and
    each thread writes its hits (a thread with more than one triangle tests the later ones again).
    Other pairs are left to the trees."""
    block, lane = wp.tid()
    per_block = wp.block_dim() // lanes
    n = used_count(pair_count, pair_capacity)
    sub = lane % lanes
    for base in range(block * per_block, n, num_blocks * per_block):
        k = base + lane // lanes
        a = int(0)
        b = int(0)
        big = int(0)
        small = int(0)
        m_big = int(0)
        m_small = int(0)
        if k < n:
            p = pair[k]
            a = p[0]
            b = p[1]
            if _is_whole_pair(topology.object_triangle_start, a, b, whole_max):
                ma = topology.object_triangle_start[a + 1] - topology.object_triangle_start[a]
                mb = topology.object_triangle_start[b + 1] - topology.object_triangle_start[b]
                big = wp.where(ma >= mb, a, b)
                small = wp.where(ma >= mb, b, a)
                m_big = wp.max(ma, mb)
                m_small = wp.min(ma, mb)
        count = int(0)
        first = wp.int64(0)
        for i in range(sub, m_big, lanes):
            hits, found = _whole_row(topology, world_vertex, world_vertex_start, swept, pad_abs, margin_rel, big, i,
                                     small, m_small)
            if i == sub:
                first = hits
            count += found
        slot = block_reserve(candidate_count, lane, count)
        if count > 0:
            for i in range(sub, m_big, lanes):
                hits = first
                if i != sub:
                    hits, _found = _whole_row(topology, world_vertex, world_vertex_start, swept, pad_abs, margin_rel,
                                              big, i, small, m_small)
                slot = _write_whole_row(hits, m_small, a, b, big == a, i, slot, candidate, candidate_capacity)


_WHOLE = precision_overloads(_whole_pair_kernel, swept_arg_types)


class MidPhase:
    """What both mid phases share: the candidate buffer (``capacity``, it grows) of ``wp.vec4i`` rows
    ``(obj_a, tri_a, obj_b, tri_b)``, and the options of whole-object pairs, checked when set (read
    at each launch by :class:`MidPhaseBVH`, unused by :class:`MidPhaseAllPairs`, whose pairs are all
    whole: one setting serves either).

    Attributes:
        whole_triangles_max: pairs of objects of at most this many triangles each skip the trees (at
            most :data:`WHOLE_TRIANGLES_LIMIT`; 0, the default here: none): their triangles' world
            boxes are tested pair by pair in one launch (:func:`_whole_pair_kernel`); a scene of
            such objects alone launches no tree traversal.
        whole_lanes: threads per whole-object pair (default :data:`WHOLE_LANES`; a power of two up to 256).
    """

    def __init__(self, *, capacity: int = 4096, device: DeviceLike = None) -> None:
        self.device = wp.get_device(device)
        self.candidates = GrowableBuffer(wp.vec4i, capacity, self.device, "candidate triangle pairs")
        self.whole_triangles_max = 0
        self.whole_lanes = WHOLE_LANES

    @property
    def whole_triangles_max(self) -> int:
        """Pairs of objects of at most this many triangles each skip the trees (see the class docs)."""
        return self._whole_triangles_max

    @whole_triangles_max.setter
    def whole_triangles_max(self, value: int) -> None:
        self._whole_triangles_max = integer_option("whole_triangles_max", value, low=0, high=WHOLE_TRIANGLES_LIMIT)

    @property
    def whole_lanes(self) -> int:
        """Threads per whole-object pair (see the class docs)."""
        return self._whole_lanes

    @whole_lanes.setter
    def whole_lanes(self, value: int) -> None:
        self._whole_lanes = integer_option("whole_lanes", value, choices=(1, 2, 4, 8, 16, 32, 64, 128, 256))


class MidPhaseBVH(MidPhase):
    """Tree-vs-tree traversal over the broad phase's object pairs, level by level over the front of
    overlapping node pairs (see module docs).

    Args:
        bvh: the scene's :class:`~warp_ccd._src.trees.bvh.SceneBVH` (refit before each launch).
        capacity: initial capacity of the candidate buffer (it grows).
        front_capacity: initial capacity of each level's front of node pairs (it grows; default
            four per object).
        separating_axes: 6 (default) tests ``b``'s boxes as the boxes around them in ``a``'s space
            and ``a``'s in ``b``'s; 3 the first alone (more candidates, less arithmetic a test).
        whole_triangles_max: default :data:`WHOLE_TRIANGLES_MAX` up to :data:`WHOLE_OBJECTS_MAX` objects, else 0.
        clearance: candidates are the triangle pairs whose boxes come within this distance (scene units,
            >= 0): every test padded by it (a tree's boxes in its object's space by ``clearance /
            scale``, a whole-object pair's triangle boxes by half of it each), so that no pair of
            triangles within it is culled (:mod:`warp_ccd._src.narrowphase.clearance`). 0 (default): pairs whose
            boxes overlap.
        device: Warp device.

    Attributes:
        candidates, whole_triangles_max, whole_lanes: as in :class:`MidPhase`.
        front: the :class:`~warp_ccd._src.runtime.buffers.GrowableBuffer` of node pairs ``(pair, node a, node
            b)`` (``wp.vec3i``) between two levels (two halves, one read, one written); its
            counter holds the largest level's count.
        num_levels: expansion launches a frame: the deepest tree's levels less one (at least 1).
        separating_axes, clearance: as above (read at each launch: a captured frame keeps the value it
            was captured with).
        num_blocks, block_dim: the largest grid of an expansion, in blocks, and their size (on the
            CPU one block, of one thread that takes every node pair in turn unless
            ``wp.config.enable_cpu_blocks`` is set); a launch takes at most one thread per slot of
            its input (the pairs' capacity, the front's).

    The front's :meth:`~warp_ccd._src.runtime.buffers.GrowableBuffer.held` and ``numpy()`` mean little: its
    storage is two halves, its counter the largest level's count.
    """

    def __init__(self, bvh: SceneBVH, *, capacity: int = 4096, front_capacity: int | None = None,
                 separating_axes: int = 6, whole_triangles_max: int | None = None, clearance: float = 0.0,
                 device: DeviceLike = None) -> None:
        super().__init__(capacity=capacity, device=device)
        self.bvh = bvh
        self.clearance = number_option("clearance", clearance, low=0.0)
        self.separating_axes = integer_option("separating_axes", separating_axes, choices=SEPARATING_AXES)
        self.num_levels = max(1, bvh.num_levels - 1)
        self.front = GrowableBuffer(wp.vec3i, front_capacity or max(256, 4 * bvh.lower.shape[0]), self.device,
                                    "tree-pair front", factor=2)
        self.block_dim = block_dim_for(self.device)
        self.num_blocks = self.device.sm_count * EXPAND_THREADS_PER_SM // BLOCK_DIM if self.device.is_cuda else 1
        if whole_triangles_max is None:
            whole_triangles_max = WHOLE_TRIANGLES_MAX if bvh.lower.shape[0] <= WHOLE_OBJECTS_MAX else 0
        self.whole_triangles_max = whole_triangles_max
        # Entries of each level's front: [0] unused (level 0 is the pairs), zeroed by the pair kernel.
        self._level_count = wp.zeros(self.num_levels + 1, dtype=wp.int64, device=self.device)
        self._level_views = [self._level_count[i : i + 1] for i in range(self.num_levels + 1)]
        self._pairs_capacity = -1

    @property
    def counters(self) -> list[GrowableBuffer]:
        """The buffers with counters that :meth:`launch` resets and writes, whose counters the caller
        reads after it: the front (its largest level), then the candidates."""
        return [self.front, self.candidates]

    def launch(self, scene: Scene, pairs: GrowableBuffer, *, reset_counters: bool = True,
               world_vertex_start: wp.array | None = None) -> None:
        """Writes candidates of the object ``pairs`` of ``scene`` into :attr:`candidates`.

        Args:
            scene: the scene whose trees :attr:`bvh` holds (refit for this frame).
            pairs: the broad phase's object pairs.
            reset_counters: zero the counters of :attr:`counters` first; False when the caller has.
            world_vertex_start: the start of a linear motion to ``scene.world_vertex`` (a continuous
                frame: the trees were refit with it, and whole-object pairs test swept boxes too).
        """
        d = self.device
        if reset_counters:
            for buffer in self.counters:
                buffer.reset()
        if self._pairs_capacity != pairs.capacity:  # scratch follows the pair capacity
            self._pairs_capacity = pairs.capacity
            self._tree_pair = wp.zeros(pairs.capacity, dtype=TreePair, device=d)
            self._pair_rows = wp.zeros(pairs.capacity, dtype=wp.vec4i, device=d)
        tree = self.bvh.tree
        eps = float(np.finfo(np.float64 if scene.precision == "float64" else np.float32).eps)
        cap = self.front.capacity
        cand = self.candidates
        whole = self.whole_triangles_max
        if whole >= self.bvh.min_triangles:  # some object pairs may be whole-object pairs
            lanes = min(self.whole_lanes, self.block_dim)
            per_block = self.block_dim // lanes
            blocks = min(self.num_blocks, (pairs.capacity + per_block - 1) // per_block)
            wp.launch_tiled(_WHOLE[scene.precision], dim=[blocks],
                            inputs=[scene.topology, *self.bvh.sweep_args(scene, world_vertex_start,
                                                                         0.5 * self.clearance),
                                    scene.scalar_type(self.bvh.margin_rel),
                                    pairs.data, pairs.count, pairs.capacity, whole, lanes, blocks, cand.capacity],
                            outputs=[cand.data, cand.count], block_dim=self.block_dim, device=d)
        if self.bvh.max_triangles <= whole:
            return  # every pair is a whole-object pair
        wp.launch(_PAIR[scene.precision], dim=pairs.capacity,
                  inputs=[tree, scene.object_shape, scene.object_pose, scene.object_scale,
                          self.bvh.object_deforming, WORLD_ERROR_ULPS * eps, wp.float64(self.clearance),
                          pairs.data, pairs.count, pairs.capacity],
                  outputs=[self._tree_pair, self._pair_rows, self._level_count], device=d)
        halves = (self.front.data[:cap], self.front.data[cap:])
        for level in range(self.num_levels):
            roots = level == 0
            slots = pairs.capacity if roots else cap
            blocks = min(self.num_blocks, (slots + self.block_dim - 1) // self.block_dim)
            wp.launch_tiled(
                _expand_kernel, dim=[blocks],
                inputs=[tree, self._tree_pair, self._pair_rows, halves[(level + 1) % 2],
                        pairs.count if roots else self._level_views[level], slots, int(roots),
                        scene.object_triangle_start, whole, blocks, cap, cand.capacity, self.separating_axes],
                outputs=[halves[level % 2], self._level_views[level + 1], self.front.count, cand.data, cand.count],
                block_dim=self.block_dim, device=d)
