"""Narrow phase: exact triangle-triangle tests, and the batched kernels over candidate pairs.

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
  (:func:`_unit_normal`), so that thin triangles keep their plane in float32 scenes too.
* A degenerate triangle (twice its area at most ``tol_rel`` times its longest edge squared: a
  sliver, collinear or repeated vertices) is still a closed set, within ``tol_rel`` times its
  longest edge of the segment (or point) it spans, and of its edges; it meets what they meet,
  within ``eps``. Fan-triangulated polygons of scanned and CAD meshes leave such slivers, and a
  sliver's edge through another triangle is a real contact.
* Every device gives the same verdict: the module is compiled without floating-point
  contraction (``fuse_fp=False``), so CUDA does not fuse ``a * b + c`` into an FMA that the CPU
  rounds in two steps. Only add, multiply, divide and square root (correctly rounded on every
  device) decide a verdict; the winding number of the containment option uses ``atan2`` and may
  differ in its last bits, far from its decision at 1/2.

Over candidate pairs (:class:`NarrowPhase`), Möller's test runs as three kernels. One thread per
candidate takes steps 1 to 3, and the pairs that do not cross go to a touch list whose step 4 (six
edge-against-face tests) runs in a second kernel, two threads a pair (the edges of one triangle
against the other's face each; six threads, one test each, recomputed the pair's set-up six
times). A warp of the first kernel then no longer waits for its slowest lane's six tests, the
longest of the test's paths (at 1,000 polyhedra, 874 of 4,917 candidates reach step 4, in nearly
every warp; steps 1 to 3 alone take 0.006 ms on an H100 where the whole test took 0.014 ms). The
rare pairs, with a degenerate triangle or coplanar, go from the first kernel to a third that runs
the whole test (:func:`tri_tri_moller`), so that the first holds only the common path in its
registers (capped at :data:`MAX_REGISTERS` on CUDA, as the second's). The verdicts are those of
:func:`tri_tri_moller`, bit for bit.

Precision: every function takes ``wp.vec3`` or ``wp.vec3d`` vertices and computes in their
precision (Warp generics: ``Any``-typed arguments, literals as ``type(eps)(0.5)``); the kernels'
float32 and float64 variants are declared with ``wp.overload`` after them, so the module compiles
once for both. The functions take the tolerance in either precision and round it to the
vertices' (the kernels take it in float64).
"""


from typing import Any

import warp as wp

from ..geometry.precision import PRECISIONS, precision_overloads, precision_types
from ..scene.scene import MeshTopology, mesh_triangle
from .buffers import GrowableBuffer, reserve_slot, used_count

# Forward kernels only; no FMA contraction, so that CPU and CUDA round every step alike.
wp.set_module_options({"enable_backward": False, "fuse_fp": False})

__all__ = [
    "CONTACT_AREA",
    "CONTACT_NONE",
    "CONTACT_SEGMENT",
    "METHOD_EDGE_FACE",
    "METHOD_MOLLER",
    "NARROW_METHODS",
    "NarrowPhase",
    "TOLERANCE",
    "crossing_depth",
    "pair_crossing_depth",
    "tri_tri_batch_kernel",
    "tri_tri_edge_face",
    "tri_tri_moller",
    "tri_tri_segment",
    "tri_tri_segment_batch_kernel",
    "tri_tri_test",
    "winding_number",
]

TOLERANCE = 1.0e-5
"""Default relative tolerance of the triangle tests (about 80 float32 units in the last place)."""

MAX_REGISTERS = 128
"""Most registers a thread of the two kernels of Möller's test on CUDA: as compiled freely they take
255 (with spills) and 164, so that an H100 multiprocessor holds 256 of their threads; at 128 it
holds 512 and the frame at 10^6 polyhedra / 10^5 80-triangle objects took 3.33 / 1.32 ms against
4.36 / 1.66 (at 64, 4.22 / 1.79: spills; ``warp_ccd/bench/box_tests.py --max-registers``,
``bench/results/box_tests_registers_cuda0.json``, ``warp_ccd/bench/kernel_resources.py``)."""

METHOD_MOLLER = wp.constant(0)
"""``method`` of :func:`tri_tri_test` and the kernels: Möller's test."""
METHOD_EDGE_FACE = wp.constant(1)
"""``method`` of :func:`tri_tri_test` and the kernels: the edge-face test."""

NARROW_METHODS = {"moller": METHOD_MOLLER, "edge_face": METHOD_EDGE_FACE}
"""The ``narrow_phase`` option's names of the two tests, and their ``method`` ids."""

CONTACT_NONE = wp.constant(0)
"""``kind`` of :func:`tri_tri_segment`: the triangles are apart."""
CONTACT_SEGMENT = wp.constant(1)
"""``kind`` of :func:`tri_tri_segment`: they cross or touch along a segment (or at a point)."""
CONTACT_AREA = wp.constant(2)
"""``kind`` of :func:`tri_tri_segment`: coplanar contact, an area (no segment)."""

FOUR_PI = wp.constant(wp.float64(12.566370614359172))
"""The solid angle of the whole sphere (the winding number's unit)."""


@wp.func
def _snap(d: Any, eps: Any):
    if wp.abs(d) <= eps:
        return type(d)(0.0)
    return d


