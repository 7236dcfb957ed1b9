"""The exact intersection of two closed triangles, in rational arithmetic: an oracle of the
self-intersection rules that shares none of them.

:func:`triangle_intersection` returns the intersection of two non-degenerate closed triangles as the
corners of a convex set (empty, a point, a segment or a polygon): where the planes cross, the common
part of the two triangles' sections of the other's plane along the planes' line; where the triangles are
coplanar, one clipped by the other's closed half-planes (Sutherland-Hodgman, in the plane's projection
onto the axis plane its normal is least parallel to); :func:`intersection` takes a degenerate triangle
(three collinear points) as the segment it spans. :func:`meets_beyond` says whether that set holds a
point other than the given shared vertices (for a shared edge: a point off the edge): a convex set lies
in a point or a segment exactly when its corners do. No tolerance: on small integer coordinates every
gap is far wider than the library's tolerance, so its verdicts must equal these.
"""

from __future__ import annotations

from fractions import Fraction


def _sub(a, b):
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


def _dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def _cross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def _lerp(a, b, t):
    return tuple(x + (y - x) * t for x, y in zip(a, b))


def _section(tri, n, origin):
    """Points of the closed triangle on the plane through ``origin`` of normal ``n``: its vertices on
    it and its edges' crossings."""
    d = [_dot(n, _sub(v, origin)) for v in tri]
    out = [v for v, x in zip(tri, d) if x == 0]
    for i in range(3):
        j = (i + 1) % 3
        if d[i] * d[j] < 0:
            out.append(_lerp(tri[i], tri[j], d[i] / (d[i] - d[j])))
    return out


def _clip(poly, a, b, inside):
    """Sutherland-Hodgman: the part of polygon ``poly`` (2D points) on the closed side of line ``ab``
    where ``inside`` (the sign of a point strictly inside) holds."""
    def side(p):
        return ((b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0])) * inside

    out = []
    for i, p in enumerate(poly):
        q = poly[(i + 1) % len(poly)]
        sp, sq = side(p), side(q)
        if sp >= 0:
            out.append(p)
        if sp * sq < 0:
            out.append(_lerp(p, q, sp / (sp - sq)))
    return out


def triangle_intersection(ta, tb) -> list:
    """Corners (3D rational points) of the intersection of two non-degenerate closed triangles (any
    numbers, rationals included)."""
    a = [tuple(Fraction(x) for x in v) for v in ta]
    b = [tuple(Fraction(x) for x in v) for v in tb]
    na = _cross(_sub(a[1], a[0]), _sub(a[2], a[0]))
    nb = _cross(_sub(b[1], b[0]), _sub(b[2], b[0]))
    line = _cross(na, nb)
    if line != (0, 0, 0):
        pa, pb = _section(a, nb, b[0]), _section(b, na, a[0])
        if not pa or not pb:
            return []
        ta_, tb_ = [_dot(line, p) for p in pa], [_dot(line, p) for p in pb]
        lo, hi = max(min(ta_), min(tb_)), min(max(ta_), max(tb_))
        if lo > hi:
            return []
        pts = pa + pb
        ts = ta_ + tb_
        return [pts[ts.index(lo)], pts[ts.index(hi)]]
    if _dot(na, _sub(b[0], a[0])) != 0:
        return []  # parallel planes apart
    drop = max(range(3), key=lambda k: abs(na[k]))
    keep = [k for k in range(3) if k != drop]
    two = {}
    poly = []
    for v in a:
        p = (v[keep[0]], v[keep[1]])
        two[p] = v
        poly.append(p)
    b2 = [(v[keep[0]], v[keep[1]]) for v in b]
    inside = 1 if ((b2[1][0] - b2[0][0]) * (b2[2][1] - b2[0][1]) - (b2[1][1] - b2[0][1]) * (b2[2][0] - b2[0][0])) > 0 \
        else -1
    for i in range(3):
        poly = _clip(poly, b2[i], b2[(i + 1) % 3], inside)
        if not poly:
            return []
    # Back to 3D on a's plane: the dropped coordinate from the plane's equation.
    out = []
    for p in poly:
        x = [Fraction(0)] * 3
        x[keep[0]], x[keep[1]] = p
        rest = na[keep[0]] * (x[keep[0]] - a[0][keep[0]]) + na[keep[1]] * (x[keep[1]] - a[0][keep[1]])
        x[drop] = a[0][drop] - rest / na[drop]
        out.append(tuple(x))
    return out


