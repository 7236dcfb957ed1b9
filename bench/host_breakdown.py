"""Where the host time of a graph frame goes: Python before the launch, the launch call, the wait,
Python after it.

For each object count (``--objects``) and triangle spec (``--triangles``) of the scaling scene,
after three warm-up frames, ``--frames`` frames of ``detect(advance=dt)`` replayed as one graph,
back to back, measured twice in a row (variants ``plain`` and ``again``). ``wp.capture_launch``
and ``wp.synchronize_device`` are wrapped with timestamps, so each frame splits into ``pre``
(``detect()`` up to the launch), ``launch`` (the call), ``between`` (launch to wait), ``wait`` and
``post`` (after the wait: the counters read, the result made), in ms; ``host`` is the frame's
:attr:`~warp_ccd._src.pipeline.pipeline.CollisionResult.host_ms`. Medians and minima per variant.

JSON (``--out``): device, date, versions, git commit, ``config`` and ``rows`` of ``{"n", "shapes",
"variant", "build_s", "median": {...}, "min": {...}}``.

    python -m bench.host_breakdown --device cuda:0 --objects 1e6 --triangles poly 80 \\
        --out bench/results/host_breakdown_cuda0.json
"""

from __future__ import annotations

import sys
import time

import numpy as np
import warp as wp

from warp_ccd import CollisionPipeline, Scene
from warp_ccd._src.bench.meshes import parse_triangles

from .command import add_row, add_run_options, bench_parser, start, write_result

DT = 1.0 / 60.0
VARIANTS = ("plain", "again")
"""The same frames measured twice in a row (the second tells how much the host itself moves)."""


def frames(pipe: CollisionPipeline, device, count: int) -> list[dict]:
    """``count`` graph frames, each split at the launch and the wait (ms)."""
    marks = {}
    launch, sync = wp.capture_launch, wp.synchronize_device

    def timed_launch(*a, **k):
        marks["l0"] = time.perf_counter()
        launch(*a, **k)
        marks["l1"] = time.perf_counter()

    def timed_sync(*a, **k):
        marks["s0"] = time.perf_counter()
        sync(*a, **k)
        marks["s1"] = time.perf_counter()

    rows = []
    for _ in range(count):
        sync(device)
        wp.capture_launch, wp.synchronize_device = timed_launch, timed_sync
        try:
            start = time.perf_counter()
            result = pipe.detect(advance=DT)
            end = time.perf_counter()
        finally:
            wp.capture_launch, wp.synchronize_device = launch, sync
        rows.append({"pre": (marks.get("l0", start) - start) * 1e3,
                     "launch": (marks.get("l1", 0) - marks.get("l0", 0)) * 1e3,
                     "between": (marks["s0"] - marks.get("l1", marks["s0"])) * 1e3,
                     "wait": (marks["s1"] - marks["s0"]) * 1e3, "post": (end - marks["s1"]) * 1e3,
                     "host": result.host_ms})
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = bench_parser(__doc__.splitlines()[0])
    parser.add_argument("--objects", type=lambda t: int(float(t)), nargs="+", default=[1000000])
    parser.add_argument("--triangles", nargs="+", default=["poly", "80"])
    add_run_options(parser, frames=20)
    args, device, doc = start(parser, argv)
    for spec in args.triangles:
        _, shapes = parse_triangles(spec)
        for n in args.objects:
            t0 = time.perf_counter()
            scene = Scene.random(n, seed=0, device=device, **({} if shapes is None else {"shapes": shapes}))
            pipe = CollisionPipeline(scene)
            for _ in range(3):
                pipe.detect(advance=DT)
            build = time.perf_counter() - t0
            for variant in VARIANTS:
                rows = frames(pipe, device, args.frames)
                row = {"n": n, "shapes": shapes, "variant": variant, "build_s": round(build, 1),
                       "median": {k: round(float(np.median([r[k] for r in rows])), 4) for k in rows[0]},
                       "min": {k: round(float(np.min([r[k] for r in rows])), 4) for k in rows[0]}}
                add_row(doc, row)
            write_result(args.out, doc)
    return 0


if __name__ == "__main__":
    sys.exit(main())
