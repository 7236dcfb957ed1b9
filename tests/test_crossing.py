"""Penetrating or touching (:mod:`warp_ccd._src.check.crossing`): a property of the surfaces, not of their
triangulation. Crafted scenes (a crate sunk into or resting on floors cut every way, flush boxes,
CAD-like contacts), and random boxes judged against the exact rational oracle of ``solids.py``,
under re-triangulation, mirroring and non-uniform scale."""

from fractions import Fraction as F

import numpy as np
import pytest
import warp as wp
from depth_reference import convex_depth, pair_convex_depth
from solids import Box, interiors_overlap, rotation

import warp_ccd as wc
from warp_ccd._src.check.crossing import CrossingClassifier
from warp_ccd._src.narrowphase.surface import surface_topology


def grid(n: int, size: float = 3.0, angle: float = 0.0, offset=(0.0, 0.0), z: float = 0.0, flip: bool = False):
    """An ``n x n`` quad grid in the plane ``z``, facing +z (-z when ``flip``), rotated by ``angle`` about z."""
    xs = np.linspace(-size / 2, size / 2, n + 1)
    gx, gy = np.meshgrid(xs, xs, indexing="ij")
    p = np.stack([gx.ravel() + offset[0], gy.ravel() + offset[1]], axis=1)
    c, s = np.cos(angle), np.sin(angle)
    p = p @ np.array([[c, s], [-s, c]])
    v = np.concatenate([p, np.full((len(p), 1), z)], axis=1)
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    q = np.stack([idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]], axis=-1).reshape(-1, 4)
    t = np.concatenate([q[:, [0, 1, 2]], q[:, [0, 2, 3]]])
    return v, (t[:, ::-1] if flip else t).astype(np.int32)


