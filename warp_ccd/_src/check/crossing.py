"""Penetrating or touching: whether two surfaces cross where their triangles meet, and how deep.

The exact test (:mod:`~warp_ccd._src.geometry.triangle`) finds every pair of closed triangles that meet.
Whether two *surfaces* pass through each other is a question about the surfaces, not about how
they are cut into triangles: a crate standing on a floor touches it wherever the floor's grid
lines fall, and a crate sunk into it crosses it wherever they fall. This module decides it from
each intersecting triangle pair together with the triangles around it.

**Surfaces are oriented**: a triangle's normal (right-handed winding) points out of its object,
so the object lies *behind* its triangles. For a closed mesh that is its solid; for an open one
(a floor, a cloth) it is the side behind its faces. Two surfaces **cross** (penetrate) where,
near a point they share, one enters the region behind the other: their insides overlap. They
**touch** where they meet but neither enters the other: a crate resting on a floor, parts meeting
face to face, edge on edge, edge on face or vertex on anything.

**The verdict of one triangle pair** ``(ta, tb)`` (:func:`_verdict`):

* *coplanar* (each within the tolerance of the other's plane): they cross when they face the
  same way and overlap in an area (two solids with flush faces overlap behind them); facing
  each other, or meeting only along edges, they touch.
* otherwise their intersection is a segment ``s`` on the line where the planes meet (a point:
  they touch). Along the open segment each triangle is either crossed through its interior or
  has ``s`` on one of its edges (its vertices can only be at ``s``'s ends). In the plane across
  ``s`` at its midpoint each surface is a set of rays from that point: a face crossed through its
  interior gives two opposite rays (a sheet); with ``s`` on an edge the triangle gives one ray,
  and its neighbour across that edge another (a fold, convex or concave by the orientation; on
  an open boundary or a non-manifold edge a single ray with no inside). The region behind a
  sheet is a half-plane; behind a convex fold, the wedge behind both faces; behind a concave
  one, behind either. The pair **crosses** when a ray of one surface goes into the region behind
  the other by more than the tolerance (within its triangle's reach). A floor's grid line under
  a crate's wall is a flat fold: the floor there is still one sheet, crossed by the wall.

The tolerance is ``tolerance * L`` with ``L`` the longest edge of the *smaller* triangle of the
pair (a 1 cm cube half sunk into a floor of 1 km triangles crosses it), and at least what the
world vertices' precision resolves at the pair's coordinates (:data:`ROUNDING_ULPS`: float32
rounding at 1,000 units from the origin is not a crossing). A ray counts only as far as the other
triangle's size: beyond it, that triangle's plane says nothing of its surface.

Nothing lies behind what has no side: a degenerate triangle (a sliver, a segment, a point; its
pairs only touch, the surfaces' crossings are decided at its neighbours), a *two-sided* face (one
listed twice, as assets draw both sides of a sheet), an open boundary, a non-manifold edge, or a
fold whose neighbour is degenerate or two-sided. Closed shapes wound inside out are turned round
(:func:`~warp_ccd._src.narrowphase.surface.shape_sides`); open ones are taken as wound. The surfaces' topology
(neighbours across edges, vertex fans, two-sided faces, sides) and the side of a point at its
nearest feature come from :mod:`~warp_ccd._src.narrowphase.surface`.

**Depth** (:mod:`~warp_ccd._src.narrowphase.depth`): an object pair's is the deepest point of either surface
inside the other object's closed solid, measured to that solid's surface; undefined (NaN) where neither
object is closed. A crossing row's depth is the deepest point the pair's search measured on its two triangles
inside the other solid (a lower bound of their own); a crossing is never 0 deep (at least its tolerance), and a
touching row has depth 0.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import warp as wp

from ..geometry.precision import precision_overloads
from ..geometry.primitives import (
    _common_part,
    _max_abs,
    _max_edge,
    _pick,
    _plane_section,
    _snap,
    _unit_normal,
)
from ..geometry.triangle import TOLERANCE, crossing_depth
from ..narrowphase.depth import PenetrationDepth
from ..narrowphase.pairs import pair_triangles
from ..narrowphase.surface import SurfaceTopology, _local_triangle, _neighbour, surface_topology
from ..scene.scene import MeshTopology
from ..trees.bvh import SceneBVH

__all__ = ["CrossingClassifier", "Crossings", "pair_crossing_depth"]

wp.set_module_options({"enable_backward": False, "fuse_fp": False})

SURFACE_SHEET = wp.constant(0)
"""A surface crossed through a face's interior: two opposite rays, one normal."""
SURFACE_FOLD = wp.constant(1)
"""A surface met along an edge with a neighbour across it: two rays, two normals."""
SURFACE_OPEN = wp.constant(2)
"""A surface met along a boundary (or non-manifold) edge: one ray, nothing behind it."""


