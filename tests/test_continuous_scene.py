"""Continuous detection at the scene level: ``CollisionPipeline(continuous=True)`` and ``collide(...,
transforms_end=, vertices_end=)`` against a brute-force reference that runs the same device
function, :func:`~warp_ccd._src.geometry.ccd.triangle_pair_toi`, on every triangle pair of every object pair."""

from itertools import combinations
from typing import Any

import numpy as np
import pytest
import warp as wp

import warp_ccd as wc
from warp_ccd._src.geometry.ccd import (
    CCD_MAX_ITERATIONS,
    CCD_TOLERANCE,
    MEETS_UNDECIDED,
    pair_meets,
    pair_meets_common,
    triangle_pair_toi,
)
from warp_ccd._src.scene.scene import MeshTopology, mesh_triangle
from warp_ccd._src.scene.shapes import icosphere, shape

from awkward_pairs import awkward_pairs

wp.set_module_options({"enable_backward": False, "fuse_fp": False})  # as the pipeline's module: same bits


@wp.kernel
def _reference_toi_kernel(mesh: MeshTopology, start: wp.array[Any], end: wp.array[Any], rows: wp.array[wp.vec4i],
                          min_distance: wp.float64, tolerance: wp.float64, max_iterations: int,
                          toi: wp.array[wp.float64]):
    k = wp.tid()
    c = rows[k]
    a0, a1, a2 = mesh_triangle(mesh, start, c[0], c[1])
    b0, b1, b2 = mesh_triangle(mesh, start, c[2], c[3])
    a0e, a1e, a2e = mesh_triangle(mesh, end, c[0], c[1])
    b0e, b1e, b2e = mesh_triangle(mesh, end, c[2], c[3])
    toi[k] = triangle_pair_toi(a0, a1, a2, b0, b1, b2, a0e, a1e, a2e, b0e, b1e, b2e, min_distance, tolerance,
                               max_iterations)


for _vec in (wp.vec3, wp.vec3d):
    wp.overload(_reference_toi_kernel, {"start": wp.array[_vec], "end": wp.array[_vec]})


def reference(scene, start: wp.array, min_distance: float = 0.0):
    """``(rows (M, 4), toi (M,))`` of every triangle pair of every object pair that collides over
    the motion from ``start`` to the scene's world vertices, rows sorted."""
    tri = np.diff(scene.object_triangle_start.numpy())
    rows = [np.stack(np.broadcast_arrays(a, np.arange(tri[a])[:, None], b, np.arange(tri[b])[None, :]),
                     axis=-1).reshape(-1, 4) for a, b in combinations(range(scene.num_objects), 2)]
    rows = np.concatenate(rows).astype(np.int32)
    toi = wp.empty(len(rows), dtype=wp.float64, device=scene.device)
    wp.launch(_reference_toi_kernel, dim=len(rows),
              inputs=[scene.topology, start, scene.world_vertex, wp.array(rows, dtype=wp.vec4i, device=scene.device),
                      wp.float64(min_distance), wp.float64(CCD_TOLERANCE), CCD_MAX_ITERATIONS],
              outputs=[toi], device=scene.device)
    t = toi.numpy()
    hit = t <= 1.0
    return rows[hit], t[hit]


def assert_matches_reference(result, rows, toi):
    assert result.continuous
    np.testing.assert_array_equal(result.triangle_pairs, rows)
    np.testing.assert_array_equal(result.triangle_toi, toi)  # bitwise: the same device function
    pairs = np.unique(rows[:, [0, 2]], axis=0) if len(rows) else np.zeros((0, 2), np.int32)
    np.testing.assert_array_equal(result.object_pairs, pairs)
    expected = np.array([toi[(rows[:, 0] == a) & (rows[:, 2] == b)].min() for a, b in pairs])
    np.testing.assert_array_equal(result.object_toi, expected.reshape(-1))
    assert result.toi == (toi.min() if len(toi) else np.inf)
    flags = np.zeros(result.num_objects, bool)
    flags[pairs.ravel()] = True
    np.testing.assert_array_equal(result.colliding, flags)


def tetrahedron(size: float = 0.2):
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float) * size
    return v, np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])


