"""Brute-force self-intersection of one mesh, exactly: every pair of triangles in rational arithmetic.

The oracle of :func:`warp_ccd.self_intersections` and the pipeline's ``self_pairs``. Two triangles of a
mesh meet other than through their shared vertices (ids after welding coincident positions) when:

* they share none: their exact distance (the least over each edge of one against the other triangle,
  0 where an edge crosses it) is within ``eps = tol * L`` (``L`` the longest edge of the two);
* they share one vertex ``p``: the edge opposite ``p`` of one is within ``eps`` of the other triangle;
  a degenerate one is the segment it spans, whose halves from ``p`` are tested (a far end within ``eps``
  of the other triangle, or the half within ``eps`` of its edge opposite ``p``; two degenerate ones: an
  end within ``eps`` of the other's half), and the other's opposite edge against its span;
* they share an edge ``pq`` (thirds ``r``, ``s``): ``r`` within ``eps`` of ``pqs``, ``s`` of ``pqr``, or
  segment ``pr`` of ``qs``, or ``qr`` of ``ps``; a degenerate triangle (twice its area at most
  ``tol * L^2``) meets the other only where both are degenerate and reach beyond one end of the edge;
* they share three: always.

:func:`pair_meets` decides a pair in exact rational arithmetic (``fractions.Fraction``).
:func:`reference_self_pairs` decides all pairs of a mesh with the same distances in float64, vectorised
over the pairs (numpy), and hands to :func:`pair_meets` the few whose float64 distance lies within a
relative 1e-9 of ``eps`` or that hold a degenerate triangle, so that no rounding decides a verdict.
"""

from __future__ import annotations

from fractions import Fraction

import numpy as np

from distance_reference import _add, _cross, _dot, _mul, _sub, point_segment_sq, point_triangle_sq, segment_segment_sq


def _seg_tri_sq(p, q, a, b, c):
    """Exact squared distance of the closed segment ``pq`` to the closed triangle ``abc`` (its edges
    when it has no area)."""
    n = _cross(_sub(b, a), _sub(c, a))
    if _dot(n, n):
        dp = _dot(_sub(p, a), n)
        dq = _dot(_sub(q, a), n)
        if (dp <= 0 <= dq or dq <= 0 <= dp) and dp != dq:
            x = _add(p, _mul(_sub(q, p), dp / (dp - dq)))  # where pq crosses the plane
            if (_dot(_cross(_sub(b, a), _sub(x, a)), n) >= 0 and _dot(_cross(_sub(c, b), _sub(x, b)), n) >= 0
                    and _dot(_cross(_sub(a, c), _sub(x, c)), n) >= 0):
                return Fraction(0)
    best = min(point_triangle_sq(p, a, b, c), point_triangle_sq(q, a, b, c))
    for u, v in ((a, b), (b, c), (c, a)):
        best = min(best, segment_segment_sq(p, q, u, v))
    return best


def _tri_tri_sq(a, b):
    """Exact squared distance of two closed triangles (0 when they meet)."""
    best = None
    for x, y in ((a, b), (b, a)):
        for i in range(3):
            d = _seg_tri_sq(x[i], x[(i + 1) % 3], *y)
            best = d if best is None else min(best, d)
            if best == 0:
                return best
    return best


def _longest_sq(t):
    return max(_dot(_sub(t[1], t[0]), _sub(t[1], t[0])), _dot(_sub(t[2], t[1]), _sub(t[2], t[1])),
               _dot(_sub(t[0], t[2]), _sub(t[0], t[2])))


def _degenerate(t, tol):
    n = _cross(_sub(t[1], t[0]), _sub(t[2], t[0]))
    return _dot(n, n) <= (Fraction(tol) * _longest_sq(t)) ** 2


def _span(t):
    pairs = [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])]
    return max(pairs, key=lambda e: _dot(_sub(e[1], e[0]), _sub(e[1], e[0])))


