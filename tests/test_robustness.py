"""Overflow, determinism, containment and property-based tests of the triangle tests."""

import numpy as np
import pytest
import warp as wp
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import warp_ccd as wc

from conftest import CUDA_DEVICES, HOST_DEVICES
from oracles import intersect_tri_tri_f64
from test_narrow_phase import run_test


def random_rotations(rng, n):
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    x, y, z, w = q.T
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
        np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
        np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
    ], 1)


def crowded_cubes(n=300, seed=0):
    rng = np.random.default_rng(seed)
    cube = wc.scene.shape("cube")
    transforms = np.tile(np.eye(4), (n, 1, 1))
    transforms[:, :3, :3] = random_rotations(rng, n)
    transforms[:, :3, 3] = rng.normal(scale=0.05, size=(n, 3))
    return [cube] * n, transforms


@pytest.mark.parametrize("capacity", [1, None])
def test_crowded_scene_every_pair(device, capacity):
    """300 cubes around one point: every one of the 44,850 pairs, from any initial capacity."""
    meshes, transforms = crowded_cubes()
    caps = dict(pair_capacity=capacity, candidate_capacity=capacity, hit_capacity=capacity,
                front_capacity=capacity) if capacity else {}
    res = wc.collide(meshes, transforms, device=device, **caps)
    assert len(res.object_pairs) == 300 * 299 // 2
    if capacity:
        ref = wc.collide(meshes, transforms, device=device)
        assert np.array_equal(res.triangle_pairs, ref.triangle_pairs)


def test_deterministic_across_runs_and_devices():
    outputs = []
    for device in [str(d) for d in wp.get_devices()]:
        scene = wc.Scene.random(500, seed=11, device=device)
        pipe = wc.CollisionPipeline(scene)
        for _ in range(2):
            scene.advance(0.3)
            outputs.append(pipe.detect().triangle_pairs)
            outputs.append(wc.CollisionPipeline(scene).detect().triangle_pairs)
    for frame in range(2):
        same_frame = outputs[2 * frame :: 4] + outputs[2 * frame + 1 :: 4]
        assert all(np.array_equal(same_frame[0], o) for o in same_frame)


def nested(outer_name, inner_name, inner_scale, offset=(0.0, 0.0, 0.0)):
    ov, ot = wc.scene.shape(outer_name)
    iv, it = wc.scene.shape(inner_name)
    return [(ov * 3.0, ot), (iv * inner_scale + np.float32(offset), it)]


@pytest.mark.parametrize("outer", ["cube", "dodecahedron", "icosphere2", "tetrahedron"])
def test_containment(device, outer):
    meshes = nested(outer, "octahedron", 0.4, offset=(0.1, -0.1, 0.05))
    meshes.append((wc.scene.shape("cube")[0] * 0.3 + np.float32([20, 0, 0]), wc.scene.shape("cube")[1]))  # far away
    plain = wc.collide(meshes, device=device)
    assert plain.object_pairs.shape == (0, 2) and plain.containment_pairs is None
    assert not plain.colliding.any()
    res = wc.collide(meshes, device=device, containment=True)
    assert res.object_pairs.shape == (0, 2)
    assert res.containment_pairs.tolist() == [[1, 0]]
    assert res.colliding.tolist() == [True, True, False]


def test_containment_excludes_surface_contacts(device):
    # inner object pokes through the outer surface: a surface pair, not a containment pair
    meshes = nested("cube", "octahedron", 1.0, offset=(1.2, 0.0, 0.0))
    res = wc.collide(meshes, device=device, containment=True)
    assert res.object_pairs.tolist() == [[0, 1]]
    assert res.containment_pairs.shape == (0, 2)
    # boxes nest but the inner object is outside the outer (a corner of the tetrahedron's box)
    tv, tt = wc.scene.shape("tetrahedron")
    v = tv * 3.0
    corner = v.min(axis=0) * 0.9 + np.float32([0.05, 0.05, 0.05])
    inside_box_not_mesh = [(v, tt), (wc.scene.shape("cube")[0] * 0.05 + corner, wc.scene.shape("cube")[1])]
    lo, hi = v.min(0), v.max(0)
    assert (inside_box_not_mesh[1][0] >= lo).all() and (inside_box_not_mesh[1][0] <= hi).all()
    res = wc.collide(inside_box_not_mesh, device=device, containment=True)
    assert res.containment_pairs.shape == (0, 2) and res.object_pairs.shape == (0, 2)


