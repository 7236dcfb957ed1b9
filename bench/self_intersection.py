"""Benchmark: self-intersection of one large mesh, and deforming cloth scenes frame by frame.

**One mesh** (``--mesh-triangles``, about 1.3M by default): a figure-eight torus (it crosses itself all
around its circle) and an icosphere (none), each

* as a deforming object of a :class:`~warp_ccd._src.pipeline.pipeline.CollisionPipeline` with
  ``self_intersections=True``: a frame refits its tree and walks it against itself (on CUDA one replayed
  graph): ``frame`` ms, min and median over ``--frames`` after ``--warmup``;
* one-shot :func:`warp_ccd.self_intersections` (scene, tree build, walk, read): ``one_shot`` ms;
* pymeshlab's ``compute_selection_by_self_intersections_per_face`` on the CPU, in the same process
  (``--peer-runs`` runs; skipped with a note when pymeshlab is missing): ``pymeshlab`` ms, the ratio
  against the frame, and whether it selects the faces of our pairs that share at most one vertex
  (VCG's test skips triangles sharing an edge).

**Cloth** (``--sheets``, ``--crumpled``): ``k`` deforming sheets of ``--sheet-n``² vertices (72: 10,082
triangles), each folded over itself, stacked in overlapping piles: waved (crossing itself where a wave's
crest rises through the fold) or crumpled (through itself and its neighbours nearly everywhere,
:func:`crumpled_sheets`). Frames of a pipeline with ``self_intersections=True`` (self plus pairwise) against one without
(pairwise alone), on the same vertices: min and median ms, pairs found.

    python -m bench.self_intersection --device cuda:0 --sheets 1e2 1e3 1e4 \\
        --out bench/results/self_intersection_cuda0.json
"""

from __future__ import annotations

import gc
import sys
import time

import numpy as np
import warp as wp

import warp_ccd as wc
from warp_ccd._src.bench.timing import synced_ms
from warp_ccd.scene import figure_eight_torus, icosphere, sheet

from .command import add_row, add_run_options, bench_parser, start, write_result
from .timing import ms_stats


def crumpled_sheets(k: int, n: int, seed: int = 0, kind: str = "crumpled") -> list[tuple[np.ndarray, np.ndarray]]:
    """``k`` sheets of ``n x n`` vertices, each with its right part folded back over the rest and lifted,
    placed in piles of four whose sheets overlap by half, piles on a square grid. ``"crumpled"``: random
    heights (amplitude 0.03 of the sheet's size, more than the lift): every sheet passes through itself
    and its pile-mates nearly everywhere they overlap (about one self-intersecting pair a triangle: the
    output-bound worst case); ``"waved"``: smooth waves (amplitude 0.01, one crest per sheet) under a
    lift of 0.012, so that each fold crosses itself only where a wave's crest rises through it (cloth
    as a simulation leaves it, mostly near contact)."""
    rng = np.random.default_rng(seed)
    v0, t = sheet(n)
    v0 = v0.astype(np.float64)
    f = v0[:, 0] > 0.5
    v0[f, 0] = 1.0 + 0.37 / (n - 1) - v0[f, 0]
    side = int(np.ceil(np.sqrt(max(1, k) / 4)))
    out = []
    for i in range(k):
        v = v0.copy()
        if kind == "crumpled":
            v[:, 2] = 0.03 * rng.standard_normal(len(v)) + np.where(f, 0.01, 0.0) + 0.02 * (i % 4)
        else:
            phase = rng.uniform(0.0, 2.0 * np.pi, 2)
            wave = 0.01 * np.sin(2.0 * np.pi * v0[:, 1] + phase[0]) * np.sin(np.pi * v0[:, 0] + phase[1])
            v[:, 2] = wave + np.where(f, 0.012, 0.0) + 0.05 * (i % 4)
        pile = i // 4
        v[:, 0] += 1.5 * (pile % side) + 0.12 * (i % 4)
        v[:, 1] += 1.5 * (pile // side)
        out.append((v, t))
    return out


def _frames(pipe, args, device) -> list[float]:
    for _ in range(args.warmup):
        pipe.detect()
    return [synced_ms(pipe.detect, device) for _ in range(args.frames)]


def _profile(scene, args) -> list[dict]:
    """The slowest activities of an eager frame (median of 3) of a self-intersecting pipeline, rounded."""
    from .profile_frame import activities

    pipe = wc.CollisionPipeline(scene, self_intersections=True, graph=False, leaf_size=args.leaf_size)
    pipe.detect()
    rows = activities(None, 3, run=pipe.detect)
    return [{"name": r["name"][:60], "count": r["count"], "ms": round(r["ms"], 4)} for r in rows[:10]]


def _counts(pipe) -> dict:
    walk = pipe.self_phase.traversal
    return {"candidates": int(walk.candidates.last_count), "front_peak": int(walk.front.last_count)}


def one_mesh(name: str, mesh, args, device) -> dict:
    """The row of one mesh: pipeline frame, one-shot call, pymeshlab."""
    v, t = mesh
    row = {"mesh": name, "triangles": int(len(t)), "leaf_size": args.leaf_size}
    scene = wc.Scene.from_meshes([(v, t)], deforming=True, device=device)
    pipe = wc.CollisionPipeline(scene, self_intersections=True, leaf_size=args.leaf_size)
    row["frame"] = ms_stats(_frames(pipe, args, device))
    res = pipe.detect()
    pairs = res.self_pairs[:, 1:]
    row["self_pairs"] = int(len(pairs))
    row.update(_counts(pipe))
    if args.profile:
        row["activities"] = _profile(scene, args)
    del pipe, scene
    gc.collect()
    shots = []
    for _ in range(max(1, args.one_shot_runs)):
        wp.synchronize_device(device)
        t0 = time.perf_counter()
        got = wc.self_intersections(v, t, device=device)
        shots.append((time.perf_counter() - t0) * 1e3)
    row["one_shot"] = ms_stats(shots)
    row["one_shot_equal"] = bool(np.array_equal(got, pairs))
    try:
        import pymeshlab
    except (ImportError, OSError) as exc:  # not installed, or its Qt libraries lack libGL
        row["pymeshlab"] = f"skipped: pymeshlab does not load here ({str(exc)[:120]})"
        return row
    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(np.asarray(v, np.float64), np.asarray(t, np.int32)))
    peer = []
    for _ in range(max(1, args.peer_runs)):
        t0 = time.perf_counter()
        ms.compute_selection_by_self_intersections_per_face()
        peer.append((time.perf_counter() - t0) * 1e3)
    theirs = np.nonzero(ms.current_mesh().face_selection_array())[0]
    shared = (t[pairs[:, 0]][:, :, None] == t[pairs[:, 1]][:, None, :]).any(axis=2).sum(axis=1)
    row["pymeshlab"] = ms_stats(peer)
    row["pymeshlab_faces"] = int(len(theirs))
    row["pymeshlab_same_faces"] = bool(np.array_equal(np.unique(pairs[shared <= 1]), theirs))
    row["speedup_frame_vs_pymeshlab"] = row["pymeshlab"]["ms_min"] / row["frame"]["ms_median"]
    row["speedup_one_shot_vs_pymeshlab"] = row["pymeshlab"]["ms_min"] / row["one_shot"]["ms_median"]
    return row


