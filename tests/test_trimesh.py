"""warp_ccd.trimesh.CollisionManager does what trimesh's CollisionManager does (the behaviours its own tests
check), and agrees with it (python-fcl underneath) on seeded scenes of trimesh's primitives."""

import importlib.util

import numpy as np
import pytest

from warp_ccd.trimesh import CollisionManager, ContactData, DistanceData, scene_to_collision

from conftest import DEFAULT_DEVICE

trimesh = pytest.importorskip("trimesh")


def moved(x=0.0, y=0.0, z=0.0) -> np.ndarray:
    t = np.eye(4)
    t[:3, 3] = [x, y, z]
    return t


@pytest.fixture(scope="module")
def cube():
    return trimesh.creation.box()  # the unit cube about the origin


def test_one_to_many_internal_and_moves(cube, device):
    m = CollisionManager(device=device)
    m.add_object("cube0", cube)
    m.add_object("cube1", cube, moved(5))
    assert m.in_collision_single(cube) is True
    hit, names = m.in_collision_single(cube, moved(5), return_names=True)
    assert hit is True and names == {"cube1"}
    hit, names = m.in_collision_single(cube, moved(-5), return_names=True)
    assert hit is False and names == set()
    assert m.in_collision_internal() is False

    m.add_object("cube2", cube, moved(5))
    hit, names = m.in_collision_internal(return_names=True)
    assert hit is True and names == {("cube1", "cube2")}
    m.set_transform("cube2", moved(-5))
    assert m.in_collision_internal() is False
    m.set_transform("cube2", moved(5))
    assert m.in_collision_internal() is True
    m.remove_object("cube2")
    assert m.in_collision_internal() is False


def test_manager_to_manager(cube):
    m = CollisionManager()
    m.add_object("cube0", cube)
    m.add_object("cube1", cube, moved(5))
    n = CollisionManager()
    n.add_object("cube0", cube, moved(-5))
    assert m.in_collision_other(n) is False
    n.add_object("cube3", cube, moved(5))
    assert m.in_collision_other(n) is True
    hit, names = m.in_collision_other(n, return_names=True)
    assert hit is True and names == {("cube1", "cube3")}  # (this manager's, the other's)
    hit, names = n.in_collision_other(m, return_names=True)
    assert names == {("cube3", "cube1")}


def test_names_are_ordered_as_trimesh_orders_them(cube):
    m = CollisionManager()
    m.add_object("b", cube)
    m.add_object("a", cube, moved(0.6))
    m.add_object("c", cube, moved(-0.6))
    _, names = m.in_collision_internal(return_names=True)
    assert names == {("a", "b"), ("b", "c")}  # each pair sorted, whatever the order of adding
    assert all(isinstance(p, tuple) for p in names)
    d, names = m.min_distance_internal(return_names=True)
    assert isinstance(names, tuple) and names[0] < names[1]


def test_distances(cube):
    m = CollisionManager()
    m.add_object("cube1", cube, moved(5))
    assert m.min_distance_single(cube) == pytest.approx(4.0)
    assert m.min_distance_single(cube, return_name=True) == (pytest.approx(4.0), "cube1")
    assert m.min_distance_single(cube, moved(5.75)) == pytest.approx(-0.25)  # minus the depth, python-fcl's sign

    m.add_object("cube2", cube, moved(-5))
    assert m.min_distance_single(cube, moved(2), return_name=True) == (pytest.approx(2.0), "cube1")
    assert m.min_distance_single(cube, moved(-2), return_name=True) == (pytest.approx(2.0), "cube2")
    assert m.min_distance_internal() == pytest.approx(9.0)
    assert m.min_distance_internal(return_names=True) == (pytest.approx(9.0), ("cube1", "cube2"))
    m.add_object("cube3", cube, moved(2))
    assert m.min_distance_internal(return_names=True) == (pytest.approx(2.0), ("cube1", "cube3"))
    m.set_transform("cube3", moved(-2))
    assert m.min_distance_internal(return_names=True) == (pytest.approx(2.0), ("cube2", "cube3"))
    assert m.min_distance_internal(name="cube1", return_names=True) == (pytest.approx(6.0), ("cube1", "cube3"))

    m = CollisionManager()
    m.add_object("cube0", cube)
    m.add_object("cube1", cube, moved(5))
    n = CollisionManager()
    n.add_object("cube4", cube, moved(-5))
    d, names, data = m.min_distance_other(n, return_names=True, return_data=True)
    assert d == pytest.approx(4.0) and names == ("cube0", "cube4")
    assert isinstance(data, DistanceData) and data.names == {"cube0", "cube4"} and data.distance == pytest.approx(4.0)
    assert np.linalg.norm(data.point("cube0") - data.point("cube4")) == pytest.approx(4.0)
    assert data.point("cube0")[0] == pytest.approx(-0.5) and data.point("cube4")[0] == pytest.approx(-4.5)
    for name in names:
        assert 0 <= data.index(name) < len(cube.faces)
    n.add_object("cube5", cube, moved(-2))
    d, names, data = m.min_distance_other(n, return_names=True, return_data=True)
    assert d == pytest.approx(1.0) and names == ("cube0", "cube5")
    assert np.linalg.norm(data.point(names[0]) - data.point(names[1])) == pytest.approx(1.0)