@wp.func
def _one_side(d0: Any, d1: Any, d2: Any) -> bool:
    """All three distances strictly positive, or all strictly negative."""
    zero = type(d0)(0.0)
    return (d0 > zero and d1 > zero and d2 > zero) or (d0 < zero and d1 < zero and d2 < zero)


@wp.func
def _max_edge(a: Any, b: Any, c: Any):
    return wp.max(wp.max(wp.length(b - a), wp.length(c - b)), wp.length(a - c))


@wp.func
def _cross2(a: Any, b: Any):
    return a[0] * b[1] - a[1] * b[0]


@wp.func
def _point_segment_dist(p: Any, a: Any, b: Any):
    ab = b - a
    den = wp.dot(ab, ab)
    zero = type(den)(0.0)
    t = zero
    if den > zero:
        t = wp.clamp(wp.dot(p - a, ab) / den, zero, type(den)(1.0))
    return wp.length(p - (a + ab * t))


@wp.func
def _segments_within_2d(p: Any, q: Any, r: Any, s: Any, eps: Any) -> bool:
    """Closed segments ``pq`` and ``rs`` in a plane are within ``eps`` of each other."""
    o1 = _cross2(q - p, r - p)
    o2 = _cross2(q - p, s - p)
    o3 = _cross2(s - r, p - r)
    o4 = _cross2(s - r, q - r)
    if o1 * o2 < type(eps)(0.0) and o3 * o4 < type(eps)(0.0):
        return True
    d = wp.min(
        wp.min(_point_segment_dist(p, r, s), _point_segment_dist(q, r, s)),
        wp.min(_point_segment_dist(r, p, q), _point_segment_dist(s, p, q)),
    )
    return d <= eps


@wp.func
def _inside_edge_2d(p: Any, a: Any, b: Any, orient: Any) -> bool:
    """``p`` on the inner side of edge ``ab`` (or on its line) of a triangle of orientation ``orient``."""
    return orient * _cross2(b - a, p - a) >= type(orient)(0.0)


@wp.func
def _point_in_triangle_2d(p: Any, a: Any, b: Any, c: Any) -> bool:
    """``p`` inside the closed (non-degenerate) triangle ``abc``; near its boundary rounding
    decides, so callers test the boundary within their tolerance apart."""
    orient = wp.sign(_cross2(b - a, c - a))
    return (
        _inside_edge_2d(p, a, b, orient)
        and _inside_edge_2d(p, b, c, orient)
        and _inside_edge_2d(p, c, a, orient)
    )


@wp.func
def _to_plane(p: Any, e1: Any, e2: Any):
    return wp.vector(wp.dot(p, e1), wp.dot(p, e2))


@wp.func
def _coplanar_overlap(
    a0: Any, a1: Any, a2: Any, b0: Any, b1: Any, b2: Any, n: Any, eps: Any
) -> bool:
    """Both triangles in the plane of unit normal ``n``: 2D overlap test, isometric projection."""
    e1 = wp.normalize(a1 - a0)
    if wp.length(a2 - a1) > wp.length(a1 - a0):
        e1 = wp.normalize(a2 - a1)
    e2 = wp.cross(n, e1)
    p0 = _to_plane(a0, e1, e2)
    p1 = _to_plane(a1, e1, e2)
    p2 = _to_plane(a2, e1, e2)
    q0 = _to_plane(b0, e1, e2)
    q1 = _to_plane(b1, e1, e2)
    q2 = _to_plane(b2, e1, e2)
    # A vertex of one inside the other (closed, not widened: near the boundary the edge test
    # below decides, so that a sharp corner does not reach further than eps) ...
    if _point_in_triangle_2d(p0, q0, q1, q2) or _point_in_triangle_2d(q0, p0, p1, p2):
        return True
    # ... otherwise they are within eps only if their boundaries are.
    for i in range(3):
        pa = p0
        pb = p1
        if i == 1:
            pa = p1
            pb = p2
        elif i == 2:
            pa = p2
            pb = p0
        if (
            _segments_within_2d(pa, pb, q0, q1, eps)
            or _segments_within_2d(pa, pb, q1, q2, eps)
            or _segments_within_2d(pa, pb, q2, q0, eps)
        ):
            return True
    return False


@wp.func
def _push(p: Any, q: Any, count: int, x: Any):
    if count == 0:
        return x, x, 1
    return p, x, count + 1


@wp.func
def _plane_section(a: Any, b: Any, c: Any, da: Any, db: Any, dc: Any):
    """Segment ``(p, q)`` where triangle ``abc`` meets a plane, from its snapped signed distances
    (not all zero, not all of one strict sign). Returns ``(p, q)`` (``p == q`` for a point)."""
    zero = type(da)(0.0)
    p = a
    q = a
    count = int(0)
    if da == zero:
        p, q, count = _push(p, q, count, a)
    if db == zero:
        p, q, count = _push(p, q, count, b)
    if dc == zero:
        p, q, count = _push(p, q, count, c)
    if da * db < zero:
        p, q, count = _push(p, q, count, a + (b - a) * (da / (da - db)))
    if db * dc < zero:
        p, q, count = _push(p, q, count, b + (c - b) * (db / (db - dc)))
    if dc * da < zero:
        p, q, count = _push(p, q, count, c + (a - c) * (dc / (dc - da)))
    return p, q


