"""Benchmark: the traversal's options on the scaling scenes: its box test (3 or 6 separating axes),
the rigid objects' boxes for the broad phase (from world vertices, from the tree, or by size), the
leaf size and the traversal's threads per multiprocessor.

For each scene (``--cases`` of ``TRIANGLES:N``, a ``--triangles`` spec of the scaling benchmark and
an object count), for each ``--max-registers`` (the heavy kernels compiled with at most that many
registers a thread), each combination of ``--axes``, ``--bounds``, ``--leaf-sizes`` and
``--threads-per-sm`` (:class:`~warp_ccd._src.pipeline.pipeline.CollisionPipeline` options ``separating_axes``,
``object_bounds``, ``leaf_size``, and the expansion grid, :attr:`~warp_ccd._src.midphase.bvh.MidPhaseBVH.num_blocks`
on CUDA), after ``--warmup`` frames: ``--frames``
frames of ``detect(advance=dt)`` as the pipeline runs them (a CUDA graph on CUDA), wall-clock with
a synchronisation before and after (``frame``), then as many timed stage by stage
(``timings=True``: ``refit``, ``broad``, ``mid``, ``narrow``, each synchronised), min and median;
and the counts of the last frame: broad-phase pairs, the traversal front's largest level, candidate
triangle pairs, those the exact test sent to its touch step, triangle pairs (the same for every
combination: checked).

    python -m bench.box_tests --device cuda:0 --cases poly:1000000 80:100000 \\
        --out bench/results/box_tests_cuda0.json
"""

from __future__ import annotations

import argparse
import itertools
import sys
import time

import numpy as np
import warp as wp

from warp_ccd import Scene
from warp_ccd._src.bench.meshes import parse_triangles
from warp_ccd._src.geometry.precision import PRECISIONS
from warp_ccd._src.midphase import bvh as mid_phase
from warp_ccd._src.narrowphase import discrete as narrow_phase
from warp_ccd._src.pipeline.pipeline import STAGES, CollisionPipeline
from warp_ccd._src.trees import traversal
from warp_ccd._src.trees.bvh import OBJECT_BOUNDS
from warp_ccd._src.trees.traversal import EXPAND_THREADS_PER_SM

from .command import add_run_options, bench_parser, start, write_result
from .timing import ms_stats

DT = 1.0 / 60.0


def _bounds(text: str) -> str | int:
    """``--bounds`` value: a name of :data:`~warp_ccd._src.trees.bvh.OBJECT_BOUNDS` or a vertex count."""
    if text in OBJECT_BOUNDS:
        return text
    if text.isdigit():
        return int(text)
    raise argparse.ArgumentTypeError(f"{text!r} is neither one of {tuple(OBJECT_BOUNDS)} nor a vertex count")


def _case(text: str) -> tuple[str, int]:
    spec, _, count = text.partition(":")
    try:
        parse_triangles(spec)
        n = int(float(count))
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"{text!r}: expected TRIANGLES:N, e.g. poly:1e5 ({exc})") from None
    return spec, n



def _set_grid(pipe: CollisionPipeline, threads_per_sm: int) -> None:
    """The expansion grid of ``threads_per_sm`` threads per multiprocessor (CUDA; the CPU keeps one block): the
    mid phase's walk (:class:`~warp_ccd._src.trees.traversal.FrontWalk`) and its own launches."""
    mid = pipe.mid
    if mid.device.is_cuda:
        mid.num_blocks = mid.device.sm_count * threads_per_sm // mid.block_dim  # the walk's grid too


def _heavy_kernels() -> list:
    """The kernels whose register budget ``--max-registers`` sets: the exact test's two, the
    traversal's expansion (the mid phase's walk) and its pair set-up (both precisions)."""
    kernels = [mid_phase._WALK]
    for precision in PRECISIONS:
        kernels += [narrow_phase._NARROW_MOLLER[precision], narrow_phase._NARROW_TOUCH[precision],
                    traversal.PAIR_KERNELS[precision]]
    return kernels


_COMPILED_OPTIONS = {id(k): dict(k.options) for k in _heavy_kernels()}


def _set_max_registers(registers: int) -> None:
    """Compiles the heavy kernels with at most ``registers`` registers a thread (CUDA's
    ``__maxnreg__``), or as the library declares them (0)."""
    for kernel in _heavy_kernels():
        kernel.options = dict(_COMPILED_OPTIONS[id(kernel)])
        if registers:
            kernel.options.pop("launch_bounds", None)
            kernel.options["cuda_max_registers"] = registers
        kernel.module.mark_modified()


