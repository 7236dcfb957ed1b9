"""USD import and ``warp-ccd check``: the import against world meshes computed independently, the
check's verdicts against ``collide()`` and python-fcl, crossing depths (touching is not
penetrating), PointInstancer and polygon details, errors naming the file or prim, the command."""

import json
import os
import re

import numpy as np
import pytest
import warp as wp
from depth_reference import convex_depth
from hypothesis import HealthCheck, event, example, given, settings
from hypothesis import strategies as st

import warp_ccd as wc
from warp_ccd._src.check.check import check_usd
from warp_ccd._src.check.crossing import pair_crossing_depth
from warp_ccd._src.check.overlay import COLOR_PENETRATING
from warp_ccd._src.check.report import report_schema
from warp_ccd._src.cli import commands as cli
from warp_ccd._src.usd.importer import UsdMeshImport, scene_from_usd
from warp_ccd._src.usd.stage import stage_time_codes

pxr = pytest.importorskip("pxr")
from pxr import Gf, Sdf, Usd, UsdGeom, Vt  # noqa: E402
from usd_stages import define_mesh, fan, grid, mixed_stage, prism, world_polygon_meshes  # noqa: E402

from conftest import message_lines  # noqa: E402
from oracles import triangle_pairs_fcl  # noqa: E402

NUM_FRAMES = 24
IMPORT_TIMES = [0.0, 7.0, 16.0, 23.0]
CHECK_TIMES = np.arange(0.0, NUM_FRAMES, 3.0)  # 8 frames
CUBES = ["/World/Inst[0]/Cube/Geom", "/World/Inst[2]/Cube/Geom", "/World/Inst[4]/Cube/Geom"]
TETS = ["/World/Inst[1]/Tet", "/World/Inst[3]/Tet", "/World/Inst[5]/Tet"]
OBJECTS = {"/World/Floor", "/World/Resting", "/World/Movers/A/Geom", "/World/Movers/B/Geom", "/World/Stretched",
           "/World/Blob", "/World/RefA/Left", "/World/RefA/Right", "/World/RefB/Left", "/World/RefB/Right",
           *CUBES, *TETS}


# ---------------------------------------------------------------------------------------------
# helpers


@pytest.fixture(scope="module")
def mixed():
    """The mixed stage in memory (read only: tests that change a stage build their own)."""
    return mixed_stage(num_frames=NUM_FRAMES)


@pytest.fixture(scope="module")
def mixed_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("mixed") / "anim.usda"
    mixed_stage(path, num_frames=NUM_FRAMES)
    return path


def new_stage(path=None, end=None):
    stage = Usd.Stage.CreateNew(str(path)) if path is not None else Usd.Stage.CreateInMemory()
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    if end is not None:
        stage.SetStartTimeCode(0)
        stage.SetEndTimeCode(end)
    stage.SetDefaultPrim(UsdGeom.Xform.Define(stage, "/World").GetPrim())
    return stage


def box(lo=(0.0, 0.0, 0.0), hi=(1.0, 1.0, 1.0)):
    """An axis-aligned box: ``(points, counts, indices)``, six outward quads."""
    (x0, y0, z0), (x1, y1, z1) = lo, hi
    points = [[x0, y0, z0], [x1, y0, z0], [x1, y1, z0], [x0, y1, z0],
              [x0, y0, z1], [x1, y0, z1], [x1, y1, z1], [x0, y1, z1]]
    quads = [[0, 3, 2, 1], [4, 5, 6, 7], [0, 1, 5, 4], [2, 3, 7, 6], [0, 4, 7, 3], [1, 2, 6, 5]]
    return points, [4] * 6, [i for q in quads for i in q]


def path_pairs(names, pairs):
    """Object pairs as a set of sorted name pairs."""
    return {tuple(sorted((names[a], names[b]))) for a, b in np.asarray(pairs).reshape(-1, 2).tolist()}


def face_pairs(names, rows, face_of=None):
    """Rows ``(a, face_a or tri_a, b, face_b or tri_b)`` as a list of sorted ``((name, face), (name, face))``;
    ``face_of[name]`` maps triangles to faces when given."""
    out = []
    for a, fa, b, fb in np.asarray(rows).reshape(-1, 4).tolist():
        if face_of is not None:
            fa, fb = int(face_of[names[a]][fa]), int(face_of[names[b]][fb])
        out.append(tuple(sorted(((names[a], fa), (names[b], fb)))))
    return out


def deepest_by_pair(report, frame):
    """``{(name a, name b): deepest crossing}`` of one frame of a report."""
    out = {}
    for (a, _, b, _), d in zip(frame.triangle_pairs.tolist(), frame.depth.tolist()):
        key = tuple(sorted((report.object_path[a], report.object_path[b])))
        out[key] = max(out.get(key, 0.0), d)
    return out


# ---------------------------------------------------------------------------------------------
# 1. the import against independently computed world meshes


def test_import_matches_independent_world_meshes(mixed, device):
    times = stage_time_codes(mixed, IMPORT_TIMES)
    imp = UsdMeshImport(mixed, times=times, device=device)
    scene = imp.scene
    assert set(imp.object_path) == OBJECTS and len(imp.object_path) == len(OBJECTS) == scene.num_objects
    for k, t in enumerate(times):
        imp.set_frame(k)
        want = world_polygon_meshes(mixed, t)
        assert set(want) == set(imp.object_path)
        everything = np.concatenate([v for v, _, _ in want.values()])
        size = float(np.linalg.norm(everything.max(axis=0) - everything.min(axis=0)))
        got = scene.world_meshes()
        for i, path in enumerate(imp.object_path):
            v, tri, face = want[path]
            np.testing.assert_allclose(got[i][0], v, rtol=0, atol=1e-6 * size, err_msg=f"{path} at time {t:g}")
            np.testing.assert_array_equal(got[i][1], tri, err_msg=path)
            np.testing.assert_array_equal(imp.faces(np.full(len(tri), i), np.arange(len(tri))), face, err_msg=path)

    # Skipped: the guide and the invisible mesh, with their reasons.
    skipped = dict(imp.skipped)
    assert set(skipped) == {"/World/Guide", "/World/Hidden"}
    assert "guide" in skipped["/World/Guide"] and "invisible" in skipped["/World/Hidden"]
    # Only the blob's points are time-sampled; nothing else changes shape over time.
    assert {p for p, d in zip(imp.object_path, imp.object_deforming) if d} == {"/World/Blob"}
    assert scene.deforming

    # Shapes: instance proxies of one prototype share one, so do the instancer's instances of
    # one prototype; everything else (the non-uniformly scaled prism included) has its own.
    groups = {}
    for path, s in zip(imp.object_path, scene.object_shape_np.tolist()):
        groups.setdefault(s, set()).add(path)
    shared = [{"/World/RefA/Left", "/World/RefB/Left"}, {"/World/RefA/Right", "/World/RefB/Right"}, set(CUBES),
              set(TETS)]
    singles = OBJECTS - set().union(*shared)
    assert sorted(map(sorted, groups.values())) == sorted(map(sorted, shared + [{p} for p in singles]))
    assert scene.num_shapes == len(groups) == 10
    # The non-uniform scale is baked into that shape: the points times diag(2, 1, 0.5).
    stretched = imp.object_path.index("/World/Stretched")
    points = np.asarray(prism(5, radius=0.5, height=1.0)[0], np.float32).astype(np.float64)
    np.testing.assert_allclose(scene.shape_meshes[scene.object_shape_np[stretched]][0], points * [2.0, 1.0, 0.5],
                               rtol=0, atol=1e-6)

    # Point instances: named instancer[i]/..., with their prototype mesh, instancer and index.
    for i, path in enumerate(imp.object_path):
        m = re.fullmatch(r"/World/Inst\[(\d)\](/.*)", path)
        if m:
            assert imp.object_prim[i] == "/World/Inst/Protos" + m.group(2)
            assert imp.object_instancer[i] == "/World/Inst"
            assert imp.object_instance[i] == int(m.group(1))
        else:
            assert imp.object_prim[i] == path
            assert imp.object_instancer[i] is None and imp.object_instance[i] == -1


