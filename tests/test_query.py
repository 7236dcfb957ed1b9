"""Least distances however far apart (``wc.distance``, ``wc.DistanceQuery``: branch and bound over two
trees), on every device: against a float64 brute force over the triangle pairs that could be closer
than the answer, python-fcl's ``distance`` with nearest points (and its builds), and crafted cases."""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp

import warp_ccd as wc
from warp_ccd._src.scene.shapes import icosphere, shape

from oracles import fcl_model, fcl_pair_distance, pair_distance_brute
from test_clearance import _box, asset_meshes


def _check_brute(meshes, res, rel):
    """Each row's distance is the least over all triangle pairs (brute force over those whose boxes
    come within the answer: no farther pair can be closer), its triangles attain it, its points lie
    ``distance`` apart along the normal."""
    size = max(np.abs(v).max() for v, _ in meshes) + 1.0
    for row, (a, b) in enumerate(res.pairs):
        d = res.distance[row]
        ref, rows = pair_distance_brute(meshes[a], meshes[b], reach=d + 4 * rel * size)
        assert abs(ref - d) <= rel * size, (a, b, ref, d)
        p, q = res.closest_points[row]
        assert abs(np.linalg.norm(q - p) - d) <= 4 * rel * size
        if d > 1e-3:
            np.testing.assert_allclose(res.normal[row], (q - p) / d, atol=1e-4)


@pytest.mark.parametrize("precision", ["float32", "float64"])
def test_spheres_far_apart_match_brute_force(device, precision):
    rng = np.random.default_rng(3)
    v, t = icosphere(3)
    meshes = [(v * rng.uniform(0.5, 1.5) + rng.uniform(-6, 6, 3), t) for _ in range(6)]
    res = wc.distance(meshes, device=device, precision=precision)
    assert res.pairs.shape == (15, 2) and (res.pairs[:, 0] < res.pairs[:, 1]).all()
    _check_brute(meshes, res, {"float32": 2e-6, "float64": 1e-9}[precision])
    assert res.distance.min() > 1.0 and not res.intersecting.any()


