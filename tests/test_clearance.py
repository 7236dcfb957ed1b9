"""Clearance (``CollisionPipeline(scene, clearance=d)``, ``collide(..., clearance=d)``): every object pair
within ``d``, its least distance, closest points, direction and closest triangles, on every device.

Against a float64 numpy brute force over all triangle pairs (``oracles.clearance_pairs_brute``) and
python-fcl's ``distance`` with nearest points, on seeded scenes of polyhedra (whole-object pairs),
scaled icospheres (tree traversal), rigid and deforming objects, both precisions and both mid phases,
and on real meshes (the scanned bunny, CAD parts from newton's assets); crafted cases: cubes a gap
apart, touching, a crate sunk in a floor, overlapping spheres, far from the origin, tiny, empty."""

from __future__ import annotations

import importlib.util
import os

import numpy as np
import pytest
import warp as wp

import warp_ccd as wc
from warp_ccd._src.scene.shapes import cube, icosphere, shape

from distance_reference import point_on_triangle_sq, triangle_distance
from oracles import clearance_pairs_brute, fcl_model, fcl_pair_distance, pair_distance_brute

POLYHEDRA = ("tetrahedron", "cube", "octahedron", "icosahedron", "dodecahedron")


def _rotations(rng, n):
    q = rng.normal(size=(n, 4))
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def polyhedra_scene(device, precision, seed=1, n=24, spread=5.0, deforming=False):
    """Polyhedra (whole-object pairs) at random places and orientations; ``deforming``: half of them
    deforming, their world vertices set from the poses and sheared a little."""
    rng = np.random.default_rng(seed)
    shapes = [shape(s) for s in POLYHEDRA]
    poses = np.concatenate([rng.uniform(0, spread, (n, 3)), _rotations(rng, n)], axis=1)
    mask = (np.arange(n) % 2 == 0) if deforming else False
    scene = wc.Scene(shapes, rng.integers(0, len(shapes), n), poses=poses, device=device, precision=precision,
                     deforming=mask)
    if deforming:
        v = scene.world_vertex.numpy().astype(np.float64)
        own = np.repeat(mask, np.diff(scene.object_vertex_start_np))
        v[own] += 0.15 * np.sin(3.0 * v[own][:, [1, 2, 0]])
        scene.set_world_vertices(v)
    return scene


def spheres_scene(device, precision, seed=2, n=10, spread=3.5):
    """Icospheres of 80 and 320 triangles (trees), scaled 0.5 to 1.5, at random places."""
    rng = np.random.default_rng(seed)
    shapes = [icosphere(1), icosphere(2)]
    poses = np.concatenate([rng.uniform(0, spread, (n, 3)), _rotations(rng, n)], axis=1)
    return wc.Scene(shapes, rng.integers(0, 2, n), object_scale=rng.uniform(0.5, 1.5, n), poses=poses, device=device,
                    precision=precision)


def world(scene):
    return [(v.astype(np.float64), t) for v, t in scene.world_meshes()]


def check_against_brute(scene, res, clearance: float, rel: float):
    """The pipeline's rows against the brute force: the same pairs (up to those within ``rel`` of
    the clearance, either answer right), distances within ``rel`` of the scene's size, points on
    their triangles, ``|p - q|`` the distance, unit normals along ``q - p``."""
    meshes = world(scene)
    size = max(np.abs(v).max() for v, _ in meshes) + 1.0
    ref = clearance_pairs_brute(meshes, clearance * (1 + rel) + rel * size)
    got = {tuple(p): d for p, d in zip(res.object_pairs.tolist(), res.object_distance)}
    must = {k for k, d in ref.items() if d <= clearance - rel * size}
    assert must <= set(got), f"missing pairs {sorted(must - set(got))[:5]}"
    assert set(got) <= set(ref), f"extra pairs {sorted(set(got) - set(ref))[:5]}"
    for k, d in got.items():
        assert abs(d - ref[k]) <= rel * size, (k, d, ref[k])
    points = res.closest_points
    for row, (a, b) in enumerate(res.object_pairs):
        ta, tb = res.closest_triangles[row]
        for side, (obj, tri) in enumerate(((a, ta), (b, tb))):
            v, t = meshes[obj]
            assert float(point_on_triangle_sq(points[row, side], v[t[tri]])) ** 0.5 <= 64 * rel * size
    gap = np.linalg.norm(points[:, 0] - points[:, 1], axis=1)
    np.testing.assert_allclose(gap, res.object_distance, rtol=0, atol=64 * rel * size)
    assert np.allclose(np.linalg.norm(res.object_normal, axis=1), 1.0, atol=1e-5)
    apart = res.object_distance > 1e-3 * clearance
    along = np.einsum("ij,ij->i", res.object_normal[apart], points[apart, 1] - points[apart, 0])
    np.testing.assert_allclose(along, res.object_distance[apart], rtol=1e-3)
    # Intersecting rows are exactly the object pairs of the intersecting triangle pairs.
    inter = {tuple(p) for p in res.triangle_pairs[:, [0, 2]].tolist()}
    assert {tuple(p) for p, i in zip(res.object_pairs.tolist(), res.object_intersecting) if i} == inter
    assert (res.object_distance[res.object_intersecting] == 0).all()
    near = np.zeros(scene.num_objects, bool)
    near[res.object_pairs.ravel()] = True
    np.testing.assert_array_equal(res.near, near)
    return ref


