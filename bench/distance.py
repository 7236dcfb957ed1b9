"""Benchmark: the least distance between two big meshes, against python-fcl with its builds.

For each size of ``--triangles``, two lumpy closed surfaces of that many triangles each (seeded
blobs of :mod:`warp_ccd._src.bench.meshes`, radius 1) are placed ``--gap`` apart (the gap between their
bounding spheres; several gaps, each a row), both rigid in their world positions. Measured, each
with ``--warmup`` untimed runs first, min and median of ``--frames`` runs:

* ``query``: :meth:`~warp_ccd._src.queries.distance.DistanceQuery.query` with the trees built (on CUDA one replayed
  graph), synchronised; the persistent form, as a user asks again after moving the objects;
* ``one_shot``: :func:`~warp_ccd._src.queries.distance.distance` from numpy meshes: scene, validation, tree builds,
  query; ``one_shot_phases_ms`` splits it: the scene, the query's set-up (trees, buffers), its first
  query (eager), each synchronised;
* ``fcl_query``: python-fcl's ``fcl.distance`` (nearest points) on its two BVH models (OBBRSS),
  built before; ``fcl_build``: building the two models (``BVHModel``, ``beginModel`` ..
  ``endModel``); ``fcl_one_shot`` = build + query.

Each row also gives the two distances and their difference (the same pair of meshes), and the ratios
``fcl_query / query`` and ``fcl_one_shot / one_shot``; with ``--profile`` (CUDA), an eager query's
kernels, GPU ms each (``wp.timing``), and their sum.

    python -m bench.distance --device cuda:0 --triangles 1e4 1e5 --gap 0.5 0.01 \\
        --out bench/results/distance_cuda0.json
"""

from __future__ import annotations

import gc
import sys
import time

import numpy as np

import warp_ccd as wc
from warp_ccd._src.bench.meshes import _blob
from warp_ccd._src.bench.peers import fcl_bvh
from warp_ccd._src.bench.timing import synced_ms

from .command import add_run_options, bench_parser, start, write_result
from .profile_frame import activities


def blob_pair(triangles: int, gap: float, seed: int) -> list:
    """Two seeded blobs of about ``triangles`` triangles each, radius 1, their bounding spheres
    ``gap`` apart along a tilted axis (float64 vertices, int32 triangles)."""
    n = max(4, int(round((triangles / 2.0) ** 0.5)))
    meshes = []
    axis = np.array([1.0, 0.35, -0.2])
    axis /= np.linalg.norm(axis)
    for k in range(2):
        v, t = _blob(n + 1, n, seed=seed + k, bumps=16, amplitude=0.3, stretch=(1.0, 0.8, 0.9))
        v = v / np.linalg.norm(v, axis=1).max()
        meshes.append((v + axis * k * (2.0 + gap), np.ascontiguousarray(t, np.int32)))
    return meshes


def _fcl_models(meshes):
    import fcl

    return [fcl.CollisionObject(fcl_bvh(v, t), fcl.Transform()) for v, t in meshes]


def _fcl_distance(objs) -> float:
    import fcl

    return fcl.distance(objs[0], objs[1], fcl.DistanceRequest(enable_nearest_points=True), fcl.DistanceResult())


def _stats(prefix: str, values) -> dict:
    return {f"{prefix}_ms_min": float(np.min(values)), f"{prefix}_ms_median": float(np.median(values))}


