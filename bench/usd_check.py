"""Benchmark: ``warp-ccd check`` on USD animations, where the time goes (read, build, per frame).

Two stages, written first (not timed as part of the check) into a temporary folder:

* **rigid**: ``--rigid`` prims (default 10,000), each an ``Xform`` with a time-sampled
  ``translate`` and ``orient`` at every frame and a static uniform ``scale``, over a ``Mesh`` of a
  polyhedron (4-20 faces, its own copy of the points: shapes are shared by content); the motion
  of :meth:`Scene.random <warp_ccd._src.scene.scene.Scene.random>` (inclined ellipses with spin).
* **deforming**: ``--deforming`` meshes (default 100) of 10,000 triangles (latitude-longitude
  spheres of 4,900 quads and 200 pole triangles), whose ``points`` are time-sampled at every
  frame (a wobble of the surface), each on an ellipse, dense enough that some overlap.

For each, :func:`~warp_ccd._src.check.check.check_usd` runs over ``--frames`` time codes and reports its
seconds: ``read`` (open, traverse, topology, every frame's transforms), ``build`` (scene,
trees, pipeline), ``set`` (moving the scene to each frame: poses, or reading and copying the
deforming points), ``detect`` (the pipeline's frames) and ``classify`` (depths, USD faces, the
report's rows); per frame in ms. On the rigid stage python-fcl (the same scene's meshes, one
``BVHModel`` each, its dynamic AABB tree, contacts on) runs every ``--fcl-every``-th frame as a
peer, timed (update + collide), with its object pairs compared with ours (touching included).

    python -m bench.usd_check --device cuda:0 --out bench/results/usd_check_cuda0.json
"""

from __future__ import annotations

import json
import os
import platform
import tempfile
import time

import numpy as np
import warp as wp

from warp_ccd import Scene, check_usd
from warp_ccd._src.bench.report import git_commit

from .command import add_out_option, add_run_options, bench_parser, parse_options, write_result


def _commit_label() -> str:
    """The commit measured (:func:`~warp_ccd._src.bench.report.git_commit`) as this file records it: the
    commit, ``-dirty`` when the tracked code was modified, or ``unknown``."""
    commit, dirty = git_commit()
    return "unknown" if commit is None else commit + ("-dirty" if dirty else "")


def write_rigid_prims(layer, scene: Scene, poses: np.ndarray, objects) -> None:
    """Writes objects of ``scene`` into an ``Sdf.Layer`` as the rigid stage's prims (``/World/obj_<i>``, an
    ``Xform`` with time-sampled ``translate`` and ``orient`` over its ``Mesh``), in one change block.

    Args:
        layer: the ``Sdf.Layer``.
        scene: the scene (shapes, scales).
        poses: ``(F, K, 7)`` poses of the objects at time codes ``0 .. F - 1``.
        objects: the ``K`` object indices written.
    """
    from pxr import Gf, Sdf, Vt

    frames = [float(f) for f in range(len(poses))]
    names = Vt.TokenArray(["xformOp:translate", "xformOp:orient", "xformOp:scale"])
    with Sdf.ChangeBlock():
        world = Sdf.CreatePrimInLayer(layer, "/World")
        world.specifier, world.typeName = Sdf.SpecifierDef, "Xform"
        for j, i in enumerate(objects):
            prim = Sdf.CreatePrimInLayer(layer, f"/World/obj_{i}")
            prim.specifier, prim.typeName = Sdf.SpecifierDef, "Xform"
            translate = Sdf.AttributeSpec(prim, "xformOp:translate", Sdf.ValueTypeNames.Double3)
            orient = Sdf.AttributeSpec(prim, "xformOp:orient", Sdf.ValueTypeNames.Quatf)
            s = float(scene.object_scale_np[i])
            Sdf.AttributeSpec(prim, "xformOp:scale", Sdf.ValueTypeNames.Float3).default = Gf.Vec3f(s, s, s)
            Sdf.AttributeSpec(prim, "xformOpOrder", Sdf.ValueTypeNames.TokenArray,
                              variability=Sdf.VariabilityUniform).default = names
            for f, (p, q) in enumerate(zip(poses[:, j, :3].tolist(), poses[:, j, 3:].tolist())):
                layer.SetTimeSample(translate.path, frames[f], Gf.Vec3d(*p))
                layer.SetTimeSample(orient.path, frames[f], Gf.Quatf(q[3], q[0], q[1], q[2]))
            v, t = scene.shape_meshes[scene.object_shape_np[i]]
            mesh = Sdf.CreatePrimInLayer(layer, f"/World/obj_{i}/Geom")
            mesh.specifier, mesh.typeName = Sdf.SpecifierDef, "Mesh"
            Sdf.AttributeSpec(mesh, "points", Sdf.ValueTypeNames.Point3fArray).default = \
                Vt.Vec3fArray.FromNumpy(np.asarray(v, np.float32))
            Sdf.AttributeSpec(mesh, "faceVertexCounts", Sdf.ValueTypeNames.IntArray).default = \
                Vt.IntArray.FromNumpy(np.full(len(t), 3, np.int32))
            Sdf.AttributeSpec(mesh, "faceVertexIndices", Sdf.ValueTypeNames.IntArray).default = \
                Vt.IntArray.FromNumpy(np.ascontiguousarray(t, np.int32).ravel())