def box(lo, hi, diagonal: int = 0, n: int = 1):
    """An axis-aligned box, outward-wound."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    b = Box([F(x).limit_denominator(1 << 20) / 2 for x in hi - lo],
            centre=[F(x).limit_denominator(1 << 20) / 2 for x in hi + lo])
    return b.mesh(diagonal, n)


def classify(meshes, device, precision="float32"):
    """The :class:`Crossings` of every intersecting triangle pair of the meshes, and the rows."""
    scene = wc.Scene.from_meshes(meshes, device=device, precision=precision)
    res = wc.CollisionPipeline(scene).detect()
    found = CrossingClassifier(scene)(res.device_triangle_pairs)
    return found, res.device_triangle_pairs.numpy().reshape(-1, 4)


def verdict(meshes, device, precision="float32"):
    """``(touch, cross, deepest)``: whether the first two meshes meet, cross, and the pairs' largest depth
    (0 when nothing crosses; NaN where it is undefined)."""
    found, rows = classify(meshes, device, precision)
    depth = float(found.pair_depth.max()) if len(found.pair_depth) else 0.0
    return len(rows) > 0, bool(found.crossing.any()), depth


def test_surface_topology_neighbours_and_fans(device):
    v, t = box([0, 0, 0], [1, 1, 1])
    fv, ft = grid(2)
    scene = wc.Scene.from_meshes([(v, t), (fv, ft)], device=device)
    s = surface_topology(scene)
    nb = s.neighbour.numpy()
    cube, floor = nb[:12], nb[12:]
    assert (cube >= 0).all(), "a closed box has no open edge"
    for i in range(12):  # neighbours are mutual and share the edge
        for k in range(3):
            j = cube[i, k]
            assert i in cube[j]
            assert {t[i, k], t[i, (k + 1) % 3]} <= set(t[j])
    assert (floor == -1).sum() == 8, "a 2 x 2 grid has 8 boundary edges"
    fan_start, fan = s.fan_start.numpy(), s.fan.numpy()
    assert fan_start[-1] == 3 * (len(t) + len(ft))
    for vert in range(len(v)):
        assert sorted(fan[fan_start[vert]:fan_start[vert + 1]]) == sorted(np.nonzero((t == vert).any(axis=1))[0])
    assert s.shape_side.numpy().tolist() == [1.0, 1.0]
    inside_out = wc.Scene.from_meshes([(v, t[:, ::-1].copy()), (fv, ft[:, ::-1].copy())], device=device)
    assert surface_topology(inside_out).shape_side.numpy().tolist() == [-1.0, 1.0], "only a solid is turned round"


# 1. A crate sunk 0.5 into a floor, or resting on it, whatever the floor's grid.

FLOORS = [(n, 0.0) for n in range(1, 9)] + [(n, a) for n in (3, 4, 7) for a in (0.3, np.pi / 4)]


@pytest.mark.parametrize("n,angle", FLOORS)
def test_crate_sunk_in_a_floor_penetrates_by_its_depth(device, n, angle):
    floor = grid(n, angle=angle)
    touch, cross, deepest = verdict([floor, box([-0.5, -0.5, -0.5], [0.5, 0.5, 0.5])], device)
    assert touch and cross
    assert deepest == pytest.approx(0.5, rel=1e-5)
    # Sunk by 0.25 with its walls on the grid lines of a 3 x 3 floor of size 3 (n = 3, no rotation).
    touch, cross, deepest = verdict([floor, box([-0.5, -0.5, -0.25], [0.5, 0.5, 0.75], diagonal=1)], device)
    assert cross and deepest == pytest.approx(0.25, rel=1e-5)


@pytest.mark.parametrize("n,angle", FLOORS)
def test_crate_resting_on_a_floor_touches(device, n, angle):
    floor = grid(n, angle=angle)
    for diagonal in (0, 1):
        touch, cross, deepest = verdict([floor, box([-0.5, -0.5, 0.0], [0.5, 0.5, 1.0], diagonal)], device)
        assert touch and not cross and deepest == 0.0
    # Under a floor facing down, a crate hanging from it touches too.
    touch, cross, _ = verdict([grid(n, angle=angle, flip=True), box([-0.5, -0.5, -1.0], [0.5, 0.5, 0.0])], device)
    assert touch and not cross


def test_crossing_sheets_and_a_poking_vertex(device):
    # Two open quads crossing in an X: they cross, and bound no solid: no depth (NaN).
    a = grid(1, size=2.0)
    b = (a[0][:, [2, 0, 1]], a[1])  # the same quad in the plane x = 0
    touch, cross, deepest = verdict([a, b], device)
    assert cross and np.isnan(deepest)
    # A tetrahedron's tip poking h through a plate, coarse or finely cut: the plate inside the tetrahedron
    # (the plate is open), measured to its faces: the exact linear program's depth, however it is cut.
    h = 0.05
    tip = np.array([[0.0, 0.0, -h], [0.3, 0.0, 1.0], [-0.2, 0.25, 1.0], [-0.2, -0.25, 1.0]])
    tet = np.array([[0, 2, 1], [0, 3, 2], [0, 1, 3], [1, 2, 3]], np.int32)
    for n in (1, 2, 5, 16):
        plate = grid(n, size=2.0, offset=(0.1, 0.07))
        touch, cross, deepest = verdict([plate, (tip, tet)], device)
        assert cross and deepest == pytest.approx(convex_depth(plate, (tip, tet)), rel=1e-4), n
    # Resting on its tip: touching.
    touch, cross, _ = verdict([grid(4, size=2.0), (tip + [0, 0, h], tet)], device)
    assert touch and not cross


def test_flush_boxes(device):
    # Overlapping by a quarter of their volume with four faces flush: penetrating.
    for n in (1, 2, 3):
        touch, cross, _ = verdict([box([0, 0, 0], [1, 1, 1], n=n), box([0.75, 0, 0], [1.75, 1, 1], 1, n)], device)
        assert cross, n
    # Side by side, face on face, or stacked with an offset: touching.
    touch, cross, _ = verdict([box([0, 0, 0], [1, 1, 1]), box([1, 0, 0], [2, 1, 1], 1)], device)
    assert touch and not cross
    touch, cross, _ = verdict([box([0, 0, 0], [1, 1, 1]), box([0.3, 0.2, 1], [1.4, 0.9, 2], 1, 2)], device)
    assert touch and not cross
    # The same box twice: penetrating (all of it overlaps).
    touch, cross, _ = verdict([box([0, 0, 0], [1, 1, 1]), box([0, 0, 0], [1, 1, 1], 1)], device)
    assert cross


def test_cad_contacts_touch(device):
    s = F(1, 2)
    cube = Box([s, s, s])
    # Edge on edge (crossed), edge on face, vertex on face, vertex on edge, face on face with an offset
    # (at the cube's corner the rotated box's lowest point may miss the cube: apart).
    touching = 0
    for q in [(3, 1, 0, 0), (5, 1, 2, 0), (4, 1, 1, 1), (2, 0, 0, 1)]:
        other = Box([F(1, 3), F(1, 4), F(1, 2)], rotation(q))
        for lateral in [(0, 0), (F(1, 2), 0), (F(1, 2), F(1, 2)), (F(1, 5), -F(1, 7))]:
            lo, _ = other.extent([0, 0, 1])
            placed = other.moved([lateral[0], lateral[1], s - lo])
            assert not interiors_overlap(cube, placed)
            touch, cross, _ = verdict([cube.mesh(), placed.mesh(1)], device)
            assert not cross, (q, lateral)
            touching += touch
    assert touching >= 12


# 2. Random boxes against the exact oracle, every way they are cut, mirrored and stretched.

QUATERNIONS = [(1, 0, 0, 0), (2, 1, 0, 0), (3, 1, 1, 0), (4, 1, 2, 2), (1, 1, 0, 0), (5, 2, 1, 3), (2, 0, 1, 1)]


def random_pairs(seed: int, count: int):
    """``count`` box pairs ``(a, b, h)``: ``b`` resting on ``a``'s top face (h = 0), sunk ``h > 0``, or
    lifted (h < 0), or flush with it (sharing face planes) overlapping or not."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(count):
        rot_a = rotation(QUATERNIONS[rng.integers(len(QUATERNIONS))])
        a = Box([F(1, 2), F(int(rng.integers(2, 5)), 6), F(1, 2)], rot_a)
        if rng.random() < 0.3:  # flush: the same orientation, faces in shared planes
            half = [F(int(rng.integers(1, 4)), 6), a.half[1], a.half[2]]
            shift = a.half[0] + half[0] - F(int(rng.integers(0, 3)), 8)
            b = Box(half, rot_a, [x * shift for x in a.axis(0)])
            out.append((a, b, None))
            continue
        rot_b = rotation(QUATERNIONS[rng.integers(len(QUATERNIONS))])
        b = Box([F(int(rng.integers(1, 4)), 6) for _ in range(3)], rot_b)
        up = a.axis(2)
        top = a.extent(up)[1]
        lo, _ = b.extent(up)
        sx, sy = F(int(rng.integers(-2, 3)), 10), F(int(rng.integers(-2, 3)), 10)
        lateral = [sx * x + sy * y for x, y in zip(a.axis(0), a.axis(1))]
        h = [F(0), F(1, 16), F(-1, 16)][int(rng.integers(3))]
        out.append((a, b.moved([lat + u * (top - lo - h) for lat, u in zip(lateral, up)]), h))
    return out


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_random_boxes_against_the_exact_oracle(device, seed):
    mirror = np.array([-1.0, 1.0, 1.0])
    stretch = np.array([1.0, 2.0, 0.5])
    for a, b, h in random_pairs(seed, 8):
        overlap = interiors_overlap(a, b)
        if h is not None:
            assert overlap == (h > 0)
        for diagonal, n in [(0, 1), (1, 1), (0, 2), (1, 3)]:
            (va, ta), (vb, tb) = a.mesh(diagonal, n), b.mesh(1 - diagonal, max(1, n - 1))
            for scale, wound in [(None, 1), (mirror, -1), (stretch, 1)]:
                ma = (va * scale if scale is not None else va, ta[:, ::wound].copy())
                mb = (vb * scale if scale is not None else vb, tb[:, ::wound].copy())
                touch, cross, deepest = verdict([ma, mb], device, "float64")
                assert cross == overlap, (seed, diagonal, n, scale, h)
                if scale is None and overlap:
                    # The pair's depth, whatever the cut: the exact linear program's (depth_reference).
                    assert deepest == pytest.approx(pair_convex_depth(ma, mb), rel=1e-9), (seed, diagonal, n)


