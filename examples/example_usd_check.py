"""Example USD Check

Shows ``warp-ccd check`` on an animation a user might bring: it writes a small USD stage, checks
every frame for interpenetration with :func:`warp_ccd.usd.check_usd`, and prints the report.

The stage (``--stage-path``, a ``.usda`` you can open in usdview) holds:

* a floor of quads and a crate of quads resting on it (they touch in every frame: resting
  contact, which the check does not count as penetration);
* a robot arm: a base and two links of 6- and 8-sided prisms under nested, rotating ``Xform``s,
  whose second link swings down into the crate for a few frames;
* a wheel (an 8-sided prism, instanced twice through instanceable references) rolling along the
  floor, sunk 1-5 cm into it: penetrating, but shallow, so ``--min-depth 0.05`` forgives it;
* a cloth (a deforming quad grid, time-sampled points) sagging over a pole, 2 cm above its top
  until it drops through it in the last frames.

The check's summary lists the prim pairs that penetrate, with their first and last frames, and
the JSON report (``--report``) names prims by path and faces by their USD face index.

Exit status: 1, as the equivalent command's (``warp-ccd check STAGE``) is when something
penetrates: the arm and the wheels penetrate on purpose (0 when ``--min-depth`` forgives every
crossing, 2 on bad arguments). Without ``--stage-path`` the stage goes to a temporary folder that
is removed at the end.
"""

import argparse
import json
import os
import shutil
import tempfile

import numpy as np

from warp_ccd.usd import check_usd


def prism(sides: int, radius: float, height: float):
    """A closed prism of two ``sides``-gons and ``sides`` quads: ``(points, counts, indices)``."""
    a = 2 * np.pi * (np.arange(sides) + 0.5) / sides
    ring = np.stack([radius * np.cos(a), np.zeros(sides), radius * np.sin(a)], axis=1)
    points = np.concatenate([ring, ring + [0.0, height, 0.0]])
    counts = [sides, sides] + [4] * sides
    indices = list(range(sides - 1, -1, -1)) + list(range(sides, 2 * sides))
    for i in range(sides):
        j = (i + 1) % sides
        indices += [i, j, sides + j, sides + i]
    return points, counts, indices


def quad_grid(n: int, size: float):
    """A flat ``n x n`` quad grid in the y = 0 plane, centred: ``(points, counts, indices)``."""
    x = np.linspace(-size / 2, size / 2, n + 1)
    gx, gz = np.meshgrid(x, x, indexing="ij")
    points = np.stack([gx.ravel(), np.zeros(gx.size), gz.ravel()], axis=1)
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    quads = np.stack([idx[:-1, :-1], idx[:-1, 1:], idx[1:, 1:], idx[1:, :-1]], axis=-1).reshape(-1, 4)
    return points, [4] * len(quads), quads.ravel().tolist()