def test_single_distance_data_names_the_query_external(cube):
    m = CollisionManager()
    m.add_object("far", cube, moved(0, 10))
    m.add_object("near", cube, moved(0, 3))
    d, name, data = m.min_distance_single(cube, return_name=True, return_data=True)
    assert (d, name) == (pytest.approx(2.0), "near")
    assert data.names == {"near", "__external"}
    assert data.point("__external")[1] == pytest.approx(0.5) and data.point("near")[1] == pytest.approx(2.5)


def test_least_distance_ties_go_to_the_first_names(cube):
    m = CollisionManager()
    for name, x in (("d", 6.0), ("b", -3.0), ("c", 3.0), ("a", 0.0)):
        m.add_object(name, cube, moved(x))
    assert m.min_distance_internal(return_names=True) == (pytest.approx(2.0), ("a", "b"))
    assert m.min_distance_single(cube, moved(1.5, 4), return_name=True) == (pytest.approx(37**0.5 / 2), "a")  # or c


def test_empty_managers_answer_as_trimesh_does(cube):
    m = CollisionManager()
    assert m.in_collision_internal(return_names=True, return_data=True) == (False, set(), [])
    assert m.in_collision_single(cube, return_names=True) == (False, set())
    assert m.min_distance_single(cube, return_name=True) == (np.finfo(np.float64).max, None)
    assert m.min_distance_internal() == np.finfo(np.float64).max
    m.add_object("a", cube)
    assert m.min_distance_internal(name="a", return_names=True) == (np.finfo(np.float64).max, None)
    assert m.in_collision_other(CollisionManager(), return_names=True) == (False, set())


def test_unknown_names_and_bad_transforms(cube):
    m = CollisionManager()
    m.add_object("a", cube)
    for call in (lambda: m.remove_object("zz"), lambda: m.set_transform("zz", np.eye(4)),
                 lambda: m.min_distance_internal(name="zz")):
        with pytest.raises(ValueError, match="^zz not in collision manager!$"):
            call()
    with pytest.raises(ValueError, match=r"^transform must be \(4,4\)!$"):
        m.add_object("b", cube, np.eye(3))
    with pytest.raises(ValueError, match=r"^transform must be \(4,4\)!$"):
        m.set_transform("a", np.eye(3))
    scaled = np.diag([2.0, 1.0, 1.0, 1.0])
    with pytest.raises(ValueError, match="object 'a': transform is not rigid"):
        m.set_transform("a", scaled)
    with pytest.raises(ValueError, match="object 'b': transform is not rigid"):
        m.add_object("b", cube, scaled)
    with pytest.raises(ValueError, match="query mesh: transform is not rigid"):
        m.in_collision_single(cube, scaled)
    with pytest.raises(TypeError, match="vertices and faces"):
        m.add_object("c", "not a mesh")
    with pytest.raises(TypeError, match="other_manager"):
        m.in_collision_other(object())
    assert "b" not in m._index and m.in_collision_single(cube) is True  # nothing half added