def run(triangles: int, gap: float, args, device) -> dict:
    meshes = blob_pair(triangles, gap, args.seed)
    row = {"triangles_each": int(len(meshes[0][1])), "gap": gap}
    scene = wc.Scene.from_meshes(meshes, device=device, precision=args.precision)
    query = wc.DistanceQuery(scene, [[0, 1]])
    for _ in range(args.warmup):
        query.query()
    times = [synced_ms(query.query, device) for _ in range(args.frames)]
    res = query.query()
    row.update(_stats("query", times), distance=float(res.distance[0]), query_runs=res.runs,
               front_capacity=query.stage.front.capacity, listed=query.stage.listed.last_count)
    one = []
    for k in range(args.warmup + max(3, args.frames // 4)):
        ms = synced_ms(lambda: wc.distance(meshes[0], meshes[1], device=device, precision=args.precision), device)
        if k >= args.warmup:
            one.append(ms)
    row.update(_stats("one_shot", one))
    # Where a one-shot call's time goes: the scene (validation, precision check, upload), the query's
    # set-up (the trees built, buffers), the first query (eager); each synchronised, medians of 3.
    phases = {"scene": [], "setup": [], "query": []}
    for _ in range(3):
        made = {}
        phases["scene"].append(synced_ms(lambda: made.setdefault("scene", wc.Scene.from_meshes(
            meshes, device=device, precision=args.precision)), device))
        phases["setup"].append(synced_ms(lambda: made.setdefault("query", wc.DistanceQuery(made["scene"], [[0, 1]])),
                                         device))
        phases["query"].append(synced_ms(made["query"].query, device))
    row["one_shot_phases_ms"] = {k: float(np.median(v)) for k, v in phases.items()}
    if args.profile and device.is_cuda:  # one eager query kernel by kernel
        eager = wc.DistanceQuery(scene, [[0, 1]], graph=False)
        eager.query()
        acts = activities(None, 5, run=eager.query)
        row["query_activities"] = acts[:10]
        row["query_kernels_ms"] = float(sum(a["ms"] for a in acts))
    if not args.no_fcl:
        try:
            builds, queries = [], []
            for _ in range(max(2, args.frames // 4)):
                t = time.perf_counter()
                objs = _fcl_models(meshes)
                builds.append((time.perf_counter() - t) * 1e3)
            for _ in range(max(3, args.frames // 2)):
                t = time.perf_counter()
                d = _fcl_distance(objs)
                queries.append((time.perf_counter() - t) * 1e3)
            row.update(_stats("fcl_build", builds), **_stats("fcl_query", queries), fcl_distance=float(d),
                       difference=float(row["distance"] - d))
            row["fcl_one_shot_ms_median"] = row["fcl_build_ms_median"] + row["fcl_query_ms_median"]
            row["speedup_query"] = row["fcl_query_ms_median"] / row["query_ms_median"]
            row["speedup_one_shot"] = row["fcl_one_shot_ms_median"] / row["one_shot_ms_median"]
        except ImportError:
            row["fcl"] = "python-fcl is not installed"
    text = (f"{row['triangles_each']:>9,} triangles each, gap {gap:g}: query {row['query_ms_median']:.3f} ms, "
            f"one-shot {row['one_shot_ms_median']:.2f} ms, distance {row['distance']:.6g}")
    if "fcl_query_ms_median" in row:
        text += (f"; fcl query {row['fcl_query_ms_median']:.2f} ms ({row['speedup_query']:.0f}x), build + query "
                 f"{row['fcl_one_shot_ms_median']:.1f} ms ({row['speedup_one_shot']:.1f}x), "
                 f"difference {row['difference']:.2e}")
    print(text, flush=True)
    return row


def main(argv=None) -> int:
    parser = bench_parser(__doc__.splitlines()[0])
    parser.add_argument("--triangles", type=lambda x: int(float(x)), nargs="+", default=[10_000, 100_000])
    parser.add_argument("--gap", type=float, nargs="+", default=[0.5, 0.01],
                        help="gaps between the two meshes' bounding spheres (radius 1)")
    parser.add_argument("--precision", choices=("float32", "float64"), default="float32")
    parser.add_argument("--no-fcl", action="store_true", help="leave python-fcl out")
    parser.add_argument("--profile", action="store_true", help="one eager query kernel by kernel (CUDA)")
    add_run_options(parser, frames=20, warmup=3, seed=0, out_help="JSON file (default: none)")
    args, device, document = start(parser, argv)
    for n in args.triangles:
        for gap in args.gap:
            document["rows"].append(run(n, gap, args, device))
            gc.collect()
            write_result(args.out, document)
    if args.out:
        print(f"results written to {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