@wp.func
def _common_part(pa: Any, qa: Any, pb: Any, qb: Any):
    """Where two segments that come within the tolerance meet, for reporting: ``(p, q)``, the
    overlap of their projections on the longer one's line (a point when they only touch).
    Two sections of crossing triangles lie on one line, so this is the segment they share."""
    da = qa - pa
    db = qb - pb
    origin = pa
    d = da
    if wp.dot(db, db) > wp.dot(da, da):
        origin = pb
        d = db
    ld = wp.length(d)
    if ld == type(ld)(0.0):  # two points
        mid = (pa + pb) * type(ld)(0.5)
        return mid, mid
    u = d / ld
    ta0 = wp.dot(pa - origin, u)
    ta1 = wp.dot(qa - origin, u)
    tb0 = wp.dot(pb - origin, u)
    tb1 = wp.dot(qb - origin, u)
    lo = wp.max(wp.min(ta0, ta1), wp.min(tb0, tb1))
    hi = wp.min(wp.max(ta0, ta1), wp.max(tb0, tb1))
    if lo > hi:  # touching within the tolerance: one point between the two ends
        lo = (lo + hi) * type(ld)(0.5)
        hi = lo
    return origin + u * lo, origin + u * hi


@wp.func
def _unit_normal(x0: Any, x1: Any, x2: Any, tol_rel: Any):
    """Unit normal of triangle ``x0 x1 x2`` and whether it is degenerate (twice its area at most
    ``tol_rel`` times its longest edge squared; its normal is then zero).

    Computed in float64 from the vertices as given: the edges of float32 vertices and their
    products are exact there, so a thin triangle keeps its plane. In float32 the cross product
    of two nearly parallel edges would turn the normal by about 6e-8 over the triangle's
    doubled area in units of its longest edge squared: 6e-3 rad for a triangle just above the
    degeneracy threshold, which moves its own vertices hundreds of tolerances off its plane.
    """
    e1 = wp.vec3d(x1) - wp.vec3d(x0)
    e2 = wp.vec3d(x2) - wp.vec3d(x0)
    e3 = wp.vec3d(x2) - wp.vec3d(x1)
    n = wp.cross(e1, e2)
    ln = wp.length(n)
    longest_sq = wp.max(wp.max(wp.length_sq(e1), wp.length_sq(e2)), wp.length_sq(e3))
    if ln <= wp.float64(tol_rel) * longest_sq:
        return type(x0)(), True  # zero
    return type(x0)(n / ln), False


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
def _pick(x0: Any, x1: Any, x2: Any, i: int):
    """``x0``, ``x1`` or ``x2`` for ``i`` 0, 1 or 2."""
    if i == 0:
        return x0
    if i == 1:
        return x1
    return x2


@wp.func
def _edge(a: Any, b: Any, c: Any, i: int):
    """Edge ``i`` of triangle ``abc``: ``(a, b)``, ``(b, c)`` or ``(c, a)``."""
    return _pick(a, b, c, i), _pick(b, c, a, i)


@wp.func
def _span(a: Any, b: Any, c: Any):
    """The longest edge ``(p, q)`` of triangle ``abc``. A degenerate triangle lies within
    ``tol_rel`` times its longest edge of this segment (its third vertex's distance is twice
    its area over the edge), so it is tested as this segment (a point when ``p == q``)."""
    lab = wp.length_sq(b - a)
    lbc = wp.length_sq(c - b)
    lca = wp.length_sq(a - c)
    if lab >= lbc and lab >= lca:
        return a, b
    if lbc >= lca:
        return b, c
    return c, a


@wp.func
def _closest_segment_points(p1: Any, q1: Any, p2: Any, q2: Any):
    """Closest points ``(c1, c2)`` of the closed segments ``p1 q1`` and ``p2 q2`` (either may be a
    point; Ericson, Real-Time Collision Detection, 5.1.9)."""
    d1 = q1 - p1
    d2 = q2 - p2
    r = p1 - p2
    a = wp.dot(d1, d1)
    e = wp.dot(d2, d2)
    f = wp.dot(d2, r)
    zero = type(a)(0.0)
    one = type(a)(1.0)
    s = zero
    t = zero
    if a > zero and e > zero:
        b = wp.dot(d1, d2)
        c = wp.dot(d1, r)
        denom = a * e - b * b
        if denom > zero:
            s = wp.clamp((b * f - c * e) / denom, zero, one)
        t = (b * s + f) / e
        if t < zero:
            t = zero
            s = wp.clamp(-c / a, zero, one)
        elif t > one:
            t = one
            s = wp.clamp((b - c) / a, zero, one)
    elif a > zero:
        s = wp.clamp(-wp.dot(d1, r) / a, zero, one)
    elif e > zero:
        t = wp.clamp(f / e, zero, one)
    return p1 + d1 * s, p2 + d2 * t


@wp.func
def _segments_within(p1: Any, q1: Any, p2: Any, q2: Any, eps: Any) -> bool:
    """Closed segments (or points) in space within ``eps`` of each other."""
    c1, c2 = _closest_segment_points(p1, q1, p2, q2)
    return wp.length(c1 - c2) <= eps


