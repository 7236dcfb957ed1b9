"""Benchmark: the continuous frame against the discrete frame of the same scene.

For each ``N`` of ``--objects``, on the scaling scene ``Scene.random(N, --seed)``, a discrete
:class:`~warp_ccd._src.pipeline.pipeline.CollisionPipeline` and a continuous one (``continuous=True``) share the
scene. Each frame:

* ``discrete``: ``detect(advance=dt)``: the scene moves by 1/60 s and the discrete pipeline
  detects on the new vertices (on CUDA one replayed graph, motion included);
* ``continuous``: ``detect()`` on the same vertices: it covers the linear motion of every vertex
  since its previous ``detect()``, which is exactly that step (on CUDA one replayed graph; its
  frame alternates between two start arrays, so two graphs).

Each is timed wall-clock with ``wp.synchronize_device`` before and after; ``--warmup`` frames, then
``--frames`` timed ones; rows give min and median ms per frame, the ratio continuous / discrete
(medians), object pairs found per frame (mean) by each, and over the timed frames the object pairs
only the continuous frame found: ``only_continuous`` (not in the discrete frame at the step's end),
``between_frames`` (in neither the discrete frame at the step's start nor at its end: contacts the
discrete frames miss) and, the other way, ``discrete_only`` (pairs the discrete frame found that the
continuous one did not; none is expected but for pairs within the tolerances of touching). On CUDA
the free device memory after the warm-up is recorded. A continuous pipeline that cannot be built or
run (memory, at the largest ``N``) is reported as a note and the discrete rows are kept.

With ``--profile`` the continuous row also holds one eager frame activity by activity (a pipeline
launched kernel by kernel, ``wp.timing``: GPU ms per kernel, median of 5 frames) and the counts of
its stages (candidates, candidates with queries left to search after the first pass).

    python -m bench.continuous --device cuda:0 --objects 1e3 1e4 1e5 1e6 --profile \\
        --out bench/results/continuous_cuda0.json
"""

from __future__ import annotations

import gc
import sys

import numpy as np
import warp as wp

import warp_ccd as wc
from warp_ccd._src.bench.timing import synced_ms

from .command import add_run_options, bench_parser, start, write_result
from .profile_frame import activities
from .timing import ms_stats

DT = 1.0 / 60.0


def _keys(pairs: np.ndarray, n: int) -> np.ndarray:
    """Object pairs ``(K, 2)`` as sorted int64 keys."""
    return np.unique(pairs[:, 0].astype(np.int64) * n + pairs[:, 1]) if len(pairs) else np.zeros(0, np.int64)



def _free_gb(device) -> float | None:
    return device.free_memory / 1024**3 if device.is_cuda else None


def _profile(n: int, args, device) -> dict:
    """One continuous frame of a fresh scene (same seed) launched kernel by kernel: its activities
    (the 12 slowest, GPU ms) and its stages' counts."""
    scene = wc.Scene.random(n, seed=args.seed, device=device)
    pipe = wc.CollisionPipeline(scene, continuous=True, graph=False)
    for _ in range(args.warmup):
        pipe.detect(advance=DT)
    acts = activities(pipe, 5)
    narrow = pipe.narrow
    return {"activities": acts[:12], "kernels_ms": float(sum(a["ms"] for a in acts)),
            "candidates": pipe.mid.candidates.last_count, "deferred": narrow.deferred.last_count,
            "triangle_pairs": narrow.hits.last_count}


