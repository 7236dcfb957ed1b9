"""``check --continuous``: a thin box so fast that the time codes show it on either side of a wall,
never touching it. The discrete check finds nothing; the continuous one reports the pair as
tunnelling, at a time no later than the analytic crossing; a pair that intersects at an end frame is
reported but not tunnelling; the report's JSON section, the overlay's colour and attribute, the
summary and the exit status; the input is never written."""

import json

import numpy as np
import pytest

from warp_ccd._src.check.sweep import COLOR_TUNNELLING
from warp_ccd._src.cli import commands as cli
from warp_ccd.usd import check_usd

pxr = pytest.importorskip("pxr")
from pxr import Gf, Usd, UsdGeom  # noqa: E402
from usd_stages import define_mesh  # noqa: E402

SPEED = 4.0
"""The bullet's x moves this far per time code."""
BULLET_X0 = -2.0
BULLET_LENGTH = 0.1
CROSSING = (-BULLET_X0 - BULLET_LENGTH) / SPEED
"""When the bullet's front face (x = -1.9 at time code 0) reaches the wall's face at x = 0: 0.475."""


def box_mesh(lo, hi):
    """A closed box of six quads from corner ``lo`` to ``hi``: ``(points, counts, indices)``."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    points = np.array([[(hi if (k >> a) & 1 else lo)[a] for a in range(3)] for k in range(8)])
    quads = [[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]]
    return points, [4] * 6, [i for q in quads for i in q]


def bullet_stage(path, end_x: float, gap: float | None = None):
    """``/World/Wall`` (x in [0, 0.05]), ``/World/Bullet`` (a 0.1-long box) at x = -2 at time code 0,
    +2 at 1 and ``end_x`` at 2, and ``/World/Far`` far away. With ``gap``, the bullet instead slides
    along the wall's face at that distance (z from -3 to 3), never crossing it."""
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    stage.SetStartTimeCode(0)
    stage.SetEndTimeCode(2)
    stage.SetDefaultPrim(UsdGeom.Xform.Define(stage, "/World").GetPrim())
    define_mesh(stage, "/World/Wall", *box_mesh((0.0, -1.0, -1.0), (0.05, 1.0, 1.0)))
    bullet = define_mesh(stage, "/World/Bullet", *box_mesh((0.0, -0.1, -0.1), (BULLET_LENGTH, 0.1, 0.1)))
    op = UsdGeom.Xformable(bullet).AddTranslateOp()
    if gap is None:
        for tc, x in ((0, BULLET_X0), (1, BULLET_X0 + SPEED), (2, end_x)):
            op.Set(Gf.Vec3d(x, 0.0, 0.0), tc)
    else:
        for tc, z in ((0, -3.0), (1, 3.0), (2, 3.0)):
            op.Set(Gf.Vec3d(-BULLET_LENGTH - gap, 0.0, z), tc)
    far = define_mesh(stage, "/World/Far", *box_mesh((0.0, 0.0, 0.0), (1.0, 1.0, 1.0)))
    UsdGeom.Xformable(far).AddTranslateOp().Set(Gf.Vec3d(20.0, 0.0, 0.0))
    stage.GetRootLayer().Save()
    return path


@pytest.fixture(scope="module")
def stages(tmp_path_factory):
    folder = tmp_path_factory.mktemp("bullets")
    return {"through": bullet_stage(folder / "through.usda", end_x=-0.05),  # 1 -> 2 ends in the wall
            "grazing": bullet_stage(folder / "grazing.usda", end_x=0.0, gap=0.03)}


def pair_names(report, interval):
    return [(report.object_path[a], report.object_path[b]) for a, b in interval.object_pairs.tolist()]


def test_the_discrete_check_misses_the_bullet(stages, device):
    report = check_usd(stages["through"], frames=slice(0, 1), device=device)
    assert [len(f.triangle_pairs) for f in report.frames] == [0, 0]
    assert report.findings is None and report.intervals is None and not report.tunnelling
    assert "continuous" not in report.to_json()


