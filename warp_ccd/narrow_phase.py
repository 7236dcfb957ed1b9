"""Narrow phase: exact triangle-triangle tests, and the batched kernel over candidate pairs.

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
     from snapped distances need not lie on one line; projecting them on one direction reported
     pairs thousands of tolerances apart).
  Coplanar triangles (all of one triangle's vertices within ``eps`` of the other's plane) go to a
  2D test in that plane: an edge of one within ``eps`` of an edge of the other, or a vertex of one
  inside the other (as the vertices are flattened onto the plane first, such pairs count as
  touching up to ``sqrt(2) eps`` apart).
* :func:`tri_tri_edge_face`, the seed's edge-vs-face test: an edge of either triangle within
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
"""


from types import SimpleNamespace

import warp as wp

from .buffers import GrowableBuffer, reserve_slot, used_count
from .scene import SCENE_TYPES

# Forward kernels only; no FMA contraction, so that CPU and CUDA round every step alike.
wp.set_module_options({"enable_backward": False, "fuse_fp": False})

__all__ = [
    "NARROW_METHODS",
    "NARROW_TYPES",
    "NarrowPhase",
    "TOLERANCE",
    "narrow_phase_kernel",
    "tri_tri_edge_face",
    "tri_tri_moller",
    "tri_tri_segment",
]

TOLERANCE = 1.0e-5
"""Default relative tolerance of the triangle tests (about 80 float32 units in the last place)."""

NARROW_METHODS = {"moller": 0, "edge_face": 1}