REL = {"float32": 2e-6, "float64": 1e-9}


@pytest.mark.parametrize("precision", ["float32", "float64"])
@pytest.mark.parametrize("mid", ["bvh", "all_pairs"])
def test_polyhedra_match_brute_force(device, precision, mid):
    scene = polyhedra_scene(device, precision)
    res = wc.CollisionPipeline(scene, clearance=0.6, mid_phase=mid).detect()
    ref = check_against_brute(scene, res, 0.6, REL[precision])
    assert len(ref) > 20 and res.object_intersecting.sum() > 3


@pytest.mark.parametrize("precision", ["float32", "float64"])
@pytest.mark.parametrize("options", [{}, {"leaf_size": 4}, {"separating_axes": 3}, {"mid_phase": "all_pairs"}])
def test_scaled_spheres_match_brute_force(device, precision, options):
    scene = spheres_scene(device, precision)
    res = wc.CollisionPipeline(scene, clearance=0.3, **options).detect()
    ref = check_against_brute(scene, res, 0.3, REL[precision])
    assert len(ref) >= 8 and 0 < res.object_intersecting.sum() < len(ref)


@pytest.mark.parametrize("precision", ["float32", "float64"])
def test_deforming_objects_match_brute_force(device, precision):
    scene = polyhedra_scene(device, precision, seed=5, deforming=True)
    for leaf in (1, 4):
        res = wc.CollisionPipeline(scene, clearance=0.5, leaf_size=leaf).detect()
        check_against_brute(scene, res, 0.5, REL[precision])


def test_zero_clearance_is_todays_answer(device):
    scene = spheres_scene(device, "float32")
    plain = wc.CollisionPipeline(scene).detect()
    zero = wc.CollisionPipeline(scene, clearance=0.0).detect()
    assert zero.object_distance is None and zero.near is None and zero.clearance == 0.0
    np.testing.assert_array_equal(plain.triangle_pairs, zero.triangle_pairs)
    np.testing.assert_array_equal(plain.object_pairs, zero.object_pairs)
    # With a clearance the intersecting triangle pairs and flags are those of the plain frame.
    near = wc.CollisionPipeline(scene, clearance=0.4).detect()
    np.testing.assert_array_equal(plain.triangle_pairs, near.triangle_pairs)
    np.testing.assert_array_equal(plain.colliding, near.colliding)
    assert set(map(tuple, plain.object_pairs.tolist())) < set(map(tuple, near.object_pairs.tolist()))


def test_a_frame_sequence_and_graphs(device):
    """A persistent pipeline over moving frames (graphs on CUDA) gives each frame's brute-force rows,
    and the same rows as an eager pipeline."""
    scene = wc.Scene.random(num_objects=40, seed=3, device=device)
    pipe = wc.CollisionPipeline(scene, clearance=0.25)
    eager = wc.CollisionPipeline(scene, clearance=0.25, graph=False)
    for _ in range(3):
        scene.advance(0.05)
        res = pipe.detect()
        check_against_brute(scene, res, 0.25, REL["float32"])
        other = eager.detect()
        np.testing.assert_array_equal(res.object_pairs, other.object_pairs)
        np.testing.assert_array_equal(res.object_distance, other.object_distance)
        np.testing.assert_array_equal(res.closest_triangles, other.closest_triangles)