@wp.func
def _support(d0: wp.float64, d1: wp.float64, d2: wp.float64):
    """Where a triangle meets the other's plane, from its vertices' snapped distances: -1 through
    its interior, edge ``k`` (0-2) along that edge, -2 at a point only (touching)."""
    zero = wp.float64(0.0)
    if d0 == zero and d1 == zero and d2 != zero:
        return 0
    if d1 == zero and d2 == zero and d0 != zero:
        return 1
    if d2 == zero and d0 == zero and d1 != zero:
        return 2
    lo = wp.min(wp.min(d0, d1), d2)
    hi = wp.max(wp.max(d0, d1), d2)
    if (lo < zero and hi > zero) or (lo == zero and hi == zero):
        return -1
    return -2


@wp.func
def _reach(x0: wp.vec3d, x1: wp.vec3d, x2: wp.vec3d, m: wp.vec3d, w: wp.vec3d):
    """How far triangle ``x`` extends from ``m`` along ``w``."""
    return wp.max(wp.max(wp.dot(x0 - m, w), wp.dot(x1 - m, w)), wp.dot(x2 - m, w))


@wp.func
def _across(y: wp.vec3d, m: wp.vec3d, d: wp.vec3d):
    """Unit direction from ``m`` toward ``y`` across the line of direction ``d``, and the distance."""
    w = y - m
    w = w - d * wp.dot(w, d)
    r = wp.length(w)
    if r > wp.float64(0.0):
        return w / r, r
    return w, r


@wp.func
def _behind(kind: int, n1: wp.vec3d, n2: wp.vec3d, w2: wp.vec3d, r: wp.vec3d):
    """How far (per unit length) direction ``r`` goes behind a surface seen across its crossing:
    a sheet of normal ``n1``; a fold of faces ``n1`` and ``n2`` (``w2`` the second's ray); an open
    edge has nothing behind it (-1)."""
    b1 = -wp.dot(n1, r)
    if kind == SURFACE_SHEET:
        return b1
    if kind == SURFACE_OPEN:
        return wp.float64(-1.0)
    b2 = -wp.dot(n2, r)
    if wp.dot(n1, w2) < wp.float64(0.0):  # convex: the second face bends behind the first
        return wp.min(b1, b2)
    return wp.max(b1, b2)


