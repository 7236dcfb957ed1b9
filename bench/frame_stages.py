"""A small scene's frame as a CUDA graph: what each stage adds, and what each small-scene path saves.

The frame of a few thousand objects is latency: each launch of a graph costs a few microseconds
however little it does. For each case (``--cases``, ``triangles:N`` of the scaling scene) and each
variant of the pipeline (``default``; ``trees``: no whole-object pairs, ``whole_triangles_max=0``;
``whole``: whole-object pairs at any size, ``whole_triangles_max=64``; ``lanes32``: 32 threads a
whole-object pair, ``whole_lanes=32``; ``sap``: the broad phase never tests all pairs,
``all_pairs_max=0``; ``before``: neither small-scene path, the frame as it was), after warm-up frames:

1. **Frames.** ``--frames`` calls of ``detect(advance=dt)`` (the scene's motion and detection, one
   graph), each timed with a synchronisation before and after: wall ms (min, median) and Python's
   host time; then as many back to back (a simulation loop).
2. **Device time by stage.** Graphs of the frame cut after each stage (counter reset, motion,
   refit, broad, mid, narrow, counter read; the motion by 0 s, so that every replay does the same
   work), each replayed ``--replays`` times back to back and timed as a whole: device ms per
   frame, medians of 5 such runs. The difference between two cuts is what that stage costs in
   the graph; ``launches`` counts the stage's kernels, copies and memsets (from an eager frame
   recorded with ``wp.timing_begin``; CUB's sort kernels are not listed).

JSON (``--out``): device, date, versions, git commit, ``rows`` of ``{"case", "triangles",
"n_objects", "variant", "measure", "ms_min", "ms_median", "launches"}``: ``measure`` is
``frame``, ``host``, ``loop`` or ``upto_<stage>``.

    python -m bench.frame_stages --device cuda:0 --cases poly:1000 poly:10000 \\
        --out bench/results/frame_stages_cuda0.json
"""

from __future__ import annotations

import sys
import time

import numpy as np
import warp as wp

from warp_ccd import CollisionPipeline, Scene
from warp_ccd._src.bench.meshes import parse_triangles

from .command import add_out_option, add_run_options, bench_parser, start, write_result
from .timing import detect_frames

DT = 1.0 / 60.0
STAGES = ("reset", "motion", "refit", "broad", "mid", "narrow", "read")
VARIANTS = {"default": {}, "trees": {"whole_triangles_max": 0}, "whole": {"whole_triangles_max": 64},
            "lanes32": {"whole_lanes": 32}, "sap": {"all_pairs_max": 0},
            "before": {"whole_triangles_max": 0, "all_pairs_max": 0}}


def make_pipeline(scene: Scene, variant: str) -> CollisionPipeline:
    """A graph pipeline of ``variant`` (:data:`VARIANTS`)."""
    pipe = CollisionPipeline(scene, graph=True)
    for name, value in VARIANTS[variant].items():
        stage = pipe.broad if name == "all_pairs_max" else pipe.mid
        if hasattr(stage, name):
            setattr(stage, name, value)
    return pipe


def enqueue_upto(pipe: CollisionPipeline, stage: str) -> None:
    """Enqueues the frame (motion by 0 s) up to and including ``stage``."""
    for name in STAGES[: STAGES.index(stage) + 1]:
        enqueue_one(pipe, name)


def replay_ms(graph, device, replays: int) -> list[float]:
    """Device ms per frame of ``graph`` replayed ``replays`` times back to back, five times."""
    out = []
    for _ in range(5):
        wp.synchronize_device(device)
        start = time.perf_counter()
        for _ in range(replays):
            wp.capture_launch(graph)
        wp.synchronize_device(device)
        out.append((time.perf_counter() - start) * 1e3 / replays)
    return out