def run(spec: str, n: int, args, device, registers: int, pairs_by_case: dict) -> list[dict]:
    """Rows of one scene: every option combination, frames then stages."""
    _, shapes = parse_triangles(spec)
    rows = []
    pairs_seen = pairs_by_case.get((spec, n))
    for axes, bounds, leaf, threads in itertools.product(args.axes, args.bounds, args.leaf_sizes, args.threads_per_sm):
        scene = Scene.random(n, seed=args.seed, device=device, **({} if shapes is None else {"shapes": shapes}))
        options = dict(separating_axes=axes, object_bounds=bounds, leaf_size=leaf)
        pipe = CollisionPipeline(scene, **options)
        _set_grid(pipe, threads)
        frames = []
        for k in range(args.warmup + args.frames):
            wp.synchronize_device(device)
            start = time.perf_counter()
            res = pipe.detect(advance=DT)
            wp.synchronize_device(device)
            if k >= args.warmup:
                frames.append((time.perf_counter() - start) * 1e3)
        touch = pipe.narrow.touch
        counts = {"broad_pairs": res.num_broad_pairs, "front_peak": pipe.mid.front.last_count,
                  "candidates": res.num_candidates, "touch_tests": touch.last_count if touch else None,
                  "triangle_pairs": res.num_triangle_pairs}
        pairs = res.triangle_pairs
        if pairs_seen is None:
            pairs_seen = pairs_by_case[(spec, n)] = pairs
        elif not np.array_equal(pairs, pairs_seen):
            raise SystemExit(f"{spec}:{n} {options} threads={threads}: other triangle pairs than the first combination")
        base = {"triangles": spec, "n_objects": n, **options, "threads_per_sm": threads, "max_registers": registers,
                **counts}
        rows.append({**base, "stage": "frame", **ms_stats(frames)})
        timed = CollisionPipeline(scene, timings=True, **options)
        _set_grid(timed, threads)
        stages = {s: [] for s in (*STAGES, "total")}
        for k in range(args.warmup + args.frames):
            scene.advance(0.0)  # same poses: the frame above's scene, timed stage by stage
            t = timed.detect().timings
            if k >= args.warmup:
                for s in stages:
                    stages[s].append(t[s])
        rows += [{**base, "stage": s, **ms_stats(v)} for s, v in stages.items()]
        frame_ms = rows[-len(stages) - 1]["ms_median"]
        print(f"{spec:>6} {n:>9,}  axes {axes}  bounds {str(bounds):<8}  leaf {leaf or '-'}  threads/SM {threads:>5}"
              f"  registers {registers or '-':>3}"
              f"  frame {frame_ms:8.3f} ms"
              f"  mid {ms_stats(stages['mid'])['ms_median']:7.3f}  refit {ms_stats(stages['refit'])['ms_median']:7.3f}"
              f"  broad pairs {counts['broad_pairs']:>9,}  candidates {counts['candidates']:>11,}"
              f"  touch tests {counts['touch_tests'] or 0:>10,}  hits {counts['triangle_pairs']:>10,}", flush=True)
    return rows


def main(argv=None) -> int:
    parser = bench_parser(__doc__.splitlines()[0])
    parser.add_argument("--cases", type=_case, nargs="+", default=[("poly", 1000), ("80", 1000)],
                        help="TRIANGLES:N scenes (default: %(default)s)")
    parser.add_argument("--axes", type=int, nargs="+", default=[3, 6], choices=[3, 6])
    parser.add_argument("--bounds", type=_bounds, nargs="+", default=["auto", "vertices", "tree"],
                        help="object_bounds: auto, vertices, tree, or the most vertices of an object whose box "
                             "comes from its vertices (default: %(default)s)")
    parser.add_argument("--leaf-sizes", type=int, nargs="+", default=[None],
                        help="leaf sizes (default: the pipeline's own)")
    parser.add_argument("--threads-per-sm", type=int, nargs="+", default=[EXPAND_THREADS_PER_SM],
                        help="threads per multiprocessor of each expansion launch (CUDA; default: %(default)s)")
    parser.add_argument("--max-registers", type=int, nargs="+", default=[0],
                        help="most registers a thread of the heavy kernels, 0: as declared (CUDA; default: "
                             "%(default)s)")
    add_run_options(parser, frames=10, warmup=3, seed=0, out_help="JSON file")
    args, device, document = start(parser, argv)
    document["config"] = {**vars(args), "cases": [f"{s}:{n}" for s, n in args.cases]}
    rows = document["rows"]
    pairs_by_case = {}
    for registers in args.max_registers:
        _set_max_registers(registers)
        for spec, n in args.cases:
            rows += run(spec, n, args, device, registers, pairs_by_case)
            write_result(args.out, document)
    _set_max_registers(0)
    return 0


if __name__ == "__main__":
    sys.exit(main())
