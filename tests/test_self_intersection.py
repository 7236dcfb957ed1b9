"""Self-intersection (:func:`warp_ccd.self_intersections`, the pipeline's ``self_pairs``) against the exact
brute force (:mod:`self_reference`, the rules in rational arithmetic), the exact intersection of closed
triangles (:mod:`exact_intersection`, which knows none of the rules: random pairs on an integer grid,
sharing 0, 1 or 2 vertices, coplanar or degenerate) and pymeshlab, on every device.

Crafted: a fold flat onto itself along a shared edge, folds to the other side and bent, two triangles
sharing a vertex and crossing beyond it, or meeting only there, coplanar wedges at a shared vertex,
one face twice, near misses; closed meshes without defects (icospheres, split-vertex copies, fanned
polygons with collinear corners, the scanned bunny, the RJ45 plug's CAD parts): 0 pairs. Seeded: cloth
sheets crumpled and folded through themselves, a figure-eight torus. The pipeline: rigid objects once
from their shapes (instances share them), deforming objects every frame, flags, growth, one object.
"""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp
from exact_intersection import meets_beyond
from hypothesis import given, settings
from hypothesis import strategies as st
from self_reference import pair_meets, reference_self_pairs

import warp_ccd as wc
from warp_ccd._src.narrowphase.self_intersection import weld_vertices
from warp_ccd.scene import figure_eight_torus, icosphere, sheet

from test_clearance import asset_meshes

TOL = wc.TOLERANCE


def _reference(v, t, tol=TOL):
    return reference_self_pairs(v, t, weld_vertices(np.asarray(v, np.float64), [0, len(v)]), tol)


def crumpled_sheet(n: int, seed: int, fold: float | None = 0.5, amplitude: float = 0.03):
    """A sheet of ``n x n`` vertices with random heights, its part beyond ``x = fold`` folded back over
    the rest (mirrored, shifted so that no column lands on another) and lifted a little: it passes
    through itself where the heights cross."""
    rng = np.random.default_rng(seed)
    v, t = sheet(n)
    v = v.astype(np.float64)
    v[:, 2] = amplitude * rng.standard_normal(len(v))
    if fold is not None:
        f = v[:, 0] > fold
        v[f, 0] = 2 * fold + 0.37 / (n - 1) - v[f, 0]
        v[f, 2] += 0.3 * amplitude
    return v, t