def _anim_nonuniform_scale(stage):
    mesh = define_mesh(stage, "/World/Squash", *prism(5, radius=0.5))
    op = UsdGeom.Xformable(mesh).AddScaleOp()
    for f in range(4):  # uniform at first, then squashed: deforming from the start
        op.Set(Gf.Vec3f(1.0, 1.0 + 0.2 * f, 1.0), f)
    return {"/World/Squash"}


def _anim_uniform_scale_from_zero(stage):
    mesh = define_mesh(stage, "/World/Grow", *prism(5, radius=0.5))
    op = UsdGeom.Xformable(mesh).AddScaleOp()
    for f in range(4):  # a zero scale at the first time code: the mesh collapses to a point
        op.Set(Gf.Vec3f(0.4 * f, 0.4 * f, 0.4 * f), f)
    return {"/World/Grow"}


def test_import_refuses_a_zero_scale_naming_prim_op_and_time(device):
    """A zero scale collapses the mesh (a point here): an error naming the prim, its op and the time."""
    stage = new_stage(end=3)
    define_mesh(stage, "/World/Floor", *grid(2, 4.0))
    _anim_uniform_scale_from_zero(stage)
    with pytest.raises(ValueError, match=re.escape("prim /World/Grow: xformOp:scale at time 0 is (0, 0, 0): a zero "
                                                   "scale collapses the mesh")):
        UsdMeshImport(stage, times=[0.0, 1.0, 3.0], device=device)


def _proxies_scaled_and_mirrored(stage):
    # Instance proxies under a non-uniform scale and a mirror: baked shapes, rigid all the same.
    for k, (name, scale) in enumerate((("RefA", Gf.Vec3f(1.0, 2.0, 1.0)), ("RefB", Gf.Vec3f(-1.0, 1.0, 1.0)))):
        ref = UsdGeom.Xform.Define(stage, f"/World/{name}")
        ref.GetPrim().GetReferences().AddInternalReference("/Proto")
        ref.GetPrim().SetInstanceable(True)
        ref.AddTranslateOp().Set(Gf.Vec3d(0.3 * k, 0.0, 0.0))
        ref.AddScaleOp().Set(scale)
    return set()


def _instancer_animated_scales(stage):
    inst = UsdGeom.PointInstancer.Define(stage, "/World/Inst")
    define_mesh(stage, "/World/Inst/Protos/Cube", *box())
    inst.CreatePrototypesRel().SetTargets(["/World/Inst/Protos/Cube"])
    inst.CreateProtoIndicesAttr(Vt.IntArray([0, 0, 0]))
    inst.CreatePositionsAttr(Vt.Vec3fArray([Gf.Vec3f(0.7 * i, 0.0, 0.0) for i in range(3)]))
    scales = inst.CreateScalesAttr()
    for f in range(4):  # instance 1 stretches in y over time, the others stay uniform
        scales.Set(Vt.Vec3fArray([Gf.Vec3f(1.0, 1.0 + 0.3 * f * (i == 1), 1.0) for i in range(3)]), f)
    return {"/World/Inst[1]/Cube"}


def _deforming_and_moving(stage):
    points, counts, indices = prism(6, radius=0.5)
    mesh = define_mesh(stage, "/World/Wobble", points, counts, indices)
    for f in range(4):
        p = points.copy()
        p[:, 1] *= 1.0 + 0.1 * f
        mesh.GetPointsAttr().Set(Vt.Vec3fArray.FromNumpy(p.astype(np.float32)), f)
    xf = UsdGeom.Xformable(mesh)
    translate, rotate = xf.AddTranslateOp(), xf.AddRotateYOp()
    for f in range(4):
        translate.Set(Gf.Vec3d(0.4 * f, 0.2, 0.0), f)
        rotate.Set(25.0 * f, f)
    return {"/World/Wobble"}


@pytest.mark.parametrize("build", [_anim_nonuniform_scale, _proxies_scaled_and_mirrored,
                                   _instancer_animated_scales, _deforming_and_moving], ids=lambda f: f.__name__[1:])
def test_import_of_awkward_transforms(device, build):
    """Transforms that do not stay a rotation times a uniform scale: the objects deform (world
    vertices from the host) or get baked shapes, and land where USD puts them."""
    stage = new_stage(end=3)
    define_mesh(stage, "/Proto/Left", *prism(4, radius=0.4, height=0.6))
    stage.GetPrimAtPath("/Proto").SetSpecifier(Sdf.SpecifierClass)
    define_mesh(stage, "/World/Floor", *grid(2, 4.0))
    deforming = build(stage)
    times = [0.0, 1.0, 3.0]
    imp = UsdMeshImport(stage, times=times, device=device)
    assert {p for p, d in zip(imp.object_path, imp.object_deforming) if d} == deforming
    for k, t in enumerate(times):
        imp.set_frame(k)
        want = world_polygon_meshes(stage, t)
        assert set(want) == set(imp.object_path)
        for i, (v, tri) in enumerate(imp.scene.world_meshes()):
            path = imp.object_path[i]
            np.testing.assert_allclose(v, want[path][0], rtol=0, atol=1e-5, err_msg=f"{path} at {t:g}")
            np.testing.assert_array_equal(tri, want[path][1])


# ---------------------------------------------------------------------------------------------
# 2. verdicts against collide() on the oracle's world meshes, and python-fcl


def test_check_matches_collide_and_fcl(mixed, device):
    report = check_usd(mixed, frames=CHECK_TIMES, count_touching=True, device=device)
    names = report.object_path
    assert [f.time for f in report.frames] == CHECK_TIMES.tolist()
    touching_only = set()
    for f in report.frames:
        want = world_polygon_meshes(mixed, f.time)
        paths = list(want)
        meshes = [(v, t) for v, t, _ in want.values()]
        face_of = {p: face for p, (_, _, face) in want.items()}
        res = wc.collide(meshes, device=device)
        assert res.num_triangle_pairs > 0
        got = face_pairs(names, f.triangle_pairs)
        assert len(got) == len(set(got)), "one row per (object, face) pair"
        assert set(got) == set(face_pairs(paths, res.triangle_pairs, face_of)), f"time {f.time:g}"
        objects = path_pairs(names, f.object_pairs)
        assert objects == path_pairs(paths, res.object_pairs), f"time {f.time:g}"

        # python-fcl reports touching contact too, but not all of it: at time 12 the stretched
        # prism's bottom face lies exactly in the floor's plane (coplanar faces), which the exact
        # test counts as touching and FCL (its BVH triangle test) does not. So what holds is:
        # every pair that penetrates (depth > 0) is one FCL finds, every pair FCL finds is one the
        # check reports with count_touching, and the check's extra pairs only touch (depth 0).
        fcl = path_pairs(paths, triangle_pairs_fcl(meshes)[:, [0, 2]])
        deepest = deepest_by_pair(report, f)
        penetrating = {pair for pair, d in deepest.items() if d > 0}
        assert penetrating <= fcl <= objects, f"time {f.time:g}"
        for pair in objects - fcl:
            assert deepest[pair] == 0.0, (f.time, pair)
            touching_only.add(pair)
    assert touching_only <= {("/World/Floor", "/World/Resting"), ("/World/Floor", "/World/Stretched")}


