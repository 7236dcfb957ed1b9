"""Benchmark: the clearance frame against the discrete frame of the same scene.

For each ``N`` of ``--objects`` and each distance of ``--clearance``, on the scaling scene
``Scene.random(N, --seed)`` (polyhedra of radius 0.5 to 1.5), a discrete
:class:`~warp_ccd._src.pipeline.pipeline.CollisionPipeline` and one with ``clearance=d`` share the scene. Each frame:

* ``discrete``: ``detect(advance=dt)``: the scene moves by 1/60 s and the discrete pipeline detects
  (on CUDA one replayed graph, motion included);
* ``clearance``: ``detect()`` on the same vertices: every object pair within ``d``, its least
  distance, closest points, direction (on CUDA one replayed graph).

Each is timed wall-clock with ``wp.synchronize_device`` before and after; ``--warmup`` frames, then
``--frames`` timed ones; rows give min and median ms per frame, the ratio clearance / discrete
(medians), object pairs per frame (the discrete frame's intersecting ones, the clearance frame's
within ``d``), candidates of the last frame, and ``mismatches``: frames where the clearance frame's
intersecting pairs differ from the discrete frame's (none expected). With ``--profile`` each
clearance row also holds one eager frame stage by stage (``timings=True``, median of 5 frames).

    python -m bench.clearance --device cuda:0 --objects 1e3 1e4 1e5 1e6 --clearance 0.05 0.2 \\
        --profile --out bench/results/clearance_cuda0.json
"""

from __future__ import annotations

import gc
import sys

import numpy as np
import warp as wp

import warp_ccd as wc
from warp_ccd._src.bench.timing import synced_ms

from .command import add_run_options, bench_parser, start, write_result
from .timing import ms_stats

DT = 1.0 / 60.0



def _profile(scene, d: float, frames: int = 5) -> dict:
    """Median ms per stage of eager frames of a clearance pipeline timed stage by stage."""
    pipe = wc.CollisionPipeline(scene, clearance=d, timings=True)
    pipe.detect()
    stages: dict[str, list] = {}
    for _ in range(frames):
        for name, ms in pipe.detect().timings.items():
            stages.setdefault(name, []).append(ms)
    return {name: float(np.median(v)) for name, v in stages.items()}


def run(n: int, clearances: list[float], args, device) -> list[dict]:
    """Rows for one object count: the discrete frame, then a clearance frame for each distance."""
    scene = wc.Scene.random(n, seed=args.seed, device=device)
    discrete = wc.CollisionPipeline(scene)
    near = {d: wc.CollisionPipeline(scene, clearance=d) for d in clearances}
    times = {key: [] for key in ("discrete", *clearances)}
    pairs = {key: [] for key in times}
    mismatches = dict.fromkeys(clearances, 0)
    last = {}
    for k in range(args.warmup + args.frames):
        out = {}
        ms = {"discrete": synced_ms(lambda: out.setdefault("discrete", discrete.detect(advance=DT)), device)}
        for d, pipe in near.items():
            ms[d] = synced_ms(lambda pipe=pipe, d=d: out.setdefault(d, pipe.detect()), device)
            if not np.array_equal(out[d].intersecting_pairs, out["discrete"].object_pairs):
                mismatches[d] += 1
        if k >= args.warmup:
            for key, res in out.items():
                times[key].append(ms[key])
                pairs[key].append(len(res.object_pairs))
                last[key] = res
    base = {"n_objects": n, "triangles": scene.num_triangles, "graph": discrete.graph}
    rows = [{**base, "method": "discrete", "frames": args.frames, **ms_stats(times["discrete"]),
             "object_pairs_per_frame": float(np.mean(pairs["discrete"])),
             "candidates_last": last["discrete"].num_candidates}]
    text = f"{n:>9,} objects: discrete {rows[0]['ms_median']:8.3f} ms ({rows[0]['object_pairs_per_frame']:.1f} pairs)"
    for d in clearances:
        row = {**base, "method": "clearance", "clearance": d, "frames": args.frames, **ms_stats(times[d]),
               "ratio_median": float(np.median(times[d]) / np.median(times["discrete"])),
               "object_pairs_per_frame": float(np.mean(pairs[d])),
               "intersecting_last": int(last[d].object_intersecting.sum()),
               "candidates_last": last[d].num_candidates, "broad_pairs_last": last[d].num_broad_pairs,
               "mismatches": mismatches[d]}
        if args.profile:
            row["stages_ms"] = _profile(scene, d)
        rows.append(row)
        text += (f"; d={d:g}: {row['ms_median']:8.3f} ms, {row['ratio_median']:.2f}x "
                 f"({row['object_pairs_per_frame']:.1f} pairs within, {row['candidates_last']} candidates)")
    print(text, flush=True)
    return rows


def main(argv=None) -> int:
    parser = bench_parser(__doc__.splitlines()[0])
    parser.add_argument("--objects", type=lambda x: int(float(x)), nargs="+",
                        default=[1000, 10_000, 100_000, 1_000_000])
    parser.add_argument("--clearance", type=float, nargs="+", default=[0.05, 0.2],
                        help="distances, scene units (object radii are 0.5 to 1.5)")
    parser.add_argument("--profile", action="store_true", help="one eager frame per row, stage by stage")
    add_run_options(parser, frames=20, warmup=3, seed=0, out_help="JSON file (default: none)")
    args, device, document = start(parser, argv)
    for n in args.objects:
        document["rows"] += run(n, args.clearance, args, device)
        gc.collect()
        if device.is_cuda:
            wp.synchronize_device(device)
        write_result(args.out, document)
    if args.out:
        print(f"results written to {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