def launches_by_stage(pipe: CollisionPipeline) -> dict:
    """Kernels, copies and memsets each stage enqueues (one eager frame, recorded)."""
    out = {}
    for stage in STAGES:
        wp.synchronize_device(pipe.device)
        wp.timing_begin(cuda_filter=wp.TIMING_ALL)
        enqueue_one(pipe, stage)
        wp.synchronize_device(pipe.device)
        out[stage] = len(wp.timing_end())
    return out


def enqueue_one(pipe: CollisionPipeline, stage: str) -> None:
    """Enqueues ``stage`` alone."""
    scene = pipe.scene
    if stage == "reset":
        pipe.counter_read.reset()
    elif stage == "motion":
        scene.enqueue_advance(0.0)
    elif stage == "refit":
        pipe.boxes.refit(scene)
    elif stage == "broad":
        pipe.broad.launch(pipe.boxes.lower, pipe.boxes.upper, pipe.pairs)
    elif stage == "mid":
        pipe.mid.launch(scene, pipe.pairs, reset_counters=False)
    elif stage == "narrow":
        pipe.narrow.launch(scene, pipe.mid.candidates, pipe.pairs, pipe.boxes.lower, pipe.boxes.upper,
                           reset_counters=False)
    else:
        pipe.counter_read.enqueue()


def measure_case(spec: str, variant: str, args, device) -> list[dict]:
    """Every row of one case and variant."""
    label, count = spec.split(":")
    name, shapes = parse_triangles(label)
    n = int(float(count))
    scene = Scene.random(n, seed=0, device=device, **({} if shapes is None else {"shapes": shapes}))
    pipe = make_pipeline(scene, variant)
    for _ in range(args.warmup):
        pipe.detect(advance=DT)
    base = {"case": spec, "triangles": name, "n_objects": n, "variant": variant}
    rows = []
    walls, hosts = detect_frames(pipe, args.frames, DT)
    wp.synchronize_device(device)
    start = time.perf_counter()
    for _ in range(args.frames):
        pipe.detect(advance=DT)
    loop = (time.perf_counter() - start) * 1e3 / args.frames
    for measure, values in (("frame", walls), ("host", hosts), ("loop", [loop])):
        rows.append({**base, "measure": measure, "ms_min": float(np.min(values)),
                     "ms_median": float(np.median(values)), "launches": None})
    counts = launches_by_stage(pipe)
    for stage in STAGES:
        with wp.ScopedCapture(device=device, force_module_load=False) as capture:
            enqueue_upto(pipe, stage)
        times = replay_ms(capture.graph, device, args.replays)
        rows.append({**base, "measure": f"upto_{stage}", "ms_min": float(np.min(times)),
                     "ms_median": float(np.median(times)), "launches": counts[stage]})
    pipe.detect(advance=0.0)  # counters as the stages left them, read
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = bench_parser(__doc__.splitlines()[0])
    parser.add_argument("--cases", nargs="+", default=["poly:1000", "poly:10000"], metavar="TRIANGLES:N")
    parser.add_argument("--variants", nargs="+", default=list(VARIANTS), choices=list(VARIANTS))
    add_run_options(parser, frames=50, warmup=5, out=False)
    parser.add_argument("--replays", type=int, default=200)
    add_out_option(parser)
    args, device, doc = start(parser, argv)
    if not device.is_cuda:
        print("frame_stages: graphs need a CUDA device; nothing measured")
        return 0
    for spec in args.cases:
        for variant in args.variants:
            rows = measure_case(spec, variant, args, device)
            doc["rows"].extend(rows)
            by = {r["measure"]: r for r in rows}
            cuts = "  ".join(f"{s} {by['upto_' + s]['ms_median']:.4f}({by['upto_' + s]['launches']})" for s in STAGES)
            print(f"{spec:>12} {variant:<13}: frame {by['frame']['ms_median']:.4f} "
                  f"(min {by['frame']['ms_min']:.4f}) host {by['host']['ms_median']:.4f} loop "
                  f"{by['loop']['ms_median']:.4f} | device up to: {cuts}", flush=True)
            write_result(args.out, doc)
    return 0


if __name__ == "__main__":
    sys.exit(main())