@wp.func
def _plane_distances(n: Any, origin: Any, x0: Any, x1: Any, x2: Any, eps: Any):
    """Signed distances of ``x0, x1, x2`` to the plane through ``origin`` of unit normal ``n``:
    exact, then snapped to zero within ``eps``."""
    r0 = wp.dot(n, x0 - origin)
    r1 = wp.dot(n, x1 - origin)
    r2 = wp.dot(n, x2 - origin)
    return r0, r1, r2, _snap(r0, eps), _snap(r1, eps), _snap(r2, eps)


@wp.func
def _clip(f0: Any, f1: Any, lo: Any, hi: Any):
    """Narrows ``[lo, hi]`` to the ``t`` where ``f0 + t (f1 - f0) >= 0``; empty when ``lo > hi``."""
    zero = type(f0)(0.0)
    if f0 < zero and f1 < zero:
        return type(f0)(1.0), zero
    if f0 < zero:
        return wp.max(lo, f0 / (f0 - f1)), hi
    if f1 < zero:
        return lo, wp.min(hi, f0 / (f0 - f1))
    return lo, hi


@wp.func
def _edge_normals(a: Any, b: Any, c: Any, n: Any):
    """Unit normals of the edges ``ab``, ``bc``, ``ca`` in the plane of triangle ``abc`` (unit
    normal ``n``), pointing into the triangle."""
    return (
        wp.normalize(wp.cross(n, b - a)),
        wp.normalize(wp.cross(n, c - b)),
        wp.normalize(wp.cross(n, a - c)),
    )


@wp.func
def _segment_triangle_section(
    p: Any, q: Any, a: Any, b: Any, c: Any, n: Any, m0: Any, m1: Any, m2: Any, eps: Any
):
    """Where the closed segment ``pq`` (a point when ``p == q``) meets the closed triangle
    ``abc`` of unit normal ``n`` and inward edge normals ``m0, m1, m2`` (:func:`_edge_normals`)
    within ``eps``: ``(hit, s0, s1)``.

    They meet when the segment comes within ``eps`` of the triangle: it passes through the
    triangle's prism within ``eps`` of its plane, or within ``eps`` of one of its edges (the
    triangle thickened by ``eps`` is exactly that union). ``s0 s1`` is the point where the
    segment crosses the plane (moved into the part within ``eps`` of the triangle when it
    crosses just outside), else the part of the segment within ``eps`` of the plane and of the
    inner side of every edge line (an in-plane sliver's overlap with the triangle).
    """
    rp = wp.dot(n, p - a)
    rq = wp.dot(n, q - a)
    # Parameters t of p + t (q - p) within eps of the plane ...
    lo, hi = _clip(eps - rp, eps - rq, type(eps)(0.0), type(eps)(1.0))
    lo, hi = _clip(eps + rp, eps + rq, lo, hi)
    if lo > hi:
        return False, p, p
    wide_lo = lo
    wide_hi = hi
    # ... and over the triangle (lo, hi), or within eps of its edge lines (wide_lo, wide_hi).
    for i in range(3):
        u, v = _edge(a, b, c, i)
        m = _pick(m0, m1, m2, i)
        fp = wp.dot(m, p - u)
        fq = wp.dot(m, q - u)
        lo, hi = _clip(fp, fq, lo, hi)
        wide_lo, wide_hi = _clip(fp + eps, fq + eps, wide_lo, wide_hi)
        if wide_lo > wide_hi:
            return False, p, p
    if lo > hi and not (
        _segments_within(p, q, a, b, eps) or _segments_within(p, q, b, c, eps) or _segments_within(p, q, c, a, eps)
    ):
        return False, p, p  # near an edge line, beyond a sharp corner: more than eps away
    d = q - p
    if rp * rq < type(eps)(0.0):
        x = p + d * wp.clamp(rp / (rp - rq), wide_lo, wide_hi)
        return True, x, x
    return True, p + d * wide_lo, p + d * wide_hi


@wp.func
def _edges_near_face(x0: Any, x1: Any, x2: Any, f0: Any, f1: Any, f2: Any, nf: Any, eps: Any):
    """Some edge of triangle ``x`` within ``eps`` of triangle ``f`` (unit normal ``nf``):
    ``(hit, p, q)``, ``pq`` where the first such edge meets it."""
    m0, m1, m2 = _edge_normals(f0, f1, f2, nf)
    for i in range(3):
        p, q = _edge(x0, x1, x2, i)
        hit, s0, s1 = _segment_triangle_section(p, q, f0, f1, f2, nf, m0, m1, m2, eps)
        if hit:
            return True, s0, s1
    return False, x0, x0


