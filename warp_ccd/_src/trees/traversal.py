"""The one tree-pair traversal: a front of node pairs, level by level, for every item at once.

Three stages walk two trees together (or one tree against itself), and each is this one walk with its own
tests plugged in (:func:`front_kernel`, as coal writes ``collisionRecurseT`` once and newton builds kernel
variants from one factory):

* the mid phase (:mod:`~warp_ccd._src.midphase.bvh`): two objects' trees, node pairs whose boxes overlap,
  leaf pairs' triangle pairs written as candidates;
* the self-intersection stage (:mod:`~warp_ccd._src.narrowphase.self_intersection`): one tree against
  itself, each unordered node pair once, a leaf's own triangle pairs too;
* the distance query (:mod:`~warp_ccd._src.queries.tree_distance`): two trees, node pairs that may still
  hold the closest triangles (branch and bound), leaf pairs' triangles measured.

**The walk.** An item (an object pair, one object) starts as one front entry ``(item, root, root)``. Each
level is one launch over the front: an entry ``(k, na, nb)`` asks its use whether it is worth opening
(its ``entry``; the mid phase tests the roots' boxes, the distance query its bound), opens both nodes (a
leaf stays itself) and classifies the two to four child pairs (:data:`CHILD_NONE`, :data:`CHILD_PUSH`,
:data:`CHILD_LEAF`; with ``self_pairs``, a node against itself opens into ``(c0, c0)``, ``(c0, c1)``,
``(c1, c1)``, a leaf against itself is :data:`CHILD_SELF_LEAF`): a pair whose test (``near``) fails is
dropped, a pair of two leaves goes to the use (``leaf_rows``, ``reserve``, ``emit``), the others to the next
level's front. The deepest tree's levels bound the launches, so a frame is a fixed sequence of kernels (a
CUDA graph); each launch is a fixed grid whose blocks stride over the level's entries, and each round a
block reserves its front slots with one atomic add (:func:`~warp_ccd._src.runtime.buffers.block_reserve`).
The front is a buffer with a capacity and a counter (the largest level's count), grown as any other
(:class:`FrontWalk` holds it and launches the levels).

**Object pairs** (:class:`TreePair`, :data:`PAIR_KERNELS`): what a walk of two objects' trees needs of a
pair, computed once per pair in float64: the trees' starts and the maps between the two objects' box spaces
(a rigid object's shape space, a deforming object's world) with paddings that bound every rounding of a
float32 box test (:func:`boxes_overlap_mapped`), so that a test never rejects what the world vertices would
put in contact.
"""

# No `from __future__ import annotations`: the kernel factory annotates with the types it is given.
from typing import Any

import warp as wp

from ..geometry.precision import precision_overloads
from ..geometry.primitives import _max_abs
from ..runtime.buffers import BLOCK_DIM, GrowableBuffer, block_dim_for, block_reserve, used_count
from .bvh import TreeView, abs_matrix, box_radius

# Forward kernels only. The pair kernel is compiled with the default contraction (its float64 paddings are
# the mid phase's); the walks' kernels live in their users' modules and take those modules' options.
wp.set_module_options({"enable_backward": False})

__all__ = ["CHILD_LEAF", "CHILD_NONE", "CHILD_PUSH", "CHILD_SELF_LEAF", "PAIR_KERNELS", "FrontWalk", "TreePair",
           "boxes_overlap_mapped", "front_kernel", "is_leaf", "node_pair_overlap"]

EXPAND_THREADS_PER_SM = 1024
"""Most threads of a level's launch per streaming multiprocessor on CUDA: the grid is fixed (so that the
frame can be a CUDA graph), no bigger than one thread per slot of the level's input (a small scene launches
few blocks), and its threads stride over the level's node pairs (1,024 and 2,048 measured alike)."""

PAIR_MAX_REGISTERS = 128
"""Most registers a thread of the pair set-up kernel on CUDA (it compiles to more when free; capped as the
exact test's kernels are)."""

TEST_ERROR_ULPS = 32.0
"""Bound on the rounding of one box test in float32 (centres, half extents, the transform applied),
in units in the last place of the boxes' and the translation's sizes."""