def test_buffers_grow_and_the_rows_stay(device):
    scene = polyhedra_scene(device, "float32")
    big = wc.CollisionPipeline(scene, clearance=0.6).detect()
    small = wc.CollisionPipeline(scene, clearance=0.6, near_capacity=1, pair_capacity=1, candidate_capacity=1,
                                 hit_capacity=1)
    res = small.detect()
    assert res.runs > 1
    for name in ("object_pairs", "object_distance", "closest_points", "object_normal", "closest_triangles",
                 "object_intersecting", "near"):
        np.testing.assert_array_equal(getattr(res, name), getattr(big, name))
    copy = res.copy()
    small.detect()
    np.testing.assert_array_equal(copy.object_distance, big.object_distance)


def test_the_answer_is_deterministic(device):
    scene = spheres_scene(device, "float32", seed=9)
    first = wc.CollisionPipeline(scene, clearance=0.3).detect()
    again = wc.CollisionPipeline(scene, clearance=0.3, candidate_capacity=7).detect()
    for name in ("object_pairs", "object_distance", "closest_points", "closest_triangles"):
        np.testing.assert_array_equal(getattr(first, name), getattr(again, name))


def _box(lo, hi):
    """An axis-aligned box mesh (outward-wound) from ``lo`` to ``hi``."""
    v, t = cube()  # corners at +-1/sqrt(3)
    v = np.sign(v)
    lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
    return (v + 1.0) * 0.5 * (hi - lo) + lo, t


def test_cubes_a_gap_apart(device):
    """The new user's first question: two unit cubes 0.05 apart."""
    a = _box([0, 0, 0], [1, 1, 1])
    b = _box([1.05, 0.2, 0.1], [2.05, 1.2, 1.1])
    res = wc.collide([a, b], clearance=0.1, device=device)
    np.testing.assert_array_equal(res.object_pairs, [[0, 1]])
    assert abs(res.object_distance[0] - 0.05) < 1e-6
    np.testing.assert_allclose(res.object_normal[0], [1, 0, 0], atol=1e-5)  # float32 points: ulp(1) / 0.05
    np.testing.assert_allclose(res.closest_points[0, :, 0], [1.0, 1.05], atol=1e-6)
    assert not res.object_intersecting[0] and not res.colliding.any() and res.near.all()
    assert len(wc.collide([a, b], clearance=0.04, device=device).object_pairs) == 0
    touching = wc.collide([a, _box([1, 0, 0], [2, 1, 1])], clearance=0.01, device=device)
    assert touching.object_distance[0] == 0.0 and touching.object_intersecting[0]


def test_crate_sunk_in_a_floor_points_up(device):
    """An intersecting pair's direction: a crate sunk into a floor (whatever the floor's triangles),
    the floor's normal; two overlapping spheres, the line of their centres."""
    floor = _box([-5, -5, -1], [5, 5, 0])
    crate = _box([-0.5, -0.3, -0.2], [0.5, 0.7, 0.8])
    res = wc.collide([floor, crate], clearance=0.01, device=device)
    assert res.object_intersecting[0] and res.object_distance[0] == 0.0
    np.testing.assert_allclose(res.object_normal[0], [0, 0, 1], atol=1e-6)
    p = res.closest_points[0, 0]
    assert abs(p[2]) < 1e-6 and (p == res.closest_points[0, 1]).all()
    v, t = icosphere(3)
    centres = np.array([[0.0, 0.0, 0.0], [1.2, 0.9, -0.4]])
    res = wc.collide([(v + c, t) for c in centres], clearance=0.01, device=device)
    line = (centres[1] - centres[0]) / np.linalg.norm(centres[1] - centres[0])
    assert res.object_intersecting[0] and np.dot(res.object_normal[0], line) > 0.995