def test_degenerate_and_empty(device):
    # No rows: nothing to classify.
    scene = wc.Scene.from_meshes([box([0, 0, 0], [1, 1, 1])], device=device)
    found = CrossingClassifier(scene)(wp.zeros(0, dtype=wp.vec4i, device=device))
    crossing, depth = found.crossing, found.depth
    assert crossing.shape == (0,) and depth.shape == (0,)
    # A fan-triangulated floor with slivers (collinear points on its rim, where a crate's walls
    # cross it) still crosses the crate; resting on it, the crate touches.
    v, _ = grid(1)
    rim = np.array([[-1.5, -0.5, 0.0], [-1.5, 0.5, 0.0]])
    verts = np.concatenate([v, rim])
    fan = np.array([[0, 2, 3], [0, 3, 1], [0, 1, 5], [0, 5, 4]], np.int32)
    touch, cross, deepest = verdict([(verts, fan), box([-2, -0.5, -0.5], [-1, 0.5, 0.5])], device)
    assert cross and deepest >= 0.5
    touch, cross, deepest = verdict([(verts, fan), box([-2, -0.5, 0], [-1, 0.5, 1])], device)
    assert touch and not cross


def test_far_from_the_origin_and_tiny(device):
    for offset, size in [(np.array([1e5, -2e5, 3e4]), 1.0), (np.zeros(3), 1e-4)]:
        floor = grid(4)
        sunk = box([-0.5, -0.5, -0.5], [0.5, 0.5, 0.5])
        rest = box([-0.5, -0.5, 0.0], [0.5, 0.5, 1.0])
        place = lambda m: (m[0] * size + offset, m[1])  # noqa: E731
        _, cross, deepest = verdict([place(floor), place(sunk)], device, "float64")
        assert cross and deepest == pytest.approx(0.5 * size, rel=1e-5)
        _, cross, _ = verdict([place(floor), place(rest)], device, "float64")
        assert not cross


