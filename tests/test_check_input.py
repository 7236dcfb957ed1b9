"""Bad input to ``warp-ccd check``: errors naming the stage or prim, never a silent clean result.

Stage time ranges: a reversed range, too many time codes; the read's progress bar.
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
from pxr import Gf, Usd, UsdGeom  # noqa: E402
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
