"""Benchmark: continuous collision queries per second (vertex-face and edge-edge), against Tight Inclusion.

Two query sets, each half vertex-face and half edge-edge queries (``--queries`` in all):

* ``mixed``: queries as a simulation produces them. The scaling scene (``Scene.random(--objects,
  --seed)``) moves by ``--step-frames`` frames of 1/60 s at once (a large step, so that there are
  contacts); a continuous :class:`~warp_ccd._src.pipeline.pipeline.CollisionPipeline` gives its candidate triangle
  pairs over that motion, and each candidate expands into its 6 vertex-face and 9 edge-edge
  queries (duplicates removed). Each kind is shuffled and tiled, every copy after the first
  translated by a random offset within the scene's extent, to reach its count.
* ``random``: the four points uniform in the unit cube, each moving by a displacement uniform in
  ``[-0.3, 0.3]`` per coordinate.

Coordinates are rounded to float32 once, so that the float32 and float64 arrays hold the same values
(the answers must then be the same, bit for bit). Methods, in the same process:

* ``ours_device``: the two passes of ``ccd_queries`` (``run_queries``: every query within a few boxes,
  then the rest packed) on arrays uploaded beforehand, float64 and
  float32, on ``--device``; kernel time only (CUDA events; wall time on the CPU), min and median
  over ``--repeats`` launches after one warm-up launch; with ``min_distance = 0`` and with
  ``--min-distance`` times the set's scale (the median object radius, 1 for ``random``).
* ``ours_cpu``: the same kernel on Warp's CPU device (one thread), float64, on a subset: the first
  ``--ipctk-queries / 2`` queries of each kind (a random sample: the sets are shuffled);
  ``--cpu-repeats`` launches. Skipped where Warp has no CPU device.
* ``ipctk``: Tight Inclusion (``ipctk.tight_inclusion.point_triangle_ccd`` / ``edge_edge_ccd``,
  ``min_distance=0``, ``tolerance=1e-6``, ``max_iterations=-1``), one call a query from Python on
  one thread, on the same subset (its time includes the binding's per-call cost); a query that
  raises is counted and left out. Skipped with a note when ipctk is not installed.

Rows give queries, hits and the hit fraction, ms min and median, us per query, queries per second
and ms per 10^7 queries (``all``: the two kinds' launches added). Ratios: ipctk's us per query over
ours (device and CPU). Checks, on the subset: ``missed`` (ipctk hits, we do not: must be 0),
``extra`` (we hit, ipctk does not: our false positives, reported), ``late`` (both hit, our toi later
than ipctk's by more than 1e-5, reported); the CPU's tois must equal the device's and float32's
float64's, bit for bit. A ``missed`` query or a differing toi makes the command end with status 3
after the results are written.

    python -m bench.ccd_queries --device cuda:0 --queries 1e7 --out bench/results/ccd_queries_cuda0.json
"""

from __future__ import annotations

import math
import sys
import time

import numpy as np
import warp as wp

import warp_ccd as wc
from warp_ccd._src.cli.common import EXIT_INTERNAL, EXIT_OK
from warp_ccd._src.geometry.ccd import CCD_KINDS, CCD_MAX_ITERATIONS, CCD_TOLERANCE
from warp_ccd._src.queries.ccd import run_queries

from .command import add_run_options, bench_parser, start, write_result
from .narrow_phase import gpu_ms

DT = 1.0 / 60.0
KINDS = ("vertex_face", "edge_edge")
PRECISIONS = ("float64", "float32")
SETS = ("mixed", "random")
LATE = 1e-5
"""A toi later than ipctk's by more than this is reported as late."""


def _count(text: str) -> int:
    return int(float(text))


# ---------------------------------------------------------------------------------------------
# Query sets: {kind: (x0, x1)} of (n, 4, 3) float32 points at t = 0 and t = 1


