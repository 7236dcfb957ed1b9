"""Building blocks of the exact triangle tests (:mod:`~warp_ccd._src.geometry.triangle`), inside kernels.

Points, segments, planes and triangles within a tolerance ``eps`` (scene units): signed distances
to a plane snapped to zero within ``eps`` (:func:`_plane_distances`), where a triangle meets a
plane (:func:`_plane_section`), the closest points of two closed segments
(:func:`_closest_segment_points`, Ericson 5.1.9), a segment against a closed triangle thickened by
``eps`` (:func:`_segment_triangle_section`), the edges of one triangle against the other's face
(:func:`_edges_meet`), the overlap of coplanar triangles in their plane (:func:`_coplanar_overlap`),
a triangle's unit normal and whether it is degenerate (:func:`_unit_normal`), and the point of a
triangle closest to a point (:func:`_closest_on_triangle`, Ericson 5.1.5).

Warp generics: ``Any``-typed ``wp.vec3`` or ``wp.vec3d`` arguments, computed in their precision,
literals as ``type(x)(0.5)`` (:func:`_closest_on_triangle` takes ``wp.vec3d`` only). A function is
compiled into the module of the kernel that calls it, with that module's options (see
:mod:`~warp_ccd._src.geometry.triangle` on ``fuse_fp``). The names carry an underscore: they serve this
package's geometry and stage modules; the device functions for a user's kernels are those of
:mod:`warp_ccd.geometry`.
"""


from typing import Any

import warp as wp

# No kernels here (a kernel compiles these functions with its own module's options); as every module
# that calls them: forward only, no FMA contraction.
wp.set_module_options({"enable_backward": False, "fuse_fp": False})


@wp.func
def _max_abs(v: wp.vec3d) -> wp.float64:
    """The largest absolute coordinate of ``v`` (its infinity norm)."""
    return wp.max(wp.max(wp.abs(v[0]), wp.abs(v[1])), wp.abs(v[2]))


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
def _closest_on_triangle(p: wp.vec3d, a: wp.vec3d, b: wp.vec3d, c: wp.vec3d):
    """Closest point of triangle ``abc`` to ``p`` and its feature: 0 the face, 1-3 vertex 0-2,
    4-6 edge 0-2 (edge ``k`` joins vertices ``k`` and ``k + 1``). Ericson, Real-Time Collision
    Detection, 5.1.5."""
    zero = wp.float64(0.0)
    ab = b - a
    ac = c - a
    ap = p - a
    d1 = wp.dot(ab, ap)
    d2 = wp.dot(ac, ap)
    if d1 <= zero and d2 <= zero:
        return a, 1
    bp = p - b
    d3 = wp.dot(ab, bp)
    d4 = wp.dot(ac, bp)
    if d3 >= zero and d4 <= d3:
        return b, 2
    vc = d1 * d4 - d3 * d2
    if vc <= zero and d1 >= zero and d3 <= zero:
        return a + ab * (d1 / (d1 - d3)), 4
    cp = p - c
    d5 = wp.dot(ab, cp)
    d6 = wp.dot(ac, cp)
    if d6 >= zero and d5 <= d6:
        return c, 3
    vb = d5 * d2 - d1 * d6
    if vb <= zero and d2 >= zero and d6 <= zero:
        return a + ac * (d2 / (d2 - d6)), 6
    va = d3 * d6 - d5 * d4
    if va <= zero and (d4 - d3) >= zero and (d5 - d6) >= zero:
        return b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6))), 5
    denom = wp.float64(1.0) / (va + vb + vc)
    return a + ab * (vb * denom) + ac * (vc * denom), 0
