"""Bad input to ``warp-ccd check``: errors naming the stage or prim, never a silent clean result.

Stage time ranges (reversed, too many time codes), PointInstancers (negative or out-of-range
prototype indices, zero or non-finite orientations, prototypes outside the instancer), holes
that are not faces, and the read's progress bar.
"""


import io
import re
import sys

import numpy as np
import pytest

from warp_ccd import cli
from warp_ccd.check import check_usd
from warp_ccd.usd_import import MAX_FRAMES, UsdMeshImport, stage_time_codes

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