def test_a_vertex_over_a_thin_face(device):
    """Regressions: a vertex over a thin face near its long edge. The closest point is inside the face
    (Ericson's products of dot products put it on the long edge, 8% too far in float32), and a float64
    pair exactly at its distance is within a clearance 3.6e-14 above it (a separating plane of a thin
    float64 triangle, its normal turned by rounding, once ruled it out)."""
    t = np.array([[0, 1, 2]])
    a = np.array([[-0.43159768, 0.2970944, 0.392432], [-0.5148065, 0.30719745, 1.0361987],
                  [-0.48223013, 0.3030965, 0.78469718]], np.float32).astype(np.float64)
    b = np.array([[-0.47163823, 0.30197608, 0.70325524], [-0.07324737, 0.1646561, 0.65398103],
                  [-0.4165917, 0.64257765, 0.80794746]], np.float32).astype(np.float64)
    exact = triangle_distance(a, b)
    res = wc.collide([(a, t), (b, t)], clearance=exact * 1.04, device=device)
    assert len(res.object_pairs) == 1 and abs(res.object_distance[0] - exact) < 1e-7  # float32: a few ulp of 0.6
    assert abs(wc.distance((a, t), (b, t), device=device).distance[0] - exact) < 1e-7
    a = np.array([[0.7377085886946386, 0.2681399586948865, -0.00685661240229396],
                  [0.21585915675600886, 0.8136754425040781, -0.4091521293082436],
                  [0.4575276673616038, 0.5609208199260912, -0.22287543121586423]])
    b = np.array([[0.3956497574918546, 0.5308514168645914, -0.1387253408841634],
                  [0.14524018957587825, 0.7799267059524224, 0.09634177434454608],
                  [0.29576023442622357, 0.2033509600073351, -0.02574067847368741]])
    for mid in ("bvh", "all_pairs"):
        res = wc.collide([(a, t), (b, t)], clearance=0.10664512417501185, mid_phase=mid, precision="float64",
                         device=device)
        assert len(res.object_pairs) == 1 and abs(res.object_distance[0] - 0.10664512417497554) < 1e-15


def test_far_from_the_origin_in_float64(device):
    a = _box([0, 0, 0], [1, 1, 1])
    b = _box([1.25, 0.0, 0.0], [2.25, 1, 1])
    near = wc.collide([a, b], clearance=0.3, precision="float64", device=device)
    shift = np.array([3e7, -2e7, 1e7])
    far = wc.collide([(a[0] + shift, a[1]), (b[0] + shift, b[1])], clearance=0.3, precision="float64",
                     device=device)
    assert abs(far.object_distance[0] - 0.25) < 1e-8 and abs(near.object_distance[0] - 0.25) < 1e-14
    np.testing.assert_allclose(far.closest_points[0] - shift, near.closest_points[0], atol=1e-8)


def test_tiny_scene_scales(device):
    a = _box([0, 0, 0], [1, 1, 1])
    b = _box([1.25, 0.3, 0.0], [2.25, 1.3, 1])
    for scale in (1e-4, 1e3):
        res = wc.collide([(a[0] * scale, a[1]), (b[0] * scale, b[1])], clearance=0.3 * scale, device=device,
                         precision="float64")
        assert abs(res.object_distance[0] / scale - 0.25) < 1e-12


def test_empty_and_single_object(device):
    res = wc.collide([], clearance=1.0, device=device)
    assert res.object_pairs.shape == (0, 2) and res.object_distance.shape == (0,)
    assert res.closest_points.shape == (0, 2, 3) and res.near.shape == (0,)
    one = wc.collide([_box([0, 0, 0], [1, 1, 1])], clearance=1.0, device=device)
    assert one.object_pairs.shape == (0, 2) and one.near.tolist() == [False]


@pytest.mark.parametrize("bad", [-1.0, float("nan"), float("inf"), True, "0.1", 1e39])
def test_bad_clearance_is_refused(device, bad):
    scene = polyhedra_scene(device, "float32", n=3)
    with pytest.raises(ValueError, match="clearance"):
        wc.CollisionPipeline(scene, clearance=bad)


def test_clearance_is_not_continuous(device):
    scene = polyhedra_scene(device, "float32", n=3)
    with pytest.raises(ValueError, match="min_distance"):
        wc.CollisionPipeline(scene, clearance=0.1, continuous=True)