def run(n: int, args, device, notes: list) -> list[dict]:
    """Rows for one object count: the discrete frame, then the continuous one (unless it failed)."""
    scene = wc.Scene.random(n, seed=args.seed, device=device)
    discrete = wc.CollisionPipeline(scene)
    previous = _keys(discrete.detect().object_pairs, n)  # the state the continuous pipeline starts from
    continuous = None
    graph = {"discrete": discrete.graph}
    try:
        continuous = wc.CollisionPipeline(scene, continuous=True)
        graph["continuous"] = continuous.graph
    except Exception as exc:  # noqa: BLE001 (memory at the largest N: reported, the discrete rows kept)
        notes.append(f"{n} objects: the continuous pipeline could not be built: {type(exc).__name__}: {exc}")
    times = {"discrete": [], "continuous": []}
    pairs = {"discrete": [], "continuous": []}
    counts = {"only_continuous": 0, "between_frames": 0, "discrete_only": 0}
    last = {}
    free = None
    for k in range(args.warmup + args.frames):
        out = {}
        ms = synced_ms(lambda: out.setdefault("discrete", discrete.detect(advance=DT)), device)
        found = _keys(out["discrete"].object_pairs, n)
        timed = k >= args.warmup
        if timed:
            times["discrete"].append(ms)
            pairs["discrete"].append(len(found))
            last["discrete"] = out["discrete"]
        if continuous is not None:
            try:
                ms = synced_ms(lambda: out.setdefault("continuous", continuous.detect()), device)
            except Exception as exc:  # noqa: BLE001 (as above)
                notes.append(f"{n} objects: the continuous frame failed at frame {k}: {type(exc).__name__}: {exc}")
                continuous = None
                out.clear()
                gc.collect()
        if continuous is not None and timed:
            both = _keys(out["continuous"].object_pairs, n)
            times["continuous"].append(ms)
            pairs["continuous"].append(len(both))
            last["continuous"] = out["continuous"]
            only = np.setdiff1d(both, found, assume_unique=True)
            counts["only_continuous"] += len(only)
            counts["between_frames"] += len(np.setdiff1d(only, previous, assume_unique=True))
            counts["discrete_only"] += len(np.setdiff1d(found, both, assume_unique=True))
        if k + 1 == args.warmup or (args.warmup == 0 and k == 0):
            free = _free_gb(device)
        previous = found
    rows = []
    base = {"n_objects": n, "triangles": scene.num_triangles, "free_gb_after_warmup": free}
    for method in ("discrete", "continuous"):
        if not times[method]:
            continue
        res = last[method]
        row = {**base, "method": method, "frames": len(times[method]), "graph": graph[method],
               **ms_stats(times[method]), "object_pairs_per_frame": float(np.mean(pairs[method])),
               "object_pairs_last": len(res.object_pairs),
               "triangle_pairs_last": res.num_triangle_pairs, "candidates_last": res.num_candidates}
        if method == "continuous":
            row["ratio_median"] = row["ms_median"] / rows[0]["ms_median"]
            row.update(counts)
            if args.profile:
                row["profile"] = _profile(n, args, device)
        rows.append(row)
    text = f"{n:>9,} objects: discrete {rows[0]['ms_median']:8.3f} ms ({rows[0]['object_pairs_per_frame']:.1f} pairs)"
    if len(rows) > 1:
        c = rows[1]
        text += (f", continuous {c['ms_median']:8.3f} ms ({c['object_pairs_per_frame']:.1f} pairs), "
                 f"{c['ratio_median']:.2f}x; only continuous {c['only_continuous']}, between frames "
                 f"{c['between_frames']}, discrete only {c['discrete_only']} over {args.frames} frames")
    else:
        text += ", continuous: none (see the notes)"
    print(text, flush=True)
    return rows


def main(argv=None) -> int:
    parser = bench_parser(__doc__.splitlines()[0])
    parser.add_argument("--objects", type=lambda x: int(float(x)), nargs="+", default=[1000, 10_000, 100_000,
                                                                                        1_000_000])
    parser.add_argument("--profile", action="store_true", help="profile one eager continuous frame per N")
    add_run_options(parser, frames=20, warmup=3, seed=0, out_help="JSON file (default: none)")
    args, device, document = start(parser, argv)
    document["notes"] = []
    for n in args.objects:
        document["rows"] += run(n, args, device, document["notes"])
        gc.collect()  # the previous scene's pipelines go before the next scene is built
        if device.is_cuda:
            wp.synchronize_device(device)
        write_result(args.out, document)
    for note in document["notes"]:
        print(f"note: {note}")
    if args.out:
        print(f"results written to {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
