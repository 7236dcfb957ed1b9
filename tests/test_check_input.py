"""Bad input to ``warp-ccd check`` and ``collide()``: errors naming the prim or object, never a
silent clean result.

Stage time ranges (reversed, too many time codes), PointInstancers (negative or out-of-range
prototype indices, zero or non-finite orientations, prototypes outside the instancer), holes
that are not faces, the read's progress bar, and the precision guard: coordinates too far from
the origin for float32 at the triangles' size switch a check to float64 (with a warning) and
make ``collide()`` refuse float32; beyond float64, or float32's range, everything refuses.
"""

import io
import re
import sys
import warnings

import numpy as np
import pytest

import warp_ccd as wc
from warp_ccd._src.check.check import check_usd
from warp_ccd._src.cli import commands as cli
from warp_ccd._src.geometry.precision import PrecisionWarning, needed_precision, triangle_size
from warp_ccd._src.usd.importer import UsdMeshImport
from warp_ccd._src.usd.stage import MAX_FRAMES, stage_time_codes

from conftest import DEFAULT_DEVICE

pxr = pytest.importorskip("pxr")
from pxr import Gf, Sdf, Usd, UsdGeom, Vt  # noqa: E402
from usd_stages import define_mesh, grid  # noqa: E402


def new_stage(path=None, start=0.0, end=None):
    stage = Usd.Stage.CreateNew(str(path)) if path is not None else Usd.Stage.CreateInMemory()
    if end is not None:
        stage.SetStartTimeCode(start)
        stage.SetEndTimeCode(end)
    stage.SetDefaultPrim(UsdGeom.Xform.Define(stage, "/World").GetPrim())
    return stage


def unit_cube():
    """A unit cube ``[0, 1]^3``: ``(points, counts, indices)``, six outward quads."""
    points = [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]]
    quads = [[0, 3, 2, 1], [4, 5, 6, 7], [0, 1, 5, 4], [2, 3, 7, 6], [0, 4, 7, 3], [1, 2, 6, 5]]
    return points, [4] * 6, [i for q in quads for i in q]


def instancer_stage(proto_indices=(0, 1, 0), orientations=None, orientations_f=None, prototypes=None):
    """``/World/Inst``: a PointInstancer of two prototypes under it (a cube and a smaller cube),
    instances 3 apart along x; time codes 0..2."""
    stage = new_stage(end=2)
    inst = UsdGeom.PointInstancer.Define(stage, "/World/Inst")
    define_mesh(stage, "/World/Inst/Protos/Big", *unit_cube())
    small = define_mesh(stage, "/World/Inst/Protos/Small", *unit_cube())
    UsdGeom.Xformable(small).AddScaleOp().Set(Gf.Vec3f(0.5, 0.5, 0.5))
    define_mesh(stage, "/World/Elsewhere", *unit_cube())
    targets = prototypes or ["/World/Inst/Protos/Big", "/World/Inst/Protos/Small"]
    inst.CreatePrototypesRel().SetTargets([Sdf.Path(t) for t in targets])
    inst.CreateProtoIndicesAttr(Vt.IntArray(list(proto_indices)))
    n = len(proto_indices)
    inst.CreatePositionsAttr(Vt.Vec3fArray([Gf.Vec3f(3.0 * i, 0, 0) for i in range(n)]))
    if orientations is not None:
        inst.CreateOrientationsAttr(Vt.QuathArray([Gf.Quath(*q) for q in orientations]))
    if orientations_f is not None:
        inst.CreateOrientationsfAttr(Vt.QuatfArray([Gf.Quatf(*q) for q in orientations_f]))
    return stage


# ---------------------------------------------------------------------------------------------
# time ranges


def test_reversed_stage_range_is_an_error(tmp_path, capsys):
    stage = new_stage(tmp_path / "reversed.usda", start=10, end=5)
    define_mesh(stage, "/World/Box", *unit_cube())
    stage.GetRootLayer().Save()
    for frames in (None, slice(None, 7), slice(6, None)):
        with pytest.raises(ValueError, match=r"startTimeCode 10 is after its endTimeCode 5.*--frames"):
            stage_time_codes(stage, frames)
    with pytest.raises(ValueError, match="reversed.usda"):
        check_usd(stage, device=DEFAULT_DEVICE)
    # Time codes given in full are checked as asked (the stage's range says nothing then).
    np.testing.assert_array_equal(stage_time_codes(stage, slice(5, 7)), [5, 6, 7])
    assert len(check_usd(stage, frames=[7.0], device=DEFAULT_DEVICE).frames) == 1
    # A stage without a range is still one time code, 0.
    plain = new_stage()
    np.testing.assert_array_equal(stage_time_codes(plain), [0.0])
    # The command: bad input, exit status 2, the file named.
    assert cli.main(["check", str(tmp_path / "reversed.usda"), "--device", DEFAULT_DEVICE]) == 2
    assert "startTimeCode 10 is after its endTimeCode 5" in capsys.readouterr().err


