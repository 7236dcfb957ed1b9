"""Oracles of the depth of two solids (:mod:`warp_ccd._src.narrowphase.depth`), in float64 with numpy.

``depth(A, B) = max over p in surface(A) inside solid(B) of dist(p, surface(B))``.

* :func:`convex_depth`: ``B`` convex, exact. Inside a convex solid the distance to its surface is the least
  distance behind its faces' planes, so over one triangle ``T`` of ``A`` the depth is a linear program in
  ``(p, t)``: maximise ``t`` with ``p`` on ``T`` (its plane, its three edges) and ``t`` behind every plane of
  ``B``. Solved by enumerating the vertices of the feasible set (every choice of three tight inequalities
  besides the plane's equation), a method that shares nothing with the library's branch and bound.
* :func:`sampled_depth`: any closed ``B``, bounds that converge. Points on a barycentric grid of every
  triangle of ``A``; those inside ``B`` (ray parity along three directions, the majority) measured to every
  triangle of ``B`` (exact point-triangle distance, Ericson). The largest is a lower bound of the depth; the
  depth is at most it plus the grid's spacing (a point of ``A`` lies within that of a sample, and the
  distance is 1-Lipschitz), where every triangle of ``A`` inside ``B`` is sampled.
"""

from __future__ import annotations

from itertools import combinations

import numpy as np
from scipy.spatial import cKDTree


def planes(v: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit outward normals ``(F, 3)`` and offsets ``(F,)`` of a closed mesh's triangles (``n . x <= c``
    inside), degenerate triangles left out; the winding is taken from the signed volume."""
    x = np.asarray(v, np.float64)[np.asarray(t)]
    n = np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0])
    length = np.linalg.norm(n, axis=1)
    ok = length > 1e-12 * np.max(np.linalg.norm(x[:, 1] - x[:, 0], axis=1)) ** 2
    n = n[ok] / length[ok, None]
    centre = x.reshape(-1, 3).mean(axis=0)
    volume = np.einsum("ij,ij->i", x[:, 0] - centre, np.cross(x[:, 1] - centre, x[:, 2] - centre)).sum()
    n = n if volume > 0 else -n
    return n, np.einsum("ij,ij->i", n, x[ok, 0])


def _triangle_depth(x: np.ndarray, n_b: np.ndarray, c_b: np.ndarray) -> float:
    """The linear program of one triangle ``x`` (3, 3) against the planes of a convex solid: the largest
    ``t`` with ``p`` on the triangle and ``n_b . p + t <= c_b``; -inf when no vertex is feasible."""
    e1, e2 = x[1] - x[0], x[2] - x[0]
    # Variables (a, b, t): p = x0 + a e1 + b e2. Inequalities G z <= h.
    g = [[-1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [1.0, 1.0, 0.0]]
    h = [0.0, 0.0, 1.0]
    for n, c in zip(n_b, c_b):
        g.append([n @ e1, n @ e2, 1.0])
        h.append(c - n @ x[0])
    g, h = np.array(g), np.array(h)
    idx = np.array(list(combinations(range(len(g)), 3)))
    m = g[idx]
    det = np.linalg.det(m)
    ok = np.abs(det) > 1e-12
    z = np.linalg.solve(m[ok], h[idx[ok]][..., None])[..., 0]
    scale = np.abs(h).max() + 1.0
    feasible = (z @ g.T <= h + 1e-9 * scale).all(axis=1)
    return float(z[feasible, 2].max()) if feasible.any() else -np.inf


def convex_depth(a: tuple, b: tuple) -> float:
    """``depth(A, B)`` with ``B`` convex (closed), exact up to float64 rounding: 0 when no point of ``A``'s
    surface lies inside ``B``."""
    n_b, c_b = planes(*b)
    x = np.asarray(a[0], np.float64)[np.asarray(a[1])]
    vb = np.asarray(b[0], np.float64)
    lo, hi = vb.min(axis=0), vb.max(axis=0)
    x = x[((x.max(axis=1) >= lo) & (x.min(axis=1) <= hi)).all(axis=1)]  # the triangles that may reach B
    best = 0.0
    for tri in x:
        best = max(best, _triangle_depth(tri, n_b, c_b))
    return best


def pair_convex_depth(a: tuple, b: tuple, a_closed: bool = True, b_closed: bool = True) -> float:
    """A pair's depth, both solids convex (or open: no solid), exact: NaN when neither is closed."""
    out = [convex_depth(a, b) if b_closed else np.nan, convex_depth(b, a) if a_closed else np.nan]
    return float(np.fmax(*out))


