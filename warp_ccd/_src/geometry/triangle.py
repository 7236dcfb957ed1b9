"""The exact triangle-triangle tests: whether two closed triangles meet, where, and how deep they cross.

Two tests with the same semantics, one the cross-check of the other:

* :func:`tri_tri_moller`, Möller (1997), "A Fast Triangle-Triangle Intersection Test":
  1. reject when the three vertices of one triangle lie beyond ``eps`` on one side of the other's
     plane (tested both ways);
  2. when both triangles truly straddle the other's plane, each crosses it in a segment (a vertex,
     an edge, or two edge crossings), from the exact distances;
  3. both segments lie on the common line of the two planes: the triangles cross when they meet;
  4. otherwise they touch when they come within ``eps`` of each other: an edge of one within
     ``eps`` of the other (distance, not snapped sections: with nearly parallel planes the part
     of a triangle within ``eps`` of the other's plane is a wide strip, and two "sections" made
     from snapped distances need not lie on one line; projected on one direction they would
     report pairs thousands of tolerances apart).
  Coplanar triangles (all of one triangle's vertices within ``eps`` of the other's plane) go to a
  2D test in that plane: an edge of one within ``eps`` of an edge of the other, or a vertex of one
  inside the other (as the vertices are flattened onto the plane first, such pairs count as
  touching up to ``sqrt(2) eps`` apart).
* :func:`tri_tri_edge_face`, the edge-vs-face test: an edge of either triangle within
  ``eps`` of the other triangle (closed triangles intersect exactly when an edge of one meets the
  other, and are within ``eps`` exactly when an edge of one is).

A segment is within ``eps`` of a triangle when it passes through the triangle's prism within
``eps`` of its plane, or within ``eps`` of one of its edges: the triangle thickened by ``eps``,
without the corners that widening its edge lines would add (a thin triangle's sharp corner
would otherwise reach ``eps / sin(angle / 2)`` beyond its tip).

A degenerate triangle (see below) is decided as what it is: Möller's test takes the segment its
longest edge spans (a point when all three vertices coincide) and clips it to the other triangle
(or, for two degenerate triangles, takes the closest points of the two segments); the edge-face
test takes its three edges, against the other's face or, for two degenerate triangles, against
the other's edges.

Semantics shared by both:

* Triangles are closed sets: touching (at a vertex, along an edge) counts as intersecting.
* Tolerance: ``eps = tol_rel * L`` with ``L`` the longest edge of the two triangles, so the
  result does not change when a scene is scaled, and vertices are first expressed relative to
  the pair's centroid, so it does not change when a scene is translated far from the origin
  (float32 rounding of the input aside). Triangles within ``eps`` of each other touch.
* A triangle's plane comes from a normal computed in float64 from its vertices
  (:func:`~warp_ccd._src.geometry.primitives._unit_normal`), so that thin triangles keep their plane
  in float32 scenes too.
* A degenerate triangle (twice its area at most ``tol_rel`` times its longest edge squared: a
  sliver, collinear or repeated vertices) is still a closed set, within ``tol_rel`` times its
  longest edge of the segment (or point) it spans, and of its edges; it meets what they meet,
  within ``eps``. Fan-triangulated polygons of scanned and CAD meshes leave such slivers, and a
  sliver's edge through another triangle is a real contact.
* Every device gives the same verdict: only add, multiply, divide and square root (correctly
  rounded on every device) decide a verdict, and the module of a kernel that calls these tests is
  compiled without floating-point contraction (``fuse_fp=False``), so that CUDA does not fuse
  ``a * b + c`` into an FMA that the CPU rounds in two steps. Warp compiles a function into the
  module of the kernel that calls it, with that module's options: this module and the stages'
  set ``wp.set_module_options({"fuse_fp": False})``, and a user's module should too.

:func:`tri_tri_segment` is Möller's test that also says where the triangles meet (a segment, or a
coplanar area); :func:`crossing_depth` how deep two intersecting triangles cross;
:func:`tri_tri_batch_kernel` and :func:`tri_tri_segment_batch_kernel` run the tests over arrays of
triangle pairs. Their building blocks are in :mod:`~warp_ccd._src.geometry.primitives`.

Precision: every function takes ``wp.vec3`` or ``wp.vec3d`` vertices and computes in their
precision (Warp generics: ``Any``-typed arguments, literals as ``type(eps)(0.5)``); the batch
kernels' float32 and float64 variants are declared with ``wp.overload`` after them, so the module
compiles once for both. The functions take the tolerance in either precision and round it to the
vertices' (the kernels take it in float64).
"""