def cloth(k: int, kind: str, args, device) -> dict:
    """The row of ``k`` sheets of ``kind`` (:func:`crumpled_sheets`): frames with and without self-intersections."""
    meshes = crumpled_sheets(k, args.sheet_n, args.seed, kind)
    scene = wc.Scene.from_meshes(meshes, deforming=True, device=device)
    row = {"sheets": k, "kind": kind, "triangles": int(scene.num_triangles), "leaf_size": args.leaf_size}
    both = wc.CollisionPipeline(scene, self_intersections=True, leaf_size=args.leaf_size)
    pairwise = wc.CollisionPipeline(scene, leaf_size=args.leaf_size)
    row["self_plus_pairwise"] = ms_stats(_frames(both, args, device))
    row["pairwise"] = ms_stats(_frames(pairwise, args, device))
    res = both.detect()
    row["self_pairs"] = int(len(res.self_pairs))
    row["self_colliding"] = int(res.self_colliding.sum())
    row["object_pairs"] = int(len(res.object_pairs))
    row["ratio"] = row["self_plus_pairwise"]["ms_median"] / row["pairwise"]["ms_median"]
    row.update(_counts(both))
    if args.profile:
        row["activities"] = _profile(scene, args)
    return row


def main(argv=None) -> int:
    parser = bench_parser(__doc__)
    add_run_options(parser, frames=20, warmup=3)
    parser.add_argument("--mesh-triangles", type=float, default=1.3e6,
                        help="triangles of the one-mesh cases (about; 0: none)")
    parser.add_argument("--sheets", type=float, nargs="*", default=[1e2, 1e3], help="counts of waved sheets")
    parser.add_argument("--crumpled", type=float, nargs="*", default=[1e2], help="counts of crumpled sheets")
    parser.add_argument("--sheet-n", type=int, default=72, help="vertices along a sheet's side (72: 10,082 triangles)")
    parser.add_argument("--peer-runs", type=int, default=1)
    parser.add_argument("--one-shot-runs", type=int, default=3)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--leaf-size", type=int, default=None, help="triangles per leaf (default: the pipeline's)")
    parser.add_argument("--profile", action="store_true", help="each row: the slowest activities of an eager frame")
    args, device, document = start(parser, argv)
    m = int(args.mesh_triangles)
    if m > 0:
        nv = max(4, 2 * int(np.sqrt(m / 16)))  # figure-eight torus: 2 nu nv = 4 nv^2 triangles (nu = 2 nv)
        level = max(0, int(round(np.log(max(m, 20) / 20) / np.log(4))))
        for name, mesh in (("figure_eight_torus", figure_eight_torus(2 * nv, nv)), ("icosphere", icosphere(level))):
            add_row(document, {"case": "mesh", **one_mesh(name, mesh, args, device)})
            write_result(args.out, document)  # each row as it comes: a later case may not finish
            gc.collect()
    for kind, k in [("waved", k) for k in args.sheets] + [("crumpled", k) for k in args.crumpled]:
        try:
            row = cloth(int(k), kind, args, device)
        except (MemoryError, RuntimeError, OverflowError) as exc:  # too big for the device: say so, go on
            row = {"sheets": int(k), "kind": kind, "error": str(exc)[:300]}
        add_row(document, {"case": "cloth", **row})
        write_result(args.out, document)
        gc.collect()
    write_result(args.out, document)
    return 0


if __name__ == "__main__":
    sys.exit(main())
