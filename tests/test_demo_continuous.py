"""``warp-ccd demo --continuous``: fast boxes through thin walls. The contacts it counts against
``collide`` at each frame and over each frame step, the USD's colours (any time of the step), and a
small run that sees contacts the frames alone miss."""

import re

import numpy as np
import pytest

import warp_ccd as wc
from warp_ccd._src.cli import commands as cli
from warp_ccd._src.cli.tunnelling import BOX_HALF, WALL_SPACING, ContactTally, ThinWalls


def test_the_boxes_fly_between_the_walls_and_the_tally_matches_collide(device):
    walls = ThinWalls(12, seed=3, device=device)
    scene = walls.scene
    w = walls.num_walls
    meshes = scene.world_meshes()
    local = [scene.shape_meshes[s] for s in scene.object_shape_np]
    tally = ContactTally()
    previous = None
    expected = [0, 0, 0]
    for frame in range(5):
        m = walls.transforms(frame)
        x = m[w:, 0, 3]
        assert (x >= -WALL_SPACING / 2 - 1e-9).all() and (x <= WALL_SPACING * (w - 0.5) + 1e-9).all()
        at = wc.collide(local, m, device=device).object_pairs
        step = wc.collide(local, walls.transforms(max(frame - 1, 0)), device=device, transforms_end=m).object_pairs
        tally.add(at, step)
        seen = {tuple(p) for p in at.tolist()} | ({tuple(p) for p in previous.tolist()} if previous is not None
                                                  else set())
        expected[0] += len(at)
        expected[1] += len(step)
        expected[2] += sum(tuple(p) not in seen for p in step.tolist())
        previous = at
    assert [tally.at_frames, tally.over_steps, tally.only_continuous] == expected
    assert tally.only_continuous > 0
    assert len(meshes) == 12 and np.ptp(meshes[w][0], axis=0).max() <= 2 * np.sqrt(3) * BOX_HALF + 1e-6


def test_demo_continuous_counts_contacts_only_the_continuous_detection_saw(tmp_path, device, capsys):
    pxr = pytest.importorskip("pxr")
    out = tmp_path / "walls.usda"
    rc = cli.main(["demo", "--continuous", "--num-objects", "10", "--num-frames", "4", "--device", device,
                   "--out", str(out), "--seed", "1"])
    captured = capsys.readouterr()
    assert rc == 0, captured.err
    assert "fast boxes through thin walls (9 boxes, 1 wall)" in captured.out
    found = re.search(r"at the frames (\d+), over the frame steps (\d+), only continuous \(the frames miss them\) "
                      r"(\d+)", captured.out)
    assert found, captured.out
    at_frames, over_steps, only = map(int, found.groups())
    assert only >= 1 and over_steps >= only
    assert "continuous ms / frame" in captured.out
    # Coloured in the USD: the objects that collide at the frame or at any time of the step to it.
    from warp_ccd._src.usd.export import COLOR_COLLIDING

    walls = ThinWalls(10, seed=1, device=device)
    local = [walls.scene.shape_meshes[k] for k in walls.scene.object_shape_np]
    stage = pxr.Usd.Stage.Open(str(out))
    assert stage.GetEndTimeCode() == 3
    (instancer,) = [p for p in stage.Traverse() if p.IsA(pxr.UsdGeom.PointInstancer)]
    colours = pxr.UsdGeom.PrimvarsAPI(instancer).GetPrimvar("displayColor")
    for frame in range(4):
        m = walls.transforms(frame)
        expected = wc.collide(local, m, device=device).colliding
        expected |= wc.collide(local, walls.transforms(max(frame - 1, 0)), device=device, transforms_end=m).colliding
        c = np.asarray(colours.Get(frame))
        np.testing.assert_array_equal(np.abs(c - COLOR_COLLIDING).max(axis=1) < 1e-6, expected)


def test_demo_continuous_needs_two_objects(tmp_path, capsys):
    rc = cli.main(["demo", "--continuous", "--num-objects", "1", "--num-frames", "1", "--out",
                   str(tmp_path / "x.usda")])
    err = capsys.readouterr().err
    assert rc == 2 and "at least 2 objects" in err
    assert not (tmp_path / "x.usda").exists()
