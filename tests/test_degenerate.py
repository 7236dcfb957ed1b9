"""Degenerate triangles (slivers, segments, points) are the closed sets they are.

Fan-triangulated polygons of scanned and CAD meshes leave slivers whose doubled area is about 1e-8
of their longest edge squared. Each crafted case below is checked first against a float64 numpy
reference (:func:`oracles.closed_triangle_distance`), then both triangle tests must agree with it,
in both argument orders, at several scales and offsets, in float32 and float64. Seeded random
slivers, points and segment pairs are then checked against the same reference away from the
tolerance band.
"""

import numpy as np
import pytest
import warp as wp

import warp_ccd as wc
from warp_ccd._src.geometry.precision import precision_types
from warp_ccd._src.geometry.triangle import CONTACT_NONE, CONTACT_SEGMENT, TOLERANCE, tri_tri_segment_batch_kernel
from warp_ccd._src.narrowphase.discrete import NARROW_METHODS

from oracles import closed_triangle_distance, tolerance_length, touching_band
from test_narrow_phase import run_test
from test_robustness import random_rotations

T1 = [[0, 0, 0], [2, 0, 0], [0, 2, 0]]
THIN = [[0, 0, 0], [10, 0, 0], [0, 0.0625, 0]]  # a sharp corner of about 0.36 degrees at (10, 0, 0)
GAP = 0.0625  # far beyond the tolerance (about 3e-5 here), and exact in float32 at an offset of 1e4


def sliver(p, q, lift=1e-8):
    """A triangle of vertices ``p``, ``q`` and a third one a third of the way along, off the line by
    ``lift`` times ``|pq|``: doubled area about ``lift * |pq|**2``, as a fan triangulation leaves."""
    p, q = np.asarray(p, np.float64), np.asarray(q, np.float64)
    d = q - p
    side = np.cross(d, [0.0, 0.0, 1.0]) if abs(d[2]) < 0.9 * np.linalg.norm(d) else np.cross(d, [1.0, 0.0, 0.0])
    side = side / max(np.linalg.norm(side), 1e-300)
    return [p.tolist(), q.tolist(), (p + d / 3 + side * lift * np.linalg.norm(d)).tolist()]


def point(x):
    return [list(x)] * 3


