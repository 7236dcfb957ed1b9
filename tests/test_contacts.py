"""Contacts for solvers (:mod:`warp_ccd._src.narrowphase.contacts`) and the signed distance.

Every contact is checked against float64 oracles of its own (``depth_reference``): ``point_a`` on the surface of
``a`` and ``point_b`` on ``b``'s (brute-force nearest distances), ``point_a = point_b - depth * normal`` with a unit
normal, a positive depth's point of one surface inside the other's solid (ray parity), the deepest contact of a
pair of convex solids equal to the exact depth of the linear program (``convex_depth``); crafted cases for the
normals (stacked boxes, flush, coincident, resting exactly), the reduction (at most ``max_per_pair``, the deepest
kept, stable under motions of 1e-9), speculative contacts within a margin, open sheets; the same contacts on every
device; the signed distance (python-fcl's sign) against the same oracle.
"""

import numpy as np
import pytest
from depth_reference import closest_distance, inside, pair_convex_depth
from test_crossing import box, grid
from test_depth import _convex_shapes, random_rotation, rotated

import warp_ccd as wc

import distance_digests
from conftest import ALL_DEVICES


def world_triangles(mesh):
    v, t = mesh
    return np.asarray(v, np.float64)[np.asarray(t)]


def check_contacts(meshes, c, tol=1e-5):
    """Every contact on both surfaces, consistent, unit normal, a positive depth's point inside the other."""
    size = max(np.ptp(np.asarray(m[0]), axis=0).max() for m in meshes)
    assert c.pairs.shape == (c.count, 2) and (c.pairs[:, 0] < c.pairs[:, 1]).all()
    assert np.allclose(np.linalg.norm(c.normal, axis=1), 1.0, atol=1e-9)
    assert np.allclose(c.point_a, c.point_b - c.depth[:, None] * c.normal, atol=tol * size)
    for k, (a, b) in enumerate(c.pairs):
        ta, tb = world_triangles(meshes[a]), world_triangles(meshes[b])
        assert closest_distance(c.point_a[k:k + 1], ta)[0] <= tol * size, (k, "point_a off a")
        assert closest_distance(c.point_b[k:k + 1], tb)[0] <= tol * size, (k, "point_b off b")
        if c.depth[k] > tol * size:  # the point of one surface inside the other's solid, at that depth
            in_b = inside(c.point_a[k:k + 1], tb)[0] and closest_distance(c.point_a[k:k + 1], tb)[0] == pytest.approx(
                c.depth[k], rel=1e-6, abs=tol * size)
            in_a = inside(c.point_b[k:k + 1], ta)[0] and closest_distance(c.point_b[k:k + 1], ta)[0] == pytest.approx(
                c.depth[k], rel=1e-6, abs=tol * size)
            assert in_b or in_a, (k, c.depth[k])


# 1. The crafted cases.

def test_stacked_boxes_push_apart_along_the_stack(device):
    a = box([0, 0, 0], [1, 1, 1])
    b = box([0, 0, 0.95], [1, 1, 1.95])
    c = wc.contacts([a, b], device=device, max_per_pair=4)
    check_contacts([a, b], c)
    assert c.count == 4 and c.depth.max() == pytest.approx(0.05, rel=1e-6)
    assert np.allclose(c.normal, [0, 0, -1])  # a, below, leaves downwards
    assert np.argmax(c.depth) == 0  # the deepest first
    corners = c.point_a[c.depth < 1e-9]
    assert len(corners) == 3 and np.allclose(corners[:, 2], 0.95)  # the outline, at the corners


def test_flush_cubes_overlapping_by_a_quarter_give_the_trimesh_depth(device):
    a = box([-0.5] * 3, [0.5] * 3)
    b = box([0.25, -0.5, -0.5], [1.25, 0.5, 0.5])
    c = wc.contacts([a, b], device=device)
    check_contacts([a, b], c)
    assert c.depth.max() == pytest.approx(0.25, rel=1e-6)
    assert np.allclose(c.normal, [-1, 0, 0])
    assert c.pair_depth.tolist() == pytest.approx([0.25])