CRAFTED = {
    # name: (vertices, triangles, expected pairs)
    "fold_onto_itself": ([[0, 0, 0], [1, 0, 0], [0.5, 1, 0], [0.3, 0.6, 0]], [[0, 1, 2], [0, 1, 3]], [[0, 1]]),
    "fold_nearly_flat": ([[0, 0, 0], [1, 0, 0], [0.5, 1, 0], [0.3, 0.6, 2e-6]], [[0, 1, 2], [0, 1, 3]], [[0, 1]]),
    "folded_bent": ([[0, 0, 0], [1, 0, 0], [0.5, 1, 0], [0.3, 0.6, 1e-3]], [[0, 1, 2], [0, 1, 3]], []),
    "flat_neighbours": ([[0, 0, 0], [1, 0, 0], [0.5, 1, 0], [0.3, -0.6, 0]], [[0, 1, 2], [0, 1, 3]], []),
    "fold_beyond": ([[0, 0, 0], [1, 0, 0], [0.5, 1, 0], [1.5, 2, 0]], [[0, 1, 2], [0, 1, 3]], [[0, 1]]),
    "vertex_crossing": ([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0.5, 0.5, -0.5], [0.2, 0.3, 0.5]],
                        [[0, 1, 2], [0, 3, 4]], [[0, 1]]),
    "vertex_only": ([[0, 0, 0], [1, 0, 0], [0, 1, 0], [-1, -0.2, 0.5], [-0.3, -1, 0.4]], [[0, 1, 2], [0, 3, 4]], []),
    "vertex_coplanar_wedges": ([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 0.3, 0], [0.8, 0.9, 0]],
                               [[0, 1, 2], [0, 3, 4]], [[0, 1]]),
    "vertex_coplanar_apart": ([[0, 0, 0], [1, 0, 0], [0.3, 1, 0], [-1, 0.3, 0], [-0.8, 0.9, 0]],
                              [[0, 1, 2], [0, 3, 4]], []),
    "vertex_edge_along": ([[0, 0, 0], [1, 0, 0], [0, 1, 0], [2, 0, 0], [1, -1, 1]], [[0, 1, 2], [0, 3, 4]], [[0, 1]]),
    "face_twice": ([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2], [2, 0, 1]], [[0, 1]]),
    "near_miss": ([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0.2, 0.2, 1e-3], [0.6, 0.2, 1e-3], [0.2, 0.6, 0.5]],
                  [[0, 1, 2], [3, 4, 5]], []),
    "touching": ([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0.2, 0.2, 0], [0.6, 0.2, 1], [0.2, 0.6, 1]],
                 [[0, 1, 2], [3, 4, 5]], [[0, 1]]),
    "split_vertices_fold": ([[0, 0, 0], [1, 0, 0], [0.5, 1, 0], [0, 0, 0], [1, 0, 0], [0.3, 0.6, 0]],
                            [[0, 1, 2], [3, 4, 5]], [[0, 1]]),
    "split_vertices_flat": ([[0, 0, 0], [1, 0, 0], [0.5, 1, 0], [0, 0, 0], [1, 0, 0], [0.3, -0.6, 0]],
                            [[0, 1, 2], [3, 4, 5]], []),
    # A sliver whose middle vertex is shared, its span crossing the neighbour's plane only there (and, in
    # the neighbour's plane, running into it beyond the vertex).
    "sliver_through_vertex": ([[0, 0, 0], [-1, 0, -1], [1, 0, 1], [1, 1, 0], [0, 1, 1]], [[0, 1, 2], [0, 3, 4]], []),
    "sliver_through_vertex_in_plane": ([[0, 0, 0], [-1, -1, 0], [1, 1, 0], [1, 0, 0], [0, 2, 0]],
                                       [[0, 1, 2], [0, 3, 4]], [[0, 1]]),
    "sliver_end_at_vertex": ([[0, 0, 0], [0.5, 0.5, 0], [1, 1, 0], [1, 0, 0], [0, -1, 0]], [[0, 1, 2], [0, 3, 4]], []),
    "two_slivers_along": ([[0, 0, 0], [1, 0, 0], [2, 0, 0], [0.5, 0, 0], [3, 0, 0]], [[0, 1, 2], [0, 3, 4]], [[0, 1]]),
    "two_slivers_apart": ([[0, 0, 0], [1, 0, 0], [2, 0, 0], [-0.5, 0, 0], [-3, 0, 0]], [[0, 1, 2], [0, 3, 4]], []),
    # A polygon fanned from a corner collinear with the next two: a sliver along the next triangle's edge.
    "fan_sliver": ([[0, 0, 0], [1, 0, 0], [2, 0, 0], [2, 1, 0], [0, 1, 0]], [[0, 1, 2], [0, 2, 3], [0, 3, 4]], []),
    "slivers_beyond_edge": ([[0, 0, 0], [1, 0, 0], [2, 0, 0], [3, 0, 0]], [[0, 1, 2], [0, 1, 3]], [[0, 1]]),
}


@pytest.mark.parametrize("name", sorted(CRAFTED))
@pytest.mark.parametrize("precision", ["float32", "float64"])
def test_crafted(device, name, precision):
    v, t, expected = CRAFTED[name]
    v, t = np.array(v, np.float64), np.array(t)
    got = wc.self_intersections(v, t, device=device, precision=precision)
    assert got.tolist() == expected
    assert _reference(v, t).tolist() == expected  # the oracle agrees with the crafted answer
    res = wc.collide([(v, t)], device=device, precision=precision, self_intersections=True)
    assert res.self_pairs.tolist() == [[0, *p] for p in expected]
    assert res.self_colliding.tolist() == [bool(expected)]


