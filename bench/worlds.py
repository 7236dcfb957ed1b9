"""Benchmark: thousands of independent worlds in one scene, against one world, a Python loop over worlds
and newton's per-world broad phase; the cost of filters; a frame driven from device arrays.

The scene (:func:`robot_world`): ``--worlds`` copies (4,096 by default) of a robot-like cell of 20 objects
(an arm of 8 links in a chain, each touching the next; a table; 11 parts on and around it, some touching
the arm or each other), each copy jittered by its own seed, so the worlds differ. Rows, each a frame of
:meth:`~warp_ccd._src.pipeline.pipeline.CollisionPipeline.detect` (a replayed graph on CUDA), min and median ms over
``--frames`` after ``--warmup``, with the pairs found:

* ``worlds``: every world at the same place, ``world=`` ids (the case worlds are for: a simulator's
  environments on top of each other);
* ``one_world``: the same objects with no ids, each world's copy moved to its own cell of a grid so
  copies never meet: the same objects, pairs and triangles in one world (the target: ``worlds`` within
  1.2x of it);
* ``worlds_spread``: the grid with ids too;
* ``worlds_filtered``: ``worlds`` plus excluded pairs (each arm's 7 adjacent links) and groups and masks
  (the table ignores the arm's base): the cost of filters, and the pairs they remove;
* ``worlds_floor``: ``worlds`` plus one floor in world -1 under every world (a box that meets them all);
* ``python_loop``: one :class:`~warp_ccd._src.pipeline.pipeline.CollisionPipeline` per world, ``detect()`` on each in
  a Python loop, as a user without worlds writes it: timed over ``--loop-worlds`` worlds and scaled to
  all of them (each world is the same work; the row says so), the ratio against ``worlds``;
* ``newton_sap`` and ``sap``: the broad phase alone on the ``worlds`` scene's boxes, newton's
  ``BroadPhaseSAP`` with its per-world segmented sort (``shape_world``) against ours with the worlds'
  filter, same pairs checked;
* ``device_frame``: ``scene.set_poses(device array)`` then ``detect()``, the poses a Warp array viewed
  through ``__cuda_array_interface__`` (standing in for a torch or JAX tensor): Warp's memcpy activities
  counted over the timed frames (0: no data through the host), eager and replayed.

    python -m bench.worlds --device cuda:0 --out bench/results/worlds_cuda0.json
"""

from __future__ import annotations

import sys
import time

import numpy as np
import warp as wp

import warp_ccd as wc
from warp_ccd._src.bench.methods import device_modes
from warp_ccd._src.bench.peers import NewtonBroadPhaseSAP, PeerUnavailable
from warp_ccd._src.bench.timing import ModeFrames, StageTimes, synced_ms
from warp_ccd._src.runtime.buffers import GrowableBuffer
from warp_ccd.scene import icosphere, shape
from warp_ccd.stages import BroadPhaseSAP

from .command import add_row as _add_row
from .command import add_run_options, bench_parser, start, write_result
from .timing import ms_stats

OBJECTS_PER_WORLD = 20
LINKS = 8
"""The arm's links: objects 0..7 of each world, link ``k`` touching link ``k + 1``."""
TABLE = 8
"""The table: object 8 of each world."""


