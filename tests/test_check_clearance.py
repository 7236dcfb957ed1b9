"""``check --clearance D``: soft clashes. A crate rests on a floor (touching: distance 0, not a
collision) and a cable comes down onto a hot part: 0.2 above it at time code 0, 0.03 at 1, sunk 0.05
into it at 2. With a clearance of 0.1 the crate and the floor clash softly every frame, the cable and
the part at 1 (0.03 apart, the closest points on the facing faces), and at 2 they penetrate: a
collision, not a soft clash. The report's section and rows, the summary, the overlay's colours and
curves, the exit status; no clearance, no soft clash."""

import json

import numpy as np
import pytest

from warp_ccd._src.check.clearance import COLOR_CLEARANCE, COLOR_SOFT_CLASH
from warp_ccd._src.cli import commands as cli
from warp_ccd.usd import check_usd

pxr = pytest.importorskip("pxr")
from pxr import Gf, Usd, UsdGeom  # noqa: E402
from usd_stages import define_mesh  # noqa: E402

from test_check_continuous import box_mesh  # noqa: E402

CABLE_HEIGHTS = (0.2, 0.03, -0.05)
"""The gap between the cable's underside and the hot part's top at time codes 0, 1, 2."""


@pytest.fixture(scope="module")
def stage_path(tmp_path_factory):
    path = tmp_path_factory.mktemp("clearance") / "workshop.usda"
    stage = Usd.Stage.CreateNew(str(path))
    stage.SetStartTimeCode(0)
    stage.SetEndTimeCode(2)
    stage.SetDefaultPrim(UsdGeom.Xform.Define(stage, "/World").GetPrim())
    define_mesh(stage, "/World/Floor", *box_mesh((-5.0, -5.0, -1.0), (5.0, 5.0, 0.0)))
    define_mesh(stage, "/World/Crate", *box_mesh((-4.0, -4.0, 0.0), (-3.0, -3.0, 1.0)))
    define_mesh(stage, "/World/Part", *box_mesh((1.0, 1.0, 0.5), (2.0, 2.0, 1.0)))  # 0.5 above the floor
    cable = define_mesh(stage, "/World/Cable", *box_mesh((1.4, 0.0, 0.0), (1.6, 3.0, 0.1)))
    op = UsdGeom.Xformable(cable).AddTranslateOp()
    for tc, gap in enumerate(CABLE_HEIGHTS):
        op.Set(Gf.Vec3d(0.0, 0.0, 1.0 + gap), tc)
    stage.GetRootLayer().Save()
    return path


def names(report, pairs):
    return {frozenset((report.object_path[a], report.object_path[b])) for a, b in pairs.tolist()}


CRATE = frozenset(("/World/Floor", "/World/Crate"))
CABLE = frozenset(("/World/Part", "/World/Cable"))


@pytest.mark.parametrize("precision", ["float32", "float64"])
def test_soft_clashes_frame_by_frame(stage_path, device, precision):
    report = check_usd(stage_path, device=device, precision=precision, clearance=0.1)
    soft = [f.soft_clashes for f in report.frames]
    assert [names(report, s.object_pairs) for s in soft] == [{CRATE}, {CRATE, CABLE}, {CRATE}]
    assert names(report, report.frames[2].object_pairs) == {CABLE}  # penetrating at 2: a collision
    assert report.findings == "penetrating" and report.soft_clash
    crate = soft[0].object_pairs.tolist().index(sorted(report.object_path.index(p) for p in CRATE))
    assert soft[0].distance[crate] == 0.0  # resting: touching
    row = [names(report, soft[1].object_pairs[k : k + 1]) == {CABLE} for k in range(2)].index(True)
    assert abs(soft[1].distance[row] - 0.03) < 1e-5
    points = soft[1].points[row]
    assert np.allclose(points[:, 2], [1.0, 1.03], atol=1e-5) or np.allclose(points[:, 2], [1.03, 1.0], atol=1e-5)
    assert (soft[1].faces[row] >= 0).all() and (soft[1].faces[row] < 6).all()  # the quads' USD faces
    # The first two frames alone: the soft clashes are the finding.
    first = check_usd(stage_path, frames=slice(0, 1), device=device, precision=precision, clearance=0.1)
    assert first.findings == "soft_clash" and not first.penetrating


def test_no_clearance_no_soft_clash(stage_path, device):
    report = check_usd(stage_path, frames=slice(0, 1), device=device)
    assert report.findings is None and all(f.soft_clashes is None for f in report.frames)
    data = report.to_json()
    assert "clearance" not in data and "soft_clashes" not in data["frames"][0]
    with pytest.raises(ValueError, match="clearance"):
        check_usd(stage_path, device=device, clearance=-0.1)


def test_command_line_report_and_overlay(stage_path, device, tmp_path, capsys):
    before = stage_path.read_bytes()
    report_path, overlay = tmp_path / "r.json", tmp_path / "over.usda"
    rc = cli.main(["check", str(stage_path), "--device", device, "--frames", "0:1", "--clearance", "0.1",
                   "--report", str(report_path), "--usd-out", str(overlay)])
    out = capsys.readouterr()
    assert rc == 1, out.err
    assert "soft clashes (within 0.1, not reported as collisions): 2 prim pairs in 2 of 2 frames" in out.out
    data = json.loads(report_path.read_text())
    assert data["findings"] == "soft_clash" and data["soft_clash"] is True
    section = data["clearance"]
    assert section["clearance"] == 0.1 and section["soft_clashes"] is True
    by_pair = {frozenset((p["a"], p["b"])): p for p in section["pairs"]}
    assert by_pair[CRATE]["frames"] == 2 and by_pair[CRATE]["min_distance"] == 0.0
    assert by_pair[CABLE]["frames"] == 1 and abs(by_pair[CABLE]["min_distance"] - 0.03) < 1e-5
    assert by_pair[CABLE]["at"] == 1.0
    (row,) = [r for r in data["frames"][1]["soft_clashes"] if frozenset((r["a"], r["b"])) == CABLE]
    assert len(row["points"]) == 2 and len(row["faces"]) == 2 and abs(row["distance"] - 0.03) < 1e-5
    stage = Usd.Stage.Open(str(overlay))
    colour = UsdGeom.PrimvarsAPI(stage.GetPrimAtPath("/World/Cable")).GetPrimvar("displayColor")
    np.testing.assert_allclose(colour.Get(1.0)[0], COLOR_SOFT_CLASH, atol=1e-6)
    assert tuple(colour.Get(0.0)[0]) != pytest.approx(COLOR_SOFT_CLASH)
    curves = UsdGeom.BasisCurves(stage.GetPrimAtPath("/WarpCcdCheck/Clearance"))
    np.testing.assert_allclose(curves.GetDisplayColorPrimvar().Get()[0], COLOR_CLEARANCE, atol=1e-6)
    assert len(curves.GetPointsAttr().Get(1.0)) == 4 and len(curves.GetPointsAttr().Get(0.0)) == 2
    assert stage_path.read_bytes() == before
    rc = cli.main(["check", str(stage_path), "--device", device, "--frames", "0:1", "--clearance", "-1"])
    assert rc == 2 and "--clearance" in capsys.readouterr().err
