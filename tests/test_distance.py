"""The distance of two triangles (:func:`warp_ccd.geometry.tri_tri_distance`), on every device, in both
precisions: against exact rational distances (``distance_reference.py``), python-fcl's ``distance``
with nearest points, and its own properties (the points lie on their triangles, ``|p - q|`` is the
distance, no sampled pair of points is closer, intersecting triangles are at distance 0).

The pairs: random, nearly parallel, coplanar and apart, vertex-face and edge-edge at known
distances, slivers, degenerate (collinear, point) triangles, far from the origin, tiny and huge,
touching and crossing."""

from __future__ import annotations

from functools import lru_cache

import numpy as np
import pytest
import warp as wp
from hypothesis import given, settings
from hypothesis import strategies as st

import warp_ccd as wc
from warp_ccd._src.geometry.distance import DISTANCE_ERROR_ULPS, tri_tri_distance_batch_kernel

import distance_digests
from conftest import DEFAULT_DEVICE
from distance_reference import point_on_triangle_sq, triangle_distance
from oracles import closed_triangle_distance, degenerate_height, fcl_model

TYPES = {"float32": (wp.vec3, wp.float32, np.float32, 2.0**-24),
         "float64": (wp.vec3d, wp.float64, np.float64, 2.0**-53)}


def run_distance(tri_a: np.ndarray, tri_b: np.ndarray, precision: str, device, tol: float = wc.TOLERANCE):
    """``(distance (P,), points (P, 2, 3))`` of the kernel, as float64 numpy arrays."""
    vec, scalar, npt, _ = TYPES[precision]
    n = len(tri_a)
    a = wp.array(np.asarray(tri_a, npt), dtype=vec, device=device)
    b = wp.array(np.asarray(tri_b, npt), dtype=vec, device=device)
    d = wp.zeros(n, dtype=scalar, device=device)
    pts = wp.zeros((n, 2), dtype=vec, device=device)
    wp.launch(tri_tri_distance_batch_kernel, dim=n, inputs=[a, b, wp.float64(tol)], outputs=[d, pts], device=device)
    return d.numpy().astype(np.float64), pts.numpy().astype(np.float64)


def centred_extent(tri_a: np.ndarray, tri_b: np.ndarray, precision: str) -> np.ndarray:
    """``R`` of each pair: the largest coordinate relative to the pair's centroid (module docstring of
    :mod:`warp_ccd._src.geometry.distance`)."""
    both = np.concatenate([tri_a, tri_b], axis=1).astype(np.float64)
    return np.abs(both - both.mean(axis=1, keepdims=True)).max(axis=(1, 2))


def _apart(rng, n, scale=1.0, gap=3.0):
    a = rng.normal(size=(n, 3, 3)) * scale
    b = rng.normal(size=(n, 3, 3)) * scale + rng.normal(size=(n, 1, 3)) * gap * scale
    return a, b


def _near_parallel(rng, n):
    a = rng.normal(size=(n, 3, 3))
    shift = rng.normal(size=(n, 1, 3))
    shift *= rng.uniform(0.05, 0.5, size=(n, 1, 1)) / np.linalg.norm(shift, axis=2, keepdims=True)
    b = a[:, [1, 2, 0]] + shift + rng.normal(size=(n, 3, 3)) * 10.0 ** rng.uniform(-7, -3, size=(n, 1, 1))
    return a, b


def _coplanar(rng, n):
    a = np.zeros((n, 3, 3))
    b = np.zeros((n, 3, 3))
    a[:, :, :2] = rng.normal(size=(n, 3, 2))
    b[:, :, :2] = rng.normal(size=(n, 3, 2)) + rng.normal(size=(n, 1, 2)) * 3.0
    rot = np.linalg.qr(rng.normal(size=(3, 3)))[0]
    return a @ rot.T, b @ rot.T