# name: (triangle a, triangle b, whether they meet)
CASES = {
    # a sliver against a proper triangle
    "sliver_crossing": (sliver([0.5, 0.5, -1], [0.5, 0.5, 1]), T1, True),
    "sliver_crossing_beside": (sliver([2.5, 0.5, -1], [2.5, 0.5, 1]), T1, False),
    "sliver_crossing_just_outside": (sliver([1 + GAP, 1, -1], [1 + GAP, 1, 1]), T1, False),
    "sliver_slanted_crossing": (sliver([0.25, 0.25, -1], [1, 0.75, 0.5]), T1, True),
    "sliver_in_plane": (sliver([-1, 0.5, 0], [3, 0.5, 0]), T1, True),
    "sliver_in_plane_inside": (sliver([0.25, 0.5, 0], [1, 0.5, 0]), T1, True),
    "sliver_in_plane_apart": (sliver([-1, 2.5, 0], [3, 2.5, 0]), T1, False),
    "sliver_parallel_above": (sliver([-1, 0.5, GAP], [3, 0.5, GAP]), T1, False),
    "sliver_grazing_edge_in_plane": (sliver([1, -1, 0], [1, 0, 0]), T1, True),
    "sliver_grazing_edge_across": (sliver([1, 0, -1], [1, 0, 1]), T1, True),
    "sliver_grazing_vertex": (sliver([2, 0, -1], [2, 0, 1]), T1, True),
    "sliver_near_edge_across": (sliver([1, -GAP, -1], [1, -GAP, 1]), T1, False),
    "sliver_along_edge": (sliver([1, 0, 0], [3, 0, 0]), T1, True),
    "sliver_touching_face_at_end": (sliver([0.5, 0.5, 0], [0.5, 0.5, 1]), T1, True),
    "sliver_ending_above_face": (sliver([0.5, 0.5, GAP], [0.5, 0.5, 1]), T1, False),
    "sliver_beyond_sharp_corner": (sliver([10 + GAP / 4, 0, -1], [10 + GAP / 4, 0, 1]), THIN, False),
    # a point (three equal vertices)
    "point_on_face": (point([0.5, 0.5, 0]), T1, True),
    "point_just_off_face": (point([0.5, 0.5, GAP]), T1, False),
    "point_on_edge": (point([1, 0, 0]), T1, True),
    "point_at_vertex": (point([0, 2, 0]), T1, True),
    "point_beside_edge_in_plane": (point([1, -GAP, 0]), T1, False),
    "point_beyond_sharp_corner": (point([10 + GAP / 4, 0, 0]), THIN, False),
    # repeated vertices: a segment
    "repeated_first_crossing": ([[0.5, 0.5, -1], [0.5, 0.5, -1], [0.5, 0.5, 1]], T1, True),
    "repeated_last_crossing": ([[0.5, 0.5, -1], [0.5, 0.5, 1], [0.5, 0.5, 1]], T1, True),
    "repeated_beside": ([[2.5, 0.5, -1], [2.5, 0.5, 1], [2.5, 0.5, 1]], T1, False),
    "collinear_three_crossing": ([[0.5, 0.5, -1], [0.5, 0.5, 0.5], [0.5, 0.5, 1]], T1, True),
    # two degenerate triangles
    "slivers_crossing": (sliver([0, 0, 0], [2, 2, 0]), sliver([0, 2, 0], [2, 0, 0]), True),
    "slivers_skew_apart": (sliver([0, 0, 0], [2, 2, 0]), sliver([0, 2, GAP], [2, 0, GAP]), False),
    "slivers_end_on_side": (sliver([0, 0, 0], [2, 0, 0]), sliver([1, 0, 0], [1, 1, 1]), True),
    "slivers_collinear_overlap": (sliver([0, 0, 0], [2, 0, 0]), sliver([1, 0, 0], [3, 0, 0]), True),
    "slivers_collinear_end_to_end": (sliver([0, 0, 0], [2, 0, 0]), sliver([2, 0, 0], [3, 0, 0]), True),
    "slivers_collinear_apart": (sliver([0, 0, 0], [2, 0, 0]), sliver([2 + GAP, 0, 0], [3, 0, 0]), False),
    "slivers_parallel_apart": (sliver([0, 0, 0], [2, 0, 0]), sliver([0, GAP, 0], [2, GAP, 0]), False),
    "point_on_sliver": (point([1, 0, 0]), sliver([0, 0, 0], [2, 0, 0]), True),
    "point_beside_sliver": (point([1, GAP, 0]), sliver([0, 0, 0], [2, 0, 0]), False),
    "points_identical": (point([1, 2, 3]), point([1, 2, 3]), True),
    "points_apart": (point([1, 2, 3]), point([1, 2, 3 + GAP]), False),
}
NAMES = sorted(CASES)


def crafted(offset=(0.0, 0.0, 0.0), scale=1.0, rotation=None):
    ta = np.array([CASES[n][0] for n in NAMES], np.float64)
    tb = np.array([CASES[n][1] for n in NAMES], np.float64)
    if rotation is not None:
        ta, tb = ta @ rotation.T, tb @ rotation.T
    return ta * scale + offset, tb * scale + offset, np.array([CASES[n][2] for n in NAMES])


def test_crafted_cases_against_float64_reference():
    ta, tb, expect = crafted()
    dist = closed_triangle_distance(ta, tb)
    eps = tolerance_length(ta, tb, TOLERANCE)
    wrong = [n for n, d, e, x in zip(NAMES, dist, eps, expect) if (d > 1e-9 if x else d < 100 * e)]
    assert not wrong, f"the reference disagrees with the crafted truth for {wrong}"


TRANSFORMS = {
    "unit": ((0, 0, 0), 1.0, None),
    "far": ((1e4, -1e4, 1e4), 1.0, None),
    "tiny": ((0, 0, 0), 1e-4, None),
    "huge": ((0, 0, 0), 1e3, None),
    "rotated": ((3.0, -2.0, 5.0), 1.0, "random"),
}


