"""Benchmark: the contacts frame against the discrete frame of the same scene.

For each ``N`` of ``--objects``, on the scaling scene ``Scene.random(N, --seed)`` (polyhedra of radius 0.5 to
1.5), a discrete :class:`~warp_ccd._src.pipeline.pipeline.CollisionPipeline` and one with ``contacts=True``
(``max_per_pair=--max-per-pair``) share the scene. Each frame:

* ``discrete``: ``detect(advance=dt)``: the scene moves by 1/60 s and the discrete pipeline detects (on CUDA one
  replayed graph, motion included);
* ``contacts``: ``detect()`` on the same vertices: the frame, each intersecting pair's depth and witness (levels of
  the depth's search, one count read a level) and the contacts (candidates, one sort, the reduction).

Each is timed wall-clock with ``wp.synchronize_device`` before and after; ``--warmup`` frames, then ``--frames``
timed ones; rows give min and median ms per frame, the ratio contacts / discrete (medians), object pairs and
contacts per frame, and the depth's regions and levels of the last frame.

    python -m bench.contacts --device cuda:0 --objects 1e3 1e4 1e5 1e6 --out bench/results/contacts_cuda0.json
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


def run(n: int, args, device) -> list[dict]:
    """Rows for one object count: the discrete frame, then the contacts frame."""
    scene = wc.Scene.random(n, seed=args.seed, device=device)
    discrete = wc.CollisionPipeline(scene)
    contacts = wc.CollisionPipeline(scene, contacts=True, max_per_pair=args.max_per_pair)
    times = {"discrete": [], "contacts": []}
    pairs = {"discrete": [], "contacts": []}
    count, mismatches = [], 0
    for k in range(args.warmup + args.frames):
        out = {}
        ms = {"discrete": synced_ms(lambda: out.setdefault("discrete", discrete.detect(advance=DT)), device)}
        ms["contacts"] = synced_ms(lambda: out.setdefault("contacts", contacts.detect()), device)
        c = out["contacts"].contacts
        if not np.array_equal(np.unique(c.pairs, axis=0).reshape(-1, 2), out["discrete"].object_pairs):
            mismatches += 1
        if k >= args.warmup:
            for key, res in out.items():
                times[key].append(ms[key])
                pairs[key].append(len(res.object_pairs))
            count.append(c.count)
    base = {"n_objects": n, "triangles": scene.num_triangles, "graph": discrete.graph, "frames": args.frames}
    rows = [{**base, "method": "discrete", **ms_stats(times["discrete"]),
             "object_pairs_per_frame": float(np.mean(pairs["discrete"]))},
            {**base, "method": "contacts", "max_per_pair": args.max_per_pair, **ms_stats(times["contacts"]),
             "ratio_median": float(np.median(times["contacts"]) / np.median(times["discrete"])),
             "object_pairs_per_frame": float(np.mean(pairs["contacts"])),
             "contacts_per_frame": float(np.mean(count)), "depth_levels_last": contacts.depth.level_regions,
             "mismatches": mismatches}]
    print(f"{n:>9,} objects: discrete {rows[0]['ms_median']:8.3f} ms, contacts {rows[1]['ms_median']:8.3f} ms "
          f"({rows[1]['ratio_median']:.2f}x; {rows[1]['object_pairs_per_frame']:.1f} pairs, "
          f"{rows[1]['contacts_per_frame']:.1f} contacts, {mismatches} mismatches)", flush=True)
    return rows


def main(argv=None) -> int:
    parser = bench_parser(__doc__.splitlines()[0])
    parser.add_argument("--objects", type=lambda x: int(float(x)), nargs="+",
                        default=[1000, 10_000, 100_000, 1_000_000])
    parser.add_argument("--max-per-pair", type=int, default=8)
    add_run_options(parser, frames=20, warmup=3, seed=0, out_help="JSON file (default: none)")
    args, device, document = start(parser, argv)
    for n in args.objects:
        document["rows"] += run(n, args, device)
        gc.collect()
        if device.is_cuda:
            wp.synchronize_device(device)
        write_result(args.out, document)
    if args.out:
        print(f"results written to {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
