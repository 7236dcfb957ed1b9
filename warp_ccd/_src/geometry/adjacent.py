"""Two triangles of one mesh: do they meet other than through the vertices they share?

A mesh intersects itself where two of its triangles meet *other than through the vertices they share*
(:func:`tri_tri_self`). Which vertices two triangles share is said by vertex ids (a mesh's indices,
after welding coincident vertices: :func:`~warp_ccd._src.narrowphase.self_intersection.weld_vertices`), not by
positions, so a triangle's neighbours never touch it merely by being its neighbours:

* **No shared vertex**: as between two objects, :func:`~warp_ccd._src.geometry.triangle.tri_tri_moller`
  (touching within the tolerance counts).
* **One shared vertex** ``p``, triangles ``p a b`` and ``p c d``: they meet elsewhere exactly when the
  edge opposite ``p`` of one meets the other (segment ``ab`` meets ``pcd`` or ``cd`` meets ``pab``).
  Their common part lies on a line through ``p`` (or, coplanar, in two wedges at ``p``); its far end is
  on the opposite edge of the triangle it leaves first, which then lies in the other.
* **A shared edge** ``pq``, triangles ``p q r`` and ``p q s``: they meet beyond the edge exactly when
  they are folded flat onto each other, coplanar with ``r`` and ``s`` on the same side of ``pq``;
  then ``r`` lies in ``pqs``, ``s`` in ``pqr``, or edge ``pr`` crosses ``qs`` or ``qr`` crosses ``ps``
  (the corner of the overlap farthest from ``pq``). Those four tests decide it: none of them involves a
  point of the shared edge, so none fires merely because the triangles are neighbours.
* **Three shared vertices**: one face twice: they meet.

Each test is within ``eps`` (:mod:`warp_ccd._src.geometry.triangle`'s tolerance: ``tol_rel`` times the longest
edge of the two, vertices centred on the pair), so touching counts as between objects. A degenerate
triangle is the segment it spans (as there): with one shared vertex, the halves of its span from the
vertex (the span may run through it: a sliver whose middle vertex is shared) are tested, each's far end
against the other's face and the half across the other's opposite edge (and that edge against the span),
or, when both are degenerate, each half along the other's; with a shared edge, a degenerate triangle lies
along the edge's line, which the other meets only in the edge: no intersection, unless both are
degenerate and reach beyond the same end of the edge. (A shared edge shorter than the tolerance is
outside these rules: a triangle on it is degenerate whatever its direction, and is taken to lie along
it.) A triangle with a repeated vertex id (a segment or a point by construction) that shares a vertex
with the other is taken to meet it only where both have the same three ids.

Vertex ids come from the mesh as stored; a deforming object's are welded from its shape's vertices
(the rest pose): copies of a vertex that come apart later are still one vertex.

Every verdict is made of the building blocks of :mod:`warp_ccd._src.geometry.primitives` (add, multiply,
divide, square root), so every device gives the same one when the calling module is compiled without
floating-point contraction (``fuse_fp=False``).
"""

from typing import Any

import warp as wp

from .primitives import _clip, _edge, _segments_within, _span
from .triangle import _centre_pair, tri_tri_moller

__all__ = ["shared_vertices", "tri_tri_self"]


@wp.func
def _has(ids: wp.vec3i, x: int) -> int:
    """1 when ``x`` is one of ``ids``, else 0."""
    return wp.where(ids[0] == x or ids[1] == x or ids[2] == x, 1, 0)


@wp.func
def shared_vertices(ia: wp.vec3i, ib: wp.vec3i) -> int:
    """How many of triangle ``a``'s vertex ids ``ia`` are among ``ib``'s (0 to 3)."""
    return _has(ib, ia[0]) + _has(ib, ia[1]) + _has(ib, ia[2])


@wp.func
def _rotate(x0: Any, x1: Any, x2: Any, k: int):
    """The triangle's vertices starting from vertex ``k`` (same orientation)."""
    if k == 1:
        return x1, x2, x0
    if k == 2:
        return x2, x0, x1
    return x0, x1, x2


