"""The whole frame against independent oracles, and the public API's contract."""

import numpy as np
import pytest
import warp as wp

import warp_ccd as wc

from oracles import triangle_pairs_fcl, triangle_pairs_warp64
from test_narrow_phase import run_test


def check_against_oracles(scene, result, device):
    meshes = scene.world_meshes()
    fcl_pairs = triangle_pairs_fcl(meshes)
    w64 = triangle_pairs_warp64(meshes, scale=20.0, device=device)
    got = result.triangle_pairs
    assert np.array_equal(got, w64), f"ours {len(got)} vs warp float64 {len(w64)}"
    assert np.array_equal(got, fcl_pairs), f"ours {len(got)} vs fcl {len(fcl_pairs)}"
    obj = np.unique(got[:, [0, 2]], axis=0) if len(got) else np.zeros((0, 2), np.int32)
    assert np.array_equal(result.object_pairs, obj)
    flags = np.zeros(scene.num_objects, bool)
    flags[obj.ravel()] = True
    assert np.array_equal(result.colliding, flags)


@pytest.mark.parametrize("num_objects, seed", [(60, 0), (300, 1), (1000, 2)])
def test_random_scene_matches_oracles(device, num_objects, seed):
    scene = wc.Scene.random(num_objects, seed=seed, device=device)
    pipe = wc.CollisionPipeline(scene)
    frames = 3 if num_objects < 1000 else 1
    for _ in range(frames):
        scene.advance(0.13)
        res = pipe.detect()
        assert res.num_triangle_pairs > 0
        check_against_oracles(scene, res, device)


@pytest.mark.parametrize(
    "options",
    [dict(broad_phase="all_pairs"), dict(narrow_phase="edge_face"), dict(mid_phase="all_pairs"),
     dict(pair_capacity=1, candidate_capacity=1, hit_capacity=1),
     dict(mid_phase="all_pairs", pair_capacity=1, candidate_capacity=1, hit_capacity=1)],
    ids=["broad_all_pairs", "edge_face", "all_pairs", "capacity_1", "all_pairs_capacity_1"],
)
def test_pipeline_options_agree(device, options):
    scene = wc.Scene.random(400, seed=5, device=device)
    scene.advance(0.5)
    ref = wc.CollisionPipeline(scene).detect()
    got = wc.CollisionPipeline(scene, **options).detect()
    assert ref.num_triangle_pairs > 0
    assert np.array_equal(got.triangle_pairs, ref.triangle_pairs)
    assert np.array_equal(got.colliding, ref.colliding)


@pytest.mark.parametrize("front_capacity", [1, None])
def test_traversal_front(device, front_capacity):
    """The descent level by level: trees of different depths end together at leaves (the last
    level's front is empty), the front's counter holds its largest level, and a front of capacity 1
    grows until the frame fits; the pairs are those of every triangle pair."""
    scene = wc.Scene.random(80, seed=2, shapes=("cube", "icosphere2", "dodecahedron"), density=0.2, device=device)
    scene.advance(0.3)
    ref = wc.CollisionPipeline(scene, mid_phase="all_pairs").detect()
    pipe = wc.CollisionPipeline(scene)
    mid = pipe.mid
    mid.whole_triangles_max = 0  # every pair walks its trees
    if front_capacity is not None:
        mid.front._allocate(front_capacity)
    got = pipe.detect()
    assert ref.num_triangle_pairs > 0
    assert np.array_equal(got.triangle_pairs, ref.triangle_pairs)
    assert mid.num_levels == pipe.boxes.num_levels - 1 == 9  # icosphere2: 320 leaves of 1 triangle, 10 levels
    levels = mid.walk.level_count.numpy()
    assert levels[-1] == 0 and levels[1:-1].min() > 0
    assert mid.front.last_count == levels.max() <= mid.front.capacity
    if front_capacity is not None:
        assert got.runs >= 2  # the front grew (a frame overflowing at one level counts less below it)
    again = pipe.detect()
    assert again.runs == 1 and np.array_equal(again.triangle_pairs, ref.triangle_pairs)