@wp.func
def _surface_at(
    mesh: MeshTopology,
    surface: SurfaceTopology,
    world_vertex: wp.array[Any],
    obj: int,
    tri: int,
    idx: wp.vec3i,
    x0: wp.vec3d,
    x1: wp.vec3d,
    x2: wp.vec3d,
    n: wp.vec3d,
    sup: int,
    m: wp.vec3d,
    d: wp.vec3d,
    o: wp.vec3d,
    tol_rel: wp.float64,
):
    """The surface of ``obj`` across the line ``m + t d`` where triangle ``tri`` meets the other
    (``sup``: :func:`_support`): ``(kind, n1, w1, reach1, n2, w2, reach2)``, two rays ``w`` from
    ``m`` across the line with the normals of their faces and how far each face reaches along
    its ray (the second 0 on an open edge). Nothing is behind a two-sided face, an open edge, or
    an edge whose neighbour has no side (:data:`SURFACE_OPEN`)."""
    thin = surface.two_sided[mesh.shape_triangle_start[mesh.object_shape[obj]] + tri] != 0
    if sup < 0:
        w = wp.normalize(wp.cross(n, d))
        kind = SURFACE_SHEET
        if thin:
            kind = SURFACE_OPEN
        return kind, n, w, _reach(x0, x1, x2, m, w), n, -w, _reach(x0, x1, x2, m, -w)
    w1, r1 = _across(_pick(x0, x1, x2, (sup + 2) % 3), m, d)
    found, n2, y = _neighbour(mesh, surface, world_vertex, obj, tri, idx, sup, o, tol_rel)
    if found != 1:  # a boundary, or a neighbour without a side (degenerate, two-sided)
        return SURFACE_OPEN, n, w1, r1, n, -w1, wp.float64(0.0)
    w2, r2 = _across(y, m, d)
    if thin:
        return SURFACE_OPEN, n, w1, r1, n2, w2, r2
    return SURFACE_FOLD, n, w1, r1, n2, w2, r2


@wp.func
def _enters(kind: int, n1: wp.vec3d, n2: wp.vec3d, w2: wp.vec3d, ray: wp.vec3d, reach: wp.float64,
            extent: wp.float64, eps: wp.float64):
    """Whether a face reaching ``reach`` along ``ray`` goes more than ``eps`` behind the surface,
    seen within ``extent`` (the size of the surface's triangle: farther, its plane says nothing)."""
    return wp.min(reach, extent) * _behind(kind, n1, n2, w2, ray) > eps


@wp.func
def _verdict(
    mesh: MeshTopology,
    surface: SurfaceTopology,
    world_vertex: wp.array[Any],
    c: wp.vec4i,
    a0: wp.vec3d,
    a1: wp.vec3d,
    a2: wp.vec3d,
    ia: wp.vec3i,
    na: wp.vec3d,
    b0: wp.vec3d,
    b1: wp.vec3d,
    b2: wp.vec3d,
    ib: wp.vec3i,
    nb: wp.vec3d,
    o: wp.vec3d,
    size_a: wp.float64,
    size_b: wp.float64,
    eps: wp.float64,
    tol_rel: wp.float64,
) -> bool:
    """Whether the surfaces of two non-degenerate intersecting triangles cross there (module
    docstring); ``size_a``, ``size_b`` their longest edges."""
    zero = wp.float64(0.0)
    da0 = _snap(wp.dot(nb, a0 - b0), eps)
    da1 = _snap(wp.dot(nb, a1 - b0), eps)
    da2 = _snap(wp.dot(nb, a2 - b0), eps)
    db0 = _snap(wp.dot(na, b0 - a0), eps)
    db1 = _snap(wp.dot(na, b1 - a0), eps)
    db2 = _snap(wp.dot(na, b2 - a0), eps)
    if da0 == zero and da1 == zero and da2 == zero and db0 == zero and db1 == zero and db2 == zero:
        thin = surface.two_sided[mesh.shape_triangle_start[mesh.object_shape[c[0]]] + c[1]] != 0 or (
            surface.two_sided[mesh.shape_triangle_start[mesh.object_shape[c[2]]] + c[3]] != 0)
        return not thin and wp.dot(na, nb) > zero and _coplanar_area(a0, a1, a2, b0, b1, b2, na, eps)
    sup_a = _support(da0, da1, da2)
    sup_b = _support(db0, db1, db2)
    if sup_a == -2 or sup_b == -2:
        return False
    # Where they meet: the common part of each one's section by the other's plane.
    pa, qa = _plane_section(a0, a1, a2, da0, da1, da2)
    pb, qb = _plane_section(b0, b1, b2, db0, db1, db2)
    p, q = _common_part(pa, qa, pb, qb)
    length = wp.length(q - p)
    if length <= eps:
        return False
    d = (q - p) / length
    m = (p + q) * wp.float64(0.5)
    ka, na1, wa1, ra1, na2, wa2, ra2 = _surface_at(mesh, surface, world_vertex, c[0], c[1], ia, a0, a1, a2, na,
                                                   sup_a, m, d, o, tol_rel)
    kb, nb1, wb1, rb1, nb2, wb2, rb2 = _surface_at(mesh, surface, world_vertex, c[2], c[3], ib, b0, b1, b2, nb,
                                                   sup_b, m, d, o, tol_rel)
    return (_enters(kb, nb1, nb2, wb2, wa1, ra1, size_b, eps) or _enters(kb, nb1, nb2, wb2, wa2, ra2, size_b, eps)
            or _enters(ka, na1, na2, wa2, wb1, rb1, size_a, eps) or _enters(ka, na1, na2, wa2, wb2, rb2, size_a, eps))


