"""Least distances of object pairs however far apart: branch and bound over their two trees, on the device.

:class:`TreeDistance` answers, for each queried object pair ``(a, b)``, how close their surfaces come,
with no cut-off distance (where the clearance stage, :mod:`warp_ccd._src.narrowphase.clearance`, reports only
pairs within one). It walks the two objects' trees together, level by level for every queried pair at
once, as the mid phase does: the tree-pair walk (:mod:`warp_ccd._src.trees.traversal`) with this query's
tests plugged in, which keep a node pair only while it may still hold the pair's closest triangles:

* every queried pair has an upper bound ``U`` on its distance, lowered with ``atomic_min`` by every
  triangle distance measured (:func:`~warp_ccd._src.geometry.distance.tri_tri_distance`): first by one
  greedy descent of both trees (:func:`_greedy_kernel`: the nearest child boxes at each step, down
  to a pair of leaves), which for objects apart lands at or near their closest triangles, then at
  each node pair of the walk by that of the nodes' first triangles, and at each pair of leaves by
  those of their triangles;
* a node pair whose boxes are farther apart than ``U`` is dropped (by more than the rounding of a
  triangle distance: :data:`PRUNE_SLACK_ULPS`). The boxes' distance is bounded below as the mid
  phase tests them (:func:`_box_gap`): in ``a``'s space, the distance between ``a``'s box and the
  box around ``b``'s there (which holds it), each axis's gap less the test's rounding padding, times
  ``a``'s scale; or the same in ``b``'s space; the larger of the two;
* a pair of leaves' triangle pair at most ``U`` apart (when it is measured) goes to a list
  (capacity + counter) with its distance; after the walk, each pair's closest triangle pair is the least key
  ``tri_a << 32 | tri_b`` among the listed ones at exactly its final ``U``. ``U`` is always some
  measured distance, and the triangle pair of least measured distance is never dropped (its boxes
  are never farther apart than any ``U`` by more than the slack), so the answer is the least
  distance over all triangle pairs whatever order the device visited the node pairs in: the same on
  every device and run.

Cost: the node pairs within ``U`` of each other at each level, about those near the closest points
for objects apart (a few per level), those facing each other for surfaces close together. The
levels are the deepest tree's; a frame is a fixed sequence of launches (a CUDA graph).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import warp as wp

from ..geometry.distance import DISTANCE_ERROR_ULPS, feature_distance, tri_tri_distance
from ..geometry.precision import precision_overloads
from ..geometry.primitives import _unit_normal
from ..geometry.triangle import TOLERANCE
from ..runtime.aliases import DeviceLike
from ..runtime.buffers import GrowableBuffer, reserve_slot, used_count
from ..runtime.options import check_option
from ..scene.scene import MeshTopology, Scene, mesh_triangle
from ..trees.bvh import WORLD_ERROR_ULPS, SceneBVH, TreeView, abs_matrix
from ..trees.traversal import CHILD_LEAF, PAIR_KERNELS, FrontWalk, TreePair, front_kernel

# Forward kernels only; no FMA contraction, so that CPU and CUDA round every step alike.
wp.set_module_options({"enable_backward": False, "fuse_fp": False})

__all__ = ["TreeDistance"]

KEY_NONE = wp.constant(wp.int64(0x7FFFFFFFFFFFFFFF))
"""A pair's triangle key before any listed triangle pair lowered it."""

PRUNE_SLACK_ULPS = 4.0 * DISTANCE_ERROR_ULPS
"""A node pair is dropped only when its boxes are farther apart than the bound by more than this many
units in the last place of the bound plus the size of their triangles: a triangle distance is within
:data:`~warp_ccd._src.geometry.distance.DISTANCE_ERROR_ULPS` units of its pair's extent of the exact one, so
the triangle pair of least computed distance is never dropped (module docstring)."""


@wp.func
def _axis_gap(d: wp.vec3, e: wp.vec3, pad: float) -> float:
    """The distance between two axis-aligned boxes whose centres are ``d`` apart and whose half
    extents add up to ``e``, each axis's gap less ``pad`` (0 when they may overlap)."""
    g = wp.max(wp.vec3(wp.abs(d[0]), wp.abs(d[1]), wp.abs(d[2])) - e - wp.vec3(pad), wp.vec3(0.0))
    return wp.length(g)


