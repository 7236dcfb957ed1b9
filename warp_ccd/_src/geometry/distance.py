"""Distance between closed triangles: how far apart they are, and their closest points.

:func:`tri_tri_distance` gives the distance of two closed triangles and a closest pair of points,
one on each, with the semantics of the intersection tests (:mod:`~warp_ccd._src.geometry.triangle`):

* Triangles that intersect, or touch within the tolerance ``eps = tol_rel * L`` (``L`` the longest
  edge of the two), as Möller's test (:func:`~warp_ccd._src.geometry.triangle.tri_tri_segment`) decides,
  are at distance 0; their closest points are one point where they meet (the middle of their
  intersection segment; for a coplanar overlap, a point of the overlap).
* Otherwise the closest pair lies on two features: a vertex of one triangle and the face of the
  other, or an edge of each (two disjoint convex sets are closest where the boundary of one meets
  the other's; for triangles, a vertex-face or an edge-edge pair: Larsen et al., "Fast distance
  queries with rectangular swept sphere volumes", 2000, the argument of PQP's ``TriDist``). The
  distance is the least of the nine edge-edge distances
  (:func:`~warp_ccd._src.geometry.primitives._closest_segment_points`, Ericson 5.1.9) and of the six
  vertex-face ones where the vertex lies over the face (its distance to the plane; elsewhere its
  closest point is on an edge, which the edge pairs measure), taken in a fixed order, the first
  least one winning ties, so that the points are the same on every device. A vertex over a face is
  told from the signed distances of its foot to the edge lines (:func:`_over_face`; the face's unit
  normal computed in float64 and held orthogonal to its longest edge, :func:`_face_normal`):
  Ericson's closest point on a triangle (5.1.5), from differences of products of dot products,
  cancels on a thin triangle and puts a point over its face on its long edge.
* A degenerate triangle (twice its area at most ``tol_rel`` times its longest edge squared:
  :func:`~warp_ccd._src.geometry.primitives._unit_normal`) has no face: it is the union of its edges, and
  lies within ``tol_rel`` times its longest edge of them (its height), so its distances are
  within that of the exact ones. A point triangle's edges are points.

Precision: the vertices' own (``wp.vec3``: float32; ``wp.vec3d``: float64), computed relative to the
pair's centroid, so that a translation of the scene changes nothing beyond the rounding of the
translated coordinates. The rounding of the arithmetic is bounded by a few units in the last place of
``R``, the largest coordinate of the centred pair (about the pair's extent plus their distance):
float32 distances are within :data:`DISTANCE_ERROR_ULPS` ``* 2^-24 * R`` of the distance of the same
float32 vertices computed in float64 (``tests/test_distance.py`` measures it over random, nearly
parallel, nearly degenerate and far-apart pairs), float64 ones within the same number of units of
``2^-53 R``.

:func:`tri_tri_distance_batch_kernel` runs it over arrays of triangle pairs. The distance stage of a
scene (:mod:`warp_ccd._src.narrowphase.clearance`) calls :func:`closest_features` directly on the candidate
pairs of object pairs that do not intersect (their triangles do not, so the least feature distance
is the distance), and takes intersecting pairs from the narrow phase; :func:`distance_lower_bound`
(box gap, separating planes) spares it the candidates plainly farther apart than its clearance.
"""

from typing import Any

import warp as wp

from .precision import PRECISIONS, precision_types
from .primitives import _closest_segment_points, _edge, _edge_normals, _pick
from .triangle import CONTACT_NONE, CONTACT_SEGMENT, tri_tri_segment

# Forward kernels only; no FMA contraction, so that CPU and CUDA round every step alike.
wp.set_module_options({"enable_backward": False, "fuse_fp": False})

__all__ = ["DISTANCE_ERROR_ULPS", "centred_features", "closest_features", "distance_lower_bound", "feature_distance",
           "tri_tri_distance",
           "tri_tri_distance_batch_kernel"]

DISTANCE_ERROR_ULPS = 16.0
"""Bound on the rounding of :func:`tri_tri_distance` in units in the last place of the largest
coordinate of the centred pair (see the module docstring)."""

FEATURE_PAIRS = 15
"""Feature pairs of two triangles: 3 + 3 vertex-face, 3 x 3 edge-edge."""