@wp.func
def _edges_meet(
    a0: Any, a1: Any, a2: Any, b0: Any, b1: Any, b2: Any, na: Any, nb: Any, eps: Any, face_a: bool, face_b: bool
):
    """Some edge of one triangle within ``eps`` of the other: ``(hit, p, q)``, ``pq`` where the
    first such edge meets it. The edges of ``a`` are tested against ``b``'s face when
    ``face_b``, the edges of ``b`` against ``a``'s when ``face_a``. Two closed triangles are
    within ``eps`` of each other exactly when one of these six tests says so."""
    if face_b:
        hit, p, q = _edges_near_face(a0, a1, a2, b0, b1, b2, nb, eps)
        if hit:
            return True, p, q
    if face_a:
        return _edges_near_face(b0, b1, b2, a0, a1, a2, na, eps)
    return False, a0, a0


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
        v0, v1, v2, u0, u1, u2: vertices in one coordinate frame (any units), all ``wp.vec3`` (the
            test computes in float32) or all ``wp.vec3d`` (in float64).
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
def winding_number(mesh: MeshTopology, world_vertex: wp.array[Any], obj: int, num_triangles: int, p: Any):
    """Generalised winding number of point ``p`` w.r.t. object ``obj``'s closed mesh.

    Sum of the solid angles of its triangles seen from ``p`` over 4 pi (Van Oosterom and
    Strackee's formula): about 1 inside, 0 outside, with no special cases for rays through
    edges or vertices. O(m), in the precision of ``p`` and ``world_vertex``.
    """
    total = type(p[0])(0.0)
    for t in range(num_triangles):
        a, b, c = mesh_triangle(mesh, world_vertex, obj, t)
        a = a - p
        b = b - p
        c = c - p
        la = wp.length(a)
        lb = wp.length(b)
        lc = wp.length(c)
        num = wp.dot(a, wp.cross(b, c))
        den = la * lb * lc + wp.dot(a, b) * lc + wp.dot(a, c) * lb + wp.dot(b, c) * la
        total += type(p[0])(2.0) * wp.atan2(num, den)
    return total / type(p[0])(FOUR_PI)


@wp.func
def _point_in_box(p: wp.vec3, lo: wp.vec3, hi: wp.vec3) -> bool:
    """Point ``p`` lies in the closed box (a box of the broad phase: rounded outward, so a float64
    point rounded to float32 stays in it)."""
    return lo[0] <= p[0] and p[0] <= hi[0] and lo[1] <= p[1] and p[1] <= hi[1] and lo[2] <= p[2] and p[2] <= hi[2]


@wp.func
def _pair_triangles(mesh: MeshTopology, world_vertex: wp.array[Any], c: wp.vec4i):
    """World vertices of the two triangles of row ``c = (obj_a, tri_a, obj_b, tri_b)``."""
    a0, a1, a2 = mesh_triangle(mesh, world_vertex, c[0], c[1])
    b0, b1, b2 = mesh_triangle(mesh, world_vertex, c[2], c[3])
    return a0, a1, a2, b0, b1, b2


@wp.func
def _centred_row(mesh: MeshTopology, world_vertex: wp.array[Any], c: wp.vec4i, tol_rel: wp.float64):
    """The two triangles of row ``c`` centred on the pair's centroid, with their normals, the
    absolute tolerance ``eps`` and degeneracy flags (:func:`_centre_pair`), in the precision of
    ``world_vertex``."""
    v0, v1, v2, u0, u1, u2 = _pair_triangles(mesh, world_vertex, c)
    return _centre_pair(v0, v1, v2, u0, u1, u2, type(v0[0])(tol_rel))


@wp.func
def _append_hit(
    c: wp.vec4i,
    hit_capacity: int,
    hit: wp.array[wp.vec4i],
    hit_count: wp.array[wp.int64],
    object_colliding: wp.array[wp.int32],
):
    """Appends the triangle pair ``c`` to the hits (capacity + counter) and flags its two objects."""
    slot = reserve_slot(hit_count, hit_capacity)
    if slot >= 0:
        hit[slot] = c
    object_colliding[c[0]] = 1
    object_colliding[c[2]] = 1


@wp.kernel(cuda_max_registers=MAX_REGISTERS)
def _narrow_moller_kernel(
    mesh: MeshTopology,
    world_vertex: wp.array[Any],
    candidate: wp.array[wp.vec4i],
    candidate_count: wp.array[wp.int64],
    candidate_capacity: int,
    tol_rel: wp.float64,
    hit_capacity: int,
    touch_capacity: int,
    rare_capacity: int,
    # Outputs
    hit: wp.array[wp.vec4i],
    hit_count: wp.array[wp.int64],
    object_colliding: wp.array[wp.int32],
    touch: wp.array[wp.vec4i],
    touch_count: wp.array[wp.int64],
    touch_flag: wp.array[wp.int32],
    rare: wp.array[wp.vec4i],
    rare_count: wp.array[wp.int64],
):
    """One thread per candidate ``(obj_a, tri_a, obj_b, tri_b)``: steps 1 to 3 of Möller's test
    (:func:`_moller_steps`); a crossing is a hit, a pair that does not cross goes to the touch
    list (its flag cleared) for step 4 (:func:`_narrow_touch_kernel`), and a pair with a
    degenerate triangle, or coplanar, to the rare list (:func:`_narrow_rare_kernel`): their code
    stays out of this kernel, whose registers then hold the common path."""
    k = wp.tid()
    if k >= used_count(candidate_count, candidate_capacity):
        return
    c = candidate[k]
    v0, v1, v2, u0, u1, u2 = _pair_triangles(mesh, world_vertex, c)
    tol = type(v0[0])(tol_rel)
    na, degenerate_a = _unit_normal(v0, v1, v2, tol)
    nb, degenerate_b = _unit_normal(u0, u1, u2, tol)
    kind = CONTACT_NONE
    is_rare = degenerate_a or degenerate_b
    if not is_rare:
        a0, a1, a2, b0, b1, b2, eps = _centre(v0, v1, v2, u0, u1, u2, tol)
        kind, p, q = _moller_steps(a0, a1, a2, b0, b1, b2, na, nb, eps)
        is_rare = kind == CONTACT_COPLANAR_A or kind == CONTACT_COPLANAR_B
    if kind == CONTACT_TOUCH_TEST:
        slot = reserve_slot(touch_count, touch_capacity)
        if slot >= 0:
            touch[slot] = c
            touch_flag[slot] = 0
    elif is_rare:
        slot = reserve_slot(rare_count, rare_capacity)
        if slot >= 0:
            rare[slot] = c
    elif kind != CONTACT_NONE:
        _append_hit(c, hit_capacity, hit, hit_count, object_colliding)