@pytest.mark.parametrize("precision", ["float32", "float64"])
def test_rigid_and_deforming_depths_agree(device, precision, rng):
    """The same spheres placed by poses (their trees in their shapes' space) and given as world vertices
    (deforming: trees in the world): the same pairs and depths, down the pipeline's trees or the depth's own."""
    sphere = wc.scene.icosphere(3)
    meshes, transforms = [], []
    for _ in range(12):
        q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        m = np.eye(4)
        m[:3, :3] = q * np.sign(np.linalg.det(q))
        m[:3, 3] = rng.uniform(-1.5, 1.5, 3) + [100.0, -50.0, 20.0]
        meshes.append((sphere[0] * rng.uniform(0.6, 1.0), sphere[1]))
        transforms.append(m)
    out = []
    for deforming in (False, True):
        if deforming:
            world = [(v @ t[:3, :3].T + t[:3, 3], f) for (v, f), t in zip(meshes, transforms)]
            scene = wc.Scene.from_meshes(world, deforming=True, device=device, precision=precision)
        else:
            scene = wc.Scene.from_meshes(meshes, np.array(transforms), device=device, precision=precision)
        pipe = wc.CollisionPipeline(scene)
        pairs = pipe.detect().device_triangle_pairs
        found = CrossingClassifier(scene, trees=pipe.boxes)(pairs)
        own = CrossingClassifier(scene)(pairs)
        assert found.crossing.any() and len(found.pairs) >= 5
        np.testing.assert_array_equal(found.pairs, own.pairs)
        np.testing.assert_array_equal(found.pair_depth, own.pair_depth)
        out.append(found)
    np.testing.assert_array_equal(out[0].pairs, out[1].pairs)
    # The world vertices themselves differ by float32's rounding at 100 units (the poses applied in float32 or
    # float64): about 8e-6 there.
    atol = 1e-9 if precision == "float64" else 8 * np.finfo(np.float32).eps * 120
    np.testing.assert_allclose(out[0].pair_depth, out[1].pair_depth, rtol=1e-9, atol=atol)


# 3. What assets do that the crafted solids above do not.

def test_open_surfaces_keep_their_winding(device):
    """An open grid is never turned round, however many of its edges are inner ones: a tray-shaped
    floor (its rim raised) or a tilted flat one, with a crate resting on it, only touches."""
    floor = grid(8)
    tray = (floor[0] + [[0, 0, 0.5 * (abs(x) > 1.2 or abs(y) > 1.2)] for x, y, _ in floor[0]], floor[1])
    assert surface_topology(wc.Scene.from_meshes([tray], device=device)).shape_side.numpy().tolist() == [1.0]
    touch, cross, _ = verdict([tray, box([-0.5, -0.5, 0], [0.5, 0.5, 1])], device, "float64")
    assert touch and not cross
    rng = np.random.default_rng(0)
    for _ in range(3):
        q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        q[:, 0] *= np.sign(np.linalg.det(q))
        shift = 10 * rng.normal(size=3)
        place = lambda m: (m[0] @ q.T + shift, m[1])  # noqa: E731
        touch, cross, _ = verdict([place(floor), place(box([-0.5, -0.5, 0], [0.5, 0.5, 1]))], device, "float64")
        assert touch and not cross