def test_set_transform_moves_a_pose_and_equal_meshes_share_a_shape(cube):
    m = CollisionManager()
    copy = trimesh.Trimesh(cube.vertices.copy(), cube.faces.copy())
    for i in range(3):
        m.add_object(f"c{i}", cube if i < 2 else copy, moved(3 * i))
    assert m.in_collision_internal() is False
    scene = m._own_world().scene
    assert scene.num_shapes == 1  # the same mesh twice, and an equal copy
    m.set_transform("c1", moved(0.5))
    assert m.in_collision_internal(return_names=True) == (True, {("c0", "c1")})
    assert m._own_world().scene is scene  # moved, not built again
    m.add_object("c1", cube, moved(9))  # the same mesh again: a move too
    assert m.in_collision_internal() is False and m._own_world().scene is scene
    m.add_object("c3", trimesh.creation.icosphere(), moved(-3))
    assert m._own_world().scene is not scene


def test_repeated_single_queries_keep_their_scene(cube):
    m = CollisionManager()
    m.add_object("a", cube)
    probe = trimesh.creation.icosphere(subdivisions=1, radius=0.3)
    worlds = set()
    for x in np.linspace(-2, 2, 9):
        hit = m.in_collision_single(probe, moved(x))
        assert hit is bool(abs(x) <= 0.8)
        worlds.add(id(m._single_world(probe, moved(x)).scene))
    assert len(worlds) == 1


def test_containment_in_a_closed_mesh_collides(cube):
    m = CollisionManager()
    m.add_object("big", trimesh.creation.box(extents=[4, 4, 4]))
    m.add_object("small", cube)  # wholly inside, no surface crossing
    assert m.in_collision_internal(return_names=True) == (True, {("big", "small")})
    assert m.in_collision_single(trimesh.creation.icosphere(radius=0.2), moved(1.2), return_names=True) == \
        (True, {"big"})
    sheet = trimesh.Trimesh([[-3, -3, 0], [3, -3, 0], [0, 3, 0]], [[0, 1, 2]])  # an open surface holds nothing
    n = CollisionManager()
    n.add_object("sheet", sheet)
    n.add_object("ball", trimesh.creation.icosphere(radius=0.2), moved(z=1))
    assert n.in_collision_internal() is False


def test_rigid_motion_with_rotation(cube):
    """A rotated long box reaches a cube its unrotated box would miss."""
    m = CollisionManager()
    m.add_object("bar", trimesh.creation.box(extents=[4, 0.2, 0.2]))
    m.add_object("cube", cube, moved(0, 2.2))
    assert m.in_collision_internal() is False
    turn = trimesh.transformations.rotation_matrix(np.pi / 2, [0, 0, 1])
    m.set_transform("bar", turn)
    assert m.in_collision_internal() is True
    assert m.min_distance_internal(name="cube") == pytest.approx(-0.3, abs=1e-5)


def test_far_from_the_origin_in_float64(cube):
    """A scene that float32 cannot resolve at its triangles' size is built again in float64 (where FCL computes);
    beyond float64 too, the error names the object."""
    m = CollisionManager()
    m.add_object("a", cube)
    m.add_object("b", cube, moved(0.9))
    assert m.in_collision_internal() is True and m._own_world().scene.precision == "float32"
    m.set_transform("a", moved(1e5))
    m.set_transform("b", moved(1e5 + 0.9))
    assert m.in_collision_internal() is True and m._own_world().scene.precision == "float64"
    assert m.min_distance_internal() == pytest.approx(-0.1, abs=1e-6)
    m.set_transform("b", moved(1e5 + 1.25))
    assert m.min_distance_internal() == pytest.approx(0.25, abs=1e-6)
    m.set_transform("b", moved(1e14))
    with pytest.raises(ValueError, match="'b': placed too far from the origin"):
        m.in_collision_internal()