# ---------------------------------------------------------------------------------------------
# 3. touching is not penetrating


def test_resting_pair_touches_but_never_penetrates(mixed, device):
    touching = check_usd(mixed, frames=CHECK_TIMES, count_touching=True, device=device)
    strict = check_usd(mixed, frames=CHECK_TIMES, device=device)
    resting = ("/World/Floor", "/World/Resting")
    assert strict.penetrating and not strict.count_touching and touching.count_touching
    for t, s in zip(touching.frames, strict.frames):
        assert resting in path_pairs(touching.object_path, t.object_pairs)
        assert resting not in path_pairs(strict.object_path, s.object_pairs)
        assert deepest_by_pair(touching, t)[resting] == 0.0
        # Without count_touching, the rows are those that cross deeper than min_depth = 0.
        deep = t.depth > 0
        np.testing.assert_array_equal(s.triangle_pairs, t.triangle_pairs[deep])
        np.testing.assert_array_equal(s.depth, t.depth[deep])
        assert s.num_touching == int((~deep).sum()) > 0
        assert t.num_touching == 0
    # At time 12 the stretched prism's bottom face lies in the floor's plane: touching, depth 0.
    twelve = touching.frames[list(CHECK_TIMES).index(12.0)]
    assert deepest_by_pair(touching, twelve)[("/World/Floor", "/World/Stretched")] == 0.0
    assert ("/World/Floor", "/World/Resting") not in {(p["a"], p["b"]) for p in strict.pair_summary()}


@pytest.mark.parametrize("h", [0.01, 0.1])
def test_sunk_cube_depth_and_min_depth(device, h):
    stage = new_stage()
    define_mesh(stage, "/World/Floor", *grid(6, 12.0))  # cells of 2: the cube lies inside cell [0, 2]^2
    cube = define_mesh(stage, "/World/Cube", *box())
    UsdGeom.Xformable(cube).AddTranslateOp().Set(Gf.Vec3d(0.5, -h, 0.5))
    report = check_usd(stage, device=device)
    assert [f.time for f in report.frames] == [0.0]
    (pair,) = report.pair_summary()
    assert (pair["a"], pair["b"]) == ("/World/Floor", "/World/Cube")
    assert pair["max_depth"] == pytest.approx(h, rel=1e-4)
    assert report.frames[0].depth.max() == pytest.approx(h, rel=1e-4)

    above = check_usd(stage, min_depth=h * 1.02, device=device)
    assert not above.penetrating and above.pair_summary() == []
    assert above.frames[0].num_touching == len(report.frames[0].triangle_pairs) + report.frames[0].num_touching
    below = check_usd(stage, min_depth=h * 0.98, device=device)
    assert below.penetrating
    assert below.pair_summary()[0]["max_depth"] == pytest.approx(h, rel=1e-4)


def test_rotated_cube_resting_far_from_origin_does_not_penetrate(device):
    stage = new_stage()
    far = UsdGeom.Xform.Define(stage, "/World/Far")
    far.AddTranslateOp().Set(Gf.Vec3d(1.0e3, 1.0e3 + 0.3, -1.0e3))
    define_mesh(stage, "/World/Far/Floor", *grid(4, 8.0))
    cube = define_mesh(stage, "/World/Far/Cube", *box((-0.5, 0.0, -0.5), (0.5, 1.0, 0.5)))
    xf = UsdGeom.Xformable(cube)
    xf.AddTranslateOp().Set(Gf.Vec3d(0.9, 0.0, 1.1))
    xf.AddRotateYOp().Set(30.0)
    report = check_usd(stage, device=device)
    assert not report.penetrating and report.pair_summary() == []
    touching = check_usd(stage, count_touching=True, device=device)
    # Not vacuous: the cube's bottom does touch the floor.
    assert path_pairs(touching.object_path, touching.frames[0].object_pairs) == {("/World/Far/Cube",
                                                                                  "/World/Far/Floor")}
    assert (touching.frames[0].depth == 0).all()
    assert report.frames[0].num_touching == len(touching.frames[0].triangle_pairs) > 0


@pytest.mark.parametrize("h", [0.01, 0.1])
def test_tetrahedron_vertex_poking_through(device, h):
    stage = new_stage()
    define_mesh(stage, "/World/Floor", *grid(2, 4.0))
    apex = [1.4, -h, 0.6]
    tet = [apex, [0.8, 0.9, 0.2], [2.0, 0.9, 0.4], [1.3, 0.9, 1.4]]
    define_mesh(stage, "/World/Tet", tet, [3, 3, 3, 3], [0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3])
    report = check_usd(stage, device=device)
    (pair,) = report.pair_summary()
    assert (pair["a"], pair["b"]) == ("/World/Floor", "/World/Tet")
    # The floor is open: the depth is the floor's part inside the tetrahedron, measured to its faces (the
    # exact linear program), less than h; nothing crosses deeper than the vertex pokes.
    points, _, quads = grid(2, 4.0)
    quads = np.reshape(quads, (-1, 4))
    floor = (points, np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]]))
    solid = (np.array(tet, np.float64), np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]]))
    assert pair["max_depth"] == pytest.approx(convex_depth(floor, solid), rel=1e-4) and 0 < pair["max_depth"] < h
    assert (report.frames[0].depth <= h * (1 + 1e-4)).all()


def test_invisible_and_guides_on_request(mixed, device):
    report = check_usd(mixed, frames=[0.0], include_invisible=True, include_purposes=("guide",), device=device)
    assert {"/World/Guide", "/World/Hidden"} <= set(report.object_path) and report.skipped == []
    pairs = path_pairs(report.object_path, report.frames[0].object_pairs)
    assert {("/World/Floor", "/World/Guide"), ("/World/Floor", "/World/Hidden")} <= pairs  # both cross the floor
    with pytest.raises(ValueError, match=re.escape("/World/Guide")):
        check_usd(mixed, frames=[0.0], prims=["/World/Guide"], device=device)


# ---------------------------------------------------------------------------------------------
# 4. crossing_depth on crafted triangle pairs