def test_far_from_origin_and_scaled(device):
    """The verdicts hold under translation far away (float64) and scaling."""
    for name, (v, t, expected) in CRAFTED.items():
        v = np.array(v, np.float64)
        for scale, shift, precision in ((1e-4, 0.0, "float32"), (1e4, 0.0, "float32"), (1.0, 1e7, "float64")):
            got = wc.self_intersections(v * scale + shift, t, device=device, precision=precision)
            assert got.tolist() == expected, (name, scale, shift)


def test_closed_meshes_without_defects(device):
    """Icospheres, a copy with every triangle's vertices split (as STL stores them), the polyhedra: 0."""
    meshes = [icosphere(level) for level in (0, 2, 4)] + [wc.scene.shape(n) for n in wc.scene.SHAPES]
    v, t = icosphere(2)
    meshes.append((v[t].reshape(-1, 3), np.arange(3 * len(t)).reshape(-1, 3)))  # split vertices
    for v, t in meshes:
        assert len(wc.self_intersections(v, t, device=device)) == 0
    res = wc.collide(meshes, device=device, self_intersections=True)
    assert len(res.self_pairs) == 0 and not res.self_colliding.any()


def test_real_meshes(device):
    """Real assets as this package's USD reader gives them (polygons fanned into triangles): the scanned
    bunny, the bear and the shirt have no self-intersection; the CAD parts of the RJ45 plug and the
    quadrotor hold bodies exported into one mesh through each other (their self-intersections are real:
    the exact brute force finds the same pairs, and pymeshlab the same faces)."""
    pymeshlab = pytest.importorskip("pymeshlab") if not wp.get_device(device).is_cuda else None
    found = {}
    for name in ("bunny.usd", "bear.usd", "unisex_shirt.usd", "rj45_plug.usd", "crazyflie.usd"):
        found[name] = 0
        for v, t in asset_meshes(name, device):
            got = wc.self_intersections(v, t, device=device, precision="float64")
            assert got.tolist() == _reference(v, t).tolist(), name
            found[name] += len(got)
            if pymeshlab is not None and len(got):
                ms = pymeshlab.MeshSet()
                ms.add_mesh(pymeshlab.Mesh(v, np.asarray(t, np.int32)))
                ms.compute_selection_by_self_intersections_per_face()
                theirs = np.nonzero(ms.current_mesh().face_selection_array())[0]
                assert set(theirs.tolist()) <= set(np.unique(got).tolist()), name
    assert found["bunny.usd"] == found["bear.usd"] == found["unisex_shirt.usd"] == 0
    assert found["rj45_plug.usd"] > 100 and found["crazyflie.usd"] > 100


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("precision", ["float32", "float64"])
def test_crumpled_sheets_against_reference(device, seed, precision):
    n = 14 + 3 * seed
    v, t = crumpled_sheet(n, seed, fold=None if seed == 3 else 0.5, amplitude=0.03 if seed < 2 else 0.2)
    ref = _reference(v.astype(np.float32).astype(np.float64) if precision == "float32" else v, t)
    got = wc.self_intersections(v, t, device=device, precision=precision, leaf_size=1 + seed)
    assert got.tolist() == ref.tolist()
    if seed < 3:
        assert len(ref) > 20


def test_figure_eight_torus(device):
    v, t = figure_eight_torus(40, 12)
    ref = _reference(v, t)
    got = wc.self_intersections(v, t, device=device)
    assert got.tolist() == ref.tolist()
    # It crosses itself all around the circle: every segment of it has crossing triangles.
    seg = np.unique(got // (2 * 12))
    assert len(seg) == 40


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), n=st.integers(3, 9), amplitude=st.sampled_from([0.0, 1e-3, 0.1, 0.5]),
       fold=st.sampled_from([None, 0.3, 0.5]))