@pytest.mark.parametrize("precision", ["float32", "float64"])
def test_continuous_reports_the_tunnelling_pair_no_later_than_it_happens(stages, device, precision):
    report = check_usd(stages["through"], device=device, precision=precision, continuous=True)
    assert [f.time for f in report.frames] == [0.0, 1.0, 2.0]
    assert [len(f.object_pairs) for f in report.frames] == [0, 0, 1]  # the end: in the wall
    first, second = report.intervals
    assert (first.start, first.end, second.start, second.end) == (0.0, 1.0, 1.0, 2.0)
    assert pair_names(report, first) == [("/World/Wall", "/World/Bullet")] or \
        pair_names(report, first) == [("/World/Bullet", "/World/Wall")]
    assert first.tunnelling.tolist() == [True]
    assert CROSSING - 1e-3 <= first.toi[0] <= CROSSING
    assert first.time[0] == first.toi[0]  # the interval 0..1
    assert first.triangle_pairs[0] >= 1
    # 1 -> 2: back from x = 2 into the wall; the end frame shows the pair: reported, not tunnelling.
    assert len(second.object_pairs) == 1 and second.tunnelling.tolist() == [False]
    assert 0.0 < second.toi[0] < 1.0 and second.time[0] == 1.0 + second.toi[0]
    assert report.tunnelling and report.findings == "penetrating"
    # Only the first interval: the tunnelling is the finding.
    only = check_usd(stages["through"], frames=slice(0, 1), device=device, precision=precision, continuous=True)
    assert [len(f.triangle_pairs) for f in only.frames] == [0, 0]
    assert only.findings == "tunnelling"
    np.testing.assert_array_equal(only.intervals[0].toi, first.toi)


def test_min_distance(stages, device):
    """The bullet slides past the wall 0.03 away: touching within 0.05, not within 0.01, nor without."""
    for d, expected in ((0.0, 0), (0.01, 0), (0.05, 1)):
        report = check_usd(stages["grazing"], frames=slice(0, 1), device=device, continuous=True, min_distance=d)
        assert len(report.intervals[0].object_pairs) == expected, d
        assert report.to_json()["continuous"]["min_distance"] == d
    with pytest.raises(ValueError, match="min_distance"):
        check_usd(stages["grazing"], device=device, min_distance=0.1)


def test_command_line(stages, device, tmp_path, capsys):
    src = stages["through"]
    before = src.read_bytes()
    report_path, overlay = tmp_path / "r.json", tmp_path / "over.usda"
    rc = cli.main(["check", str(src), "--device", device, "--frames", "0:1", "--continuous", "--report",
                   str(report_path), "--usd-out", str(overlay)])
    out = capsys.readouterr()
    assert rc == 1, out.err  # the tunnelling pair is a finding
    assert "tunnelling pairs (neither end frame intersects): 1" in out.out
    assert "0..1" in out.out and "/World/Bullet" in out.out
    data = json.loads(report_path.read_text())
    assert data["findings"] == "tunnelling" and data["tunnelling"] is True and data["frames_with_contacts"] == []
    section = data["continuous"]
    assert section["tunnelling_pairs"] == 1 and section["min_distance"] == 0.0
    assert section["intervals_with_contacts"] == 1
    (interval,) = section["intervals"]
    assert interval["start"] == 0.0 and interval["end"] == 1.0
    (pair,) = interval["pairs"]
    assert {pair["a"], pair["b"]} == {"/World/Wall", "/World/Bullet"}
    assert pair["tunnelling"] is True and CROSSING - 1e-3 <= pair["toi"] <= CROSSING
    assert pair["time"] == pair["toi"] and pair["triangle_pairs"] >= 1 and len(pair["faces"]) == 2
    # The overlay: both prims orange at the interval's start, their colour back at its end.
    stage = Usd.Stage.Open(str(overlay))
    for path in ("/World/Bullet", "/World/Wall"):
        prim = stage.GetPrimAtPath(path)
        colour = UsdGeom.PrimvarsAPI(prim).GetPrimvar("displayColor")
        np.testing.assert_allclose(colour.Get(0.0)[0], COLOR_TUNNELLING, atol=1e-6)
        assert tuple(colour.Get(1.0)[0]) != pytest.approx(COLOR_TUNNELLING)
        flag = prim.GetAttribute("warpCcd:tunnelling")
        assert flag.Get(0.0) is True and flag.Get(1.0) is False
    assert not stage.GetPrimAtPath("/World/Far").GetAttribute("warpCcd:tunnelling")
    assert src.read_bytes() == before  # the input untouched
    # The same frames without --continuous: nothing found.
    rc = cli.main(["check", str(src), "--device", device, "--frames", "0:1"])
    out = capsys.readouterr()
    assert rc == 0, out.err
    assert "continuous" not in out.out


def test_min_distance_needs_continuous(stages, capsys):
    rc = cli.main(["check", str(stages["through"]), "--min-distance", "0.1"])
    err = capsys.readouterr().err
    assert rc == 2 and "--min-distance is an option of the continuous check (--continuous), got 0.1" in err


def test_the_input_is_never_the_overlay(stages, device, capsys):
    src = stages["through"]
    before = src.read_bytes()
    rc = cli.main(["check", str(src), "--device", device, "--continuous", "--usd-out", str(src)])
    err = capsys.readouterr().err
    assert rc == 2 and "would be written over" in err
    assert src.read_bytes() == before