H = 0.05
BASE = [[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [0.0, 1.0, 0.0]]  # in the plane z = 0
DEPTH_CASES = {
    # vertical triangle through BASE: reaches 0.3 below z = 0 and 0.7 above; BASE spans y in [-1, 1]
    "crossing_x": ([[-0.5, 0.0, -0.3], [0.5, 0.0, -0.3], [0.0, 0.0, 0.7]], 0.3),
    "coplanar_overlap": ([[-0.5, -0.5, 0.0], [0.5, -0.5, 0.0], [0.0, 0.5, 0.0]], 0.0),
    "edge_on_face": ([[-0.3, 0.0, 0.0], [0.3, 0.0, 0.0], [0.0, 0.2, 1.0]], 0.0),
    "vertex_on_face": ([[0.1, 0.05, 0.0], [-0.5, 0.3, 1.0], [0.4, -0.4, 1.0]], 0.0),
    "vertex_within_tolerance": ([[0.1, 0.05, -1e-7], [-0.5, 0.3, 1.0], [0.4, -0.4, 1.0]], 0.0),
    "vertex_poke": ([[0.1, 0.05, -H], [-0.5, 0.3, 1.0], [0.4, -0.4, 1.0]], H),
    # a sliver (twice its area 7e-7 of its longest edge squared: degenerate, no plane of its own)
    # from z = -0.2 to 0.5: its lesser excursion from BASE's plane
    "sliver": ([[0.1, 0.1, -0.2], [0.1, 0.1, 0.5], [0.1 + 1e-6, 0.1, 0.15]], 0.2),
}


def lesser_side(tri, other):
    """numpy: how far ``tri`` reaches to the lesser side of ``other``'s plane."""
    other = np.asarray(other, np.float64)
    n = np.cross(other[1] - other[0], other[2] - other[0])
    d = (np.asarray(tri, np.float64) - other[0]) @ (n / np.linalg.norm(n))
    return min(d.max(), -d.min())


@pytest.mark.parametrize("precision", ["float32", "float64"])
def test_crossing_depth_of_crafted_pairs(device, precision):
    names = list(DEPTH_CASES)
    meshes = [(np.array(BASE), np.array([[0, 1, 2]]))]
    meshes += [(np.array(DEPTH_CASES[n][0]), np.array([[0, 1, 2]])) for n in names]
    # The poking vertex's depth is the smaller of the two sides: BASE reaches further across the
    # other's plane than H (so the answer is H, not BASE's excursion).
    assert lesser_side(BASE, DEPTH_CASES["vertex_poke"][0]) > 4 * H
    assert lesser_side(BASE, DEPTH_CASES["crossing_x"][0]) == pytest.approx(1.0)
    scene = wc.Scene.from_meshes(meshes, device=device, precision=precision)
    rows = [(0, 0, i + 1, 0) for i in range(len(names))] + [(i + 1, 0, 0, 0) for i in range(len(names))]
    pairs = wp.array(np.array(rows, np.int32), dtype=wp.vec4i, device=device)
    depth = pair_crossing_depth(scene, pairs).numpy()
    assert depth.dtype == np.float64 and depth.shape == (2 * len(names),)
    tol = 1e-6 if precision == "float32" else 1e-12
    for i, name in enumerate(names):
        want = DEPTH_CASES[name][1]
        assert depth[i] == pytest.approx(want, abs=tol), name
        assert depth[len(names) + i] == pytest.approx(want, abs=tol), f"{name} (swapped)"
    assert pair_crossing_depth(scene, wp.zeros(0, dtype=wp.vec4i, device=device)).shape == (0,)


# ---------------------------------------------------------------------------------------------
# 5. PointInstancer: the mask and the prototype root's transform


def test_point_instancer_mask_and_prototype_transform(device, mixed):
    stage = mixed_stage(num_frames=NUM_FRAMES)
    inst = UsdGeom.PointInstancer(stage.GetPrimAtPath("/World/Inst"))
    inst.DeactivateId(2)
    inst.InvisId(3, Usd.TimeCode(0))
    times = [0.0, 11.0]
    imp = UsdMeshImport(stage, prims=["/World/Inst"], times=times, device=device)
    kept = {"/World/Inst[0]/Cube/Geom", "/World/Inst[4]/Cube/Geom", "/World/Inst[1]/Tet", "/World/Inst[5]/Tet"}
    assert set(imp.object_path) == kept and len(imp.object_path) == 4
    assert sorted(imp.object_instance.tolist()) == [0, 1, 4, 5]
    for k, t in enumerate(times):
        imp.set_frame(k)
        want = world_polygon_meshes(mixed, t)  # the same stage without the mask: all six instances
        got = imp.scene.world_meshes()
        for i, path in enumerate(imp.object_path):
            np.testing.assert_allclose(got[i][0], want[path][0], rtol=0, atol=1e-5, err_msg=path)
            extent = np.ptp(got[i][0], axis=0)
            if "Cube" in path:  # prism(4, radius 1, height 1) under the prototype root's scale 0.5
                np.testing.assert_allclose(extent, [1.0, 0.5, 1.0], rtol=1e-6)
            else:
                np.testing.assert_allclose(extent, [0.8, 0.8, 0.8], rtol=1e-6)
    report = check_usd(stage, frames=times, count_touching=True, device=device)
    assert not {"/World/Inst[2]/Cube/Geom", "/World/Inst[3]/Tet"} & set(report.object_path)


# ---------------------------------------------------------------------------------------------
# 6. polygons of 3 to 8 sides, holes


def test_polygons_fan_and_holes(device, mixed):
    stage = new_stage()
    points, counts, indices = [], [], []
    for n in range(3, 9):  # one regular n-gon per n, side by side, vertices listed in a shuffled order
        a = 2 * np.pi * np.arange(n) / n
        ring = np.stack([np.cos(a) + 3.0 * n, np.zeros(n), np.sin(a)], axis=1)
        base = len(points)
        points += ring.tolist()
        counts.append(n)
        indices += (base + np.roll(np.arange(n)[::-1], n // 2)).tolist()
    perm = np.random.default_rng(1).permutation(len(points))  # points stored in another order
    inverse = np.argsort(perm)
    points = np.asarray(points)[perm]
    indices = inverse[np.asarray(indices)].tolist()
    define_mesh(stage, "/World/Polys", points, counts, indices)
    define_mesh(stage, "/World/Holed", points, counts, indices, holes=[0, 3, 5])
    imp = UsdMeshImport(stage, device=device)
    assert imp.object_path == ["/World/Polys", "/World/Holed"] and imp.skipped == []
    for i, holes in enumerate([(), (0, 3, 5)]):
        tri, face = fan(counts, indices, holes)
        keep = [f for f in range(len(counts)) if f not in holes]
        assert len(tri) == sum(counts[f] - 2 for f in keep)
        np.testing.assert_array_equal(face, np.repeat(keep, [counts[f] - 2 for f in keep]))
        v, t = imp.scene.world_meshes()[i]
        np.testing.assert_array_equal(t, tri)
        np.testing.assert_array_equal(imp.faces(np.full(len(t), i), np.arange(len(t))), face)
        np.testing.assert_allclose(v, points, rtol=0, atol=1e-5)
        # Every triangle lies within its polygon: its vertices are the polygon's.
        starts = np.concatenate([[0], np.cumsum(counts)])
        for (a, b, c), f in zip(t.tolist(), face.tolist()):
            assert {a, b, c} <= set(indices[starts[f]:starts[f + 1]])

    # The mixed stage: an octagonal prism (2 x 6 + 8 x 2 triangles), a hexagonal one with face 2 a hole.
    movers = UsdMeshImport(mixed, prims=["/World/Movers"], device=device)
    assert movers.object_path == ["/World/Movers/A/Geom", "/World/Movers/B/Geom"]
    ntri = [len(t) for _, t in movers.scene.world_meshes()]
    assert ntri == [2 * 6 + 8 * 2, 2 * 4 + 6 * 2 - 2]
    faces_b = movers.faces(np.ones(ntri[1], np.int64), np.arange(ntri[1]))
    assert 2 not in faces_b and sorted(set(faces_b.tolist())) == [0, 1, 3, 4, 5, 6, 7]


@pytest.mark.parametrize("kind", ["no_faces", "every_face_a_hole"])
def test_meshes_without_faces_are_skipped(device, kind):
    stage = new_stage()
    define_mesh(stage, "/World/Floor", *grid(2, 4.0))
    if kind == "no_faces":
        UsdGeom.Mesh.Define(stage, "/World/Empty")  # a mesh prim with no points and no faces
    else:
        define_mesh(stage, "/World/Empty", *box(), holes=list(range(6)))
    imp = UsdMeshImport(stage, device=device)
    assert imp.object_path == ["/World/Floor"]
    assert [p for p, _ in imp.skipped] == ["/World/Empty"] and "no faces" in imp.skipped[0][1]


# ---------------------------------------------------------------------------------------------
# 7. errors: ValueError naming the file or the prim


def bad_mesh_stage(kind):
    """A floor and ``/World/Bad``, broken as ``kind`` says; time codes 0..2."""
    stage = new_stage(end=2)
    define_mesh(stage, "/World/Floor", *grid(2, 4.0))
    points, counts, indices = box()
    if kind == "index_out_of_range":
        indices = indices[:-1] + [8]
    elif kind == "two_vertex_face":
        counts, indices = counts[:5] + [2, 2], indices[:20] + [1, 2, 6, 5]
    elif kind == "nan_point":
        points = [list(p) for p in points]
        points[5][1] = float("nan")
    mesh = define_mesh(stage, "/World/Bad", points, counts, indices)
    if kind == "point_count_changes":
        attr = mesh.GetPointsAttr()
        attr.Set(Vt.Vec3fArray.FromNumpy(np.asarray(points, np.float32)), 0)
        attr.Set(Vt.Vec3fArray.FromNumpy(np.asarray(points + [[2.0, 2.0, 2.0]], np.float32)), 1)
    elif kind == "nan_later":
        attr = mesh.GetPointsAttr()
        attr.Set(Vt.Vec3fArray.FromNumpy(np.asarray(points, np.float32)), 0)
        later = np.asarray(points, np.float32)
        later[3, 0] = np.nan
        attr.Set(Vt.Vec3fArray.FromNumpy(later), 1)
    elif kind == "animated_topology":
        attr = mesh.GetFaceVertexIndicesAttr()
        attr.Set(Vt.IntArray(indices), 0)
        attr.Set(Vt.IntArray(indices[::-1]), 1)
    return stage


@pytest.mark.parametrize("kind, words", [
    ("index_out_of_range", "faceVertexIndices"),
    ("two_vertex_face", "2 vertices"),
    ("nan_point", "not finite"),
    ("animated_topology", "animated topology"),
])
def test_bad_mesh_names_the_prim(device, kind, words):
    stage = bad_mesh_stage(kind)
    with pytest.raises(ValueError, match=re.escape("/World/Bad")) as info:
        UsdMeshImport(stage, device=device)
    assert words in str(info.value)
    with pytest.raises(ValueError, match=re.escape("/World/Bad")):
        check_usd(stage, device=device)


@pytest.mark.parametrize("kind, words", [("point_count_changes", "points"), ("nan_later", "finite")])
def test_deforming_mesh_going_bad_later_names_the_prim(device, kind, words):
    stage = bad_mesh_stage(kind)
    imp = UsdMeshImport(stage, times=[0.0, 1.0], device=device)  # the first time code is fine
    assert "/World/Bad" in imp.object_path
    with pytest.raises(ValueError, match=re.escape("/World/Bad")) as info:
        imp.set_frame(1)
    assert words in str(info.value)
    with pytest.raises(ValueError, match=re.escape("/World/Bad")):
        check_usd(stage, frames=slice(0, 2), device=device)
    assert not check_usd(stage, frames=[0.0], device=device).penetrating  # box on the floor: touching


def test_missing_and_unreadable_files(tmp_path):
    missing = tmp_path / "missing.usda"
    for call in (lambda p: UsdMeshImport(p), lambda p: check_usd(p), lambda p: scene_from_usd(p)):
        with pytest.raises(ValueError, match="missing.usda"):
            call(missing)
    garbage = tmp_path / "x.usd"
    garbage.write_text("this is not a USD file\n" * 10)
    with pytest.raises(ValueError, match=re.escape(str(garbage))):
        UsdMeshImport(garbage)
    with pytest.raises(ValueError, match="x.usd"):
        check_usd(str(garbage))


def test_stage_without_meshes():
    stage = new_stage()
    UsdGeom.Xform.Define(stage, "/World/Empty")
    with pytest.raises(ValueError, match="no meshes"):
        UsdMeshImport(stage)
    with pytest.raises(ValueError, match="no meshes"):
        UsdMeshImport(stage, prims=["/World/Empty"])


def test_stage_file_without_meshes_names_the_file(tmp_path):
    stage = new_stage(tmp_path / "empty.usda")
    UsdGeom.Xform.Define(stage, "/World/Empty")
    stage.GetRootLayer().Save()
    with pytest.raises(ValueError, match="empty.usda: no meshes"):
        UsdMeshImport(tmp_path / "empty.usda")
    with pytest.raises(ValueError, match="no meshes with faces under /World/Empty"):
        UsdMeshImport(tmp_path / "empty.usda", prims=["/World/Empty"])


def test_prims_that_do_not_exist_or_match_nothing(mixed):
    with pytest.raises(ValueError, match=re.escape("/World/Nope")):
        UsdMeshImport(mixed, prims=["/World/Floor", "/World/Nope"])
    with pytest.raises(ValueError, match=re.escape("/World/Zz*")):
        UsdMeshImport(mixed, prims=["/World/Zz*"])
    imp = UsdMeshImport(mixed, prims=["/World/Movers/*"])  # a pattern that matches: the prims under it
    assert imp.object_path == ["/World/Movers/A/Geom", "/World/Movers/B/Geom"]


def test_frames_outside_the_stage_range(mixed):
    with pytest.raises(ValueError, match="outside"):
        stage_time_codes(mixed, slice(0, 100))
    with pytest.raises(ValueError, match="outside"):
        check_usd(mixed, frames=[-1.0, 3.0])
    np.testing.assert_array_equal(stage_time_codes(mixed, slice(0, 23, 6)), [0, 6, 12, 18])
    np.testing.assert_array_equal(stage_time_codes(mixed), np.arange(NUM_FRAMES))


def run_cli(capsys, args):
    rc = cli.main(args)
    captured = capsys.readouterr()
    assert "Traceback" not in captured.err
    return rc, captured


@pytest.mark.parametrize("case", ["garbage", "missing", "no_meshes", "frames", "bad_mesh", "pattern"])
def test_cli_bad_input_exits_2_and_writes_nothing(tmp_path, capsys, mixed_file, case):
    stage = tmp_path / "in.usda"
    frames = []
    if case == "garbage":
        stage = tmp_path / "x.usd"
        stage.write_text("not usd at all\n")
    elif case == "no_meshes":
        empty = new_stage(stage)
        empty.GetRootLayer().Save()
    elif case == "frames":
        stage, frames = mixed_file, ["--frames", "10:40"]
    elif case == "bad_mesh":
        bad = bad_mesh_stage("two_vertex_face")  # kept: its anonymous root layer lives as long as the stage
        bad.GetRootLayer().Export(str(stage))
    elif case == "pattern":
        stage, frames = mixed_file, ["--prims", "/World/Nothing*"]
    before = sorted(os.listdir(tmp_path))
    out = tmp_path / "out"
    out.mkdir()
    rc, captured = run_cli(capsys, ["check", str(stage), *frames, "--report", str(out / "r.json"),
                                    "--usd-out", str(out / "o.usda"), "--preview", str(out / "p.png")])
    assert rc == 2
    lines = message_lines(captured.err)
    assert len(lines) == 1, captured.err
    assert lines[0].startswith("warp-ccd check: error:")
    expected = {"garbage": "x.usd", "missing": "in.usda", "no_meshes": "no meshes", "frames": "outside",
                "bad_mesh": "/World/Bad", "pattern": "/World/Nothing*"}[case]
    assert expected in lines[0]
    assert os.listdir(out) == [] and sorted(os.listdir(tmp_path)) == sorted(before + ["out"])


def test_cli_checks_destinations_before_reading(tmp_path, capsys, mixed_file):
    garbage = tmp_path / "x.usd"
    garbage.write_text("not usd at all\n")
    # The report's folder is missing: that is the error, even for an input that cannot be read.
    for stage in (mixed_file, garbage):
        rc, captured = run_cli(capsys, ["check", str(stage), "--report", str(tmp_path / "nope" / "r.json"),
                                        "--usd-out", str(tmp_path / "o.usda")])
        assert rc == 2
        (line,) = message_lines(captured.err)
        assert "nope" in line and "does not exist" in line
    # A GIF preview: the check draws one picture.
    rc, captured = run_cli(capsys, ["check", str(garbage), "--report", str(tmp_path / "r.json"),
                                    "--preview", str(tmp_path / "p.gif")])
    assert rc == 2
    (line,) = message_lines(captured.err)
    assert "p.gif" in line and ".png" in line
    rc, captured = run_cli(capsys, ["check", str(mixed_file), "--min-depth", "-1"])
    assert rc == 2 and len(message_lines(captured.err)) == 1
    assert sorted(os.listdir(tmp_path)) == ["x.usd"]


# ---------------------------------------------------------------------------------------------
# 8. the command, end to end


def test_cli_check_end_to_end(tmp_path, capsys, device):
    stage_path = tmp_path / "anim.usda"
    mixed_stage(stage_path, num_frames=NUM_FRAMES)
    report_path, overlay_path, png = tmp_path / "r.json", tmp_path / "over.usda", tmp_path / "p.png"
    rc, captured = run_cli(capsys, ["check", str(stage_path), "--frames", "0:23:6", "--device", device,
                                    "--report", str(report_path), "--usd-out", str(overlay_path), "--segments",
                                    "--preview", str(png)])
    assert rc == 1, captured.err
    assert sorted(os.listdir(tmp_path)) == ["anim.usda", "over.usda", "p.png", "r.json"]
    assert "/World/Stretched" in captured.out and str(report_path) in captured.out
    times = [0.0, 6.0, 12.0, 18.0]

    data = json.loads(report_path.read_text())
    assert data["penetrating"] is True and data["times"] == times and data["device"] == device
    assert data["objects"] == len(OBJECTS)
    assert {s["prim"] for s in data["skipped"]} == {"/World/Guide", "/World/Hidden"}
    assert data["pairs"] and all(p["a"] in OBJECTS and p["b"] in OBJECTS for p in data["pairs"])
    ref = check_usd(stage_path, frames=times, segments=True, device=device)
    assert data["pairs"] == json.loads(json.dumps(ref.pair_summary()))
    for frame, f in zip(data["frames"], ref.frames):
        assert frame["time"] == f.time and frame["triangle_pairs"] == len(f.triangle_pairs)
        assert frame["touching_pairs"] == f.num_touching
        rows = []
        for p in frame["pairs"]:
            assert p["a"] in OBJECTS and p["b"] in OBJECTS and p["max_depth"] > 0
            assert all(type(x) is int for pair in p["faces"] for x in pair) and all(len(x) == 2 for x in p["faces"])
            assert np.asarray(p["segments"], np.float64).shape == (len(p["faces"]), 2, 3)
            a, b = ref.object_path.index(p["a"]), ref.object_path.index(p["b"])
            rows += [(a, fa, b, fb) for fa, fb in p["faces"]]
        np.testing.assert_array_equal(np.array(rows, np.int32).reshape(-1, 4), f.triangle_pairs)

    overlay = Usd.Stage.Open(str(overlay_path))
    assert list(overlay.GetRootLayer().subLayerPaths) == ["anim.usda"]
    assert overlay.GetPrimAtPath("/World/Floor").IsA(UsdGeom.Mesh)  # the sublayer resolves
    red = np.asarray(COLOR_PENETRATING, np.float32)
    hit = {}  # prim to colour -> frames it penetrates in
    for k, f in enumerate(ref.frames):
        for i in np.unique(f.triangle_pairs[:, [0, 2]]).tolist():
            path = ref.object_path[i]
            key = "/World/Inst" if path.startswith("/World/Inst[") else re.sub(r"^(/World/Ref[AB])/.*", r"\1", path)
            hit.setdefault(key, set()).add(k)
    assert {"/World/RefA", "/World/RefB", "/World/Inst", "/World/Stretched"} <= set(hit)
    for path, frames in hit.items():
        primvar = UsdGeom.PrimvarsAPI(overlay.GetPrimAtPath(path)).GetPrimvar("displayColor")
        assert primvar.GetAttr().GetTimeSamples() == times, path
        for k, t in enumerate(times):
            colors = np.asarray(primvar.Get(t), np.float32)
            if path == "/World/Inst":
                assert primvar.GetInterpolation() == UsdGeom.Tokens.vertex and len(colors) == 6
                want = {ref.source.object_instance[i] for i in np.unique(ref.frames[k].triangle_pairs[:, [0, 2]])
                        if ref.object_path[i].startswith("/World/Inst[")}
                assert {j for j in range(6) if np.allclose(colors[j], red)} == want
            else:
                assert np.allclose(colors[0], red) == (k in frames), (path, t)
    layer = overlay.GetRootLayer()
    assert layer.GetPrimAtPath("/World/Resting") is None  # only touches: not in the overlay
    curves = UsdGeom.BasisCurves(overlay.GetPrimAtPath("/WarpCcdCheck/Segments"))
    assert curves and curves.GetPointsAttr().GetTimeSamples() == times
    for t, f in zip(times, ref.frames):
        finite = np.isfinite(f.segments).all(axis=(1, 2))
        assert len(curves.GetCurveVertexCountsAttr().Get(t)) == int(finite.sum()) > 0
        np.testing.assert_allclose(np.asarray(curves.GetPointsAttr().Get(t)).reshape(-1, 2, 3), f.segments[finite],
                                   rtol=0, atol=1e-5)

    from PIL import Image

    with Image.open(png) as im:
        assert im.format == "PNG" and im.size == (640, 480)


def test_cli_exits_0_when_nothing_penetrates(tmp_path, capsys):
    path = tmp_path / "resting.usda"
    stage = new_stage(path, end=3)
    define_mesh(stage, "/World/Floor", *grid(6, 12.0))
    cube = define_mesh(stage, "/World/Resting", *prism(4, radius=0.7, height=1.0))
    tr = UsdGeom.Xformable(cube).AddTranslateOp()
    for f in range(4):
        tr.Set(Gf.Vec3d(-4.0 + 0.5 * f, 0.0, -4.0), f)
    stage.GetRootLayer().Save()
    report = tmp_path / "r.json"
    rc, captured = run_cli(capsys, ["check", str(path), "--report", str(report)])
    assert rc == 0, captured.err
    data = json.loads(report.read_text())
    assert data["penetrating"] is False and data["pairs"] == [] and len(data["frames"]) == 4
    assert all(f["touching_pairs"] > 0 and f["pairs"] == [] for f in data["frames"])
    rc, captured = run_cli(capsys, ["check", str(path), "--count-touching"])
    assert rc == 1, captured.err
    assert "/World/Resting" in captured.out


def test_cli_options_select_what_is_checked(tmp_path, capsys, mixed_file):
    report = tmp_path / "r.json"
    # Several prims: separated by commas, or --prims again; the file name after them stays the input.
    args = ["check", "--prims", "/World/Floor,/World/Guide", "--prims", "/World/Hidden", str(mixed_file),
            "--frames", "0"]
    rc, captured = run_cli(capsys, args + ["--include-purpose", "guide", "--include-invisible",
                                           "--report", str(report)])
    assert rc == 1, captured.err
    data = json.loads(report.read_text())
    assert data["times"] == [0.0] and data["objects"] == 3
    assert {(p["a"], p["b"]) for p in data["pairs"]} == {("/World/Floor", "/World/Guide"),
                                                          ("/World/Floor", "/World/Hidden")}
    rc, captured = run_cli(capsys, args)  # the guide is not checked unless asked for
    assert rc == 2 and "/World/Guide" in message_lines(captured.err)[0]
    # Deeper than anything in the stage: nothing penetrates.
    rc, captured = run_cli(capsys, ["check", str(mixed_file), "--frames", "0:12:6", "--min-depth", "10"])
    assert rc == 0, captured.err


# ---------------------------------------------------------------------------------------------
# 9. scene_from_usd


def test_scene_from_usd_matches_import(mixed_file, device):
    scene = scene_from_usd(mixed_file, time=5, device=device)
    imp = UsdMeshImport(mixed_file, times=[0.0, 5.0, 9.0], device=device)
    imp.set_frame(1)
    assert scene.usd.object_path == imp.object_path
    np.testing.assert_array_equal(scene.world_vertex.numpy(), imp.scene.world_vertex.numpy())

    stage = Usd.Stage.Open(str(mixed_file))
    want = world_polygon_meshes(stage, 5.0)
    every = np.concatenate([v for v, _, _ in want.values()])
    size = float(np.linalg.norm(every.max(axis=0) - every.min(axis=0)))
    double = scene_from_usd(str(mixed_file), time=5, device=device, precision="float64")
    assert double.precision == "float64" and double.world_vertex.dtype == wp.vec3d
    assert double.usd.object_path == imp.object_path
    for i, (v, t) in enumerate(double.world_meshes()):
        path = double.usd.object_path[i]
        assert v.dtype == np.float64
        # float32 points (as stored), transformed in float64: far closer than float32 placement
        np.testing.assert_allclose(v, want[path][0], rtol=0, atol=1e-12 * size, err_msg=path)
        np.testing.assert_array_equal(t, want[path][1])
    np.testing.assert_allclose(double.world_vertex.numpy(), scene.world_vertex.numpy(), rtol=0, atol=1e-6 * size)
    with pytest.raises(ValueError, match="time"):
        scene_from_usd(mixed_file, time=5, times=[0, 5])
    report = check_usd(mixed_file, frames=[5.0], precision="float64", count_touching=True, device=device)
    single = check_usd(mixed_file, frames=[5.0], count_touching=True, device=device)
    assert path_pairs(report.object_path, report.frames[0].object_pairs) == \
        path_pairs(single.object_path, single.frames[0].object_pairs)


# ---------------------------------------------------------------------------------------------
# 10. property: random nested similarity transforms of two prisms


PRISMS = [prism(5, radius=0.5, height=1.0), prism(6, radius=0.4, height=0.8)]


def quat_matrix(q):
    """Column-vector rotation matrix of quaternion ``(w, x, y, z)`` (normalised here)."""
    w, x, y, z = np.asarray(q, np.float64) / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def similarity(level):
    """4x4 column-vector matrix of translate * orient * uniform scale (USD's op order)."""
    t, q, s = level
    m = np.eye(4)
    m[:3, :3] = quat_matrix(q) * s
    m[:3, 3] = t
    return m


coord = st.floats(-1.0, 1.0, allow_nan=False, allow_infinity=False)
quat = st.tuples(coord, coord, coord, coord).filter(lambda q: np.linalg.norm(q) > 0.2)
level = st.tuples(st.tuples(coord, coord, coord), quat, st.floats(0.5, 2.0))
placement = st.tuples(level, level)  # parent, then child


@settings(max_examples=10, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(first=placement, second=placement)
@example(first=(((0, 0, 0), (1, 0, 0, 0), 1.0), ((0, 0, 0), (1, 0, 0, 0), 1.0)),
         second=(((0.3, 0.2, 0), (1, 0, 0, 0), 1.0), ((0, 0, 0), (0.9, 0.3, 0.2, 0.1), 1.0)))  # overlapping
@example(first=(((-1, 0, 0), (1, 0, 0, 0), 1.0), ((0, 0, 0), (1, 0, 0, 0), 0.5)),
         second=(((1, 0, 0), (1, 0, 0, 0), 1.0), ((0, 0, 0), (1, 0, 0, 0), 0.5)))  # apart
def test_random_nested_transforms_match_collide(device, first, second):
    stage = new_stage()
    world = []
    for n, (placed, (points, counts, indices)) in enumerate(zip((first, second), PRISMS)):
        matrix = np.eye(4)
        prim_path = f"/World/P{n}"
        for depth, (t, q, s) in enumerate(placed):
            path = prim_path if depth == 0 else f"{prim_path}/C"
            xf = UsdGeom.Xform.Define(stage, path)
            xf.AddTranslateOp(UsdGeom.XformOp.PrecisionDouble).Set(Gf.Vec3d(*t))
            xf.AddOrientOp(UsdGeom.XformOp.PrecisionDouble).Set(Gf.Quatd(*q).GetNormalized())
            xf.AddScaleOp(UsdGeom.XformOp.PrecisionDouble).Set(Gf.Vec3d(s, s, s))
            matrix = matrix @ similarity((t, q, s))
        define_mesh(stage, f"{prim_path}/C/Geom", points, counts, indices)
        local = np.asarray(points, np.float32).astype(np.float64)
        world.append((local @ matrix[:3, :3].T + matrix[:3, 3], fan(counts, indices)[0]))
    res = wc.collide(world, device=device)
    report = check_usd(stage, count_touching=True, device=device)
    assert report.object_path == ["/World/P0/C/Geom", "/World/P1/C/Geom"]
    for (got, _), (want, _) in zip(report.source.scene.world_meshes(), world):  # the import places them so
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-5 * max(1.0, np.abs(want).max()))
    assert report.frames[0].object_pairs.tolist() == res.object_pairs.tolist()
    assert report.penetrating == (res.num_triangle_pairs > 0)
    event("colliding" if res.num_triangle_pairs else "apart")


def test_transforms_read_by_worker_processes_match(mixed_file, device):
    """Worker processes (each opening the file, a share of the time codes) give the same poses, and
    the same world vertices at every frame, as reading in this process; a transform that is not
    finite at some time code is still named."""
    times = stage_time_codes(Usd.Stage.Open(str(mixed_file)))
    serial = UsdMeshImport(mixed_file, times=times, device=device, workers=0)
    pooled = UsdMeshImport(mixed_file, times=times, device=device, workers=2)
    assert pooled.object_path == serial.object_path
    np.testing.assert_array_equal(pooled.object_deforming, serial.object_deforming)
    for k in (0, 11, len(times) - 1):
        serial.set_frame(k)
        pooled.set_frame(k)
        np.testing.assert_array_equal(pooled.scene.world_vertex.numpy(), serial.scene.world_vertex.numpy())


def test_worker_processes_name_a_transform_that_is_not_finite(tmp_path):
    path = tmp_path / "nan.usda"
    stage = new_stage(path, end=3)
    mesh = define_mesh(stage, "/World/Box", *prism(4))
    op = UsdGeom.Xformable(mesh).AddTranslateOp()
    for f in range(4):
        op.Set(Gf.Vec3d(float("nan") if f == 2 else 0.0, 0.0, 0.0), f)
    stage.GetRootLayer().Save()
    with pytest.raises(ValueError, match="/World/Box: xformOp:translate at time 2 is not finite"):
        UsdMeshImport(path, times=[0, 1, 2, 3], workers=2)


def test_deepest_face_pair_rows_match_the_full_sort():
    """The frame's rows without segments (one sort of a packed key, or of two keys where it does not fit in 63
    bits) equal the full sort by (a, b, face_a, face_b, deepest first, triangles) and its first row per face pair."""
    from warp_ccd._src.check.check import _face_pair_groups

    def _deepest_per_face_pair(faces, depth, objects, count):
        order, starts = _face_pair_groups(faces, objects, count)
        return faces[order][starts], np.maximum.reduceat(depth[order], starts)

    rng = np.random.default_rng(1)
    for _ in range(100):
        m, n, num_faces = int(rng.integers(1, 300)), int(rng.integers(1, 20)), int(rng.integers(1, 10))
        faces = np.stack([rng.integers(0, n, m), rng.integers(0, num_faces, m), rng.integers(0, n, m),
                          rng.integers(0, num_faces, m)], axis=1).astype(np.int32)
        depth = np.round(rng.random(m), 1) * (rng.random(m) < 0.7)  # ties and zeros (touching rows)
        tri = rng.integers(0, 50, (m, 2))
        order = np.lexsort((tri[:, 1], tri[:, 0], -depth, faces[:, 3], faces[:, 1], faces[:, 2], faces[:, 0]))
        first = np.ones(m, bool)
        first[1:] = (faces[order][1:] != faces[order][:-1]).any(axis=1)
        for objects, count in ((n, num_faces), (2**20, 2**20)):
            got, deepest = _deepest_per_face_pair(faces, depth, objects, count)
            assert got.dtype == np.int32 and np.array_equal(got, faces[order][first])
            assert np.array_equal(deepest, depth[order][first])


# The depth the check gates on, containment (narrowphase/depth.py).

def test_flush_cubes_have_depth_03_and_min_depth_gates_on_it(tmp_path, capsys):
    """Two unit cubes overlapping by 0.7 along x, flush on y and z: no vertex of either lies inside the other,
    yet the depth is 0.3 (the middle of A's face x = 0.5 lies 0.3 inside B): ``--min-depth 0.01`` exits 1, 0.31
    exits 0; the report says 0.3 for the pair."""
    path = tmp_path / "flush.usda"
    stage = new_stage(path, end=0)
    define_mesh(stage, "/World/A", *box((-0.5, -0.5, -0.5), (0.5, 0.5, 0.5)))
    define_mesh(stage, "/World/B", *box((-0.2, -0.5, -0.5), (0.8, 0.5, 0.5)))
    stage.GetRootLayer().Save()
    report = tmp_path / "r.json"
    rc, captured = run_cli(capsys, ["check", str(path), "--min-depth", "0.01", "--report", str(report)])
    assert rc == 1, captured.err
    data = json.loads(report.read_text())
    assert data["findings"] == "penetrating" and data["pairs"][0]["max_depth"] == pytest.approx(0.3, rel=1e-6)
    rc, captured = run_cli(capsys, ["check", str(path), "--min-depth", "0.31"])
    assert rc == 0, captured.err


def test_crossing_open_sheets_have_no_depth_and_always_penetrate(tmp_path, capsys):
    """Two open quads crossing in an X bound no solid: the report's depth is null, the summary says undefined,
    and the pair penetrates whatever --min-depth."""
    path = tmp_path / "sheets.usda"
    stage = new_stage(path, end=0)
    define_mesh(stage, "/World/A", [[-1, 0, -1], [1, 0, -1], [1, 0, 1], [-1, 0, 1]], [4], [0, 1, 2, 3])
    define_mesh(stage, "/World/B", [[0, -1, -1], [0, 1, -1], [0, 1, 1], [0, -1, 1]], [4], [0, 1, 2, 3])
    stage.GetRootLayer().Save()
    report = tmp_path / "r.json"
    rc, captured = run_cli(capsys, ["check", str(path), "--min-depth", "10", "--report", str(report)])
    assert rc == 1, captured.err
    assert "undefined" in captured.out
    data = json.loads(report.read_text())
    assert data["pairs"][0]["max_depth"] is None and data["frames"][0]["pairs"][0]["max_depth"] is None


def test_containment_is_a_finding_with_its_depth(tmp_path, capsys):
    """A box wholly inside another passes a plain check (exit 0); with --containment it is a finding
    ("contained", exit 1) with its depth (its bottom face's middle, 0.4 from the outer surface), in the report,
    the summary and the overlay (violet)."""
    from warp_ccd._src.check.overlay import COLOR_CONTAINED

    path = tmp_path / "inside.usda"
    stage = new_stage(path, end=0)
    define_mesh(stage, "/World/Outer", *box((-0.5, -0.5, -0.5), (0.5, 0.5, 0.5)))
    define_mesh(stage, "/World/Inner", *box((-0.2, -0.1, -0.2), (0.2, 0.3, 0.2)))
    stage.GetRootLayer().Save()
    rc, captured = run_cli(capsys, ["check", str(path)])
    assert rc == 0, captured.err
    report, overlay = tmp_path / "r.json", tmp_path / "o.usda"
    rc, captured = run_cli(capsys, ["check", str(path), "--containment", "--report", str(report),
                                    "--usd-out", str(overlay)])
    assert rc == 1, captured.err
    assert "/World/Inner inside /World/Outer" in captured.out
    data = json.loads(report.read_text())
    assert data["findings"] == "contained" and data["contained"] is True
    (row,) = data["frames"][0]["contained"]
    assert (row["inner"], row["outer"]) == ("/World/Inner", "/World/Outer")
    assert row["depth"] == pytest.approx(0.4, rel=1e-6)
    assert data["containment"]["pairs"][0]["max_depth"] == pytest.approx(0.4, rel=1e-6)
    jsonschema = pytest.importorskip("jsonschema")
    jsonschema.validate(data, report_schema())
    layered = Usd.Stage.Open(str(overlay))
    color = UsdGeom.PrimvarsAPI(layered.GetPrimAtPath("/World/Inner")).GetPrimvar("displayColor").Get(0)
    assert tuple(color[0]) == pytest.approx(COLOR_CONTAINED)