def pair_meets(ta, tb, ia, ib, tol: float) -> bool:
    """Whether triangles ``ta``, ``tb`` (``(3, 3)`` floats) with welded vertex ids ``ia``, ``ib`` meet
    other than through what they share (module docs)."""
    a = [tuple(Fraction(float(c)) for c in v) for v in np.asarray(ta, np.float64)]
    b = [tuple(Fraction(float(c)) for c in v) for v in np.asarray(tb, np.float64)]
    ia, ib = [int(x) for x in ia], [int(x) for x in ib]
    length = float(np.sqrt(float(max(_longest_sq(a), _longest_sq(b)))))
    eps_sq = Fraction(tol * length) ** 2
    shared = [x for x in ia if x in ib]
    k = len(shared)
    if k == 0:
        return _tri_tri_sq(a, b) <= eps_sq
    if len(set(ia)) < 3 or len(set(ib)) < 3:
        return k == 3 and all(x in ia for x in ib)
    if k == 3:
        return True
    deg_a, deg_b = _degenerate(a, tol), _degenerate(b, tol)
    if k == 1:
        pa = ia.index(shared[0])
        pb = ib.index(shared[0])
        p = a[pa]
        opp_a = (a[(pa + 1) % 3], a[(pa + 2) % 3])
        opp_b = (b[(pb + 1) % 3], b[(pb + 2) % 3])
        if not deg_a and not deg_b:
            return min(_seg_tri_sq(*opp_a, *b), _seg_tri_sq(*opp_b, *a)) <= eps_sq
        # A degenerate triangle: the halves of its span from the shared vertex (never the vertex itself).
        halves_a = [e for e in _span(a) if e != p]
        halves_b = [e for e in _span(b) if e != p]
        if deg_a and deg_b:
            return any(point_segment_sq(e, p, f) <= eps_sq or point_segment_sq(f, p, e) <= eps_sq
                       for e in halves_a for f in halves_b)
        d, t, opp_t, halves = (a, b, opp_b, halves_a) if deg_a else (b, a, opp_a, halves_b)
        if segment_segment_sq(*opp_t, *_span(d)) <= eps_sq:
            return True
        return any(point_triangle_sq(e, *t) <= eps_sq or segment_segment_sq(p, e, *opp_t) <= eps_sq for e in halves)
    r_i = next(i for i in range(3) if ia[i] not in ib)
    s_i = next(i for i in range(3) if ib[i] not in ia)
    r, p, q = a[r_i], a[(r_i + 1) % 3], a[(r_i + 2) % 3]
    s = b[s_i]
    if deg_a or deg_b:
        if not (deg_a and deg_b):
            return False
        e = _sub(q, p)
        le = Fraction(float(np.sqrt(float(_dot(e, e)))))
        eps = Fraction(tol * length)
        if le <= eps:
            return False
        tr, ts = _dot(_sub(r, p), e) / le, _dot(_sub(s, p), e) / le
        return (tr > le + eps and ts > le + eps) or (tr < -eps and ts < -eps)
    return min(point_triangle_sq(r, *b), point_triangle_sq(s, *a), segment_segment_sq(p, r, q, s),
               segment_segment_sq(q, r, p, s)) <= eps_sq


# Float64, vectorised over pairs: arrays (P, 3) of points.

def _dot64(a, b):
    return np.einsum("ij,ij->i", a, b)


def _point_segment64(x, p, q):
    d = q - p
    den = _dot64(d, d)
    t = np.clip(np.where(den > 0, _dot64(x - p, d) / np.where(den > 0, den, 1.0), 0.0), 0.0, 1.0)
    r = x - (p + d * t[:, None])
    return _dot64(r, r)


def _segment_segment64(p1, q1, p2, q2):
    best = np.minimum.reduce([_point_segment64(p1, p2, q2), _point_segment64(q1, p2, q2),
                              _point_segment64(p2, p1, q1), _point_segment64(q2, p1, q1)])
    d1, d2, r = q1 - p1, q2 - p2, p1 - p2
    a, e, b = _dot64(d1, d1), _dot64(d2, d2), _dot64(d1, d2)
    c, f = _dot64(d1, r), _dot64(d2, r)
    den = a * e - b * b
    ok = den > 0
    safe = np.where(ok, den, 1.0)
    s = (b * f - c * e) / safe
    t = (a * f - b * c) / safe
    inside = ok & (s >= 0) & (s <= 1) & (t >= 0) & (t <= 1)
    g = (p1 + d1 * s[:, None]) - (p2 + d2 * t[:, None])
    return np.where(inside, np.minimum(best, _dot64(g, g)), best)


def _point_triangle64(x, a, b, c):
    n = np.cross(b - a, c - a)
    nn = _dot64(n, n)
    edges = np.minimum.reduce([_point_segment64(x, a, b), _point_segment64(x, b, c), _point_segment64(x, c, a)])
    h = _dot64(x - a, n)
    y = x - n * (h / np.where(nn > 0, nn, 1.0))[:, None]
    inside = ((nn > 0) & (_dot64(np.cross(b - a, y - a), n) >= 0) & (_dot64(np.cross(c - b, y - b), n) >= 0)
              & (_dot64(np.cross(a - c, y - c), n) >= 0))
    return np.where(inside, h * h / np.where(nn > 0, nn, 1.0), edges)


def _segment_triangle64(p, q, a, b, c):
    n = np.cross(b - a, c - a)
    dp, dq = _dot64(p - a, n), _dot64(q - a, n)
    cross = (np.sign(dp) * np.sign(dq) <= 0) & (dp != dq)
    x = p + (q - p) * (dp / np.where(dp != dq, dp - dq, 1.0))[:, None]
    inside = (cross & (_dot64(np.cross(b - a, x - a), n) >= 0) & (_dot64(np.cross(c - b, x - b), n) >= 0)
              & (_dot64(np.cross(a - c, x - c), n) >= 0))
    best = np.minimum(_point_triangle64(p, a, b, c), _point_triangle64(q, a, b, c))
    for u, v in ((a, b), (b, c), (c, a)):
        best = np.minimum(best, _segment_segment64(p, q, u, v))
    return np.where(inside, 0.0, best)