def test_sheets_property(seed, n, amplitude, fold):
    """Random sheets, flat or crumpled, folded or not: the same pairs as the exact brute force."""
    v, t = crumpled_sheet(n, seed, fold=fold, amplitude=amplitude)
    v = v.astype(np.float32).astype(np.float64)
    assert wc.self_intersections(v, t).tolist() == _reference(v, t).tolist()


def test_against_pymeshlab(device):
    """The faces in pairs that share at most one vertex are those pymeshlab selects
    (``compute_selection_by_self_intersections_per_face``; VCG's test skips triangles sharing an edge,
    so folds along an edge are ours alone)."""
    pymeshlab = pytest.importorskip("pymeshlab")
    meshes = [crumpled_sheet(24, seed) for seed in range(3)] + [figure_eight_torus(48, 16)]
    for v, t in meshes:
        v = np.asarray(v, np.float64)
        got = wc.self_intersections(v, t, device=device, precision="float64")
        shared = (t[got[:, 0]][:, :, None] == t[got[:, 1]][:, None, :]).any(axis=2).sum(axis=1)
        ms = pymeshlab.MeshSet()
        ms.add_mesh(pymeshlab.Mesh(v, np.asarray(t, np.int32)))
        ms.compute_selection_by_self_intersections_per_face()
        theirs = np.nonzero(ms.current_mesh().face_selection_array())[0]
        assert np.unique(got[shared <= 1]).tolist() == theirs.tolist()
        assert len(theirs) > 0


def test_pipeline_rigid_and_deforming(device):
    """Rigid objects report their shape's pairs (two instances of one shape: both), computed once;
    deforming objects every frame, as their vertices change."""
    folded = crumpled_sheet(12, 1)
    flat = crumpled_sheet(10, 2, fold=None, amplitude=0.0)
    torus = figure_eight_torus(24, 8)
    ref = {k: _reference(v, t) for k, (v, t) in enumerate((folded, flat, torus))}
    transforms = np.tile(np.eye(4), (4, 1, 1))
    transforms[:, 0, 3] = [0, 3, 6, 12]
    scene = wc.Scene.from_meshes([folded, flat, torus, folded], transforms, device=device)
    pipe = wc.CollisionPipeline(scene, self_intersections=True)
    expect = np.concatenate([np.c_[np.full(len(ref[s]), i), ref[s]] for i, s in enumerate((0, 1, 2, 0))])
    for _ in range(2):
        res = pipe.detect()
        assert res.self_pairs.tolist() == expect.tolist()
        assert res.self_colliding.tolist() == [True, False, True, True]
    assert pipe.self_phase.shape_rows[:, 0].tolist() == [0] * len(ref[0]) + [2] * len(ref[2])

    # Deforming: the flat sheet folds, then the folded one lies flat.
    meshes = [(v + [3.0 * k, 0, 0], t) for k, (v, t) in enumerate((folded, flat))]
    scene = wc.Scene.from_meshes(meshes, deforming=True, device=device)
    pipe = wc.CollisionPipeline(scene, self_intersections=True, self_capacity=1)
    res = pipe.detect().copy()
    assert res.self_pairs.tolist() == np.c_[np.zeros(len(ref[0]), int), ref[0]].tolist()
    refolded = crumpled_sheet(10, 5)
    scene.set_world_vertices(np.concatenate([crumpled_sheet(12, 1, fold=None, amplitude=0.0)[0],
                                             refolded[0] + [3.0, 0, 0]]))
    res2 = pipe.detect()
    expect = _reference(*refolded)
    assert res2.self_pairs.tolist() == np.c_[np.ones(len(expect), int), expect].tolist()
    assert res2.self_colliding.tolist() == [False, True]
    assert res.self_colliding.tolist() == [True, False]  # the copy kept its own


