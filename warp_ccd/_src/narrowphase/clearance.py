"""Clearance: which object pairs come within a distance, how close, where, and in which direction.

A pipeline with a clearance ``d > 0`` (:class:`~warp_ccd._src.pipeline.pipeline.CollisionPipeline`) reports every
object pair whose surfaces come within ``d``: object boxes are padded by ``d / 2`` for the broad phase
and the mid phase pads its tests by ``d`` (:class:`~warp_ccd._src.midphase.bvh.MidPhaseBVH`), so the
candidates hold every triangle pair within ``d``; the narrow phase finds the intersecting ones as
ever. This stage (:class:`ClearancePhase`) then gives each object pair its least distance, the
triangle pair that attains it, the two closest points and a direction, in five kernels:

1. one thread per object pair of the broad phase resets the pair's minima and enters ``(a, b)`` in a
   hash table (open addressing, linear probing, keys ``(a << 32 | b) + 1``, 0 empty; a power of two
   slots, at least twice the pairs' capacity, zeroed by one memset), so that a triangle pair finds its
   object pair's slot in a probe or two;
2. one thread per candidate: the least distance of the two triangles' feature pairs
   (:func:`~warp_ccd._src.geometry.distance.closest_features`, the scene's precision, centred; not
   measured, ``+inf``, where a cheap lower bound, the gap of their boxes or a separating plane of
   one, passes ``d`` by more than the rounding), kept with its pair's slot; a distance within ``d``
   lowers the pair's least (``atomic_min``);
3. one thread per candidate whose distance is its pair's least: the pair's closest triangle pair is
   the least key ``tri_a << 32 | tri_b`` among them (``atomic_min``), the same on every device and
   run whatever order the candidates came in;
4. one thread per intersecting triangle pair (the narrow phase's hits): its object pair intersects;
   the least such key, and the direction sums below;
5. one thread per object pair: a row for each pair within ``d`` (capacity + counter).

Why the feature distance serves: two triangles that do not intersect are as far apart as their
closest vertex-face or edge-edge pair; where some triangle pair of an object pair intersects, the
pair's distance is 0 whatever the others' distances, and the narrow phase says which do (the same
verdicts as without a clearance, so ``triangle_pairs`` do not change).

What a row holds (:class:`~warp_ccd._src.pipeline.pipeline.CollisionResult`: ``object_distance``,
``closest_points``, ``object_normal``, ``closest_triangles``, ``object_intersecting``):

* a pair that does not intersect: its least distance (scene units, the scene's precision), the
  closest points ``p`` on ``a`` and ``q`` on ``b``, the unit direction ``(q - p) / |q - p|`` from
  ``a`` to ``b``, and the triangle pair;
* an intersecting pair: distance 0, the first intersecting triangle pair (least key) and the middle
  of its intersection segment as both points (a point of a coplanar overlap for a coplanar
  contact), and the direction of least penetration from the intersection segments: the sum over
  the pair's intersecting triangle pairs of ``w (n_a - n_b)``, normalised, with ``n`` the
  triangles' unit normals as wound and ``w`` the length of their intersection segment (the longest
  edge of the two for a coplanar contact). For solids wound outward both terms point from ``a``
  into ``b`` across the crossing (``n_a`` out of ``a``, ``-n_b`` into ``b``): a crate sunk into a
  floor gets the floor's normal (the crate's sides cancel around the crossing), two overlapping
  spheres the line of their centres, a face pressed flush on another that face's normal.
* where that direction is undefined (the sums cancel, within ``1e-6`` of the sum of the weights: a
  sheet wound both ways, a symmetric crossing; or closest points that coincide without an
  intersection), the direction from the centre of ``a``'s box to ``b``'s (zero when they coincide).

Every device gives the same rows bit for bit (compiled without contraction, ties broken by triangle
keys), but for the direction of an intersecting pair: its sums are float64 atomic adds, in the order
the device ran them, so its last bits may vary from run to run on CUDA.

The reported distance is :func:`~warp_ccd._src.geometry.distance.closest_features`' in the scene's
precision, within its rounding (:data:`~warp_ccd._src.geometry.distance.DISTANCE_ERROR_ULPS`) of the exact
distance of the scene's vertices, a degenerate triangle within its height; a pair is within ``d``
when that distance is at most ``d`` rounded to the scene's precision.
"""