@wp.func
def _face_normal(x0: Any, x1: Any, x2: Any, tol: Any):
    """Unit normal of triangle ``x0 x1 x2`` for distances, and whether it is degenerate (the test of
    :func:`~warp_ccd._src.geometry.primitives._unit_normal`, the same verdict): computed in float64, then
    made orthogonal to the longest edge. A thin triangle's plane holds its longest edge to a unit in
    the last place, but the cross product of two nearly parallel edges of float64 vertices turns it
    by up to a unit in the last place times its longest edge squared over twice its area, about any
    axis: about the axis across the longest edge that tilt would move a point over the far end by
    that times the edge's length. (From float32 vertices the edges are exact in float64, and so the
    normal.)"""
    e1 = wp.vec3d(x1) - wp.vec3d(x0)
    e2 = wp.vec3d(x2) - wp.vec3d(x0)
    e3 = wp.vec3d(x2) - wp.vec3d(x1)
    n = wp.cross(e1, e2)
    ln = wp.length(n)
    l1 = wp.length_sq(e1)
    l2 = wp.length_sq(e2)
    l3 = wp.length_sq(e3)
    longest_sq = wp.max(wp.max(l1, l2), l3)
    if ln <= wp.float64(tol) * longest_sq:
        return type(x0)(), True  # zero
    edge = e1
    if l2 >= l1 and l2 >= l3:
        edge = e2
    elif l3 >= l1 and l3 >= l2:
        edge = e3
    n = n / ln
    n = n - edge * (wp.dot(n, edge) / wp.length_sq(edge))
    return type(x0)(wp.normalize(n)), False


@wp.func
def _over_face(x: Any, t0: Any, t1: Any, t2: Any, n: Any, m0: Any, m1: Any, m2: Any):
    """The foot ``q`` of point ``x`` on the plane of triangle ``t`` (unit normal ``n``), and whether it
    lies in the closed triangle (inward unit edge normals ``m``: its signed distances to the three
    edge lines). Distances to a plane and to lines, not Ericson's products of dot products, which
    cancel on a thin triangle and put a point over its face on its long edge."""
    q = x - n * wp.dot(n, x - t0)
    zero = type(x[0])(0.0)
    return q, wp.dot(m0, q - t0) >= zero and wp.dot(m1, q - t1) >= zero and wp.dot(m2, q - t2) >= zero


