"""``check --self``: prims that pass through themselves. A cloth (an 8 x 8 quad grid) lies flat at time
code 0, and at 1 its half beyond x = 0 is folded back over the other half as a wave that crosses it (a
deforming mesh through itself); a box beside it stays clean. The frames' face pairs (USD quads) and
depths, the report's section and rows, the summary, the overlay's colour, the exit status; without
``--self`` nothing of it."""

import json

import numpy as np
import pytest

from warp_ccd._src.check.self_intersection import COLOR_SELF
from warp_ccd._src.cli import commands as cli
from warp_ccd.usd import check_usd

pxr = pytest.importorskip("pxr")
from pxr import Usd, UsdGeom, Vt  # noqa: E402
from usd_stages import define_mesh, grid  # noqa: E402

from test_check_continuous import box_mesh  # noqa: E402


def folded(points: np.ndarray) -> np.ndarray:
    """The grid's half beyond x = 0 folded back over the other half, waving through it (amplitude 0.2)."""
    p = points.copy()
    f = p[:, 0] > 1e-9
    p[f, 1] = 0.2 * np.sin(3.0 * p[f, 2] + 0.3)
    p[f, 0] = 0.037 - p[f, 0]
    return p


@pytest.fixture(scope="module")
def stage_path(tmp_path_factory):
    path = tmp_path_factory.mktemp("self") / "cloth.usda"
    stage = Usd.Stage.CreateNew(str(path))
    stage.SetStartTimeCode(0)
    stage.SetEndTimeCode(1)
    stage.SetDefaultPrim(UsdGeom.Xform.Define(stage, "/World").GetPrim())
    points, counts, indices = grid(8, 2.0)
    cloth = define_mesh(stage, "/World/Cloth", points, counts, indices)
    attr = cloth.GetPointsAttr()
    attr.Set(Vt.Vec3fArray.FromNumpy(points.astype(np.float32)), 0)
    attr.Set(Vt.Vec3fArray.FromNumpy(folded(points).astype(np.float32)), 1)
    define_mesh(stage, "/World/Box", *box_mesh((3.0, -1.0, -1.0), (4.0, 1.0, 1.0)))
    stage.GetRootLayer().Save()
    return path


@pytest.mark.parametrize("precision", ["float32", "float64"])
def test_self_intersections_frame_by_frame(stage_path, device, precision):
    report = check_usd(stage_path, device=device, precision=precision, self_intersections=True)
    first, second = (f.self_intersections for f in report.frames)
    assert len(first.face_pairs) == 0
    cloth = report.object_path.index("/World/Cloth")
    assert len(second.face_pairs) > 4 and set(second.face_pairs[:, 0].tolist()) == {cloth}
    faces = second.face_pairs[:, 1:]
    assert (faces >= 0).all() and (faces < 64).all() and (faces[:, 0] <= faces[:, 1]).all()
    assert len(np.unique(second.face_pairs, axis=0)) == len(second.face_pairs)
    # Each pair holds a quad of either half: x < 0 columns against folded ones (quad k: column k // 8).
    assert ((faces[:, 0] // 8 < 4) & (faces[:, 1] // 8 >= 4)).all()
    assert second.depth.max() > 0.01 and (second.depth >= 0).all()
    assert report.findings == "self_intersecting" and report.self_intersecting
    assert not report.penetrating


def test_no_self_without_the_option(stage_path, device):
    report = check_usd(stage_path, device=device)
    assert report.findings is None and all(f.self_intersections is None for f in report.frames)
    data = report.to_json()
    assert "self_intersections" not in data and "self_intersections" not in data["frames"][1]


def test_command_line_report_and_overlay(stage_path, device, tmp_path, capsys):
    before = stage_path.read_bytes()
    report_path, overlay = tmp_path / "r.json", tmp_path / "over.usda"
    rc = cli.main(["check", str(stage_path), "--device", device, "--self", "--report", str(report_path),
                   "--usd-out", str(overlay)])
    out = capsys.readouterr()
    assert rc == 1, out.err
    assert "self-intersections: 1 prims in 1 of 2 frames" in out.out
    data = json.loads(report_path.read_text())
    assert data["findings"] == "self_intersecting" and data["self_intersecting"] is True
    (prim,) = data["self_intersections"]["prims"]
    assert prim["prim"] == "/World/Cloth" and prim["frames"] == 1 and prim["first"] == prim["last"] == 1.0
    assert prim["max_depth"] > 0.01 and prim["max_face_pairs"] > 4
    rows = data["frames"][1]["self_intersections"]
    assert len(rows) == prim["max_face_pairs"] and data["frames"][0]["self_intersections"] == []
    assert all(r["prim"] == "/World/Cloth" and len(r["faces"]) == 2 and r["depth"] >= 0 for r in rows)
    stage = Usd.Stage.Open(str(overlay))
    colour = UsdGeom.PrimvarsAPI(stage.GetPrimAtPath("/World/Cloth")).GetPrimvar("displayColor")
    np.testing.assert_allclose(colour.Get(1.0)[0], COLOR_SELF, atol=1e-6)
    assert tuple(colour.Get(0.0)[0]) != pytest.approx(COLOR_SELF)
    box = UsdGeom.PrimvarsAPI(stage.GetPrimAtPath("/World/Box")).GetPrimvar("displayColor")
    assert not box or box.Get(1.0) is None or tuple(box.Get(1.0)[0]) != pytest.approx(COLOR_SELF)
    assert stage_path.read_bytes() == before
    rc = cli.main(["check", str(stage_path), "--device", device, "--frames", "0:0", "--self"])
    assert rc == 0


def test_preview_draws_the_frame_with_the_most_findings(tmp_path, device, capsys):
    """``--self --preview`` draws the frame whose findings are most (here the one frame of five, time code 3,
    where the cloth passes through itself; no pair penetrates, so it drew time code 0)."""
    path = tmp_path / "late.usda"
    stage = Usd.Stage.CreateNew(str(path))
    stage.SetStartTimeCode(0)
    stage.SetEndTimeCode(4)
    stage.SetDefaultPrim(UsdGeom.Xform.Define(stage, "/World").GetPrim())
    points, counts, indices = grid(8, 2.0)
    attr = define_mesh(stage, "/World/Cloth", points, counts, indices).GetPointsAttr()
    for t in range(5):
        attr.Set(Vt.Vec3fArray.FromNumpy((folded(points) if t == 3 else points).astype(np.float32)), t)
    define_mesh(stage, "/World/Box", *box_mesh((3.0, -1.0, -1.0), (4.0, 1.0, 1.0)))
    stage.GetRootLayer().Save()
    report = check_usd(path, device=device, self_intersections=True)
    per_frame = report.findings_per_frame()
    assert per_frame[3] > 4 and per_frame.tolist() == [0, 0, 0, per_frame[3], 0] and report.worst_frame == 3
    assert check_usd(path, device=device).worst_frame == 0  # no findings: the first frame
    rc = cli.main(["check", str(path), "--device", device, "--self", "--preview", str(tmp_path / "p.png")])
    out = capsys.readouterr()
    assert rc == 1, out.err
    assert "(time 3)" in out.out + out.err and (tmp_path / "p.png").stat().st_size > 0