def closest_distance(p: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``(P,)`` distance from each point ``p`` (P, 3) to the nearest of triangles ``x`` (T, 3, 3) (Ericson,
    Real-Time Collision Detection 5.1.5, vectorised over all points and triangles)."""
    a, b, c = x[None, :, 0], x[None, :, 1], x[None, :, 2]
    q = p[:, None, :]
    ab, ac, ap = b - a, c - a, q - a
    d1, d2 = (ab * ap).sum(-1), (ac * ap).sum(-1)
    bp = q - b
    d3, d4 = (ab * bp).sum(-1), (ac * bp).sum(-1)
    cp = q - c
    d5, d6 = (ab * cp).sum(-1), (ac * cp).sum(-1)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    with np.errstate(divide="ignore", invalid="ignore"):
        denom = va + vb + vc
        v = vb / denom
        w = vc / denom
        out = a + ab * v[..., None] + ac * w[..., None]  # the face
        t_ab = d1 / (d1 - d3)
        t_ac = d2 / (d2 - d6)
        t_bc = (d4 - d3) / ((d4 - d3) + (d5 - d6))
    out = np.where(((va <= 0) & (d4 - d3 >= 0) & (d5 - d6 >= 0))[..., None], b + (c - b) * t_bc[..., None], out)
    out = np.where(((vb <= 0) & (d2 >= 0) & (d6 <= 0))[..., None], a + ac * t_ac[..., None], out)
    out = np.where(((vc <= 0) & (d1 >= 0) & (d3 <= 0))[..., None], a + ab * t_ab[..., None], out)
    out = np.where(((d6 >= 0) & (d5 <= d6))[..., None], c, out)
    out = np.where(((d3 >= 0) & (d4 <= d3))[..., None], b, out)
    out = np.where(((d1 <= 0) & (d2 <= 0))[..., None], a, out)
    return np.sqrt(((q - out) ** 2).sum(-1)).min(axis=1)


def inside(p: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``(P,)`` whether each point lies inside the closed mesh of triangles ``x`` (T, 3, 3): the majority of
    three rays' parities (Möller-Trumbore), directions chosen off the axes."""
    votes = np.zeros(len(p), np.int64)
    for d in np.array([[0.5773, 0.5774, 0.5775], [-0.3, 0.8, 0.52], [0.71, -0.2, -0.67]]):
        d = d / np.linalg.norm(d)
        e1, e2 = x[:, 1] - x[:, 0], x[:, 2] - x[:, 0]
        pv = np.cross(d, e2)
        det = (e1 * pv).sum(-1)
        inv = np.where(np.abs(det) > 1e-30, 1.0 / np.where(det == 0, 1, det), 0.0)
        s = p[:, None, :] - x[None, :, 0]
        u = (s * pv[None]).sum(-1) * inv
        qv = np.cross(s, e1[None])
        v = (qv * d).sum(-1) * inv
        t = (qv * e2[None]).sum(-1) * inv
        hit = (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0) & (np.abs(det) > 1e-30)
        votes += hit.sum(axis=1) % 2
    return votes >= 2


def sampled_depth(a: tuple, b: tuple, per_edge: int, chunk: int = 256) -> tuple[float, float]:
    """``(lower, spacing)``: the deepest sample of ``A``'s surface inside ``B``, and the largest distance from
    a point of a triangle of ``A`` to its nearest sample (the lower bound plus it bounds the depth above).

    Args:
        a, b: meshes ``(vertices, triangles)``, ``B`` closed.
        per_edge: samples along a triangle's edge (a barycentric grid of ``(k + 1)(k + 2) / 2`` points).
        chunk: points measured at once.
    """
    va, ta = np.asarray(a[0], np.float64), np.asarray(a[1])
    xb = np.asarray(b[0], np.float64)[np.asarray(b[1])]
    lo, hi = xb.reshape(-1, 3).min(axis=0), xb.reshape(-1, 3).max(axis=0)
    k = per_edge
    i, j = np.meshgrid(np.arange(k + 1), np.arange(k + 1), indexing="ij")
    keep = i + j <= k
    w = np.stack([i[keep], j[keep]], axis=1) / k
    x = va[ta]
    spacing = float(np.max(np.linalg.norm(x[:, [1, 2, 0]] - x, axis=2))) / k
    pts = (x[:, None, 0] + w[None, :, 0, None] * (x[:, None, 1] - x[:, None, 0])
           + w[None, :, 1, None] * (x[:, None, 2] - x[:, None, 0])).reshape(-1, 3)
    pts = np.unique(pts[((pts >= lo) & (pts <= hi)).all(axis=1)], axis=0)
    # The distance to the nearest vertex of B bounds a point's distance to B's surface above: points are
    # measured from the farthest, and those that cannot beat the deepest so far are left.
    reach = cKDTree(xb.reshape(-1, 3)).query(pts)[0]
    order = np.argsort(-reach, kind="stable")
    pts, reach = pts[order], reach[order]
    best = 0.0
    for s in range(0, len(pts), chunk):
        if reach[s] <= best:
            break
        p = pts[s:s + chunk]
        p = p[inside(p, xb)]
        if len(p):
            best = max(best, float(closest_distance(p, xb).max()))
    return best, spacing