def test_least_distance_measures_few_pairs(monkeypatch):
    """Among 300 spheres the search measures pairs in increasing order of their bound and stops early: its
    answer is the least over all pairs, for a small part of the 44,850 pairs."""
    from warp_ccd._src.compat.trimesh import _World

    measured = []
    distances = _World.distances
    monkeypatch.setattr(_World, "distances", lambda self, pairs: measured.append(len(pairs)) or distances(self, pairs))
    rng = np.random.default_rng(3)
    ball = trimesh.creation.icosphere(subdivisions=1, radius=0.4)
    m = CollisionManager()
    centres = rng.uniform(0, 40, (300, 3))
    for k, c in enumerate(centres):
        m.add_object(f"ball{k:03d}", ball, moved(*c))
    d, names = m.min_distance_internal(return_names=True)
    gaps = np.linalg.norm(centres[:, None] - centres[None], axis=2) + np.diag(np.full(300, np.inf))
    i, j = np.unravel_index(np.argmin(gaps), gaps.shape)
    assert names == tuple(sorted((f"ball{i:03d}", f"ball{j:03d}")))
    assert d == pytest.approx(gaps[i, j] - 0.8, abs=0.05)  # the icosphere's faces lie within 0.8 of its radius
    assert sum(measured) < 200


def test_contact_data(cube):
    """The library's contacts of a pair (its deepest point, then the outline of the region where the surfaces
    cross, at depth 0), with python-fcl's normal: from the first name towards the second."""
    m = CollisionManager()
    m.add_object("cube0", cube)
    m.add_object("cube1", cube, moved(5))
    hit, names, data = m.in_collision_single(cube, moved(0.75), return_names=True, return_data=True)
    assert hit is True and names == {"cube0"} and 1 <= len(data) <= 8
    for c in data:
        assert isinstance(c, ContactData) and c.names == {"cube0", "__external"}
        np.testing.assert_allclose(c.normal, [1, 0, 0], atol=1e-6)  # the query lies at +x
        assert -1e-6 <= c.depth <= 0.25 + 1e-6
        assert 0.25 - 1e-6 <= c.point[0] <= 0.5 + 1e-6 and np.abs(c.point[1:]).max() <= 0.5 + 1e-6
        assert 0 <= c.index("cube0") < 12 and 0 <= c.index("__external") < 12
    deepest = max(data, key=lambda c: c.depth)
    assert deepest.depth == pytest.approx(0.25, abs=1e-6)  # the cubes overlap by 0.25 along x
    assert deepest.point[0] == pytest.approx(0.375, abs=1e-6)  # midway between the deepest points
    hit, data = m.in_collision_single(cube, moved(-5), return_data=True)
    assert hit is False and data == []

    m.add_object("cube2", cube, moved(5.75, 0.1))
    hit, names, data = m.in_collision_internal(return_names=True, return_data=True)
    assert names == {("cube1", "cube2")} and data
    assert {frozenset(c.names) for c in data} == {frozenset({"cube1", "cube2"})}
    assert max(c.depth for c in data) == pytest.approx(0.25, abs=1e-6)
    deepest = max(data, key=lambda c: c.depth)
    np.testing.assert_allclose(deepest.normal, [1, 0, 0], atol=1e-6)  # from cube1 (added first) towards cube2
    assert 0 <= deepest.index("cube1") < 12 and 0 <= deepest.index("cube2") < 12
    n = CollisionManager()
    n.add_object("other", cube, moved(-0.75))
    hit, names, data = m.in_collision_other(n, return_names=True, return_data=True)
    assert names == {("cube0", "other")} and data
    deepest = max(data, key=lambda c: c.depth)
    np.testing.assert_allclose(deepest.normal, [-1, 0, 0], atol=1e-6)  # from cube0 towards the other


def test_max_per_pair(cube):
    with pytest.raises(ValueError, match="max_per_pair"):
        CollisionManager(max_per_pair=0)
    m = CollisionManager(max_per_pair=1)
    m.add_object("a", cube)
    _, data = m.in_collision_single(cube, moved(0.75, 0.1), return_data=True)
    assert len(data) == 1 and data[0].depth == pytest.approx(0.25, abs=1e-6)  # the deepest