def test_too_many_time_codes_are_refused():
    stage = new_stage(end=1e7)
    define_mesh(stage, "/World/Box", *unit_cube())
    with pytest.raises(ValueError, match=re.escape(f"10000001 time codes in 0..1e+07 (step 1), more than {MAX_FRAMES}")
                       + ".*--frames"):
        stage_time_codes(stage)
    with pytest.raises(ValueError, match="--frames"):
        check_usd(stage, device=DEFAULT_DEVICE)
    with pytest.raises(ValueError, match="more than"):
        stage_time_codes(stage, slice(0, 2e6))
    np.testing.assert_array_equal(stage_time_codes(stage, slice(0, 1e7, 2.5e6)), [0, 2.5e6, 5e6, 7.5e6, 1e7])
    assert len(stage_time_codes(stage, slice(0, MAX_FRAMES - 1))) == MAX_FRAMES  # the most it takes


class _Terminal(io.StringIO):
    """stderr as a terminal: progress bars draw on it."""

    def isatty(self):
        return True


def test_reading_shows_progress(monkeypatch):
    stage = new_stage(end=299)
    box = define_mesh(stage, "/World/Box", *unit_cube())
    move = UsdGeom.Xformable(box).AddTranslateOp()
    for f in (0, 299):
        move.Set(Gf.Vec3d(0.01 * f, 0, 0), f)
    define_mesh(stage, "/World/Floor", *grid(2, 4.0))
    err = _Terminal()
    monkeypatch.setattr(sys, "stderr", err)
    check_usd(stage, device=DEFAULT_DEVICE, progress=True)
    assert re.search(r"reading transforms: .*/300", err.getvalue())
    err.seek(0)
    err.truncate()
    check_usd(stage, device=DEFAULT_DEVICE, progress=False)
    UsdMeshImport(stage, times=np.arange(300.0), device=DEFAULT_DEVICE)
    assert err.getvalue() == ""


# ---------------------------------------------------------------------------------------------
# PointInstancers and holes


@pytest.mark.parametrize("indices, words", [
    ((0, 1, -1, 0), "prim /World/Inst: protoIndices has index -1 at instance 2"),
    ((0, -3), "prim /World/Inst: protoIndices has index -3 at instance 1"),
    ((0, 5, 1), "prim /World/Inst: protoIndices refer to prototype 5 at instance 1, but it has 2 prototypes"),
])
def test_bad_proto_indices(indices, words):
    with pytest.raises(ValueError, match=re.escape(words)):
        UsdMeshImport(instancer_stage(indices), device=DEFAULT_DEVICE)


@pytest.mark.parametrize("half", [True, False])
@pytest.mark.parametrize("bad, words", [((0, 0, 0, 0), "is zero"), ((float("nan"), 0, 0, 1), "is not finite"),
                                        ((float("inf"), 0, 0, 0), "is not finite")])
def test_zero_or_non_finite_orientation(half, bad, words):
    quats = [(1, 0, 0, 0), (1, 0, 0, 0), bad]
    stage = instancer_stage(orientations=quats) if half else instancer_stage(orientations_f=quats)
    attr = "orientations" if half else "orientationsf"
    with pytest.raises(ValueError, match=re.escape(f"prim /World/Inst: {attr}[2] (instance 2) {words} at time 0")):
        UsdMeshImport(stage, device=DEFAULT_DEVICE)


def test_zero_orientation_at_a_later_time():
    stage = instancer_stage(orientations_f=[(1, 0, 0, 0)] * 3)
    attr = UsdGeom.PointInstancer(stage.GetPrimAtPath("/World/Inst")).GetOrientationsfAttr()
    attr.Set(Vt.QuatfArray([Gf.Quatf(1, 0, 0, 0)] * 3), 0)
    attr.Set(Vt.QuatfArray([Gf.Quatf(1, 0, 0, 0), Gf.Quatf(0, 0, 0, 0), Gf.Quatf(1, 0, 0, 0)]), 2)
    words = "prim /World/Inst: orientationsf[1] (instance 1) is zero at time 2"
    with pytest.raises(ValueError, match=re.escape(words)):
        check_usd(stage, device=DEFAULT_DEVICE)
    # A masked instance is not checked.
    UsdGeom.PointInstancer(stage.GetPrimAtPath("/World/Inst")).DeactivateId(1)
    assert check_usd(stage, device=DEFAULT_DEVICE).object_path == ["/World/Elsewhere", "/World/Inst[0]/Big",
                                                                     "/World/Inst[2]/Big"]
    # Unit and merely unnormalised quaternions are read as USD computes their transforms.
    imp = UsdMeshImport(instancer_stage(orientations=[(1, 0, 0, 0), (0, 0, 1, 0), (0.5, 0, 0, 0)]),
                        device=DEFAULT_DEVICE)
    assert set(imp.object_path) == {"/World/Elsewhere", "/World/Inst[0]/Big", "/World/Inst[1]/Small",
                                    "/World/Inst[2]/Big"}