@wp.func
def _box_gap(lo_a: wp.vec3, hi_a: wp.vec3, lo_b: wp.vec3, hi_b: wp.vec3, r: TreePair, scale_a: float,
             scale_b: float):
    """``(gap, size)``: a lower bound on the world distance between box ``a`` (``a``'s space) and box
    ``b`` (``b``'s): in ``a``'s space, the distance between ``a``'s box and the box around ``b``'s
    (the mid phase's test, along ``a``'s axes: each axis's gap less the test's rounding padding),
    times ``a``'s scale, or the same in ``b``'s space, the larger; and the sum of their diagonals in
    the world (a bound on the size of the triangles within)."""
    ca = (lo_a + hi_a) * 0.5
    ha = (hi_a - lo_a) * 0.5
    cb = (lo_b + hi_b) * 0.5
    hb = (hi_b - lo_b) * 0.5
    gap_a = _axis_gap(r.b_to_a * cb + r.b_to_a_shift - ca, ha + abs_matrix(r.b_to_a) * hb, r.pad_a)
    gap_b = _axis_gap(r.a_to_b * ca + r.a_to_b_shift - cb, hb + abs_matrix(r.a_to_b) * ha, r.pad_b)
    size = 2.0 * (wp.length(ha) * scale_a + wp.length(hb) * scale_b)
    return wp.max(gap_a * scale_a, gap_b * scale_b), size


@wp.func
def _beyond(tree: TreeView, r: TreePair, na: int, nb: int, scale_a: float, scale_b: float, bound: Any,
            ulp: wp.float64) -> bool:
    """Whether node ``na`` of ``a``'s tree and ``nb`` of ``b``'s (local ids) are farther apart than
    ``bound`` by more than the rounding of a triangle distance (:data:`PRUNE_SLACK_ULPS` units in the
    last place of the bound plus the triangles' size): none of their triangle pairs can be closer."""
    slot_a = r.slot_a_start + na
    slot_b = r.slot_b_start + nb
    gap, size = _box_gap(tree.node_lower[slot_a], tree.node_upper[slot_a], tree.node_lower[slot_b],
                         tree.node_upper[slot_b], r, scale_a, scale_b)
    slack = wp.float64(PRUNE_SLACK_ULPS) * ulp * (wp.float64(bound) + wp.float64(size))
    return wp.float64(gap) > wp.float64(bound) + slack


@wp.func
def _first_triangle(tree: TreeView, node_start: int, tri_start: int, node: int) -> int:
    """The first triangle (local id) of ``node`` (local id) of a tree."""
    return tree.tri_order[tri_start + tree.node_triangle[node_start + node][0]]


@wp.func
def _measure(mesh: MeshTopology, world_vertex: wp.array[Any], r: TreePair, k: int, tri_a: int, tri_b: int,
             tol_rel: wp.float64, upper: wp.array[Any], listed_capacity: int, listed: wp.array[wp.vec4i],
             listed_distance: wp.array[Any], listed_count: wp.array[wp.int64], leaf: bool):
    """The exact distance of triangles ``tri_a`` of ``a`` and ``tri_b`` of ``b`` (pair ``k``): it
    lowers the pair's bound; measured at a pair of leaves (``leaf``), it is listed when it is at most
    the bound it met. An inner node pair's triangles give only their feature distance
    (:func:`~warp_ccd._src.geometry.distance.feature_distance`: the same bits as the exact distance of
    triangles that do not intersect, a bound above it for those that do), and are measured again at
    their leaves, whose pair a bound they set never drops."""
    v0, v1, v2 = mesh_triangle(mesh, world_vertex, r.a, tri_a)
    u0, u1, u2 = mesh_triangle(mesh, world_vertex, r.b, tri_b)
    tol = type(v0[0])(tol_rel)
    d = type(tol)(0.0)
    if leaf:
        d, p, q = tri_tri_distance(v0, v1, v2, u0, u1, u2, tol)
    else:
        d, p, q = feature_distance(v0, v1, v2, u0, u1, u2, tol)
    if d <= wp.atomic_min(upper, k, d) and leaf:
        slot = reserve_slot(listed_count, listed_capacity)
        if slot >= 0:
            listed[slot] = wp.vec4i(k, tri_a, tri_b, 0)
            listed_distance[slot] = d


@wp.func
def _scale(object_scale: wp.array[wp.float32], object_deforming: wp.array[wp.int32], obj: int) -> float:
    """The factor from ``obj``'s box space to the world: its scale, 1 for a deforming object."""
    if object_deforming[obj] != 0:
        return 1.0
    return object_scale[obj]