@pytest.mark.parametrize("precision", ["float32", "float64"])
@pytest.mark.parametrize("whole_triangles_max, lanes", [(0, 32), (12, 32), (64, 32), (64, 8), (64, 64)])
def test_whole_object_pairs(device, whole_triangles_max, lanes, precision):
    """Pairs of objects of at most ``whole_triangles_max`` triangles test their triangles' world
    boxes pair by pair instead of walking trees; with none, some or all pairs so, a candidate
    buffer of capacity 1, the pairs are those of every triangle pair; a scene of small objects
    alone launches no traversal."""
    shapes = ("cube", "icosphere2", "dodecahedron", "tetrahedron")
    scene = wc.Scene.random(120, seed=3, shapes=shapes, density=0.2, device=device, precision=precision)
    scene.advance(0.3)
    ref = wc.CollisionPipeline(scene, mid_phase="all_pairs").detect()
    pipe = wc.CollisionPipeline(scene, candidate_capacity=1)
    pipe.mid.whole_triangles_max = whole_triangles_max
    pipe.mid.whole_lanes = lanes
    got = pipe.detect()
    assert got.runs >= 2 and ref.num_triangle_pairs > 0
    assert np.array_equal(got.triangle_pairs, ref.triangle_pairs)
    small = wc.Scene.random(200, seed=4, density=0.3, device=device, precision=precision)  # polyhedra: <= 36 triangles
    pipe = wc.CollisionPipeline(small)
    pipe.mid.whole_triangles_max = whole_triangles_max
    pipe.mid.whole_lanes = lanes
    got = pipe.detect()
    want = wc.CollisionPipeline(small, mid_phase="all_pairs").detect()
    assert np.array_equal(got.triangle_pairs, want.triangle_pairs)
    assert (pipe.mid.front.last_count == 0) == (whole_triangles_max >= 36)  # no traversal: its front stays empty


def test_whole_object_pairs_deforming(device):
    """Deforming small objects (their world vertices given each frame) as whole-object pairs."""
    v, t = wc.scene.icosphere(0)
    meshes = [(v * 0.5 + np.float32([0.6 * k, 0.1 * k, 0.0]), t) for k in range(6)]
    scene = wc.Scene.from_meshes(meshes, deforming=True, device=device)
    pipe = wc.CollisionPipeline(scene)
    for k in range(3):
        world = np.concatenate([m[0] * np.float32(1.0 + 0.2 * k) for m in meshes])
        scene.set_world_vertices(world)
        got = pipe.detect()
        want = wc.CollisionPipeline(scene, mid_phase="all_pairs").detect()
        assert want.num_triangle_pairs > 0 and np.array_equal(got.triangle_pairs, want.triangle_pairs)
        assert pipe.mid.front.last_count == 0  # no traversal


def test_whole_object_pairs_default_by_scene_size():
    """Whole-object pairs by default up to WHOLE_OBJECTS_MAX objects, trees for every pair above."""
    from warp_ccd._src.midphase.bvh import WHOLE_OBJECTS_MAX, WHOLE_TRIANGLES_MAX

    bvh = wc.stages.SceneBVH(wc.Scene.random(50, seed=0))
    assert wc.stages.MidPhaseBVH(bvh).whole_triangles_max == WHOLE_TRIANGLES_MAX
    bvh.lower = wp.zeros(WHOLE_OBJECTS_MAX + 1, dtype=wp.vec3, device=bvh.device)  # as a larger scene's
    assert wc.stages.MidPhaseBVH(bvh).whole_triangles_max == 0


@pytest.mark.parametrize("value", [-1, 65, 2.5, True])
def test_bad_whole_triangles_max(value):
    scene = wc.Scene.random(4, seed=0)
    with pytest.raises(ValueError, match="whole_triangles_max"):
        wc.stages.MidPhaseBVH(wc.stages.SceneBVH(scene), whole_triangles_max=value)
    mid = wc.stages.MidPhaseBVH(wc.stages.SceneBVH(scene))
    with pytest.raises(ValueError, match="whole_triangles_max"):
        mid.whole_triangles_max = value
    for lanes in (0, 3, 512, 32.0, True):
        with pytest.raises(ValueError, match="whole_lanes"):
            mid.whole_lanes = lanes


def _kinds_built(scene):
    """Every stage class the factories make, with each method, by the protocol of its kind."""
    from warp_ccd import stages

    built = {stages.BroadPhaseStage: [stages.make_broad_phase(m) for m in ("sap", "all_pairs")],
             stages.NarrowPhaseStage: [stages.make_narrow_phase(6, narrow_phase=m, segments=True, containment=True)
                                       for m in ("moller", "edge_face")]
             + [stages.make_narrow_phase(6, continuous=True)]}
    for method, (bounds, mid) in ((m, stages.make_mid_phase(scene, mid_phase=m)) for m in ("bvh", "all_pairs")):
        built.setdefault(stages.BoundsStage, []).append(bounds)
        built.setdefault(stages.MidPhaseStage, []).append(mid)
        assert type(mid) is {"bvh": stages.MidPhaseBVH, "all_pairs": stages.MidPhaseAllPairs}[method]
    pipe = wc.CollisionPipeline(scene, clearance=0.1, self_intersections=True)
    built[stages.ClearanceStage] = [pipe.near_phase]
    built[stages.SelfStage] = [pipe.self_phase]
    return built


