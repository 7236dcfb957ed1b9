"""Benchmark: deforming meshes, whose trees are refit every frame, against Warp's built-in pipeline.

Scene: ``N`` icospheres (``--level``, 1,280 triangles at level 3) placed as ``Scene.random`` places
them, as a deforming scene (each object its own mesh). Every frame one kernel moves every world
vertex on the device from its rest position: each object breathes (scale ``1 + 0.1 sin``), wobbles
(a shear growing with height) and drifts on a small circle, so pairs come and go.

For each ``--leaf-sizes`` value, from the same start (the clock at 0), after ``--warmup`` frames,
``--frames`` frames of:

* ``frame``: the move, then ``detect()`` (on CUDA a captured graph), wall-clock with a
  synchronisation before and after;
* the stages of ``detect()`` with ``timings=True`` (``refit``, ``broad``, ``mid``, ``narrow``,
  ``total``; each synchronised);
* ``refit_kernels``: the refit alone (the deforming objects' trees and the object boxes), as a
  captured graph on CUDA (eagerly on the CPU), wall-clock;

and Warp's built-in pipeline (:class:`~warp_ccd._src.bench.peers.WarpMeshPipeline`: one ``wp.Mesh``
refit over all world vertices, a query per triangle, ``wp.intersect_tri_tri``), its frame
(``detect``: the faster of eager and graph) and its refit alone (``refit``). Every leaf size ends on
the same vertices and must find the same triangle pairs there (else the run stops); the peer's
triangle pairs on them are judged against ours as the scaling benchmark judges them
(:func:`~warp_ccd._src.bench.compare.compare_triangle_pairs`: pairs near touching may differ, and every
real difference is charged to the method an exact arbiter finds wrong).

    python -m bench.deforming --device cuda:0 --objects 1000 10000 \\
        --out bench/results/deforming_cuda0.json
"""

from __future__ import annotations

import sys

import numpy as np
import warp as wp

import warp_ccd as wc
from warp_ccd._src.bench.compare import compare_triangle_pairs
from warp_ccd._src.bench.methods import DevicePeerMethod
from warp_ccd._src.bench.peers import WarpMeshPipeline
from warp_ccd._src.bench.timing import synced_ms
from warp_ccd._src.pipeline.pipeline import STAGES

from .command import add_run_options, bench_parser, start, write_result
from .timing import ms_stats

DT = 1.0 / 60.0


@wp.kernel
def _deform_kernel(
    rest: wp.array[wp.vec3],
    vertex_object: wp.array[wp.int32],
    centre: wp.array[wp.vec3],
    phase: wp.array[wp.float32],
    t: float,
    # Outputs
    world_vertex: wp.array[wp.vec3],
):
    """One thread per vertex: breathing, a wobble and a drift of its object about its centre."""
    v = wp.tid()
    i = vertex_object[v]
    c = centre[i]
    p = rest[v] - c
    ph = phase[i]
    s = 1.0 + 0.1 * wp.sin(3.0 * t + ph)
    shear = 0.15 * wp.sin(2.0 * t + ph)
    drift = wp.vec3(0.3 * wp.cos(t + ph), 0.3 * wp.sin(t + ph), 0.0)
    world_vertex[v] = c + drift + wp.vec3(p[0] * s + shear * p[2], p[1] * s, p[2] * s)


def deforming_scene(n: int, level: int, seed: int, device) -> tuple:
    """``(scene, mover)``: the deforming scene and ``mover(t)``, which enqueues the move to time ``t``."""
    rigid = wc.Scene.random(n, seed=seed, shapes=(f"icosphere{level}",), device=device)
    rigid.advance(DT)
    world = rigid.world_vertex.numpy()
    _, tri = wc.scene.icosphere(level)
    per = len(world) // max(n, 1)
    meshes = [(world[k * per:(k + 1) * per], tri) for k in range(n)]
    scene = wc.Scene(meshes, np.arange(n), deforming=True, device=device)
    rest = wp.clone(scene.world_vertex)
    centre = wp.array(world.reshape(n, per, 3).mean(axis=1) if n else np.zeros((0, 3)), dtype=wp.vec3,
                      device=device)
    phase = wp.array(np.random.default_rng(seed).uniform(0, 2 * np.pi, n).astype(np.float32), device=device)

    def mover(t: float) -> None:
        wp.launch(_deform_kernel, dim=scene.num_world_vertices,
                  inputs=[rest, scene.vertex_object, centre, phase, float(t)], outputs=[scene.world_vertex],
                  device=device)

    return scene, mover