def _slivers(rng, n):
    a, b = _apart(rng, n)
    t = rng.uniform(0.2, 0.8, size=(n, 1))
    a[:, 2] = a[:, 0] + (a[:, 1] - a[:, 0]) * t + rng.normal(size=(n, 3)) * 10.0 ** rng.uniform(-9, -4, size=(n, 1))
    return a, b


def _degenerate(rng, n):
    a, b = _apart(rng, n)
    half = n // 2
    a[:half, 2] = (a[:half, 0] + a[:half, 1]) * 0.5  # collinear
    b[half:, 1] = b[half:, 0]  # points
    b[half:, 2] = b[half:, 0]
    return a, b


def _thin_faces(rng, n):
    """A vertex of ``b`` over a thin face of ``a`` (twice its area 1e-5 to 1e-2 of its longest edge
    squared), near its long edge, 1e-4 to 1e-1 above it: the closest point is inside the face."""
    p0 = rng.uniform(-1, 1, (n, 3))
    along = rng.normal(size=(n, 3))
    along /= np.linalg.norm(along, axis=1, keepdims=True)
    p1 = p0 + along * rng.uniform(0.5, 1.0, (n, 1))
    across = np.cross(along, rng.normal(size=(n, 3)))
    across /= np.linalg.norm(across, axis=1, keepdims=True)
    edge = np.linalg.norm(p1 - p0, axis=1, keepdims=True)
    p2 = p0 + (p1 - p0) * rng.uniform(0.3, 0.7, (n, 1)) + across * edge * 10.0 ** rng.uniform(-5, -2, (n, 1))
    normal = np.cross(p1 - p0, p2 - p0)
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    c = 0.4 * p0 + 0.3 * p1 + 0.3 * p2 + normal * 10.0 ** rng.uniform(-4, -1, (n, 1))
    side = rng.normal(size=(n, 3))
    side -= np.sum(side * normal, axis=1, keepdims=True) * normal
    side /= np.linalg.norm(side, axis=1, keepdims=True)
    a = np.stack([p0, p1, p2], axis=1)
    b = np.stack([c, c + 0.3 * side + 0.3 * normal, c - 0.3 * side + 0.2 * normal], axis=1)
    return a, b


def _far(rng, n):
    a, b = _apart(rng, n)
    offset = rng.normal(size=(n, 1, 3)) * 1e3
    return a + offset, b + offset


SETS = {
    "random": lambda rng, n: _apart(rng, n),
    "close": lambda rng, n: _apart(rng, n, gap=1.0),
    "near_parallel": _near_parallel,
    "coplanar": _coplanar,
    "slivers": _slivers,
    "thin_faces": _thin_faces,
    "degenerate": _degenerate,
    "far": _far,
    "tiny": lambda rng, n: _apart(rng, n, scale=1e-6),
    "huge": lambda rng, n: _apart(rng, n, scale=1e6),
}


@lru_cache(maxsize=None)
def reference_set(name: str, n: int = 160):
    """``(tri_a, tri_b, exact distance)`` of a set's pairs that do not intersect, in float32 vertices
    (exact in float64 too: both precisions are checked on the same values)."""
    rng = np.random.default_rng(sorted(SETS).index(name) + 7)
    a, b = SETS[name](rng, n)
    a = a.astype(np.float32)
    b = b.astype(np.float32)
    size = np.abs(np.concatenate([a, b], axis=1)).max(axis=(1, 2))
    keep = closed_triangle_distance(a, b) > 1e-4 * np.maximum(size, 1e-30)  # crossing pairs are tested apart
    a, b = a[keep], b[keep]
    return a, b, np.array([triangle_distance(x, y) for x, y in zip(a, b)])