def test_stages_keep_their_contracts():
    """Every stage the factories make, with every method, has what the frame calls of its kind (the
    protocols of :mod:`warp_ccd._src.pipeline.stages`): the members, and calls of the protocol's signature
    (every parameter of the protocol's method, of the same kind and default); the pipeline holds such stages."""
    import inspect

    from warp_ccd import stages

    scene = wc.Scene.random(6, seed=0)
    built = _kinds_built(scene)
    classes = {type(stage) for kind in built.values() for stage in kind}
    assert classes == {stages.ObjectBounds, stages.SceneBVH, stages.BroadPhaseSAP, stages.BroadPhaseAllPairs,
                       stages.MidPhaseBVH, stages.MidPhaseAllPairs, stages.NarrowPhase, stages.ContinuousNarrowPhase,
                       stages.ClearancePhase, stages.SelfIntersection}
    for kind, made in built.items():
        calls = [name for name in ("launch", "refit") if name in vars(kind)]
        assert calls, kind
        for stage in made:
            assert isinstance(stage, kind), (type(stage).__name__, kind.__name__)
            for name in calls:
                want = list(inspect.signature(getattr(kind, name)).parameters.values())[1:]
                got = inspect.signature(getattr(stage, name)).parameters
                for p in want:
                    assert p.name in got, (type(stage).__name__, name, p.name)
                    q = got[p.name]
                    assert (q.kind, q.default) == (p.kind, p.default), (type(stage).__name__, name, p.name)
                extra = [q for q in got.values() if q.name not in {p.name for p in want}]
                assert all(q.default is not inspect.Parameter.empty for q in extra), (type(stage).__name__, extra)
    assert not isinstance(stages.make_broad_phase("sap"), stages.MidPhaseStage)  # no candidates
    pipe = wc.CollisionPipeline(scene)
    for stage, kind in ((pipe.boxes, stages.BoundsStage), (pipe.broad, stages.BroadPhaseStage),
                        (pipe.mid, stages.MidPhaseStage), (pipe.narrow, stages.NarrowPhaseStage)):
        assert isinstance(stage, kind)


def test_the_frame_branches_on_no_stage_class():
    """The frame calls its stages through their protocols: no ``isinstance`` on a concrete stage."""
    import inspect

    from warp_ccd._src.pipeline import pipeline

    source = inspect.getsource(pipeline.CollisionPipeline)
    for name in ("SceneBVH", "ObjectBounds", "NarrowPhase", "ContinuousNarrowPhase", "MidPhaseBVH", "BroadPhaseSAP"):
        assert f"isinstance(self.boxes, {name})" not in source and f", {name})" not in source, name


def test_factories_name_the_methods():
    """An unknown method's error lists the known ones; every option is checked by its one rule."""
    from warp_ccd import stages

    scene = wc.Scene.random(4, seed=0)
    with pytest.raises(ValueError, match=r"^mid_phase must be one of \['all_pairs', 'bvh'\], got 'octree'$"):
        stages.make_mid_phase(scene, mid_phase="octree")
    with pytest.raises(ValueError, match=r"^narrow_phase must be one of \['edge_face', 'moller'\], got 'gjk'$"):
        stages.make_narrow_phase(4, narrow_phase="gjk")
    with pytest.raises(ValueError, match=r"^broad_phase must be one of \['all_pairs', 'nxn', 'sap'\]"):
        stages.make_broad_phase(["sap"])
    with pytest.raises(ValueError, match=r"^leaf_size must be an integer in \[1, 256\] or None, got 0$"):
        stages.make_mid_phase(scene, mid_phase="all_pairs", leaf_size=0)  # checked with either method
    with pytest.raises(ValueError, match=r"^front_capacity must be an integer >= 1 or None, got 0$"):
        stages.make_mid_phase(scene, front_capacity=0)
    with pytest.raises(ValueError, match=r"^tolerance must be a finite number in \[0, 0.1\), got 0.1$"):
        stages.make_narrow_phase(4, tolerance=0.1)
    with pytest.raises(ValueError, match=r"^hit_capacity must be an integer >= 1 or None, got 2.0$"):
        stages.make_narrow_phase(4, hit_capacity=2.0)
    with pytest.raises(ValueError, match=r"^rebuild_every must be 0 with the all_pairs mid phase \(no trees\), got 2$"):
        wc.CollisionPipeline(scene, mid_phase="all_pairs", rebuild_every=2)
    with pytest.raises(ValueError, match=r"^separating_axes must be an integer in \{3, 6\}, got 6.0$"):
        wc.CollisionPipeline(scene, separating_axes=6.0)
    with pytest.raises(TypeError, match="unexpected keyword argument 'tolerence'"):
        wc.CollisionPipeline(scene, tolerence=0.01)


def test_pipeline_options_are_one_checked_object():
    """The pipeline's options are one object, checked when made and passed down: keywords and an object
    give the same pipeline; an object is immutable and a changed copy is checked again."""
    scene = wc.Scene.random(20, seed=3)
    options = wc.PipelineOptions(clearance=0.05, segments=True)
    by_object = wc.CollisionPipeline(scene, options)
    by_keywords = wc.CollisionPipeline(scene, clearance=0.05, segments=True)
    assert by_object.options == by_keywords.options
    assert by_object.options.leaf_size == 1  # chosen for the scene where None was given
    np.testing.assert_array_equal(by_object.detect().triangle_pairs, by_keywords.detect().triangle_pairs)
    with pytest.raises(AttributeError):
        options.clearance = 0.1
    with pytest.raises(ValueError, match="clearance must be a finite number in"):
        options.replace(clearance=-1.0)
    assert wc.CollisionPipeline(scene, options, segments=False).options.segments is False
    with pytest.raises(TypeError, match="options must be a PipelineOptions"):
        wc.CollisionPipeline(scene, {"clearance": 0.05})
    for flag in ("segments", "containment", "continuous", "self_intersections", "timings"):
        with pytest.raises(ValueError, match=rf"^{flag} must be True or False, got 'yes'$"):
            wc.PipelineOptions(**{flag: "yes"})