@pytest.mark.parametrize("shift", [0.0, 1e3])
def test_coincident_and_resting_boxes_have_face_normals_never_zero(device, shift):
    a = box([0, 0, 0], [1, 1, 1])
    for b in (box([0, 0, 0], [1, 1, 1], 1), box([0, 0, 1], [1, 1, 2])):
        meshes = [(a[0] + shift, a[1]), (b[0] + shift, b[1])]
        c = wc.contacts(meshes, device=device, precision="float64")
        assert c.count >= 1
        assert np.allclose(np.linalg.norm(c.normal, axis=1), 1.0)
        assert np.abs(c.depth).max() <= 1e-9
    # Resting exactly: the floor's normal along the bottom edges too.
    assert np.allclose(c.normal, [0, 0, -1])


def test_box_sunk_into_a_slab_gives_its_corners_at_the_depth(device):
    slab = box([-2, -2, -1], [2, 2, 0])
    crate = box([-0.5, -0.3, -0.1], [0.5, 0.3, 0.9])
    c = wc.contacts([slab, crate], device=device)
    check_contacts([slab, crate], c)
    deep = c.depth > 0.1 - 1e-6
    assert deep.sum() >= 4 and np.allclose(c.depth[deep], 0.1, rtol=1e-6)
    assert np.allclose(c.normal[deep], [0, 0, -1])  # the slab (a) leaves downwards
    bottom = c.point_b[deep]
    assert {tuple(np.round(p[:2], 6)) for p in bottom} >= {(-0.5, -0.3), (0.5, -0.3), (-0.5, 0.3), (0.5, 0.3)}


def test_an_object_wholly_inside_another_gets_its_deepest_contact_with_containment(device):
    v, t = wc.scene.shape("cube")  # faces at +-0.577
    big, small = (v * 3, t), (v * 0.5 + [0.2, 0, 0], t)
    for meshes, sign in (([small, big], -1.0), ([big, small], 1.0)):
        res = wc.collide(meshes, device=device, precision="float64", containment=True, contacts=True)
        c = res.contacts
        assert res.colliding.all() and c.count == 1 and c.pairs.tolist() == [[0, 1]]
        # The inner surface's deepest point (its face at x = 0.2 - 0.289) and the outer's nearest, 1.643 away.
        assert c.depth[0] == pytest.approx(3 * 0.57735027 - (0.57735027 * 0.5 - 0.2), rel=1e-6)
        assert np.allclose(c.normal[0], [sign, 0, 0])
        assert np.allclose(c.point_a, c.point_b - c.depth[:, None] * c.normal)
    assert wc.contacts([small, big], device=device).count == 0  # without containment the frame sees no pair


def test_signed_distance_of_an_object_wholly_inside_another_is_negative(device):
    v, t = wc.scene.shape("cube")
    big, small = (v * 3, t), (v * 0.5 + [0.2, 0, 0], t)
    poking = (v * 0.5 + [3 * 0.57735027 - 0.2, 0, 0], t)  # half out of the big one's +x face
    d_in = wc.distance([small], [big], device=device, precision="float64")
    d_out = wc.distance([poking], [big], device=device, precision="float64")
    assert d_in.distance[0] == pytest.approx(-(3 * 0.57735027 - (0.57735027 * 0.5 - 0.2)), rel=1e-6)
    assert d_out.distance[0] < 0.0 and d_in.distance[0] < d_out.distance[0]  # deeper inside: more negative
    assert np.allclose(d_in.normal, [[1, 0, 0]])  # from a to b: a leaves along minus it
    assert wc.distance([big], [small], device=device, precision="float64").distance == pytest.approx(d_in.distance)