@pytest.mark.parametrize("precision", ["float32", "float64"])
@pytest.mark.parametrize("method", sorted(NARROW_METHODS))
@pytest.mark.parametrize("where", sorted(TRANSFORMS))
def test_crafted_degenerate_cases(device, method, where, precision):
    offset, scale, rotation = TRANSFORMS[where]
    if rotation == "random":
        rotation = random_rotations(np.random.default_rng(5), 1)[0]
    ta, tb, expect = crafted(offset, scale, rotation)
    for a, b in ((ta, tb), (tb, ta), (ta[:, [1, 2, 0]], tb[:, [2, 0, 1]])):
        got = run_test(a, b, device, method, precision=precision)
        wrong = [n for n, g, e in zip(NAMES, got, expect) if g != e]
        assert not wrong, f"{method} {precision}, {where}: wrong answers for {wrong}"


@pytest.mark.parametrize("method", sorted(NARROW_METHODS))
def test_crafted_degenerate_cases_float64_far(device, method):
    ta, tb, expect = crafted(offset=(1e8, -3e8, 2e8))
    for a, b in ((ta, tb), (tb, ta)):
        got = run_test(a, b, device, method, precision="float64")
        wrong = [n for n, g, e in zip(NAMES, got, expect) if g != e]
        assert not wrong, f"{method}, float64 at 1e8: wrong answers for {wrong}"


def segments(ta, tb, device, tol=TOLERANCE, precision="float32"):
    """``(kind, (P, 2, 3) segment)`` of Möller's test, computed in ``precision``."""
    n = len(ta)
    _, vec3, _, _ = precision_types(precision)
    dtype = np.dtype(precision)
    kind = wp.zeros(n, dtype=wp.int32, device=device)
    seg = wp.zeros((n, 2), dtype=vec3, device=device)
    wp.launch(tri_tri_segment_batch_kernel, dim=n,
              inputs=[wp.array(np.asarray(ta, dtype), dtype=vec3, device=device),
                      wp.array(np.asarray(tb, dtype), dtype=vec3, device=device), wp.float64(tol)],
              outputs=[kind, seg], device=device)
    return kind.numpy(), seg.numpy().reshape(n, 2, 3)


@pytest.mark.parametrize("precision", ["float32", "float64"])
def test_degenerate_segments(device, precision):
    """Where a degenerate triangle meets: the crossing point, or the part of a sliver over the face."""
    names = ["sliver_crossing", "sliver_in_plane", "sliver_along_edge", "point_on_face", "slivers_crossing",
             "slivers_collinear_overlap", "sliver_crossing_beside"]
    ta = np.array([CASES[n][0] for n in names])
    tb = np.array([CASES[n][1] for n in names])
    kind, seg = segments(ta, tb, device, precision=precision)
    assert kind.tolist() == [CONTACT_SEGMENT] * 6 + [CONTACT_NONE]
    ends = {n: np.sort(s, axis=0) for n, s in zip(names, seg)}  # end points in either order
    expected = {
        "sliver_crossing": [[0.5, 0.5, 0], [0.5, 0.5, 0]],
        "sliver_in_plane": [[0, 0.5, 0], [1.5, 0.5, 0]],  # clipped to the triangle
        "sliver_along_edge": [[1, 0, 0], [2, 0, 0]],
        "point_on_face": [[0.5, 0.5, 0], [0.5, 0.5, 0]],
        "slivers_crossing": [[1, 1, 0], [1, 1, 0]],
        "slivers_collinear_overlap": [[1, 0, 0], [2, 0, 0]],
    }
    for n, e in expected.items():
        assert np.allclose(ends[n], e, atol=1e-4), (n, ends[n])


# ---------------------------------------------------------------------------------------------
# Seeded random degenerate pairs against the float64 reference