def box(lo, hi):
    """A closed box mesh from corner ``lo`` to ``hi``."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    v = np.array([[(hi if (k >> a) & 1 else lo)[a] for a in range(3)] for k in range(8)])
    t = np.array([[0, 2, 1], [1, 2, 3], [4, 5, 6], [5, 7, 6], [0, 1, 4], [1, 5, 4], [2, 6, 3], [3, 6, 7],
                  [0, 4, 2], [2, 4, 6], [1, 3, 5], [3, 7, 5]])
    return v, t


def translation(x=0.0, y=0.0, z=0.0):
    m = np.eye(4)
    m[:3, 3] = (x, y, z)
    return m


WALL = box((0.0, -5.0, -5.0), (0.01, 5.0, 5.0))


@pytest.mark.parametrize("precision", ["float32", "float64"])
def test_fast_tetrahedron_through_a_thin_wall(device, precision):
    """Discrete detection at either end finds nothing; continuous finds the crossing, its toi no later
    than the analytic entry time (front face at x = -1.8, 4 units a step: 0.45) and within 1e-3."""
    meshes = [tetrahedron(), WALL]
    start = np.stack([translation(-2.0), np.eye(4)])
    end = np.stack([translation(2.0), np.eye(4)])
    for t in (start, end):
        assert len(wc.collide(meshes, t, device=device, precision=precision).object_pairs) == 0
    r = wc.collide(meshes, start, device=device, precision=precision, transforms_end=end)
    assert r.continuous
    np.testing.assert_array_equal(r.object_pairs, [[0, 1]])
    assert 0.45 - 1e-3 <= r.toi <= 0.45
    assert r.object_toi[0] == r.toi == r.triangle_toi.min()
    np.testing.assert_array_equal(r.colliding, [True, True])
    # The same motion as end vertices of a deforming mesh (in the mesh's frame, placed by transforms).
    v = wc.collide(meshes, start, device=device, precision=precision,
                   vertices_end=[meshes[0][0] + [4.0, 0.0, 0.0], WALL[0]])
    np.testing.assert_array_equal(v.object_pairs, [[0, 1]])
    assert 0.45 - 1e-3 <= v.toi <= 0.45


def test_a_discrete_result_has_no_toi(device):
    r = wc.collide([tetrahedron(), WALL], np.stack([translation(-0.1), np.eye(4)]), device=device)
    assert not r.continuous and r.device_toi is None and r.triangle_toi is None and r.object_toi is None
    assert r.toi == np.inf and len(r.object_pairs) == 1


SPHERE = icosphere(1)  # 80 triangles: beyond the whole-object pairs, the trees are walked


def _scene(deforming: bool, precision: str, device, seed: int):
    shapes = ("tetrahedron", "cube", "octahedron", SPHERE)
    scene = wc.Scene.random(10, seed=seed, shapes=shapes, density=0.15, device=device, precision=precision)
    if not deforming:
        return scene
    meshes = scene.world_meshes()
    return wc.Scene.from_meshes(meshes, deforming=True, device=device, precision=precision)


def _move(scene, rng, pipe, step: float):
    """Moves the scene (rigid: along its ellipses by ``step`` inside the frame; deforming: every vertex
    by its object's random shift plus a jitter) and detects."""
    if not scene.deforming:
        return pipe.detect(advance=step)
    v = scene.world_vertex.numpy().astype(np.float64)
    owner = np.searchsorted(scene.object_vertex_start.numpy(), np.arange(len(v)), side="right") - 1
    shift = rng.uniform(-1.5, 1.5, size=(scene.num_objects, 3))
    scene.set_world_vertices(v + shift[owner] + rng.uniform(-0.1, 0.1, size=v.shape))
    return pipe.detect()


@pytest.mark.parametrize("deforming", [False, True], ids=["rigid", "deforming"])
@pytest.mark.parametrize("precision", ["float32", "float64"])
@pytest.mark.parametrize("broad,mid", [("sap", "bvh"), ("all_pairs", "all_pairs"), ("sap", "all_pairs"),
                                       ("all_pairs", "bvh")])
def test_random_scenes_match_the_brute_force(device, deforming, precision, broad, mid):
    """Every triangle pair of every object pair tested with triangle_pair_toi: the pipeline reports
    the same pairs with the same tois, over two successive motions (each from the previous detect)."""
    rng = np.random.default_rng(7)
    scene = _scene(deforming, precision, device, seed=3)
    pipe = wc.CollisionPipeline(scene, continuous=True, broad_phase=broad, mid_phase=mid, pair_capacity=4,
                                candidate_capacity=8, hit_capacity=2, front_capacity=4)
    found = 0
    for step in (0.4, 0.3):
        start = wp.clone(pipe.world_vertex_start)
        result = _move(scene, rng, pipe, step)
        rows, toi = reference(scene, start)
        assert_matches_reference(result, rows, toi)
        found += len(rows)
        np.testing.assert_array_equal(pipe.world_vertex_start.numpy(), scene.world_vertex.numpy())
    assert found > 0  # the scenes collide somewhere


def test_min_distance(device):
    """Two cubes sliding past each other with a gap of 0.5 d (in every norm: the gap is along one
    axis) are reported with min_distance d, with a gap of 2 d not; without it neither."""
    d = 0.1
    cube = box((0, 0, 0), (1, 1, 1))
    for gap, expected in ((0.5 * d, 1), (2.0 * d, 0)):
        start = np.stack([np.eye(4), translation(-3.0, 1.0 + gap, 0.0)])
        end = np.stack([np.eye(4), translation(3.0, 1.0 + gap, 0.0)])
        r = wc.collide([cube, cube], start, device=device, transforms_end=end, min_distance=d)
        assert len(r.object_pairs) == expected, gap
        if expected:
            assert 0.0 < r.toi <= 2.0 / 6.0  # x overlap starts at t = 1/3 (the y gap is within d all along)
        plain = wc.collide([cube, cube], start, device=device, transforms_end=end)
        assert len(plain.object_pairs) == 0
    # A static query: min_distance alone, no motion.
    near = wc.collide([cube, cube], np.stack([np.eye(4), translation(0.0, 1.0 + 0.5 * d)]), device=device,
                      min_distance=d)
    assert near.continuous and near.toi == 0.0 and len(near.object_pairs) == 1


def test_successive_detects_cover_each_interval_and_reruns_keep_the_start(device):
    """Motion A (the tetrahedron through the wall) then B (back out to where it was): each detect
    sees its own interval. Tiny capacities make the first frames grow their buffers and run again,
    on the same start."""
    scene = wc.Scene.from_meshes([tetrahedron(), WALL], np.stack([translation(-2.0), np.eye(4)]), device=device)
    pipe = wc.CollisionPipeline(scene, continuous=True, pair_capacity=1, candidate_capacity=1, hit_capacity=1,
                                front_capacity=1)
    big = wc.CollisionPipeline(scene, continuous=True)  # a second start of its own, default capacities
    first = pipe.detect()  # no motion yet
    big.detect()
    assert first.continuous and len(first.object_pairs) == 0 and first.toi == np.inf
    scene.set_transforms(np.stack([translation(2.0), np.eye(4)]))  # A: through the wall
    a, a_big = pipe.detect(), big.detect()
    assert a.runs > 1 and a_big.runs == 1
    np.testing.assert_array_equal(a.triangle_pairs, a_big.triangle_pairs)
    np.testing.assert_array_equal(a.triangle_toi, a_big.triangle_toi)
    assert 0.45 - 1e-3 <= a.toi <= 0.45
    kept = a.copy()
    scene.set_transforms(np.stack([translation(2.5), np.eye(4)]))  # B: on beyond the wall, no contact
    b = pipe.detect()
    assert len(b.object_pairs) == 0 and b.toi == np.inf
    assert kept.continuous and 0.45 - 1e-3 <= kept.toi <= 0.45  # the copy owns its arrays
    scene.set_transforms(np.stack([translation(-2.5), np.eye(4)]))  # back through the wall
    c = pipe.detect()
    np.testing.assert_array_equal(c.object_pairs, [[0, 1]])
    entry = (2.5 - 0.01) / 5.0  # the vertex at x = 2.5 reaches the wall's face at x = 0.01
    assert entry - 1e-3 <= c.toi <= entry


def test_detect_with_advance_covers_the_motion_of_the_step(device):
    scene = wc.Scene.random(6, seed=1, density=0.2, device=device)
    pipe = wc.CollisionPipeline(scene, continuous=True)
    start = wp.clone(scene.world_vertex)
    result = pipe.detect(advance=0.5)
    assert not np.array_equal(start.numpy(), scene.world_vertex.numpy())
    rows, toi = reference(scene, start)
    assert_matches_reference(result, rows, toi)


@pytest.mark.parametrize("options,name", [
    ({"continuous": True, "min_distance": -1.0}, "min_distance"),
    ({"continuous": True, "ccd_tolerance": 0.0}, "ccd_tolerance"),
    ({"continuous": True, "ccd_max_iterations": 0}, "ccd_max_iterations"),
    ({"continuous": "yes"}, "continuous"),
    ({"min_distance": 0.1}, "min_distance"),
    ({"ccd_tolerance": 1e-3}, "ccd_tolerance"),
    ({"continuous": True, "segments": True}, "segments"),
    ({"continuous": True, "containment": True}, "containment"),
    ({"continuous": True, "narrow_phase": "edge_face"}, "narrow_phase"),
])
def test_bad_options(device, options, name):
    scene = wc.Scene.from_meshes([tetrahedron(), WALL], device=device)
    with pytest.raises(ValueError, match=name):
        wc.CollisionPipeline(scene, **options)


def test_bad_end_states(device):
    meshes = [tetrahedron(), WALL]
    with pytest.raises(ValueError, match="vertices_end: expected 2 arrays"):
        wc.collide(meshes, device=device, vertices_end=[meshes[0][0]])
    with pytest.raises(ValueError, match=r"vertices_end: mesh 1: expected shape \(8, 3\)"):
        wc.collide(meshes, device=device, vertices_end=[meshes[0][0], np.zeros((7, 3))])
    bad = WALL[0].copy()
    bad[3, 1] = np.nan
    with pytest.raises(ValueError, match="vertices_end: mesh 1: vertex 3 is not finite"):
        wc.collide(meshes, device=device, vertices_end=[meshes[0][0], bad])
    with pytest.raises(ValueError, match="transforms_end"):
        wc.collide(meshes, device=device, transforms_end=np.zeros((2, 4, 4)))
    with pytest.raises(ValueError, match="transforms_end"):
        wc.collide(meshes, device=device, transforms_end=np.stack([np.eye(4)] * 3), vertices_end=[m[0] for m in meshes])
    with pytest.raises(ValueError, match="min_distance"):
        wc.collide(meshes, device=device, min_distance=-0.5)


def test_fewer_than_two_objects(device):
    scene = wc.Scene.from_meshes([tetrahedron()], device=device)
    pipe = wc.CollisionPipeline(scene, continuous=True)
    r = pipe.detect()
    assert r.continuous and r.toi == np.inf and len(r.triangle_toi) == 0 and len(r.object_toi) == 0
    assert shape("cube")  # the named shapes import beside the meshes of these tests


@wp.kernel
def _meets_kernel(ta: wp.array2d[Any], tb: wp.array2d[Any], common: wp.array[wp.int32],
                  whole: wp.array[wp.int32]):
    i = wp.tid()
    common[i] = pair_meets_common(ta[i, 0], ta[i, 1], ta[i, 2], tb[i, 0], tb[i, 1], tb[i, 2])
    whole[i] = wp.where(pair_meets(ta[i, 0], ta[i, 1], ta[i, 2], tb[i, 0], tb[i, 1], tb[i, 2]), 1, 0)


for _vec in (wp.vec3, wp.vec3d):
    wp.overload(_meets_kernel, {"ta": wp.array2d[_vec], "tb": wp.array2d[_vec]})


@pytest.mark.parametrize("precision", ["float32", "float64"])
def test_discrete_common_path_agrees_with_the_whole_test(device, precision):
    """The passes' common path of the discrete test (steps 1 to 3 of Möller's) gives the whole
    test's verdict whenever it gives one, on 20,000 near-degenerate pairs (touching, coplanar,
    degenerate, far from the origin, tiny) in both orders, and leaves some undecided."""
    ta, tb = awkward_pairs(precision, n=20_000)
    vec = wp.vec3 if precision == "float32" else wp.vec3d
    for a, b in ((ta, tb), (tb, ta)):
        n = len(a)
        common = wp.zeros(n, dtype=wp.int32, device=device)
        whole = wp.zeros(n, dtype=wp.int32, device=device)
        wp.launch(_meets_kernel, dim=n, inputs=[wp.array(a, dtype=vec, device=device),
                                                wp.array(b, dtype=vec, device=device)],
                  outputs=[common, whole], device=device)
        c, w = common.numpy(), whole.numpy()
        decided = c != MEETS_UNDECIDED
        np.testing.assert_array_equal(c[decided], w[decided])
        assert decided.sum() > n // 2 and (~decided).sum() > 0 and w.sum() > 0 and (w == 0).sum() > 0


def test_collide_keeps_the_options_least_distance(device):
    """``collide`` over a motion takes the least distance of the options object it is given (the keyword, where
    given, wins): two cubes sliding past each other 0.03 apart come within 0.05, never touch."""
    cube = wc.scene.shape("cube")
    side = float(np.ptp(cube[0][:, 0]))
    t0 = np.tile(np.eye(4), (2, 1, 1))
    t0[1, :3, 3] = (side + 0.03, 0.0, 0.0)  # faces 0.03 apart
    t1 = t0.copy()
    t1[:, 1, 3] += 0.5  # both slide along y
    near = wc.PipelineOptions(continuous=True, min_distance=0.05)
    got = wc.collide([cube, cube], t0, device=device, transforms_end=t1, options=near)
    assert got.object_pairs.tolist() == [[0, 1]]
    assert wc.collide([cube, cube], t0, device=device, transforms_end=t1).object_pairs.tolist() == []
    far = wc.collide([cube, cube], t0, device=device, transforms_end=t1, min_distance=0.01, options=near)
    assert far.object_pairs.tolist() == []  # the keyword's 0.01 over the options' 0.05