from __future__ import annotations

from typing import Any

import warp as wp

from ..geometry.distance import DISTANCE_ERROR_ULPS, centred_features
from ..geometry.precision import precision_overloads
from ..geometry.primitives import _max_edge, _unit_normal
from ..geometry.triangle import CONTACT_SEGMENT, TOLERANCE, tri_tri_segment
from ..runtime.aliases import DeviceLike
from ..runtime.buffers import GrowableBuffer, reserve_slot, used_count
from ..runtime.options import check_option
from ..scene.scene import MeshTopology, Scene, mesh_triangle

# Forward kernels only; no FMA contraction, so that CPU and CUDA round every step alike.
wp.set_module_options({"enable_backward": False, "fuse_fp": False})

__all__ = ["ClearancePhase", "DIRECTION_CANCELLED", "bound_slacks"]


KEY_NONE = wp.constant(wp.int64(0x7FFFFFFFFFFFFFFF))
"""A pair's triangle key before any triangle pair lowered it."""

HASH_MULTIPLIER = wp.constant(wp.uint64(0x9E3779B97F4A7C15))
"""Fibonacci hashing: a key times 2^64 over the golden ratio; the table slot is its high bits."""

BOUND_SLACK_ULPS = 4.0 * DISTANCE_ERROR_ULPS
"""A candidate is measured unless its lower bound passes the clearance by more than this many units in
the last place of the centred pair's largest coordinate (the bound's and the distance's rounding;
a plane's bound in float64 more: :func:`bound_slacks`)."""

DIRECTION_CANCELLED = 1.0e-6
"""An intersecting pair's direction sum shorter than this times the sum of its weights has cancelled
(see the module docstring): the boxes' centres give the direction instead."""


@wp.func
def _pair_key(a: int, b: int) -> wp.int64:
    """Hash key of the object pair ``(a, b)``: never 0 (an empty slot)."""
    return (wp.int64(a) << wp.int64(32)) + wp.int64(b) + wp.int64(1)


@wp.func
def _home(key: wp.int64, mask: int) -> int:
    """First table slot to probe for ``key`` (table of ``mask + 1`` slots, a power of two)."""
    h = wp.uint64(key) * HASH_MULTIPLIER
    return int((h >> wp.uint64(32)) & wp.uint64(mask))


@wp.func
def _find(table_key: wp.array[wp.int64], table_slot: wp.array[wp.int32], a: int, b: int) -> int:
    """The broad phase's slot of object pair ``(a, b)``, or -1 when it is not in the table."""
    key = _pair_key(a, b)
    mask = table_key.shape[0] - 1
    h = _home(key, mask)
    for _probe in range(table_key.shape[0]):
        k = table_key[h]
        if k == key:
            return table_slot[h]
        if k == wp.int64(0):
            return -1
        h = (h + 1) & mask
    return -1


@wp.func
def _triangle_key(tri_a: int, tri_b: int) -> wp.int64:
    """Order of the triangle pairs of one object pair: ``tri_a`` first, then ``tri_b``."""
    return (wp.int64(tri_a) << wp.int64(32)) + wp.int64(tri_b)