@wp.func
def _leaf_pairs(tree: TreeView, mesh: MeshTopology, world_vertex: wp.array[Any], r: TreePair, k: int, xa: int,
                xb: int, tol_rel: wp.float64, upper: wp.array[Any], listed_capacity: int,
                listed: wp.array[wp.vec4i], listed_distance: wp.array[Any], listed_count: wp.array[wp.int64]):
    """:func:`_measure` every triangle pair of two leaves (local ids ``xa``, ``xb``) of pair ``k``."""
    ra = tree.node_triangle[r.node_a_start + xa]
    rb = tree.node_triangle[r.node_b_start + xb]
    for i in range(ra[0], ra[0] + ra[1]):
        tri_a = tree.tri_order[r.tri_a_start + i]
        for j in range(rb[0], rb[0] + rb[1]):
            _measure(mesh, world_vertex, r, k, tri_a, tree.tri_order[r.tri_b_start + j], tol_rel, upper,
                     listed_capacity, listed, listed_distance, listed_count, True)


@wp.struct
class DistancePair:
    """An entry's pair: its :class:`~warp_ccd._src.trees.traversal.TreePair`, the factors from its box
    spaces to the world, its bound (in float64: a float32 bound widens exactly)."""

    r: TreePair
    scale_a: float
    scale_b: float
    bound: wp.float64


def _params_struct(name: str, scalar: type, vec3: type):
    """The ``@wp.struct`` of what the walk reads and writes besides the trees, in one precision."""
    fields = {"mesh": MeshTopology, "world_vertex": wp.array[vec3], "object_scale": wp.array[wp.float32],
              "object_deforming": wp.array[wp.int32], "tree_pair": wp.array[TreePair], "tol_rel": wp.float64,
              "ulp": wp.float64, "upper": wp.array[scalar], "listed": wp.array[wp.vec4i],
              "listed_distance": wp.array[scalar], "listed_count": wp.array[wp.int64], "listed_capacity": int}
    return wp.struct(type(name, (), {"__annotations__": fields, "__module__": __name__, "__qualname__": name}))


_PARAMS = {"float32": _params_struct("DistanceParams32", wp.float32, wp.vec3),
           "float64": _params_struct("DistanceParams64", wp.float64, wp.vec3d)}


@wp.func
def _entry(p: Any, tree: TreeView, k: int, na: int, nb: int, roots: int):
    """Pair ``k`` and its bound; an entry still within the bound (the roots always) lowers it by the
    feature distance of the nodes' first triangles (:func:`_measure`) and is opened."""
    c = DistancePair()
    c.r = p.tree_pair[k]
    c.scale_a = _scale(p.object_scale, p.object_deforming, c.r.a)
    c.scale_b = _scale(p.object_scale, p.object_deforming, c.r.b)
    c.bound = wp.float64(p.upper[k])
    opened = roots != 0 or not _beyond(tree, c.r, na, nb, c.scale_a, c.scale_b, c.bound, p.ulp)
    if opened:
        _measure(p.mesh, p.world_vertex, c.r, k, _first_triangle(tree, c.r.node_a_start, c.r.tri_a_start, na),
                 _first_triangle(tree, c.r.node_b_start, c.r.tri_b_start, nb), p.tol_rel, p.upper,
                 p.listed_capacity, p.listed, p.listed_distance, p.listed_count, False)
        c.bound = wp.float64(p.upper[k])
    return c, c.r.node_a_start, c.r.node_b_start, opened


@wp.func
def _near(p: Any, tree: TreeView, c: DistancePair, xa: int, xb: int) -> bool:
    """A child pair is kept while it is within the bound (:func:`_beyond`)."""
    return not _beyond(tree, c.r, xa, xb, c.scale_a, c.scale_b, c.bound, p.ulp)


@wp.func
def _rows(p: Any, tree: TreeView, c: DistancePair, kind: int, xa: int, xb: int) -> int:
    """A pair of leaves is one visit (its triangle pairs measured, nothing written)."""
    return wp.where(kind == CHILD_LEAF, 1, 0)


@wp.func
def _reserve(p: Any, lane: int, rows: int) -> wp.int64:
    return wp.int64(0)  # measured triangle pairs are listed one by one (reserve_slot), not per block