CHILD_NONE = wp.constant(0)
"""Kind of a child pair: its use's test drops it (boxes apart, beyond a bound)."""
CHILD_PUSH = wp.constant(1)
"""Kind of a child pair: kept, and one node is not a leaf (to the next level's front)."""
CHILD_LEAF = wp.constant(2)
"""Kind of a child pair: two leaves kept (their triangle pairs go to the use)."""
CHILD_SELF_LEAF = wp.constant(3)
"""Kind of a child pair of a walk with ``self_pairs``: a leaf against itself (its pairs ``i < j``)."""


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


PAIR_KERNELS = precision_overloads(_pair_kernel, lambda s, v, q, t: {"object_pose": wp.array[t]})


@wp.func
def boxes_overlap_mapped(lo_a: wp.vec3, hi_a: wp.vec3, lo_b: wp.vec3, hi_b: wp.vec3, r: TreePair, axes: int) -> bool:
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
def is_leaf(tree: TreeView, node: int) -> bool:
    """Whether ``node`` (global id) is a leaf."""
    return tree.node_child[node][0] < 0


@wp.func
def node_pair_overlap(tree: TreeView, r: TreePair, na: int, nb: int, axes: int) -> bool:
    """Whether node ``na`` of ``a``'s tree and ``nb`` of ``b``'s (local ids) may overlap
    (:func:`boxes_overlap_mapped` on their boxes)."""
    slot_a = r.slot_a_start + na
    slot_b = r.slot_b_start + nb
    return boxes_overlap_mapped(tree.node_lower[slot_a], tree.node_upper[slot_a], tree.node_lower[slot_b],
                                tree.node_upper[slot_b], r, axes)


@wp.func
def _child(kept: bool, tree: TreeView, node_a: int, node_b: int, xa: int, xb: int) -> int:
    """Kind of child pair ``(xa, xb)`` (local ids of trees starting at global ``node_a``, ``node_b``) that
    its use's test kept or dropped."""
    if not kept:
        return CHILD_NONE
    if is_leaf(tree, node_a + xa) and is_leaf(tree, node_b + xb):
        return CHILD_LEAF
    return CHILD_PUSH


@wp.func
def _own_child(tree: TreeView, node: int, x: int) -> int:
    """Kind of node ``x`` (local id) against itself: :data:`CHILD_SELF_LEAF` for a leaf, else to the front."""
    if is_leaf(tree, node + x):
        return CHILD_SELF_LEAF
    return CHILD_PUSH


@wp.func
def _is_push(kind: int) -> int:
    return wp.where(kind == CHILD_PUSH, 1, 0)


@wp.func
def _push(front_out: wp.array[wp.vec3i], front_capacity: int, slot: wp.int64, kind: int, k: int, xa: int,
          xb: int) -> wp.int64:
    """Writes a child pair of kind :data:`CHILD_PUSH` of item ``k`` into the front at ``slot`` (below the
    capacity); returns the next slot."""
    if kind != CHILD_PUSH:
        return slot
    if slot < wp.int64(front_capacity):
        front_out[int(slot)] = wp.vec3i(k, xa, xb)
    return slot + wp.int64(1)