@pytest.mark.parametrize("precision", ["float32", "float64"])
@pytest.mark.parametrize("name", sorted(SETS))
def test_distance_matches_exact_reference(device, name, precision):
    a, b, exact = reference_set(name)
    assert len(a) > 40
    d, pts = run_distance(a, b, precision, device)
    ulp = TYPES[precision][3]
    bound = DISTANCE_ERROR_ULPS * ulp * centred_extent(a, b, precision)
    # A triangle the test takes as degenerate is its edges: within its height of the exact distance.
    bound += degenerate_height(a, wc.TOLERANCE) + degenerate_height(b, wc.TOLERANCE)
    err = np.abs(d - exact)
    assert (err <= bound).all(), f"{name}: {int((err > bound).sum())} pairs off, worst {np.max(err / bound):.2f}x"
    gap = np.linalg.norm(pts[:, 0] - pts[:, 1], axis=1)  # the points, back in the input frame, rounded there
    assert (np.abs(gap - d) <= bound + 8 * ulp * np.abs(pts).max(axis=(1, 2))).all()


@pytest.mark.parametrize("precision", ["float32", "float64"])
def test_closest_points_lie_on_their_triangles(device, precision):
    ulp = TYPES[precision][3]
    for name in ("random", "near_parallel", "coplanar", "far"):
        a, b, _ = reference_set(name)
        d, pts = run_distance(a, b, precision, device)
        scale = np.abs(np.concatenate([a, b], axis=1)).max(axis=(1, 2))
        for k in range(0, len(a), 7):
            for side, tri in ((0, a[k]), (1, b[k])):
                off = float(point_on_triangle_sq(pts[k, side], tri)) ** 0.5
                assert off <= 64 * ulp * scale[k], (name, k, side, off)


