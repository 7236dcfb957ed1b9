"""Independent references the tests compare against.

* :func:`box_pairs_numpy`: numpy truth for closed axis-aligned boxes.
* :func:`triangle_pairs_warp64`: all triangle pairs of object pairs whose exact (numpy) boxes
  overlap, each tested with Warp's float64 ``wp.intersect_tri_tri``. That built-in snaps plane
  distances below an absolute 1e-6 (on the unnormalised normal), so callers scale scenes up first
  (``scale``): uniform scaling changes no intersection.
* :func:`triangle_pairs_fcl`: python-fcl's BVH collision with per-triangle contacts (one
  :func:`fcl_bvh` model per mesh).
* :func:`closed_triangle_distance`: distances of closed triangles (numpy float64), and from it
  :func:`pair_distance_brute` / :func:`clearance_pairs_brute`, the least distance of mesh pairs over
  all their triangle pairs (within a reach); :func:`fcl_pair_distance`, python-fcl's.
"""

from __future__ import annotations

import numpy as np
import warp as wp

wp.set_module_options({"enable_backward": False})  # forward kernels only


def fcl_bvh(vertices, triangles):
    """A python-fcl ``BVHModel`` (its default OBBRSS) of one mesh: float64 vertices, int64 triangles."""
    import fcl

    model = fcl.BVHModel()
    model.beginModel(len(vertices), len(triangles))
    model.addSubModel(np.asarray(vertices, np.float64), np.asarray(triangles, np.int64))
    model.endModel()
    return model