def _span(t):
    """The farthest two of three collinear points: the segment a degenerate triangle is."""
    pairs = [(t[0], t[1]), (t[1], t[2]), (t[0], t[2])]
    return max(pairs, key=lambda e: _dot(_sub(e[1], e[0]), _sub(e[1], e[0])))


def _segment_parts(seg, other) -> list:
    """Corners of the intersection of a segment with a closed triangle or segment ``other`` (3 or 2 points)."""
    p, q = seg
    d = _sub(q, p)
    if len(other) == 3:
        a, b, c = other
        n = _cross(_sub(b, a), _sub(c, a))
        dp, dq = _dot(n, _sub(p, a)), _dot(n, _sub(q, a))
        if dp != 0 or dq != 0:
            if dp * dq > 0 or dp == dq:
                return []
            x = _lerp(p, q, dp / (dp - dq))
            inside = all(_dot(_cross(_sub(v, u), _sub(x, u)), n) >= 0 for u, v in ((a, b), (b, c), (c, a)))
            return [x] if inside else []
        lo, hi = Fraction(0), Fraction(1)  # coplanar: clip p + t d by the three closed half-planes
        for u, v in ((a, b), (b, c), (c, a)):
            m = _cross(n, _sub(v, u))  # inward
            f0, f1 = _dot(m, _sub(p, u)), _dot(m, _sub(q, u))
            if f0 < 0 and f1 < 0:
                return []
            if f0 < 0:
                lo = max(lo, f0 / (f0 - f1))
            elif f1 < 0:
                hi = min(hi, f0 / (f0 - f1))
        return [] if lo > hi else [_lerp(p, q, lo), _lerp(p, q, hi)]
    u, v = other
    e = _sub(v, u)
    if _cross(d, e) == (0, 0, 0):
        if _cross(d, _sub(u, p)) != (0, 0, 0):
            return []  # parallel lines apart
        dd = _dot(d, d)
        t = sorted([_dot(_sub(u, p), d) / dd, _dot(_sub(v, p), d) / dd])
        lo, hi = max(Fraction(0), t[0]), min(Fraction(1), t[1])
        return [] if lo > hi else [_lerp(p, q, lo), _lerp(p, q, hi)]
    n = _cross(d, e)
    if _dot(n, _sub(u, p)) != 0:
        return []  # skew
    s = _dot(_cross(_sub(u, p), e), n) / _dot(n, n)
    t = _dot(_cross(_sub(u, p), d), n) / _dot(n, n)
    return [_lerp(p, q, s)] if 0 <= s <= 1 and 0 <= t <= 1 else []


def intersection(ta, tb) -> list:
    """Corners of the intersection of two closed triangles, degenerate ones (three collinear points)
    taken as the segments they span."""
    a = [tuple(Fraction(x) for x in v) for v in ta]
    b = [tuple(Fraction(x) for x in v) for v in tb]
    deg_a = _cross(_sub(a[1], a[0]), _sub(a[2], a[0])) == (0, 0, 0)
    deg_b = _cross(_sub(b[1], b[0]), _sub(b[2], b[0])) == (0, 0, 0)
    if not deg_a and not deg_b:
        return triangle_intersection(a, b)
    if deg_a:
        return _segment_parts(_span(a), _span(b) if deg_b else b)
    return _segment_parts(_span(b), a)


def meets_beyond(ta, tb, shared: list) -> bool:
    """Whether two closed triangles (degenerate ones: their spans) meet other than in ``shared``: no
    point (none shared), one vertex, or two (then the segment between them)."""
    corners = intersection(ta, tb)
    if not corners:
        return False
    s = [tuple(Fraction(x) for x in v) for v in shared]
    if not s:
        return True
    if len(s) == 1:
        return any(c != s[0] for c in corners)
    p, q = s[0], s[1]
    e = _sub(q, p)
    for c in corners:
        r = _sub(c, p)
        if _cross(e, r) != (0, 0, 0) or not 0 <= _dot(e, r) <= _dot(e, e):
            return True
    return False