def test_pipeline_options_and_errors(device):
    v, t = crumpled_sheet(8, 0)
    scene = wc.Scene.from_meshes([(v, t), (v + 5.0, t)], device=device)
    plain = wc.CollisionPipeline(scene).detect()
    assert plain.self_pairs is None and plain.self_colliding is None
    with pytest.raises(ValueError, match="self_intersections"):
        wc.CollisionPipeline(scene, self_intersections="yes")
    with pytest.raises(ValueError, match="mid_phase"):
        wc.CollisionPipeline(scene, self_intersections=True, mid_phase="all_pairs")
    with pytest.raises(ValueError, match="continuous"):
        wc.CollisionPipeline(scene, self_intersections=True, continuous=True)
    with pytest.raises(ValueError, match="self_capacity"):
        wc.CollisionPipeline(scene, self_intersections=True, self_capacity=0)
    timed = wc.CollisionPipeline(scene, self_intersections=True, timings=True).detect()
    assert "self" in timed.timings and len(timed.self_pairs) == 2 * len(_reference(v, t))
    empty = wc.CollisionPipeline(wc.Scene.from_meshes([], device=device), self_intersections=True).detect()
    assert empty.self_pairs.shape == (0, 3)
    with pytest.raises(ValueError):
        wc.self_intersections(np.zeros((3, 3)), [[0, 1, 5]])
    with pytest.raises(ValueError):
        wc.self_intersections([[0, 0, np.nan], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]])


def test_one_object_with_clearance_and_timings(device):
    """One object: its self-intersections alone, the clearance's rows empty, every stage timed."""
    v, t = crumpled_sheet(8, 0)
    expect = _reference(v, t)
    for deforming in (False, True):
        scene = wc.Scene.from_meshes([(v, t)], deforming=deforming, device=device)
        res = wc.CollisionPipeline(scene, self_intersections=True, clearance=0.1, timings=True).detect()
        assert res.self_pairs[:, 1:].tolist() == expect.tolist() and res.self_colliding.tolist() == [True]
        assert len(res.object_pairs) == 0 and len(res.object_distance) == 0
        assert {"refit", "self", "clearance", "total"} <= set(res.timings)
        assert res.copy().self_pairs.tolist() == res.self_pairs.tolist()


@pytest.mark.parametrize("tol", [TOL, 0.05])
def test_unshared_pairs_as_between_objects(device, tol):
    """Two triangles sharing no vertex meet in one mesh exactly when they do as two objects (Möller's
    test, whose coplanar pairs touch up to sqrt(2) eps: the candidates' box filter must keep them), on
    random pairs and on coplanar pairs just beyond ``eps`` across the diagonal of their boxes."""
    rng = np.random.default_rng(5)
    a = np.array([[0, 0, 0], [1, 1, 0], [1, 0, 0]], np.float64)  # the longest edge: the box's diagonal
    cases = []
    for _ in range(60):
        b = rng.uniform(-1, 1, (3, 3))
        cases.append((a, b * rng.uniform(0.2, 2) + rng.choice([0.0, 1.0]) * rng.normal(size=3)))
        gap = rng.uniform(1.0, 1.45) * tol * 2**0.5  # beyond eps = tol * sqrt(2), within sqrt(2) eps
        side = np.array([-1.0, 1.0, 0.0]) / 2**0.5  # away from the diagonal, in the plane
        cases.append((a, a @ np.diag([-1, -1, 1]) + [1, 1, 0] + side * gap + [0, 0, rng.uniform(-0.5, 0.5) * tol]))
    for x, y in cases:
        mesh = (np.concatenate([x, y]), np.array([[0, 1, 2], [3, 4, 5]]))
        pair = wc.collide([(x, [[0, 1, 2]]), (y, [[0, 1, 2]])], device=device, precision="float64", tolerance=tol)
        got = wc.self_intersections(*mesh, device=device, precision="float64", tolerance=tol)
        assert (len(got) == 1) == (len(pair.object_pairs) == 1), (x, y)