@wp.kernel
def _pair_table_kernel(
    pair: wp.array[wp.vec2i],
    pair_count: wp.array[wp.int64],
    pair_capacity: int,
    # Outputs
    table_key: wp.array[wp.int64],
    table_slot: wp.array[wp.int32],
    pair_distance: wp.array[Any],
    pair_triangle: wp.array[wp.int64],
    pair_hit: wp.array[wp.int64],
    pair_direction: wp.array[wp.vec3d],
    pair_weight: wp.array[wp.float64],
):
    """One thread per object pair slot: resets the pair's minima and sums, enters it in the table
    (zeroed before)."""
    k = wp.tid()
    if k >= used_count(pair_count, pair_capacity):
        return
    pair_distance[k] = type(pair_distance[k])(wp.inf)
    pair_triangle[k] = KEY_NONE
    pair_hit[k] = KEY_NONE
    pair_direction[k] = wp.vec3d(0.0)
    pair_weight[k] = wp.float64(0.0)
    p = pair[k]
    key = _pair_key(p[0], p[1])
    mask = table_key.shape[0] - 1
    h = _home(key, mask)
    for _probe in range(table_key.shape[0]):
        prev = wp.atomic_cas(table_key, h, wp.int64(0), key)
        if prev == wp.int64(0) or prev == key:
            table_slot[h] = k
            return
        h = (h + 1) & mask


@wp.func
def _row_features(mesh: MeshTopology, world_vertex: wp.array[Any], obj_a: int, tri_a: int, obj_b: int, tri_b: int,
                  tol: Any, reach: Any, slack: wp.float64, plane_slack: wp.float64):
    """The feature distance of two triangles (:func:`~warp_ccd._src.geometry.distance.centred_features`):
    ``(distance, p, q, o)``, ``p`` and ``q`` centred on ``o``; ``+inf`` without the features when a
    lower bound shows them farther apart than ``reach`` by more than its rounding (``slack`` and
    ``plane_slack``: :func:`bound_slacks`)."""
    v0, v1, v2 = mesh_triangle(mesh, world_vertex, obj_a, tri_a)
    u0, u1, u2 = mesh_triangle(mesh, world_vertex, obj_b, tri_b)
    return centred_features(v0, v1, v2, u0, u1, u2, tol, reach, type(tol)(slack), type(tol)(plane_slack))


def bound_slacks(precision: str, tolerance: float) -> tuple[float, float]:
    """``(slack, plane_slack)`` of the lower bound that spares a candidate its feature distances
    (:func:`~warp_ccd._src.geometry.distance.centred_features`), per unit of the centred pair's largest
    coordinate: :data:`BOUND_SLACK_ULPS` units in the last place for the box gap, and for a plane as
    much in float32 (its normal exact in float64 from float32 vertices), in float64 that plus the
    turn of a normal of float64 vertices, up to a unit in the last place over the triangle's
    doubled area in units of its longest edge squared, which is at least ``tolerance`` for a face
    that is not degenerate (4x that); no plane at all with a tolerance of 0 in float64."""
    ulp = 2.0**-53 if precision == "float64" else 2.0**-24
    slack = BOUND_SLACK_ULPS * ulp
    if precision != "float64":
        return slack, slack
    return slack, (slack + 4.0 * ulp / tolerance) if tolerance > 0.0 else float("inf")


@wp.kernel
def _candidate_distance_kernel(
    mesh: MeshTopology,
    world_vertex: wp.array[Any],
    candidate: wp.array[wp.vec4i],
    candidate_count: wp.array[wp.int64],
    candidate_capacity: int,
    table_key: wp.array[wp.int64],
    table_slot: wp.array[wp.int32],
    tol_rel: wp.float64,
    clearance: wp.float64,
    slack: wp.float64,
    plane_slack: wp.float64,
    # Outputs
    candidate_distance: wp.array[Any],
    candidate_slot: wp.array[wp.int32],
    pair_distance: wp.array[Any],
):
    """One thread per candidate: its feature distance (``+inf`` when plainly beyond the clearance)
    and its object pair's slot; within the clearance, the pair's least distance lowered to it."""
    k = wp.tid()
    if k >= used_count(candidate_count, candidate_capacity):
        return
    c = candidate[k]
    slot = _find(table_key, table_slot, c[0], c[2])
    tol = type(candidate_distance[k])(tol_rel)
    d, p, q, o = _row_features(mesh, world_vertex, c[0], c[1], c[2], c[3], tol, type(tol)(clearance), slack,
                               plane_slack)
    candidate_distance[k] = d
    candidate_slot[k] = slot
    if slot >= 0 and d <= type(d)(clearance):
        wp.atomic_min(pair_distance, slot, d)