from typing import Any

import warp as wp

from .precision import PRECISIONS, precision_types
from .primitives import (
    _closest_segment_points,
    _common_part,
    _coplanar_overlap,
    _edge,
    _edge_normals,
    _edges_meet,
    _max_edge,
    _one_side,
    _plane_distances,
    _plane_section,
    _segment_triangle_section,
    _segments_within,
    _span,
    _unit_normal,
)

# Forward kernels only; no FMA contraction, so that CPU and CUDA round every step alike.
wp.set_module_options({"enable_backward": False, "fuse_fp": False})

__all__ = [
    "CONTACT_AREA",
    "CONTACT_NONE",
    "CONTACT_SEGMENT",
    "METHOD_EDGE_FACE",
    "METHOD_MOLLER",
    "TOLERANCE",
    "crossing_depth",
    "tri_tri_batch_kernel",
    "tri_tri_edge_face",
    "tri_tri_moller",
    "tri_tri_segment",
    "tri_tri_segment_batch_kernel",
    "tri_tri_test",
]


TOLERANCE = 1.0e-5
"""Default relative tolerance of the triangle tests (about 80 float32 units in the last place)."""

METHOD_MOLLER = wp.constant(0)
"""``method`` of :func:`tri_tri_test` and the kernels: Möller's test."""
METHOD_EDGE_FACE = wp.constant(1)
"""``method`` of :func:`tri_tri_test` and the kernels: the edge-face test."""

CONTACT_NONE = wp.constant(0)
"""``kind`` of :func:`tri_tri_segment`: the triangles are apart."""
CONTACT_SEGMENT = wp.constant(1)
"""``kind`` of :func:`tri_tri_segment`: they cross or touch along a segment (or at a point)."""
CONTACT_AREA = wp.constant(2)
"""``kind`` of :func:`tri_tri_segment`: coplanar contact, an area (no segment)."""


@wp.func
def _centre(v0: Any, v1: Any, v2: Any, u0: Any, u1: Any, u2: Any, tol_rel: Any):
    """Vertices relative to the pair's centroid, and the tolerance ``eps``."""
    o = (v0 + v1 + v2 + u0 + u1 + u2) / type(tol_rel)(6.0)
    a0 = v0 - o
    a1 = v1 - o
    a2 = v2 - o
    b0 = u0 - o
    b1 = u1 - o
    b2 = u2 - o
    eps = tol_rel * wp.max(_max_edge(a0, a1, a2), _max_edge(b0, b1, b2))
    return a0, a1, a2, b0, b1, b2, eps


@wp.func
def _centre_pair(v0: Any, v1: Any, v2: Any, u0: Any, u1: Any, u2: Any, tol_rel: Any):
    """Shared set-up of both tests: vertices relative to the pair's centroid, unit normals
    ``na``, ``nb`` (:func:`_unit_normal`), the tolerance ``eps``, and whether each triangle is
    degenerate (then its normal is zero and unused)."""
    a0, a1, a2, b0, b1, b2, eps = _centre(v0, v1, v2, u0, u1, u2, tol_rel)
    na, degenerate_a = _unit_normal(v0, v1, v2, tol_rel)
    nb, degenerate_b = _unit_normal(u0, u1, u2, tol_rel)
    return a0, a1, a2, b0, b1, b2, na, nb, eps, degenerate_a, degenerate_b


@wp.func
def _degenerate_section(
    a0: Any, a1: Any, a2: Any, b0: Any, b1: Any, b2: Any, na: Any, nb: Any, eps: Any, degenerate_a: bool,
    degenerate_b: bool,
):
    """Möller's test when a triangle is degenerate: it is the segment (or point) it spans.
    Returns ``(hit, p, q)``, ``pq`` where they meet (centred frame)."""
    pa, qa = _span(a0, a1, a2)
    pb, qb = _span(b0, b1, b2)
    if degenerate_a and degenerate_b:
        c1, c2 = _closest_segment_points(pa, qa, pb, qb)
        if wp.length(c1 - c2) > eps:
            return False, c1, c1
        # Parallel segments (collinear, as they are close) share an interval, not a point.
        da = qa - pa
        db = qb - pb
        if wp.length(wp.cross(da, db)) <= eps * wp.max(wp.length(da), wp.length(db)):
            p, q = _common_part(pa, qa, pb, qb)
            return True, p, q
        mid = (c1 + c2) * type(eps)(0.5)
        return True, mid, mid
    if degenerate_a:
        m0, m1, m2 = _edge_normals(b0, b1, b2, nb)
        return _segment_triangle_section(pa, qa, b0, b1, b2, nb, m0, m1, m2, eps)
    m0, m1, m2 = _edge_normals(a0, a1, a2, na)
    return _segment_triangle_section(pb, qb, a0, a1, a2, na, m0, m1, m2, eps)