def test_float32_rounding_far_from_the_origin_is_not_a_crossing(device):
    """A crate resting on a floor, both placed by one rotation and a translation of 1,000 or 3,000,
    in float32: the world vertices' rounding (about 1e-4 there) is no penetration."""
    rng = np.random.default_rng(0)
    for offset in (1e3, 3e3):
        for _ in range(3):
            q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
            q[:, 0] *= np.sign(np.linalg.det(q))
            m = np.eye(4)
            m[:3, :3], m[:3, 3] = q, offset * np.array([1.0, -0.7, 0.5])
            scene = wc.Scene.from_meshes([grid(4), box([-0.5, -0.5, 0], [0.5, 0.5, 1])], np.array([m, m]),
                                         device=device)
            pairs = wc.CollisionPipeline(scene).detect().device_triangle_pairs
            crossing = CrossingClassifier(scene)(pairs).crossing
            assert pairs.shape[0] > 0 and not crossing.any(), offset


def test_two_sided_sheets_and_slivers_on_rims(device):
    """A sheet drawn from both sides (each face twice) has nothing behind it; a sliver on a solid's
    rim is no flat continuation."""
    fv, ft = grid(4)
    two_sided = (fv, np.concatenate([ft, ft[:, ::-1]]))
    touch, cross, _ = verdict([two_sided, box([-0.5, -0.5, 0], [0.5, 0.5, 1])], device)
    assert touch and not cross
    touch, cross, _ = verdict([two_sided, box([-0.5, -0.5, -0.5], [0.5, 0.5, 0.5])], device)
    assert cross, "a crate sunk through a two-sided floor still crosses it"
    shelf = (fv * [0.3, 0.3, 1] + [0.45, 0, 0.5], np.concatenate([ft, ft[:, ::-1]]))
    touch, cross, _ = verdict([shelf, box([-1, -1, 0], [0, 1, 1])], device)
    assert touch and not cross, "a two-sided shelf butting against a wall"
    # A unit cube whose top face is fanned with a sliver (a collinear vertex on its front rim).
    v = np.array([[0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1], [0.5, 0, 1], [0, 0, 0], [1, 0, 0], [1, 1, 0],
                  [0, 1, 0]], float)
    t = np.array([[0, 4, 1], [0, 1, 2], [0, 2, 3], [5, 6, 1], [5, 1, 4], [5, 4, 0], [5, 7, 6], [5, 8, 7],
                  [6, 7, 2], [6, 2, 1], [7, 8, 3], [7, 3, 2], [8, 5, 0], [8, 0, 3]], np.int32)
    touch, cross, _ = verdict([(v, t), box([0.2, -0.5, 1], [0.8, 0.5, 2])], device)
    assert touch and not cross, "a crate resting on the cube, overhanging the sliver's rim"


def test_depth_at_an_open_rim_and_a_tiny_object(device):
    # A crate sunk 0.1 into a floor whose edge runs under it: as deep as it is sunk, not as far as
    # its corners beyond the rim are from that edge.
    floor = (grid(2)[0] * [0.5, 1, 1] - [0.75, 0, 0], grid(2)[1])  # x in [-1.5, 0]
    touch, cross, deepest = verdict([floor, box([-0.5, -0.5, -0.1], [0.5, 0.5, 0.9])], device, "float64")
    assert cross and deepest == pytest.approx(0.1, rel=1e-6)
    # A 1 cm cube half sunk into a floor of two 1,000-unit triangles: the tolerance is the cube's.
    big = (grid(1)[0] * 1000 / 3, grid(1)[1])
    touch, cross, deepest = verdict([big, box([0, 0, -0.005], [0.01, 0.01, 0.005])], device, "float64")
    assert cross and deepest == pytest.approx(0.005, rel=1e-6)