def _grid_pairs(rng, shared: int, count: int, flat: bool, degenerate: bool = False):
    """``count`` pairs of triangles on the integer grid [-2, 2]^3 (the plane z = 0 when ``flat``) sharing
    ``shared`` vertices: ``(ta, tb, ids_a, ids_b)``; non-degenerate, or with ``degenerate`` at least one
    of three collinear points (a segment)."""
    out = []
    while len(out) < count:
        pts = rng.integers(-2, 3, (6 - shared, 3)).astype(float)
        if flat:
            pts[:, 2] = 0.0
        if len({tuple(p) for p in pts}) < len(pts):
            continue
        ids_a = [0, 1, 2]
        ids_b = list(range(shared)) + list(range(3, 6 - shared))
        rng.shuffle(ids_b)
        ta, tb = pts[ids_a], pts[ids_b]
        flat_tris = [np.linalg.norm(np.cross(t[1] - t[0], t[2] - t[0])) == 0 for t in (ta, tb)]
        if any(flat_tris) != degenerate:
            continue
        out.append((ta, tb, ids_a, ids_b))
    return out


@pytest.mark.parametrize("shared", [0, 1, 2])
@pytest.mark.parametrize("kind", ["space", "flat", "degenerate"])
def test_grid_pairs_against_exact_intersection(device, shared, kind):
    """Random pairs of triangles on a small integer grid (coplanar throughout when flat; with a segment,
    three collinear points, when degenerate), sharing 0, 1 or 2 vertices: a pair self-intersects exactly
    when the exact intersection of the two closed sets holds a point beyond what they share
    (:mod:`exact_intersection`, which knows none of the rules). On such coordinates every gap dwarfs
    the tolerance."""
    rng = np.random.default_rng(100 * shared + len(kind))
    flat = kind == "flat" or (kind == "degenerate" and shared == 2)
    pairs = _grid_pairs(rng, shared, 300, flat, degenerate=kind == "degenerate")
    vertices, triangles, expected = [], [], []
    for i, (ta, tb, ia, ib) in enumerate(pairs):
        n = 6 - shared
        local = np.zeros((n, 3))
        local[ia] = ta
        local[ib] = tb
        base = len(vertices) and sum(len(v) for v in vertices)
        vertices.append(local + [100.0 * i, 0.0, 0.0])
        triangles += [[base + k for k in ia], [base + k for k in ib]]
        shared_points = [ta[k] for k in range(3) if ia[k] in ib]
        if meets_beyond(ta, tb, shared_points):
            expected.append([2 * i, 2 * i + 1])
    got = wc.self_intersections(np.concatenate(vertices), np.array(triangles), device=device, precision="float64")
    assert got.tolist() == expected
    least = 3 if kind == "degenerate" else 10
    assert least < len(expected) < len(pairs) - least  # both verdicts represented


def test_weld_vertices():
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 0, 0], [-0.0, 0, 0], [1, 0, 0], [2, 0, 0]], np.float64)
    assert weld_vertices(v, [0, 3, 6]).tolist() == [0, 1, 0, 0, 1, 2]
    assert weld_vertices(np.zeros((0, 3)), [0]).tolist() == []


def test_reference_agrees_with_itself():
    """The float64 sweep of the reference and its exact pairwise decision agree on a crumpled sheet (50
    triangles, 28 crossing pairs among 1,225: the exact decision costs some 14 ms a pair)."""
    v, t = crumpled_sheet(6, 7)
    w = weld_vertices(v, [0, len(v)])
    exact = [[i, j] for i in range(len(t)) for j in range(i + 1, len(t))
             if pair_meets(v[t[i]], v[t[j]], w[t[i]], w[t[j]], TOL)]
    assert _reference(v, t).tolist() == exact