def test_every_probe_of_a_batch_is_reported():
    """700 probes each crossing one large anvil: no pair is dropped."""
    anvil = trimesh.creation.box(extents=[200, 200, 200])
    probe = trimesh.creation.revolve(np.array([[0, 3.0], [3, 3], [3, 75], [127, 75], [127, 580], [0, 580]]),
                                     sections=32)
    names = [f"probe_{i}" for i in range(700)]
    batch = CollisionManager()
    for i, name in enumerate(names):
        batch.add_object(name, probe, transform=moved((i / 700 - 0.5) * 30, 0, -50))
    hit, reported = batch.in_collision_single(anvil, return_names=True)
    assert hit is True and reported == set(names)


def test_scene_to_collision():
    spheres = [trimesh.creation.icosphere(subdivisions=1, radius=r).apply_translation(p)
               for r, p in ((1.0, [0, 0, 0]), (0.5, [1.2, 0, 0]), (0.5, [5, 0, 0]))]
    scene = trimesh.Scene(spheres)
    scene.add_geometry(trimesh.creation.box(), node_name="stretched", transform=np.diag([3.0, 1.0, 1.0, 1.0]) @
                       moved(0, 0, 3))
    manager, objects = scene_to_collision(scene)
    assert set(objects) == set(scene.graph.nodes_geometry)
    hit, names = manager.in_collision_internal(return_names=True)
    nodes = sorted(objects, key=lambda node: np.asarray(scene.geometry[scene.graph[node][1]].vertices)[:, 0].max())
    assert hit is True and len(names) == 1 and set(next(iter(names))) <= set(nodes)
    # the stretched box (x in [-1.5, 1.5], z in [2.5, 3.5]) was baked: 1.5 from the unit sphere's top
    assert manager.min_distance_internal(name="stretched") == pytest.approx(1.5, rel=1e-3)


# ------------------------------------------------------------------ against trimesh's FCL-based manager
needs_fcl = pytest.mark.skipif(importlib.util.find_spec("fcl") is None, reason="trimesh's manager needs python-fcl")


def primitives(rng, count: int, spread: float) -> list:
    """``count`` random boxes, icospheres, cylinders and capsules, randomly turned and placed."""
    out = []
    for k in range(count):
        kind = k % 4
        if kind == 0:
            mesh = trimesh.creation.box(extents=rng.uniform(0.3, 1.5, 3))
        elif kind == 1:
            mesh = trimesh.creation.icosphere(subdivisions=2, radius=rng.uniform(0.2, 0.8))
        elif kind == 2:
            mesh = trimesh.creation.cylinder(radius=rng.uniform(0.2, 0.6), height=rng.uniform(0.4, 1.6), sections=16)
        else:
            mesh = trimesh.creation.capsule(height=rng.uniform(0.3, 1.2), radius=rng.uniform(0.15, 0.5), count=[8, 8])
        t = trimesh.transformations.random_rotation_matrix(rng.random(3))
        t[:3, 3] = rng.uniform(0, spread, 3)
        out.append((f"{'bscy'[kind]}{k:02d}", mesh, t))
    return out


def both(objects):
    """A trimesh (FCL) manager and ours, of the same objects."""
    theirs, ours = trimesh.collision.CollisionManager(), CollisionManager(device=DEFAULT_DEVICE)
    for name, mesh, t in objects:
        theirs.add_object(name, mesh, t)
        ours.add_object(name, mesh, t)
    return theirs, ours


@needs_fcl
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_colliding_names_agree_with_trimesh(seed):
    rng = np.random.default_rng(seed)
    objects = primitives(rng, 24, 3.0)
    theirs, ours = both(objects)
    expected = theirs.in_collision_internal(return_names=True)
    assert expected[1], "a scene where something collides"
    assert ours.in_collision_internal(return_names=True) == expected
    probe, t = trimesh.creation.capsule(height=2.0, radius=0.3), moved(1.5, 1.5, 1.5)
    assert ours.in_collision_single(probe, t, return_names=True) == theirs.in_collision_single(probe, t,
                                                                                             return_names=True)
    # half the objects in another manager; move a few of them
    their_other, our_other = both(objects[::2])
    for manager in (theirs, ours):
        for name, _, _ in objects[::2]:
            manager.remove_object(name)
    for name, _, t in objects[:8:2]:
        t2 = t.copy()
        t2[:3, 3] += rng.uniform(-0.5, 0.5, 3)
        their_other.set_transform(name, t2)
        our_other.set_transform(name, t2)
    assert ours.in_collision_other(our_other, return_names=True) == \
        theirs.in_collision_other(their_other, return_names=True)


