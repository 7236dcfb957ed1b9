"""Benchmark: ``warp-ccd check`` in one process and on Ray (``check_many``), one GPU and several.

Stages, written first into a temporary folder (not timed as part of a check), each of rigid prims as
:mod:`bench.usd_check` writes them (an ``Xform`` with time-sampled ``translate`` and ``orient`` over a
polyhedron ``Mesh``, the motion of :meth:`Scene.random <warp_ccd._src.scene.scene.Scene.random>`):

* **rigid**: ``--objects`` prims x ``--frames`` time codes in one layer: the whole check in one process on one
  GPU (reading included), the target of "10,000 x 240 in 3 s".
* **long**: ``--objects`` prims x ``--long-frames`` time codes, their animation in ``--layers`` sublayers (a share
  of the prims each, written in parallel): one process on one GPU, then Ray with 1 worker and with 2 (one GPU
  each where the machine has two, else two sharing one GPU, said so in the result); the time codes cut into
  ranges (one or more per worker).
* **batch**: ``--batch`` stages of ``--batch-objects`` x ``--batch-frames``: one process, file after file, then Ray
  with 1 and 2 workers, a whole file per task.

Each Ray result is compared with the one-process result: the same frames, rows, depths and pair summaries
(``identical``). Times are wall clock of the whole call, the Ray cluster already started (its actors' start,
Warp's initialisation and kernel loads included).

    python -m bench.distributed --device cuda:0 --out bench/results/distributed_cuda0.json
"""

from __future__ import annotations

import json
import multiprocessing
import os
import platform
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor

import numpy as np
import warp as wp

from .command import add_out_option, bench_parser, parse_options, write_result
from .usd_check import _commit_label, write_rigid_prims, write_rigid_stage


def write_part(task) -> None:
    """One sublayer of the long stage: prims ``lo..hi`` of ``num_objects`` (the motion of all, these kept)."""
    path, num_objects, num_frames, lo, hi, seed, device = task
    from pxr import Sdf

    from warp_ccd import Scene

    scene = Scene.random(num_objects, seed=seed, device=device)
    poses = np.empty((num_frames, hi - lo, 7))
    for f in range(num_frames):
        poses[f] = scene.object_pose.numpy()[lo:hi]
        scene.advance(1 / 24)
    layer = Sdf.Layer.CreateNew(path)
    write_rigid_prims(layer, scene, poses, range(lo, hi))
    layer.Save()


def write_layered_stage(path: str, num_objects: int, num_frames: int, layers: int, pool: ProcessPoolExecutor,
                        seed: int = 0, device: str = "cpu") -> None:
    """A root layer over ``layers`` sublayers written in parallel, each holding a share of the prims."""
    from pxr import Sdf

    cuts = np.linspace(0, num_objects, layers + 1).round().astype(int)
    stem = os.path.splitext(path)[0]
    parts = [(f"{stem}_part{k}.usdc", num_objects, num_frames, int(cuts[k]), int(cuts[k + 1]), seed, device)
             for k in range(layers) if cuts[k + 1] > cuts[k]]
    list(pool.map(write_part, parts))
    root = Sdf.Layer.CreateNew(path)
    root.subLayerPaths = [os.path.basename(p[0]) for p in parts]
    root.startTimeCode, root.endTimeCode = 0, num_frames - 1
    root.defaultPrim = "World"
    root.Save()


def _write_small(task) -> None:
    path, n, frames, seed, device = task
    write_rigid_stage(path, n, frames, seed=seed, device=device)


def same_results(a, b) -> bool:
    """Whether two reports found the same: objects, time codes, rows, depths, touching counts, pair summaries."""
    if a is None or b is None or a.object_path != b.object_path or len(a.frames) != len(b.frames):
        return False
    for f, g in zip(a.frames, b.frames):
        if f.time != g.time or f.num_touching != g.num_touching or not np.array_equal(f.triangle_pairs,
                                                                                       g.triangle_pairs):
            return False
        if not np.array_equal(f.depth, g.depth):
            return False
    return a.pair_summary() == b.pair_summary()


def _timed(fn, *args, **kwargs):
    t = time.perf_counter()
    out = fn(*args, **kwargs)
    return out, time.perf_counter() - t