def _decisive64(ta, tb, ia, ib):
    """Per pair of triangles ``(P, 3, 3)`` with ids ``(P, 3)``: the squared float64 distance that
    :func:`pair_meets` compares with ``eps^2`` (NaN where it is not one number: a pair it decides itself)."""
    shared = (ia[:, :, None] == ib[:, None, :]).any(axis=2)  # (P, 3): a's vertex among b's
    k = shared.sum(axis=1)
    out = np.full(len(ta), np.nan)
    zero = k == 0
    if zero.any():
        a, b = ta[zero], tb[zero]
        d = [_segment_triangle64(x[:, i], x[:, (i + 1) % 3], *(y[:, j] for j in range(3)))
             for x, y in ((a, b), (b, a)) for i in range(3)]
        out[zero] = np.minimum.reduce(d)
    one = k == 1
    if one.any():
        a, b, sa, sb = ta[one], tb[one], shared[one], (ib[one][:, :, None] == ia[one][:, None, :]).any(axis=2)
        pa, pb = sa.argmax(axis=1), sb.argmax(axis=1)
        rows = np.arange(len(a))
        opp_a = [a[rows, (pa + 1) % 3], a[rows, (pa + 2) % 3]]
        opp_b = [b[rows, (pb + 1) % 3], b[rows, (pb + 2) % 3]]
        out[one] = np.minimum(_segment_triangle64(*opp_a, b[:, 0], b[:, 1], b[:, 2]),
                              _segment_triangle64(*opp_b, a[:, 0], a[:, 1], a[:, 2]))
    two = k == 2
    if two.any():
        a, b, sa, sb = ta[two], tb[two], shared[two], (ib[two][:, :, None] == ia[two][:, None, :]).any(axis=2)
        ra, sbi = (~sa).argmax(axis=1), (~sb).argmax(axis=1)
        rows = np.arange(len(a))
        r, p, q = a[rows, ra], a[rows, (ra + 1) % 3], a[rows, (ra + 2) % 3]
        s = b[rows, sbi]
        out[two] = np.minimum.reduce([_point_triangle64(r, b[:, 0], b[:, 1], b[:, 2]),
                                      _point_triangle64(s, a[:, 0], a[:, 1], a[:, 2]),
                                      _segment_segment64(p, r, q, s), _segment_segment64(q, r, p, s)])
    return out


def reference_self_pairs(vertices, triangles, weld, tol: float, chunk: int = 200_000) -> np.ndarray:
    """``(M, 2)`` int32 sorted rows ``(i, j)``, ``i < j``, of every pair of ``triangles`` that meets
    (:func:`pair_meets`; module docs), over all pairs whose float64 boxes padded by twice the largest
    ``eps`` overlap (the others are farther apart than ``eps``)."""
    v = np.asarray(vertices, np.float64)
    t = np.asarray(triangles, np.int64)
    w = np.asarray(weld, np.int64)[t]
    tv = v[t]  # (m, 3, 3)
    lo, hi = tv.min(axis=1), tv.max(axis=1)
    edges = np.linalg.norm(tv - np.roll(tv, 1, axis=1), axis=2).max(axis=1)
    area2 = np.linalg.norm(np.cross(tv[:, 1] - tv[:, 0], tv[:, 2] - tv[:, 0]), axis=1)
    odd = (area2 <= 2.0 * tol * edges**2) | (w[:, 0] == w[:, 1]) | (w[:, 1] == w[:, 2]) | (w[:, 0] == w[:, 2])
    pad = 2.0 * tol * edges.max(initial=0.0) + 1e-300
    order = np.argsort(lo[:, 0])  # pairs whose x extents overlap, by a sweep over sorted lower ends
    end = np.searchsorted(lo[order, 0], hi[order, 0] + pad, side="right")
    counts = end - np.arange(len(t)) - 1
    i = np.repeat(order, np.maximum(counts, 0))
    j = order[np.concatenate([np.arange(s + 1, e) for s, e in enumerate(end)] or [np.zeros(0, np.int64)])]
    near = np.all((lo[i] <= hi[j] + pad) & (lo[j] <= hi[i] + pad), axis=1)
    i, j = np.minimum(i[near], j[near]), np.maximum(i[near], j[near])
    rows = []
    for c in range(0, len(i), chunk):
        a, b = i[c : c + chunk], j[c : c + chunk]
        d = _decisive64(tv[a], tv[b], w[a], w[b])
        eps = tol * np.maximum(edges[a], edges[b])
        close = np.abs(np.sqrt(np.where(np.isnan(d), 0.0, d)) - eps) <= 1e-9 * np.maximum(edges[a], edges[b])
        exact = np.isnan(d) | close | odd[a] | odd[b]
        rows.append(np.stack([a, b], axis=1)[~exact & (d <= eps * eps)])
        rows += [np.array([[x, y]]) for x, y in zip(a[exact], b[exact])
                 if pair_meets(tv[x], tv[y], w[x], w[y], tol)]
    out = np.concatenate(rows).astype(np.int32).reshape(-1, 2) if rows else np.zeros((0, 2), np.int32)
    return out[np.lexsort((out[:, 1], out[:, 0]))]