@wp.func
def _centred_pair(
    mesh: MeshTopology,
    surface: SurfaceTopology,
    world_vertex: wp.array[Any],
    c: wp.vec4i,
    tol_rel: wp.float64,
    rounding: wp.float64,
):
    """Row ``c``'s triangles in float64 relative to their centroid ``o``, their local vertex ids,
    unit normals (out of their objects) and degeneracy, their longest edges, and the absolute
    tolerance ``eps``: ``tol_rel`` times the smaller triangle's longest edge, at least ``rounding``
    times the largest coordinate (what the world vertices' precision resolves there)."""
    a0, a1, a2, ia = _local_triangle(mesh, world_vertex, c[0], c[1], wp.vec3d())
    b0, b1, b2, ib = _local_triangle(mesh, world_vertex, c[2], c[3], wp.vec3d())
    big = wp.max(wp.max(wp.max(_max_abs(a0), _max_abs(a1)), wp.max(_max_abs(a2), _max_abs(b0))),
                 wp.max(_max_abs(b1), _max_abs(b2)))
    o = (a0 + a1 + a2 + b0 + b1 + b2) / wp.float64(6.0)
    a0 = a0 - o
    a1 = a1 - o
    a2 = a2 - o
    b0 = b0 - o
    b1 = b1 - o
    b2 = b2 - o
    size_a = _max_edge(a0, a1, a2)
    size_b = _max_edge(b0, b1, b2)
    na, degenerate_a = _unit_normal(a0, a1, a2, tol_rel)
    nb, degenerate_b = _unit_normal(b0, b1, b2, tol_rel)
    na = na * surface.shape_side[mesh.object_shape[c[0]]]
    nb = nb * surface.shape_side[mesh.object_shape[c[2]]]
    eps = wp.max(tol_rel * wp.min(size_a, size_b), rounding * big)
    return a0, a1, a2, ia, na, degenerate_a, b0, b1, b2, ib, nb, degenerate_b, o, size_a, size_b, eps


@wp.kernel
def _crossing_kernel(
    mesh: MeshTopology,
    surface: SurfaceTopology,
    world_vertex: wp.array[Any],
    pair: wp.array[wp.vec4i],
    tol_rel: wp.float64,
    rounding: wp.float64,
    # Outputs
    crossing: wp.array[wp.int32],
    eps_out: wp.array[wp.float64],
):
    """One thread per intersecting triangle pair: the verdict (:func:`_verdict`) and the tolerance."""
    k = wp.tid()
    c = pair[k]
    a0, a1, a2, ia, na, dega, b0, b1, b2, ib, nb, degb, o, size_a, size_b, eps = _centred_pair(
        mesh, surface, world_vertex, c, tol_rel, rounding)
    hit = 0
    if not dega and not degb:
        if _verdict(mesh, surface, world_vertex, c, a0, a1, a2, ia, na, b0, b1, b2, ib, nb, o, size_a, size_b, eps,
                    tol_rel):
            hit = 1
    crossing[k] = hit
    eps_out[k] = eps