CONTACT_TOUCH_TEST = wp.constant(3)
"""Internal ``kind`` of :func:`_moller_crossing`: no crossing; whether the triangles touch is step
4's to decide (:func:`_edges_meet`)."""
CONTACT_COPLANAR_A = wp.constant(4)
"""Internal ``kind`` of :func:`_moller_steps`: ``b`` lies in ``a``'s plane (within ``eps``)."""
CONTACT_COPLANAR_B = wp.constant(5)
"""Internal ``kind`` of :func:`_moller_steps`: ``a`` lies in ``b``'s plane (within ``eps``)."""


@wp.func
def _moller_steps(a0: Any, a1: Any, a2: Any, b0: Any, b1: Any, b2: Any, na: Any, nb: Any, eps: Any):
    """Steps 1 to 3 of Möller's test on a centred pair of triangles that are not degenerate:
    ``(kind, p, q)`` as :func:`_moller_crossing`, except that a coplanar pair is only named
    (:data:`CONTACT_COPLANAR_A` or :data:`CONTACT_COPLANAR_B`), not decided."""
    zero_v = type(a0)()
    # 1. Triangle b against the plane of a, then a against the plane of b.
    rb0, rb1, rb2, db0, db1, db2 = _plane_distances(na, a0, b0, b1, b2, eps)
    if _one_side(db0, db1, db2):
        return CONTACT_NONE, zero_v, zero_v
    ra0, ra1, ra2, da0, da1, da2 = _plane_distances(nb, b0, a0, a1, a2, eps)
    if _one_side(da0, da1, da2):
        return CONTACT_NONE, zero_v, zero_v
    zero = type(eps)(0.0)
    if db0 == zero and db1 == zero and db2 == zero:  # coplanar
        return CONTACT_COPLANAR_A, zero_v, zero_v
    if da0 == zero and da1 == zero and da2 == zero:
        return CONTACT_COPLANAR_B, zero_v, zero_v
    # 2. Where each triangle crosses the other's plane (a section of each, from the exact
    # distances, when both truly straddle the other's plane), and 3. whether the two sections,
    # on the common line, meet: the triangles cross.
    if not _one_side(ra0, ra1, ra2) and not _one_side(rb0, rb1, rb2):
        pa, qa = _plane_section(a0, a1, a2, ra0, ra1, ra2)
        pb, qb = _plane_section(b0, b1, b2, rb0, rb1, rb2)
        if _segments_within(pa, qa, pb, qb, eps):
            p, q = _common_part(pa, qa, pb, qb)
            return CONTACT_SEGMENT, p, q
    return CONTACT_TOUCH_TEST, zero_v, zero_v


@wp.func
def _moller_crossing(
    a0: Any, a1: Any, a2: Any, b0: Any, b1: Any, b2: Any, na: Any, nb: Any, eps: Any, degenerate_a: bool,
    degenerate_b: bool,
):
    """Steps 1 to 3 of Möller's test on a centred pair (:func:`_centre_pair`): ``(kind, p, q)``,
    ``pq`` in the centred frame (zero unless ``kind`` is :data:`CONTACT_SEGMENT`, or the pair has
    a degenerate triangle), ``kind`` that of :func:`tri_tri_segment` or
    :data:`CONTACT_TOUCH_TEST` when step 4 decides."""
    zero_v = type(a0)()
    if degenerate_a or degenerate_b:
        hit, p, q = _degenerate_section(a0, a1, a2, b0, b1, b2, na, nb, eps, degenerate_a, degenerate_b)
        return wp.where(hit, CONTACT_SEGMENT, CONTACT_NONE), p, q
    kind, p, q = _moller_steps(a0, a1, a2, b0, b1, b2, na, nb, eps)
    if kind == CONTACT_COPLANAR_A:
        return wp.where(_coplanar_overlap(a0, a1, a2, b0, b1, b2, na, eps), CONTACT_AREA, CONTACT_NONE), zero_v, zero_v
    if kind == CONTACT_COPLANAR_B:
        return wp.where(_coplanar_overlap(b0, b1, b2, a0, a1, a2, nb, eps), CONTACT_AREA, CONTACT_NONE), zero_v, zero_v
    return kind, p, q