def test_open_sheets_crossing_have_contacts_at_depth_zero(device):
    a = grid(2, 2.0)
    b = grid(2, 2.0)
    b = (b[0][:, [0, 2, 1]], b[1])  # the same sheet stood up: they cross along a line
    c = wc.contacts([a, b], device=device)
    assert c.count >= 2 and np.isnan(c.pair_depth).all()
    assert np.abs(c.depth).max() == 0.0
    assert np.allclose(np.linalg.norm(c.normal, axis=1), 1.0)
    assert np.allclose(c.point_a[:, 2], 0.0, atol=1e-6) and np.allclose(c.point_a[:, 1], 0.0, atol=1e-6)


def test_apart_pairs_within_the_margin_get_a_speculative_contact(device):
    a = box([0, 0, 0], [1, 1, 1])
    b = box([0.2, 0.2, 1.03], [0.8, 0.8, 1.5])
    far = box([5, 5, 5], [6, 6, 6])
    c = wc.contacts([a, b, far], device=device, margin=0.05)
    assert c.pairs.tolist() == [[0, 1]]
    assert c.depth == pytest.approx([-0.03], rel=1e-5)
    assert np.allclose(c.normal, [0, 0, -1], atol=1e-4)  # float32 closest points
    assert np.allclose(c.point_a, c.point_b - c.depth[:, None] * c.normal, atol=1e-6)
    assert wc.contacts([a, b, far], device=device).count == 0  # no margin: nothing
    assert wc.contacts([a, (b[0] + [0, 0, 0.04], b[1])], device=device, margin=0.05).count == 0  # 0.07 apart


def test_stacked_cubes_with_flush_sides_push_along_the_stack_not_sideways(device):
    """The deepest points of a flat overlap form a plateau whose rim is as near to the side faces as to the top: the
    witness is taken from the middle of a triangle, and the normals point along the stack."""
    for n in (1, 2, 3):
        a = box([0, 0, 0], [0.2, 0.2, 0.2], 0, n)
        b = box([0, 0, 0.1992], [0.2, 0.2, 0.3992], 1, n)
        c = wc.contacts([b, a], device=device, precision="float64")
        assert c.depth.max() == pytest.approx(0.0008, rel=1e-6)
        assert np.allclose(c.normal, [0, 0, 1]), (n, c.normal)


def test_empty_and_apart_scenes(device):
    assert wc.contacts([], device=device).count == 0
    c = wc.contacts([box([0, 0, 0], [1, 1, 1]), box([3, 0, 0], [4, 1, 1])], device=device)
    assert c.count == 0 and c.pairs.shape == (0, 2) and c.depth.shape == (0,)


# 2. Against the exact depth, at random.

@pytest.mark.parametrize("seed", [0, 1])
def test_random_convex_pairs_deepest_contact_is_the_exact_depth(device, seed):
    rng = np.random.default_rng(seed)
    shapes = list(_convex_shapes())
    checked = 0
    for _ in range(6):
        (_, a), (_, b) = (shapes[i] for i in rng.integers(len(shapes), size=2))
        a = rotated(a, random_rotation(rng), np.zeros(3))
        d = rng.normal(size=3)
        b = rotated(b, random_rotation(rng), d / np.linalg.norm(d) * rng.uniform(0.2, 1.0))
        c = wc.contacts([a, b], device=device, precision="float64")
        want = pair_convex_depth(a, b)
        if c.count == 0:
            assert want < 1e-9
            continue
        check_contacts([a, b], c, tol=1e-7)
        assert c.depth.max() == pytest.approx(want, rel=1e-6, abs=1e-9)
        assert c.count <= 8
        checked += 1
    assert checked >= 3