def test_arrays_on_another_device_are_copied_there():
    """Arrays on another device than the scene's are copied to it once (as numpy arrays are), then read
    and checked there like the scene's own."""
    cuda, host = CUDA_DEVICES, HOST_DEVICES
    if not cuda or not host:
        pytest.skip("needs a CUDA device beside the host")
    scene = wc.Scene.random(5, seed=0, device=cuda[0])
    deforming = wc.Scene.from_meshes(scene.world_meshes(), deforming=True, device=cuda[0])
    vertices = scene.world_vertex.numpy() + 1.0
    deforming.set_world_vertices(wp.array(vertices, dtype=wp.vec3, device=host[0]))
    assert np.array_equal(deforming.world_vertex.numpy(), vertices)
    poses = np.tile(np.array([1, 2, 3, 0, 0, 0, 1], np.float32), (5, 1))
    scene.set_poses(wp.array(poses, dtype=wp.transform, device=host[0]))
    scene.check_inputs()
    assert np.array_equal(scene.object_pose.numpy(), poses)
    scene.set_poses(wp.zeros(scene.num_objects, dtype=wp.transform, device=host[0]))
    with pytest.raises(ValueError, match="set_poses: row 0 has a quaternion that is not unit"):
        scene.check_inputs()


def test_set_world_vertices_validation():
    rigid = wc.Scene.from_meshes([wc.scene.shape("cube")])
    with pytest.raises(ValueError, match="objects are rigid, placed by their poses"):
        rigid.set_world_vertices(np.zeros((8, 3)))
    with pytest.raises(ValueError, match=r"deforming: expected a bool or \(1,\) bools"):
        wc.Scene([wc.scene.shape("cube")], [0], deforming=[True, False])
    scene = wc.Scene.from_meshes([wc.scene.shape("cube")], deforming=True)
    with pytest.raises(ValueError, match=r"expected shape \(8, 3\)"):
        scene.set_world_vertices(np.zeros((7, 3)))
    bad = np.zeros((8, 3))
    bad[5, 1] = np.inf
    with pytest.raises(ValueError, match="vertex 5 \\(object 0\\) is not finite"):
        scene.set_world_vertices(bad)
    with pytest.raises(ValueError, match="a deforming scene takes world vertices"):
        scene.set_transforms(np.eye(4)[None])
    with pytest.raises(ValueError, match="no motion"):
        scene.advance(0.1)


# ---------------------------------------------------------------------------------------------
# Property-based tests of the two triangle tests.

coord = st.floats(-1.0, 1.0, allow_nan=False, width=32)
tri = st.lists(st.tuples(coord, coord, coord), min_size=3, max_size=3)


def rigid(seed):
    rng = np.random.default_rng(seed)
    return random_rotations(rng, 1)[0], rng.uniform(-5, 5, 3)


def answers(ta, tb, device, method):
    return run_test(np.asarray(ta), np.asarray(tb), device, method)


def in_band(ta, tb, device):
    """The pair is within the tolerance band: some answer changes when one triangle moves by
    1e-3 of its size along an axis, or when the tolerance goes from 0 to 1e-3 (touching and
    nearly touching configurations, where tests may legitimately differ)."""
    size = max(np.ptp(np.concatenate([ta[0], tb[0]]), axis=0).max(), 1e-12)
    shifts = np.concatenate([np.eye(3), -np.eye(3)]) * 1e-3 * size
    moved_b = tb + shifts[:, None, :]
    for m in ("moller", "edge_face"):
        base = run_test(ta, tb, device, m)[0]
        if (run_test(np.repeat(ta, 6, 0), moved_b, device, m) != base).any():
            return True
        if run_test(ta, tb, device, m, 0.0)[0] != base or run_test(ta, tb, device, m, 1e-3)[0] != base:
            return True
    return False


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(a=tri, b=tri, perm=st.permutations([0, 1, 2]), seed=st.integers(0, 2**31 - 1),
       method=st.sampled_from(["moller", "edge_face"]))
def test_triangle_test_properties(device, a, b, perm, seed, method):
    ta = np.array(a, np.float64)[None]
    tb = np.array(b, np.float64)[None]
    base = answers(ta, tb, device, method)[0]
    assert answers(tb, ta, device, method)[0] == base  # swapping the triangles
    if in_band(ta, tb, device):
        return
    assert answers(ta[:, perm], tb[:, perm[::-1]], device, method)[0] == base  # vertex order
    r, t = rigid(seed)
    assert answers(ta @ r.T + t, tb @ r.T + t, device, method)[0] == base  # rigid motion of both
    # agreement with Warp's float64 test (scaled up, see DESIGN.md), degenerate triangles aside
    area = min(np.linalg.norm(np.cross(x[0, 1] - x[0, 0], x[0, 2] - x[0, 0])) for x in (ta, tb))
    if area > 1e-3:
        assert intersect_tri_tri_f64(ta * 10, tb * 10, device=device)[0] == base