_CROSSING = precision_overloads(_crossing_kernel, lambda s, v, q, t: {"world_vertex": wp.array[v]})


ROUNDING_ULPS = 8.0
"""What the world vertices' precision resolves, in units in the last place of the largest
coordinate of a pair: a crossing must go deeper than that (float32 at 1,000 units from the
origin: 1e-3), besides the tolerance relative to the triangles (:func:`_centred_pair`)."""

@wp.kernel
def _crossing_depth_kernel(
    mesh: MeshTopology,
    world_vertex: wp.array[Any],
    pair: wp.array[wp.vec4i],
    tol_rel: wp.float64,
    # Outputs
    depth: wp.array[wp.float64],
):
    """One thread per triangle pair ``(obj_a, tri_a, obj_b, tri_b)``: :func:`crossing_depth`."""
    k = wp.tid()
    v0, v1, v2, u0, u1, u2 = pair_triangles(mesh, world_vertex, pair[k])
    depth[k] = wp.float64(crossing_depth(v0, v1, v2, u0, u1, u2, type(v0[0])(tol_rel)))


_CROSSING_DEPTH = precision_overloads(_crossing_depth_kernel, lambda s, v, q, t: {"world_vertex": wp.array[v]})


def pair_crossing_depth(scene, pairs: wp.array, tolerance: float = TOLERANCE, out: wp.array | None = None) -> wp.array:
    """:func:`crossing_depth` of triangle pairs of a scene, on its device.

    Args:
        scene: the :class:`~warp_ccd._src.scene.scene.Scene` (its world vertices as they are now).
        pairs: ``(M,)`` ``wp.vec4i`` rows ``(obj_a, tri_a, obj_b, tri_b)`` on the scene's device
            (a result's ``device_triangle_pairs``).
        tolerance: relative tolerance of the triangle test.
        out: ``(>= M,)`` float64 array to write to (default: a new one).

    Returns:
        ``(M,)`` float64 depths, scene units (a view of ``out`` when given).
    """
    m = int(pairs.shape[0])
    if m == 0:
        return wp.zeros(0, dtype=wp.float64, device=scene.device)
    if out is None or out.shape[0] < m:
        out = wp.zeros(m, dtype=wp.float64, device=scene.device)
    wp.launch(_CROSSING_DEPTH[scene.precision], dim=m,
              inputs=[scene.topology, scene.world_vertex, pairs, float(tolerance)], outputs=[out],
              device=scene.device)
    return out[:m]


@dataclass
class Crossings:
    """What :class:`CrossingClassifier` found for a frame's intersecting triangle pairs (host arrays).

    Attributes:
        crossing: ``(M,)`` bool, whether the surfaces cross at each row (else they touch).
        depth: ``(M,)`` float64 depth of each row (scene units): for a crossing row the deepest point measured on
            its two triangles inside the other object's solid, at least the row's tolerance (a crossing is never
            0 deep); NaN where neither object is closed (undefined); 0 for a touching row.
        pairs: ``(K,)`` object pairs ``(a, b)``, ``a < b``, sorted, of the crossing rows.
        pair_depth: ``(K,)`` float64 depth of each pair
            (:class:`~warp_ccd._src.narrowphase.depth.PenetrationDepth`), at least its rows' tolerance; NaN
            where neither object is closed.
        contained_depth: ``(C,)`` float64 depth of the ``(inner, outer)`` pairs asked for.
    """

    crossing: np.ndarray
    depth: np.ndarray
    pairs: np.ndarray
    pair_depth: np.ndarray
    contained_depth: np.ndarray

    def row_pair(self, rows: np.ndarray) -> np.ndarray:
        """The index in :attr:`pairs` of each row's object pair, -1 where it is not one."""
        key = self.pairs[:, 0].astype(np.int64) * (1 << 31) + self.pairs[:, 1]
        want = rows[:, 0].astype(np.int64) * (1 << 31) + rows[:, 2]
        if len(key) == 0:
            return np.full(len(rows), -1, np.int64)
        at = np.minimum(np.searchsorted(key, want), len(key) - 1)
        return np.where(key[at] == want, at, -1)


