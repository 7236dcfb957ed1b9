"""``warp-ccd check``'s verdicts on stages: penetrating or touching is a property of the surfaces,
the same however their polygons are fanned into triangles, mirrored, scaled or wound
(``leftHanded``); depth as deep as the crate is sunk. The cases a user met on real assets (a
battery resting in its holder, sub-meshes meeting in a parting plane, a latch against its plug)
as small stages."""

import numpy as np
import pytest

from warp_ccd._src.check.check import check_usd
from warp_ccd._src.cli import commands as cli

pxr = pytest.importorskip("pxr")
from pxr import Gf, Usd, UsdGeom, Vt  # noqa: E402

CUBE_QUADS = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]
"""The faces of a box with corner ``k`` at ``(k & 1, k & 2, k & 4)``, wound outward (right-handed)."""


def box_polygons(lo, hi, start: int = 0, skip=()):
    """A box as USD quads, each face's vertex list rotated to begin at its ``start``-th vertex
    (so it fans from there); faces in ``skip`` left out (an open shell)."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    points = np.array([[(hi if k >> i & 1 else lo)[i] for i in range(3)] for k in range(8)])
    quads = [q[start % 4:] + q[:start % 4] for f, q in enumerate(CUBE_QUADS) if f not in skip]
    return points, [4] * len(quads), [i for q in quads for i in q]


def grid_polygons(n: int, size: float = 3.0, angle: float = 0.0, start: int = 0):
    """An ``n x n`` quad grid in the plane z = 0, facing +z, rotated by ``angle`` about z."""
    xs = np.linspace(-size / 2, size / 2, n + 1)
    gx, gy = np.meshgrid(xs, xs, indexing="ij")
    c, s = np.cos(angle), np.sin(angle)
    points = np.stack([c * gx.ravel() - s * gy.ravel(), s * gx.ravel() + c * gy.ravel(), np.zeros(gx.size)], 1)
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    quads = np.stack([idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]], axis=-1).reshape(-1, 4)
    quads = np.roll(quads, -start, axis=1)
    return points, [4] * len(quads), quads.ravel().tolist()


def add_mesh(stage, path, points, counts, indices, left_handed=False):
    mesh = UsdGeom.Mesh.Define(stage, path)
    mesh.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(np.asarray(points, np.float32)))
    mesh.CreateFaceVertexCountsAttr(Vt.IntArray(list(counts)))
    if left_handed:  # the same surface, its faces listed the other way round
        indices = [i for k in range(len(counts)) for i in
                   reversed(indices[sum(counts[:k]):sum(counts[:k + 1])])]
        mesh.CreateOrientationAttr(UsdGeom.Tokens.leftHanded)
    mesh.CreateFaceVertexIndicesAttr(Vt.IntArray([int(i) for i in indices]))
    return mesh


def stage_of(meshes, parent_scale=None, parent_rotate=None):
    """An in-memory stage with ``meshes`` ``{name: (points, counts, indices[, left_handed])}`` under
    ``/World/Parent`` (scaled and rotated when asked)."""
    stage = Usd.Stage.CreateInMemory()
    stage.SetStartTimeCode(0)
    stage.SetEndTimeCode(0)
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    UsdGeom.Xform.Define(stage, "/World")
    parent = UsdGeom.Xform.Define(stage, "/World/Parent")
    if parent_rotate is not None:
        parent.AddRotateXYZOp().Set(Gf.Vec3f(*parent_rotate))
    if parent_scale is not None:
        parent.AddScaleOp().Set(Gf.Vec3f(*parent_scale))
    for name, m in meshes.items():
        add_mesh(stage, f"/World/Parent/{name}", *m)
    return stage


def verdict(stage, device):
    """``(findings, deepest depth)`` of a one-frame check."""
    report = check_usd(stage, device=device)
    pairs = report.pair_summary()
    return report.findings, max((p["max_depth"] for p in pairs), default=0.0)


TRANSFORMS = [(None, None), ((-1, 1, 1), None), ((1, 2, 0.5), None), ((-1, -1, 2), (0, 0, 30))]
"""Parent transforms: none, a mirror, a non-uniform scale, a mirrored stretch with a rotation."""


@pytest.mark.parametrize("n", range(1, 9))
def test_crate_in_a_floor_any_grid(device, n):
    for start in range(4):
        floor = grid_polygons(n, start=start)
        sunk = stage_of({"Floor": floor, "Crate": box_polygons([-0.5, -0.5, -0.5], [0.5, 0.5, 0.5], start)})
        findings, deepest = verdict(sunk, device)
        assert findings == "penetrating" and deepest == pytest.approx(0.5, rel=1e-5), start
        rest = stage_of({"Floor": floor, "Crate": box_polygons([-0.5, -0.5, 0.0], [0.5, 0.5, 1.0], start)})
        report = check_usd(rest, device=device)
        assert report.findings is None and report.touching, start
    rotated = grid_polygons(n, angle=0.4)
    findings, deepest = verdict(stage_of({"Floor": rotated, "Crate": box_polygons([-.5, -.5, -.5], [.5, .5, .5])}),
                                device)
    assert findings == "penetrating" and deepest == pytest.approx(0.5, rel=1e-5)


@pytest.mark.parametrize("scale,rotate", TRANSFORMS)
def test_verdicts_survive_mirrors_scales_and_winding(device, scale, rotate):
    """The same verdicts when the scene is mirrored, stretched, or its meshes are leftHanded."""
    # The open floor inside the crate, at its middle: half the crate's smallest side.
    stretch = 1.0 if scale is None else min(abs(x) for x in scale)
    for left in (False, True):
        floor = (*grid_polygons(3), left)
        sunk = (*box_polygons([-0.5, -0.5, -0.5], [0.5, 0.5, 0.5], 1), left)
        rest = (*box_polygons([-0.5, -0.5, 0.0], [0.5, 0.5, 1.0], 2), not left)
        findings, deepest = verdict(stage_of({"Floor": floor, "Crate": sunk}, scale, rotate), device)
        assert findings == "penetrating" and deepest == pytest.approx(0.5 * stretch, rel=1e-5)
        findings, _ = verdict(stage_of({"Floor": floor, "Crate": rest}, scale, rotate), device)
        assert findings is None
        # Boxes overlapping by a quarter with four faces flush, and side by side.
        a = (*box_polygons([0, 0, 0], [1, 1, 1]), left)
        findings, _ = verdict(stage_of({"A": a, "B": box_polygons([0.75, 0, 0], [1.75, 1, 1], 3)}, scale, rotate),
                              device)
        assert findings == "penetrating"
        findings, _ = verdict(stage_of({"A": a, "B": box_polygons([1, 0, 0], [2, 1, 1], 3)}, scale, rotate), device)
        assert findings is None


def test_real_asset_contacts_touch(device):
    # A battery resting in its holder: a U of three boxes, the battery on its floor, against its walls.
    holder = {"Base": box_polygons([0, 0, 0], [3, 1, 0.2]), "Left": box_polygons([0, 0, 0.2], [0.5, 1, 1]),
              "Right": box_polygons([2.5, 0, 0.2], [3, 1, 1])}
    battery = box_polygons([0.5, 0.1, 0.2], [2.5, 0.9, 0.9])
    report = check_usd(stage_of({**holder, "Battery": battery}), device=device)
    assert report.findings is None and report.touching
    # Two sub-meshes of one link meeting in a parting plane: open shells (the cut face left out),
    # and closed halves (the cut face in both).
    for skip in ((1,), ()):
        lower = box_polygons([0, 0, 0], [1, 1, 0.5], skip=skip)
        upper = box_polygons([0, 0, 0.5], [1, 1, 1], 1, skip=tuple(0 for _ in skip))
        report = check_usd(stage_of({"Lower": lower, "Upper": upper}), device=device)
        assert report.findings is None and report.touching, skip
    # A latch 1e-9 from its plug (touching within the tolerance), then sunk 1e-3 into it.
    plug = box_polygons([0, 0, 0], [1, 1, 1])
    report = check_usd(stage_of({"Plug": plug, "Latch": box_polygons([1 + 1e-9, 0.2, 0.2], [1.4, 0.6, 0.8])}),
                       device=device)
    assert report.findings is None
    findings, deepest = verdict(stage_of({"Plug": plug, "Latch": box_polygons([1 - 1e-3, .2, .2], [1.4, .6, .8])}),
                                device)
    assert findings == "penetrating" and deepest == pytest.approx(1e-3, rel=1e-3)


def test_cli_exit_status_of_the_sunk_crate(tmp_path, capsys):
    """The case that was reported: a 3 x 3 floor whose grid lines run along the crate's walls."""
    for z0, want in [(-0.5, 1), (0.0, 0)]:
        path = tmp_path / f"crate_{want}.usda"
        stage = stage_of({"Floor": grid_polygons(3), "Crate": box_polygons([-0.5, -0.5, z0], [0.5, 0.5, z0 + 1])})
        stage.GetRootLayer().Export(str(path))
        assert cli.main(["check", str(path)]) == want
        capsys.readouterr()