@pytest.mark.parametrize("target", ["/World/Elsewhere", "/World", "/World/Inst"])
def test_prototype_outside_the_instancer(target):
    stage = instancer_stage(prototypes=["/World/Inst/Protos/Big", target])
    with pytest.raises(ValueError, match=re.escape(f"prim /World/Inst: prototype {target} is not under the instancer")):
        UsdMeshImport(stage, device=DEFAULT_DEVICE)


@pytest.mark.parametrize("holes, words", [([1, 6], "holeIndices[1] = 6 is not a face index (it has 6 faces)"),
                                          ([-1], "holeIndices[0] = -1 is not a face index")])
def test_holes_that_are_not_faces(holes, words):
    stage = new_stage()
    define_mesh(stage, "/World/Floor", *grid(2, 4.0))
    define_mesh(stage, "/World/Holed", *unit_cube(), holes=holes)
    with pytest.raises(ValueError, match=re.escape(f"prim /World/Holed: {words}")):
        UsdMeshImport(stage, device=DEFAULT_DEVICE)


# ---------------------------------------------------------------------------------------------
# precision


def overlapping_cubes_stage(offset: float, deforming: bool = False):
    """Two unit cubes overlapping by 0.5 on every axis (a vertex of each inside the other),
    translated by ``(offset, offset, -offset)``; with ``deforming``, their points time-sampled."""
    stage = new_stage(end=1)
    for name, d in (("A", 0.0), ("B", 0.5)):
        mesh = define_mesh(stage, f"/World/{name}", *unit_cube())
        UsdGeom.Xformable(mesh).AddTranslateOp().Set(Gf.Vec3d(offset + d, offset + d, -offset + d))
        if deforming:
            points = np.asarray(unit_cube()[0], np.float32)
            for f in (0, 1):
                mesh.GetPointsAttr().Set(Vt.Vec3fArray.FromNumpy(points * (1 + 0.01 * f)), f)
    return stage


def test_needed_precision_thresholds():
    assert needed_precision(8e3, 1.0) == "float32"
    assert needed_precision(9e3, 1.0) == "float64"  # 9e3 * 2**-23 > 1e-3
    assert needed_precision(4e12, 1.0) == "float64"
    assert needed_precision(5e12, 1.0) is None  # 5e12 * 2**-52 > 1e-3
    assert needed_precision(1e30, 1e27) == "float32"  # scale-free: R / s counts
    assert needed_precision(1e30, 1e25) == "float64"
    assert needed_precision(3.5e38, 1e36) is None  # beyond float32's range: boxes are float32
    assert needed_precision(1e30, 0.0) == "float32"  # no triangle has a size: only the range counts
    # The typical size: the median longest edge over the objects' triangles (shapes times scales).
    v, t = wc.scene.shape("cube")  # longest edge 2 sqrt(2/3) = 1.633
    packed = wc.Scene.from_meshes([(v, t)] * 3).shapes
    args = packed.vertices, packed.triangles, packed.vertex_start, packed.triangle_start
    assert triangle_size(*args, [0, 0, 0]) == pytest.approx(1.6329931)
    assert triangle_size(*args, [0, 0, 0], [1.0, 3.0, 3.0]) == pytest.approx(3 * 1.6329931)


@pytest.mark.parametrize("deforming", [False, True])
def test_check_far_from_the_origin_switches_to_float64(device, deforming):
    near = check_usd(overlapping_cubes_stage(0.0, deforming), device=device)
    assert near.penetrating and near.source.scene.precision == "float32"
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        far = check_usd(overlapping_cubes_stage(1e8, deforming), device=device)
    assert far.penetrating  # in float32 every vertex there is a multiple of 8: no cube, no crossing
    note = ("coordinates up to 1e+08 are beyond float32 at triangles of size 1.41 (its step there: 12): "
            "checking in float64")
    assert [(w.category, str(w.message)) for w in caught] == [(PrecisionWarning, f"prim /World/B: {note}")]
    assert far.source.scene.precision == "float64" and far.source.precision_note == f"prim /World/B: {note}"
    assert near.source.precision_note is None
    for a, b in zip(near.frames, far.frames):
        np.testing.assert_array_equal(a.triangle_pairs, b.triangle_pairs)
        np.testing.assert_allclose(a.depth, b.depth, rtol=0, atol=1e-6)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # asked for float64: nothing to say
        assert check_usd(overlapping_cubes_stage(1e8, deforming), precision="float64", device=device).penetrating