def test_an_option_has_one_rule():
    """Every field of the options objects has its rule in the one table, and the stage classes that take an
    option check it by that rule: the same bounds and message wherever it enters."""
    import dataclasses

    from warp_ccd._src.runtime.options import OPTIONS
    from warp_ccd.stages import ClearancePhase, NarrowPhase, TreeDistance

    assert {f.name for f in dataclasses.fields(wc.PipelineOptions)} <= set(OPTIONS)
    scene = wc.Scene.random(4, seed=0)
    message = r"^tolerance must be a finite number in \[0, 0.1\), got 0.5$"
    for make in (lambda: wc.PipelineOptions(tolerance=0.5), lambda: NarrowPhase(4, tolerance=0.5),
                 lambda: ClearancePhase(4, 0.1, tolerance=0.5),
                 lambda: TreeDistance(wc.stages.SceneBVH(scene), tolerance=0.5)):
        with pytest.raises(ValueError, match=message):
            make()
    for make in (lambda: wc.PipelineOptions(clearance=2e37), lambda: ClearancePhase(4, 2e37)):
        with pytest.raises(ValueError, match=r"^clearance must be a finite number in \[0, 1e\+37\], got 2e\+37$"):
            make()


def test_mid_phases_share_whole_pair_options():
    """Both mid phases take the whole-object pair options, checked alike (the all-pairs reference,
    whose pairs are all whole, leaves them unused)."""
    from warp_ccd._src.midphase.bvh import WHOLE_LANES, MidPhase

    mid = wc.stages.MidPhaseAllPairs()
    assert isinstance(mid, MidPhase)
    assert isinstance(wc.stages.MidPhaseBVH(wc.stages.SceneBVH(wc.Scene.random(3))), MidPhase)
    assert (mid.whole_triangles_max, mid.whole_lanes) == (0, WHOLE_LANES)
    mid.whole_triangles_max, mid.whole_lanes = np.int64(12), np.int32(8)
    assert (mid.whole_triangles_max, mid.whole_lanes) == (12, 8)
    assert type(mid.whole_triangles_max) is int and type(mid.whole_lanes) is int
    with pytest.raises(ValueError, match=r"^whole_triangles_max must be an integer in \[0, 64\], got 65$"):
        mid.whole_triangles_max = 65
    with pytest.raises(ValueError, match=r"^whole_lanes must be an integer in \{1, 2, 4, 8, 16, 32, 64, 128, 256\}, "
                                         r"got 3$"):
        mid.whole_lanes = 3


@pytest.mark.parametrize(
    "check, message",
    [
        (lambda o: o.integer_option("cut_depth", 17, low=0, high=16),
         "cut_depth must be an integer in [0, 16], got 17"),
        (lambda o: o.integer_option("n", True, low=0), "n must be an integer >= 0, got True"),
        (lambda o: o.integer_option("n", np.bool_(True)), f"n must be an integer, got {np.bool_(True)!r}"),
        (lambda o: o.integer_option("n", 3.0, high=4), "n must be an integer <= 4, got 3.0"),
        (lambda o: o.integer_option("seed", -1, low=0, allow_none=True),
         "seed must be an integer >= 0 or None, got -1"),
        (lambda o: o.integer_option("icosphere: level", "1", low=0, high=8),
         "icosphere: level must be an integer in [0, 8], got '1'"),
        (lambda o: o.number_option("tolerance", -1e-9, low=0, high=0.1, high_open=True),
         "tolerance must be a finite number in [0, 0.1), got -1e-09"),
        (lambda o: o.number_option("density", 1.0, low=0, high=1, low_open=True, high_open=True),
         "density must be a finite number in (0, 1), got 1.0"),
        (lambda o: o.number_option("fps", 0, low=0, low_open=True), "fps must be a finite number > 0, got 0"),
        (lambda o: o.number_option("dt", float("nan")), "dt must be a finite number, got nan"),
        (lambda o: o.number_option("dt", 10**400), "dt must be a finite number, got " + str(10**400)),
        (lambda o: o.number_option("dt", False), "dt must be a finite number, got False"),
        (lambda o: o.number_option("dt", 1j), "dt must be a finite number, got 1j"),
        (lambda o: o.number_option("x", 2, high=1), "x must be a finite number <= 1, got 2"),
    ],
)
def test_option_messages(check, message):
    """One message shape for every integer and real option: the name, what it allows, the value."""
    from warp_ccd._src.runtime import checks as options

    with pytest.raises(ValueError) as err:
        check(options)
    assert str(err.value) == message