def test_rotated_polyhedra_with_transforms(device):
    """Rigid transforms (rotations, the trees in shape space), one set against another."""
    rng = np.random.default_rng(5)
    names = ("cube", "dodecahedron", "icosahedron", "tetrahedron")
    arms = [shape(n) for n in names]
    table = [_box([-3, -3, -1], [3, 3, 0])]
    q = rng.normal(size=(4, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    mats = np.zeros((4, 4, 4))
    for k in range(4):
        x, y, z, w = q[k]
        mats[k, :3, :3] = [[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                           [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                           [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]]
        mats[k, :3, 3] = [k - 1.5, 0.3 * k, 1.5 + 0.7 * k]
        mats[k, 3, 3] = 1.0
    res = wc.distance(arms, table, transforms_a=mats, device=device, precision="float64")
    np.testing.assert_array_equal(res.pairs, [[k, 0] for k in range(4)])
    world = [((v @ mats[k, :3, :3].T + mats[k, :3, 3]), t) for k, (v, t) in enumerate(arms)] + table
    shifted = wc.distance(world[:4], table, device=device, precision="float64")
    np.testing.assert_allclose(res.distance, shifted.distance, rtol=1e-12)
    # The table's top is z = 0: each distance is the lowest vertex's height.
    low = np.array([v[:, 2].min() for v, _ in world[:4]])
    np.testing.assert_allclose(res.distance, low, rtol=1e-12)
    assert (res.normal[:, 2] < -0.999).all()


def test_intersecting_pairs_at_minus_their_depth_touching_ones_at_zero(device):
    a = _box([0, 0, 0], [1, 1, 1])
    others = [_box([0.5, 0.5, 0.5], [2, 2, 2]), _box([1, 0, 0], [2, 1, 1]), _box([3, 0, 0], [4, 1, 1])]
    res = wc.distance([a], others, device=device)
    np.testing.assert_allclose(res.distance, [-0.5, 0.0, 2.0], atol=1e-6)  # the corner 0.5 deep both ways
    np.testing.assert_array_equal(res.intersecting, [True, True, False])
    assert np.linalg.norm(res.closest_points[0, 0] - res.closest_points[0, 1]) == pytest.approx(0.5, rel=1e-6)
    assert (res.closest_points[1, 0] == res.closest_points[1, 1]).all()
    unsigned = wc.distance([a], others, device=device, signed=False)
    np.testing.assert_allclose(unsigned.distance, [0.0, 0.0, 2.0], atol=1e-6)
    for row in (0, 1):
        assert (unsigned.closest_points[row, 0] == unsigned.closest_points[row, 1]).all()


def test_python_fcl_agrees_on_real_meshes(device):
    """The scanned bunny against the RJ45 plug's CAD parts, metres apart: python-fcl's distances and
    nearest points."""
    pytest.importorskip("fcl")
    bunny = asset_meshes("bunny.usd", device)
    parts = asset_meshes("rj45_plug.usd", device)
    placed = [((v - v.mean(axis=0)) * 10.0 + [1.5 + k, 2.0 - 0.5 * k, 0.4 * k], t) for k, (v, t) in enumerate(parts)]
    res = wc.distance(bunny, placed, device=device, precision="float64")
    objs_a = [fcl_model(v, t) for v, t in bunny]
    objs_b = [fcl_model(v, t) for v, t in placed]
    for row, (i, j) in enumerate(res.pairs):
        d, nearest, hit = fcl_pair_distance(objs_a[i], objs_b[j])
        assert not hit
        assert abs(res.distance[row] - d) <= 1e-9 * max(1.0, d), (i, j, res.distance[row], d)
    assert res.distance.min() > 0.1


def test_pairs_argument_and_one_mesh(device):
    v, t = icosphere(2)
    meshes = [(v + [3.0 * k, 0, 0], t) for k in range(4)]
    res = wc.distance(meshes, pairs=[[0, 3], [2, 1]], device=device)
    np.testing.assert_array_equal(res.pairs, [[0, 3], [2, 1]])
    np.testing.assert_allclose(res.distance, [7.0, 1.0], rtol=2e-2)  # icosphere vertices on the unit sphere
    one = wc.distance(meshes[0], meshes[1], device=device)
    assert one.pairs.tolist() == [[0, 0]] and abs(one.distance[0] - res.distance[1]) < 1e-6
    cross = wc.distance(meshes[:2], meshes[2:], pairs=[[1, 1], [0, 0]], device=device)
    full = wc.distance(meshes, device=device)
    row = {tuple(p): d for p, d in zip(full.pairs.tolist(), full.distance)}
    np.testing.assert_array_equal(cross.distance, [row[(1, 3)], row[(0, 2)]])


def test_persistent_query_moves_and_deforms(device):
    """A DistanceQuery measures again after the scene moves (rigid) or deforms (trees refit)."""
    v, t = icosphere(2)
    scene = wc.Scene([(v, t)], np.zeros(3, np.int64), poses=np.array([[0, 0, 0, 0, 0, 0, 1.0],
                                                                      [4, 0, 0, 0, 0, 0, 1.0],
                                                                      [0, 9, 0, 0, 0, 0, 1.0]]), device=device)
    query = wc.DistanceQuery(scene, [[0, 1], [0, 2]])
    first = query.query().distance.copy()
    poses = scene.object_pose.numpy()
    poses[1, 0] = 6.0
    scene.set_poses(wp.array(poses, dtype=wp.transform, device=device))
    second = query.query().distance
    np.testing.assert_allclose(second - first, [2.0, 0.0], atol=1e-5)
    deforming = wc.Scene([(v, t)] * 2, np.arange(2), deforming=True, device=device)
    moving = wc.DistanceQuery(deforming, [[0, 1]])
    deforming.set_world_vertices(np.concatenate([v, v * 0.5 + [5.0, 0, 0]]))
    np.testing.assert_allclose(moving.query().distance, [3.5], rtol=2e-2)


def test_set_pairs_measures_other_pairs_on_the_same_trees(device):
    """A DistanceQuery given other pairs (more than it held, then fewer) answers as a new query would."""
    v, t = icosphere(2)
    meshes = [(v + [3.0 * k, 0, 0], t) for k in range(5)]
    scene = wc.Scene.from_meshes(meshes, device=device)
    query = wc.DistanceQuery(scene, [[0, 1]])
    bvh = query.bvh
    for pairs in ([[0, 4], [3, 1], [2, 4]], [[4, 3]], []):
        query.set_pairs(pairs)
        res = query.query()
        fresh = wc.DistanceQuery(scene, pairs).query()
        np.testing.assert_array_equal(res.pairs, np.reshape(pairs, (-1, 2)))
        np.testing.assert_array_equal(res.distance, fresh.distance)
        np.testing.assert_array_equal(res.closest_triangles, fresh.closest_triangles)
    assert query.bvh is bvh
    with pytest.raises(ValueError, match="itself"):
        query.set_pairs([[2, 2]])


def test_small_capacities_grow_to_the_same_answer(device):
    rng = np.random.default_rng(8)
    v, t = icosphere(3)
    meshes = [(v + rng.uniform(-3, 3, 3), t) for _ in range(4)]
    scene = wc.Scene.from_meshes(meshes, device=device)
    big = wc.DistanceQuery(scene).query()
    small = wc.DistanceQuery(scene, front_capacity=1, listed_capacity=1).query()
    assert small.runs > 1
    np.testing.assert_array_equal(small.distance, big.distance)
    np.testing.assert_array_equal(small.closest_triangles, big.closest_triangles)


@pytest.mark.parametrize("bad, match", [
    ([[0, 0]], "itself"), ([[0, 5]], r"\[0, 3\)"), (np.zeros((2, 3), int), r"\(P, 2\)"), ([[0.5, 1]], "integer"),
])
def test_bad_pairs_are_refused(device, bad, match):
    v, t = icosphere(1)
    with pytest.raises(ValueError, match=match):
        wc.distance([(v, t), (v + 3, t), (v - 3, t)], pairs=bad, device=device)


def test_bad_meshes_are_named(device):
    v, t = icosphere(1)
    with pytest.raises(ValueError, match="meshes_b mesh 1"):
        wc.distance([(v, t)], [(v + 3, t), (v, t + 1000)], device=device)
    with pytest.raises(ValueError, match="transforms_a"):
        wc.distance([(v, t)], [(v + 3, t)], transforms_a=np.eye(4)[None].repeat(2, 0), device=device)


def test_no_pairs_and_copies(device):
    v, t = icosphere(1)
    none = wc.distance([(v, t), (v + 3, t)], pairs=[], device=device)
    assert none.pairs.shape == (0, 2) and none.distance.shape == (0,)
    scene = wc.Scene.from_meshes([(v, t), (v + 3, t)], device=device)
    query = wc.DistanceQuery(scene)
    kept = query.query().copy()
    poses = scene.object_pose.numpy()
    poses[1, 0] = 5.0
    scene.set_poses(wp.array(poses, dtype=wp.transform, device=device))
    moved = query.query()
    assert moved.distance[0] > kept.distance[0] + 1.9