@wp.kernel
def _narrow_rare_kernel(
    mesh: MeshTopology,
    world_vertex: wp.array[Any],
    rare: wp.array[wp.vec4i],
    rare_count: wp.array[wp.int64],
    rare_capacity: int,
    tol_rel: wp.float64,
    hit_capacity: int,
    # Outputs
    hit: wp.array[wp.vec4i],
    hit_count: wp.array[wp.int64],
    object_colliding: wp.array[wp.int32],
):
    """One thread per row of the rare list (a degenerate triangle, or coplanar triangles): the
    whole of Möller's test (:func:`tri_tri_moller`)."""
    k = wp.tid()
    if k >= used_count(rare_count, rare_capacity):
        return
    c = rare[k]
    v0, v1, v2, u0, u1, u2 = _pair_triangles(mesh, world_vertex, c)
    if tri_tri_moller(v0, v1, v2, u0, u1, u2, type(v0[0])(tol_rel)):
        _append_hit(c, hit_capacity, hit, hit_count, object_colliding)


@wp.kernel(cuda_max_registers=MAX_REGISTERS)
def _narrow_touch_kernel(
    mesh: MeshTopology,
    world_vertex: wp.array[Any],
    touch: wp.array[wp.vec4i],
    touch_count: wp.array[wp.int64],
    touch_capacity: int,
    tol_rel: wp.float64,
    hit_capacity: int,
    # Outputs
    touch_flag: wp.array[wp.int32],
    hit: wp.array[wp.vec4i],
    hit_count: wp.array[wp.int64],
    object_colliding: wp.array[wp.int32],
):
    """Step 4 of Möller's test, two threads per row ``u`` of the touch list: thread ``2 u`` tests
    the edges of triangle a against b's face, ``2 u + 1`` those of b against a's
    (:func:`_edges_near_face`; each thread computes the one normal and the edge normals of its
    face once). The pair touches when one of the six edge tests says so (:func:`_edges_meet`);
    the first thread to find it (its flag) appends the row."""
    t = wp.tid()
    u = t / 2
    side = t - 2 * u
    if u >= used_count(touch_count, touch_capacity):
        return
    c = touch[u]
    v0, v1, v2, u0, u1, u2 = _pair_triangles(mesh, world_vertex, c)
    tol = type(v0[0])(tol_rel)
    a0, a1, a2, b0, b1, b2, eps = _centre(v0, v1, v2, u0, u1, u2, tol)
    near = False
    if side == 0:  # only the face's normal (both triangles are not degenerate: step 1 to 3 decide those)
        nb, degenerate_b = _unit_normal(u0, u1, u2, tol)
        near, p, q = _edges_near_face(a0, a1, a2, b0, b1, b2, nb, eps)
    else:
        na, degenerate_a = _unit_normal(v0, v1, v2, tol)
        near, p, q = _edges_near_face(b0, b1, b2, a0, a1, a2, na, eps)
    if near and wp.atomic_add(touch_flag, u, 1) == 0:
        _append_hit(c, hit_capacity, hit, hit_count, object_colliding)


@wp.kernel
def _narrow_edge_face_kernel(
    mesh: MeshTopology,
    world_vertex: wp.array[Any],
    candidate: wp.array[wp.vec4i],
    candidate_count: wp.array[wp.int64],
    candidate_capacity: int,
    tol_rel: wp.float64,
    hit_capacity: int,
    # Outputs
    hit: wp.array[wp.vec4i],
    hit_count: wp.array[wp.int64],
    object_colliding: wp.array[wp.int32],
):
    """One thread per candidate ``(obj_a, tri_a, obj_b, tri_b)``: the edge-face test, append hits."""
    k = wp.tid()
    if k >= used_count(candidate_count, candidate_capacity):
        return
    c = candidate[k]
    a0, a1, a2, b0, b1, b2 = _pair_triangles(mesh, world_vertex, c)
    if tri_tri_edge_face(a0, a1, a2, b0, b1, b2, tol_rel):
        _append_hit(c, hit_capacity, hit, hit_count, object_colliding)


@wp.kernel
def _segment_kernel(
    mesh: MeshTopology,
    world_vertex: wp.array[Any],
    hit: wp.array[wp.vec4i],
    hit_count: wp.array[wp.int64],
    hit_capacity: int,
    tol_rel: wp.float64,
    # Outputs
    segment: wp.array2d[Any],
):
    """One thread per triangle pair found: its intersection segment (NaN for coplanar areas)."""
    k = wp.tid()
    if k >= used_count(hit_count, hit_capacity):
        return
    c = hit[k]
    a0, a1, a2, b0, b1, b2 = _pair_triangles(mesh, world_vertex, c)
    kind, p, q = tri_tri_segment(a0, a1, a2, b0, b1, b2, tol_rel)
    if kind != CONTACT_SEGMENT:
        nan = type(p[0])(wp.nan)
        p = type(p)(nan, nan, nan)
        q = p
    segment[k, 0] = p
    segment[k, 1] = q