def test_non_convex_scanned_mesh_contacts_lie_on_both_surfaces(device):
    """The scanned bear (3,968 triangles, closed, not convex) with a box pushed into its back and a copy of itself
    moved into it: every contact on both surfaces and consistent (the oracles of :func:`check_contacts`), and each
    pair's deepest contact is the pair's depth as the check measures it."""
    from warp_ccd._src.check.crossing import CrossingClassifier

    from test_clearance import asset_meshes

    v, t = asset_meshes("bear.usd", device)[0]
    size = np.ptp(v, axis=0).max()
    top = v[np.argmax(v[:, 2])]
    cube = box(top - [0.1 * size, 0.1 * size, 0.12 * size], top + [0.1 * size, 0.1 * size, 0.08 * size])
    moved = (v + [0.25 * np.ptp(v[:, 0]), 0.0, 0.05 * np.ptp(v[:, 2])], t)
    meshes = [(v, t), cube, moved]
    c = wc.contacts(meshes, device=device, precision="float64")
    check_contacts(meshes, c, tol=1e-6)
    scene = wc.Scene.from_meshes(meshes, device=device, precision="float64")
    res = wc.CollisionPipeline(scene).detect()
    found = CrossingClassifier(scene)(res.device_triangle_pairs)
    for p, want in zip(found.pairs, found.pair_depth):
        mine = (c.pairs == p).all(axis=1)
        assert c.depth[mine].max() == pytest.approx(want, rel=1e-3), p  # the check's floors differ by its tolerance


def test_reduction_keeps_the_deepest_and_at_most_max_per_pair(device):
    rng = np.random.default_rng(3)
    ball = wc.scene.icosphere(3)
    meshes = [rotated(ball, random_rotation(rng), rng.uniform(-0.7, 0.7, 3)) for _ in range(4)]
    full = wc.contacts(meshes, device=device, max_per_pair=32)
    for k in (1, 4, 8):
        c = wc.contacts(meshes, device=device, max_per_pair=k)
        check_contacts(meshes, c, tol=1e-5)
        pairs, counts = np.unique(c.pairs, axis=0, return_counts=True)
        assert counts.max() <= k
        for p in pairs:
            mine = (c.pairs == p).all(axis=1)
            theirs = (full.pairs == p).all(axis=1)
            assert c.depth[mine].max() == full.depth[theirs].max()  # the deepest always kept
            # The pair's depth (the same definition as the check's) is its deepest contact.
            at = np.flatnonzero((c.object_pairs == p).all(axis=1))[0]
            assert c.depth[mine].max() == pytest.approx(c.pair_depth[at], rel=2e-6)


def test_contacts_do_not_flip_when_objects_barely_move(device):
    a = box([0, 0, 0], [1, 1, 1], 0, 2)
    b = box([0.1, 0.1, 0.95], [0.9, 0.9, 1.5], 1, 2)
    first = wc.contacts([a, b], device=device, precision="float64", max_per_pair=4)
    for eps in (1e-9, -1e-9):
        moved = (b[0] + [eps, -eps, 0.0], b[1])
        again = wc.contacts([a, moved], device=device, precision="float64", max_per_pair=4)
        # The same points (a point on an edge may name either triangle beside it).
        assert np.allclose(again.point_a, first.point_a, atol=1e-8)
        assert np.allclose(again.normal, first.normal) and np.allclose(again.depth, first.depth)


def test_pipeline_contacts_every_frame_and_options(device):
    scene = wc.Scene.random(30, seed=2, device=device)
    pipe = wc.CollisionPipeline(scene, contacts=True, max_per_pair=4)
    for _ in range(3):
        res = pipe.detect(advance=1 / 30)
        c = res.contacts
        assert set(map(tuple, c.pairs)) == set(map(tuple, res.object_pairs))
        assert np.allclose(c.point_a, c.point_b - c.depth[:, None] * c.normal, atol=1e-5)
    assert wc.CollisionPipeline(scene).detect().contacts is None
    with pytest.raises(ValueError, match="max_per_pair"):
        wc.CollisionPipeline(scene, contacts=True, max_per_pair=0)
    with pytest.raises(ValueError, match="margin is an option of contacts"):
        wc.CollisionPipeline(scene, margin=0.1)
    with pytest.raises(ValueError, match="contacts: a continuous pipeline"):
        wc.CollisionPipeline(scene, contacts=True, continuous=True)
    cube = wc.scene.shape("cube")
    for bad, match in (({"max_per_pair": 33}, "max_per_pair"), ({"max_per_pair": True}, "max_per_pair"),
                       ({"max_per_pair": 2.5}, "max_per_pair"), ({"margin": -0.1}, "margin"),
                       ({"margin": float("nan")}, "margin")):
        with pytest.raises(ValueError, match=match):
            wc.contacts([cube, cube], **bad)
    with pytest.raises(ValueError, match="mesh 1"):
        wc.contacts([cube, (cube[0], cube[1] + 100)])