def robot_world(num_worlds: int, seed: int = 0, spacing: float = 0.0):
    """Meshes, ``(N, 7)`` poses and world ids of ``num_worlds`` jittered robot cells (module docs).

    Args:
        num_worlds: ``W``.
        seed: the jitter's seed.
        spacing: 0 puts every world at the origin; else world ``w`` lies at ``spacing * (w % side, w //
            side, 0)`` on a square grid.

    Returns:
        ``(meshes, poses, world)``: ``20 W`` meshes (shared arrays: one shape each), ``(20 W, 7)``
        float64 poses, ``(20 W,)`` int64 world ids.
    """
    rng = np.random.default_rng(seed)
    link = icosphere(1)
    parts = [shape("cube"), shape("octahedron"), shape("dodecahedron"), shape("icosahedron"), icosphere(1)]
    table = (np.array([[-2.0, -1.5, -0.3], [2.0, -1.5, -0.3], [2.0, 1.5, -0.3], [-2.0, 1.5, -0.3],
                       [-2.0, -1.5, 0.0], [2.0, -1.5, 0.0], [2.0, 1.5, 0.0], [-2.0, 1.5, 0.0]]),
             np.array([[0, 2, 1], [0, 3, 2], [4, 5, 6], [4, 6, 7], [0, 1, 5], [0, 5, 4], [1, 2, 6], [1, 6, 5],
                       [2, 3, 7], [2, 7, 6], [3, 0, 4], [3, 4, 7]]))
    cell = [link] * LINKS + [table] + [parts[k % len(parts)] for k in range(OBJECTS_PER_WORLD - LINKS - 1)]
    n = OBJECTS_PER_WORLD * num_worlds
    meshes = cell * num_worlds
    poses = np.zeros((n, 7))
    poses[:, 6] = 1.0
    base = np.zeros((OBJECTS_PER_WORLD, 3))
    angle = np.linspace(0.0, 1.2, LINKS)
    # Links: spheres of radius 0.25, 0.35 apart (each overlaps the next), the base sunk into the table top.
    base[:LINKS] = np.stack([-1.5 + 0.35 * np.cumsum(np.cos(angle)) - 0.35, np.zeros(LINKS),
                             0.2 + 0.35 * (np.cumsum(np.sin(angle)))], axis=1)
    base[TABLE] = [0.0, 0.0, 0.0]
    # Parts (radius 0.2) resting in the table top, in two rows 0.38 apart: neighbours graze each other.
    k = np.arange(OBJECTS_PER_WORLD - LINKS - 1)
    base[TABLE + 1:] = np.stack([-0.4 + 0.38 * (k % 6), -0.7 + 0.9 * (k // 6), np.full(len(k), 0.17)], axis=1)
    side = int(np.ceil(np.sqrt(num_worlds)))
    for w in range(num_worlds):  # set-up of the benchmark's scene, not of the library
        rows = slice(w * OBJECTS_PER_WORLD, (w + 1) * OBJECTS_PER_WORLD)
        offset = spacing * np.array([w % side, w // side, 0.0])
        poses[rows, :3] = base + offset + rng.normal(0.0, 0.04, base.shape) * (np.arange(OBJECTS_PER_WORLD) != TABLE)[
            :, None]
    scale = np.where(np.arange(OBJECTS_PER_WORLD) < LINKS, 0.25, np.where(np.arange(OBJECTS_PER_WORLD) == TABLE, 1.0,
                                                                             0.2))
    world = np.repeat(np.arange(num_worlds), OBJECTS_PER_WORLD)
    return meshes, poses, world, np.tile(scale, num_worlds)


def make_scene(meshes, poses, scale, device, **filters) -> wc.Scene:
    """A scene of shared shapes (one per distinct mesh) with uniform scales and poses."""
    ids = {}
    shapes, object_shape = [], []
    for m in meshes:
        key = id(m[0])
        if key not in ids:
            ids[key] = len(shapes)
            shapes.append(m)
        object_shape.append(ids[key])
    return wc.Scene(shapes, np.array(object_shape), object_scale=scale, poses=poses, device=device, **filters)


def time_detect(pipe, frames: int, warmup: int, device) -> tuple[dict, object]:
    for _ in range(warmup):
        pipe.detect()
    res = []
    ms = [synced_ms(lambda: res.append(pipe.detect()), device) for _ in range(frames)]
    return ms_stats(ms), res[-1]


class CudaInterface:
    """An array with ``__cuda_array_interface__`` alone, over a Warp array's memory (a torch or CuPy
    tensor's stand-in where those are not installed)."""

    def __init__(self, a: wp.array):
        self._a = a
        self.__cuda_array_interface__ = a.__cuda_array_interface__


def main(argv=None) -> int:
    parser = bench_parser(__doc__.split("\n\n")[0], device_help="Warp device (default: cuda:0 if available)")
    parser.add_argument("--worlds", type=int, default=4096, help="worlds of 20 objects (default 4096)")
    parser.add_argument("--loop-worlds", type=int, default=256,
                        help="worlds the Python loop is timed over, then scaled to --worlds (default 256)")
    parser.add_argument("--spacing", type=float, default=8.0, help="grid spacing of one_world (default 8)")
    add_run_options(parser, frames=20, warmup=3, seed=0)
    args, device, doc = start(parser, argv)

    def add_row(doc: dict, row: dict) -> None:  # each row written as it comes (a later failure keeps them)
        _add_row(doc, row)
        write_result(args.out, doc)

    w = args.worlds
    meshes, poses, world, scale = robot_world(w, args.seed)
    _, spread, _, _ = robot_world(w, args.seed, spacing=args.spacing)
    n = len(meshes)
    adjacent = np.array([(i * OBJECTS_PER_WORLD + k, i * OBJECTS_PER_WORLD + k + 1) for i in range(w)
                         for k in range(LINKS - 1)])
    group = np.ones(n, np.int64)
    group[TABLE::OBJECTS_PER_WORLD] = 2
    mask = np.full(n, 3)
    mask[0::OBJECTS_PER_WORLD] = 1  # the base link ignores the table (group 2)
    configs = {
        "worlds": (poses, {"world": world}),
        "one_world": (spread, {}),
        "worlds_spread": (spread, {"world": world}),
        "worlds_filtered": (poses, {"world": world, "exclude_pairs": adjacent, "group": group, "mask": mask}),
    }
    results = {}
    for name, (p, filters) in configs.items():
        scene = make_scene(meshes, p, scale, device, **filters)
        pipe = wc.CollisionPipeline(scene)
        stats, res = time_detect(pipe, args.frames, args.warmup, device)
        results[name] = (stats, res, pipe)
        add_row(doc, {"config": name, "worlds": w, "objects": n, "triangles": scene.num_triangles, **stats,
                      "object_pairs": int(len(res.object_pairs)), "triangle_pairs": int(res.num_triangle_pairs),
                      "broad_pairs": int(res.num_broad_pairs), "excluded_pairs": int(len(adjacent))
                      if "exclude_pairs" in filters else 0})
    base = results["worlds"][1].object_pairs
    same = np.array_equal(base, results["worlds_spread"][1].object_pairs) and np.array_equal(
        base, results["one_world"][1].object_pairs)
    doc["same_pairs_worlds_one_world"] = bool(same)
    doc["worlds_over_one_world"] = results["worlds"][0]["ms_median"] / results["one_world"][0]["ms_median"]
    keep = results["worlds"][2].scene.collision_filter
    filtered = wc.scene.CollisionFilter(n, world=world, exclude_pairs=adjacent, group=group, mask=mask)
    doc["filtered_pairs_equal_filter"] = bool(np.array_equal(results["worlds_filtered"][1].object_pairs,
                                                             base[filtered.allowed(base)]))
    doc["filter_over_worlds"] = results["worlds_filtered"][0]["ms_median"] / results["worlds"][0]["ms_median"]
    print(f"worlds / one world: {doc['worlds_over_one_world']:.3f} (same pairs: {same}); filters / worlds: "
          f"{doc['filter_over_worlds']:.3f}", flush=True)

    # A floor in world -1 under every world.
    floor = (np.array([[-50.0, -50, -0.25], [50, -50, -0.25], [50, 50, -0.25], [-50, 50, -0.25]]),
             np.array([[0, 1, 2], [0, 2, 3]]))
    scene = make_scene(meshes + [floor], np.concatenate([poses, [[0, 0, 0, 0, 0, 0, 1.0]]]),
                       np.concatenate([scale, [1.0]]), device, world=np.concatenate([world, [-1]]))
    stats, res = time_detect(wc.CollisionPipeline(scene), args.frames, args.warmup, device)
    add_row(doc, {"config": "worlds_floor", "worlds": w, "objects": n + 1, **stats,
                  "object_pairs": int(len(res.object_pairs)), "floor_pairs": int((res.object_pairs[:, 1] == n).sum())})

    # A Python loop over worlds, one pipeline each.
    loop = min(args.loop_worlds, w)
    pipes = []
    for i in range(loop):
        rows = slice(i * OBJECTS_PER_WORLD, (i + 1) * OBJECTS_PER_WORLD)
        pipes.append(wc.CollisionPipeline(make_scene(meshes[rows], poses[rows], scale[rows], device)))
    for p in pipes:
        for _ in range(2):
            p.detect()
    found = []

    def loop_frame():
        found.clear()
        for p in pipes:
            found.append(len(p.detect().object_pairs))

    runs = [synced_ms(loop_frame, device) for _ in range(max(3, args.frames // 4))]
    loop_pairs = list(found)
    scaled = {k: v * w / loop for k, v in ms_stats(runs).items()}
    want = int((results["worlds"][1].pair_world < loop).sum())
    add_row(doc, {"config": "python_loop", "worlds": w, "worlds_timed": loop, **scaled,
                  "timed_ms_min": float(np.min(runs)), "object_pairs_timed": int(sum(loop_pairs)),
                  "object_pairs_worlds_same_subset": want,
                  "note": f"timed over {loop} worlds, scaled by {w}/{loop}"})
    doc["loop_over_worlds"] = scaled["ms_median"] / results["worlds"][0]["ms_median"]
    print(f"python loop / worlds: {doc['loop_over_worlds']:.1f}", flush=True)
    pipes.clear()

    # The broad phase alone on the worlds' boxes: ours against newton's per-world sweep, each eager and
    # (on CUDA) replayed as a graph; the better mode's times.
    pipe = results["worlds"][2]
    lower, upper = pipe.boxes.lower, pipe.boxes.upper
    peers = {"sap": (BroadPhaseSAP(device=device), keep)}
    try:
        peers["newton_sap"] = (NewtonBroadPhaseSAP(device=device, shape_world=world.astype(np.int32)), None)
    except PeerUnavailable as exc:
        doc.setdefault("notes", []).append(f"newton_sap skipped: {exc}")
    found = {}
    for name, (broad, pair_filter) in peers.items():
        pairs = GrowableBuffer(wp.vec2i, 4 * n, device, f"{name} pairs")

        def launch(broad=broad, pairs=pairs, pair_filter=pair_filter):
            if pair_filter is None:
                broad.launch(lower, upper, pairs)
            else:
                broad.launch(lower, upper, pairs, pair_filter)

        frames = ModeFrames(launch, [pairs, *broad.counters], device, device_modes(device))
        times = StageTimes()
        for frame in range(args.warmup + args.frames):
            t = frames.run("broad")
            if frame >= args.warmup:
                times.add(t)
        count = frames.counts[0]
        found[name] = np.unique(np.sort(pairs.numpy(count).reshape(-1, 2), axis=1), axis=0)
        ms_min, ms_median = times.summary()["broad"]
        add_row(doc, {"config": name, "worlds": w, "boxes": n, "ms_min": ms_min, "ms_median": ms_median,
                      "mode": times.best_mode.get("broad", "eager"), "pairs": int(count),
                      "same_pairs_as_sap": bool(np.array_equal(found[name], found["sap"]))})
    del peers

    # A frame from device arrays: poses read in place; Warp's memcpy activities counted.
    if wp.get_device(device).is_cuda:
        for graph in (False, True):
            scene = make_scene(meshes, poses, scale, device, world=world)
            p = wc.CollisionPipeline(scene, graph=graph)
            memory = wp.array(poses.astype(np.float32), device=device)
            source = CudaInterface(memory)
            for _ in range(args.warmup):
                scene.set_poses(source)
                p.detect()
            wp.synchronize_device(device)
            wp.timing_begin(cuda_filter=wp.TIMING_MEMCPY)
            ms = []
            for _ in range(args.frames):
                t0 = time.perf_counter()
                scene.set_poses(source)
                p.detect()
                ms.append((time.perf_counter() - t0) * 1e3)
            copies = wp.timing_end()
            add_row(doc, {"config": "device_frame", "graph": graph, "worlds": w, **ms_stats(ms),
                          "memcpy_activities": len(copies), "memcpy_names": sorted({c.name for c in copies})})
    write_result(args.out, doc)
    return 0


if __name__ == "__main__":
    sys.exit(main())