def _tile(x0: np.ndarray, x1: np.ndarray, count: int, extent: float, rng) -> tuple[np.ndarray, np.ndarray]:
    """``count`` queries: ``x0``/``x1`` shuffled and repeated, every copy after the first translated by
    an offset uniform in ``[-extent / 2, extent / 2]^3`` (rounded to float32 again)."""
    n = len(x0)
    copies = math.ceil(count / n)
    order = np.concatenate([rng.permutation(n) for _ in range(copies)])[:count]
    copy = np.repeat(np.arange(copies), n)[:count]
    offset = rng.uniform(-0.5 * extent, 0.5 * extent, (copies, 3))
    offset[0] = 0.0
    shift = offset[copy][:, None, :]
    return ((x0[order] + shift).astype(np.float32), (x1[order] + shift).astype(np.float32))


def mixed_set(count: int, objects: int, step_frames: int, seed: int, device) -> tuple[dict, dict]:
    """``({kind: (x0, x1)}, info)``: the scaling scene's candidate triangle pairs over a motion of
    ``step_frames`` frames, expanded into vertex-face and edge-edge queries and tiled to ``count``
    (half each); ``info``: the scene, its candidates and hits, the queries before tiling, ``scale``."""
    scene = wc.Scene.random(objects, seed=seed, device=device)
    scene.advance(DT)
    pipe = wc.CollisionPipeline(scene, continuous=True)
    start = scene.world_vertex.numpy().astype(np.float64)
    scene.advance(step_frames * DT)
    result = pipe.detect()
    end = scene.world_vertex.numpy().astype(np.float64)
    rows = pipe.mid.candidates.numpy(pipe.mid.candidates.last_count)
    tri = scene.shape_triangle.numpy()

    def corners(obj, t):  # (M, 3) world vertex indices of local triangle t of object obj
        return tri[scene.shape_triangle_start_np[scene.object_shape_np[obj]] + t] + \
            scene.object_vertex_start_np[obj][:, None]

    a, b = corners(rows[:, 0], rows[:, 1]), corners(rows[:, 2], rows[:, 3])
    vf = np.concatenate([np.column_stack([p[:, i], f]) for p, f in ((a, b), (b, a)) for i in range(3)])
    edges_a = [np.sort(a[:, [i, (i + 1) % 3]], axis=1) for i in range(3)]
    edges_b = [np.sort(b[:, [i, (i + 1) % 3]], axis=1) for i in range(3)]
    ee = np.concatenate([np.column_stack([ea, eb]) for ea in edges_a for eb in edges_b])
    info = {"objects": objects, "triangles": scene.num_triangles, "step_frames": step_frames,
            "candidates": len(rows), "triangle_pairs_hit": result.num_triangle_pairs,
            "object_pairs_hit": len(result.object_pairs), "scale": float(np.median(scene.object_scale_np))}
    if not len(rows):
        raise SystemExit(f"ccd_queries: the mixed scene of {objects} objects has no candidate triangle pairs "
                         f"over {step_frames} frames: give more --objects")
    extent = float(np.max(end.max(axis=0) - end.min(axis=0)))
    rng = np.random.default_rng(seed)
    out = {}
    for kind, idx, n in (("vertex_face", vf, count // 2), ("edge_edge", ee, count - count // 2)):
        idx = np.unique(idx, axis=0)
        info[f"{kind}_base"] = len(idx)
        out[kind] = _tile(start[idx], end[idx], n, extent, rng)
    return out, info


def random_set(count: int, seed: int) -> tuple[dict, dict]:
    """``({kind: (x0, x1)}, info)``: points uniform in the unit cube moving by up to 0.3 per
    coordinate, ``count`` queries (half each kind)."""
    rng = np.random.default_rng(seed + 1)
    out = {}
    for kind, n in (("vertex_face", count // 2), ("edge_edge", count - count // 2)):
        x0 = rng.random((n, 4, 3))
        out[kind] = (x0.astype(np.float32), (x0 + rng.uniform(-0.3, 0.3, (n, 4, 3))).astype(np.float32))
    return out, {"scale": 1.0}


# ---------------------------------------------------------------------------------------------
# Methods


def _upload(x: np.ndarray, precision: str, device) -> wp.array:
    if precision == "float64":
        return wp.array(x.astype(np.float64), dtype=wp.vec3d, device=device)
    return wp.array(x, dtype=wp.vec3, device=device)


def ours(kind: str, x0: np.ndarray, x1: np.ndarray, precision: str, min_distance: float, device,
         repeats: int) -> tuple[np.ndarray, float, float]:
    """``(toi, ms_min, ms_median)`` of the two passes of ``ccd_queries`` (``run_queries``) on
    ``device`` (arrays and scratch allocated first, kernel time only)."""
    a0, a1 = _upload(x0, precision, device), _upload(x1, precision, device)
    toi = wp.empty(len(x0), dtype=wp.float64, device=device)
    deferred = wp.empty(len(x0), dtype=wp.int32, device=device)
    deferred_count = wp.zeros(1, dtype=wp.int32, device=device)

    def launch():
        run_queries(CCD_KINDS[kind], a0, a1, min_distance, CCD_TOLERANCE, CCD_MAX_ITERATIONS, toi, deferred,
                    deferred_count)

    lo, med = gpu_ms(launch, device, repeats)
    return toi.numpy(), lo, med


def ipctk_queries(module, kind: str, x0: np.ndarray, x1: np.ndarray) -> tuple[np.ndarray, float, np.ndarray]:
    """``(toi, ms, raised)``: ipctk on each query in turn (toi inf where no hit or where it raised;
    ``raised`` marks those)."""
    tight = module.tight_inclusion
    ccd = tight.point_triangle_ccd if kind == "vertex_face" else tight.edge_edge_ccd
    x0, x1 = x0.astype(np.float64), x1.astype(np.float64)
    toi = np.full(len(x0), np.inf)
    raised = np.zeros(len(x0), bool)
    t = time.perf_counter()
    for i in range(len(x0)):
        try:
            hit, when, _ = ccd(*x0[i], *x1[i], min_distance=0.0, tolerance=CCD_TOLERANCE, max_iterations=-1)
        except Exception:  # noqa: BLE001 (a query the peer cannot answer is counted, not fatal)
            raised[i] = True
            continue
        if hit:
            toi[i] = when
    return toi, (time.perf_counter() - t) * 1e3, raised


def _row(name: str, kind: str, method: str, device, precision: str, min_distance: float, toi: np.ndarray | None,
         queries: int, lo: float, med: float, hits: int | None = None) -> dict:
    hits = int((toi <= 1.0).sum()) if hits is None else hits
    return {"set": name, "kind": kind, "method": method, "device": str(device), "precision": precision,
            "min_distance": min_distance, "queries": queries, "hits": hits,
            "hit_fraction": hits / queries if queries else None, "ms_min": lo, "ms_median": med,
            "us_per_query": med * 1e3 / queries if queries else None,
            "queries_per_s": queries / (med * 1e-3) if med > 0 else None,
            "ms_per_1e7": med * 1e7 / queries if queries else None}


def _compare(name: str, kind: str, toi: np.ndarray, ip_toi: np.ndarray, errors: np.ndarray) -> dict:
    """Our tois against ipctk's on the subset (queries where ipctk raised left out)."""
    ok = ~errors
    hit, ip_hit = toi <= 1.0, ip_toi <= 1.0
    missed = np.nonzero(ok & ip_hit & ~hit)[0]
    late = ok & ip_hit & hit & (toi > ip_toi + LATE)
    return {"set": name, "kind": kind, "check": "ipctk", "queries": int(ok.sum()), "ipctk_errors": int(errors.sum()),
            "both_hit": int((ok & hit & ip_hit).sum()), "missed": len(missed), "missed_first": missed[:10].tolist(),
            "extra": int((ok & hit & ~ip_hit).sum()), "late": int(late.sum()),
            "late_max": float(np.max(toi[late] - ip_toi[late])) if late.any() else 0.0, "ok": not len(missed)}


def _same(name: str, kind: str, what: str, a: np.ndarray, b: np.ndarray) -> dict:
    differ = np.nonzero(a != b)[0]
    return {"set": name, "kind": kind, "check": what, "queries": len(a), "differ": len(differ),
            "differ_first": differ[:10].tolist(), "ok": not len(differ)}


def run_set(name: str, queries: dict, info: dict, args, device, peer) -> tuple[list, list, list]:
    """``(rows, checks, ratios)`` of one query set."""
    rows, checks, ratios = [], [], []
    d = args.min_distance * info["scale"]
    cpu = wp.get_device("cpu") if wp.is_cpu_available() else None
    subset = max(1, args.ipctk_queries // 2)
    for kind in KINDS:
        x0, x1 = queries[kind]
        n = len(x0)
        toi = {}
        for precision in PRECISIONS:
            toi[precision], lo, med = ours(kind, x0, x1, precision, 0.0, device, args.repeats)
            rows.append(_row(name, kind, "ours_device", device, precision, 0.0, toi[precision], n, lo, med))
            t, lo, med = ours(kind, x0, x1, precision, d, device, args.repeats)
            rows.append(_row(name, kind, "ours_device", device, precision, d, t, n, lo, med))
        checks.append(_same(name, kind, "float32_vs_float64", toi["float32"], toi["float64"]))
        s0, s1 = x0[:subset], x1[:subset]
        ref = toi["float64"][:len(s0)]
        us = {"ours_device": rows[-4]["us_per_query"]}
        if cpu is not None:
            t, lo, med = ours(kind, s0, s1, "float64", 0.0, cpu, args.cpu_repeats)
            rows.append(_row(name, kind, "ours_cpu", cpu, "float64", 0.0, t, len(s0), lo, med))
            checks.append(_same(name, kind, "cpu_vs_device", t, ref))
            us["ours_cpu"] = rows[-1]["us_per_query"]
        if peer is not None:
            ip_toi, ms, raised = ipctk_queries(peer, kind, s0, s1)
            rows.append(_row(name, kind, "ipctk", "cpu", "float64", 0.0, ip_toi, len(s0), ms, ms))
            checks.append(_compare(name, kind, ref, ip_toi, raised))
            for method in ("ours_device", "ours_cpu"):
                if method in us:
                    ratios.append({"set": name, "kind": kind, "ours": method, "ipctk_us_per_query":
                                   rows[-1]["us_per_query"], "ours_us_per_query": us[method],
                                   "speedup": rows[-1]["us_per_query"] / us[method]})
    # Both kinds together: their launches added.
    for precision in PRECISIONS:
        for dist in (0.0, d):
            parts = [r for r in rows if r["method"] == "ours_device" and r["precision"] == precision
                     and r["min_distance"] == dist]
            n = sum(r["queries"] for r in parts)
            rows.append(_row(name, "all", "ours_device", device, precision, dist, None, n,
                             sum(r["ms_min"] for r in parts), sum(r["ms_median"] for r in parts),
                             hits=sum(r["hits"] for r in parts)))
    return rows, checks, ratios


def _print(doc: dict) -> None:
    print(f"\nccd queries on {doc['device']} ({doc['device_name']}); subsets of {doc['config']['ipctk_queries']:,} "
          f"for the CPU (one thread) and ipctk")
    print(f"{'set':<8}{'kind':<13}{'method':<13}{'precision':<10}{'min_dist':>9}{'queries':>12}{'hit %':>8}"
          f"{'ms min':>10}{'ms median':>11}{'us/query':>10}{'Mquery/s':>10}{'ms per 1e7':>12}")
    for r in doc["rows"]:
        print(f"{r['set']:<8}{r['kind']:<13}{r['method']:<13}{r['precision']:<10}{r['min_distance']:>9.2g}"
              f"{r['queries']:>12,}{100 * r['hit_fraction']:>8.2f}{r['ms_min']:>10.3f}{r['ms_median']:>11.3f}"
              f"{r['us_per_query']:>10.4f}{(r['queries_per_s'] or 0) / 1e6:>10.2f}{r['ms_per_1e7']:>12.1f}")
    for r in doc["ratios"]:
        print(f"{r['set']:<8}{r['kind']:<13}ipctk {r['ipctk_us_per_query']:.3f} us/query, {r['ours']} "
              f"{r['ours_us_per_query']:.4f}: {r['speedup']:.1f}x")
    for c in doc["checks"]:
        extra = {k: v for k, v in c.items() if k not in ("set", "kind", "check", "ok")}
        print(f"check {c['set']:<8}{c['kind']:<13}{c['check']:<20}{'ok' if c['ok'] else 'MISMATCH'} {extra}")
    for note in doc["notes"]:
        print(f"note: {note}")


def main(argv=None) -> int:
    parser = bench_parser(__doc__.splitlines()[0])
    parser.add_argument("--queries", type=_count, default=None,
                        help="queries of each set, half of each kind (default: 1e7 on CUDA, 1e5 on the CPU)")
    parser.add_argument("--objects", type=_count, default=None,
                        help="objects of the mixed set's scene (default: 1e4 on CUDA, 1e3 on the CPU)")
    parser.add_argument("--step-frames", type=int, default=4, help="frames of 1/60 s the mixed scene moves at once")
    parser.add_argument("--sets", nargs="+", choices=SETS, default=list(SETS))
    parser.add_argument("--ipctk-queries", type=_count, default=20_000,
                        help="queries of each set for ipctk and the CPU, half of each kind (default: 2e4)")
    parser.add_argument("--min-distance", type=float, default=1e-3,
                        help="the min_distance rows' distance, relative to the set's scale (default: 1e-3)")
    parser.add_argument("--repeats", type=int, default=10, help="timed launches on the device")
    parser.add_argument("--cpu-repeats", type=int, default=3, help="timed launches on the CPU subset")
    parser.add_argument("--no-ipctk", action="store_true", help="leave the ipctk peer out")
    add_run_options(parser, seed=0, out_help="JSON file (default: none)")
    args, device, doc = start(parser, argv)
    if args.queries is None:
        args.queries = 10_000_000 if device.is_cuda else 100_000
    if args.objects is None:
        args.objects = 10_000 if device.is_cuda else 1_000
    doc.update(sets={}, checks=[], ratios=[], notes=[])
    peer = None
    if not args.no_ipctk:
        try:
            import ipctk as peer
            doc["versions"]["ipctk"] = getattr(peer, "__version__", None)
        except ImportError:
            doc["notes"].append("ipctk is not installed: its rows and the agreement checks are skipped")
    if not wp.is_cpu_available():
        doc["notes"].append("Warp has no CPU device here: the ours_cpu rows are skipped")
    for name in args.sets:
        t = time.perf_counter()
        if name == "mixed":
            queries, info = mixed_set(args.queries, args.objects, args.step_frames, args.seed, device)
        else:
            queries, info = random_set(args.queries, args.seed)
        info["generated_s"] = time.perf_counter() - t
        doc["sets"][name] = info
        print(f"{name}: {info}", flush=True)
        rows, checks, ratios = run_set(name, queries, info, args, device, peer)
        doc["rows"] += rows
        doc["checks"] += checks
        doc["ratios"] += ratios
        write_result(args.out, doc)
    doc["ok"] = all(c["ok"] for c in doc["checks"])
    write_result(args.out, doc)
    _print(doc)
    if args.out:
        print(f"results written to {args.out}")
    return EXIT_OK if doc["ok"] else EXIT_INTERNAL


if __name__ == "__main__":
    sys.exit(main())