@wp.kernel
def _candidate_argmin_kernel(
    candidate: wp.array[wp.vec4i],
    candidate_count: wp.array[wp.int64],
    candidate_capacity: int,
    candidate_distance: wp.array[Any],
    candidate_slot: wp.array[wp.int32],
    pair_distance: wp.array[Any],
    clearance: wp.float64,
    # Outputs
    pair_triangle: wp.array[wp.int64],
):
    """One thread per candidate within the clearance at its pair's least distance: the pair's triangle
    key lowered to its own."""
    k = wp.tid()
    if k >= used_count(candidate_count, candidate_capacity):
        return
    slot = candidate_slot[k]
    if slot < 0:
        return
    d = candidate_distance[k]
    if d <= type(d)(clearance) and d == pair_distance[slot]:
        c = candidate[k]
        wp.atomic_min(pair_triangle, slot, _triangle_key(c[1], c[3]))


@wp.kernel
def _hit_kernel(
    mesh: MeshTopology,
    world_vertex: wp.array[Any],
    hit: wp.array[wp.vec4i],
    hit_count: wp.array[wp.int64],
    hit_capacity: int,
    table_key: wp.array[wp.int64],
    table_slot: wp.array[wp.int32],
    tol_rel: wp.float64,
    # Outputs
    pair_hit: wp.array[wp.int64],
    pair_direction: wp.array[wp.vec3d],
    pair_weight: wp.array[wp.float64],
):
    """One thread per intersecting triangle pair: its object pair's least intersecting key, and
    ``w (n_a - n_b)`` and ``w`` added to the pair's direction sums (module docstring)."""
    k = wp.tid()
    if k >= used_count(hit_count, hit_capacity):
        return
    c = hit[k]
    slot = _find(table_key, table_slot, c[0], c[2])
    if slot < 0:
        return
    wp.atomic_min(pair_hit, slot, _triangle_key(c[1], c[3]))
    v0, v1, v2 = mesh_triangle(mesh, world_vertex, c[0], c[1])
    u0, u1, u2 = mesh_triangle(mesh, world_vertex, c[2], c[3])
    tol = type(v0[0])(tol_rel)
    kind, s0, s1 = tri_tri_segment(v0, v1, v2, u0, u1, u2, tol)
    w = wp.float64(wp.max(_max_edge(v0, v1, v2), _max_edge(u0, u1, u2)))
    if kind == CONTACT_SEGMENT:
        w = wp.float64(wp.length(s1 - s0))
    na, degenerate_a = _unit_normal(v0, v1, v2, tol)
    nb, degenerate_b = _unit_normal(u0, u1, u2, tol)
    wp.atomic_add(pair_direction, slot, (wp.vec3d(na) - wp.vec3d(nb)) * w)
    wp.atomic_add(pair_weight, slot, w)


@wp.func
def _box_direction(object_lower: wp.array[wp.vec3], object_upper: wp.array[wp.vec3], a: int, b: int) -> wp.vec3d:
    """Unit direction from the centre of ``a``'s box to ``b``'s, or zero where they coincide."""
    ca = (wp.vec3d(object_lower[a]) + wp.vec3d(object_upper[a])) * wp.float64(0.5)
    cb = (wp.vec3d(object_lower[b]) + wp.vec3d(object_upper[b])) * wp.float64(0.5)
    d = cb - ca
    n = wp.length(d)
    if n > wp.float64(0.0):
        return d / n
    return wp.vec3d(0.0)