def write_animation(path: str, num_frames: int = 48) -> None:
    """Writes the stage described in the module docstring, time codes ``0 .. num_frames - 1`` at 24 fps."""
    from pxr import Gf, Sdf, Usd, UsdGeom, Vt

    stage = Usd.Stage.CreateInMemory()
    stage.SetStartTimeCode(0)
    stage.SetEndTimeCode(num_frames - 1)
    stage.SetTimeCodesPerSecond(24)
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    stage.SetDefaultPrim(UsdGeom.Xform.Define(stage, "/World").GetPrim())
    last = max(num_frames - 1, 1)

    def mesh(where: str, points, counts, indices):
        m = UsdGeom.Mesh.Define(stage, where)
        m.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(np.asarray(points, np.float32)))
        m.CreateFaceVertexCountsAttr(Vt.IntArray([int(c) for c in counts]))
        m.CreateFaceVertexIndicesAttr(Vt.IntArray([int(i) for i in indices]))
        return m

    mesh("/World/Floor", *quad_grid(8, 10.0))
    crate = mesh("/World/Crate", *prism(4, 0.8, 1.0))
    UsdGeom.Xformable(crate).AddTranslateOp().Set(Gf.Vec3d(2.0, 0.0, 0.0))

    # The arm: base, upper link, lower link, each under the previous one's rotation.
    arm = UsdGeom.Xform.Define(stage, "/World/Arm")
    arm.AddTranslateOp().Set(Gf.Vec3d(0.0, 0.0, 0.0))
    mesh("/World/Arm/Base", *prism(6, 0.4, 0.5))
    upper = UsdGeom.Xform.Define(stage, "/World/Arm/Upper")
    upper.AddTranslateOp().Set(Gf.Vec3d(0.0, 0.5, 0.0))
    swing = upper.AddRotateZOp()
    link = mesh("/World/Arm/Upper/Link", *prism(8, 0.15, 1.3))
    UsdGeom.Xformable(link).AddTranslateOp().Set(Gf.Vec3d(0.0, 0.2, 0.0))  # clear of the joint
    lower = UsdGeom.Xform.Define(stage, "/World/Arm/Upper/Lower")
    lower.AddTranslateOp().Set(Gf.Vec3d(0.0, 1.6, 0.0))
    bend = lower.AddRotateZOp()
    link = mesh("/World/Arm/Upper/Lower/Link", *prism(8, 0.12, 1.2))
    UsdGeom.Xformable(link).AddTranslateOp().Set(Gf.Vec3d(0.0, 0.2, 0.0))
    for f in range(num_frames):
        s = f / last
        swing.Set(float(-10.0 - 40.0 * s), f)  # leans towards the crate
        bend.Set(float(-20.0 - 90.0 * s), f)  # and folds down into it

    # The wheel: one prototype, two instanceable references rolling along z, 2 cm into the floor.
    UsdGeom.Xform.Define(stage, "/Prototypes/Wheel")
    stage.GetPrimAtPath("/Prototypes").SetSpecifier(Sdf.SpecifierClass)
    tyre = mesh("/Prototypes/Wheel/Tyre", *prism(8, 0.5, 0.3))
    tyre_xf = UsdGeom.Xformable(tyre)
    tyre_xf.AddRotateZOp().Set(90.0)  # axle along x
    tyre_xf.AddTranslateOp().Set(Gf.Vec3d(0.0, -0.15, 0.0))  # centred on it
    for name, x in (("WheelL", -3.0), ("WheelR", -1.8)):
        wheel = UsdGeom.Xform.Define(stage, f"/World/{name}")
        wheel.GetPrim().GetReferences().AddInternalReference("/Prototypes/Wheel")
        wheel.GetPrim().SetInstanceable(True)
        move = wheel.AddTranslateOp()
        roll = wheel.AddRotateXOp()
        for f in range(num_frames):
            z = -3.0 + 6.0 * f / last
            move.Set(Gf.Vec3d(x, 0.45, z), f)  # corners at radius 0.5: 1-5 cm below the floor
            roll.Set(float(np.degrees(z / 0.5)), f)

    # The cloth: a grid over a pole, sagging a little more each frame; it tears through in the end.
    pole = mesh("/World/Pole", *prism(6, 0.1, 1.28))
    UsdGeom.Xformable(pole).AddTranslateOp().Set(Gf.Vec3d(0.0, 0.0, 3.0))
    points, counts, indices = quad_grid(12, 2.0)
    cloth = mesh("/World/Cloth", points, counts, indices)
    UsdGeom.Xformable(cloth).AddTranslateOp().Set(Gf.Vec3d(0.0, 1.3, 3.0))
    attr = cloth.GetPointsAttr()
    r = np.hypot(points[:, 0], points[:, 2])
    for f in range(num_frames):
        sag = 0.25 * f / last
        p = points.copy()
        p[:, 1] = -sag * np.clip(r, 0.0, 1.0) ** 2 - (0.2 * sag if f > 0.8 * last else 0.0)
        attr.Set(Vt.Vec3fArray.FromNumpy(p.astype(np.float32)), f)
    stage.GetRootLayer().Export(path)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description="Write a USD animation, check it for interpenetration.")
    parser.add_argument("--device", default=None, help="Warp device (default: Warp's default)")
    parser.add_argument("--stage-path", default=None, help="where to write the stage (.usda); default: a temp folder")
    parser.add_argument("--num-frames", type=int, default=48)
    parser.add_argument("--min-depth", type=float, default=0.0, help="forgive crossings up to this depth")
    parser.add_argument("--report", default=None, help="also write the JSON report here")
    args = parser.parse_args(argv)

    folder = tempfile.mkdtemp(prefix="warp_ccd_check_") if args.stage_path is None else None
    try:
        path = args.stage_path or os.path.join(folder, "animation.usda")
        write_animation(path, args.num_frames)
        report = check_usd(path, device=args.device, min_depth=args.min_depth)
        print(report.summary())
        if args.report:
            report.write_json(args.report)
            with open(args.report) as fh:
                first = json.load(fh)["pairs"][:1]
            print(f"report: {args.report}; the pair penetrating longest: {first}")
    finally:
        if folder is not None:
            shutil.rmtree(folder, ignore_errors=True)
    if report.penetrating:
        print("exit status 1: penetrations found, as warp-ccd check reports them (the animation has them on "
              "purpose: the arm folds into the crate; the wheels roll 1-5 cm deep in the floor, unless "
              "--min-depth forgives that)")
        return 1
    print("exit status 0: nothing penetrates deeper than --min-depth")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
