"""Benchmark: what one verdict on every device costs the narrow phase (``fuse_fp`` off against on).

The narrow-phase module is compiled without floating-point contraction (``fuse_fp=False``) so that
CUDA rounds every step as the CPU does. This script measures, on one device and in one process,
both builds of the module (the option is switched and the module rebuilt in between):

* **time**: the narrow-phase kernel (``NarrowPhase.launch``: exact test of every candidate triangle
  pair, hits appended) on the candidates of a real frame of the scaling scene (``--objects`` objects
  of ``--triangles`` triangles), and the batch kernel on the 10^5 near-degenerate pairs of
  ``tests/awkward_pairs.py``; GPU time per launch from CUDA events (wall time on the CPU), min
  and median over ``--repeats`` launches after a warm-up;
* **verdicts**: how many of the near-degenerate pairs' verdicts (both tests, float32 and float64)
  differ from the CPU's with the shipped build (computed in the same run; the tests hold them
  recorded, ``tests/data/narrow_phase_verdicts.npz``, and check that the CPU still gives them), and
  how many hits the scene frame has.

    python -m bench.narrow_phase --device cuda:0 --out bench/results/narrow_phase_cuda0.json
"""

from __future__ import annotations

import sys
import time

import numpy as np
import warp as wp

import warp_ccd as wc
from tests.awkward_pairs import METHODS, PRECISIONS, awkward_pairs, verdicts
from warp_ccd._src.bench.meshes import parse_triangles
from warp_ccd._src.geometry import triangle
from warp_ccd._src.geometry.precision import precision_types
from warp_ccd._src.narrowphase import discrete as narrow_phase

from .command import add_out_option, bench_parser, start, write_result


def gpu_ms(fn, device, repeats: int) -> tuple[float, float]:
    """``(min, median)`` ms of ``fn()`` per launch: CUDA events on a GPU, wall time on the CPU."""
    fn()
    wp.synchronize_device(device)
    times = []
    for _ in range(repeats):
        if device.is_cuda:
            start, end = wp.Event(device, enable_timing=True), wp.Event(device, enable_timing=True)
            wp.record_event(start)
            fn()
            wp.record_event(end)
            wp.synchronize_device(device)
            times.append(wp.get_event_elapsed_time(start, end))
        else:
            t = time.perf_counter()
            fn()
            wp.synchronize_device(device)
            times.append((time.perf_counter() - t) * 1e3)
    return float(np.min(times)), float(np.median(times))


def set_fuse_fp(fuse: bool) -> None:
    """Builds the stage's kernels and the batch kernels with (``True``) or without floating-point
    contraction; they are rebuilt at their next launch."""
    for module in (narrow_phase, triangle):
        wp.set_module_options({"fuse_fp": fuse}, module=module)


def measure(fuse: bool, args, device, scene, pipe, cpu: dict) -> list[dict]:
    """Rows of one build of the narrow-phase module (``fuse_fp=fuse``): the scene frame's narrow phase,
    then each precision and test on the near-degenerate pairs, their verdicts against ``cpu`` (per
    precision, ``verdicts`` of ``tests/awkward_pairs.py`` on the CPU with the shipped build)."""
    set_fuse_fp(fuse)
    rows = []
    narrow = pipe.narrow
    candidates = pipe.mid.candidates

    def frame_narrow():
        narrow.hits.reset()
        narrow.launch(scene, candidates)

    lo, med = gpu_ms(frame_narrow, device, args.repeats)
    hits = int(narrow.hits.count.numpy()[0])
    rows.append({"fuse_fp": fuse, "workload": f"scene {args.objects} x {args.triangles}", "precision": "float32",
                 "method": narrow.method, "pairs": int(candidates.count.numpy()[0]), "hits": hits,
                 "ms_min": lo, "ms_median": med})
    for precision in PRECISIONS:
        got = verdicts(precision, device)
        ta, tb = awkward_pairs(precision)
        _, vec3, _, _ = precision_types(precision)
        a, b = wp.array(ta, dtype=vec3, device=device), wp.array(tb, dtype=vec3, device=device)
        hit = wp.zeros(len(ta), dtype=wp.int32, device=device)
        for method in METHODS:

            def batch(method=method):
                wp.launch(triangle.tri_tri_batch_kernel, dim=len(ta),
                          inputs=[a, b, narrow_phase.NARROW_METHODS[method], wp.float64(triangle.TOLERANCE)],
                          outputs=[hit], device=device)

            lo, med = gpu_ms(batch, device, args.repeats)
            differ = int((got[method] != cpu[precision][method]).sum())
            rows.append({"fuse_fp": fuse, "workload": "near-degenerate pairs", "precision": precision,
                         "method": method, "pairs": len(ta), "hits": int(got[method].sum()),
                         "verdicts_differing_from_cpu": differ,
                         "segments_match_cpu": got["segment_sha256"] == cpu[precision]["segment_sha256"]
                         if method == "moller" else None,
                         "ms_min": lo, "ms_median": med})
    return rows


def main(argv=None) -> int:
    parser = bench_parser(__doc__.split("\n\n")[0])
    parser.add_argument("--objects", type=lambda s: int(float(s)), default=100_000)
    parser.add_argument("--triangles", default="80", help="'poly' or an icosphere's triangle count (default: 80)")
    parser.add_argument("--repeats", type=int, default=30)
    add_out_option(parser, "JSON file (default: none)")
    args, device, doc = start(parser, argv)
    label, shapes = parse_triangles(args.triangles)
    scene = wc.Scene.random(args.objects, seed=0, device=device, **({} if shapes is None else {"shapes": shapes}))
    scene.advance(0.5)
    pipe = wc.CollisionPipeline(scene)
    pipe.detect()  # candidates of a real frame stay in pipe.mid.candidates
    set_fuse_fp(False)  # the shipped build
    cpu = {precision: verdicts(precision, "cpu") for precision in PRECISIONS}
    rows = doc["rows"]
    for fuse in (False, True):  # the shipped build first, then with contraction
        rows += measure(fuse, args, device, scene, pipe, cpu)
    set_fuse_fp(False)
    print(f"narrow phase on {device} ({getattr(device, 'name', '')}): fuse_fp off (shipped) vs on")
    print(f"{'workload':<28}{'precision':<10}{'method':<11}{'pairs':>10}{'hits':>10}"
          f"{'ms off':>10}{'ms on':>10}{'on/off':>8}{'differ from CPU off / on':>28}")
    off = [r for r in rows if not r["fuse_fp"]]
    on = [r for r in rows if r["fuse_fp"]]
    for a, b in zip(off, on):
        differ = f"{a.get('verdicts_differing_from_cpu', '-')} / {b.get('verdicts_differing_from_cpu', '-')}"
        print(f"{a['workload']:<28}{a['precision']:<10}{a['method']:<11}{a['pairs']:>10,}{a['hits']:>10,}"
              f"{a['ms_median']:>10.4f}{b['ms_median']:>10.4f}{b['ms_median'] / a['ms_median']:>8.2f}{differ:>28}")
    if args.out:
        write_result(args.out, doc)
        print(f"results written to {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