@pytest.mark.parametrize("offset, words", [
    (1e19, "coordinates up to 1e+19 are beyond float64 at triangles of size 1.41 (its step there: 2.2e+03)"),
    (1e30, "coordinates up to 1e+30 are beyond float64 at triangles of size 1.41"),
    (1e39, "coordinates up to 1e+39 are beyond float32's range"),
])
def test_check_beyond_float64_is_an_error(offset, words):
    for precision in ("float32", "float64"):
        with pytest.raises(ValueError, match=r"prim /World/[AB]: " + re.escape(words)):
            check_usd(overlapping_cubes_stage(offset), precision=precision, device=DEFAULT_DEVICE)


def test_deforming_points_that_move_away_later():
    """Deforming points are read frame by frame: one that leaves float32's reach at a later time
    code stops a float32 check there, naming the prim and the time."""
    stage = overlapping_cubes_stage(0.0, deforming=True)
    op = UsdGeom.Xformable(stage.GetPrimAtPath("/World/B")).GetOrderedXformOps()[0]
    op.Set(Gf.Vec3d(0.5, 0.5, 0.5), 0)
    op.Set(Gf.Vec3d(3e4, 0.5, 0.5), 1)
    with pytest.raises(ValueError, match=re.escape("prim /World/B at time 1: coordinates up to 3e+04 are beyond "
                                                   "float32") + ".*precision='float64'"):
        check_usd(stage, device=DEFAULT_DEVICE)
    report = check_usd(stage, precision="float64", device=DEFAULT_DEVICE)
    assert [len(f.triangle_pairs) > 0 for f in report.frames] == [True, False]


def cube_meshes_and_transforms(offset: float):
    v, t = unit_cube()[0], [[0, 3, 2], [0, 2, 1], [4, 5, 6], [4, 6, 7], [0, 1, 5], [0, 5, 4], [2, 3, 7], [2, 7, 6],
                            [0, 4, 7], [0, 7, 3], [1, 2, 6], [1, 6, 5]]
    v, t = np.asarray(v, np.float64), np.asarray(t, np.int32)
    transforms = np.tile(np.eye(4), (2, 1, 1))
    transforms[:, :3, 3] = [[offset, offset, -offset], [offset + 0.5, offset + 0.5, -offset + 0.5]]
    return [(v, t), (v, t)], transforms


def test_collide_far_from_the_origin(device):
    meshes, transforms = cube_meshes_and_transforms(0.0)
    ref = wc.collide(meshes, transforms, device=device)
    assert ref.object_pairs.tolist() == [[0, 1]]
    far_meshes, far = cube_meshes_and_transforms(1e8)
    world = [(v + tr[:3, 3], t) for (v, t), tr in zip(far_meshes, far)]
    for args in ((far_meshes, far), (world, None)):
        with pytest.raises(ValueError, match=r"mesh [01]: " + re.escape("coordinates up to 1e+08 are beyond float32 "
                                                                         "at triangles of size 1.41")
                           + r".*use precision='float64'"):
            wc.collide(*args, device=device)
        with pytest.raises(ValueError, match="use precision='float64'"):
            wc.Scene.from_meshes(*args, device=device)
        got = wc.collide(*args, device=device, precision="float64")
        np.testing.assert_array_equal(got.triangle_pairs, ref.triangle_pairs)
    for offset in (1e19, 1e30):
        far_meshes, far = cube_meshes_and_transforms(offset)
        with pytest.raises(ValueError, match=r"mesh [01]: coordinates up to .* are beyond float64"):
            wc.collide(far_meshes, far, device=device, precision="float64")
    # Near enough for float32: 1e3 from the origin with triangles of 1.4.
    meshes, transforms = cube_meshes_and_transforms(1e3)
    assert wc.collide(meshes, transforms, device=device).object_pairs.tolist() == [[0, 1]]


def test_cli_says_it_switched_to_float64_in_one_line(tmp_path, capsys):
    path = tmp_path / "far.usda"
    stage = overlapping_cubes_stage(1e8)
    stage.GetRootLayer().Export(str(path))
    assert cli.main(["check", str(path), "--device", DEFAULT_DEVICE]) == 1
    err = [line for line in capsys.readouterr().err.splitlines() if "float64" in line]
    assert err == ["warp-ccd check: note: prim /World/B: coordinates up to 1e+08 are beyond float32 at triangles "
                   "of size 1.41 (its step there: 12): checking in float64"]