def test_options_accept_numpy_scalars():
    from warp_ccd._src.runtime.checks import integer_option, is_integer, number_option

    assert integer_option("n", np.int16(3), low=0) == 3 and type(integer_option("n", np.uint8(3))) is int
    assert integer_option("n", None, allow_none=True) is None
    assert integer_option("n", np.int64(6), choices=(3, 6)) == 6
    assert number_option("x", np.float32(0.5), low=0, high=1) == 0.5 and type(number_option("x", 1)) is float
    assert number_option("x", 0.0, low=0) == 0.0 and number_option("x", np.int64(2), high=2) == 2.0
    assert is_integer(np.int8(1)) and not is_integer(True) and not is_integer(1.0)


def test_timings(device):
    scene = wc.Scene.random(100, seed=1, device=device)
    res = wc.CollisionPipeline(scene, timings=True).detect()
    assert set(res.timings) >= {"refit", "broad", "mid", "narrow", "total"}
    assert all(v >= 0 for v in res.timings.values())
    assert wc.CollisionPipeline(scene).detect().timings is None


CUBE = wc.scene.shape("cube")


def cube_at(x, y=0.0, z=0.0, s=1.0):
    v, t = CUBE
    return (v * s + np.float32([x, y, z]), t)


def test_collide_world_space(device):
    meshes = [cube_at(0), cube_at(1.0), cube_at(10), cube_at(11.0)]
    res = wc.collide(meshes, device=device)
    assert res.object_pairs.tolist() == [[0, 1], [2, 3]]
    assert res.colliding.tolist() == [True, True, True, True]
    t = res.triangle_pairs
    assert t.dtype == np.int32 and t.shape[1] == 4
    assert (t[:, 0] < t[:, 2]).all()
    assert np.array_equal(t, t[np.lexsort((t[:, 3], t[:, 2], t[:, 1], t[:, 0]))])


def test_collide_with_transforms_matches_fcl(device):
    rng = np.random.default_rng(4)
    shapes = [wc.scene.icosphere(2), *(wc.scene.shape(s) for s in ("dodecahedron", "cube", "tetrahedron"))]
    meshes = [shapes[i % 4] for i in range(40)]  # shared arrays: instanced shapes
    transforms = np.tile(np.eye(4), (40, 1, 1))
    q = rng.normal(size=(40, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    x, y, z, w = q.T
    transforms[:, :3, :3] = np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
        np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
        np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
    ], 1)
    transforms[:, :3, 3] = rng.uniform(-4, 4, size=(40, 3))
    res = wc.collide(meshes, transforms, device=device)
    world = [((v.astype(np.float64) @ m[:3, :3].T) + m[:3, 3], t) for (v, t), m in zip(meshes, transforms)]
    want = triangle_pairs_fcl(world)
    assert len(want) > 0
    assert np.array_equal(res.triangle_pairs, want)


def test_touching_cubes_count(device):
    """Face-touching cubes collide (closed sets); cubes a hair apart do not."""
    v, t = wc.scene.shape("cube")
    side = float(v[:, 0].max() - v[:, 0].min())
    res = wc.collide([cube_at(0), cube_at(side)], device=device)
    assert res.object_pairs.tolist() == [[0, 1]]
    res = wc.collide([cube_at(0), cube_at(side * 1.001)], device=device)
    assert res.object_pairs.tolist() == []


def _all_triangle_pairs_moller(meshes, device):
    """Every triangle pair of every object pair, decided by Möller's test in one function (the
    pipeline decides its step 4 in a second kernel): rows ``(obj_a, tri_a, obj_b, tri_b)``."""
    rows, ta, tb = [], [], []
    for a in range(len(meshes)):
        for b in range(a + 1, len(meshes)):
            (va, fa), (vb, fb) = meshes[a], meshes[b]
            for i in range(len(fa)):
                for j in range(len(fb)):
                    rows.append((a, i, b, j))
                    ta.append(va[fa[i]])
                    tb.append(vb[fb[j]])
    return np.int32(rows)[run_test(ta, tb, device)].reshape(-1, 4)


