"""Convex solids in exact rational arithmetic, and whether two of them overlap: the oracle of the
penetrating / touching verdict (:mod:`warp_ccd._src.check.crossing`).

Two closed convex solids penetrate exactly when their interiors share a point: when the largest
``t`` with ``n . x + t <= c`` for every face plane ``n . x <= c`` of both (and ``t <= 1``) is
positive. That linear program is solved here by enumerating the vertices of its feasible set
with :class:`fractions.Fraction`: no rounding, no tolerance. Boxes are placed by rational
rotations (from integer quaternions) and rational offsets, and cut into triangles in several
ways (either diagonal of each face, faces subdivided into grids).
"""

from __future__ import annotations

from fractions import Fraction as F
from itertools import combinations

import numpy as np


def rotation(q) -> list:
    """The rational rotation matrix (rows) of the integer quaternion ``q = (w, x, y, z)``."""
    w, x, y, z = (F(v) for v in q)
    s = w * w + x * x + y * y + z * z
    return [[(w * w + x * x - y * y - z * z) / s, 2 * (x * y - w * z) / s, 2 * (x * z + w * y) / s],
            [2 * (x * y + w * z) / s, (w * w - x * x + y * y - z * z) / s, 2 * (y * z - w * x) / s],
            [2 * (x * z - w * y) / s, 2 * (y * z + w * x) / s, (w * w - x * x - y * y + z * z) / s]]


def _apply(r, v):
    return [sum(r[i][j] * v[j] for j in range(3)) for i in range(3)]


def _dot(a, b):
    return sum(x * y for x, y in zip(a, b))


class Box:
    """A box ``centre + R (s_x hx, s_y hy, s_z hz)``, ``s = +-1``, in rationals."""

    def __init__(self, half, rot=None, centre=(0, 0, 0)):
        self.half = [F(h) for h in half]
        self.rot = rot if rot is not None else rotation((1, 0, 0, 0))
        self.centre = [F(c) for c in centre]

    def moved(self, offset) -> Box:
        return Box(self.half, self.rot, [c + F(o) for c, o in zip(self.centre, offset)])

    def axis(self, i: int) -> list:
        return [self.rot[r][i] for r in range(3)]

    def corners(self) -> list:
        """The 8 corners, corner ``k`` at signs ``(k & 1, k & 2, k & 4)`` (set bit: +)."""
        out = []
        for k in range(8):
            local = [self.half[i] if k >> i & 1 else -self.half[i] for i in range(3)]
            out.append([c + d for c, d in zip(self.centre, _apply(self.rot, local))])
        return out

    def planes(self) -> list:
        """Face planes ``(n, c)``, inside ``n . x <= c``."""
        out = []
        for i in range(3):
            a = self.axis(i)
            for s in (1, -1):
                n = [s * x for x in a]
                out.append((n, _dot(n, self.centre) + self.half[i]))
        return out

    def extent(self, direction) -> tuple:
        """``(min, max)`` of ``direction . x`` over the box."""
        values = [_dot(direction, c) for c in self.corners()]
        return min(values), max(values)

    def mesh(self, diagonal: int = 0, n: int = 1):
        """Vertices (float64) and outward-wound triangles; each face an ``n x n`` grid of quads, each
        quad cut along diagonal ``diagonal`` (0 or 1: a fan from either corner)."""
        faces = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]
        c = self.corners()
        verts, tris = [], []
        for a, b, cc, d in faces:
            pa, pb, pc, pd = c[a], c[b], c[cc], c[d]
            base = len(verts)
            for i in range(n + 1):
                for j in range(n + 1):
                    u, v = F(i, n), F(j, n)
                    verts.append([pa[k] * (1 - u) * (1 - v) + pb[k] * u * (1 - v) + pc[k] * u * v + pd[k] * (1 - u) * v
                                  for k in range(3)])
            for i in range(n):
                for j in range(n):
                    q = [base + i * (n + 1) + j, base + (i + 1) * (n + 1) + j, base + (i + 1) * (n + 1) + j + 1,
                         base + i * (n + 1) + j + 1]
                    if diagonal == 0:
                        tris += [(q[0], q[1], q[2]), (q[0], q[2], q[3])]
                    else:
                        tris += [(q[1], q[2], q[3]), (q[1], q[3], q[0])]
        v = np.array([[float(x) for x in p] for p in verts])
        # Weld the faces' shared rim vertices (the same rationals) into one closed surface.
        _, first, inverse = np.unique(v, axis=0, return_index=True, return_inverse=True)
        order = np.argsort(first)
        rank = np.empty_like(order)
        rank[order] = np.arange(len(order))
        return v[np.sort(first)], rank[inverse.reshape(-1)][np.array(tris)].astype(np.int32)


def _solve4(rows, rhs):
    """Solves the 4 x 4 system exactly; None when singular."""
    m = [list(r) + [b] for r, b in zip(rows, rhs)]
    for col in range(4):
        piv = next((r for r in range(col, 4) if m[r][col] != 0), None)
        if piv is None:
            return None
        m[col], m[piv] = m[piv], m[col]
        for r in range(4):
            if r != col and m[r][col] != 0:
                f = m[r][col] / m[col][col]
                m[r] = [x - f * y for x, y in zip(m[r], m[col])]
    return [m[i][4] / m[i][i] for i in range(4)]


def interiors_overlap(a: Box, b: Box) -> bool:
    """Whether two boxes' interiors share a point (exact): the largest common slack is positive."""
    rows = [(n + [F(1)], c) for n, c in a.planes() + b.planes()] + [([F(0), F(0), F(0), F(1)], F(1))]
    best = None
    for subset in combinations(range(len(rows)), 4):
        x = _solve4([rows[i][0] for i in subset], [rows[i][1] for i in subset])
        if x is None or (best is not None and x[3] <= best):
            continue
        if all(_dot(r, x) <= c for r, c in rows):
            best = x[3]
    return best is not None and best > 0


def vertex_depth(a: Box, b: Box) -> float:
    """The deepest corner of either box inside the other: its distance to the other's surface
    (faces have unit normals: the smallest slack of its planes), 0 when none is inside."""
    deepest = F(0)
    for inner, outer in ((a, b), (b, a)):
        for x in inner.corners():
            slack = min(c - _dot(n, x) for n, c in outer.planes())
            deepest = max(deepest, slack)
    return float(deepest)