def front_kernel(*, name: str, module: str, params_type: type, context_type: type, entry: wp.Function,
                 near: wp.Function, leaf_rows: wp.Function, reserve: wp.Function, emit: wp.Function,
                 self_pairs: bool = False) -> wp.Kernel:
    """One level of the walk, with a use's tests plugged in (module docs).

    Args:
        name: the kernel's name (unique in ``module``).
        module: the Python module the kernel belongs to (the caller's ``__name__``): it compiles with that
            module's options (contraction, backward passes), as the use's other kernels do.
        params_type: the ``@wp.struct`` of everything the use's functions read and write (its arrays,
            counters, capacities), passed to every launch.
        context_type: the ``@wp.struct`` ``entry`` returns for an entry (a default one stands for lanes past
            the level's entries).
        entry: ``entry(params, tree, k, na, nb, roots) -> (context, node_a, node_b, open)``: item ``k``'s
            context, the global ids of its trees' node 0 (the same for one tree), and whether node pair
            ``(na, nb)`` is opened (``roots``: the level-0 entry, whose own test is still to be made).
        near: ``near(params, tree, context, xa, xb) -> bool``: whether child pair ``(xa, xb)`` (local ids) is
            kept.
        leaf_rows: ``leaf_rows(params, tree, context, kind, xa, xb) -> int``: the rows a child pair of that
            kind gives (0 for :data:`CHILD_NONE` and :data:`CHILD_PUSH`).
        reserve: ``reserve(params, lane, rows) -> int64``: cooperative (every lane calls it): the lane's
            first output slot for its ``rows``.
        emit: ``emit(params, tree, context, k, kind, xa, xb, slot) -> int64``: writes (or measures) a child
            pair's rows from ``slot``; returns the next slot. Called for the four child pairs of a lane
            with rows, whatever their kinds.
        self_pairs: a tree against itself: an entry ``(k, n, n)`` opens into its children against
            themselves and each other (each unordered node pair reached once).

    Returns:
        A kernel launched by :meth:`FrontWalk.launch`: ``(tree, params, front_in, front_in_count,
        front_in_capacity, roots, num_blocks, front_capacity, front_out, front_out_count, front_peak)``.
    """

    @wp.kernel(name=name, module=module, enable_backward=False)
    def kernel(
        tree: TreeView,
        params: params_type,
        front_in: wp.array[wp.vec3i],
        front_in_count: wp.array[wp.int64],
        front_in_capacity: int,
        roots: int,
        num_blocks: int,
        front_capacity: int,
        # Outputs
        front_out: wp.array[wp.vec3i],
        front_out_count: wp.array[wp.int64],
        front_peak: wp.array[wp.int64],
    ):
        block, lane = wp.tid()
        width = wp.block_dim()
        n = int(wp.min(front_in_count[0], wp.int64(front_in_capacity)))
        base = block * width
        while base < n:
            e = base + lane
            k = int(0)
            ctx = context_type()
            # The (up to) four child pairs (xa0 | xa1) x (xb0 | xb1) and their kinds, in registers: no
            # arrays indexed at run time (they would live in local memory).
            xa0 = int(0)
            xa1 = int(0)
            xb0 = int(0)
            xb1 = int(0)
            k00 = CHILD_NONE
            k01 = CHILD_NONE
            k10 = CHILD_NONE
            k11 = CHILD_NONE
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
                node_a = int(0)
                node_b = int(0)
                opened = False
                ctx, node_a, node_b, opened = entry(params, tree, k, na, nb, roots)
                if opened:
                    ca = tree.node_child[node_a + na]
                    cb = tree.node_child[node_b + nb]
                    xa0 = na
                    xa1 = na
                    xb0 = nb
                    xb1 = nb
                    diagonal = False
                    if wp.static(self_pairs):
                        diagonal = na == nb
                    if diagonal:
                        if ca[0] < 0:
                            k00 = CHILD_SELF_LEAF  # a root that is a leaf
                        else:
                            xa0 = ca[0]  # (c0, c0), (c0, c1), (c1, c1): k00, k01, k11
                            xb0 = ca[0]
                            xa1 = ca[1]
                            xb1 = ca[1]
                            k00 = _own_child(tree, node_a, xa0)
                            k01 = _child(near(params, tree, ctx, xa0, xb1), tree, node_a, node_b, xa0, xb1)
                            k11 = _own_child(tree, node_a, xa1)
                    elif ca[0] < 0 and cb[0] < 0:
                        k00 = CHILD_LEAF  # two roots that are leaves
                    else:
                        if ca[0] >= 0:
                            xa0 = ca[0]
                            xa1 = ca[1]
                        if cb[0] >= 0:
                            xb0 = cb[0]
                            xb1 = cb[1]
                        k00 = _child(near(params, tree, ctx, xa0, xb0), tree, node_a, node_b, xa0, xb0)
                        if cb[0] >= 0:
                            k01 = _child(near(params, tree, ctx, xa0, xb1), tree, node_a, node_b, xa0, xb1)
                        if ca[0] >= 0:
                            k10 = _child(near(params, tree, ctx, xa1, xb0), tree, node_a, node_b, xa1, xb0)
                            if cb[0] >= 0:
                                k11 = _child(near(params, tree, ctx, xa1, xb1), tree, node_a, node_b, xa1, xb1)
            num_push = _is_push(k00) + _is_push(k01) + _is_push(k10) + _is_push(k11)
            rows = (leaf_rows(params, tree, ctx, k00, xa0, xb0) + leaf_rows(params, tree, ctx, k01, xa0, xb1)
                    + leaf_rows(params, tree, ctx, k10, xa1, xb0) + leaf_rows(params, tree, ctx, k11, xa1, xb1))
            slot = block_reserve(front_out_count, lane, num_push)
            if lane == width - 1:
                wp.atomic_max(front_peak, 0, slot + wp.int64(num_push))
            slot = _push(front_out, front_capacity, slot, k00, k, xa0, xb0)
            slot = _push(front_out, front_capacity, slot, k01, k, xa0, xb1)
            slot = _push(front_out, front_capacity, slot, k10, k, xa1, xb0)
            slot = _push(front_out, front_capacity, slot, k11, k, xa1, xb1)
            slot = reserve(params, lane, rows)
            if rows > 0:
                slot = emit(params, tree, ctx, k, k00, xa0, xb0, slot)
                slot = emit(params, tree, ctx, k, k01, xa0, xb1, slot)
                slot = emit(params, tree, ctx, k, k10, xa1, xb0, slot)
                slot = emit(params, tree, ctx, k, k11, xa1, xb1, slot)
            base += num_blocks * width

    return kernel