@wp.func
def _feature_pair(f: int, a0: Any, a1: Any, a2: Any, b0: Any, b1: Any, b2: Any, na: Any, nb: Any, face_a: bool,
                  face_b: bool, ma0: Any, ma1: Any, ma2: Any, mb0: Any, mb1: Any, mb2: Any):
    """Closest points ``(x, y, used)`` of feature pair ``f``: 0-2 vertex ``f`` of ``a`` and face ``b``,
    3-5 face ``a`` and vertex ``f - 3`` of ``b``, 6-14 edge ``(f - 6) // 3`` of ``a`` and edge
    ``(f - 6) % 3`` of ``b``. A vertex and a face are used only where the vertex lies over the face
    (:func:`_over_face`; elsewhere its closest point is on an edge, which the edge pairs measure)
    and the face is not degenerate (``face_a`` / ``face_b``; unit normals ``na``, ``nb``, inward edge
    normals ``ma``, ``mb``)."""
    if f < 6:
        i = f % 3
        on_b = f < 3
        x = wp.where(on_b, _pick(a0, a1, a2, i), _pick(b0, b1, b2, i))
        if (on_b and not face_b) or (not on_b and not face_a):
            return x, x, False
        if on_b:
            q, inside = _over_face(x, b0, b1, b2, nb, mb0, mb1, mb2)
            return x, q, inside
        q, inside = _over_face(x, a0, a1, a2, na, ma0, ma1, ma2)
        return q, x, inside
    pa, qa = _edge(a0, a1, a2, (f - 6) // 3)
    pb, qb = _edge(b0, b1, b2, (f - 6) % 3)
    c1, c2 = _closest_segment_points(pa, qa, pb, qb)
    return c1, c2, True


@wp.func
def closest_features(a0: Any, a1: Any, a2: Any, b0: Any, b1: Any, b2: Any, na: Any, nb: Any, face_a: bool,
                     face_b: bool):
    """The least distance over the feature pairs of two triangles (module docstring), on vertices
    the caller has centred: ``(distance, p, q)``, ``p`` on ``a``, ``q`` on ``b``. The distance of
    the triangles when they do not intersect; ``na``, ``nb`` their unit normals
    (:func:`_face_normal`), ``face_a`` / ``face_b`` False for a degenerate triangle (its edges alone)."""
    best = wp.length_sq(b0 - a0) + type(a0[0])(1.0)  # above any feature pair's, so that one wins
    p = a0
    q = b0
    ma0, ma1, ma2 = _edge_normals(a0, a1, a2, na)
    mb0, mb1, mb2 = _edge_normals(b0, b1, b2, nb)
    num = int(FEATURE_PAIRS)  # a loop, not 15 copies (Warp unrolls constant ranges)
    for f in range(num):
        x, y, used = _feature_pair(f, a0, a1, a2, b0, b1, b2, na, nb, face_a, face_b, ma0, ma1, ma2, mb0, mb1, mb2)
        d = wp.length_sq(y - x)
        if used and d < best:
            best = d
            p = x
            q = y
    return wp.sqrt(best), p, q


@wp.func
def distance_lower_bound(a0: Any, a1: Any, a2: Any, b0: Any, b1: Any, b2: Any, na: Any, nb: Any, face_a: bool,
                         face_b: bool, box_slack: Any, plane_slack: Any):
    """A cheap lower bound on the distance of two triangles: the distance between their bounding
    boxes less ``box_slack``, or between one triangle's plane and the other triangle when it lies
    wholly on one side less ``plane_slack`` (unit normals ``na``, ``nb``; a plane only where
    ``face_a`` / ``face_b``), the largest; 0 when nothing separates them. The slacks (scene units)
    bound the rounding of each: a box's gap is a few units in the last place of the coordinates, a
    plane's distance depends on its normal too (:func:`centred_features`)."""
    zero = type(a0[0])(0.0)
    gap = wp.max(wp.max(wp.min(wp.min(b0, b1), b2) - wp.max(wp.max(a0, a1), a2),
                        wp.min(wp.min(a0, a1), a2) - wp.max(wp.max(b0, b1), b2)), type(a0)())
    bound = wp.length(gap) - box_slack
    plane = zero
    if face_a:
        r0 = wp.dot(na, b0 - a0)
        r1 = wp.dot(na, b1 - a0)
        r2 = wp.dot(na, b2 - a0)
        plane = wp.max(plane, wp.max(wp.min(wp.min(r0, r1), r2), -wp.max(wp.max(r0, r1), r2)))
    if face_b:
        r0 = wp.dot(nb, a0 - b0)
        r1 = wp.dot(nb, a1 - b0)
        r2 = wp.dot(nb, a2 - b0)
        plane = wp.max(plane, wp.max(wp.min(wp.min(r0, r1), r2), -wp.max(wp.max(r0, r1), r2)))
    return wp.max(wp.max(bound, plane - plane_slack), zero)


@wp.func
def tri_tri_distance(v0: Any, v1: Any, v2: Any, u0: Any, u1: Any, u2: Any, tol_rel: Any):
    """Distance of the closed triangles ``(v0, v1, v2)`` and ``(u0, u1, u2)``, and a closest pair of points.

    Args:
        v0: first vertex of the first triangle, in one frame with the others (any units); all six
            vertices ``wp.vec3`` (float32) or all ``wp.vec3d`` (float64).
        v1: second vertex of the first triangle.
        v2: third vertex of the first triangle.
        u0: first vertex of the second triangle.
        u1: second vertex of the second triangle.
        u2: third vertex of the second triangle.
        tol_rel: tolerance relative to the longest edge, as for
            :func:`~warp_ccd._src.geometry.triangle.tri_tri_moller` (triangles that touch within it are at
            distance 0; it also says which triangles are degenerate).

    Returns:
        ``(distance, p, q)``: the distance (scene units, the vertices' precision; 0 when the triangles
        intersect), ``p`` on the first triangle and ``q`` on the second, with ``|p - q|`` the distance
        (``p == q`` for intersecting triangles: a point where they meet).
    """
    tol = type(v0[0])(tol_rel)
    kind, s0, s1 = tri_tri_segment(v0, v1, v2, u0, u1, u2, tol)
    zero = type(tol)(0.0)
    if kind == CONTACT_SEGMENT:
        m = (s0 + s1) * type(tol)(0.5)
        return zero, m, m
    d, p, q, o = centred_features(v0, v1, v2, u0, u1, u2, tol, type(tol)(wp.inf), zero, zero)
    if kind != CONTACT_NONE:  # a coplanar overlap: the closest pair found is a point of it
        m = (p + q) * type(tol)(0.5) + o
        return zero, m, m
    return d, p + o, q + o


@wp.func
def _extent(x0: Any, x1: Any, x2: Any):
    """The largest absolute coordinate of three points."""
    m = wp.max(wp.max(wp.abs(x0), wp.abs(x1)), wp.abs(x2))
    return wp.max(wp.max(m[0], m[1]), m[2])


@wp.func
def centred_features(v0: Any, v1: Any, v2: Any, u0: Any, u1: Any, u2: Any, tol: Any, reach: Any, slack: Any,
                     plane_slack: Any):
    """:func:`closest_features` on the pair centred on its centroid ``o``, degenerate triangles by
    ``tol``: ``(distance, p, q, o)``, ``p`` and ``q`` centred. With a finite ``reach``, a pair whose
    :func:`distance_lower_bound` passes it is not measured: ``+inf``; the bound's slacks are
    ``slack`` (its box gap's) and ``plane_slack`` (its planes') times the centred pair's largest
    coordinate. A plane's distance is as good as its normal: from float32 vertices their edges and
    products are exact in float64, so a few units in the last place; from float64 ones a normal
    turns by up to a unit in the last place times the triangle's longest edge squared over twice its
    area (less than ``1 / tol`` for a triangle that is not degenerate)."""
    o = (v0 + v1 + v2 + u0 + u1 + u2) / type(tol)(6.0)
    na, degenerate_a = _face_normal(v0, v1, v2, tol)
    nb, degenerate_b = _face_normal(u0, u1, u2, tol)
    a0 = v0 - o
    a1 = v1 - o
    a2 = v2 - o
    b0 = u0 - o
    b1 = u1 - o
    b2 = u2 - o
    if reach < type(tol)(wp.inf):
        size = wp.max(_extent(a0, a1, a2), _extent(b0, b1, b2))
        if distance_lower_bound(a0, a1, a2, b0, b1, b2, na, nb, not degenerate_a, not degenerate_b, slack * size,
                                plane_slack * size) > reach:
            return type(tol)(wp.inf), a0, b0, o
    d, p, q = closest_features(a0, a1, a2, b0, b1, b2, na, nb, not degenerate_a, not degenerate_b)
    return d, p, q, o


@wp.func
def feature_distance(v0: Any, v1: Any, v2: Any, u0: Any, u1: Any, u2: Any, tol: Any):
    """:func:`closest_features` of two triangles as :func:`tri_tri_distance` computes it (centred on
    the pair's centroid, degenerate triangles by ``tol``, the vertices' precision): ``(distance, p,
    q)`` in the input frame. Their distance where they do not intersect (the same bits as
    :func:`tri_tri_distance`'s), else the distance of two of their points: an upper bound always."""
    d, p, q, o = centred_features(v0, v1, v2, u0, u1, u2, tol, type(tol)(wp.inf), type(tol)(0.0), type(tol)(0.0))
    return d, p + o, q + o


@wp.kernel
def tri_tri_distance_batch_kernel(
    tri_a: wp.array2d[Any],
    tri_b: wp.array2d[Any],
    tol_rel: wp.float64,
    # Outputs
    distance: wp.array[Any],
    points: wp.array2d[Any],
):
    """One thread per pair of triangles given as ``(P, 3)`` vertex arrays (``wp.vec3`` or
    ``wp.vec3d``; ``tol_rel`` in float64, rounded to their precision): :func:`tri_tri_distance`'s
    distance ``(P,)`` and closest points ``(P, 2)`` (on ``a``, on ``b``), in the vertices' precision."""
    k = wp.tid()
    d, p, q = tri_tri_distance(tri_a[k, 0], tri_a[k, 1], tri_a[k, 2], tri_b[k, 0], tri_b[k, 1], tri_b[k, 2], tol_rel)
    distance[k] = d
    points[k, 0] = p
    points[k, 1] = q


# Both precisions, declared up front: the module compiles once, for float32 and float64 together.
for _precision in PRECISIONS:
    _scalar, _vec3, _, _ = precision_types(_precision)
    _triangles = wp.array2d[_vec3]
    wp.overload(tri_tri_distance_batch_kernel, {"tri_a": _triangles, "tri_b": _triangles,
                                                "distance": wp.array[_scalar], "points": _triangles})