def box_pairs_numpy(lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """``(K, 2)`` int32 sorted pairs ``a < b`` of overlapping closed boxes (chunked O(N^2))."""
    lower = np.asarray(lower)
    upper = np.asarray(upper)
    n = lower.shape[0]
    out = []
    chunk = max(1, 4_000_000 // max(n, 1))
    for s in range(0, n, chunk):
        lo = lower[s : s + chunk, None, :]
        hi = upper[s : s + chunk, None, :]
        ov = np.all((lo <= upper[None]) & (lower[None] <= hi), axis=2)
        a, b = np.nonzero(ov)
        a = a + s
        keep = a < b
        out.append(np.stack([a[keep], b[keep]], axis=1))
    if not out:
        return np.zeros((0, 2), np.int32)
    p = np.concatenate(out).astype(np.int32)
    return p[np.lexsort((p[:, 1], p[:, 0]))]


def box_pairs_between(lo_a, hi_a, lo_b, hi_b) -> np.ndarray:
    """``(K, 2)`` index pairs ``(i, j)`` with box ``i`` of set a overlapping box ``j`` of set b."""
    out = []
    chunk = max(1, 2_000_000 // max(len(lo_b), 1))
    for s in range(0, len(lo_a), chunk):
        ov = np.all((lo_a[s : s + chunk, None] <= hi_b[None]) & (lo_b[None] <= hi_a[s : s + chunk, None]), axis=2)
        i, j = np.nonzero(ov)
        out.append(np.stack([i + s, j], axis=1))
    return np.concatenate(out) if out else np.zeros((0, 2), np.int64)


@wp.kernel
def _tri_tri_f64_kernel(
    va: wp.array2d[wp.vec3d], vb: wp.array2d[wp.vec3d], out: wp.array[wp.int32]
):
    k = wp.tid()
    out[k] = wp.intersect_tri_tri(va[k, 0], va[k, 1], va[k, 2], vb[k, 0], vb[k, 1], vb[k, 2])


def intersect_tri_tri_f64(ta: np.ndarray, tb: np.ndarray, device=None) -> np.ndarray:
    """Warp's float64 Möller test on ``(P, 3, 3)`` triangle pairs; ``(P,)`` bool."""
    if len(ta) == 0:
        return np.zeros(0, bool)
    va = wp.array(np.asarray(ta, np.float64), dtype=wp.vec3d, device=device)
    vb = wp.array(np.asarray(tb, np.float64), dtype=wp.vec3d, device=device)
    out = wp.zeros(len(ta), dtype=wp.int32, device=device)
    wp.launch(_tri_tri_f64_kernel, dim=len(ta), inputs=[va, vb, out], device=device)
    return out.numpy().astype(bool)


def _sorted4(rows) -> np.ndarray:
    p = np.asarray(rows, np.int32).reshape(-1, 4)
    return p[np.lexsort((p[:, 3], p[:, 2], p[:, 1], p[:, 0]))]


def triangle_pairs_warp64(meshes, scale: float = 1.0, device=None) -> np.ndarray:
    """Brute force over the triangle pairs of objects with overlapping boxes.

    Args:
        meshes: per object ``(world vertices (n, 3), triangles (m, 3))``.
        scale: uniform scale applied (in float64) before testing.

    Returns:
        ``(M, 4)`` int32 sorted rows ``(obj_a, tri_a, obj_b, tri_b)``.
    """
    tris = [np.asarray(v, np.float64)[np.asarray(t)] * scale for v, t in meshes]
    lower = np.array([t.reshape(-1, 3).min(0) for t in tris])
    upper = np.array([t.reshape(-1, 3).max(0) for t in tris])
    rows, ta, tb = [], [], []
    for a, b in box_pairs_numpy(lower, upper):
        # Triangle pairs whose (exact, closed) boxes overlap: a necessary condition.
        lo_a, hi_a = tris[a].min(axis=1), tris[a].max(axis=1)
        lo_b, hi_b = tris[b].min(axis=1), tris[b].max(axis=1)
        sel_a = np.nonzero(np.all((lo_a <= upper[b]) & (lower[b] <= hi_a), axis=1))[0]
        sel_b = np.nonzero(np.all((lo_b <= upper[a]) & (lower[a] <= hi_b), axis=1))[0]
        if len(sel_a) == 0 or len(sel_b) == 0:
            continue
        pairs = box_pairs_between(lo_a[sel_a], hi_a[sel_a], lo_b[sel_b], hi_b[sel_b])
        ia, ib = sel_a[pairs[:, 0]], sel_b[pairs[:, 1]]
        rows.append(np.stack([np.full_like(ia, a), ia, np.full_like(ib, b), ib], 1))
        ta.append(tris[a][ia])
        tb.append(tris[b][ib])
    if not rows:
        return np.zeros((0, 4), np.int32)
    rows = np.concatenate(rows)
    hit = intersect_tri_tri_f64(np.concatenate(ta), np.concatenate(tb), device=device)
    return _sorted4(rows[hit])


def triangle_pairs_fcl(meshes) -> np.ndarray:
    """python-fcl: ``DynamicAABBTreeCollisionManager`` with per-triangle contacts.

    ``num_max_contacts`` is set far above any count here: FCL truncates silently at it.
    """
    import fcl

    objs, index = [], {}
    for i, (v, t) in enumerate(meshes):
        m = fcl_bvh(v, t)
        index[id(m)] = i
        objs.append((m, fcl.CollisionObject(m, fcl.Transform())))
    mgr = fcl.DynamicAABBTreeCollisionManager()
    mgr.registerObjects([o for _, o in objs])
    mgr.setup()
    limit = 10_000_000
    data = fcl.CollisionData(request=fcl.CollisionRequest(num_max_contacts=limit, enable_contact=True))
    mgr.collide(data, fcl.defaultCollisionCallback)
    contacts = data.result.contacts
    assert len(contacts) < limit, "FCL hit its contact limit"
    rows = set()
    for c in contacts:
        a, b = index[id(c.o1)], index[id(c.o2)]
        ta, tb = c.b1, c.b2
        if a > b:
            a, b, ta, tb = b, a, tb, ta
        rows.add((a, ta, b, tb))
    return _sorted4(sorted(rows)) if rows else np.zeros((0, 4), np.int32)


# ---------------------------------------------------------------------------------------------
# Distances between closed triangles that may be degenerate (numpy, float64)

ORACLE_DEGENERATE = 1e-9
"""A triangle whose doubled area is at most this times its longest edge squared is taken as the
union of its edges (in float64 its normal is then too poorly defined; its height is below 1e-9 of
its size, far below any tolerance tested)."""


def _dot(a, b):
    return np.sum(a * b, axis=-1)


def point_segment_distance(x, p, q):
    """Distances of points ``x`` to closed segments ``pq`` (a point when ``p == q``); ``(P, 3)`` each."""
    d = q - p
    den = _dot(d, d)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(den > 0, np.clip(_dot(x - p, d) / den, 0.0, 1.0), 0.0)
    return np.linalg.norm(x - (p + d * t[:, None]), axis=1)


def segment_segment_distance(p1, q1, p2, q2):
    """Distances between closed segments (either may be a point): the least of the four
    end-to-segment distances and, where the closest points of the two lines lie inside both
    segments, their distance. Nearly parallel segments (sine of their angle squared below 1e-12)
    take the end-to-segment distances alone, which exceed the true one by at most about 1e-6 of
    their length."""
    best = np.minimum(np.minimum(point_segment_distance(p1, p2, q2), point_segment_distance(q1, p2, q2)),
                      np.minimum(point_segment_distance(p2, p1, q1), point_segment_distance(q2, p1, q1)))
    d1, d2, r = q1 - p1, q2 - p2, p1 - p2
    a, e, b = _dot(d1, d1), _dot(d2, d2), _dot(d1, d2)
    c, f = _dot(d1, r), _dot(d2, r)
    den = a * e - b * b
    with np.errstate(divide="ignore", invalid="ignore"):
        s = (b * f - c * e) / den
        t = (a * f - b * c) / den
        inside = (den > 1e-12 * a * e) & (s >= 0) & (s <= 1) & (t >= 0) & (t <= 1)
        gap = np.linalg.norm(p1 + d1 * s[:, None] - p2 - d2 * t[:, None], axis=1)
    return np.where(inside, np.minimum(best, gap), best)


def _inside_prism(x, a, b, c, n):
    """``x`` projects into the closed triangle ``abc`` of normal ``n`` (not normalised)."""
    return ((_dot(np.cross(b - a, x - a), n) >= 0) & (_dot(np.cross(c - b, x - b), n) >= 0)
            & (_dot(np.cross(a - c, x - c), n) >= 0))


def segment_triangle_distance(p, q, a, b, c):
    """Distances between closed segments ``pq`` and non-degenerate closed triangles ``abc``: 0 where
    the segment crosses the triangle, else the least of the end-to-face and segment-to-edge
    distances."""
    n = np.cross(b - a, c - a)
    unit = n / np.linalg.norm(n, axis=1, keepdims=True)
    rp, rq = _dot(p - a, unit), _dot(q - a, unit)
    out = np.full(len(p), np.inf)
    for x, r in ((p, rp), (q, rq)):  # an end over the face: its height
        out = np.where(_inside_prism(x, a, b, c, n), np.minimum(out, np.abs(r)), out)
    for u, v in ((a, b), (b, c), (c, a)):
        out = np.minimum(out, segment_segment_distance(p, q, u, v))
    t = np.divide(rp, rp - rq, out=np.zeros_like(rp), where=rp * rq < 0)
    crossing = (rp * rq < 0) & _inside_prism(p + (q - p) * t[:, None], a, b, c, n)
    return np.where(crossing, 0.0, out)


def degenerate(tri, ratio=ORACLE_DEGENERATE):
    """``(P,)`` bool: triangles ``(P, 3, 3)`` whose doubled area is at most ``ratio`` times their
    longest edge squared."""
    area2 = np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    longest = np.max(np.linalg.norm(tri - np.roll(tri, 1, axis=1), axis=2), axis=1)
    return area2 <= ratio * longest**2


def closed_triangle_distance(tri_a, tri_b):
    """Distances between closed triangles ``(P, 3, 3)``, degenerate ones (:func:`degenerate`) taken as
    the union of their edges: the least over the edges of each against the other (its face, or its
    edges when it is degenerate). Two closed triangles intersect exactly when an edge of one meets
    the other, so a crossing gives 0."""
    a = np.asarray(tri_a, np.float64)
    b = np.asarray(tri_b, np.float64)
    flat_a, flat_b = degenerate(a), degenerate(b)
    out = np.full(len(a), np.inf)
    for one, other, other_flat in ((a, b, flat_b), (b, a, flat_a)):
        for i in range(3):
            p, q = one[:, i], one[:, (i + 1) % 3]
            edges = np.full(len(a), np.inf)
            for j in range(3):
                edges = np.minimum(edges, segment_segment_distance(p, q, other[:, j], other[:, (j + 1) % 3]))
            face = np.full(len(a), np.inf)
            if (~other_flat).any():
                k = ~other_flat
                face[k] = segment_triangle_distance(p[k], q[k], other[k, 0], other[k, 1], other[k, 2])
            out = np.minimum(out, np.where(other_flat, edges, face))
    return out


def degenerate_height(tri, tol):
    """``(P,)`` height over the longest edge of the triangles ``(P, 3, 3)`` that a test with relative
    tolerance ``tol`` takes as degenerate (twice the area at most ``tol`` times the longest edge
    squared), else 0: how far such a test's segment may lie from the triangle itself."""
    area2 = np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    longest = np.max(np.linalg.norm(tri - np.roll(tri, 1, axis=1), axis=2), axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        height = np.where(longest > 0, area2 / longest, 0.0)
    return np.where(area2 <= tol * longest**2, height, 0.0)


def tolerance_length(tri_a, tri_b, tol):
    """``eps`` of each pair ``(P, 3, 3)``: ``tol`` times the longest edge of the two triangles."""
    edges = np.concatenate([np.linalg.norm(t - np.roll(t, 1, axis=1), axis=2) for t in (tri_a, tri_b)], axis=1)
    return tol * edges.max(axis=1)


def touching_band(tri_a, tri_b, tol, degenerate_slack=False):
    """Where the reference decides what a triangle test with relative tolerance ``tol`` must say:
    ``(must_touch, must_miss)``, ``(P,)`` bool. A pair within ``eps / 4`` must touch, one at least
    ``4 eps`` apart must not (``eps``: :func:`tolerance_length`); in between either answer is right.
    With ``degenerate_slack`` a pair must touch only when it does so by more than the heights of its
    triangles that the test takes as degenerate (:func:`degenerate_height`), since it decides such a
    triangle as a segment that far from it."""
    dist = closed_triangle_distance(tri_a, tri_b)
    eps = tolerance_length(tri_a, tri_b, tol)
    slack = degenerate_height(tri_a, tol) + degenerate_height(tri_b, tol) if degenerate_slack else 0.0
    return dist + slack <= 0.25 * eps, dist >= 4.0 * eps


# ---------------------------------------------------------------------------------------------
# Clearance: the least distance of object pairs (numpy float64 brute force, python-fcl)

def _triangle_boxes(v, t):
    tri = np.asarray(v, np.float64)[np.asarray(t)]
    return tri, tri.min(axis=1), tri.max(axis=1)


def box_gap(lo_a, hi_a, lo_b, hi_b):
    """Euclidean distance between closed boxes (broadcast), 0 where they overlap."""
    gap = np.maximum(0.0, np.maximum(lo_a - hi_b, lo_b - hi_a))
    return np.linalg.norm(gap, axis=-1)


def pair_distance_brute(mesh_a, mesh_b, reach: float = np.inf):
    """Least distance between two meshes (world vertices, triangles), and the triangle pairs that
    attain it, by :func:`closed_triangle_distance` over every triangle pair whose boxes lie within
    ``reach`` of each other (a pair farther apart than ``reach`` in its boxes cannot come closer; an
    infinite ``reach`` tests them all): ``(distance, (K, 2) int rows (tri_a, tri_b) at it)``, or
    ``(inf, empty)`` when no triangle pair is within ``reach``."""
    ta, lo_a, hi_a = _triangle_boxes(*mesh_a)
    tb, lo_b, hi_b = _triangle_boxes(*mesh_b)
    best, rows = np.inf, []
    chunk = max(1, 400_000 // max(len(tb), 1))
    for s in range(0, len(ta), chunk):
        gap = box_gap(lo_a[s : s + chunk, None], hi_a[s : s + chunk, None], lo_b[None], hi_b[None])
        i, j = np.nonzero(gap <= reach)
        if not len(i):
            continue
        i = i + s
        d = closed_triangle_distance(ta[i], tb[j])
        m = d.min()
        if m < best:
            best, rows = m, []
        if m == best:
            rows.append(np.stack([i[d == m], j[d == m]], axis=1))
    return best, (np.concatenate(rows) if rows else np.zeros((0, 2), np.int64))


def clearance_pairs_brute(meshes, clearance: float) -> dict:
    """``{(a, b): least distance}`` of every object pair ``a < b`` within ``clearance`` (float64
    numpy; object boxes first, then :func:`pair_distance_brute` within the clearance)."""
    boxes = [_triangle_boxes(v, t) for v, t in meshes]
    lo = np.array([b[1].min(axis=0) for b in boxes])
    hi = np.array([b[2].max(axis=0) for b in boxes])
    out = {}
    for a in range(len(meshes)):
        near = np.nonzero(box_gap(lo[a], hi[a], lo, hi) <= clearance)[0]
        for b in near[near > a]:
            d, _ = pair_distance_brute(meshes[a], meshes[b], reach=clearance)
            if d <= clearance:
                out[(a, int(b))] = d
    return out


def fcl_model(v, t):
    """A python-fcl collision object of a mesh in world coordinates."""
    import fcl

    return fcl.CollisionObject(fcl_bvh(v, t), fcl.Transform())


def fcl_pair_distance(obj_a, obj_b):
    """``(distance, nearest points (2, 3), collide)`` by python-fcl: ``fcl.distance`` with nearest
    points, and ``fcl.collide`` (FCL's mesh distance is not meant for intersecting meshes)."""
    import fcl

    hit = fcl.collide(obj_a, obj_b, fcl.CollisionRequest(), fcl.CollisionResult()) > 0
    res = fcl.DistanceResult()
    d = fcl.distance(obj_a, obj_b, fcl.DistanceRequest(enable_nearest_points=True), res)
    return d, np.array(res.nearest_points, np.float64), hit