def test_python_fcl_agrees(device):
    """python-fcl's distance (nearest points) and collide, pair by pair: the same pairs within the
    clearance, the same distances for those apart."""
    pytest.importorskip("fcl")
    scene = spheres_scene(device, "float64", seed=4, n=12)
    clearance = 0.35
    res = wc.CollisionPipeline(scene, clearance=clearance).detect()
    meshes = world(scene)
    objs = [fcl_model(v, t) for v, t in meshes]
    got = {tuple(p): (d, i) for p, d, i in zip(res.object_pairs.tolist(), res.object_distance,
                                               res.object_intersecting)}
    within = 0
    for a in range(len(objs)):
        for b in range(a + 1, len(objs)):
            d, nearest, hit = fcl_pair_distance(objs[a], objs[b])
            if hit:
                assert (a, b) in got and got[(a, b)][1], (a, b)
            elif abs(d - clearance) > 1e-9:
                assert ((a, b) in got) == (d < clearance), (a, b, d)
                if d < clearance:
                    within += 1
                    assert abs(got[(a, b)][0] - d) <= 1e-9, (a, b, got[(a, b)][0], d)
                    assert abs(np.linalg.norm(nearest[0] - nearest[1]) - d) <= 1e-9
    assert within >= 5


def _newton_asset(name: str) -> str:
    spec = importlib.util.find_spec("newton")
    if spec is None:
        pytest.skip("newton is not installed (its example assets hold the bunny and the CAD parts)")
    return os.path.join(os.path.dirname(spec.origin), "examples", "assets", name)


def asset_meshes(name: str, device=None) -> list:
    """The meshes of a newton example asset, as this package's USD reader gives them (polygons fanned
    into triangles, placed by their world transforms at the stage's first time code), float64."""
    from warp_ccd.usd import scene_from_usd

    return [(v.astype(np.float64), t) for v, t in scene_from_usd(_newton_asset(name), device=device,
                                                                   precision="float64").world_meshes()]


@pytest.mark.slow
def test_real_meshes_against_fcl_and_brute_force(device):
    """The scanned bunny (12,200 triangles) and the RJ45 plug's CAD parts around it, scaled to the
    bunny's size: the same pairs and distances as python-fcl; the brute force over triangle pairs
    within reach agrees on the bunny's pairs."""
    pytest.importorskip("fcl")
    bunny = asset_meshes("bunny.usd", device)
    parts = asset_meshes("rj45_plug.usd", device)
    meshes = list(bunny)
    bv = bunny[0][0]
    centre = bv.mean(axis=0)
    for k, ((v, t), gap, anchor) in enumerate(zip(parts, (0.03, 0.08, -0.05, 0.4), (100, 2500, 4100, 5800))):
        v = (v - v.mean(axis=0)) * 12.0
        out = (bv[anchor] - centre) / np.linalg.norm(bv[anchor] - centre)
        reach = np.abs(v @ out).max()  # the part's extent along the way out
        meshes.append((v + bv[anchor] + out * (reach + gap), t))
    clearance = 0.15
    res = wc.collide(meshes, clearance=clearance, device=device, precision="float64")
    objs = [fcl_model(v, t) for v, t in meshes]
    got = {tuple(p): d for p, d in zip(res.object_pairs.tolist(), res.object_distance)}
    checked = 0
    for a in range(len(objs)):
        for b in range(a + 1, len(objs)):
            d, _, hit = fcl_pair_distance(objs[a], objs[b])
            if hit:
                assert got.get((a, b)) == 0.0
            elif abs(d - clearance) > 1e-9:
                assert ((a, b) in got) == (d < clearance), (a, b, d)
                if d < clearance:
                    assert abs(got[(a, b)] - d) <= 1e-9 * 4
                    ref, _ = pair_distance_brute(meshes[a], meshes[b], reach=d * (1 + 1e-9) + 1e-12)
                    assert abs(ref - d) <= 1e-9 * 4
                    checked += 1
    assert checked >= 2


def test_device_arrays_and_repr(device):
    scene = polyhedra_scene(device, "float64", n=12)
    res = wc.CollisionPipeline(scene, clearance=0.5).detect()
    k = len(res.object_pairs)
    assert res.device_near_pairs.shape == (k,) and res.device_near_distance.dtype == wp.float64
    assert res.device_near_points.shape == (k, 2) and res.device_near_normal.dtype == wp.vec3d
    assert "clearance=0.5" in repr(res)