def random_degenerate_pairs(rng, n):
    """``(ta, tb)`` float64 ``(n, 3, 3)``: slivers (doubled area 1e-12..1e-6 of the longest edge
    squared), points and repeated-vertex segments against proper triangles, crossing them, in
    their plane, or passing near their edges and vertices; and pairs of slivers and points a
    controlled distance apart. A random rigid motion is applied to each pair."""
    tb = rng.uniform(-1, 1, size=(n, 3, 3))
    nb = np.cross(tb[:, 1] - tb[:, 0], tb[:, 2] - tb[:, 0])
    unit_n = nb / np.linalg.norm(nb, axis=1, keepdims=True)
    # A target point on b: barycentric coordinates in [-0.1, 1.1] (some outside), or on an edge.
    w = rng.uniform(-0.1, 1.1, size=(n, 3))
    on_edge = rng.random(n) < 0.4
    w[on_edge, rng.integers(0, 3, size=on_edge.sum())] = 0.0
    w /= w.sum(axis=1, keepdims=True)
    w = np.where(np.isfinite(w), w, 1.0 / 3.0)
    target = np.einsum("nk,nkj->nj", w, tb)
    size = np.linalg.norm(tb - np.roll(tb, 1, axis=1), axis=2).max(axis=1)
    gap = rng.choice([0.0, 1e-7, 1e-6, 1e-5, 1e-4, 1e-3, 1e-2], size=n) * size
    kind = rng.integers(0, 4, size=n)  # 0 across the plane, 1 in the plane, 2 point, 3 sliver pair
    direction = rng.normal(size=(n, 3))
    in_plane = direction - unit_n * np.sum(direction * unit_n, axis=1, keepdims=True)
    direction = np.where((kind == 1)[:, None], in_plane, direction)
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    offset = rng.normal(size=(n, 3))
    offset /= np.linalg.norm(offset, axis=1, keepdims=True)
    offset = np.where((kind == 1)[:, None], unit_n * rng.choice([-1.0, 1.0], size=(n, 1)), offset)
    start = target + offset * gap[:, None]
    s0 = -rng.uniform(0, 1, size=n)
    s1 = rng.uniform(0, 1, size=n)
    p = start + direction * s0[:, None]
    q = start + direction * s1[:, None]
    q[kind == 2] = p[kind == 2] = start[kind == 2]
    lift = rng.choice([0.0, 1e-12, 1e-10, 1e-8, 1e-6], size=n)
    side = np.cross(direction, rng.normal(size=(n, 3)))
    side /= np.linalg.norm(side, axis=1, keepdims=True)
    third = p + (q - p) * rng.uniform(0, 1, size=(n, 1)) + side * (lift * np.linalg.norm(q - p, axis=1))[:, None]
    ta = np.stack([p, q, third], axis=1)
    repeated = rng.random(n) < 0.15
    ta[repeated, 2] = ta[repeated, 0]
    # Sliver pairs: b becomes a sliver through a point of a's segment, moved by the gap.
    pair = kind == 3
    on_a = p + (q - p) * rng.uniform(0, 1, size=(n, 1))
    dir_b = rng.normal(size=(n, 3))
    dir_b /= np.linalg.norm(dir_b, axis=1, keepdims=True)
    parallel = rng.random(n) < 0.2
    dir_b[parallel] = direction[parallel]
    centre_b = on_a + offset * gap[:, None]
    pb = centre_b - dir_b * rng.uniform(0, 1, size=(n, 1))
    qb = centre_b + dir_b * rng.uniform(0, 1, size=(n, 1))
    tb[pair] = np.stack([pb, qb, pb + (qb - pb) * 0.5 + side * 1e-9], axis=1)[pair]
    r = random_rotations(rng, n)
    move = rng.uniform(-5, 5, size=(n, 1, 3))
    return np.einsum("nij,nkj->nki", r, ta) + move, np.einsum("nij,nkj->nki", r, tb) + move


@pytest.mark.parametrize("precision", ["float32", "float64"])
def test_random_degenerate_pairs_match_float64_reference(device, precision):
    rng = np.random.default_rng(29)
    ta, tb = random_degenerate_pairs(rng, 20_000)
    if precision == "float32":  # the reference judges the very coordinates the kernel sees
        ta, tb = ta.astype(np.float32).astype(np.float64), tb.astype(np.float32).astype(np.float64)
    must_hit, must_miss = touching_band(ta, tb, TOLERANCE)
    assert must_hit.mean() > 0.2 and must_miss.mean() > 0.2  # the sample holds both answers
    for method in NARROW_METHODS:
        for a, b in ((ta, tb), (tb, ta)):
            got = run_test(a, b, device, method, precision=precision)
            missed = np.nonzero(must_hit & ~got)[0]
            false = np.nonzero(must_miss & got)[0]
            assert not len(missed), f"{method} {precision}: {len(missed)} touching pairs missed, e.g. {missed[:5]}"
            assert not len(false), f"{method} {precision}: {len(false)} pairs apart reported, e.g. {false[:5]}"


