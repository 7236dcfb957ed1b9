"""Benchmark: trimesh's collision manager (python-fcl) against warp_ccd.trimesh.CollisionManager on the same scenes.

For each ``--objects`` N, a seeded scene of trimesh's primitives (boxes, icospheres of 320 triangles, cylinders of
16 sections, capsules), turned at random and spread in a cube whose side grows as ``N ** (1/3)`` (a few colliding
pairs an object). Both managers hold the same objects; measured, for each:

* ``one_shot``: a new manager, ``add_object`` of every object, one ``in_collision_internal(return_names=True)``
  (``--warmup`` untimed, min and median of ``--shots``);
* ``call``: ``set_transform`` of every object (a new pose each call: every object moves along its own small
  circle), then ``in_collision_internal(return_names=True)``: a simulation's step (``--warmup`` untimed, min and
  median of ``--frames``); ``set_ms``: the ``set_transform`` loop alone, the rest is the query.

Each row gives the ratios ``fcl / ours`` (above 1: ours is faster) and checks that both managers named the same
colliding pairs at every timed call (``same_names``; ``pairs``: how many at the last).

    python -m bench.trimesh_manager --device cpu --objects 100 1000 --out bench/results/trimesh_manager_cpu.json
"""

from __future__ import annotations

import gc
import sys
import time

import numpy as np

from warp_ccd.trimesh import CollisionManager

from .command import add_run_options, bench_parser, start, write_result
from .timing import ms_stats


def scene(count: int, seed: int) -> tuple[list, np.ndarray, np.ndarray]:
    """``count`` named primitives and their transforms: ``(objects [(name, mesh)], base (N, 4, 4), radius (N,))``,
    ``radius`` the circle each object moves along."""
    import trimesh

    rng = np.random.default_rng(seed)
    shapes = [trimesh.creation.box(extents=[0.8, 0.5, 1.2]), trimesh.creation.icosphere(subdivisions=2, radius=0.5),
              trimesh.creation.cylinder(radius=0.4, height=1.0, sections=16),
              trimesh.creation.capsule(height=0.8, radius=0.3, count=[8, 8])]
    side = 1.6 * count ** (1 / 3)
    base = np.empty((count, 4, 4))
    for k in range(count):
        base[k] = trimesh.transformations.random_rotation_matrix(rng.random(3))
        base[k, :3, 3] = rng.uniform(0, side, 3)
    objects = [(f"{'bscy'[k % 4]}{k}", shapes[k % 4]) for k in range(count)]
    return objects, base, rng.uniform(0.05, 0.3, count)


def poses(base: np.ndarray, radius: np.ndarray, frame: int) -> np.ndarray:
    """The transforms of ``frame``: each object moved along its circle in the xy plane."""
    out = base.copy()
    angle = 0.3 * frame + np.arange(len(base))
    out[:, 0, 3] += radius * np.cos(angle)
    out[:, 1, 3] += radius * np.sin(angle)
    return out


def make(kind: str, device):
    if kind == "fcl":
        import trimesh

        return trimesh.collision.CollisionManager()
    return CollisionManager(device=device)


def one_shot(kind: str, objects: list, transforms: np.ndarray, device) -> tuple[float, set]:
    """ms of a new manager filled and asked once, and its names."""
    start = time.perf_counter()
    manager = make(kind, device)
    for (name, mesh), t in zip(objects, transforms):
        manager.add_object(name, mesh, t)
    _, names = manager.in_collision_internal(return_names=True)
    return (time.perf_counter() - start) * 1e3, names


def calls(kind: str, objects: list, base: np.ndarray, radius: np.ndarray, args, device) -> dict:
    """Times ``set_transform`` of every object plus ``in_collision_internal(return_names=True)``, call by call."""
    manager = make(kind, device)
    for (name, mesh), t in zip(objects, base):
        manager.add_object(name, mesh, t)
    names = [name for name, _ in objects]
    total, sets, found = [], [], []
    for frame in range(args.warmup + args.frames):
        transforms = poses(base, radius, frame)
        start = time.perf_counter()
        for name, t in zip(names, transforms):
            manager.set_transform(name, t)
        moved = time.perf_counter()
        _, pairs = manager.in_collision_internal(return_names=True)
        done = time.perf_counter()
        if frame >= args.warmup:
            total.append((done - start) * 1e3)
            sets.append((moved - start) * 1e3)
            found.append(pairs)
    return {"call": ms_stats(total), "set": ms_stats(sets), "names": found}


def run(count: int, args, device) -> dict:
    objects, base, radius = scene(count, args.seed)
    row = {"objects": count, "triangles": int(sum(len(mesh.faces) for _, mesh in objects))}
    for kind in ("ours", "fcl"):
        shots, names = [], None
        for k in range(args.warmup + args.shots):
            ms, names = one_shot(kind, objects, base, device)
            if k >= args.warmup:
                shots.append(ms)
        timed = calls(kind, objects, base, radius, args, device)
        row[kind] = {"one_shot": ms_stats(shots), "call": timed["call"], "set": timed["set"],
                     "pairs_one_shot": len(names), "pairs_last_call": len(timed["names"][-1])}
        row[f"_{kind}_names"] = (names, timed["names"])
        gc.collect()
    ours, fcl = row.pop("_ours_names"), row.pop("_fcl_names")
    row["same_names"] = bool(ours[0] == fcl[0] and all(a == b for a, b in zip(ours[1], fcl[1])))
    for what in ("one_shot", "call"):
        row[f"ratio_{what}_median"] = row["fcl"][what]["ms_median"] / row["ours"][what]["ms_median"]
        row[f"ratio_{what}_min"] = row["fcl"][what]["ms_min"] / row["ours"][what]["ms_min"]
    ours, fcl = row["ours"], row["fcl"]
    print(f"{count:>6} objects ({row['triangles']:,} triangles): one-shot ours {ours['one_shot']['ms_median']:.1f} ms, "
          f"fcl {fcl['one_shot']['ms_median']:.1f} ms ({row['ratio_one_shot_median']:.2f}x); call ours "
          f"{ours['call']['ms_median']:.2f} ms (set_transform {ours['set']['ms_median']:.2f}), fcl "
          f"{fcl['call']['ms_median']:.2f} ms (set_transform {fcl['set']['ms_median']:.2f}) "
          f"({row['ratio_call_median']:.2f}x); {ours['pairs_last_call']} pairs, same names: {row['same_names']}",
          flush=True)
    return row


def main(argv=None) -> int:
    parser = bench_parser(__doc__.splitlines()[0], device_help="Warp device of our manager (default: Warp's)")
    parser.add_argument("--objects", type=int, nargs="+", default=[100, 1000])
    parser.add_argument("--shots", type=int, default=5, help="timed one-shot runs")
    add_run_options(parser, frames=30, warmup=3, seed=0, frames_help="timed calls",
                    out_help="JSON file (default: none)")
    args, device, document = start(parser, argv)
    document["config"]["device"] = str(device)
    for count in args.objects:
        document["rows"].append(run(count, args, device))
        write_result(args.out, document)
    if args.out:
        print(f"results written to {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
