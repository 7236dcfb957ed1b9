"""Profile: what one frame does on the device, activity by activity, and what a frame costs as a graph.

For each object count (``--objects``) of the scaling scene (``Scene.random``, polyhedra or
icospheres), after warm-up frames:

1. **Activities.** Ten frames of ``detect(advance=dt)`` launched eagerly, each recorded with
   ``wp.timing_begin(cuda_filter=wp.TIMING_ALL)``: every kernel, memset and copy with its device
   time (eagerly the device idles between launches, so each time is the activity alone, plus the
   few microseconds of its events). Per name: count per frame and the median of its ms over the
   frames; their total is the frame's device work. (CUB's sort and scan kernels are not listed.)
2. **Frames.** ``--frames`` frames of ``detect(advance=dt)`` in each mode (eager and, on CUDA, the
   replayed graph), wall-clock with a synchronisation before and after; min and median, and the
   host time of the frame (Python's time in ``detect()`` without the wait).

JSON (``--out``): device, date, versions, git commit, ``rows`` of ``{"n_objects", "triangles",
"mode", "ms_min", "ms_median", "host_ms_median"}`` and ``activities`` of ``{"n_objects", "triangles",
"name", "kind", "count", "ms"}``.

    python -m bench.profile_frame --device cuda:0 --objects 1000 10000 \\
        --out bench/results/profile_cuda0.json
"""

from __future__ import annotations

import sys

import numpy as np
import warp as wp

from warp_ccd import CollisionPipeline, Scene
from warp_ccd._src.bench.meshes import parse_triangles
from warp_ccd._src.runtime.frame import MODES

from .command import add_out_option, add_run_options, bench_parser, start, write_result
from .timing import detect_frames

DT = 1.0 / 60.0
KINDS = {wp.TIMING_KERNEL: "kernel", wp.TIMING_KERNEL_BUILTIN: "kernel (warp)", wp.TIMING_MEMCPY: "copy",
         wp.TIMING_MEMSET: "memset", wp.TIMING_GRAPH: "graph"}


def activities(pipe: CollisionPipeline | None, count: int = 10, run=None) -> list[dict]:
    """``count`` eager frames of ``pipe`` (or calls of ``run()``, eager work of another kind), activity
    by activity: ``{"name", "kind", "count", "ms"}`` per name, ``ms`` the median over the frames of its
    time in a frame, slowest first."""
    per_frame = []
    for _ in range(count):
        wp.timing_begin(cuda_filter=wp.TIMING_ALL)
        if run is None:
            pipe.detect(advance=DT)
        else:
            run()
        frame = {}
        for r in wp.timing_end():
            row = frame.setdefault(r.name, {"name": r.name, "kind": KINDS.get(r.filter, str(r.filter)), "count": 0,
                                            "ms": 0.0})
            row["count"] += 1
            row["ms"] += r.elapsed
        per_frame.append(frame)
    out = []
    for name, row in per_frame[0].items():
        times = [f[name]["ms"] for f in per_frame if name in f]
        out.append({**row, "ms": float(np.median(times))})
    return sorted(out, key=lambda r: -r["ms"])


def frames(pipe: CollisionPipeline, count: int) -> dict:
    """``count`` frames of ``detect(advance=dt)``: ms min and median, host ms median."""
    ms, host = detect_frames(pipe, count, DT)
    return {"ms_min": float(np.min(ms)), "ms_median": float(np.median(ms)), "host_ms_median": float(np.median(host))}


def main(argv: list[str] | None = None) -> int:
    parser = bench_parser(__doc__.splitlines()[0])
    parser.add_argument("--objects", type=lambda t: int(float(t)), nargs="+", default=[1000, 10000])
    parser.add_argument("--triangles", default="poly", help="'poly' or an icosphere's triangle count (80, 1280)")
    add_run_options(parser, frames=50, warmup=5, out=False)
    parser.add_argument("--option", action="append", default=[], metavar="NAME=INT",
                        help="a CollisionPipeline option with an integer value, e.g. cut_depth=2 (repeatable)")
    add_out_option(parser)
    args, device, doc = start(parser, argv)
    options = {}
    for item in args.option:
        name, _, value = item.partition("=")
        options[name] = int(value)
    label, shapes = parse_triangles(args.triangles)
    modes = MODES if device.is_cuda else ("eager",)
    doc["activities"] = []
    for n in args.objects:
        scene = Scene.random(n, seed=0, device=device, **({} if shapes is None else {"shapes": shapes}))
        pipes = {m: CollisionPipeline(scene, graph=m == "graph", **options) for m in modes}
        for pipe in pipes.values():
            for _ in range(args.warmup):
                pipe.detect(advance=DT)
        acts = activities(pipes["eager"])
        total = sum(a["ms"] for a in acts)
        print(f"== {n:,} objects, triangles {label}, {device} ({device.name}){' ' if options else ''}"
              f"{' '.join(args.option)}: an eager frame (medians of 10), "
              f"{sum(a['count'] for a in acts)} device activities, {total:.3f} ms of device work")
        for a in acts:
            print(f"  {a['ms']:8.4f} ms  x{a['count']:<3} {a['kind']:<14} {a['name']}")
            doc["activities"].append({"n_objects": n, "triangles": label, **a})
        for mode, pipe in pipes.items():
            row = {"n_objects": n, "triangles": label, "mode": mode, **frames(pipe, args.frames)}
            doc["rows"].append(row)
            print(f"  frame ({mode}): {row['ms_min']:.3f} ms min, {row['ms_median']:.3f} ms median, "
                  f"host {row['host_ms_median']:.4f} ms")
        write_result(args.out, doc)
    return 0


if __name__ == "__main__":
    sys.exit(main())