class FrontWalk:
    """The host side of a walk (module docs): the front between two levels, each level's count, the grid,
    and the launches of one walk.

    Args:
        tree_levels: levels of the deepest tree walked (the walk launches one fewer, at least 1).
        front_capacity: initial capacity of the front (it grows).
        name: what the front holds, for the message of a buffer that cannot grow.
        device: Warp device.

    Attributes:
        front: the :class:`~warp_ccd._src.runtime.buffers.GrowableBuffer` of node pairs ``(item, node a,
            node b)`` (``wp.vec3i``) between two levels (two halves, one read, one written); its counter holds
            the largest level's count, so its ``held()`` and ``numpy()`` mean little.
        num_levels: launches a walk: the deepest tree's levels less one (at least 1).
        level_count: ``(num_levels + 1,)`` int64 entries of each level's front (``[0]`` unused: level 0 is
            the items); a walk's levels below the roots must be zeroed before it (:meth:`launch` or a kernel
            of the caller's does).
        num_blocks, block_dim: the largest grid of a launch, in blocks, and their size (on the CPU one block,
            of one thread that takes every entry in turn unless ``wp.config.enable_cpu_blocks`` is set); a
            launch takes at most one thread per slot of its input.
    """

    def __init__(self, tree_levels: int, front_capacity: int, name: str, device) -> None:
        self.device = d = wp.get_device(device)
        self.num_levels = max(1, int(tree_levels) - 1)
        self.front = GrowableBuffer(wp.vec3i, front_capacity, d, name, factor=2)
        self.block_dim = block_dim_for(d)
        self.num_blocks = d.sm_count * EXPAND_THREADS_PER_SM // BLOCK_DIM if d.is_cuda else 1
        self.level_count = wp.zeros(self.num_levels + 1, dtype=wp.int64, device=d)
        self._level_views = [self.level_count[i : i + 1] for i in range(self.num_levels + 1)]

    def launch(self, kernel: wp.Kernel, tree: TreeView, params: Any, items_count: wp.array, items_capacity: int, *,
               zero_levels: bool = True) -> None:
        """Enqueues the walk of the items: one launch of ``kernel`` (:func:`front_kernel`) per level.

        Args:
            kernel: the walk's level kernel.
            tree: the trees walked.
            params: the use's ``@wp.struct`` of arrays and options.
            items_count: ``(1,)`` int64 device count of the items (the level-0 entries).
            items_capacity: the items' slots (the level-0 grid's bound).
            zero_levels: zero :attr:`level_count` first (one memset); False when a kernel of the caller's
                already did (the mid phase's pair kernel does, saving a graph node a frame).
        """
        if zero_levels:
            self.level_count.zero_()
        cap = self.front.capacity
        halves = (self.front.data[:cap], self.front.data[cap:])
        for level in range(self.num_levels):
            roots = level == 0
            slots = items_capacity if roots else cap
            blocks = min(self.num_blocks, (slots + self.block_dim - 1) // self.block_dim)
            wp.launch_tiled(
                kernel, dim=[blocks],
                inputs=[tree, params, halves[(level + 1) % 2], items_count if roots else self._level_views[level],
                        slots, int(roots), blocks, cap],
                outputs=[halves[level % 2], self._level_views[level + 1], self.front.count],
                block_dim=self.block_dim, device=self.device)