# ---------------------------------------------------------------------------------------------
# Precision


def test_float64_translation_invariance(device):
    """At float64 the result is unchanged when the whole scene moves 1e5 (float32 cannot do it)."""
    scene = wc.Scene.random(300, seed=21, device=device)
    scene.advance(0.4)
    meshes = [(v.astype(np.float64), t) for v, t in scene.world_meshes()]
    ref = wc.collide(meshes, device=device, precision="float64")
    assert ref.num_triangle_pairs > 0
    assert np.array_equal(ref.triangle_pairs, wc.collide(meshes, device=device).triangle_pairs)
    for offset in ([1e5, -1e5, 1e5], [3e7, 0, -2e7]):
        far = [(v + np.array(offset), t) for v, t in meshes]
        got = wc.collide(far, device=device, precision="float64")
        assert np.array_equal(got.triangle_pairs, ref.triangle_pairs), offset


def test_float64_transforms_far_away(device):
    """Rigid transforms with large translations, float64 scene: same pairs as near the origin."""
    meshes, transforms = crowded_cubes(n=40, seed=3)
    transforms[:, :3, 3] *= 40.0  # spread them out: some pairs, not all
    near = wc.collide(meshes, transforms, device=device, precision="float64")
    far_t = transforms.copy()
    far_t[:, :3, 3] += [2e5, -1e5, 7e4]
    far = wc.collide(meshes, far_t, device=device, precision="float64")
    assert 0 < len(near.object_pairs) < 40 * 39 // 2
    assert np.array_equal(far.triangle_pairs, near.triangle_pairs)


def test_float64_moving_scene_matches_fcl(device):
    from oracles import triangle_pairs_fcl

    scene = wc.Scene.random(200, seed=8, device=device, precision="float64")
    pipe = wc.CollisionPipeline(scene, containment=True)
    scene.advance(0.25)
    res = pipe.detect()
    assert scene.world_vertex.dtype == wp.vec3d
    assert np.array_equal(res.triangle_pairs, triangle_pairs_fcl(scene.world_meshes()))


@pytest.mark.parametrize("method", ["moller", "edge_face"])
def test_float64_crafted_cases_far(device, method):
    from test_narrow_phase import crafted, run_test

    ta, tb, expect = crafted(offset=(1e8, -3e8, 2e8), scale=1.0)
    assert np.array_equal(run_test(ta, tb, device, method, tol=1e-5, precision="float64"), expect)


def test_precision_validation():
    with pytest.raises(ValueError, match="precision"):
        wc.Scene.random(3, precision="float16")
    scene = wc.Scene.random(3, precision="float64")
    # float32 poses into a float64 scene are converted on the device (arrays of either precision anywhere);
    # zero quaternions are not unit: the kernel that reads them says so
    scene.set_poses(wp.zeros(3, dtype=wp.transform, device=scene.device))
    with pytest.raises(ValueError, match="set_poses: row 0 has a quaternion that is not unit"):
        scene.check_inputs()
    poses = np.tile(np.array([1.0, 2.0, 3.0, 0.0, 0.0, 0.0, 1.0], np.float32), (3, 1))
    scene.set_poses(wp.array(poses, dtype=wp.transform, device=scene.device))
    scene.check_inputs()
    assert np.array_equal(scene.object_pose.numpy(), poses.astype(np.float64))


def test_counters_do_not_wrap(device):
    """Counters are int64: past 2**31 items a stage raises OverflowError instead of wrapping."""
    from warp_ccd._src.broadphase.sap import BroadPhaseAllPairs
    from warp_ccd._src.runtime.buffers import CounterRead, GrowableBuffer

    lo = np.zeros((4, 3), np.float32)
    hi = np.ones((4, 3), np.float32)
    pairs = GrowableBuffer(wp.vec2i, 2, device, "pairs")
    pairs.count.assign(np.array([2**31 - 3], np.int64))  # as if 2**31 - 3 pairs came before
    BroadPhaseAllPairs(device=device).launch(wp.array(lo, dtype=wp.vec3, device=device),
                                             wp.array(hi, dtype=wp.vec3, device=device), pairs)
    counters = CounterRead([pairs], device)
    counters.enqueue()
    with pytest.raises(OverflowError, match="pairs"):
        counters.finish()  # reading the count grows the buffer: past the limit, it refuses
    assert counters.counts == [2**31 - 3 + 6]
    assert pairs.numpy(0).shape == (0, 2)