def run(n: int, args, device) -> list[dict]:
    """Rows for one object count: ours at each leaf size, then the built-in peer."""
    scene, mover = deforming_scene(n, args.level, args.seed, device)
    rows = []
    clock = [0.0]
    truth = None

    def move():
        clock[0] += DT
        mover(clock[0])

    for leaf in args.leaf_sizes:
        clock[0] = 0.0  # every leaf size sees the same frames
        pipe = wc.CollisionPipeline(scene, leaf_size=leaf)
        timed = wc.CollisionPipeline(scene, leaf_size=leaf, timings=True)
        frames, stages, refits = [], {s: [] for s in (*STAGES, "total")}, []
        refit_graph = None
        if device.is_cuda:
            with wp.ScopedCapture(device=device) as capture:
                pipe.boxes.refit(scene)
            refit_graph = capture.graph
        for k in range(args.warmup + args.frames):
            ms = synced_ms(lambda: (move(), pipe.detect()), device)
            res = pipe.detect()  # the same vertices again: a result to keep (the timed one is its twin)
            t = timed.detect().timings
            refit = (lambda: wp.capture_launch(refit_graph)) if refit_graph else (lambda: pipe.boxes.refit(scene))
            r = synced_ms(refit, device)
            if k >= args.warmup:
                frames.append(ms)
                refits.append(r)
                for s in stages:
                    stages[s].append(t[s])
        counts = {"object_pairs": len(res.object_pairs), "triangle_pairs": res.num_triangle_pairs,
                  "candidates": res.num_candidates}
        if truth is None:
            truth = res.triangle_pairs  # the last frame's vertices: the same for every leaf size, and the peer's
        elif not np.array_equal(res.triangle_pairs, truth):
            raise SystemExit(f"{n} objects, leaf {leaf}: other triangle pairs than leaf {args.leaf_sizes[0]}")
        base = {"method": "warp_ccd", "n_objects": n, "leaf_size": leaf, **counts}
        rows.append({**base, "stage": "frame", **ms_stats(frames)})
        rows.append({**base, "stage": "refit_kernels", **ms_stats(refits)})
        rows += [{**base, "stage": s, **ms_stats(v)} for s, v in stages.items()]
        print(f"{n:>8,} leaf {leaf}: frame {np.median(frames):8.3f} ms, refit {np.median(refits):7.3f} ms (graph), "
              + ", ".join(f"{s} {np.median(v):.3f}" for s, v in stages.items())
              + f"; {counts['object_pairs']} object pairs, {counts['candidates']:,} candidates", flush=True)
    peer = WarpMeshPipeline(scene)
    method = DevicePeerMethod(peer, device)
    detect, refit = [], []
    for k in range(args.warmup + args.frames):
        t = method.run()
        r = synced_ms(peer.refit, device)
        if k >= args.warmup:
            detect.append(min(v for key, v in t.items() if key.startswith("detect")))
            refit.append(r)
    pairs = method.triangle_pairs()
    check = compare_triangle_pairs(scene, "warp_ccd", truth, "warp_builtin", pairs)
    base = {"method": "warp_builtin", "n_objects": n, "leaf_size": None, "object_pairs": check.object_pairs[1],
            "triangle_pairs": len(pairs), "candidates": None, "check": check.to_dict()}
    rows.append({**base, "stage": "detect", **ms_stats(detect)})
    rows.append({**base, "stage": "refit", **ms_stats(refit)})
    print(f"{n:>8,} built-in: detect {np.median(detect):8.3f} ms, refit {np.median(refit):7.3f} ms (eager); "
          f"{check.summary()}", flush=True)
    return rows


def main(argv=None) -> int:
    parser = bench_parser(__doc__.splitlines()[0])
    parser.add_argument("--objects", type=lambda x: int(float(x)), nargs="+", default=[1000, 10000])
    parser.add_argument("--level", type=int, default=3, help="icosphere level (3: 1,280 triangles)")
    parser.add_argument("--leaf-sizes", type=int, nargs="+", default=[1, 2, 4, 8])
    add_run_options(parser, frames=10, warmup=3, seed=0, out_help="JSON file")
    args, device, document = start(parser, argv)
    for n in args.objects:
        document["rows"] += run(n, args, device)
        write_result(args.out, document)
    return 0


if __name__ == "__main__":
    sys.exit(main())