def _make_narrow(types):
    """The triangle tests and their kernels for vertices of the scene type ``types.vec3``."""
    S = types.scalar
    V3 = types.vec3
    V2 = wp.vec2d if S == wp.float64 else wp.vec2
    View = types.MeshView
    mesh_triangle = types.mesh_triangle

    @wp.func
    def _snap(d: S, eps: S) -> S:
        if wp.abs(d) <= eps:
            return S(0.0)
        return d


    @wp.func
    def _one_side(d0: S, d1: S, d2: S) -> bool:
        """All three distances strictly positive, or all strictly negative."""
        return (d0 > S(0.0) and d1 > S(0.0) and d2 > S(0.0)) or (d0 < S(0.0) and d1 < S(0.0) and d2 < S(0.0))


    @wp.func
    def _max_edge(a: V3, b: V3, c: V3) -> S:
        return wp.max(wp.max(wp.length(b - a), wp.length(c - b)), wp.length(a - c))


    @wp.func
    def _cross2(a: V2, b: V2) -> S:
        return a[0] * b[1] - a[1] * b[0]


    @wp.func
    def _point_segment_dist(p: V2, a: V2, b: V2) -> S:
        ab = b - a
        den = wp.dot(ab, ab)
        t = S(0.0)
        if den > S(0.0):
            t = wp.clamp(wp.dot(p - a, ab) / den, S(0.0), S(1.0))
        return wp.length(p - (a + ab * t))


    @wp.func
    def _segments_within_2d(p: V2, q: V2, r: V2, s: V2, eps: S) -> bool:
        """Closed segments ``pq`` and ``rs`` in a plane are within ``eps`` of each other."""
        o1 = _cross2(q - p, r - p)
        o2 = _cross2(q - p, s - p)
        o3 = _cross2(s - r, p - r)
        o4 = _cross2(s - r, q - r)
        if o1 * o2 < S(0.0) and o3 * o4 < S(0.0):
            return True
        d = wp.min(
            wp.min(_point_segment_dist(p, r, s), _point_segment_dist(q, r, s)),
            wp.min(_point_segment_dist(r, p, q), _point_segment_dist(s, p, q)),
        )
        return d <= eps


    @wp.func
    def _inside_edge_2d(p: V2, a: V2, b: V2, orient: S) -> bool:
        """``p`` on the inner side of edge ``ab`` (or on its line) of a triangle of orientation ``orient``."""
        return orient * _cross2(b - a, p - a) >= S(0.0)


    @wp.func
    def _point_in_triangle_2d(p: V2, a: V2, b: V2, c: V2) -> bool:
        """``p`` inside the closed (non-degenerate) triangle ``abc``; near its boundary rounding
        decides, so callers test the boundary within their tolerance apart."""
        orient = wp.sign(_cross2(b - a, c - a))
        return (
            _inside_edge_2d(p, a, b, orient)
            and _inside_edge_2d(p, b, c, orient)
            and _inside_edge_2d(p, c, a, orient)
        )


    @wp.func
    def _to_plane(p: V3, e1: V3, e2: V3) -> V2:
        return V2(wp.dot(p, e1), wp.dot(p, e2))


    @wp.func
    def _coplanar_overlap(
        a0: V3, a1: V3, a2: V3, b0: V3, b1: V3, b2: V3, n: V3, eps: S
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
    def _push(p: V3, q: V3, count: int, x: V3):
        if count == 0:
            return x, x, 1
        return p, x, count + 1


    @wp.func
    def _plane_section(a: V3, b: V3, c: V3, da: S, db: S, dc: S):
        """Segment ``(p, q)`` where triangle ``abc`` meets a plane, from its snapped signed distances
        (not all zero, not all of one strict sign). Returns ``(p, q)`` (``p == q`` for a point)."""
        p = a
        q = a
        count = int(0)
        if da == S(0.0):
            p, q, count = _push(p, q, count, a)
        if db == S(0.0):
            p, q, count = _push(p, q, count, b)
        if dc == S(0.0):
            p, q, count = _push(p, q, count, c)
        if da * db < S(0.0):
            p, q, count = _push(p, q, count, a + (b - a) * (da / (da - db)))
        if db * dc < S(0.0):
            p, q, count = _push(p, q, count, b + (c - b) * (db / (db - dc)))
        if dc * da < S(0.0):
            p, q, count = _push(p, q, count, c + (a - c) * (dc / (dc - da)))
        return p, q


    @wp.func
    def _common_part(pa: V3, qa: V3, pb: V3, qb: V3):
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
        if ld == S(0.0):  # two points
            mid = (pa + pb) * S(0.5)
            return mid, mid
        u = d / ld
        ta0 = wp.dot(pa - origin, u)
        ta1 = wp.dot(qa - origin, u)
        tb0 = wp.dot(pb - origin, u)
        tb1 = wp.dot(qb - origin, u)
        lo = wp.max(wp.min(ta0, ta1), wp.min(tb0, tb1))
        hi = wp.min(wp.max(ta0, ta1), wp.max(tb0, tb1))
        if lo > hi:  # touching within the tolerance: one point between the two ends
            lo = (lo + hi) * S(0.5)
            hi = lo
        return origin + u * lo, origin + u * hi



    @wp.func
    def _unit_normal(x0: V3, x1: V3, x2: V3, tol_rel: S):
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
            return V3(S(0.0), S(0.0), S(0.0)), True
        return V3(n / ln), False

    @wp.func
    def _centre_pair(v0: V3, v1: V3, v2: V3, u0: V3, u1: V3, u2: V3, tol_rel: S):
        """Shared set-up of both tests: vertices relative to the pair's centroid, unit normals
        ``na``, ``nb`` (:func:`_unit_normal`), the tolerance ``eps``, and whether each triangle is
        degenerate (then its normal is zero and unused)."""
        o = (v0 + v1 + v2 + u0 + u1 + u2) / S(6.0)
        a0 = v0 - o
        a1 = v1 - o
        a2 = v2 - o
        b0 = u0 - o
        b1 = u1 - o
        b2 = u2 - o
        eps = tol_rel * wp.max(_max_edge(a0, a1, a2), _max_edge(b0, b1, b2))
        na, degenerate_a = _unit_normal(v0, v1, v2, tol_rel)
        nb, degenerate_b = _unit_normal(u0, u1, u2, tol_rel)
        return a0, a1, a2, b0, b1, b2, na, nb, eps, degenerate_a, degenerate_b

    @wp.func
    def _pick(x0: V3, x1: V3, x2: V3, i: int) -> V3:
        """``x0``, ``x1`` or ``x2`` for ``i`` 0, 1 or 2."""
        if i == 0:
            return x0
        if i == 1:
            return x1
        return x2

    @wp.func
    def _edge(a: V3, b: V3, c: V3, i: int):
        """Edge ``i`` of triangle ``abc``: ``(a, b)``, ``(b, c)`` or ``(c, a)``."""
        return _pick(a, b, c, i), _pick(b, c, a, i)

    @wp.func
    def _span(a: V3, b: V3, c: V3):
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
    def _closest_segment_points(p1: V3, q1: V3, p2: V3, q2: V3):
        """Closest points ``(c1, c2)`` of the closed segments ``p1 q1`` and ``p2 q2`` (either may be a
        point; Ericson, Real-Time Collision Detection, 5.1.9)."""
        d1 = q1 - p1
        d2 = q2 - p2
        r = p1 - p2
        a = wp.dot(d1, d1)
        e = wp.dot(d2, d2)
        f = wp.dot(d2, r)
        s = S(0.0)
        t = S(0.0)
        if a > S(0.0) and e > S(0.0):
            b = wp.dot(d1, d2)
            c = wp.dot(d1, r)
            denom = a * e - b * b
            if denom > S(0.0):
                s = wp.clamp((b * f - c * e) / denom, S(0.0), S(1.0))
            t = (b * s + f) / e
            if t < S(0.0):
                t = S(0.0)
                s = wp.clamp(-c / a, S(0.0), S(1.0))
            elif t > S(1.0):
                t = S(1.0)
                s = wp.clamp((b - c) / a, S(0.0), S(1.0))
        elif a > S(0.0):
            s = wp.clamp(-wp.dot(d1, r) / a, S(0.0), S(1.0))
        elif e > S(0.0):
            t = wp.clamp(f / e, S(0.0), S(1.0))
        return p1 + d1 * s, p2 + d2 * t

    @wp.func
    def _segments_within(p1: V3, q1: V3, p2: V3, q2: V3, eps: S) -> bool:
        """Closed segments (or points) in space within ``eps`` of each other."""
        c1, c2 = _closest_segment_points(p1, q1, p2, q2)
        return wp.length(c1 - c2) <= eps

    @wp.func
    def _plane_distances(n: V3, origin: V3, x0: V3, x1: V3, x2: V3, eps: S):
        """Signed distances of ``x0, x1, x2`` to the plane through ``origin`` of unit normal ``n``:
        exact, then snapped to zero within ``eps``."""
        r0 = wp.dot(n, x0 - origin)
        r1 = wp.dot(n, x1 - origin)
        r2 = wp.dot(n, x2 - origin)
        return r0, r1, r2, _snap(r0, eps), _snap(r1, eps), _snap(r2, eps)

    @wp.func
    def _clip(f0: S, f1: S, lo: S, hi: S):
        """Narrows ``[lo, hi]`` to the ``t`` where ``f0 + t (f1 - f0) >= 0``; empty when ``lo > hi``."""
        if f0 < S(0.0) and f1 < S(0.0):
            return S(1.0), S(0.0)
        if f0 < S(0.0):
            return wp.max(lo, f0 / (f0 - f1)), hi
        if f1 < S(0.0):
            return lo, wp.min(hi, f0 / (f0 - f1))
        return lo, hi

    @wp.func
    def _edge_normals(a: V3, b: V3, c: V3, n: V3):
        """Unit normals of the edges ``ab``, ``bc``, ``ca`` in the plane of triangle ``abc`` (unit
        normal ``n``), pointing into the triangle."""
        return (
            wp.normalize(wp.cross(n, b - a)),
            wp.normalize(wp.cross(n, c - b)),
            wp.normalize(wp.cross(n, a - c)),
        )

    @wp.func
    def _segment_triangle_section(
        p: V3, q: V3, a: V3, b: V3, c: V3, n: V3, m0: V3, m1: V3, m2: V3, eps: S
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
        lo, hi = _clip(eps - rp, eps - rq, S(0.0), S(1.0))
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
        if rp * rq < S(0.0):
            x = p + d * wp.clamp(rp / (rp - rq), wide_lo, wide_hi)
            return True, x, x
        return True, p + d * wide_lo, p + d * wide_hi

    @wp.func
    def _edges_near_face(x0: V3, x1: V3, x2: V3, f0: V3, f1: V3, f2: V3, nf: V3, eps: S):
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
        a0: V3, a1: V3, a2: V3, b0: V3, b1: V3, b2: V3, na: V3, nb: V3, eps: S, face_a: bool, face_b: bool
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
        a0: V3, a1: V3, a2: V3, b0: V3, b1: V3, b2: V3, na: V3, nb: V3, eps: S, degenerate_a: bool,
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
            mid = (c1 + c2) * S(0.5)
            return True, mid, mid
        if degenerate_a:
            m0, m1, m2 = _edge_normals(b0, b1, b2, nb)
            return _segment_triangle_section(pa, qa, b0, b1, b2, nb, m0, m1, m2, eps)
        m0, m1, m2 = _edge_normals(a0, a1, a2, na)
        return _segment_triangle_section(pb, qb, a0, a1, a2, na, m0, m1, m2, eps)

    @wp.func
    def tri_tri_segment(v0: V3, v1: V3, v2: V3, u0: V3, u1: V3, u2: V3, tol_rel: S):
        """Möller's test, and where the triangles meet: ``(kind, p, q)``.

        Args:
            v0, v1, v2, u0, u1, u2: vertices in one coordinate frame (any units).
            tol_rel: tolerance relative to the longest edge (see the module docstring).

        Returns:
            ``kind`` 0: apart; 1: they cross or touch along the segment ``pq`` (a point when
            ``p == q``), in the input frame; 2: coplanar contact (an area, no segment; ``p``, ``q``
            are the pair's centroid). A degenerate triangle is tested as the segment or point it
            is (see the module docstring): its contacts are kind 1.
        """
        o = (v0 + v1 + v2 + u0 + u1 + u2) / S(6.0)
        a0, a1, a2, b0, b1, b2, na, nb, eps, degenerate_a, degenerate_b = _centre_pair(
            v0, v1, v2, u0, u1, u2, tol_rel
        )
        if degenerate_a or degenerate_b:
            hit, p, q = _degenerate_section(a0, a1, a2, b0, b1, b2, na, nb, eps, degenerate_a, degenerate_b)
            return wp.where(hit, 1, 0), p + o, q + o
        # 1. Triangle b against the plane of a, then a against the plane of b.
        rb0, rb1, rb2, db0, db1, db2 = _plane_distances(na, a0, b0, b1, b2, eps)
        if _one_side(db0, db1, db2):
            return 0, o, o
        ra0, ra1, ra2, da0, da1, da2 = _plane_distances(nb, b0, a0, a1, a2, eps)
        if _one_side(da0, da1, da2):
            return 0, o, o
        coplanar = int(-1)
        if db0 == S(0.0) and db1 == S(0.0) and db2 == S(0.0):
            coplanar = wp.where(_coplanar_overlap(a0, a1, a2, b0, b1, b2, na, eps), 2, 0)
        elif da0 == S(0.0) and da1 == S(0.0) and da2 == S(0.0):
            coplanar = wp.where(_coplanar_overlap(b0, b1, b2, a0, a1, a2, nb, eps), 2, 0)
        if coplanar >= 0:
            return coplanar, o, o
        # 2. Where each triangle crosses the other's plane (a section of each, from the exact
        # distances, when both truly straddle the other's plane), and 3. whether the two sections,
        # on the common line, meet: the triangles cross.
        if not _one_side(ra0, ra1, ra2) and not _one_side(rb0, rb1, rb2):
            pa, qa = _plane_section(a0, a1, a2, ra0, ra1, ra2)
            pb, qb = _plane_section(b0, b1, b2, rb0, rb1, rb2)
            if _segments_within(pa, qa, pb, qb, eps):
                p, q = _common_part(pa, qa, pb, qb)
                return 1, p + o, q + o
        # 4. No crossing: touching within the tolerance, decided by distance (an edge of one within
        # eps of the other). Sections from snapped distances cannot decide it: with nearly
        # parallel planes the part of a triangle within eps of the other's plane is a wide strip,
        # not a segment, and two such "sections" need not lie on one line.
        hit, p, q = _edges_meet(a0, a1, a2, b0, b1, b2, na, nb, eps, True, True)
        if hit:
            return 1, p + o, q + o
        return 0, o, o

    @wp.func
    def tri_tri_moller(
        v0: V3, v1: V3, v2: V3, u0: V3, u1: V3, u2: V3, tol_rel: S
    ) -> bool:
        """Möller's test: do the closed triangles ``(v0, v1, v2)`` and ``(u0, u1, u2)`` intersect?

        Args:
            v0, v1, v2, u0, u1, u2: vertices in one coordinate frame (any units).
            tol_rel: tolerance relative to the longest edge (see the module docstring).

        Returns:
            True when they intersect or touch within the tolerance (a degenerate triangle as the
            segment or point it is).
        """
        kind, p, q = tri_tri_segment(v0, v1, v2, u0, u1, u2, tol_rel)
        return kind != 0

    @wp.func
    def tri_tri_edge_face(
        v0: V3, v1: V3, v2: V3, u0: V3, u1: V3, u2: V3, tol_rel: S
    ) -> bool:
        """Edge-vs-face test (the seed's cross-check): some edge of either triangle meets the other.

        Same arguments, tolerance and semantics as :func:`tri_tri_moller`.
        """
        a0, a1, a2, b0, b1, b2, na, nb, eps, degenerate_a, degenerate_b = _centre_pair(
            v0, v1, v2, u0, u1, u2, tol_rel
        )
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
    def tri_tri_test(
        method: int, v0: V3, v1: V3, v2: V3, u0: V3, u1: V3, u2: V3, tol_rel: S
    ) -> bool:
        """``method`` 0: :func:`tri_tri_moller`; 1: :func:`tri_tri_edge_face`."""
        if method == 0:
            return tri_tri_moller(v0, v1, v2, u0, u1, u2, tol_rel)
        return tri_tri_edge_face(v0, v1, v2, u0, u1, u2, tol_rel)


    @wp.kernel
    def narrow_phase_kernel(
        view: View,
        candidate: wp.array[wp.vec4i],
        candidate_count: wp.array[wp.int64],
        candidate_capacity: int,
        method: int,
        tol_rel: S,
        hit_capacity: int,
        # Outputs
        hit: wp.array[wp.vec4i],
        hit_count: wp.array[wp.int64],
        object_colliding: wp.array[wp.int32],
    ):
        """One thread per candidate ``(obj_a, tri_a, obj_b, tri_b)``: exact test, append hits."""
        k = wp.tid()
        if k >= used_count(candidate_count, candidate_capacity):
            return
        c = candidate[k]
        a0, a1, a2 = mesh_triangle(view, c[0], c[1])
        b0, b1, b2 = mesh_triangle(view, c[2], c[3])
        if tri_tri_test(method, a0, a1, a2, b0, b1, b2, tol_rel):
            slot = reserve_slot(hit_count, hit_capacity)
            if slot >= 0:
                hit[slot] = c
            object_colliding[c[0]] = 1
            object_colliding[c[2]] = 1


    @wp.kernel
    def tri_tri_batch_kernel(
        tri_a: wp.array2d[V3],
        tri_b: wp.array2d[V3],
        method: int,
        tol_rel: S,
        # Outputs
        result: wp.array[wp.int32],
    ):
        """One thread per pair of triangles given directly as ``(P, 3)`` vertex arrays (tests, tools)."""
        k = wp.tid()
        r = tri_tri_test(method, tri_a[k, 0], tri_a[k, 1], tri_a[k, 2], tri_b[k, 0], tri_b[k, 1], tri_b[k, 2], tol_rel)
        result[k] = wp.where(r, 1, 0)


    @wp.kernel
    def tri_tri_segment_batch_kernel(
        tri_a: wp.array2d[V3],
        tri_b: wp.array2d[V3],
        tol_rel: S,
        # Outputs
        kind: wp.array[wp.int32],
        segment: wp.array2d[V3],
    ):
        """One thread per pair of triangles given as ``(P, 3)`` vertex arrays: :func:`tri_tri_segment`'s
        ``kind`` and segment ``(P, 2)`` (tests, tools)."""
        k = wp.tid()
        c, p, q = tri_tri_segment(tri_a[k, 0], tri_a[k, 1], tri_a[k, 2], tri_b[k, 0], tri_b[k, 1], tri_b[k, 2], tol_rel)
        kind[k] = c
        segment[k, 0] = p
        segment[k, 1] = q

    @wp.kernel
    def segment_kernel(
        view: View,
        hit: wp.array[wp.vec4i],
        hit_count: wp.array[wp.int64],
        hit_capacity: int,
        tol_rel: S,
        # Outputs
        segment: wp.array2d[V3],
    ):
        """One thread per triangle pair found: its intersection segment (NaN for coplanar areas)."""
        k = wp.tid()
        if k >= used_count(hit_count, hit_capacity):
            return
        c = hit[k]
        a0, a1, a2 = mesh_triangle(view, c[0], c[1])
        b0, b1, b2 = mesh_triangle(view, c[2], c[3])
        kind, p, q = tri_tri_segment(a0, a1, a2, b0, b1, b2, tol_rel)
        if kind != 1:
            nan = S(wp.nan)
            p = V3(nan, nan, nan)
            q = p
        segment[k, 0] = p
        segment[k, 1] = q

    @wp.func
    def winding_number(view: View, instance: int, num_triangles: int, p: V3) -> S:
        """Generalised winding number of point ``p`` w.r.t. object ``instance``'s closed mesh.

        Sum of the solid angles of its triangles seen from ``p`` over 4 pi (Van Oosterom and
        Strackee's formula): about 1 inside, 0 outside, with no special cases for rays through
        edges or vertices. O(m).
        """
        total = S(0.0)
        for t in range(num_triangles):
            a, b, c = mesh_triangle(view, instance, t)
            a = a - p
            b = b - p
            c = c - p
            la = wp.length(a)
            lb = wp.length(b)
            lc = wp.length(c)
            num = wp.dot(a, wp.cross(b, c))
            den = la * lb * lc + wp.dot(a, b) * lc + wp.dot(a, c) * lb + wp.dot(b, c) * la
            total += S(2.0) * wp.atan2(num, den)
        return total / S(12.566370614359172)


    @wp.func
    def _box_inside(lo_a: wp.vec3, hi_a: wp.vec3, lo_b: wp.vec3, hi_b: wp.vec3) -> bool:
        """Box a lies within box b."""
        return (
            lo_b[0] <= lo_a[0] and hi_a[0] <= hi_b[0]
            and lo_b[1] <= lo_a[1] and hi_a[1] <= hi_b[1]
            and lo_b[2] <= lo_a[2] and hi_a[2] <= hi_b[2]
        )


    @wp.kernel
    def containment_kernel(
        view: View,
        instance_triangle_start: wp.array[wp.int32],
        instance_lower: wp.array[wp.vec3],
        instance_upper: wp.array[wp.vec3],
        pair: wp.array[wp.vec2i],
        pair_count: wp.array[wp.int64],
        pair_capacity: int,
        contained_capacity: int,
        # Outputs
        contained: wp.array[wp.vec2i],
        contained_count: wp.array[wp.int64],
    ):
        """One thread per object pair whose boxes nest: is the inner object's first vertex inside
        the outer object (winding number above 1/2)? Writes ``(inner, outer)``."""
        k = wp.tid()
        if k >= used_count(pair_count, pair_capacity):
            return
        p = pair[k]
        for side in range(2):
            inner = p[side]
            outer = p[1 - side]
            if _box_inside(instance_lower[inner], instance_upper[inner], instance_lower[outer], instance_upper[outer]):
                point = view.world_vertex[view.instance_vertex_start[inner]]
                m = instance_triangle_start[outer + 1] - instance_triangle_start[outer]
                if winding_number(view, outer, m, point) > S(0.5):
                    slot = reserve_slot(contained_count, contained_capacity)
                    if slot >= 0:
                        contained[slot] = wp.vec2i(inner, outer)

    return SimpleNamespace(
        tri_tri_moller=tri_tri_moller,
        tri_tri_edge_face=tri_tri_edge_face,
        tri_tri_test=tri_tri_test,
        tri_tri_segment=tri_tri_segment,
        winding_number=winding_number,
        narrow_phase_kernel=narrow_phase_kernel,
        tri_tri_batch_kernel=tri_tri_batch_kernel,
        tri_tri_segment_batch_kernel=tri_tri_segment_batch_kernel,
        segment_kernel=segment_kernel,
        containment_kernel=containment_kernel,
    )


NARROW_TYPES = {p: _make_narrow(SCENE_TYPES[p]) for p in SCENE_TYPES}
"""Per scene precision: the tests (``tri_tri_moller`` ...) and kernels, computing in float32 or float64."""

tri_tri_moller = NARROW_TYPES["float32"].tri_tri_moller
tri_tri_edge_face = NARROW_TYPES["float32"].tri_tri_edge_face
tri_tri_test = NARROW_TYPES["float32"].tri_tri_test
tri_tri_batch_kernel = NARROW_TYPES["float32"].tri_tri_batch_kernel
narrow_phase_kernel = NARROW_TYPES["float32"].narrow_phase_kernel
containment_kernel = NARROW_TYPES["float32"].containment_kernel
tri_tri_segment = NARROW_TYPES["float32"].tri_tri_segment


class NarrowPhase:
    """Exact tests of candidate triangle pairs; owns the hit buffer and the per-object flags.

    Args:
        num_objects: ``N`` (size of :attr:`object_colliding`).
        method: ``"moller"`` (default) or ``"edge_face"``.
        tolerance: relative tolerance of the test.
        capacity: initial capacity of the hit buffer (it grows).
        device: Warp device.
    """

    def __init__(self, num_objects: int, *, method: str = "moller", tolerance: float = TOLERANCE,
                 capacity: int = 1024, device=None):
        if method not in NARROW_METHODS:
            raise ValueError(f"narrow_phase must be one of {sorted(NARROW_METHODS)}, got {method!r}")
        if not 0.0 <= tolerance < 0.1:
            raise ValueError(f"tolerance must lie in [0, 0.1), got {tolerance!r}")
        self.device = wp.get_device(device)
        self.method = method
        self.tolerance = float(tolerance)
        self.hits = GrowableBuffer(wp.vec4i, capacity, self.device, "triangle pairs")
        self.object_colliding = wp.zeros(num_objects, dtype=wp.int32, device=self.device)

    def launch(self, scene, candidates: GrowableBuffer) -> None:
        """Tests the candidates of ``scene``; appends hits ``(obj_a, tri_a, obj_b, tri_b)``, sets flags."""
        self.hits.reset()
        self.object_colliding.zero_()
        wp.launch(
            NARROW_TYPES[scene.precision].narrow_phase_kernel,
            dim=candidates.capacity,
            inputs=[scene.mesh_view(), candidates.data, candidates.count, candidates.capacity,
                    NARROW_METHODS[self.method], scene.types.scalar(self.tolerance), self.hits.capacity],
            outputs=[self.hits.data, self.hits.count, self.object_colliding],
            device=self.device,
        )