@wp.func
def _emit(p: Any, tree: TreeView, c: DistancePair, k: int, kind: int, xa: int, xb: int,
          slot: wp.int64) -> wp.int64:
    """Measures every triangle pair of a pair of leaves (:func:`_leaf_pairs`)."""
    if kind == CHILD_LEAF:
        _leaf_pairs(tree, p.mesh, p.world_vertex, c.r, k, xa, xb, p.tol_rel, p.upper, p.listed_capacity, p.listed,
                    p.listed_distance, p.listed_count)
    return slot


_WALK = {prec: front_kernel(name=f"distance_walk_{prec}", module=__name__, params_type=params,
                            context_type=DistancePair, entry=_entry, near=_near, leaf_rows=_rows, reserve=_reserve,
                            emit=_emit) for prec, params in _PARAMS.items()}


@wp.func
def _gap(tree: TreeView, r: TreePair, xa: int, xb: int, scale_a: float, scale_b: float) -> float:
    """:func:`_box_gap` of node ``xa`` of ``a``'s tree and ``xb`` of ``b``'s (local ids), the gap alone."""
    gap, size = _box_gap(tree.node_lower[r.slot_a_start + xa], tree.node_upper[r.slot_a_start + xa],
                         tree.node_lower[r.slot_b_start + xb], tree.node_upper[r.slot_b_start + xb], r, scale_a,
                         scale_b)
    return gap


@wp.kernel
def _greedy_kernel(
    tree: TreeView,
    mesh: MeshTopology,
    world_vertex: wp.array[Any],
    object_scale: wp.array[wp.float32],
    object_deforming: wp.array[wp.int32],
    tree_pair: wp.array[TreePair],
    pair_count: wp.array[wp.int64],
    pair_capacity: int,
    tol_rel: wp.float64,
    listed_capacity: int,
    # Outputs
    upper: wp.array[Any],
    listed: wp.array[wp.vec4i],
    listed_distance: wp.array[Any],
    listed_count: wp.array[wp.int64],
):
    """One thread per queried pair: a first bound, from one descent of both trees that always takes
    the child pair whose boxes are nearest (their gaps, :func:`_box_gap`), down to a pair of leaves
    whose triangles it measures. For objects apart this lands at or near the closest triangles, so
    that the walk keeps few node pairs from the first level on."""
    k = wp.tid()
    if k >= used_count(pair_count, pair_capacity):
        return
    r = tree_pair[k]
    scale_a = _scale(object_scale, object_deforming, r.a)
    scale_b = _scale(object_scale, object_deforming, r.b)
    na = int(0)
    nb = int(0)
    while True:
        ca = tree.node_child[r.node_a_start + na]
        cb = tree.node_child[r.node_b_start + nb]
        if ca[0] < 0 and cb[0] < 0:
            _leaf_pairs(tree, mesh, world_vertex, r, k, na, nb, tol_rel, upper, listed_capacity, listed,
                        listed_distance, listed_count)
            return
        xa0 = wp.where(ca[0] >= 0, ca[0], na)
        xa1 = wp.where(ca[0] >= 0, ca[1], na)
        xb0 = wp.where(cb[0] >= 0, cb[0], nb)
        xb1 = wp.where(cb[0] >= 0, cb[1], nb)
        na = xa0
        nb = xb0
        best = _gap(tree, r, xa0, xb0, scale_a, scale_b)
        g = _gap(tree, r, xa0, xb1, scale_a, scale_b)
        if g < best:
            best = g
            na = xa0
            nb = xb1
        g = _gap(tree, r, xa1, xb0, scale_a, scale_b)
        if g < best:
            best = g
            na = xa1
            nb = xb0
        g = _gap(tree, r, xa1, xb1, scale_a, scale_b)
        if g < best:
            na = xa1
            nb = xb1


@wp.kernel
def _reset_kernel(
    pair_count: wp.array[wp.int64],
    pair_capacity: int,
    # Outputs
    upper: wp.array[Any],
    best: wp.array[wp.int64],
):
    """One thread per queried pair: bound ``+inf``, no triangle pair yet."""
    k = wp.tid()
    if k < used_count(pair_count, pair_capacity):
        upper[k] = type(upper[k])(wp.inf)
        best[k] = KEY_NONE


@wp.kernel
def _pick_kernel(
    listed: wp.array[wp.vec4i],
    listed_distance: wp.array[Any],
    listed_count: wp.array[wp.int64],
    listed_capacity: int,
    upper: wp.array[Any],
    # Outputs
    best: wp.array[wp.int64],
):
    """One thread per listed triangle pair at its pair's final bound: the pair's least key."""
    i = wp.tid()
    if i >= used_count(listed_count, listed_capacity):
        return
    row = listed[i]
    if listed_distance[i] == upper[row[0]]:
        wp.atomic_min(best, row[0], (wp.int64(row[1]) << wp.int64(32)) + wp.int64(row[2]))