@wp.func
def tri_tri_segment(v0: Any, v1: Any, v2: Any, u0: Any, u1: Any, u2: Any, tol_rel: Any):
    """Möller's test, and where the triangles meet: ``(kind, p, q)``.

    Args:
        v0: first vertex of the first triangle, in one coordinate frame with the others (any units);
            all six vertices ``wp.vec3`` (the test computes in float32) or all ``wp.vec3d`` (in float64).
        v1: second vertex of the first triangle.
        v2: third vertex of the first triangle.
        u0: first vertex of the second triangle.
        u1: second vertex of the second triangle.
        u2: third vertex of the second triangle.
        tol_rel: tolerance relative to the longest edge (see the module docstring), a float of
            either precision, rounded to the vertices' precision. With float64 vertices give it
            in float64 (``wp.float64(wc.TOLERANCE)``): a float32 value is already rounded.

    Returns:
        ``kind`` :data:`CONTACT_NONE`: apart; :data:`CONTACT_SEGMENT`: they cross or touch along
        the segment ``pq`` (a point when ``p == q``), in the input frame; :data:`CONTACT_AREA`:
        coplanar contact (an area, no segment; ``p``, ``q`` are the pair's centroid). A degenerate
        triangle is tested as the segment or point it is (see the module docstring): its contacts
        are :data:`CONTACT_SEGMENT`.
    """
    tol = type(v0[0])(tol_rel)
    o = (v0 + v1 + v2 + u0 + u1 + u2) / type(tol)(6.0)
    a0, a1, a2, b0, b1, b2, na, nb, eps, degenerate_a, degenerate_b = _centre_pair(v0, v1, v2, u0, u1, u2, tol)
    kind, p, q = _moller_crossing(a0, a1, a2, b0, b1, b2, na, nb, eps, degenerate_a, degenerate_b)
    if kind == CONTACT_TOUCH_TEST:
        # 4. No crossing: touching within the tolerance, decided by distance (an edge of one within
        # eps of the other). Sections from snapped distances cannot decide it: with nearly
        # parallel planes the part of a triangle within eps of the other's plane is a wide strip,
        # not a segment, and two such "sections" need not lie on one line.
        hit, p, q = _edges_meet(a0, a1, a2, b0, b1, b2, na, nb, eps, True, True)
        if hit:
            return CONTACT_SEGMENT, p + o, q + o
        return CONTACT_NONE, o, o
    if kind == CONTACT_SEGMENT or degenerate_a or degenerate_b:
        return kind, p + o, q + o
    return kind, o, o


@wp.func
def tri_tri_moller(v0: Any, v1: Any, v2: Any, u0: Any, u1: Any, u2: Any, tol_rel: Any) -> bool:
    """Möller's test: do the closed triangles ``(v0, v1, v2)`` and ``(u0, u1, u2)`` intersect?

    Same arguments and precisions as :func:`tri_tri_segment`.

    Returns:
        True when they intersect or touch within the tolerance (a degenerate triangle as the
        segment or point it is).
    """
    kind, p, q = tri_tri_segment(v0, v1, v2, u0, u1, u2, tol_rel)
    return kind != CONTACT_NONE


@wp.func
def tri_tri_edge_face(v0: Any, v1: Any, v2: Any, u0: Any, u1: Any, u2: Any, tol_rel: Any) -> bool:
    """Edge-vs-face test, the cross-check of Möller's: some edge of either triangle meets the other.

    Same arguments, precisions, tolerance and semantics as :func:`tri_tri_moller`.
    """
    tol = type(v0[0])(tol_rel)
    a0, a1, a2, b0, b1, b2, na, nb, eps, degenerate_a, degenerate_b = _centre_pair(v0, v1, v2, u0, u1, u2, tol)
    if degenerate_a and degenerate_b:  # two segments (or points): some edge near some edge
        for i in range(3):
            pa, qa = _edge(a0, a1, a2, i)
            for j in range(3):
                pb, qb = _edge(b0, b1, b2, j)
                if _segments_within(pa, qa, pb, qb, eps):
                    return True
        return False
    # A degenerate triangle has no face: only its edges are tested, against the other's face.
    hit, p, q = _edges_meet(a0, a1, a2, b0, b1, b2, na, nb, eps, not degenerate_a, not degenerate_b)
    return hit