def separated(rng, count: int, spread: float) -> list:
    """Random primitives none of which meet (their bounding spheres apart)."""
    objects = []
    for name, mesh, t in primitives(rng, 4 * count, spread):
        centre = t[:3, :3] @ mesh.bounding_sphere.primitive.center + t[:3, 3]
        radius = mesh.bounding_sphere.primitive.radius
        if all(np.linalg.norm(centre - c) > radius + r for _, _, _, c, r in objects):
            objects.append((name, mesh, t, centre, radius))
        if len(objects) == count:
            break
    return [o[:3] for o in objects]


@needs_fcl
@pytest.mark.parametrize("seed", [0, 1])
def test_least_distances_agree_with_trimesh(seed):
    rng = np.random.default_rng(10 + seed)
    objects = separated(rng, 16, 6.0)
    theirs, ours = both(objects)
    d, names = theirs.min_distance_internal(return_names=True)
    assert d > 0
    got = ours.min_distance_internal(return_names=True)
    assert got[0] == pytest.approx(d, rel=1e-4) and got[1] == names
    for name in ("b00", "s01"):
        d, names = theirs.min_distance_internal(name=name, return_names=True)
        got = ours.min_distance_internal(name=name, return_names=True)
        assert got[0] == pytest.approx(d, rel=1e-4) and got[1] == names
    probe = trimesh.creation.icosphere(subdivisions=2, radius=0.4)
    d, name, data = theirs.min_distance_single(probe, moved(3, 3, 8), return_name=True, return_data=True)
    got, got_name, got_data = ours.min_distance_single(probe, moved(3, 3, 8), return_name=True, return_data=True)
    assert got == pytest.approx(d, rel=1e-4) and got_name == name
    assert np.linalg.norm(got_data.point(name) - got_data.point("__external")) == pytest.approx(got, rel=1e-4)
    their_other, our_other = both(separated(np.random.default_rng(20 + seed), 6, 6.0))
    for manager in (theirs, ours):
        for name, _, _ in objects[:8]:
            manager.remove_object(name)
    d, names = theirs.min_distance_other(their_other, return_names=True)
    if d > 0:
        got = ours.min_distance_other(our_other, return_names=True)
        assert got[0] == pytest.approx(d, rel=1e-4) and got[1] == names


def test_an_object_wholly_inside_another_is_the_nearest_pair_as_with_fcl():
    """A small box inside a big one (no surfaces crossing) and another box overlapping the big one: trimesh's FCL
    manager and ours agree on which pair is nearest and that its distance is negative (ours: minus the inner
    surface's depth, 0.9; FCL's EPA: the least translation, 1.1) and on the collision."""
    collision = pytest.importorskip("trimesh.collision")
    pytest.importorskip("fcl")
    big, small, box = (trimesh.creation.box(extents=e) for e in ([2, 2, 2], [0.2, 0.2, 0.2], [1, 1, 1]))
    answers = []
    for kind in (collision.CollisionManager, CollisionManager):
        m, n = kind(), kind()
        m.add_object("a", box, trimesh.transformations.translation_matrix([1.2, 0, 0]))
        m.add_object("b", big)
        n.add_object("s", small)
        answers.append((m.min_distance_other(n, return_names=True), m.in_collision_other(n, return_names=True)))
    (fcl_distance, fcl_names), fcl_hit = answers[0]
    (distance, names), hit = answers[1]
    assert names == fcl_names == ("b", "s") and hit == fcl_hit
    assert fcl_distance < 0 and distance == pytest.approx(-0.9, rel=1e-5)