@wp.kernel
def _answer_kernel(
    mesh: MeshTopology,
    world_vertex: wp.array[Any],
    pair: wp.array[wp.vec2i],
    pair_count: wp.array[wp.int64],
    pair_capacity: int,
    best: wp.array[wp.int64],
    tol_rel: wp.float64,
    # Outputs
    distance: wp.array[Any],
    point: wp.array2d[Any],
    normal: wp.array[Any],
    triangle: wp.array[wp.vec2i],
):
    """One thread per queried pair: its closest triangle pair again, its distance, closest points and
    direction (``(q - p) / |q - p|``; for intersecting triangles, ``n_a - n_b`` of their unit normals
    normalised, or zero when that vanishes)."""
    k = wp.tid()
    if k >= used_count(pair_count, pair_capacity):
        return
    p = pair[k]
    key = best[k]
    if key == KEY_NONE:  # only in a run whose buffers overflowed (it runs again)
        distance[k] = type(distance[k])(wp.inf)
        triangle[k] = wp.vec2i(-1, -1)
        return
    tri_a = int(key >> wp.int64(32))
    tri_b = int(key & wp.int64(0xFFFFFFFF))
    v0, v1, v2 = mesh_triangle(mesh, world_vertex, p[0], tri_a)
    u0, u1, u2 = mesh_triangle(mesh, world_vertex, p[1], tri_b)
    tol = type(v0[0])(tol_rel)
    d, x, y = tri_tri_distance(v0, v1, v2, u0, u1, u2, tol)
    n = y - x
    if d > type(d)(0.0):
        n = n / d
    else:
        na, degenerate_a = _unit_normal(v0, v1, v2, tol)
        nb, degenerate_b = _unit_normal(u0, u1, u2, tol)
        n = na - nb
        if wp.length(n) > type(d)(0.0):
            n = wp.normalize(n)
    distance[k] = d
    point[k, 0] = x
    point[k, 1] = y
    normal[k] = n
    triangle[k] = wp.vec2i(tri_a, tri_b)


_GREEDY = precision_overloads(_greedy_kernel, lambda s, v, q, t: {
    "world_vertex": wp.array[v], "upper": wp.array[s], "listed_distance": wp.array[s]})
_RESET = precision_overloads(_reset_kernel, lambda s, v, q, t: {"upper": wp.array[s]})
_PICK = precision_overloads(_pick_kernel, lambda s, v, q, t: {"listed_distance": wp.array[s], "upper": wp.array[s]})
_ANSWER = precision_overloads(_answer_kernel, lambda s, v, q, t: {
    "world_vertex": wp.array[v], "distance": wp.array[s], "point": wp.array2d[v], "normal": wp.array[v]})