@wp.kernel
def _finish_kernel(
    mesh: MeshTopology,
    world_vertex: wp.array[Any],
    pair: wp.array[wp.vec2i],
    pair_count: wp.array[wp.int64],
    pair_capacity: int,
    pair_distance: wp.array[Any],
    pair_triangle: wp.array[wp.int64],
    pair_hit: wp.array[wp.int64],
    pair_direction: wp.array[wp.vec3d],
    pair_weight: wp.array[wp.float64],
    object_lower: wp.array[wp.vec3],
    object_upper: wp.array[wp.vec3],
    tol_rel: wp.float64,
    clearance: wp.float64,
    near_capacity: int,
    # Outputs
    near: wp.array[wp.vec2i],
    near_count: wp.array[wp.int64],
    near_distance: wp.array[Any],
    near_point: wp.array2d[Any],
    near_normal: wp.array[Any],
    near_triangle: wp.array[wp.vec2i],
    near_intersecting: wp.array[wp.int32],
    object_near: wp.array[wp.int32],
):
    """One thread per object pair: a row for a pair within the clearance (module docstring)."""
    k = wp.tid()
    if k >= used_count(pair_count, pair_capacity):
        return
    key = pair_hit[k]
    intersecting = key != KEY_NONE
    if not intersecting:
        if not (pair_distance[k] <= type(pair_distance[k])(clearance)):
            return
        key = pair_triangle[k]
    p = pair[k]
    tri_a = int(key >> wp.int64(32))
    tri_b = int(key & wp.int64(0xFFFFFFFF))
    tol = type(pair_distance[k])(tol_rel)
    d, pc, qc, o = _row_features(mesh, world_vertex, p[0], tri_a, p[1], tri_b, tol, type(tol)(wp.inf),
                                 wp.float64(0.0), wp.float64(0.0))
    normal = _box_direction(object_lower, object_upper, p[0], p[1])
    point_a = pc + o
    point_b = qc + o
    if intersecting:
        d = type(d)(0.0)
        v0, v1, v2 = mesh_triangle(mesh, world_vertex, p[0], tri_a)
        u0, u1, u2 = mesh_triangle(mesh, world_vertex, p[1], tri_b)
        kind, s0, s1 = tri_tri_segment(v0, v1, v2, u0, u1, u2, tol)
        mid = (pc + qc) * type(d)(0.5) + o
        if kind == CONTACT_SEGMENT:
            mid = (s0 + s1) * type(d)(0.5)
        point_a = mid
        point_b = mid
        sum_n = pair_direction[k]
        if wp.length(sum_n) > wp.float64(DIRECTION_CANCELLED) * pair_weight[k]:
            normal = wp.normalize(sum_n)
    elif d > type(d)(0.0):
        normal = wp.vec3d(qc - pc) / wp.float64(d)
    slot = reserve_slot(near_count, near_capacity)
    if slot >= 0:
        near[slot] = p
        near_distance[slot] = d
        near_point[slot, 0] = point_a
        near_point[slot, 1] = point_b
        near_normal[slot] = type(point_a)(normal)
        near_triangle[slot] = wp.vec2i(tri_a, tri_b)
        near_intersecting[slot] = wp.where(intersecting, 1, 0)
    object_near[p[0]] = 1
    object_near[p[1]] = 1


_PAIR_TABLE = precision_overloads(_pair_table_kernel, lambda s, v, q, t: {"pair_distance": wp.array[s]})
_CANDIDATE_DISTANCE = precision_overloads(_candidate_distance_kernel, lambda s, v, q, t: {
    "world_vertex": wp.array[v], "candidate_distance": wp.array[s], "pair_distance": wp.array[s]})
_CANDIDATE_ARGMIN = precision_overloads(_candidate_argmin_kernel, lambda s, v, q, t: {
    "candidate_distance": wp.array[s], "pair_distance": wp.array[s]})