def test_touching_without_crossing(device):
    """Pairs that touch but do not cross (a vertex over a face, an edge over a face's edge, a fifth
    of the tolerance apart): the pipeline's split step 4 finds exactly what Möller's test in one
    function does."""
    ov, ot = wc.scene.shape("octahedron")
    cv, ct = wc.scene.shape("cube")
    top = float(cv[:, 2].max())
    half = float(cv[:, 0].max())
    lowest = float(ov[:, 2].min())
    turn = np.float32([[np.cos(0.3), -np.sin(0.3), 0], [np.sin(0.3), np.cos(0.3), 0], [0, 0, 1]])
    c45 = np.cos(np.pi / 4)
    edge = np.float32([[1, 0, 0], [0, c45, -c45], [0, c45, c45]])
    reach = float((cv @ edge.T)[:, 2].max())
    gap = 0.2 * wc.TOLERANCE * 2 * half  # within eps (the tolerance times the longest edge)
    meshes = [
        (cv, ct),
        ((ov @ turn.T) + np.float32([0.1, -0.05, top - lowest + gap]), ot),  # vertex over the top face
        (cv + np.float32([5.0, 0, 0]), ct),
        ((cv @ edge.T) @ turn.T + np.float32([5.0, 0.0, top + reach + gap]), ct),  # edge over the top face
        (cv + np.float32([10.0, 0, 0]), ct),
        ((ov @ turn.T) + np.float32([10.0 + half * 0.5, 0.0, top - lowest + 1e-2]), ot),  # a gap: apart
    ]
    meshes = [(np.float32(v), np.int32(t)) for v, t in meshes]
    want = _all_triangle_pairs_moller(meshes, device)
    assert len(want) > 0 and {(0, 1), (2, 3)} <= set(map(tuple, want[:, [0, 2]].tolist()))
    for capacity in (None, 1):
        res = wc.collide(meshes, device=device, **({} if capacity is None else dict(hit_capacity=capacity)))
        assert np.array_equal(res.triangle_pairs, want)
        assert res.object_pairs.tolist() == [[0, 1], [2, 3]]