def main(argv=None) -> int:
    parser = bench_parser(__doc__.splitlines()[0])
    parser.add_argument("--objects", type=int, default=10000, help="rigid prims of the rigid and long stages")
    parser.add_argument("--frames", type=int, default=240, help="time codes of the rigid stage")
    parser.add_argument("--long-frames", type=int, default=2400, help="time codes of the long stage (0: skip)")
    parser.add_argument("--layers", type=int, default=16, help="sublayers of the long stage, written in parallel")
    parser.add_argument("--batch", type=int, default=100, help="stages of the batch (0: skip)")
    parser.add_argument("--batch-objects", type=int, default=500, help="rigid prims of each batch stage")
    parser.add_argument("--batch-frames", type=int, default=48, help="time codes of each batch stage")
    parser.add_argument("--parts", default="rigid,long,batch", help="which parts to run")
    add_out_option(parser)
    args, device = parse_options(parser, argv)
    from warp_ccd import check_usd
    from warp_ccd._src.check.batch import check_many

    gpus = wp.get_cuda_device_count() if device.is_cuda else 0
    result = {"benchmark": "distributed", "device": str(device), "gpu": device.name if device.is_cuda else None,
              "gpus": gpus, "cpus": os.cpu_count(), "cpu": platform.processor() or platform.machine(),
              "warp": wp.__version__, "commit": _commit_label(), "date": time.strftime("%Y-%m-%d"), "cases": []}
    parts = set(args.parts.split(","))

    def record(row: dict) -> None:
        result["cases"].append(row)
        print(json.dumps(row), flush=True)
        write_result(args.out, result)

    with tempfile.TemporaryDirectory() as folder, ProcessPoolExecutor(
            max(1, min(32, os.cpu_count() or 1)), mp_context=multiprocessing.get_context("spawn")) as pool:
        warm = os.path.join(folder, "warm.usdc")
        write_rigid_stage(warm, 20, 2, device=device)
        check_usd(warm, device=device)  # compile and load every kernel once
        if "rigid" in parts:
            path = os.path.join(folder, "rigid.usdc")
            _, write_s = _timed(write_rigid_stage, path, args.objects, args.frames, device=device)
            for workers in (None, 0):
                runs = [_timed(check_usd, path, device=device, read_workers=workers) for _ in range(2)]
                report, wall = min(runs, key=lambda r: r[1])
                record({"case": "rigid", "objects": args.objects, "frames": args.frames, "read_workers": workers,
                        "wall_s": wall, "wall_s_runs": [r[1] for r in runs], "seconds": report.seconds,
                        "write_s": write_s, "face_pairs": int(sum(len(f.triangle_pairs) for f in report.frames))})
                del runs, report
        ray_ready = False
        if args.long_frames > 0 and "long" in parts or args.batch > 0 and "batch" in parts:
            try:
                import ray

                ray.init(num_gpus=gpus, include_dashboard=False, log_to_driver=False, logging_level="ERROR")
                ray_ready = True
            except ImportError:
                result["ray"] = "not installed"
        shared = gpus < 2
        if args.long_frames > 0 and "long" in parts:
            path = os.path.join(folder, "long.usda")
            _, write_s = _timed(write_layered_stage, path, args.objects, args.long_frames, args.layers, pool,
                                     device=str(device))
            serial, wall = _timed(check_usd, path, device=device)
            row = {"case": "long", "objects": args.objects, "frames": args.long_frames, "layers": args.layers,
                   "write_s": write_s, "one_process_s": wall, "one_process_seconds": serial.seconds}
            serial.source = None
            for workers in (1, 2) if ray_ready else ():
                batch, wall = _timed(check_many, [path], ray=True, workers=workers)
                f = batch.files[0]
                row[f"ray{workers}"] = {"wall_s": wall, "tasks": f.tasks, "error": f.error,
                                        "identical": same_results(serial, f.report),
                                        "gpus_shared": shared and workers > 1}
                del batch, f
            if ray_ready:
                row["speedup_2_over_1"] = row["ray1"]["wall_s"] / row["ray2"]["wall_s"]
            record(row)
            del serial
        if args.batch > 0 and "batch" in parts:
            paths = [os.path.join(folder, f"batch_{k}.usdc") for k in range(args.batch)]
            jobs = [(p, args.batch_objects, args.batch_frames, k, str(device)) for k, p in enumerate(paths)]
            _, write_s = _timed(lambda: list(pool.map(_write_small, jobs)))
            serial, wall = _timed(check_many, paths, device=device)
            row = {"case": "batch", "stages": args.batch, "objects": args.batch_objects, "frames": args.batch_frames,
                   "write_s": write_s, "one_process_s": wall}
            for workers in (1, 2) if ray_ready else ():
                batch, wall = _timed(check_many, paths, ray=True, workers=workers)
                same = all(same_results(a.report, b.report) for a, b in zip(serial.files, batch.files))
                row[f"ray{workers}"] = {"wall_s": wall, "identical": same, "gpus_shared": shared and workers > 1,
                                        "failed": sum(f.report is None for f in batch.files)}
            if ray_ready:
                row["speedup_2_over_1"] = row["ray1"]["wall_s"] / row["ray2"]["wall_s"]
            record(row)
    write_result(args.out, result)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