class CrossingClassifier:
    """Penetrating or touching, and how deep, for the intersecting triangle pairs of a scene (module
    docstring).

    Owns the scene's :class:`SurfaceTopology` (built once: topology does not change with the poses or the
    world vertices), its :class:`~warp_ccd._src.narrowphase.depth.PenetrationDepth` and its output buffers,
    grown as needed. Nearest points are found down the pipeline's trees when they are given (as they stand
    after its ``detect()``), else down trees of the depth's own.

    Example::

        pipe = CollisionPipeline(scene)
        classify = CrossingClassifier(scene, trees=pipe.boxes)
        res = pipe.detect()
        found = classify(res.device_triangle_pairs)
        found.pairs, found.pair_depth
    """

    def __init__(self, scene, *, tolerance: float = TOLERANCE, trees=None):
        """
        Args:
            scene: the :class:`~warp_ccd._src.scene.scene.Scene` whose pairs will be classified.
            tolerance: the exact test's relative tolerance.
            trees: the pipeline's :class:`~warp_ccd._src.trees.bvh.SceneBVH` (``CollisionPipeline.boxes``), or None.
        """
        self.scene = scene
        self.tolerance = float(tolerance)
        self.rounding = ROUNDING_ULPS * float(np.finfo(np.float32 if scene.precision == "float32" else np.float64).eps)
        self.surface = surface_topology(scene)
        self.depth = PenetrationDepth(scene, trees=trees if isinstance(trees, SceneBVH) else None,
                                      triangle_tolerance=self.tolerance, surface=self.surface)
        self._capacity = 0

    def _grow(self, m: int) -> None:
        if m <= self._capacity:
            return
        cap = max(m, 2 * self._capacity, 64)
        d = self.scene.device
        self._crossing = wp.zeros(cap, dtype=wp.int32, device=d)
        self._eps = wp.zeros(cap, dtype=wp.float64, device=d)
        self._capacity = cap

    def __call__(self, pairs: wp.array, contained: np.ndarray | None = None) -> Crossings:
        """Classifies rows of the scene as its world vertices are now, and measures their depths.

        Args:
            pairs: ``(M,)`` ``wp.vec4i`` rows ``(obj_a, tri_a, obj_b, tri_b)`` of triangles that
                meet, on the scene's device (a result's ``device_triangle_pairs``).
            contained: ``(C, 2)`` ``(inner, outer)`` object pairs, one wholly inside the other's solid (a
                result's ``containment_pairs``), whose depths are measured too.

        Returns:
            The :class:`Crossings`.
        """
        m = int(pairs.shape[0])
        contained = np.zeros((0, 2), np.int32) if contained is None else np.asarray(contained).reshape(-1, 2)
        none = np.zeros((0, 2), np.int32)
        if m == 0 and not len(contained):
            return Crossings(np.zeros(0, bool), np.zeros(0), none, np.zeros(0), np.zeros(0))
        crossing = np.zeros(0, bool)
        eps = np.zeros(0)
        rows = np.zeros((0, 4), np.int64)
        if m:
            self._grow(m)
            scene = self.scene
            wp.launch(_CROSSING[scene.precision], dim=m,
                      inputs=[scene.topology, self.surface, scene.world_vertex, pairs, self.tolerance, self.rounding],
                      outputs=[self._crossing, self._eps], device=scene.device)
            crossing = self._crossing[:m].numpy().astype(bool)
            eps = self._eps[:m].numpy()
            rows = pairs.numpy().reshape(-1, 4).astype(np.int64)
        at = np.flatnonzero(crossing)
        n = np.int64(max(self.scene.num_objects, 1))
        key, row_pair = np.unique(rows[at, 0] * n + rows[at, 2], return_inverse=True)  # one key, not rows
        object_pairs = np.stack([key // n, key % n], axis=1).astype(np.int32).reshape(-1, 2)
        # A crossing is never 0 deep: at least its tolerance, below which depths are not told apart.
        floor = np.zeros(len(object_pairs))
        np.maximum.at(floor, row_pair.reshape(-1), eps[at])
        found = self.depth(object_pairs, rows[at], contained, floors=floor)
        depth = np.zeros(m)
        depth[at] = np.where(np.isnan(found.row_depth), np.nan, np.fmax(found.row_depth, eps[at]))
        pair_depth = np.where(np.isnan(found.pair_depth), np.nan, np.fmax(found.pair_depth, floor))
        return Crossings(crossing, depth, object_pairs, pair_depth, found.contained_depth)


@wp.func
def _coplanar_area(
    a0: wp.vec3d, a1: wp.vec3d, a2: wp.vec3d, b0: wp.vec3d, b1: wp.vec3d, b2: wp.vec3d, n: wp.vec3d, eps: wp.float64
) -> bool:
    """Whether coplanar triangles overlap in an area wider than ``eps``: a vertex or centroid of
    one inside the other by more than ``eps``, or two edges crossing more than ``eps`` from their ends."""
    ca = (a0 + a1 + a2) / wp.float64(3.0)
    cb = (b0 + b1 + b2) / wp.float64(3.0)
    if _inside_by(b0, b1, b2, n, a0, eps) or _inside_by(b0, b1, b2, n, a1, eps) or _inside_by(b0, b1, b2, n, a2, eps):
        return True
    if _inside_by(a0, a1, a2, n, b0, eps) or _inside_by(a0, a1, a2, n, b1, eps) or _inside_by(a0, a1, a2, n, b2, eps):
        return True
    if _inside_by(b0, b1, b2, n, ca, eps) or _inside_by(a0, a1, a2, n, cb, eps):
        return True
    for i in range(3):
        p = _pick(a0, a1, a2, i)
        q = _pick(a0, a1, a2, (i + 1) % 3)
        for j in range(3):
            r = _pick(b0, b1, b2, j)
            s = _pick(b0, b1, b2, (j + 1) % 3)
            if _edges_cross(p, q, r, s, n, eps):
                return True
    return False


@wp.func
def _side(p: wp.vec3d, q: wp.vec3d, x: wp.vec3d, n: wp.vec3d):
    """Signed distance of ``x`` from the line ``pq`` in the plane of normal ``n`` (positive to the left)."""
    e = q - p
    le = wp.length(e)
    if le == wp.float64(0.0):
        return wp.float64(0.0)
    return wp.dot(wp.cross(e, x - p), n) / le


@wp.func
def _inside_by(x0: wp.vec3d, x1: wp.vec3d, x2: wp.vec3d, n: wp.vec3d, p: wp.vec3d, eps: wp.float64) -> bool:
    """Whether ``p`` lies inside triangle ``x`` (coplanar, either winding) farther than ``eps`` from its edges."""
    s0 = _side(x0, x1, p, n)
    s1 = _side(x1, x2, p, n)
    s2 = _side(x2, x0, p, n)
    return (s0 > eps and s1 > eps and s2 > eps) or (s0 < -eps and s1 < -eps and s2 < -eps)


@wp.func
def _edges_cross(p: wp.vec3d, q: wp.vec3d, r: wp.vec3d, s: wp.vec3d, n: wp.vec3d, eps: wp.float64) -> bool:
    """Whether coplanar segments ``pq`` and ``rs`` cross, each end more than ``eps`` off the other's line."""
    d1 = _side(p, q, r, n)
    d2 = _side(p, q, s, n)
    d3 = _side(r, s, p, n)
    d4 = _side(r, s, q, n)
    return ((d1 > eps and d2 < -eps) or (d1 < -eps and d2 > eps)) and (
        (d3 > eps and d4 < -eps) or (d3 < -eps and d4 > eps))