@wp.func
def tri_tri_test(method: int, v0: Any, v1: Any, v2: Any, u0: Any, u1: Any, u2: Any, tol_rel: Any) -> bool:
    """``method`` :data:`METHOD_MOLLER`: :func:`tri_tri_moller`; :data:`METHOD_EDGE_FACE`:
    :func:`tri_tri_edge_face`."""
    if method == METHOD_MOLLER:
        return tri_tri_moller(v0, v1, v2, u0, u1, u2, tol_rel)
    return tri_tri_edge_face(v0, v1, v2, u0, u1, u2, tol_rel)


@wp.func
def _lesser_side(n: Any, origin: Any, x0: Any, x1: Any, x2: Any, eps: Any):
    """How far triangle ``x`` reaches to the lesser side of the plane through ``origin`` of unit
    normal ``n``: ``min(max d, max -d)`` over its vertices' signed distances ``d``, zero when
    that is within ``eps`` (the triangle only touches the plane)."""
    r0 = wp.dot(n, x0 - origin)
    r1 = wp.dot(n, x1 - origin)
    r2 = wp.dot(n, x2 - origin)
    d = wp.min(wp.max(wp.max(r0, r1), r2), -wp.min(wp.min(r0, r1), r2))
    if d <= eps:
        return type(eps)(0.0)
    return d


@wp.func
def crossing_depth(v0: Any, v1: Any, v2: Any, u0: Any, u1: Any, u2: Any, tol_rel: Any):
    """How deep two intersecting triangles cross: of each triangle, how far it reaches to the
    lesser side of the other's plane; the smaller of the two (a degenerate triangle, without a
    plane, leaves the other's). Zero when one only touches the other's plane within the
    tolerance ``tol_rel * L`` (:func:`tri_tri_moller`): resting contact (face on face, an edge
    or a vertex on a face) has depth 0; a vertex poking ``h`` through a face has depth ``h``.
    Scene units, the vertices' precision."""
    a0, a1, a2, b0, b1, b2, na, nb, eps, degenerate_a, degenerate_b = _centre_pair(v0, v1, v2, u0, u1, u2, tol_rel)
    zero = type(eps)(0.0)
    if degenerate_a and degenerate_b:
        return zero
    if degenerate_b:
        return _lesser_side(na, a0, b0, b1, b2, eps)
    if degenerate_a:
        return _lesser_side(nb, b0, a0, a1, a2, eps)
    return wp.min(_lesser_side(nb, b0, a0, a1, a2, eps), _lesser_side(na, a0, b0, b1, b2, eps))


@wp.kernel
def tri_tri_batch_kernel(
    tri_a: wp.array2d[Any],
    tri_b: wp.array2d[Any],
    method: int,
    tol_rel: wp.float64,
    # Outputs
    result: wp.array[wp.int32],
):
    """One thread per pair of triangles given directly as ``(P, 3)`` vertex arrays (``wp.vec3``
    or ``wp.vec3d``; ``tol_rel`` in float64, rounded to their precision): :func:`tri_tri_test`'s
    verdict, 1 or 0."""
    k = wp.tid()
    r = tri_tri_test(method, tri_a[k, 0], tri_a[k, 1], tri_a[k, 2], tri_b[k, 0], tri_b[k, 1], tri_b[k, 2], tol_rel)
    result[k] = wp.where(r, 1, 0)


@wp.kernel
def tri_tri_segment_batch_kernel(
    tri_a: wp.array2d[Any],
    tri_b: wp.array2d[Any],
    tol_rel: wp.float64,
    # Outputs
    kind: wp.array[wp.int32],
    segment: wp.array2d[Any],
):
    """One thread per pair of triangles given as ``(P, 3)`` vertex arrays (either precision, as
    :func:`tri_tri_batch_kernel`): :func:`tri_tri_segment`'s ``kind`` and segment ``(P, 2)``."""
    k = wp.tid()
    c, p, q = tri_tri_segment(tri_a[k, 0], tri_a[k, 1], tri_a[k, 2], tri_b[k, 0], tri_b[k, 1], tri_b[k, 2], tol_rel)
    kind[k] = c
    segment[k, 0] = p
    segment[k, 1] = q


# Both precisions, declared up front: the module compiles once, for float32 and float64 together.
# The kernels take the tolerance in float64 and round it to the vertices' precision.
for _precision in PRECISIONS:
    _, _vec3, _, _ = precision_types(_precision)
    _triangles = wp.array2d[_vec3]
    wp.overload(tri_tri_batch_kernel, {"tri_a": _triangles, "tri_b": _triangles})
    wp.overload(tri_tri_segment_batch_kernel, {"tri_a": _triangles, "tri_b": _triangles, "segment": _triangles})