@wp.func
def _segment_meets(p: Any, q: Any, a0: Any, a1: Any, a2: Any, na: Any, degenerate: bool, eps: Any) -> bool:
    """Segment ``pq`` within ``eps`` of triangle ``a`` (unit normal ``na``), or of the segment it
    spans when it is ``degenerate``."""
    if degenerate:
        s0, s1 = _span(a0, a1, a2)
        return _segments_within(p, q, s0, s1, eps)
    # The verdict of _segment_triangle_section (same arithmetic, step by step), each edge normal made
    # only when its clip is reached: most neighbours are turned away by the plane or the first edges.
    zero = type(eps)(0.0)
    rp = wp.dot(na, p - a0)
    rq = wp.dot(na, q - a0)
    lo, hi = _clip(eps - rp, eps - rq, zero, type(eps)(1.0))
    lo, hi = _clip(eps + rp, eps + rq, lo, hi)
    if lo > hi:
        return False
    wide_lo = lo
    wide_hi = hi
    for i in range(3):
        u, v = _edge(a0, a1, a2, i)
        m = wp.normalize(wp.cross(na, v - u))  # _edge_normals' i-th
        fp = wp.dot(m, p - u)
        fq = wp.dot(m, q - u)
        lo, hi = _clip(fp, fq, lo, hi)
        wide_lo, wide_hi = _clip(fp + eps, fq + eps, wide_lo, wide_hi)
        if wide_lo > wide_hi:
            return False
    if lo > hi:
        return _segments_within(p, q, a0, a1, eps) or _segments_within(p, q, a1, a2, eps) or _segments_within(
            p, q, a2, a0, eps)
    return True


@wp.func
def _beyond_both(p: Any, q: Any, r: Any, s: Any, eps: Any) -> bool:
    """Two degenerate triangles ``p q r`` and ``p q s`` along the line ``pq``: whether both reach
    beyond the same end of the edge ``pq`` (by more than ``eps``), where they overlap beyond it."""
    e = q - p
    le = wp.length(e)
    zero = type(eps)(0.0)
    if le <= eps:
        return False
    tr = wp.dot(r - p, e) / le
    ts = wp.dot(s - p, e) / le
    return (tr > le + eps and ts > le + eps) or (tr < zero - eps and ts < zero - eps)


@wp.func
def _halves_meet(p: Any, e: Any, q: Any, f: Any, eps: Any) -> bool:
    """Two segments ``pe`` and ``qf`` from one vertex (``p`` and ``q`` its two copies): whether they
    meet beyond it, one running along the other (an end within ``eps`` of the other segment). A
    segment that is the vertex alone (``e`` at ``p``) meets nothing beyond it."""
    zero = type(eps)(0.0)
    if wp.length_sq(e - p) == zero or wp.length_sq(f - q) == zero:
        return False
    return _segments_within(e, e, q, f, eps) or _segments_within(f, f, p, e, eps)


@wp.func
def _segment_and_face(p: Any, d0: Any, d1: Any, d2: Any, q: Any, y1: Any, y2: Any, f0: Any, f1: Any, f2: Any,
                      nf: Any, eps: Any) -> bool:
    """A degenerate triangle ``d`` (the segment it spans) and a triangle ``f = (q, y1, y2)`` sharing the
    vertex ``p`` (``q`` in ``f``): whether they meet beyond it. ``f``'s edge opposite the vertex against
    the span; then each half of the span from the vertex: its far end within ``eps`` of ``f``, or the half
    across ``f``'s opposite edge (a segment from a vertex of ``f`` that goes into ``f`` leaves it there or
    ends inside). The span may run through the vertex (a sliver whose middle vertex is shared): its
    halves, not the span, are tested, so the vertex itself is never found."""
    s0, s1 = _span(d0, d1, d2)
    if _segments_within(y1, y2, s0, s1, eps):
        return True
    zero = type(eps)(0.0)
    for i in range(2):
        e = s0
        if i == 1:
            e = s1
        if wp.length_sq(e - p) > zero:
            if _segment_meets(e, e, f0, f1, f2, nf, False, eps) or _segments_within(p, e, y1, y2, eps):
                return True
    return False