@pytest.mark.parametrize("precision", ["float32", "float64"])
def test_every_device_gives_the_recorded_contacts(device, precision):
    """Contacts and signed distances bit for bit as recorded on the CPU, so that a GPU machine without a CPU device
    checks it too."""
    got = distance_digests.contacts_digest(precision, device)
    assert got == distance_digests.read_reference()[f"contacts_{precision}"], f"differs on {device} from the CPU's"


@pytest.mark.skipif(len(ALL_DEVICES) < 2, reason="one device")
def test_every_device_gives_the_same_contacts():
    rng = np.random.default_rng(11)
    meshes = [rotated(wc.scene.icosphere(2), random_rotation(rng), rng.uniform(-0.8, 0.8, 3)) for _ in range(5)]
    meshes.append(box([-2, -2, -2], [2, 2, -0.6]))
    out = [wc.contacts(meshes, device=d, precision="float64") for d in ALL_DEVICES]
    for c in out[1:]:
        assert c.pairs.tolist() == out[0].pairs.tolist()
        assert c.triangles.tolist() == out[0].triangles.tolist()
        assert np.allclose(c.point_a, out[0].point_a, atol=1e-12) and np.allclose(c.depth, out[0].depth, atol=1e-12)


# 3. The signed distance.

def test_signed_distance_of_overlapping_cubes_is_minus_the_depth(device):
    cube = box([-0.5] * 3, [0.5] * 3)
    t = np.tile(np.eye(4), (2, 1, 1))
    t[0, 0, 3], t[1, 0, 3] = 5.0, 5.75
    r = wc.distance([cube], [cube], t[:1], t[1:], device=device)
    assert r.distance == pytest.approx([-0.25], rel=1e-6)
    p, q = r.closest_points[0]
    assert np.linalg.norm(p - q) == pytest.approx(0.25, rel=1e-6)
    assert np.allclose(r.normal, [[1, 0, 0]])  # from a to b: a leaves along minus it
    t[1, 0, 3] = 9.0
    assert wc.distance([cube], [cube], t[:1], t[1:], device=device).distance == pytest.approx([3.0])
    t[1, 0, 3] = 6.0  # touching: 0
    assert wc.distance([cube], [cube], t[:1], t[1:], device=device).distance == pytest.approx([0.0], abs=1e-6)
    unsigned = wc.distance([cube], [cube], t[:1], t[1:], device=device, signed=False)
    assert unsigned.distance.min() >= 0.0


def test_signed_distance_of_random_convex_pairs(device):
    rng = np.random.default_rng(5)
    shapes = [s for _, s in _convex_shapes()]
    meshes = []
    for i in range(6):
        m = shapes[i % len(shapes)]
        meshes.append(rotated(m, random_rotation(rng), rng.uniform(-0.9, 0.9, 3)))
    r = wc.distance(meshes, device=device, precision="float64")
    for (i, j), d in zip(r.pairs, r.distance):
        want = pair_convex_depth(meshes[i], meshes[j])
        if d < 0:
            assert -d == pytest.approx(want, rel=1e-6)
        elif d == 0:
            assert want <= 1e-9
        else:
            assert want == 0.0
