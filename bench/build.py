"""Benchmark: tree builds on the device, rebuilds of deforming meshes, one-shot ``collide()``.

Three parts, in one process on one device:

* **builds**: every tree of ``S`` distinct shapes of ``m`` triangles (noisy icospheres: 80, 1,280,
  ... 1.3M triangles; perturbed icosahedra for 20) built by the kernels
  (:class:`~warp_ccd._src.trees.build.TreeBuild`, layout then triangle order, as ``SceneBVH`` does;
  ``kernels`` the default, subtrees finished by a thread block on CUDA, ``kernels_thread`` by one
  thread each, as before the blocks),
  against Warp's own device builds of the same triangles: one ``wp.Mesh`` (LBVH) for a single
  shape, a ``wp.Bvh`` (LBVH) over all triangle boxes grouped by shape for many; and the numpy
  reference (:func:`~warp_ccd._src.trees.reference.build_tree`, shape by shape) where it takes under a few
  seconds. Wall time from the first launch to the device's end (what a user waits for), min and
  median over ``--repeats`` after a warm-up. ``--small`` adds rows of the kernels with other
  subtree sizes finished per thread; small shapes also get a row without the radix presort
  (insertion sorts only). On CUDA, one build of each case is also profiled activity by activity
  (``build_activities``: kernels, sorts, scans, copies with their device time).
* **rebuild**: deforming meshes whose vertices move far from where their trees were built
  (icospheres stretched and twisted into long spirals): candidate triangle pairs and mid-phase
  time of a frame with the refit trees, then after :meth:`SceneBVH.rebuild
  <warp_ccd._src.trees.bvh.SceneBVH.rebuild>`, and the rebuild's own time.
* **one-shot**: ``warp_ccd.collide(meshes, transforms)`` from Python lists of numpy meshes (each
  mesh its own array: no instancing) against python-fcl doing the same with its BVH builds
  (``BVHModel`` per mesh, ``DynamicAABBTreeCollisionManager``, contacts on), on 1,000 distinct
  polyhedra and on 60 noisy spheres of 320 to 20,480 triangles (about 210k). The object pairs of
  both are compared.

Rows: ``{"method", "n_shapes", "triangles_per_shape", "ms_min", "ms_median"}`` under ``builds``;
``rebuild`` and ``one_shot`` rows say what they measured.

    python -m bench.build --device cuda:0 --out bench/results/build_cuda0.json
"""

from __future__ import annotations

import argparse
import cProfile
import io
import pstats
import time

import numpy as np
import warp as wp

import warp_ccd as wc
from warp_ccd._src.bench.peers import fcl_bvh
from warp_ccd._src.bench.report import environment
from warp_ccd._src.bench.timing import synced_ms
from warp_ccd._src.trees.build import SMALL_SUBTREE, TreeBuild
from warp_ccd._src.trees.build_block import BLOCK_SUBTREE
from warp_ccd.stages import build_tree

from .command import add_out_option, bench_parser, parse_options, write_result

POLYHEDRA = ("tetrahedron", "cube", "octahedron", "dodecahedron", "icosahedron")


def timed(fn, device, repeats: int) -> tuple[float, float]:
    """``(min, median)`` wall ms of ``fn()`` up to the device's end (None: Warp's default device, for
    host work), after one warm-up call."""
    fn()
    times = [synced_ms(fn, device) for _ in range(repeats)]
    return float(np.min(times)), float(np.median(times))


def noisy_sphere(level: int, rng, bumps: float = 0.15) -> tuple[np.ndarray, np.ndarray]:
    """An icosphere of ``20 * 4**level`` triangles with smooth bumps and a little noise, like a
    scanned blob (float32 vertices, int32 triangles)."""
    v, t = wc.scene.icosphere(level)
    v = v.astype(np.float64)
    k = rng.normal(size=(4, 3))
    phase = rng.uniform(0, 2 * np.pi, 4)
    r = 1.0 + bumps * np.sin(v @ k.T * 2.0 + phase).mean(axis=1) + rng.normal(0, 0.003, len(v))
    return (v * r[:, None]).astype(np.float32), t


def shapes_of(num_shapes: int, triangles: int, rng) -> list:
    """``num_shapes`` distinct meshes of ``triangles`` triangles each (20: icosahedra, else 20 * 4**k)."""
    if triangles == 20:
        v, t = wc.scene.shape("icosahedron")
        return [(v + rng.normal(0, 0.01, v.shape).astype(np.float32), t) for _ in range(num_shapes)]
    level = int(round(np.log(triangles / 20) / np.log(4)))
    if 20 * 4**level != triangles:
        raise ValueError(f"triangles per shape must be 20 * 4**k, got {triangles}")
    base_v, t = noisy_sphere(level, rng)
    jitter = rng.normal(0, 0.01, (num_shapes, 1, 3)).astype(np.float32)
    return [(base_v * (1 + jitter[k]), t) for k in range(num_shapes)]