def write_rigid_stage(path: str, num_objects: int, num_frames: int, seed: int = 0, device=None) -> None:
    """The rigid stage (see the module docstring), written with ``Sdf`` in one change block; the
    motion computed on ``device``."""
    from pxr import Sdf

    scene = Scene.random(num_objects, seed=seed, device=device)
    poses = np.empty((num_frames, num_objects, 7))
    for f in range(num_frames):
        poses[f] = scene.object_pose.numpy()
        scene.advance(1 / 24)
    layer = Sdf.Layer.CreateNew(path)
    write_rigid_prims(layer, scene, poses, range(num_objects))
    layer.startTimeCode, layer.endTimeCode = 0, num_frames - 1
    layer.defaultPrim = "World"
    layer.Save()


def lat_long_sphere(rings: int = 51, segments: int = 100):
    """A closed sphere of ``(rings - 1) * segments`` quads and ``2 * segments`` pole triangles
    (10,000 triangles for 51 x 100): ``(points (n, 3), counts, indices)``."""
    theta = np.pi * np.arange(1, rings) / rings  # rings - 1 latitude circles
    phi = 2 * np.pi * np.arange(segments) / segments
    st, ct = np.sin(theta)[:, None], np.cos(theta)[:, None]
    ring = np.stack([st * np.cos(phi), np.broadcast_to(ct, (rings - 1, segments)), st * np.sin(phi)], axis=-1)
    points = np.concatenate([[[0, 1, 0]], ring.reshape(-1, 3), [[0, -1, 0]]])
    idx = 1 + np.arange((rings - 1) * segments).reshape(rings - 1, segments)
    nxt = np.roll(idx, -1, axis=1)
    quads = np.stack([idx[:-1], nxt[:-1], nxt[1:], idx[1:]], axis=-1).reshape(-1, 4)
    top = np.stack([np.zeros(segments, np.int64), nxt[0], idx[0]], axis=1)
    bottom = np.stack([np.full(segments, len(points) - 1), idx[-1], nxt[-1]], axis=1)
    counts = np.concatenate([np.full(len(quads), 4), np.full(2 * segments, 3)])
    indices = np.concatenate([quads.ravel(), top.ravel(), bottom.ravel()])
    return points, counts, indices


def write_deforming_stage(path: str, num_meshes: int, num_frames: int, seed: int = 0) -> None:
    """The deforming stage (see the module docstring)."""
    from pxr import Usd, UsdGeom, Vt

    rng = np.random.default_rng(seed)
    base, counts, indices = lat_long_sphere()
    radius = rng.uniform(0.8, 1.2, num_meshes)
    side = ((4 / 3) * np.pi * np.sum(radius**3) / 0.1) ** (1 / 3)
    centre = rng.uniform(-side / 2, side / 2, (num_meshes, 3))
    axis_a, axis_b = rng.normal(size=(num_meshes, 3)), rng.normal(size=(num_meshes, 3))
    phase = rng.uniform(0, 2 * np.pi, num_meshes)
    stage = Usd.Stage.CreateNew(path)
    stage.SetStartTimeCode(0)
    stage.SetEndTimeCode(num_frames - 1)
    stage.SetDefaultPrim(UsdGeom.Xform.Define(stage, "/World").GetPrim())
    lon = np.arctan2(base[:, 2], base[:, 0])
    for i in range(num_meshes):
        mesh = UsdGeom.Mesh.Define(stage, f"/World/blob_{i}")
        mesh.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(counts.astype(np.int32)))
        mesh.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(indices.astype(np.int32)))
        points = mesh.CreatePointsAttr()
        for f in range(num_frames):
            t = f / 24.0
            wobble = 1.0 + 0.15 * np.sin(3 * lon + 2.0 * t + phase[i]) * np.sqrt(1 - base[:, 1] ** 2)
            move = centre[i] + 0.6 * radius[i] * (np.cos(t + phase[i]) * axis_a[i] + np.sin(t + phase[i]) * axis_b[i])
            p = base * (radius[i] * wobble)[:, None] + move
            points.Set(Vt.Vec3fArray.FromNumpy(p.astype(np.float32)), f)
    stage.GetRootLayer().Save()