def test_far_from_origin_and_tiny(device):
    scene = wc.Scene.random(150, seed=9, device=device)
    scene.advance(0.2)
    meshes = scene.world_meshes()
    ref = wc.collide(meshes, device=device).triangle_pairs
    assert len(ref) > 0
    far = [(v.astype(np.float64) + 1e4, t) for v, t in meshes]
    tiny = [(v.astype(np.float64) * 1e-4, t) for v, t in meshes]
    for moved in (far, tiny):
        got = wc.collide(moved, device=device).triangle_pairs
        # float32 rounding of the moved input can only shift pairs inside the tolerance band
        diff = set(map(tuple, got)) ^ set(map(tuple, ref))
        assert len(diff) <= max(1, len(ref) // 200)


def test_containment_is_not_surface_contact(device):
    big = cube_at(0, s=5.0)
    small = cube_at(0, s=0.5)
    res = wc.collide([big, small], device=device)
    assert res.object_pairs.shape == (0, 2)


def test_empty_and_single(device):
    res = wc.collide([], device=device)
    assert res.object_pairs.shape == (0, 2) and res.triangle_pairs.shape == (0, 4) and res.colliding.shape == (0,)
    res = wc.collide([cube_at(0)], device=device)
    assert res.colliding.tolist() == [False]
    scene = wc.Scene.random(0, device=device)
    scene.advance(0.1)
    assert wc.CollisionPipeline(scene).detect().triangle_pairs.shape == (0, 4)


def test_deforming_scene(device):
    """World vertices written by the caller: results follow the written geometry."""
    v, t = wc.scene.icosphere(2)
    scene = wc.Scene.from_meshes([(v, t), (v + np.float32([3, 0, 0]), t)], deforming=True, device=device)
    pipe = wc.CollisionPipeline(scene)
    assert pipe.detect().object_pairs.tolist() == []
    for k, r in enumerate([1.0, 2.4, 0.7]):
        ang = 0.3 * k
        rot = np.array([[np.cos(ang), -np.sin(ang), 0], [np.sin(ang), np.cos(ang), 0], [0, 0, 1]])
        pulsed = (v.astype(np.float64) * r * (1 + 0.1 * v[:, 2:3])) @ rot.T
        world = np.concatenate([pulsed, v + np.float32([3, 0, 0])])
        scene.set_world_vertices(world)
        res = pipe.detect()
        meshes = scene.world_meshes()
        assert np.array_equal(res.triangle_pairs, triangle_pairs_warp64(meshes, scale=10.0, device=device))
        assert (len(res.object_pairs) > 0) == (r > 2.0)


def test_device_arrays_stay_on_device(device):
    scene = wc.Scene.random(50, seed=3, device=device)
    res = wc.CollisionPipeline(scene).detect()
    assert res.device_colliding.device == wp.get_device(device)
    assert res.device_triangle_pairs.device == wp.get_device(device)


BAD_MESHES = [
    ("not a sequence", TypeError, "sequence"),
    ([(np.zeros((3, 3)),)], ValueError, "mesh 0"),
    ([cube_at(0), (np.full((8, 3), np.nan), wc.scene.shape("cube")[1])], ValueError, "mesh 1: vertex 0 is not finite"),
    ([cube_at(0), (CUBE[0], CUBE[1] + 1)], ValueError, "mesh 1: triangle .* out of range"),
    ([cube_at(0), (wc.scene.shape("cube")[0], np.zeros((0, 3), int))], ValueError, "mesh 1: the mesh has no triangles"),
    ([cube_at(0), (CUBE[0], CUBE[1].astype(float))], ValueError, "mesh 1: .*integer"),
]


@pytest.mark.parametrize("meshes, err, match", BAD_MESHES)
def test_bad_meshes(meshes, err, match):
    with pytest.raises(err, match=match):
        wc.collide(meshes)


def test_bad_transforms():
    meshes = [cube_at(0), cube_at(1)]
    eye = np.tile(np.eye(4), (2, 1, 1))
    with pytest.raises(ValueError, match="expected shape"):
        wc.collide(meshes, np.eye(4))
    bad = eye.copy()
    bad[1, 0, 3] = np.nan
    with pytest.raises(ValueError, match="transform 1: contains NaN"):
        wc.collide(meshes, bad)
    bad = eye.copy()
    bad[0, :3, :3] *= 2.0
    with pytest.raises(ValueError, match="transform 0: not rigid"):
        wc.collide(meshes, bad)
    bad = eye.copy()
    bad[1, 2, 2] = -1.0
    with pytest.raises(ValueError, match="transform 1: not rigid .*reflection"):
        wc.collide(meshes, bad)
    bad = eye.copy()
    bad[1, 3, 0] = 1.0
    with pytest.raises(ValueError, match="transform 1: bottom row"):
        wc.collide(meshes, bad)


def test_bad_options():
    scene = wc.Scene.random(3)
    with pytest.raises(ValueError, match="broad_phase"):
        wc.CollisionPipeline(scene, broad_phase="octree")
    with pytest.raises(ValueError, match="narrow_phase"):
        wc.CollisionPipeline(scene, narrow_phase="gjk")
    with pytest.raises(ValueError, match="tolerance"):
        wc.CollisionPipeline(scene, tolerance=-1.0)
    with pytest.raises(TypeError, match="Scene"):
        wc.CollisionPipeline("scene")
    with pytest.raises(ValueError, match="num_objects"):
        wc.Scene.random(-1)
    with pytest.raises(ValueError, match="num_objects"):
        wc.Scene.random(True)
    with pytest.raises(ValueError, match="tolerance"):
        wc.CollisionPipeline(scene, tolerance="a")
    with pytest.raises(ValueError, match="graph"):
        wc.CollisionPipeline(scene, graph="yes")
    if not scene.device.is_cuda:
        with pytest.raises(ValueError, match="graph"):
            wc.CollisionPipeline(scene, graph=True)
    with pytest.raises(ValueError, match="density"):
        wc.Scene.random(10, density=2.0)


def point_triangle_distance(x, tri):
    """Distance from point ``x`` to the closed triangle ``tri`` (3, 3), float64 (by sampling the
    plane projection and the edges)."""
    a, b, c = tri
    n = np.cross(b - a, c - a)
    n /= np.linalg.norm(n)
    p = x - n * (n @ (x - a))
    inside = all(np.cross(v1 - v0, p - v0) @ n >= 0 for v0, v1 in ((a, b), (b, c), (c, a)))
    if inside:
        return abs(n @ (x - a))
    best = np.inf
    for v0, v1 in ((a, b), (b, c), (c, a)):
        t = np.clip((x - v0) @ (v1 - v0) / ((v1 - v0) @ (v1 - v0)), 0, 1)
        best = min(best, np.linalg.norm(x - (v0 + t * (v1 - v0))))
    return best


@pytest.mark.parametrize("precision", ["float32", "float64"])
def test_segments_lie_on_both_triangles(device, precision):
    scene = wc.Scene.random(200, seed=12, device=device, precision=precision)
    scene.advance(0.3)
    res = wc.CollisionPipeline(scene, segments=True).detect()
    seg, pairs = res.segments, res.triangle_pairs
    assert seg.shape == (len(pairs), 2, 3) and len(pairs) > 0
    assert np.array_equal(pairs, wc.CollisionPipeline(scene).detect().triangle_pairs)
    meshes = scene.world_meshes()
    for (a, ta, b, tb), ends in zip(pairs, seg):
        if np.isnan(ends).any():
            continue
        for obj, t in ((a, ta), (b, tb)):
            tri = meshes[obj][0][meshes[obj][1][t]].astype(np.float64)
            for x in ends:
                assert point_triangle_distance(x, tri) < 1e-4
    assert wc.CollisionPipeline(scene).detect().segments is None


@pytest.mark.parametrize("precision", ["float32", "float64"])
def test_segment_of_crossing_triangles(device, precision):
    t = np.array([[0, 1, 2]])
    flat = (np.array([[0, 0, 0], [2, 0, 0], [0, 2, 0]], np.float32), t)
    upright = (np.array([[0.5, -1, -1], [0.5, 3, -1], [0.5, 0.5, 1]], np.float32), t)
    scene = wc.Scene.from_meshes([flat, upright], device=device, precision=precision)
    res = wc.CollisionPipeline(scene, segments=True).detect()
    ends = sorted(map(tuple, res.segments[0].round(5)))
    assert ends == [(0.5, 0.0, 0.0), (0.5, 1.5, 0.0)]


@pytest.mark.parametrize(
    "call, match",
    [
        (lambda s: wc.CollisionPipeline(s, leaf_size=1.5), "leaf_size"),
        (lambda s: wc.CollisionPipeline(s, leaf_size=True), "leaf_size"),
        (lambda s: wc.CollisionPipeline(s, leaf_size=1000), "leaf_size"),
        (lambda s: wc.CollisionPipeline(s, cut_depth=-1), "cut_depth"),
        (lambda s: wc.CollisionPipeline(s, cut_depth=2.0), "cut_depth"),
        (lambda s: wc.CollisionPipeline(s, graph=1), "graph"),
        (lambda s: wc.CollisionPipeline(s, pair_capacity=0), "pair_capacity"),
        (lambda s: wc.CollisionPipeline(s, candidate_capacity="big"), "candidate_capacity"),
        (lambda s: wc.Scene.random(5, density="x"), "density"),
        (lambda s: wc.Scene.random(5, size_range=(1,)), "size_range"),
        (lambda s: wc.Scene.random(5, seed=-1), "seed"),
        (lambda s: s.advance("a"), "dt"),
        (lambda s: s.advance(None), "dt"),
        (lambda s: wc.Scene([wc.scene.shape("cube")], [0.7, 0.2]), "object_shape"),
        (lambda s: wc.Scene([wc.scene.shape("cube")], [0], poses=[[0, 0, 0, 0, 0, 0, 3]]), "poses: row 0"),
        (lambda s: wc.Scene([wc.scene.shape("cube")], [0], poses=[[np.nan, 0, 0, 0, 0, 0, 1]]), "poses: row 0"),
    ],
)
def test_bad_arguments_name_the_argument(call, match):
    scene = wc.Scene.random(5, seed=0)
    with pytest.raises(ValueError, match=match):
        call(scene)


def _same_frame(got, want):
    assert np.array_equal(got.triangle_pairs, want.triangle_pairs)
    assert np.array_equal(got.colliding, want.colliding)
    assert np.array_equal(got.containment_pairs, want.containment_pairs)
    assert np.array_equal(got.segments, want.segments, equal_nan=True)
    assert (got.num_broad_pairs, got.num_candidates) == (want.num_broad_pairs, want.num_candidates)


def test_detect_with_advance_is_advance_then_detect(device):
    """``detect(advance=dt)`` (one frame: motion and detection) equals ``advance(dt)`` then ``detect()``,
    frame after frame, including frames whose buffers overflow (every capacity starts at 1)."""
    one = wc.Scene.random(120, seed=21, device=device)
    two = wc.Scene.random(120, seed=21, device=device)
    small = dict(pair_capacity=1, candidate_capacity=1, hit_capacity=1, segments=True, containment=True)
    fused = wc.CollisionPipeline(one, **small)
    split = wc.CollisionPipeline(two, graph=False, **small)
    for _ in range(6):
        got = fused.detect(advance=0.05)
        two.advance(0.05)
        _same_frame(got, split.detect())
        assert one.time == two.time and one.time_device.numpy()[0] == one.time
    assert np.array_equal(one.object_pose.numpy(), two.object_pose.numpy())


def test_graph_and_eager_frames_agree_over_100_frames(device):
    """The frame replayed as a CUDA graph gives the eager frame's results, frame after frame, as
    buffers overflow, grow and the graph is captured again (every capacity starts at 1)."""
    if not wp.get_device(device).is_cuda:
        pytest.skip("CUDA graphs need a CUDA device")
    scenes = [wc.Scene.random(400, seed=22, device=device) for _ in range(2)]
    small = dict(pair_capacity=1, candidate_capacity=1, hit_capacity=1, segments=True, containment=True)
    graph = wc.CollisionPipeline(scenes[0], graph=True, **small)
    eager = wc.CollisionPipeline(scenes[1], graph=False, **small)
    for _ in range(100):
        _same_frame(graph.detect(advance=1 / 30), eager.detect(advance=1 / 30))
    frames = list(graph._frames.frames.values())
    assert any(f.captures for f in frames) and all(f.mode == "graph" for f in frames)
    assert graph.pairs.capacity > 1 and graph.mid.candidates.capacity > 1 and graph.narrow.hits.capacity > 1


def test_result_views_and_copies(device):
    """A result holds views of the pipeline's buffers until the next detect(); copy() keeps its own."""
    scene = wc.Scene.random(200, seed=23, device=device)
    pipe = wc.CollisionPipeline(scene)
    first = pipe.detect()
    kept = first.copy()
    want = kept.triangle_pairs.copy()
    assert first.device_triangle_pairs.ptr == pipe.narrow.hits.data.ptr  # a view, no copy
    assert kept.device_triangle_pairs.ptr != pipe.narrow.hits.data.ptr
    for _ in range(3):
        pipe.detect(advance=0.3)
    assert np.array_equal(kept.triangle_pairs, want)
    assert kept.host_ms >= 0.0 and len(want) > 0