@wp.kernel
def _containment_kernel(
    mesh: MeshTopology,
    world_vertex: wp.array[Any],
    object_lower: wp.array[wp.vec3],
    object_upper: wp.array[wp.vec3],
    pair: wp.array[wp.vec2i],
    pair_count: wp.array[wp.int64],
    pair_capacity: int,
    contained_capacity: int,
    # Outputs
    contained: wp.array[wp.vec2i],
    contained_count: wp.array[wp.int64],
):
    """One thread per object pair, each way round: is the inner object's first vertex inside the
    outer object's box (a box may be loose: a rigid object's comes from its tree) and then inside
    the outer object (winding number above 1/2)? Writes ``(inner, outer)``."""
    k = wp.tid()
    if k >= used_count(pair_count, pair_capacity):
        return
    p = pair[k]
    for side in range(2):
        inner = p[side]
        outer = p[1 - side]
        point = world_vertex[mesh.object_vertex_start[inner]]
        if _point_in_box(wp.vec3(point), object_lower[outer], object_upper[outer]):
            m = mesh.object_triangle_start[outer + 1] - mesh.object_triangle_start[outer]
            if winding_number(mesh, world_vertex, outer, m, point) > type(point[0])(0.5):
                slot = reserve_slot(contained_count, contained_capacity)
                if slot >= 0:
                    contained[slot] = wp.vec2i(inner, outer)


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
    v0, v1, v2, u0, u1, u2 = _pair_triangles(mesh, world_vertex, pair[k])
    depth[k] = wp.float64(crossing_depth(v0, v1, v2, u0, u1, u2, type(v0[0])(tol_rel)))