@pytest.mark.parametrize("precision", ["float32", "float64"])
def test_crafted_distances(device, precision):
    """Pairs at known distances: vertex over a face, crossing edges, parallel faces, edges side by side."""
    h = 0.37
    tri = np.array([[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [0.0, 2.0, 0.0]])
    cases = [
        (tri, np.array([[0.5, 0.5, h], [0.5, 0.5, h + 1], [1.5, 0.5, h + 2]]), h, [[0.5, 0.5, 0], [0.5, 0.5, h]]),
        (tri, tri + [0.0, 0.0, h], h, None),  # parallel faces: any point of the overlap
        (np.array([[-1.0, 0, 0], [1, 0, 0], [0, 0, -1]]), np.array([[0.0, -1, h], [0, 1, h], [0, 0, h + 1]]), h,
         [[0, 0, 0], [0, 0, h]]),  # crossing edges
        (tri, np.array([[3.0, 0, 0], [5, 0, 0], [4, 1, 0]]), 1.0, [[2, 0, 0], [3, 0, 0]]),  # vertex to vertex, coplanar
        (tri, tri.copy(), 0.0, None),  # identical
        (tri, np.array([[1.0, 1.0, 0.0], [3, 3, 0], [3, 3, 1]]), 0.0, None),  # touching at a vertex on an edge
    ]
    a = np.array([c[0] for c in cases])
    b = np.array([c[1] for c in cases])
    d, pts = run_distance(a, b, precision, device)
    tol = 1e-6 if precision == "float32" else 1e-14
    for k, (_, _, want, points) in enumerate(cases):
        assert abs(d[k] - want) <= tol * 4, (k, d[k], want)
        if points is not None:
            np.testing.assert_allclose(pts[k], points, atol=tol * 8)
        if want == 0.0:
            assert d[k] == 0.0 and (pts[k, 0] == pts[k, 1]).all()


@pytest.mark.parametrize("precision", ["float32", "float64"])
def test_intersecting_triangles_are_at_distance_zero(device, precision, rng):
    """Crossing pairs (the intersection tests say they meet) are at distance 0, at a point of both."""
    a = rng.normal(size=(400, 3, 3))
    b = a.mean(axis=1, keepdims=True) + rng.normal(size=(400, 3, 3))  # through each other's centroid region
    a, b = a.astype(np.float32), b.astype(np.float32)
    d, pts = run_distance(a, b, precision, device)
    crossing = closed_triangle_distance(a, b) == 0.0
    assert crossing.sum() > 100
    assert (d[crossing] == 0.0).all()
    assert (pts[crossing, 0] == pts[crossing, 1]).all()
    scale = np.abs(np.concatenate([a, b], axis=1)).max(axis=(1, 2))
    ulp = TYPES[precision][3]
    for k in np.nonzero(crossing)[0][::9]:
        for tri in (a[k], b[k]):
            assert float(point_on_triangle_sq(pts[k, 0], tri)) ** 0.5 <= 1e3 * ulp * scale[k] + 4e-5 * scale[k]


def test_translation_and_scale_change_nothing_in_float64(device):
    """Distances of a scaled or translated pair (by powers of two: exact) scale or stay, within rounding."""
    a, b, exact = reference_set("random")
    d0, _ = run_distance(a, b, "float64", device)
    d1, _ = run_distance(a.astype(np.float64) * 2.0**20, b.astype(np.float64) * 2.0**20, "float64", device)
    np.testing.assert_allclose(d1 / 2.0**20, d0, rtol=0, atol=0)
    d2, _ = run_distance(a.astype(np.float64) + 1e5, b.astype(np.float64) + 1e5, "float64", device)
    np.testing.assert_allclose(d2, exact, rtol=0, atol=1e5 * 64 * 2.0**-53)


def test_float32_agrees_with_float64_within_the_bound(device):
    a, b, exact = reference_set("close")
    d32, _ = run_distance(a, b, "float32", device)
    d64, _ = run_distance(a, b, "float64", device)
    r = centred_extent(a, b, "float32")
    assert (np.abs(d32 - d64) <= 2 * DISTANCE_ERROR_ULPS * 2.0**-24 * r).all()


def test_python_fcl_distance_agrees(device):
    """python-fcl's distance and nearest points on single-triangle models: the same distances."""
    fcl = pytest.importorskip("fcl")
    a, b, exact = reference_set("random")
    a, b, exact = a[:60], b[:60], exact[:60]
    d, pts = run_distance(a, b, "float64", device)
    for k in range(len(a)):
        models = [fcl_model(tri, [[0, 1, 2]]) for tri in (a[k], b[k])]
        req = fcl.DistanceRequest(enable_nearest_points=True)
        res = fcl.DistanceResult()
        got = fcl.distance(models[0], models[1], req, res)
        assert abs(got - d[k]) <= 1e-9 * max(1.0, exact[k]), (k, got, d[k])
        assert abs(np.linalg.norm(np.subtract(res.nearest_points[0], res.nearest_points[1])) - d[k]) <= 1e-9


@settings(max_examples=60, deadline=None)
@given(st.lists(st.floats(-4, 4, allow_nan=False, width=32), min_size=18, max_size=18),
       st.lists(st.floats(0, 1), min_size=40, max_size=40))
def test_no_sampled_points_are_closer(coords, weights):
    """Property: the distance is at most that of any two points of the triangles (convex combinations)."""
    tri = np.array(coords, np.float32).reshape(2, 3, 3)
    d, pts = run_distance(tri[:1], tri[1:], "float64", DEFAULT_DEVICE)
    w = np.array(weights).reshape(4, 10) + 1e-3  # positive: every combination below is a point of its triangle
    bound = 16 * 2.0**-53 * (np.abs(tri).max() + 1)
    for i in range(0, 10, 2):
        wa = w[0:3, i] / w[0:3, i].sum()
        wb = w[1:4, i + 1] / w[1:4, i + 1].sum()
        x = wa @ tri[0].astype(np.float64)
        y = wb @ tri[1].astype(np.float64)
        assert d[0] <= np.linalg.norm(x - y) + bound


@pytest.mark.parametrize("what", ["pairs_float32", "pairs_float64", "scene_float32", "scene_float64"])
def test_every_device_gives_the_recorded_answers(device, what):
    """Distances, closest points and clearance rows bit for bit as recorded on the CPU (on 10^5
    near-degenerate pairs and on a scene), so that a GPU machine without a CPU device checks it too."""
    kind, precision = what.split("_")
    got = (distance_digests.pair_digest if kind == "pairs" else distance_digests.scene_digest)(precision, device)
    assert got == distance_digests.read_reference()[what], f"{what} differs on {device} from the CPU's record"