class TreeDistance:
    """Branch and bound over two trees: the least distance of each queried object pair (module docs);
    owns its front, its list of measured triangle pairs and its answers.

    Args:
        bvh: the scene's :class:`~warp_ccd._src.trees.bvh.SceneBVH` (refit before each launch).
        tolerance: relative tolerance of the triangle tests (intersecting or touching triangles are
            at distance 0; which triangles are degenerate).
        front_capacity: initial capacity of :attr:`front` (it grows).
        listed_capacity: initial capacity of :attr:`listed` (it grows).
        device: Warp device.

    Attributes:
        front: :class:`~warp_ccd._src.runtime.buffers.GrowableBuffer` of node pairs ``(pair, node a, node
            b)`` between two levels (two halves); its counter holds the largest level's count.
        listed: :class:`~warp_ccd._src.runtime.buffers.GrowableBuffer` of the measured triangle pairs
            ``(pair, tri_a, tri_b, 0)`` that were within their pair's bound when measured.
        distance, point, normal, triangle: per queried pair (the pairs' capacity): least distance
            (the scene's scalar type), closest points ``(capacity, 2)`` (on ``a``, on ``b``), unit
            direction from ``a`` to ``b``, closest triangle pair ``(tri_a, tri_b)``.
    """

    def __init__(self, bvh: SceneBVH, *, tolerance: float = TOLERANCE, front_capacity: int = 1024,
                 listed_capacity: int = 1024, device: DeviceLike = None) -> None:
        self.bvh = bvh
        self.device = wp.get_device(device)
        self.tolerance = check_option("tolerance", tolerance)
        self.walk = FrontWalk(bvh.num_levels, front_capacity, "distance front", self.device)
        self.front = self.walk.front
        self.listed = GrowableBuffer(wp.vec4i, listed_capacity, self.device, "measured triangle pairs")
        self._pairs_for = None
        self._listed_for = None

    @property
    def counters(self) -> list[GrowableBuffer]:
        """The buffers with counters that :meth:`launch` writes: the front (its largest level), the list."""
        return [self.front, self.listed]

    def _scratch(self, scene: Scene, pairs: GrowableBuffer) -> None:
        d = self.device
        if self._pairs_for != (pairs.capacity, scene.precision):
            self._pairs_for = (pairs.capacity, scene.precision)
            cap = pairs.capacity
            self._tree_pair = wp.zeros(cap, dtype=TreePair, device=d)
            self._pair_rows = wp.zeros(cap, dtype=wp.vec4i, device=d)
            self.upper = wp.zeros(cap, dtype=scene.scalar_type, device=d)
            self.best = wp.zeros(cap, dtype=wp.int64, device=d)
            self.distance = wp.zeros(cap, dtype=scene.scalar_type, device=d)
            self.point = wp.zeros((cap, 2), dtype=scene.vec3_type, device=d)
            self.normal = wp.zeros(cap, dtype=scene.vec3_type, device=d)
            self.triangle = wp.zeros(cap, dtype=wp.vec2i, device=d)
        if self._listed_for != (self.listed.capacity, scene.precision):
            self._listed_for = (self.listed.capacity, scene.precision)
            self.listed_distance = wp.zeros(self.listed.capacity, dtype=scene.scalar_type, device=d)

    def launch(self, scene: Scene, pairs: GrowableBuffer) -> None:
        """The least distance of every object pair ``(a, b)`` of ``pairs`` (``a != b``), into
        :attr:`distance`, :attr:`point`, :attr:`normal`, :attr:`triangle` (host reads nothing; the
        caller resets and reads :attr:`counters` and runs again when a buffer grew)."""
        d = self.device
        self._scratch(scene, pairs)
        prec = scene.precision
        tree = self.bvh.tree
        tol = wp.float64(self.tolerance)
        eps = float(np.finfo(np.float64 if prec == "float64" else np.float32).eps)
        wp.launch(_RESET[prec], dim=pairs.capacity, inputs=[pairs.count, pairs.capacity],
                  outputs=[self.upper, self.best], device=d)
        wp.launch(PAIR_KERNELS[prec], dim=pairs.capacity,
                  inputs=[tree, scene.object_shape, scene.object_pose, scene.object_scale,
                          self.bvh.object_deforming, WORLD_ERROR_ULPS * eps, wp.float64(0.0), pairs.data, pairs.count,
                          pairs.capacity],
                  outputs=[self._tree_pair, self._pair_rows, self.walk.level_count], device=d)
        listed = self.listed
        wp.launch(_GREEDY[prec], dim=pairs.capacity,
                  inputs=[tree, scene.topology, scene.world_vertex, scene.object_scale, self.bvh.object_deforming,
                          self._tree_pair, pairs.count, pairs.capacity, tol, listed.capacity],
                  outputs=[self.upper, listed.data, self.listed_distance, listed.count], device=d)
        params = _PARAMS[prec]()
        params.mesh = scene.topology
        params.world_vertex = scene.world_vertex
        params.object_scale = scene.object_scale
        params.object_deforming = self.bvh.object_deforming
        params.tree_pair = self._tree_pair
        params.tol_rel = tol
        params.ulp = wp.float64(0.5 * eps)
        params.upper = self.upper
        params.listed = listed.data
        params.listed_distance = self.listed_distance
        params.listed_count = listed.count
        params.listed_capacity = listed.capacity
        # The pair kernel zeroed the levels' counts below the roots.
        self.walk.launch(_WALK[prec], tree, params, pairs.count, pairs.capacity, zero_levels=False)
        wp.launch(_PICK[prec], dim=listed.capacity,
                  inputs=[listed.data, self.listed_distance, listed.count, listed.capacity, self.upper],
                  outputs=[self.best], device=d)
        wp.launch(_ANSWER[prec], dim=pairs.capacity,
                  inputs=[scene.topology, scene.world_vertex, pairs.data, pairs.count, pairs.capacity, self.best, tol],
                  outputs=[self.distance, self.point, self.normal, self.triangle], device=d)