def _fcl_peer(report, every: int) -> dict:
    """python-fcl on the checked scene at every ``every``-th frame; our pairs (touching included) beside it."""
    from warp_ccd import CollisionPipeline
    from warp_ccd._src.bench.peers import FclPipeline, PeerUnavailable

    imp = report.source
    try:
        fcl = FclPipeline(imp.scene)
    except PeerUnavailable as exc:
        return {"skipped": str(exc)}
    ours = CollisionPipeline(imp.scene)
    times, agree, frames = [], 0, 0
    for k in range(0, len(imp.times), every):
        imp.set_frame(k)
        mine = {tuple(p) for p in ours.detect().object_pairs.tolist()}
        t = time.perf_counter()
        while True:
            fcl.update()
            fcl.collide()
            if not fcl.finish():
                break
        times.append(time.perf_counter() - t)
        rows = fcl.triangle_pairs()
        theirs = {tuple(p) for p in rows[:, [0, 2]].tolist()} if len(rows) else set()
        agree += mine == theirs
        frames += 1
    return {"frames": frames, "ms_min": 1e3 * min(times), "ms_median": 1e3 * float(np.median(times)),
            "frames_with_equal_object_pairs": agree}


def run_case(kind: str, path: str, device, frames: int, fcl_every: int) -> dict:
    report = check_usd(path, device=device)
    s = report.seconds
    n = len(report.frames)
    row = {
        "case": kind,
        "objects": len(report.object_path),
        "triangles": int(report.source.scene.num_triangles),
        "frames": n,
        "read_s": s["read"],
        "build_s": s["build"],
        "set_ms_per_frame": 1e3 * s["set"] / n,
        "detect_ms_per_frame": 1e3 * s["detect"] / n,
        "classify_ms_per_frame": 1e3 * s["classify"] / n,
        "check_s": sum(s.values()),
        "frames_with_contacts": sum(1 for f in report.frames if len(f.triangle_pairs)),
        "penetrating_face_pairs": int(sum(len(f.triangle_pairs) for f in report.frames)),
    }
    if kind == "rigid" and fcl_every > 0:
        row["fcl"] = _fcl_peer(report, fcl_every)
    return row


def main(argv=None) -> int:
    parser = bench_parser(__doc__.splitlines()[0])
    add_run_options(parser, frames=240, out=False)
    parser.add_argument("--rigid", type=int, default=10000, help="rigid prims (0: skip)")
    parser.add_argument("--deforming", type=int, default=100, help="deforming meshes of 10k triangles (0: skip)")
    parser.add_argument("--fcl-every", type=int, default=10, help="python-fcl on every k-th frame (0: never)")
    add_out_option(parser)
    args, device = parse_options(parser, argv)
    result = {"benchmark": "usd_check", "device": str(device), "gpu": device.name if device.is_cuda else None,
              "cpu": platform.processor() or platform.machine(), "warp": wp.__version__, "commit": _commit_label(),
              "date": time.strftime("%Y-%m-%d"), "cases": []}
    with tempfile.TemporaryDirectory() as folder:
        # Compile and load every kernel once, outside the timed runs.
        warm = os.path.join(folder, "warm.usdc")
        write_rigid_stage(warm, 20, 2, device=device)
        check_usd(warm, device=device)
        for kind, count in (("rigid", args.rigid), ("deforming", args.deforming)):
            if count <= 0:
                continue
            path = os.path.join(folder, f"{kind}.usdc")
            t = time.perf_counter()
            if kind == "rigid":
                write_rigid_stage(path, count, args.frames, device=device)
            else:
                write_deforming_stage(path, count, args.frames)
            write_s = time.perf_counter() - t
            row = run_case(kind, path, device, args.frames, args.fcl_every)
            row["write_s"] = write_s
            row["file_mb"] = os.path.getsize(path) / 1e6
            result["cases"].append(row)
            print(json.dumps(row), flush=True)
    write_result(args.out, result)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