# ---------------------------------------------------------------------------------------------
# Whole meshes with slivers: fan-triangulated polygons


def fan_box(half=1.0, splits=3, lift=0.0):
    """A closed box whose square faces carry ``splits`` extra points on each edge (as a CAD export
    that splits edges does) and are fan-triangulated from one corner: most triangles along the
    split edges are slivers of zero area (``lift`` moves the split points outward, making them
    thin but proper)."""
    vertices, triangles = [], []
    for axis in range(3):
        for sign in (-1.0, 1.0):
            u, v = (axis + 1) % 3, (axis + 2) % 3
            ring = []
            corners = [(-1, -1), (1, -1), (1, 1), (-1, 1)]
            for k in range(4):
                (a0, b0), (a1, b1) = corners[k], corners[(k + 1) % 4]
                for s in range(splits + 1):
                    t = s / (splits + 1)
                    ring.append(((1 - t) * a0 + t * a1, (1 - t) * b0 + t * b1, 0.0 if s == 0 else lift))
            base = len(vertices)
            for a, b, out in ring:
                x = np.zeros(3)
                x[axis] = sign * (half + out)
                x[u], x[v] = a * half, b * half
                vertices.append(x)
            m = len(ring)
            for k in range(1, m - 1):
                tri = [base, base + k, base + k + 1]
                triangles.append(tri if sign > 0 else tri[::-1])
    v = np.array(vertices)
    # Merge the duplicated corner and split points so that the box is closed.
    key = np.round(v * 1e6).astype(np.int64)
    _, first, inverse = np.unique(key, axis=0, return_index=True, return_inverse=True)
    return v[first].astype(np.float32), inverse.reshape(-1)[np.array(triangles)].astype(np.int32)


def test_fan_triangulated_meshes_against_reference(device):
    """Two boxes with sliver-laden faces, overlapping: every triangle pair the float64 reference
    calls touching is found (slivers included), none it calls apart."""
    v, t = fan_box()
    flat = np.linalg.norm(np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]]), axis=1) == 0
    assert flat.sum() >= 12  # the mesh does have zero-area triangles
    r = random_rotations(np.random.default_rng(3), 1)[0]
    other = (v @ r.T * 0.8 + np.float32([1.1, 0.4, -0.3])).astype(np.float32)
    res = wc.collide([(v, t), (other, t)], device=device)
    ta = np.repeat(v[t].astype(np.float64), len(t), axis=0)
    tb = np.tile(other[t].astype(np.float64), (len(t), 1, 1))
    must_touch, must_miss = touching_band(ta, tb, TOLERANCE)
    index = np.stack([np.repeat(np.arange(len(t)), len(t)), np.tile(np.arange(len(t)), len(t))], axis=1)
    found = {tuple(r) for r in res.triangle_pairs[:, [1, 3]].tolist()}
    must = {tuple(r) for r in index[must_touch].tolist()}
    never = {tuple(r) for r in index[must_miss].tolist()}
    assert must and must <= found, f"missed {sorted(must - found)[:5]}"
    assert not (found & never), f"reported apart pairs {sorted(found & never)[:5]}"
    sliver_pairs = [(a, b) for a, b in must if flat[a] or flat[b]]
    assert sliver_pairs and set(sliver_pairs) <= found  # contacts through slivers are found


def test_containment_with_sliver_faces(device):
    """The winding number of a closed mesh with zero-area triangles still tells inside from outside."""
    v, t = fan_box(half=2.0)
    inner_v, inner_t = wc.scene.shape("octahedron")
    meshes = [(v, t), (inner_v * 0.5 + np.float32([0.3, -0.2, 0.1]), inner_t),
              (inner_v * 0.5 + np.float32([5.0, 0.0, 0.0]), inner_t)]
    res = wc.collide(meshes, device=device, containment=True)
    assert res.object_pairs.shape == (0, 2)
    assert res.containment_pairs.tolist() == [[1, 0]]