def pair_crossing_depth(scene, pairs: wp.array, tolerance: float = TOLERANCE, out: wp.array | None = None) -> wp.array:
    """:func:`crossing_depth` of triangle pairs of a scene, on its device.

    Args:
        scene: the :class:`~warp_ccd.scene.scene.Scene` (its world vertices as they are now).
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


# Both precisions, declared up front: the module compiles once, for float32 and float64 together.
# The kernels take the tolerance in float64 and round it to the vertices' precision.
_NARROW_MOLLER, _NARROW_TOUCH, _NARROW_RARE, _NARROW_EDGE_FACE, _CONTAINMENT = (
    precision_overloads(k, lambda s, v, q, t: {"world_vertex": wp.array[v]})
    for k in (_narrow_moller_kernel, _narrow_touch_kernel, _narrow_rare_kernel, _narrow_edge_face_kernel,
              _containment_kernel))
_CROSSING_DEPTH = precision_overloads(_crossing_depth_kernel, lambda s, v, q, t: {"world_vertex": wp.array[v]})
_SEGMENT = precision_overloads(_segment_kernel, lambda s, v, q, t: {"world_vertex": wp.array[v],
                                                                  "segment": wp.array2d[v]})
for _precision in PRECISIONS:
    _, _vec3, _, _ = precision_types(_precision)
    _triangles = wp.array2d[_vec3]
    wp.overload(tri_tri_batch_kernel, {"tri_a": _triangles, "tri_b": _triangles})
    wp.overload(tri_tri_segment_batch_kernel, {"tri_a": _triangles, "tri_b": _triangles, "segment": _triangles})


class NarrowPhase:
    """Exact tests of candidate triangle pairs; owns what it writes: the hit buffer, the
    per-object flags and, when asked for, the hits' segments and the containment pairs.

    Args:
        num_objects: ``N`` (size of :attr:`object_colliding`).
        method: ``"moller"`` (default) or ``"edge_face"``.
        tolerance: relative tolerance of the test.
        capacity: initial capacity of the hit buffer (it grows).
        segments: also compute each hit's intersection segment (:attr:`segment`).
        containment: also find objects wholly inside another (:attr:`contained`), from the
            object pairs where one holds the other's first vertex in its box.
        device: Warp device.

    Attributes:
        hits: :class:`~warp_ccd.stages.buffers.GrowableBuffer` of ``wp.vec4i`` rows
            ``(obj_a, tri_a, obj_b, tri_b)``.
        touch: with ``method="moller"``, the :class:`~warp_ccd.stages.buffers.GrowableBuffer` of the
            candidates that do not cross and may touch (step 4, tested two threads a row by a
            second kernel; else None), with ``touch_flag``, ``(touch.capacity,)`` int32.
        rare: with ``method="moller"``, the :class:`~warp_ccd.stages.buffers.GrowableBuffer` of the
            candidates with a degenerate triangle or coplanar triangles (tested whole by a third
            kernel; else None).
        object_colliding: ``(N,)`` int32, 1 for an object with a hit.
        segment: ``(hits.capacity, 2)`` end points (the scene's vector type) of each hit's
            segment (NaN for coplanar contacts), or None without ``segments``.
        contained: :class:`~warp_ccd.stages.buffers.GrowableBuffer` of ``wp.vec2i`` rows
            ``(inner, outer)``, or None without ``containment``.
    """

    def __init__(self, num_objects: int, *, method: str = "moller", tolerance: float = TOLERANCE,
                 capacity: int = 1024, segments: bool = False, containment: bool = False, device=None):
        if method not in NARROW_METHODS:
            raise ValueError(f"narrow_phase must be one of {sorted(NARROW_METHODS)}, got {method!r}")
        if not 0.0 <= tolerance < 0.1:
            raise ValueError(f"tolerance must lie in [0, 0.1), got {tolerance!r}")
        self.device = wp.get_device(device)
        self.method = method
        self.tolerance = float(tolerance)
        self.hits = GrowableBuffer(wp.vec4i, capacity, self.device, "triangle pairs")
        self.touch = (GrowableBuffer(wp.vec4i, capacity, self.device, "candidates that may touch")
                      if method == "moller" else None)
        self.rare = (GrowableBuffer(wp.vec4i, 64, self.device, "candidates degenerate or coplanar")
                     if method == "moller" else None)
        self.touch_flag = None
        self.object_colliding = wp.zeros(num_objects, dtype=wp.int32, device=self.device)
        self.segments = bool(segments)
        self.segment = None
        self.contained = (GrowableBuffer(wp.vec2i, max(16, num_objects // 8), self.device, "contained pairs")
                          if containment else None)

    @property
    def counters(self) -> list[GrowableBuffer]:
        """The buffers with counters that :meth:`launch` resets and writes; the caller reads
        their counters after it."""
        return [b for b in (self.hits, self.touch, self.rare, self.contained) if b is not None]

    def launch(self, scene, candidates: GrowableBuffer, object_pairs: GrowableBuffer | None = None,
               object_lower: wp.array | None = None, object_upper: wp.array | None = None, *,
               reset_counters: bool = True) -> None:
        """Tests the candidates of ``scene``: resets and writes the hits and the flags, and the
        segments and the containment pairs when asked for (host reads nothing).

        Args:
            scene: the :class:`~warp_ccd.scene.scene.Scene` (its world vertices now).
            candidates: ``wp.vec4i`` candidate triangle pairs.
            object_pairs, object_lower, object_upper: the broad phase's object pairs and the
                ``(N,)`` object boxes it saw (needed with ``containment``).
            reset_counters: zero the counters of :attr:`counters` first; False when the caller
                has zeroed them already (a frame zeroes all its counters with one memset).
        """
        if self.contained is not None and (object_pairs is None or object_lower is None or object_upper is None):
            raise ValueError("containment: launch needs the object pairs and the object boxes")
        d = self.device
        if reset_counters:
            for buffer in self.counters:
                buffer.reset()
        self.object_colliding.zero_()
        tol = wp.float64(self.tolerance)
        hits = self.hits
        if self.touch is None:
            wp.launch(_NARROW_EDGE_FACE[scene.precision], dim=candidates.capacity,
                      inputs=[scene.topology, scene.world_vertex, candidates.data, candidates.count,
                              candidates.capacity, tol, hits.capacity],
                      outputs=[hits.data, hits.count, self.object_colliding], device=d)
        else:
            touch = self.touch
            if self.touch_flag is None or self.touch_flag.shape[0] != touch.capacity:  # follows the capacity
                self.touch_flag = wp.zeros(touch.capacity, dtype=wp.int32, device=d)
            rare = self.rare
            wp.launch(_NARROW_MOLLER[scene.precision], dim=candidates.capacity,
                      inputs=[scene.topology, scene.world_vertex, candidates.data, candidates.count,
                              candidates.capacity, tol, hits.capacity, touch.capacity, rare.capacity],
                      outputs=[hits.data, hits.count, self.object_colliding, touch.data, touch.count,
                               self.touch_flag, rare.data, rare.count], device=d)
            wp.launch(_NARROW_RARE[scene.precision], dim=rare.capacity,
                      inputs=[scene.topology, scene.world_vertex, rare.data, rare.count, rare.capacity, tol,
                              hits.capacity],
                      outputs=[hits.data, hits.count, self.object_colliding], device=d)
            wp.launch(_NARROW_TOUCH[scene.precision], dim=2 * touch.capacity,
                      inputs=[scene.topology, scene.world_vertex, touch.data, touch.count, touch.capacity, tol,
                              hits.capacity],
                      outputs=[self.touch_flag, hits.data, hits.count, self.object_colliding], device=d)
        if self.segments:
            if self.segment is None or self.segment.shape[0] != hits.capacity or self.segment.dtype != scene.vec3_type:
                self.segment = wp.zeros((hits.capacity, 2), dtype=scene.vec3_type, device=d)
            wp.launch(_SEGMENT[scene.precision], dim=hits.capacity,
                      inputs=[scene.topology, scene.world_vertex, hits.data, hits.count, hits.capacity, tol],
                      outputs=[self.segment], device=d)
        if self.contained is not None:
            wp.launch(
                _CONTAINMENT[scene.precision],
                dim=object_pairs.capacity,
                inputs=[scene.topology, scene.world_vertex, object_lower, object_upper, object_pairs.data,
                        object_pairs.count, object_pairs.capacity, self.contained.capacity],
                outputs=[self.contained.data, self.contained.count],
                device=d,
            )