@wp.func
def tri_tri_self(v0: Any, v1: Any, v2: Any, u0: Any, u1: Any, u2: Any, ia: wp.vec3i, ib: wp.vec3i,
                 tol_rel: Any) -> bool:
    """Whether two triangles of one mesh meet other than through the vertices they share (module docs).

    Args:
        v0, v1, v2, u0, u1, u2: vertices in one frame, all ``wp.vec3`` or all ``wp.vec3d`` (the test
            computes in their precision).
        ia, ib: the triangles' vertex ids (welded: equal ids for one vertex); vertex ``k`` of ``a`` is
            ``v_k`` with id ``ia[k]``.
        tol_rel: tolerance relative to the longest edge (:func:`~warp_ccd._src.geometry.triangle.tri_tri_moller`'s).

    Returns:
        True when they meet (within the tolerance) beyond what they share.
    """
    tol = type(v0[0])(tol_rel)
    k = shared_vertices(ia, ib)
    if k == 0:
        return tri_tri_moller(v0, v1, v2, u0, u1, u2, tol)
    same_a = ia[0] == ia[1] or ia[1] == ia[2] or ia[0] == ia[2]
    same_b = ib[0] == ib[1] or ib[1] == ib[2] or ib[0] == ib[2]
    if same_a or same_b:  # a segment or a point by construction, sharing a vertex
        return k == 3 and shared_vertices(ib, ia) == 3
    if k == 3:
        return True  # one face twice
    a0, a1, a2, b0, b1, b2, na, nb, eps, degenerate_a, degenerate_b = _centre_pair(v0, v1, v2, u0, u1, u2, tol)
    if k == 1:
        # The shared vertex first in each: a = (p, a1, a2), b = (p, b1, b2).
        ka = wp.where(_has(ib, ia[0]) == 1, 0, wp.where(_has(ib, ia[1]) == 1, 1, 2))
        kb = wp.where(_has(ia, ib[0]) == 1, 0, wp.where(_has(ia, ib[1]) == 1, 1, 2))
        p, x1, x2 = _rotate(a0, a1, a2, ka)
        q, y1, y2 = _rotate(b0, b1, b2, kb)
        if not degenerate_a and not degenerate_b:
            if _segment_meets(x1, x2, b0, b1, b2, nb, False, eps):
                return True
            return _segment_meets(y1, y2, a0, a1, a2, na, False, eps)
        if degenerate_a and degenerate_b:  # two segments through the vertex: one along the other
            s0, s1 = _span(a0, a1, a2)
            t0, t1 = _span(b0, b1, b2)
            return (_halves_meet(p, s0, q, t0, eps) or _halves_meet(p, s0, q, t1, eps)
                    or _halves_meet(p, s1, q, t0, eps) or _halves_meet(p, s1, q, t1, eps))
        if degenerate_a:
            return _segment_and_face(p, a0, a1, a2, q, y1, y2, b0, b1, b2, nb, eps)
        return _segment_and_face(q, b0, b1, b2, p, x1, x2, a0, a1, a2, na, eps)
    # k == 2: a = (p, q, r) with r its vertex not in b; b's vertex not in a is s.
    ka = wp.where(_has(ib, ia[0]) == 0, 0, wp.where(_has(ib, ia[1]) == 0, 1, 2))
    kb = wp.where(_has(ia, ib[0]) == 0, 0, wp.where(_has(ia, ib[1]) == 0, 1, 2))
    r, p, q = _rotate(a0, a1, a2, ka)
    s, _y1, _y2 = _rotate(b0, b1, b2, kb)
    if degenerate_a or degenerate_b:
        if degenerate_a and degenerate_b:
            return _beyond_both(p, q, r, s, eps)
        return False
    if _segment_meets(r, r, b0, b1, b2, nb, False, eps) or _segment_meets(s, s, a0, a1, a2, na, False, eps):
        return True
    return _segments_within(p, r, q, s, eps) or _segments_within(q, r, p, s, eps)
