"""Exact distances between closed triangles, in rational arithmetic (``fractions.Fraction``).

The squared distance of two closed segments, of a point and a closed triangle, and so of two closed
triangles that do not intersect, is a rational function of the coordinates: the least of a quadratic
over a polytope is at a vertex, at a clamped one-dimensional minimiser on an edge, or at the interior
critical point, all rational. This module enumerates those candidates exactly, with no rounding, so
that it serves as the oracle of :func:`warp_ccd.geometry.tri_tri_distance` in float64 and float32.

* :func:`segment_segment_sq`: the four end-against-segment minimisers and, when the segments are not
  parallel, the interior critical point of the two parameters if it lies in the unit square.
* :func:`point_triangle_sq`: the projection onto the plane when it falls inside (barycentric signs),
  else the three edges.
* :func:`triangle_triangle_sq`: the least over the six vertex-face pairs (faces of non-degenerate
  triangles: a triangle of zero area is the union of its edges) and the nine edge-edge pairs: the
  squared distance of two triangles that do not intersect (callers exclude intersecting pairs).
"""

from __future__ import annotations

from fractions import Fraction

import numpy as np


def _vec(x) -> tuple:
    return tuple(Fraction(float(c)) for c in x)


def _sub(a, b):
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


def _add(a, b):
    return (a[0] + b[0], a[1] + b[1], a[2] + b[2])


def _mul(a, s):
    return (a[0] * s, a[1] * s, a[2] * s)


def _dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def _cross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def _clamp01(x):
    return min(max(x, Fraction(0)), Fraction(1))


def point_segment_sq(x, p, q):
    """Squared distance of point ``x`` to the closed segment ``pq`` (a point when ``p == q``)."""
    d = _sub(q, p)
    den = _dot(d, d)
    t = _clamp01(_dot(_sub(x, p), d) / den) if den else Fraction(0)
    r = _sub(x, _add(p, _mul(d, t)))
    return _dot(r, r)


def segment_segment_sq(p1, q1, p2, q2):
    """Squared distance of two closed segments (either may be a point)."""
    best = min(point_segment_sq(p1, p2, q2), point_segment_sq(q1, p2, q2), point_segment_sq(p2, p1, q1),
               point_segment_sq(q2, p1, q1))
    d1, d2, r = _sub(q1, p1), _sub(q2, p2), _sub(p1, p2)
    a, e, b = _dot(d1, d1), _dot(d2, d2), _dot(d1, d2)
    c, f = _dot(d1, r), _dot(d2, r)
    den = a * e - b * b
    if den:
        s = (b * f - c * e) / den
        t = (a * f - b * c) / den
        if 0 <= s <= 1 and 0 <= t <= 1:
            g = _sub(_add(p1, _mul(d1, s)), _add(p2, _mul(d2, t)))
            best = min(best, _dot(g, g))
    return best


def point_triangle_sq(x, a, b, c):
    """Squared distance of point ``x`` to the closed triangle ``abc`` (a degenerate one: its edges)."""
    n = _cross(_sub(b, a), _sub(c, a))
    nn = _dot(n, n)
    edges = min(point_segment_sq(x, a, b), point_segment_sq(x, b, c), point_segment_sq(x, c, a))
    if not nn:
        return edges
    h = _dot(_sub(x, a), n)
    y = _sub(x, _mul(n, h / nn))  # the projection onto the plane
    if (_dot(_cross(_sub(b, a), _sub(y, a)), n) >= 0 and _dot(_cross(_sub(c, b), _sub(y, b)), n) >= 0
            and _dot(_cross(_sub(a, c), _sub(y, c)), n) >= 0):
        return h * h / nn
    return edges


def triangle_triangle_sq(tri_a, tri_b):
    """Squared distance of two closed triangles ``(3, 3)`` that do not intersect, exactly (see the
    module docstring). Degenerate triangles (zero area) are the union of their edges."""
    a = [_vec(v) for v in np.asarray(tri_a, np.float64)]
    b = [_vec(v) for v in np.asarray(tri_b, np.float64)]
    best = None
    for x in a:
        d = point_triangle_sq(x, *b)
        best = d if best is None else min(best, d)
    for y in b:
        best = min(best, point_triangle_sq(y, *a))
    for i in range(3):
        for j in range(3):
            best = min(best, segment_segment_sq(a[i], a[(i + 1) % 3], b[j], b[(j + 1) % 3]))
    return best


def triangle_distance(tri_a, tri_b) -> float:
    """:func:`triangle_triangle_sq`'s square root, rounded once to float64."""
    sq = triangle_triangle_sq(tri_a, tri_b)
    return float(np.sqrt(float(sq))) if sq < 2**1000 else float("inf")


def point_on_triangle_sq(x, tri) -> Fraction:
    """Squared distance of a float point to a float triangle ``(3, 3)``, exactly."""
    return point_triangle_sq(_vec(x), *[_vec(v) for v in np.asarray(tri, np.float64)])