def bench_builds(device, cases, repeats: int, smalls: list[int], insertion_max: int, reference_limit: int,
                 rng, profiles: list) -> list[dict]:
    """Rows of build times; appends each case's device activities (CUDA) to ``profiles``."""
    rows = []
    for num_shapes, triangles in cases:
        meshes = shapes_of(num_shapes, triangles, rng)
        scene = wc.Scene(meshes, np.zeros(0, np.int64), device=device)
        label = f"{num_shapes:,} x {triangles:,}"

        def add(method, lo_med, **extra):
            lo, med = lo_med
            rows.append({"method": method, "n_shapes": num_shapes, "triangles_per_shape": triangles,
                         "ms_min": lo, "ms_median": med, **extra})
            print(f"{label:>18} {method:<22} min {lo:9.3f} ms  median {med:9.3f} ms", flush=True)

        # (method, finish, small, presort): the default (blocks on CUDA), subtrees of 8 finished by
        # one thread each (the build before blocks), other subtree sizes, shapes sorted by insertion.
        variants = [("kernels", None, None, None), ("kernels_thread", "thread", None, None),
                    *[(f"kernels_small{s}", None, s, None) for s in smalls]]
        if triangles <= insertion_max:  # each shape one thread, lists sorted by insertion
            variants.append(("kernels_insertion_sort", "thread", triangles, False))
        for method, finish, small, presort in variants:
            def build(finish=finish, small=small, presort=presort):
                b = TreeBuild(scene.shape_triangle, scene.shape_triangle_start_np, small=small, presort=presort,
                              finish=finish, device=device)
                b.layout()
                b.order(scene.shape_vertex, scene.shape_vertex_start)
                return b

            b = build()
            add(method, timed(build, device, repeats), global_levels=b.num_global_levels, presort=b.presort,
                small=b.small, finish=b.finish, block_dim=b.block_dim)
            if method == "kernels":
                default_build = build
                add("kernels_init", timed(lambda: TreeBuild(scene.shape_triangle, scene.shape_triangle_start_np,
                                                            device=device), device, repeats))
                b = build()
                add("kernels_layout", timed(b.layout, device, repeats))
                add("kernels_order", timed(lambda b=b: b.order(scene.shape_vertex, scene.shape_vertex_start),
                                           device, repeats))
        if device.is_cuda:  # where one build's device time goes, kernel by kernel
            wp.synchronize_device(device)
            wp.timing_begin(cuda_filter=wp.TIMING_ALL)
            default_build()
            wp.synchronize_device(device)
            activity = {}
            for r in wp.timing_end():
                count, ms = activity.get(r.name, (0, 0.0))
                activity[r.name] = (count + 1, ms + r.elapsed)
            top = sorted(activity.items(), key=lambda kv: -kv[1][1])
            profiles.append({"n_shapes": num_shapes, "triangles_per_shape": triangles,
                             "device_ms": sum(ms for _, ms in activity.values()),
                             "activities": [{"name": k, "count": c, "ms": ms} for k, (c, ms) in top]})
            print(f"{label:>18} device time {profiles[-1]['device_ms']:.3f} ms in "
                  f"{sum(c for c, _ in activity.values())} activities; top: "
                  + ", ".join(f"{k[:40]} x{c} {ms:.3f}" for k, (c, ms) in top[:4]), flush=True)
        # Warp's LBVH over the same triangles: one mesh, or one grouped Bvh over all triangle boxes.
        points = scene.shape_vertex
        tri = scene.shape_triangle_start_np
        if num_shapes == 1:
            indices = wp.array(meshes[0][1].reshape(-1).astype(np.int32), dtype=wp.int32, device=device)
            add("wp.Mesh lbvh", timed(lambda: wp.Mesh(points, indices, bvh_constructor="lbvh"), device, repeats))
        else:
            tv = np.concatenate([m[0][m[1]] for m in meshes])
            lowers = wp.array(tv.min(axis=1), dtype=wp.vec3, device=device)
            uppers = wp.array(tv.max(axis=1), dtype=wp.vec3, device=device)
            groups = wp.array(np.repeat(np.arange(num_shapes, dtype=np.int32), np.diff(tri)), dtype=wp.int32,
                              device=device)
            add("wp.Bvh lbvh grouped", timed(lambda: wp.Bvh(lowers, uppers, constructor="lbvh", groups=groups),
                                             device, repeats))
        if num_shapes * triangles <= reference_limit:
            add("numpy reference", timed(lambda: [build_tree(v, t) for v, t in meshes], None, max(1, repeats // 4)))
    return rows


def spiral(v: np.ndarray, amount: float) -> np.ndarray:
    """Stretches a sphere along z by ``1 + 6 amount`` and twists it by ``4 amount`` turns over its height."""
    z = v[:, 2] * (1 + 6 * amount)
    ang = 4 * np.pi * amount * v[:, 2]
    x = v[:, 0] * np.cos(ang) - v[:, 1] * np.sin(ang)
    y = v[:, 0] * np.sin(ang) + v[:, 1] * np.cos(ang)
    return np.stack([x, y, z], axis=1).astype(np.float32)


def bench_rebuild(device, count: int, level: int, repeats: int, rng) -> list[dict]:
    """Deforming spheres twisted into spirals: a frame with refit trees against rebuilt ones."""
    v, t = wc.scene.icosphere(level)
    # Shuffle the triangles so that a tree built on the sphere groups triangles far apart on the spiral.
    t = t[rng.permutation(len(t))]
    side = int(np.ceil(count ** (1 / 3)))
    centres = np.stack(np.meshgrid(*[np.arange(side)] * 3, indexing="ij"), -1).reshape(-1, 3)[:count] * 2.2
    meshes = [(v + c.astype(np.float32), t) for c in centres]
    scene = wc.Scene.from_meshes(meshes, deforming=True, device=device)
    pipe = wc.CollisionPipeline(scene, timings=True)
    moved = np.concatenate([spiral(v, 1.0) + c.astype(np.float32) for c in centres])
    scene.set_world_vertices(moved)
    rows = []
    for state in ("refit", "rebuilt"):
        if state == "rebuilt":
            lo, med = timed(lambda: pipe.boxes.rebuild(scene), device, repeats)
            rows.append({"what": "rebuild", "objects": count, "triangles_per_object": len(t), "ms_min": lo,
                         "ms_median": med})
        mids, res = [], None
        for _ in range(repeats):
            res = pipe.detect()
            mids.append(res.timings["mid"])
        rows.append({"what": f"frame with {state} trees", "objects": count, "triangles_per_object": len(t),
                     "candidates": int(res.num_candidates), "triangle_pairs": int(res.num_triangle_pairs),
                     "mid_ms_min": float(np.min(mids)), "mid_ms_median": float(np.median(mids))})
    for r in rows:
        print("rebuild:", r, flush=True)
    return rows


def polyhedra_meshes(num: int, rng) -> tuple[list, np.ndarray]:
    """``num`` distinct polyhedra (each its own perturbed arrays) and rigid transforms, spread at the
    density of ``Scene.random``."""
    meshes = []
    for k in rng.integers(0, len(POLYHEDRA), num):
        v, t = wc.scene.shape(POLYHEDRA[k])
        meshes.append(((v * rng.uniform(0.5, 1.5) + rng.normal(0, 0.01, v.shape)).astype(np.float64), t.copy()))
    return meshes, transforms_in_cube(num, (num * 4.19 / 0.04) ** (1 / 3), rng)


def sphere_meshes(rng) -> tuple[list, np.ndarray]:
    """60 noisy spheres of 320 to 20,480 triangles (about 210k), radii 1 to 3, some overlapping."""
    levels = [5] * 5 + [4] * 13 + [3] * 27 + [2] * 15
    meshes = []
    for level in levels:
        v, t = noisy_sphere(level, rng)
        meshes.append((v * rng.uniform(1.0, 3.0), t))
    return meshes, transforms_in_cube(len(meshes), 14.0, rng)


def transforms_in_cube(num: int, side: float, rng) -> np.ndarray:
    """Random rotations, translations uniform in a cube of ``side``."""
    q = rng.normal(size=(num, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    x, y, z, w = q.T
    rot = np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w),
                    2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w),
                    2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], axis=1).reshape(-1, 3, 3)
    out = np.tile(np.eye(4), (num, 1, 1))
    out[:, :3, :3] = rot
    out[:, :3, 3] = rng.uniform(-side / 2, side / 2, (num, 3))
    return out


def fcl_one_shot(meshes, transforms) -> np.ndarray:
    """python-fcl from the same lists: a BVH per mesh, the dynamic AABB tree manager, contacts on;
    returns the object pairs (FCL's contact limit doubled until no frame reaches it)."""
    import fcl

    objects, owner = [], {}
    for i, ((v, t), m) in enumerate(zip(meshes, transforms)):
        model = fcl_bvh(v, t)
        objects.append((model, fcl.CollisionObject(model, fcl.Transform(m[:3, :3], m[:3, 3]))))
        owner[id(model)] = i
    manager = fcl.DynamicAABBTreeCollisionManager()
    manager.registerObjects([o for _, o in objects])
    manager.setup()
    limit = 100_000
    while True:
        data = fcl.CollisionData(request=fcl.CollisionRequest(num_max_contacts=limit, enable_contact=True))
        manager.collide(data, fcl.defaultCollisionCallback)
        if len(data.result.contacts) < limit:
            break
        limit *= 2
    pairs = set()
    for c in data.result.contacts:
        a, b = owner[id(c.o1)], owner[id(c.o2)]
        pairs.add((min(a, b), max(a, b)))
    return np.array(sorted(pairs), np.int32).reshape(-1, 2)


def bench_one_shot(device, repeats: int, rng, profile: str | None = None) -> list[dict]:
    rows = []
    profiles = []
    for name, (meshes, transforms) in (("1,000 distinct polyhedra", polyhedra_meshes(1000, rng)),
                                       ("60 noisy spheres", sphere_meshes(rng))):
        tris = int(sum(len(t) for _, t in meshes))
        lo, med = timed(lambda m=meshes, x=transforms: wc.collide(m, x, device=device), device, repeats)
        res = wc.collide(meshes, transforms, device=device)
        if profile:
            profiler = cProfile.Profile()
            profiler.enable()
            wc.collide(meshes, transforms, device=device)
            wp.synchronize_device(device)
            profiler.disable()
            text = io.StringIO()
            pstats.Stats(profiler, stream=text).sort_stats("cumulative").print_stats(40)
            profiles.append(f"== one-shot collide(), {name}, on {device}\n{text.getvalue()}")
        row = {"scene": name, "objects": len(meshes), "triangles": tris, "method": "warp_ccd collide()",
               "ms_min": lo, "ms_median": med, "object_pairs": int(len(res.object_pairs)), "frame_runs": res.runs}
        rows.append(row)
        print("one-shot:", row, flush=True)
        try:
            import fcl  # noqa: F401
        except ImportError:
            print("one-shot: python-fcl is not installed; peer skipped", flush=True)
            continue
        times = []
        for _ in range(max(1, repeats // 2)):
            t = time.perf_counter()
            pairs = fcl_one_shot(meshes, transforms)
            times.append((time.perf_counter() - t) * 1e3)
        row = {"scene": name, "objects": len(meshes), "triangles": tris, "method": "python-fcl with builds (CPU)",
               "ms_min": float(np.min(times)), "ms_median": float(np.median(times)),
               "object_pairs": int(len(pairs)),
               "same_object_pairs": bool(np.array_equal(pairs, res.object_pairs))}
        rows.append(row)
        print("one-shot:", row, flush=True)
    if profile:
        with open(profile, "w") as f:
            f.write("\n".join(profiles))
    return rows


def main(argv=None) -> None:
    p = bench_parser(__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--cases", nargs="+", default=["1000x20", "100000x80", "10000x1280", "1x1310720", "60x5120"],
                   help="SHAPESxTRIANGLES (triangles 20 or 20 * 4**k)")
    p.add_argument("--small", nargs="*", type=int, default=[], help="other sizes of the subtrees finished by a block "
                   "(by a thread on the CPU)")
    p.add_argument("--insertion-max", type=int, default=80,
                   help="also time shapes of at most this many triangles sorted by insertion, one thread each")
    p.add_argument("--repeats", type=int, default=10)
    p.add_argument("--reference-limit", type=int, default=200_000,
                   help="run the numpy reference where shapes x triangles is at most this")
    p.add_argument("--rebuild", default="27x5120", help="OBJECTSxTRIANGLES of the rebuild part ('' skips it)")
    p.add_argument("--no-one-shot", action="store_true")
    p.add_argument("--profile", default=None, help="write cProfile statistics of one one-shot call per scene here")
    add_out_option(p)
    args, device = parse_options(p, argv)
    rng = np.random.default_rng(0)
    cases = [tuple(int(float(x)) for x in c.split("x")) for c in args.cases]
    doc = {"benchmark": "build", **environment(device),
           "config": {"repeats": args.repeats, "small_subtree": SMALL_SUBTREE, "block_subtree": BLOCK_SUBTREE,
                      "small": args.small}}
    doc["build_activities"] = []
    doc["builds"] = bench_builds(device, cases, args.repeats, args.small, args.insertion_max, args.reference_limit,
                                 rng, doc["build_activities"])
    if args.rebuild:
        count, tris = (int(x) for x in args.rebuild.split("x"))
        doc["rebuild"] = bench_rebuild(device, count, int(round(np.log(tris / 20) / np.log(4))), args.repeats, rng)
    if not args.no_one_shot:
        doc["one_shot"] = bench_one_shot(device, args.repeats, rng, args.profile)
    if args.out:
        write_result(args.out, doc)
        print("wrote", args.out)


if __name__ == "__main__":
    main()