_HIT = precision_overloads(_hit_kernel, lambda s, v, q, t: {"world_vertex": wp.array[v]})
_FINISH = precision_overloads(_finish_kernel, lambda s, v, q, t: {
    "world_vertex": wp.array[v], "pair_distance": wp.array[s], "near_distance": wp.array[s],
    "near_point": wp.array2d[v], "near_normal": wp.array[v]})


class ClearancePhase:
    """Object pairs within a distance, their least distance, closest points and direction; owns
    what it writes (see the module docstring).

    Args:
        num_objects: ``N`` (size of :attr:`object_near`).
        clearance: the distance (scene units, > 0).
        tolerance: relative tolerance of the triangle tests (the narrow phase's: which triangles are
            degenerate, and where intersecting ones meet).
        capacity: initial capacity of :attr:`near` (it grows).
        device: Warp device.

    Attributes:
        near: :class:`~warp_ccd._src.runtime.buffers.GrowableBuffer` of ``wp.vec2i`` object pairs ``(a, b)``,
            ``a < b``, within the clearance (unsorted), and beside it, ``near.capacity`` rows each:
            ``distance`` (the scene's scalar type), ``point`` ``(capacity, 2)`` (on ``a``, on ``b``;
            the scene's vector type), ``normal`` (unit, ``a`` to ``b``), ``triangle`` (``wp.vec2i``
            ``(tri_a, tri_b)``), ``intersecting`` (int32 0 or 1).
        object_near: ``(N,)`` int32, 1 for an object within the clearance of another.
        clearance, tolerance: as above.
    """

    def __init__(self, num_objects: int, clearance: float, *, tolerance: float = TOLERANCE, capacity: int = 256,
                 device: DeviceLike = None) -> None:
        self.clearance = check_option("clearance", clearance)
        if self.clearance == 0.0:
            raise ValueError("clearance: a clearance phase reports the pairs within a clearance > 0, got 0")
        self.tolerance = check_option("tolerance", tolerance)
        self.device = wp.get_device(device)
        self.near = GrowableBuffer(wp.vec2i, capacity, self.device, "object pairs within the clearance")
        self.object_near = wp.zeros(num_objects, dtype=wp.int32, device=self.device)
        self._rows_for = None  # (capacity, precision) the row arrays follow
        self._pairs_for = None  # (pairs capacity, precision) of the pair scratch and the table
        self._candidates_for = None  # (candidates capacity, precision) of the candidate scratch

    @property
    def counters(self) -> list[GrowableBuffer]:
        """The buffers with counters that :meth:`launch` resets and writes: :attr:`near`."""
        return [self.near]

    def _scratch(self, scene: Scene, pairs: GrowableBuffer, candidates: GrowableBuffer) -> None:
        """Allocates what follows the capacities of the rows, the pairs and the candidates."""
        d = self.device
        scalar, vec = scene.scalar_type, scene.vec3_type
        if self._rows_for != (self.near.capacity, scene.precision):
            self._rows_for = (self.near.capacity, scene.precision)
            cap = self.near.capacity
            self.distance = wp.zeros(cap, dtype=scalar, device=d)
            self.point = wp.zeros((cap, 2), dtype=vec, device=d)
            self.normal = wp.zeros(cap, dtype=vec, device=d)
            self.triangle = wp.zeros(cap, dtype=wp.vec2i, device=d)
            self.intersecting = wp.zeros(cap, dtype=wp.int32, device=d)
        if self._pairs_for != (pairs.capacity, scene.precision):
            self._pairs_for = (pairs.capacity, scene.precision)
            cap = pairs.capacity
            size = self.table_size(cap)
            self.table_key = wp.zeros(size, dtype=wp.int64, device=d)
            self.table_slot = wp.zeros(size, dtype=wp.int32, device=d)
            self.pair_distance = wp.zeros(cap, dtype=scalar, device=d)
            self.pair_triangle = wp.zeros(cap, dtype=wp.int64, device=d)
            self.pair_hit = wp.zeros(cap, dtype=wp.int64, device=d)
            self.pair_direction = wp.zeros(cap, dtype=wp.vec3d, device=d)
            self.pair_weight = wp.zeros(cap, dtype=wp.float64, device=d)
        if self._candidates_for != (candidates.capacity, scene.precision):
            self._candidates_for = (candidates.capacity, scene.precision)
            self.candidate_distance = wp.zeros(candidates.capacity, dtype=scalar, device=d)
            self.candidate_slot = wp.zeros(candidates.capacity, dtype=wp.int32, device=d)

    def launch(self, scene: Scene, pairs: GrowableBuffer, candidates: GrowableBuffer, hits: GrowableBuffer,
               object_lower: wp.array, object_upper: wp.array, *, reset_counters: bool = True) -> None:
        """Writes the rows of the object ``pairs`` of ``scene`` within the clearance (host reads nothing).

        Args:
            scene: the :class:`~warp_ccd._src.scene.scene.Scene` (its world vertices now).
            pairs: the broad phase's object pairs (boxes padded by half the clearance).
            candidates: the mid phase's candidate triangle pairs (its tests padded by the clearance).
            hits: the narrow phase's intersecting triangle pairs.
            object_lower: the ``(N,)`` lower corners of the object boxes (their centres: a fallback direction).
            object_upper: the ``(N,)`` upper corners of the object boxes.
            reset_counters: zero :attr:`near`'s counter first; False when the caller has.
        """
        d = self.device
        if reset_counters:
            self.near.reset()
        self._scratch(scene, pairs, candidates)
        prec = scene.precision
        slack, plane_slack = bound_slacks(prec, self.tolerance)
        tol = wp.float64(self.tolerance)
        clearance = wp.float64(self.clearance)
        table = [self.table_key, self.table_slot]
        self.object_near.zero_()
        self.table_key.zero_()
        wp.launch(_PAIR_TABLE[prec], dim=pairs.capacity, inputs=[pairs.data, pairs.count, pairs.capacity],
                  outputs=[*table, self.pair_distance, self.pair_triangle, self.pair_hit, self.pair_direction,
                           self.pair_weight], device=d)
        cand = [candidates.data, candidates.count, candidates.capacity]
        wp.launch(_CANDIDATE_DISTANCE[prec], dim=candidates.capacity,
                  inputs=[scene.topology, scene.world_vertex, *cand, *table, tol, clearance, wp.float64(slack),
                          wp.float64(plane_slack)],
                  outputs=[self.candidate_distance, self.candidate_slot, self.pair_distance], device=d)
        wp.launch(_CANDIDATE_ARGMIN[prec], dim=candidates.capacity,
                  inputs=[*cand, self.candidate_distance, self.candidate_slot, self.pair_distance, clearance],
                  outputs=[self.pair_triangle], device=d)
        wp.launch(_HIT[prec], dim=hits.capacity,
                  inputs=[scene.topology, scene.world_vertex, hits.data, hits.count, hits.capacity, *table, tol],
                  outputs=[self.pair_hit, self.pair_direction, self.pair_weight], device=d)
        wp.launch(_FINISH[prec], dim=pairs.capacity,
                  inputs=[scene.topology, scene.world_vertex, pairs.data, pairs.count, pairs.capacity,
                          self.pair_distance, self.pair_triangle, self.pair_hit, self.pair_direction,
                          self.pair_weight, object_lower, object_upper, tol, clearance, self.near.capacity],
                  outputs=[self.near.data, self.near.count, self.distance, self.point, self.normal, self.triangle,
                           self.intersecting, self.object_near], device=d)

    @staticmethod
    def table_size(pair_capacity: int) -> int:
        """Slots of the pair table for a pair capacity: a power of two, at least twice it (and 64)."""
        return 1 << max(6, int(2 * pair_capacity - 1).bit_length())

